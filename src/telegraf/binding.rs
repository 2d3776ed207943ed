//! Binding spec inputs to metric fields, and converting field values to stream values.
//!
//! Owns: reading `@TelegrafIn(measurement, tags, field)` from the program's inputs (an input
//! without it binds to the field of the same name in any metric), field patterns ending in `_*`
//! that gather `name_0 .. name_N` into one `List[Float]` (a missing index becomes NaN), the
//! list's known length (`@TelegrafListLength(n)`: a record up to a quarter short is filled up
//! with NaN, a longer or much shorter one is warned about and kept as it came), the record's own
//! time (`@TelegrafTime`: an `Events[Int]` input that gets the timestamp of the record that made
//! the step, even when a late record is stepped after the monitor's clock), and the lossless
//! conversions from line-protocol values to [`Value`]s of the input's type.

use lineproto::{FieldValue, Metric, Prefix, list_index};
use std::cell::Cell;
use std::sync::Arc;
use tessla_engine::{Program, Type, Value};

#[derive(Debug, Clone, PartialEq)]
pub enum FieldPattern {
    Exact(String),
    /// `ranges_*`: the prefix `ranges_`.
    Indexed(String),
}

/// Where one input's events come from.
#[derive(Debug, Clone)]
pub struct InputBinding {
    pub input: usize,
    pub name: String,
    pub ty: Type,
    pub measurement: Option<String>,
    pub tags: Vec<(String, String)>,
    pub field: FieldPattern,
    /// `@TelegrafListLength(n)` on an indexed pattern: the list's known length.
    pub length: Option<usize>,
}

/// An input annotation this program cannot be run with: the input and what is wrong.
#[derive(Debug, Clone, thiserror::Error)]
#[error("input `{input}`: {why}")]
pub struct BindingError {
    /// The input's name.
    pub input: String,
    /// What is wrong with its annotations.
    pub why: BadAnnotation,
}

/// What is wrong with an input's Telegraf annotations.
#[derive(Debug, Clone, thiserror::Error)]
pub enum BadAnnotation {
    /// `@TelegrafTime` on an input that is not `Events[Int]` (its type given).
    #[error(
        "@TelegrafTime gives the record's timestamp in ns, so the input must be Events[Int], found Events[{0}]"
    )]
    TimeNotInt(Type),
    /// `@TelegrafTime` and `@TelegrafIn` together.
    #[error(
        "@TelegrafTime and @TelegrafIn on one input; keep one (@TelegrafTime: the record's time, @TelegrafIn: a field)"
    )]
    TimeAndIn,
    /// `@TelegrafIn`'s tags do not parse.
    #[error("@TelegrafIn tags `{given}`: {error}")]
    Tags { given: String, error: TagError },
    /// A `_*` pattern on an input that is not `Events[List[Float]]` (its type given).
    #[error("a `_*` field pattern needs type Events[List[Float]], found Events[{0}]")]
    IndexedType(Type),
    /// `@TelegrafListLength` without a `_*` pattern.
    #[error("@TelegrafListLength needs a `_*` field pattern in its @TelegrafIn")]
    LengthWithoutList,
    /// `@TelegrafListLength` of something other than a whole number in range (what was found).
    #[error(
        "@TelegrafListLength needs a whole number from 1 to {max}, found {0}",
        max = MAX_LIST_LENGTH
    )]
    Length(String),
}

/// A tag list item that is not `key=value`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("`{0}` is not key=value")]
pub struct TagError(pub String);

/// Why a field value could not become an event.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvertError {
    pub input: String,
    pub reason: String,
}

fn str_arg<'a>(args: &'a [(String, Value)], name: &str, pos: usize) -> Option<&'a str> {
    args.iter()
        .find(|(n, _)| n == name)
        .or_else(|| args.get(pos))
        .and_then(|(_, v)| match v {
            Value::Str(s) => Some(&**s),
            _ => None,
        })
}

/// An input that carries the record's own time: `@TelegrafTime` on an `Events[Int]` input. At
/// each step a record's fields make, it gets that record's timestamp (ns; Telegraf's metric
/// time), which differs from the step's time when the record was late and stepped after the
/// monitor's clock (`--late shift`): what was measured when, not when it was evaluated.
#[derive(Debug, Clone, PartialEq)]
pub struct TimeBinding {
    pub input: usize,
    pub name: String,
}

