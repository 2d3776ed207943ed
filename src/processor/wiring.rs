//! Wiring diagnostics: a spec input that Telegraf's metrics never feed says so.
//!
//! Owns: watching the first records of a run (the first [`WINDOW_RECORDS`] records or
//! [`WINDOW`] of wall time, whichever ends first, or the end of the input if that comes sooner)
//! and then warning once per input that
//! - matched no metric: the warning names the input and its `@TelegrafIn`, lists the
//!   measurements, tag sets and field names actually seen, and names the nearest match (a wrong
//!   `namepass`, measurement, tag filter or field name, or a JSON string Telegraf's JSON parser
//!   dropped because it is not in `json_string_fields`);
//! - had its field present but never converting to the input's type, with the fix;
//! - gathers a list (`_*` with `@TelegrafListLength(n)`) whose records never reached `n`.
//!
//! After the window it costs one branch per record. The processor calls [`WiringCheck::observe`]
//! for each record and [`WiringCheck::finish`] when the input ends.

use crate::telegraf::binding::{FieldPattern, InputBinding, show_field};
use lineproto::{FieldValue, Metric, Prefix};
use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};
use tessla_engine::Type;

/// Records watched before the verdict.
pub const WINDOW_RECORDS: u64 = 1000;
/// Wall time watched before the verdict (from the first record).
pub const WINDOW: Duration = Duration::from_secs(10);
/// Distinct tag sets and field names kept per measurement (a fleet has many tag values).
const MAX_TAG_SETS: usize = 4;
const MAX_FIELDS: usize = 64;
const MAX_MEASUREMENTS: usize = 16;

/// What one input got during the window.
#[derive(Debug, Default, Clone)]
struct InputSeen {
    /// Records whose measurement and tags matched.
    selected: u64,
    /// Records that had the field (or an element of the list).
    present: u64,
    converted: u64,
    /// The first value that did not convert.
    failed_example: Option<FieldValue>,
    /// Longest list gathered (indexed patterns).
    max_len: usize,
}

/// What one measurement looked like.
#[derive(Debug, Default, Clone)]
struct MeasurementSeen {
    tag_sets: BTreeSet<String>,
    more_tag_sets: bool,
    /// Field name (an indexed name `lidar_12` as its prefix `lidar_`) -> largest index seen.
    fields: BTreeMap<String, Option<usize>>,
    more_fields: bool,
}

/// The watch over the first records of a run.
#[derive(Debug, Default)]
pub struct WiringCheck {
    done: bool,
    records: u64,
    started: Option<Instant>,
    inputs: Vec<InputSeen>,
    measurements: BTreeMap<String, MeasurementSeen>,
    /// Scratch for [`tag_set_key`]: the order of the record's tags, and the key.
    tag_order: Vec<usize>,
    tag_key: String,
}

/// Write into `key` the record's tag set as [`WiringCheck`] keeps it: its `k=v` pieces in
/// sorted order (as strings, so `a-b=..` before `a=..`), joined by `,`. `order` is a buffer.
fn tag_set_key(m: &Metric, order: &mut Vec<usize>, key: &mut String) {
    fn piece<'a>((k, v): &'a (String, String)) -> impl Iterator<Item = u8> + 'a {
        k.bytes().chain(std::iter::once(b'=')).chain(v.bytes())
    }
    order.clear();
    order.extend(0..m.tags.len());
    let by_piece = |a: &usize, b: &usize| match (m.tags.get(*a), m.tags.get(*b)) {
        (Some(a), Some(b)) => piece(a).cmp(piece(b)),
        _ => a.cmp(b),
    };
    if !order.is_sorted_by(|a, b| by_piece(a, b).is_le()) {
        order.sort_by(by_piece);
    }
    key.clear();
    for (n, (k, v)) in order.iter().filter_map(|&i| m.tags.get(i)).enumerate() {
        if n > 0 {
            key.push(',');
        }
        key.push_str(k);
        key.push('=');
        key.push_str(v);
    }
}

impl WiringCheck {
    pub fn new(bindings: &[InputBinding]) -> WiringCheck {
        WiringCheck {
            inputs: vec![InputSeen::default(); bindings.len()],
            done: bindings.is_empty(),
            ..WiringCheck::default()
        }
    }