/// The inputs of `program` marked `@TelegrafTime`, or a message naming one that is not an
/// `Events[Int]`.
pub fn time_bindings(program: &Program) -> Result<Vec<TimeBinding>, BindingError> {
    let mut out = Vec::new();
    for (i, info) in program.inputs.iter().enumerate() {
        if !is_time_input(info) {
            continue;
        }
        let bad = |why| BindingError {
            input: info.name.clone(),
            why,
        };
        if info.ty != Type::Int {
            return Err(bad(BadAnnotation::TimeNotInt(info.ty.clone())));
        }
        if info.annotations.iter().any(|a| a.name == "TelegrafIn") {
            return Err(bad(BadAnnotation::TimeAndIn));
        }
        out.push(TimeBinding {
            input: i,
            name: info.name.clone(),
        });
    }
    Ok(out)
}

fn is_time_input(info: &tessla_engine::InputInfo) -> bool {
    info.annotations.iter().any(|a| a.name == "TelegrafTime")
}

/// The bindings of every input of `program` that reads a field (every input but those marked
/// `@TelegrafTime`: [`time_bindings`]), or a message naming a bad annotation.
pub fn bindings(program: &Program) -> Result<Vec<InputBinding>, BindingError> {
    let mut out = Vec::new();
    for (i, info) in program.inputs.iter().enumerate() {
        if is_time_input(info) {
            continue;
        }
        let bad = |why| BindingError {
            input: info.name.clone(),
            why,
        };
        let ann = info.annotations.iter().find(|a| a.name == "TelegrafIn");
        let (measurement, tags, field) = match ann {
            None => (None, Vec::new(), FieldPattern::Exact(info.name.clone())),
            Some(a) => {
                let m = str_arg(&a.args, "measurement", 0).unwrap_or("");
                let t = str_arg(&a.args, "tags", 1).unwrap_or("");
                let f = str_arg(&a.args, "field", 2).unwrap_or(&info.name);
                let tags = parse_tags(t).map_err(|error| {
                    bad(BadAnnotation::Tags {
                        given: t.to_string(),
                        error,
                    })
                })?;
                let field = match f.strip_suffix('*') {
                    Some(prefix) => FieldPattern::Indexed(prefix.to_string()),
                    None => FieldPattern::Exact(if f.is_empty() {
                        info.name.clone()
                    } else {
                        f.to_string()
                    }),
                };
                let measurement = (!m.is_empty()).then(|| m.to_string());
                (measurement, tags, field)
            }
        };
        if matches!(field, FieldPattern::Indexed(_)) && info.ty != Type::List(Box::new(Type::Float))
        {
            return Err(bad(BadAnnotation::IndexedType(info.ty.clone())));
        }
        let length = match info
            .annotations
            .iter()
            .find(|a| a.name == "TelegrafListLength")
        {
            None => None,
            Some(a) => Some(list_length(&a.args, &field).map_err(bad)?),
        };
        out.push(InputBinding {
            input: i,
            name: info.name.clone(),
            ty: info.ty.clone(),
            measurement,
            tags,
            field,
            length,
        });
    }
    Ok(out)
}

/// The length of `@TelegrafListLength(length)`: a whole number 1..=1000000 on an input with a
/// `_*` pattern.
fn list_length(args: &[(String, Value)], field: &FieldPattern) -> Result<usize, BadAnnotation> {
    if !matches!(field, FieldPattern::Indexed(_)) {
        return Err(BadAnnotation::LengthWithoutList);
    }
    let n = args
        .iter()
        .find(|(n, _)| n == "length")
        .or_else(|| args.first())
        .map(|(_, v)| v);
    match n {
        Some(Value::Int(n)) if (1..=MAX_LIST_LENGTH as i64).contains(n) => Ok(*n as usize),
        other => Err(BadAnnotation::Length(
            other.map_or_else(|| "nothing".to_string(), ToString::to_string),
        )),
    }
}

/// Largest list an indexed pattern builds: an absurd index must not allocate gigabytes.
const MAX_LIST_LENGTH: usize = MAX_INDEX;

/// `"k=v,k2=v2"` (may be empty).
pub fn parse_tags(s: &str) -> Result<Vec<(String, String)>, TagError> {
    s.split(',')
        .filter(|p| !p.trim().is_empty())
        .map(|p| {
            p.split_once('=')
                .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
                .ok_or_else(|| TagError(p.to_string()))
        })
        .collect()
}