    /// Whether the window is over (and reported).
    pub fn is_done(&self) -> bool {
        self.done
    }

    /// Watch one record; at the end of the window, report (once).
    pub fn observe(&mut self, m: &Metric, bindings: &[InputBinding]) {
        if self.done {
            return;
        }
        let started = *self.started.get_or_insert_with(Instant::now);
        self.records += 1;
        let runs = self.note_shape(m);
        for (seen, b) in self.inputs.iter_mut().zip(bindings) {
            if !b.matches(m) {
                continue;
            }
            seen.selected += 1;
            match &b.field {
                FieldPattern::Exact(f) => {
                    if let Some(v) = m.field(f) {
                        seen.present += 1;
                        if b.convert(v).is_ok() {
                            seen.converted += 1;
                        } else if seen.failed_example.is_none() {
                            seen.failed_example = Some(v.clone());
                        }
                    }
                }
                FieldPattern::Indexed(prefix) => {
                    // A prefix ending in `_` takes exactly the keys that split into it and an
                    // index, so the runs the shape pass found give its longest list without a
                    // second pass over the record's keys.
                    let max = match &runs {
                        Some(runs) if prefix.ends_with('_') => runs
                            .iter()
                            .filter(|(name, _)| *name == prefix)
                            .map(|&(_, i)| i)
                            .max(),
                        _ => m
                            .fields
                            .iter()
                            .filter_map(|(k, _)| index_of(k.as_bytes(), prefix.as_bytes()))
                            .max(),
                    };
                    let len = max.map(|i| i + 1);
                    if let Some(len) = len {
                        seen.present += 1;
                        seen.converted += 1;
                        seen.max_len = seen.max_len.max(len);
                    }
                }
            }
        }
        if self.records >= WINDOW_RECORDS || started.elapsed() >= WINDOW {
            self.report(bindings);
        }
    }

    /// The input ended before the window did: report on what was seen.
    pub fn finish(&mut self, bindings: &[InputBinding]) {
        if !self.done && self.records > 0 {
            self.report(bindings);
        }
        self.done = true;
    }