impl InputBinding {
    /// Whether the metric's measurement and tags select this input.
    pub fn matches(&self, m: &Metric) -> bool {
        self.measurement
            .as_ref()
            .is_none_or(|x| *x == m.measurement)
            && self.tags.iter().all(|(k, v)| m.tag(k) == Some(v.as_str()))
    }

    /// The event this input gets from the metric: `None` when the metric has no such field.
    /// (The usual exact field inline; a list out of line.)
    #[inline]
    pub fn extract(&self, m: &Metric) -> Option<Result<Value, ConvertError>> {
        match &self.field {
            FieldPattern::Exact(f) => m.field(f).map(|v| self.convert(v)),
            FieldPattern::Indexed(prefix) => self.extract_list(prefix, m),
        }
    }

    /// [`InputBinding::extract`] of an indexed pattern: the list of the fields `prefix<i>`.
    #[inline(never)]
    fn extract_list(&self, prefix: &str, m: &Metric) -> Option<Result<Value, ConvertError>> {
        let mut list = spare_list();
        let fill = |l: &mut Vec<Value>| {
            if m.list.holds(prefix) {
                copy_captured(m.list.values(), l)
            } else {
                gather(prefix, &m.fields, l)
            }
        };
        let out = match Arc::get_mut(&mut list).map(|l| (fill(l), l)) {
            Some((None, _)) => None,
            Some((Some(Ok(())), l)) => {
                self.to_length(l);
                Some(Ok(Value::List(list.clone())))
            }
            Some((Some(Err(max)), _)) => Some(Err(ConvertError {
                input: self.name.clone(),
                reason: format!("index {max} in `{prefix}*` is beyond {MAX_INDEX}"),
            })),
            // Not reachable: `spare_list` gives a list nothing else holds.
            None => Some(Err(ConvertError {
                input: self.name.clone(),
                reason: "internal: the list to fill is shared".to_string(),
            })),
        };
        // An absurdly long scan (up to MAX_INDEX beams) is not kept: the spare would hold
        // its memory for the rest of the run.
        if list.capacity() <= SPARE_MAX {
            SPARE_LIST.set(Some(list));
        }
        out
    }

    /// `list` at the known length: filled up with NaN when a few elements are missing
    /// (Telegraf's JSON parser drops a trailing `null`, so a scan's last beams can vanish: up to a
    /// quarter of the length is filled), kept as it came with a warning when longer or much
    /// shorter (then the length looks wrong, e.g. another lidar, and the list's own length places
    /// the beams).
    fn to_length(&self, list: &mut Vec<Value>) {
        let Some(n) = self.length else {
            return;
        };
        let len = list.len();
        if len < n && len.saturating_mul(4) >= n.saturating_mul(3) {
            list.resize_with(n, || Value::Float(f64::NAN));
        } else if len != n {
            crate::log::warn_limited("list length", || {
                let than = if len > n { "more" } else { "far fewer" };
                format!(
                    "input `{}`: a record has {len} elements in `{}*`, {than} than \
                     @TelegrafListLength({n}); the list is used as it came; if every scan has \
                     {len} beams, set that length (bundled robot specs: --set lidar_beams={len})",
                    self.name,
                    self.prefix(),
                )
            });
        }
    }

    /// The prefix of an indexed pattern (`lidar_`), or the exact field name.
    pub fn prefix(&self) -> &str {
        match &self.field {
            FieldPattern::Exact(f) | FieldPattern::Indexed(f) => f,
        }
    }

    /// Convert where no information is lost.
    /// (Inline, with the message of a value that does not convert written out of line.)
    #[inline]
    pub fn convert(&self, v: &FieldValue) -> Result<Value, ConvertError> {
        let r = match (&self.ty, v) {
            (Type::Unit, _) => Some(Value::Unit),
            (Type::Float, FieldValue::Float(f)) => Some(Value::Float(*f)),
            (Type::Float, FieldValue::Int(i)) => Some(Value::Float(*i as f64)),
            (Type::Float, FieldValue::UInt(u)) => Some(Value::Float(*u as f64)),
            (Type::Float, FieldValue::Str(s)) => float_of_str(s).map(Value::Float),
            (Type::Int, FieldValue::Int(i)) => Some(Value::Int(*i)),
            (Type::Int, FieldValue::UInt(u)) => i64::try_from(*u).ok().map(Value::Int),
            (Type::Int, FieldValue::Float(f)) => whole(*f).map(Value::Int),
            (Type::Int, FieldValue::Str(s)) => {
                let t = s.trim();
                t.parse::<i64>()
                    .ok()
                    .or_else(|| t.parse::<f64>().ok().and_then(whole))
                    .map(Value::Int)
            }
            (Type::Bool, FieldValue::Bool(b)) => Some(Value::Bool(*b)),
            (Type::Bool, FieldValue::Str(s)) => match s.as_str() {
                "true" => Some(Value::Bool(true)),
                "false" => Some(Value::Bool(false)),
                _ => None,
            },
            (Type::String, FieldValue::Str(s)) => Some(Value::Str(s.as_str().into())),
            _ => None,
        };
        match r {
            Some(v) => Ok(v),
            None => Err(self.not_converted(v)),
        }
    }

    /// Why `v` did not convert to this input's type.
    #[cold]
    #[inline(never)]
    fn not_converted(&self, v: &FieldValue) -> ConvertError {
        ConvertError {
            input: self.name.clone(),
            reason: format!(
                "{} does not convert to {} without loss",
                show_field(v),
                self.ty
            ),
        }
    }
}

/// A float read from a string field (`"0.0226"`; spaces around it allowed). The usual short
/// decimal is read in one pass ([`lineproto::short_decimal`], the same value); anything else
/// is trimmed and parsed.
#[inline(never)]
fn float_of_str(s: &str) -> Option<f64> {
    lineproto::short_decimal(s).or_else(|| s.trim().parse::<f64>().ok())
}

/// The value of an indexed field as a list element.
fn beam(v: &FieldValue) -> f64 {
    match v {
        FieldValue::Float(f) => *f,
        FieldValue::Int(i) => *i as f64,
        FieldValue::UInt(u) => *u as f64,
        FieldValue::Str(s) => s.trim().parse().unwrap_or(f64::NAN),
        FieldValue::Bool(_) => f64::NAN,
    }
}

/// Largest index an indexed pattern accepts: an absurd index must not allocate gigabytes.
const MAX_INDEX: usize = 1_000_000;

/// Longest list kept as a thread's spare (a 360-beam scan is far below; an absurd index is not).
const SPARE_MAX: usize = 4096;

thread_local! {
    /// The list value of the last scan gathered on this thread, kept to be filled again: once the
    /// engine has dropped its event (at the end of its step, unless the spec keeps the scan), the
    /// list is this thread's alone again and the next scan is written over it, with no
    /// allocation and no drop of its 360 elements per record.
    static SPARE_LIST: Cell<Option<Arc<Vec<Value>>>> = const { Cell::new(None) };
}

/// A list value no one else holds: the spare one when it is free again, else a new one.
fn spare_list() -> Arc<Vec<Value>> {
    if let Some(mut l) = SPARE_LIST.take()
        && Arc::get_mut(&mut l).is_some()
    {
        return l;
    }
    Arc::new(Vec::new())
}

/// The list of an indexed pattern in one pass over the fields, in whatever order they come
/// (Telegraf writes a metric's fields in random order), written over `beams` (a list of an
/// earlier scan, reused): `prefixN` sets element N (a later field overwrites), missing indices
/// are NaN. `None` when no field matches; `Err(largest index)` when an index is beyond
/// [`MAX_INDEX`]; `beams` holds garbage then.
fn gather(
    prefix: &str,
    fields: &[(String, FieldValue)],
    beams: &mut Vec<Value>,
) -> Option<Result<(), usize>> {
    // Every element the earlier scan left becomes a missing beam (a float written in place).
    for b in beams.iter_mut() {
        match b {
            Value::Float(f) => *f = f64::NAN,
            other => *other = Value::Float(f64::NAN),
        }
    }
    let p = Prefix::new(prefix.as_bytes());
    let mut len = 0;
    for (k, v) in fields {
        let Some(idx) = p.rest(k.as_bytes()).and_then(list_index) else {
            continue;
        };
        if idx >= MAX_INDEX {
            let max = fields
                .iter()
                .filter_map(|(k, _)| k.strip_prefix(prefix)?.parse::<usize>().ok())
                .max()
                .unwrap_or(idx);
            return Some(Err(max));
        }
        if idx >= beams.len() {
            // Sized for every field: one allocation for a whole scan.
            beams.reserve(fields.len().max(idx + 1).saturating_sub(beams.len()));
            beams.resize_with(idx + 1, || Value::Float(f64::NAN));
        }
        // A float (every beam Telegraf writes) tested alone: `beam`'s match compiles to a jump
        // table, a dozen instructions per beam.
        let x = if let FieldValue::Float(f) = v {
            *f
        } else {
            beam(v)
        };
        match beams.get_mut(idx) {
            // The float written into the placeholder: nothing to drop.
            Some(Value::Float(slot)) => *slot = x,
            Some(other) => *other = Value::Float(x),
            None => {}
        }
        len = len.max(idx + 1);
    }
    // The earlier scan's elements past this one's end (a longer scan came before).
    beams.truncate(len);
    (len > 0).then_some(Ok(()))
}