    /// Note the record's measurement, tag set and field names; the record's indexed names
    /// (`lidar_` of `lidar_12`) with the largest index of each run of keys of one name, unless
    /// the record's measurement is not kept (too many measurements).
    fn note_shape<'m>(&mut self, m: &'m Metric) -> Option<Vec<(&'m str, usize)>> {
        if !self.measurements.contains_key(&m.measurement)
            && self.measurements.len() >= MAX_MEASUREMENTS
        {
            return None;
        }
        let seen = match self.measurements.get_mut(&m.measurement) {
            Some(seen) => seen,
            None => self.measurements.entry(m.measurement.clone()).or_default(),
        };
        // The tag set as `k=v` pieces sorted and joined by `,`, built in the check's buffers
        // (no allocation per record once warm); a new one is copied into the set.
        tag_set_key(m, &mut self.tag_order, &mut self.tag_key);
        if !seen.tag_sets.contains(self.tag_key.as_str()) {
            if seen.tag_sets.len() < MAX_TAG_SETS {
                seen.tag_sets.insert(self.tag_key.clone());
            } else {
                seen.more_tag_sets = true;
            }
        }
        // The indexed name of the last `<name><digits>` key and the largest index it had since
        // its entry was looked up: a scan's 360 beams take one map look-up, not one each. The
        // largest index is written to the entry when another indexed name comes or the record
        // ends (an entry never looked at in between, so the same as updating it per key).
        // A key of the run is its name (compared a word at a time) and digits; any other key
        // splits into another name or none.
        let mut run: Option<(Prefix<'m>, &str, usize)> = None;
        let mut runs = Vec::new();
        for (k, _) in &m.fields {
            if let Some((p, _, max)) = run.as_mut()
                && let Some(i) = p.rest(k.as_bytes()).and_then(digits_value)
            {
                *max = (*max).max(i);
                continue;
            }
            let (name, idx) = match split_index(k) {
                Some((prefix, i)) => {
                    let next = (Prefix::new(prefix.as_bytes()), prefix, i);
                    if let Some((_, p, max)) = run.replace(next) {
                        raise(&mut seen.fields, p, max);
                        runs.push((p, max));
                    }
                    (prefix, Some(i))
                }
                None => (k.as_str(), None),
            };
            let full = seen.fields.len() >= MAX_FIELDS;
            match seen.fields.get_mut(name) {
                Some(max) => {
                    if let (Some(old), Some(i)) = (max.as_mut(), idx) {
                        *old = (*old).max(i);
                    }
                }
                None if !full => {
                    seen.fields.insert(name.to_string(), idx);
                }
                None => seen.more_fields = true,
            }
        }
        if let Some((_, p, max)) = run {
            raise(&mut seen.fields, p, max);
            runs.push((p, max));
        }
        Some(runs)
    }

    fn report(&mut self, bindings: &[InputBinding]) {
        self.done = true;
        let within = if self.records >= WINDOW_RECORDS {
            format!("in the first {} records", self.records)
        } else {
            format!("in {} records", self.records)
        };
        for (seen, b) in self.inputs.iter().zip(bindings) {
            if seen.present == 0 {
                log_warn!("{}", self.unmatched(b, seen, &within));
            } else if seen.converted == 0 {
                log_warn!("{}", not_converting(b, seen, &within));
            } else if let Some(n) = b.length
                && seen.max_len < n
            {
                log_warn!(
                    "input `{}` ({}): lists had at most {} elements {within}, fewer than \
                         @TelegrafListLength({n}); the missing ones are filled as dropouts. If the \
                         lidar has {} beams, set that length (bundled robot specs: --set lidar_beams={})",
                    b.name,
                    annotation(b),
                    seen.max_len,
                    seen.max_len,
                    seen.max_len
                );
            }
        }
        self.measurements.clear();
    }

    /// The warning for an input that matched nothing: what was seen and the nearest match.
    fn unmatched(&self, b: &InputBinding, seen: &InputSeen, within: &str) -> String {
        let mut msg = format!(
            "input `{}` ({}) matched nothing {within}; seen: {}",
            b.name,
            annotation(b),
            self.describe_seen()
        );
        let wanted_field = match &b.field {
            FieldPattern::Exact(f) => f.clone(),
            FieldPattern::Indexed(p) => format!("{p}*"),
        };
        let hint = if let Some(m) = &b.measurement
            && !self.measurements.contains_key(m)
        {
            let near = nearest(m, self.measurements.keys().map(String::as_str));
            Some(match near {
                Some(n) => format!(
                    "no metric named `{m}` (did you mean `{n}`? check @TelegrafIn and Telegraf's namepass)"
                ),
                None => format!("no metric named `{m}`: check @TelegrafIn and Telegraf's namepass"),
            })
        } else if seen.selected == 0 && !b.tags.is_empty() {
            let want: Vec<String> = b.tags.iter().map(|(k, v)| format!("{k}={v}")).collect();
            Some(format!(
                "no metric carries the tags {} (the tag sets seen are listed above)",
                want.join(",")
            ))
        } else {
            let fields: Vec<String> = self
                .measurements
                .iter()
                .filter(|(name, _)| b.measurement.as_ref().is_none_or(|m| m == *name))
                .flat_map(|(_, s)| {
                    s.fields.iter().map(|(f, idx)| match idx {
                        Some(_) => format!("{f}*"),
                        None => f.clone(),
                    })
                })
                .collect();
            let near = nearest(&wanted_field, fields.iter().map(String::as_str));
            let mut h = match near {
                Some(n) => format!("no field `{wanted_field}` (did you mean `{n}`?)"),
                None => format!("no field `{wanted_field}`"),
            };
            if matches!(b.field, FieldPattern::Exact(_)) {
                h.push_str(&format!(
                    "; if the robot sends `{wanted_field}` as a JSON string, Telegraf's JSON parser \
                     drops it unless it is listed in json_string_fields"
                ));
            }
            Some(h)
        };
        if let Some(h) = hint {
            msg.push_str("; ");
            msg.push_str(&h);
        }
        msg
    }

    /// `mqtt_consumer,host=tb3,topic=tessla fields expectedSpeed, lidar_0..lidar_359; other ...`
    fn describe_seen(&self) -> String {
        if self.measurements.is_empty() {
            return "no metrics".to_string();
        }
        let parts: Vec<String> = self
            .measurements
            .iter()
            .map(|(name, s)| {
                let mut tag_sets: Vec<String> = s
                    .tag_sets
                    .iter()
                    .map(|t| {
                        if t.is_empty() {
                            name.clone()
                        } else {
                            format!("{name},{t}")
                        }
                    })
                    .collect();
                if s.more_tag_sets {
                    tag_sets.push("...".into());
                }
                let mut fields: Vec<String> = s
                    .fields
                    .iter()
                    .map(|(f, idx)| match idx {
                        Some(max) => format!("{f}0..{f}{max}"),
                        None => f.clone(),
                    })
                    .collect();
                if s.more_fields {
                    fields.push("...".into());
                }
                format!("{} fields {}", tag_sets.join(" | "), fields.join(", "))
            })
            .collect();
        parts.join("; ")
    }
}

/// The warning for an input whose field was present but never converted, with the fix.
fn not_converting(b: &InputBinding, seen: &InputSeen, within: &str) -> String {
    let field = b.prefix();
    let example = seen
        .failed_example
        .as_ref()
        .map_or_else(String::new, |v| format!(" (e.g. {})", show_field(v)));
    let fix = match (&b.ty, seen.failed_example.as_ref()) {
        (Type::Float | Type::Int, Some(FieldValue::Str(_))) => format!(
            "send a number (a numeric string such as \"0.05\" converts), or declare `in {}: Events[String]`",
            b.name
        ),
        (Type::Float | Type::Int, Some(FieldValue::Bool(_))) => {
            format!("declare `in {}: Events[Bool]`", b.name)
        }
        (Type::Int, Some(FieldValue::Float(_))) => {
            format!("declare `in {}: Events[Float]`", b.name)
        }
        (Type::Bool, _) => "send true/false (or the strings \"true\"/\"false\")".to_string(),
        (Type::String, Some(FieldValue::Bool(_))) => {
            format!("declare `in {}: Events[Bool]`", b.name)
        }
        (Type::String, _) => format!(
            "the value is a number: declare `in {}: Events[Float]` (Telegraf's json_string_fields keeps only JSON strings as strings)",
            b.name
        ),
        _ => format!("declare the input with the field's type, or change what {field} carries"),
    };
    format!(
        "input `{}` ({}): field `{field}` came {} times {within} and never converted to {}{example}; fix: {fix}",
        b.name,
        annotation(b),
        seen.present,
        b.ty
    )
}

/// The binding as the spec wrote it.
fn annotation(b: &InputBinding) -> String {
    if b.measurement.is_none()
        && b.tags.is_empty()
        && b.field == FieldPattern::Exact(b.name.clone())
    {
        return format!("no @TelegrafIn: field `{}` of any metric", b.name);
    }
    let field = match &b.field {
        FieldPattern::Exact(f) => f.clone(),
        FieldPattern::Indexed(p) => format!("{p}*"),
    };
    let tags: Vec<String> = b.tags.iter().map(|(k, v)| format!("{k}={v}")).collect();
    format!(
        "@TelegrafIn({:?}, {:?}, {field:?})",
        b.measurement.as_deref().unwrap_or(""),
        tags.join(",")
    )
}

/// An indexed name's entry (`lidar_` -> largest index) raised to at least `max`; a name seen
/// without an index, or not kept (the table full), is left alone.
fn raise(fields: &mut BTreeMap<String, Option<usize>>, name: &str, max: usize) {
    if let Some(Some(old)) = fields.get_mut(name) {
        *old = (*old).max(max);
    }
}

/// `lidar_12` with prefix `lidar_` -> 12.
fn index_of(key: &[u8], prefix: &[u8]) -> Option<usize> {
    key.strip_prefix(prefix).and_then(digits_value)
}