/// [`gather`] for a record whose elements the parser read into an array
/// ([`lineproto::ListCapture`]: every element a Float, indices canonical and below its limit,
/// missing ones NaN), written over `beams` the same way.
fn copy_captured(values: &[f64], beams: &mut Vec<Value>) -> Option<Result<(), usize>> {
    if values.is_empty() {
        return None;
    }
    let common = beams.len().min(values.len());
    for (b, &x) in beams.iter_mut().zip(values) {
        match b {
            Value::Float(f) => *f = x,
            other => *other = Value::Float(x),
        }
    }
    beams.truncate(values.len());
    if let Some(more) = values.get(common..) {
        beams.extend(more.iter().map(|&x| Value::Float(x)));
    }
    Some(Ok(()))
}

fn whole(f: f64) -> Option<i64> {
    (f.fract() == 0.0 && f.abs() < 9.2e18).then_some(f as i64)
}

/// Longest string value shown whole in a message.
const SHOW_MAX: usize = 64;

/// A field value as line protocol writes it; a string longer than 64 bytes is cut, with its size
/// (a warning about a 1 MB string stays one readable line).
pub fn show_field(v: &FieldValue) -> String {
    match v {
        FieldValue::Str(s) if s.len() > SHOW_MAX => {
            let head = crate::log::cut(s, SHOW_MAX);
            let head = head.split('…').next().unwrap_or_default();
            format!("{head:?}… (a string of {} bytes)", s.len())
        }
        FieldValue::Str(s) => format!("{s:?}"),
        FieldValue::Float(f) => f.to_string(),
        FieldValue::Int(i) => format!("{i}i"),
        FieldValue::UInt(u) => format!("{u}u"),
        FieldValue::Bool(b) => b.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b(ty: Type, field: FieldPattern) -> InputBinding {
        InputBinding {
            input: 0,
            name: "x".into(),
            ty,
            measurement: Some("m".into()),
            tags: vec![("topic".into(), "tessla".into())],
            field,
            length: None,
        }
    }

    fn metric(line: &str) -> Metric {
        lineproto::parse_record(line.as_bytes()).unwrap().unwrap()
    }

    #[test]
    fn conversions_are_lossless() {
        let f = b(Type::Float, FieldPattern::Exact("x".into()));
        assert_eq!(
            f.convert(&FieldValue::Str("0.5".into())),
            Ok(Value::Float(0.5))
        );
        assert_eq!(f.convert(&FieldValue::Int(3)), Ok(Value::Float(3.0)));
        assert!(f.convert(&FieldValue::Bool(true)).is_err());
        let i = b(Type::Int, FieldPattern::Exact("x".into()));
        assert_eq!(i.convert(&FieldValue::Float(4.0)), Ok(Value::Int(4)));
        assert!(i.convert(&FieldValue::Float(4.5)).is_err());
        assert!(i.convert(&FieldValue::UInt(u64::MAX)).is_err());
        let bo = b(Type::Bool, FieldPattern::Exact("x".into()));
        assert_eq!(
            bo.convert(&FieldValue::Str("true".into())),
            Ok(Value::Bool(true))
        );
        let u = b(Type::Unit, FieldPattern::Exact("x".into()));
        assert_eq!(u.convert(&FieldValue::Str("any".into())), Ok(Value::Unit));
    }

    #[test]
    fn matching_by_measurement_and_tag_subset() {
        let x = b(Type::Float, FieldPattern::Exact("x".into()));
        assert!(x.matches(&metric("m,host=h,topic=tessla x=1 1")));
        assert!(!x.matches(&metric("m,topic=other x=1 1")));
        assert!(!x.matches(&metric("n,topic=tessla x=1 1")));
    }

    #[test]
    fn indexed_fields_gather_into_a_list_with_nan_gaps() {
        let l = b(
            Type::List(Box::new(Type::Float)),
            FieldPattern::Indexed("lidar_".into()),
        );
        let v = l
            .extract(&metric("m,topic=tessla lidar_2=3,lidar_0=1,other=5 1"))
            .unwrap()
            .unwrap();
        let Value::List(items) = v else { panic!() };
        assert_eq!(items.len(), 3);
        assert_eq!(items[0], Value::Float(1.0));
        assert!(matches!(items[1], Value::Float(f) if f.is_nan()));
        assert_eq!(items[2], Value::Float(3.0));
        assert!(l.extract(&metric("m,topic=tessla other=5 1")).is_none());
        // In order (the one-pass path) and out of order give the same lists.
        let a = l.extract(&metric("m lidar_0=1,x=2,lidar_1=2i,lidar_2=\"3\" 1"));
        let b = l.extract(&metric("m lidar_2=\"3\",lidar_1=2i,x=2,lidar_0=1 1"));
        assert_eq!(a, b);
        assert_eq!(
            a,
            Some(Ok(Value::List(Arc::new(vec![
                Value::Float(1.0),
                Value::Float(2.0),
                Value::Float(3.0)
            ]))))
        );
        // `lidar_+1` and `lidar_01` parse as indices on the general path: same result.
        let c = l.extract(&metric("m lidar_0=1,lidar_+1=2 1"));
        assert_eq!(
            c,
            Some(Ok(Value::List(Arc::new(vec![
                Value::Float(1.0),
                Value::Float(2.0)
            ]))))
        );
    }

    #[test]
    fn a_reused_list_holds_exactly_the_new_scan() {
        let l = b(
            Type::List(Box::new(Type::Float)),
            FieldPattern::Indexed("lidar_".into()),
        );
        let lines = [
            "m lidar_0=1,lidar_1=2,lidar_2=3,lidar_3=4 1",
            "m lidar_1=5 1",
            "m lidar_2=\"x\",lidar_0=7i 1",
            "m other=1 1",
            "m lidar_5=1,lidar_0=2 1",
        ];
        let fresh: Vec<_> = lines
            .iter()
            .map(|line| {
                // Each held while the next is gathered: never the same list.
                l.extract(&metric(line))
            })
            .collect();
        for (line, want) in lines.iter().zip(&fresh) {
            // Each dropped before the next: the same list filled again.
            let got = l.extract(&metric(line));
            assert_eq!(format!("{got:?}"), format!("{want:?}"), "{line}");
        }
    }

    #[test]
    fn a_known_length_fills_missing_trailing_beams() {
        let mut l = b(
            Type::List(Box::new(Type::Float)),
            FieldPattern::Indexed("lidar_".into()),
        );
        l.length = Some(4);
        for line in [
            "m lidar_0=1,lidar_1=2,lidar_2=3 1",
            "m lidar_1=2,lidar_2=3,lidar_0=1 1",
        ] {
            let Some(Ok(Value::List(items))) = l.extract(&metric(line)) else {
                panic!("no list from {line}")
            };
            assert_eq!(items.len(), 4, "{line}");
            assert_eq!(items[1], Value::Float(2.0));
            assert!(matches!(items[3], Value::Float(f) if f.is_nan()));
        }
        // Much shorter (another lidar?): kept as it came.
        let Some(Ok(Value::List(items))) = l.extract(&metric("m lidar_0=1,lidar_1=2 1")) else {
            panic!()
        };
        assert_eq!(items.len(), 2);
        l.length = Some(2);
        let Some(Ok(Value::List(items))) = l.extract(&metric("m lidar_0=1 1")) else {
            panic!()
        };
        assert_eq!(items.len(), 1, "half missing is not filled");
        l.length = Some(4);
        // Longer than the length: kept as it came.
        let Some(Ok(Value::List(items))) = l.extract(&metric(
            "m lidar_0=1,lidar_1=2,lidar_2=3,lidar_3=4,lidar_4=5 1",
        )) else {
            panic!()
        };
        assert_eq!(items.len(), 5);
    }

    #[test]
    fn tag_lists_parse() {
        assert_eq!(parse_tags("").unwrap(), vec![]);
        assert_eq!(parse_tags("a=1,b=2").unwrap().len(), 2);
        assert_eq!(parse_tags("x=1,a").unwrap_err(), TagError("a".into()));
        assert_eq!(
            parse_tags("a").unwrap_err().to_string(),
            "`a` is not key=value"
        );
    }
}