/// `lidar_12` -> (`lidar_`, 12); names without a `_<digits>` tail -> None.
fn split_index(key: &str) -> Option<(&str, usize)> {
    // By hand instead of `rfind('_')` and `str::parse` (a third of the check's cost on 360-beam
    // records): the digits after the last `_` are the key's trailing run of digits.
    let b = key.as_bytes();
    let start = b.len() - b.iter().rev().take_while(|c| c.is_ascii_digit()).count();
    if start == 0 || b[start - 1] != b'_' {
        return None;
    }
    Some((key.get(..start)?, digits_value(&b[start..])?))
}

/// A non-empty run of ASCII digits as `usize` (None when empty, not all digits, or too large),
/// as `str::parse::<usize>` after an all-digits check.
fn digits_value(digits: &[u8]) -> Option<usize> {
    if digits.is_empty() {
        return None;
    }
    let mut v: usize = 0;
    for &d in digits {
        if !d.is_ascii_digit() {
            return None;
        }
        v = v.checked_mul(10)?.checked_add(usize::from(d - b'0'))?;
    }
    Some(v)
}

/// The candidate closest to `wanted`: equal ignoring case and `_`/`-`, else the best
/// Jaro-Winkler similarity of at least 0.8.
fn nearest<'a>(wanted: &str, candidates: impl Iterator<Item = &'a str>) -> Option<&'a str> {
    let norm = |s: &str| {
        s.chars()
            .filter(|c| *c != '_' && *c != '-')
            .flat_map(char::to_lowercase)
            .collect::<String>()
    };
    let w = norm(wanted);
    let mut best: Option<(f64, &str)> = None;
    for c in candidates {
        let score = if norm(c) == w {
            2.0
        } else {
            strsim::jaro_winkler(&w, &norm(c))
        };
        if score >= 0.8 && best.is_none_or(|(s, _)| score > s) {
            best = Some((score, c));
        }
    }
    best.map(|(_, c)| c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_names_ignore_case_and_underscores() {
        let c = ["expectedSpeed", "actual_speed", "lidar_*"];
        assert_eq!(nearest("actualSpeed", c.into_iter()), Some("actual_speed"));
        assert_eq!(
            nearest("expectedSped", c.into_iter()),
            Some("expectedSpeed")
        );
        assert_eq!(nearest("battery", c.into_iter()), None);
    }

    #[test]
    fn an_input_without_annotation_is_described_as_such() {
        let mut b = InputBinding {
            input: 0,
            name: "x".into(),
            ty: Type::Float,
            measurement: None,
            tags: Vec::new(),
            field: FieldPattern::Exact("x".into()),
            length: None,
        };
        assert_eq!(annotation(&b), "no @TelegrafIn: field `x` of any metric");
        b.measurement = Some("m".into());
        b.tags = vec![("topic".into(), "t".into())];
        assert_eq!(annotation(&b), "@TelegrafIn(\"m\", \"topic=t\", \"x\")");
        // What a run without metrics of that shape reports.
        let mut w = WiringCheck::new(std::slice::from_ref(&b));
        let m = lineproto::parse_record(b"n,topic=t y=1 1")
            .unwrap()
            .unwrap();
        w.observe(&m, std::slice::from_ref(&b));
        let msg = w.unmatched(&b, &w.inputs[0], "in 1 records");
        assert!(msg.contains("seen: n,topic=t fields y"), "{msg}");
        assert!(msg.contains("no metric named `m`"), "{msg}");
    }

    /// The tag-set key built in buffers is the one built by formatting, sorting and joining
    /// (string order of `k=v`, which differs from key order: `a-b=..` before `a=..`).
    #[test]
    fn tag_set_keys_as_formatted_and_joined() {
        let records: [&[u8]; 6] = [
            b"m f=1 1",
            b"m,t=1 f=1 1",
            b"m,b=2,a=1 f=1 1",
            b"m,a=x,a-b=y f=1 1",
            b"m,host=h,topic=t,a\\,b=c\\ d f=1 1",
            b"m,z=1,y=2,x=3,a=9,a0=1 f=1 1",
        ];
        let (mut order, mut key) = (Vec::new(), String::new());
        for r in records {
            let m = lineproto::parse_record(r).unwrap().unwrap();
            let mut want: Vec<String> = m.tags.iter().map(|(k, v)| format!("{k}={v}")).collect();
            want.sort();
            tag_set_key(&m, &mut order, &mut key);
            assert_eq!(key, want.join(","), "{r:?}");
        }
        // Seen by the check: two records of one tag set in two orders are one set.
        let b = InputBinding {
            input: 0,
            name: "x".into(),
            ty: Type::Float,
            measurement: Some("none".into()),
            tags: Vec::new(),
            field: FieldPattern::Exact("x".into()),
            length: None,
        };
        let mut w = WiringCheck::new(std::slice::from_ref(&b));
        for r in [
            &b"m,b=2,a=1 f=1 1"[..],
            b"m,a=1,b=2 f=1 2",
            b"m,a-b=1 f=1 3",
        ] {
            let m = lineproto::parse_record(r).unwrap().unwrap();
            w.observe(&m, std::slice::from_ref(&b));
        }
        let sets: Vec<&str> = w.measurements["m"]
            .tag_sets
            .iter()
            .map(String::as_str)
            .collect();
        assert_eq!(sets, ["a-b=1", "a=1,b=2"]);
    }

    #[test]
    fn indexed_names_split() {
        assert_eq!(split_index("lidar_12"), Some(("lidar_", 12)));
        assert_eq!(split_index("lidar_x"), None);
        assert_eq!(split_index("speed"), None);
        assert_eq!(index_of(b"lidar_3", b"lidar_"), Some(3));
        assert_eq!(index_of(b"lidar_+3", b"lidar_"), None);
        assert_eq!(index_of(b"lidar_", b"lidar_"), None);
        assert_eq!(index_of(b"lidar_007", b"lidar_"), Some(7));
    }

    #[test]
    fn a_list_length_from_the_runs_equals_one_from_the_keys() {
        let bind = |prefix: &str| InputBinding {
            input: 0,
            name: "scan".into(),
            ty: Type::List(Box::new(Type::Float)),
            measurement: None,
            tags: Vec::new(),
            field: FieldPattern::Indexed(prefix.into()),
            length: None,
        };
        let records: [&[u8]; 6] = [
            b"m a_3=1,b=2,a_10=1,c_1=0,a_2=1,a_x=1 1",
            b"m c_7=1,a_1=1,c_9=2 1",
            b"m a_=1,a_007=1,a_+4=1,a=2 1",
            b"m b=1 1",
            b"m a_99999999999999999999=1,a_5=1 1",
            b"m x1_2=1,a_1_2=1,a_4=1 1",
        ];
        for prefix in ["a_", "c_", "a", "x1_", "a_1_"] {
            let b = bind(prefix);
            for r in records {
                let m = lineproto::parse_record(r).unwrap().unwrap();
                let mut w = WiringCheck::new(std::slice::from_ref(&b));
                w.observe(&m, std::slice::from_ref(&b));
                let want = m
                    .fields
                    .iter()
                    .filter_map(|(k, _)| index_of(k.as_bytes(), prefix.as_bytes()))
                    .max()
                    .map_or(0, |i| i + 1);
                assert_eq!(w.inputs[0].max_len, want, "{prefix} {r:?}");
                assert_eq!(w.inputs[0].present, u64::from(want > 0), "{prefix} {r:?}");
            }
        }
    }

    #[test]
    fn indexed_names_as_the_standard_parser_reads_them() {
        fn old_split(key: &str) -> Option<(&str, usize)> {
            let cut = key.rfind('_')? + 1;
            let (prefix, digits) = key.split_at(cut);
            if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
                return None;
            }
            Some((prefix, digits.parse().ok()?))
        }
        let keys = [
            "",
            "_",
            "_1",
            "a_",
            "a_1",
            "a1",
            "1",
            "a_1_2",
            "a_1b",
            "a__12",
            "é_3",
            "x_+3",
            "x_007",
            "x_18446744073709551615",
            "x_18446744073709551616",
            "x_99999999999999999999",
            "lidar_359",
            "a_b_c",
            "a_1x_2",
        ];
        for k in keys {
            assert_eq!(split_index(k), old_split(k), "{k}");
        }
    }
}
