//! Turning one step's output events into line-protocol metrics.
//!
//! Owns: the output annotations and their metric shapes:
//! - `@TelegrafOut(name)`: one metric `name value=<v> <ts>` per event (the connector's form);
//! - `@TelegrafField(measurement, field)`: outputs naming the same measurement form ONE metric per
//!   step with one field each (how the robot gets its speed and augmented flag in one message);
//! - no annotation: all such outputs of a step form one metric named by `--measurement`
//!   (default `tessla`), one field per output, named by the output.
//!
//! Values: Int `5i`, Float, Bool, String, Unit as `true`, `Some(x)` as `x`, `None` as no field.
//! A record or tuple (a record of verdicts) is one field per member, named by its path as TeSSLa
//! names object outputs: `check.value=true,check.final=false` (`_1`, `_2` for tuples; nested
//! members `o.a.b`; a connector metric uses the paths alone: `name value=..,final=..`).
//! Values with no line-protocol form (lists, errors, NaN) drop that field with a counted warning.

use lineproto::FieldValue;
#[cfg(test)]
use lineproto::LineWriter;
use tessla_engine::{Program, Value};

#[derive(Debug, Clone, PartialEq)]
pub enum Encoding {
    Connector(String),
    Field { measurement: String, field: String },
    Default(String),
}

/// How each output (by index) is written.
pub fn encodings(program: &Program) -> Vec<Encoding> {
    program
        .outputs
        .iter()
        .map(|o| {
            let arg = |a: &tessla_engine::Annotation, name: &str, pos: usize| -> Option<String> {
                a.args
                    .iter()
                    .find(|(n, _)| n == name)
                    .or_else(|| a.args.get(pos))
                    .and_then(|(_, v)| match v {
                        Value::Str(s) => Some(s.to_string()),
                        _ => None,
                    })
            };
            for a in &o.annotations {
                match a.name.as_str() {
                    "TelegrafOut" => {
                        return Encoding::Connector(
                            arg(a, "name", 0).unwrap_or_else(|| o.name.clone()),
                        );
                    }
                    "TelegrafField" => {
                        return Encoding::Field {
                            measurement: arg(a, "measurement", 0)
                                .unwrap_or_else(|| "tessla".into()),
                            field: arg(a, "field", 1).unwrap_or_else(|| o.name.clone()),
                        };
                    }
                    _ => {}
                }
            }
            Encoding::Default(o.name.clone())
        })
        .collect()
}

/// Why a value was not written.
#[derive(Debug, Clone, PartialEq)]
pub struct Dropped {
    pub output: String,
    pub reason: String,
}

/// Why a value has no line-protocol form (its message is a [`Dropped`] reason).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Unwritable {
    /// An integer outside 64 bits (the value is a `Value::BigInt`).
    #[error("{0} does not fit a line-protocol integer (64 bits)")]
    BigInt(Value),
    /// A NaN or infinite float.
    #[error("{0} is not valid line protocol")]
    Float(f64),
    /// A TeSSLa runtime error carried as the value.
    #[error("runtime error: {0}")]
    Runtime(tessla_engine::RuntimeError),
    /// A list, set, map or function (records and tuples are written member by member).
    #[error("a compound value has no line-protocol form: {0}")]
    Compound(Value),
}

fn field_value(v: &Value) -> Result<Option<FieldValue>, Unwritable> {
    Ok(Some(match v {
        Value::Unit => FieldValue::Bool(true),
        Value::Bool(b) => FieldValue::Bool(*b),
        Value::Int(i) => FieldValue::Int(*i),
        big @ Value::BigInt(_) => return Err(Unwritable::BigInt(big.clone())),
        Value::Float(f) if f.is_finite() => FieldValue::Float(*f),
        Value::Float(f) => return Err(Unwritable::Float(*f)),
        Value::Str(s) => FieldValue::Str(s.to_string()),
        Value::Some(x) => return field_value(x),
        Value::None => return Ok(None),
        Value::Error(e) => return Err(Unwritable::Runtime(e.clone())),
        other => return Err(Unwritable::Compound(other.clone())),
    }))
}

/// A set of encodings prepared for writing, once (a processor prepares each spec version's
/// when it takes the version in): each output's measurement and field key escaped, the metric
/// each goes to, and whether all go to one. Serves only the encodings and default measurement
/// it was built from.
#[derive(Debug, Clone, PartialEq)]
pub struct Prepared {
    encodings: Vec<Encoding>,
    default_measurement: String,
    /// Per encoding: its measurement escaped (`None`: not writable) and `key=` escaped
    /// (`None`: not writable).
    names: Vec<Names>,
    /// Per encoding: the metric its fields go to, as the first encoding index of that metric
    /// (a connector output is its own metric; the others share one per measurement).
    metric: Vec<usize>,
    /// The metric every output goes to, when there is one and its measurement is writable
    /// (the usual case: outputs without annotations).
    one_metric: Option<usize>,
}

impl Prepared {
    pub fn new(encodings: Vec<Encoding>, default_measurement: &str) -> Prepared {
        let names: Vec<Names> = encodings
            .iter()
            .map(|e| prepare(e, default_measurement))
            .collect();
        let metric = metrics(&encodings, default_measurement);
        let one_metric = metric.first().copied().filter(|&g| {
            metric.iter().all(|&m| m == g) && names.get(g).is_some_and(|p| p.0.is_some())
        });
        Prepared {
            encodings,
            default_measurement: default_measurement.to_string(),
            names,
            metric,
            one_metric,
        }
    }

    /// How each output (by index) is written.
    pub fn encodings(&self) -> &[Encoding] {
        &self.encodings
    }

    /// The measurement of outputs without an annotation.
    pub fn default_measurement(&self) -> &str {
        &self.default_measurement
    }

    /// Whether it was prepared from `encodings` and `default_measurement`.
    fn serves(&self, encodings: &[Encoding], default_measurement: &str) -> bool {
        self.default_measurement == default_measurement && self.encodings == encodings
    }
}

/// Buffers reused from step to step (no allocation per step once warm), whatever encodings
/// they write.
#[derive(Debug, Default)]
pub struct Scratch {
    /// The step's metrics in first-appearance order: (its `metric` index, whether values
    /// without a line-protocol form are reported while it is written: the one-metric case).
    groups: Vec<(usize, bool)>,
    /// The path of the record or tuple member being written (`a.b`, `_1`).
    path: String,
    /// A member's field key before escaping (see [`Writer`]).
    name: String,
    /// [`encode_prepared`]'s tags escaped.
    tags: String,
    floats: Floats,
    /// [`encode_step_with`]'s last encodings prepared: used again while the same encodings
    /// come (compared each step), prepared afresh when others do.
    last: Option<Prepared>,
}

/// An encoding's measurement escaped and its field key escaped between `,` and `=` (`,key=`:
/// every field is written after a comma, and a line's first comma made a space when it ends;
/// `None`: not writable).
type Names = (Option<String>, Option<String>);

/// Measurement, field key and whether it is a connector metric, for one encoding.
fn target<'a>(enc: &'a Encoding, default_measurement: &'a str) -> (&'a str, &'a str, bool) {
    match enc {
        Encoding::Connector(n) => (n.as_str(), "value", true),
        Encoding::Field { measurement, field } => (measurement.as_str(), field.as_str(), false),
        Encoding::Default(n) => (default_measurement, n.as_str(), false),
    }
}

fn prepare(enc: &Encoding, default_measurement: &str) -> Names {
    let (measurement, field, _) = target(enc, default_measurement);
    let m = lineproto::measurement_is_writable(measurement).then(|| {
        let mut s = String::new();
        lineproto::write_measurement(&mut s, measurement);
        s
    });
    let k = lineproto::name_is_writable(field).then(|| {
        let mut s = String::from(",");
        lineproto::write_field_key(&mut s, field);
        s.push('=');
        s
    });
    (m, k)
}

/// One output event of a step: the output's index and its value (`(output, value)`, or the
/// processor's `Fired`, which also holds its time).
pub trait StepEvent {
    fn output(&self) -> usize;
    fn value(&self) -> &Value;
}

impl StepEvent for (usize, Value) {
    #[inline]
    fn output(&self) -> usize {
        self.0
    }
    #[inline]
    fn value(&self) -> &Value {
        &self.1
    }
}

/// Encode the events of one step (all at `ts`) into `out`; returns the dropped values.
pub fn encode_step(
    ts: i64,
    events: &[(usize, Value)],
    encodings: &[Encoding],
    default_measurement: &str,
    tags: &[(String, String)],
    out: &mut Vec<u8>,
) -> Vec<Dropped> {
    let mut scratch = Scratch::default();
    encode_step_with(
        &mut scratch,
        ts,
        events,
        encodings,
        default_measurement,
        tags,
        out,
    )
}

/// [`encode_step`] with buffers kept in `scratch` between steps, and the encodings prepared
/// again only when they differ from the last step's (a caller with several sets of encodings
/// prepares each once and calls [`encode_prepared`]).
pub fn encode_step_with<E: StepEvent>(
    scratch: &mut Scratch,
    ts: i64,
    events: &[E],
    encodings: &[Encoding],
    default_measurement: &str,
    tags: &[(String, String)],
    out: &mut Vec<u8>,
) -> Vec<Dropped> {
    let prepared = match scratch.last.take() {
        Some(p) if p.serves(encodings, default_measurement) => p,
        _ => Prepared::new(encodings.to_vec(), default_measurement),
    };
    let dropped = encode_prepared(scratch, &prepared, ts, events, tags, out);
    scratch.last = Some(prepared);
    dropped
}

/// Encode the events of one step (all at `ts`) into `out` by encodings prepared once, with
/// the buffers of `scratch`; returns the dropped values. The line is the one
/// [`lineproto::LineWriter`] writes (a test compares them).
#[inline]
pub fn encode_prepared<E: StepEvent>(
    scratch: &mut Scratch,
    prepared: &Prepared,
    ts: i64,
    events: &[E],
    tags: &[(String, String)],
    out: &mut Vec<u8>,
) -> Vec<Dropped> {
    let mut escaped = std::mem::take(&mut scratch.tags);
    escape_tags(&mut escaped, tags);
    let dropped = encode(scratch, prepared, ts, events, &escaped, out);
    scratch.tags = escaped;
    dropped
}

/// [`encode_prepared`] with the tags escaped once by [`escape_tags`] (a processor keeps each
/// instance's, written again only when its tags change).
#[inline]
pub fn encode_prepared_escaped<E: StepEvent>(
    scratch: &mut Scratch,
    prepared: &Prepared,
    ts: i64,
    events: &[E],
    escaped_tags: &str,
    out: &mut Vec<u8>,
) -> Vec<Dropped> {
    encode(scratch, prepared, ts, events, escaped_tags, out)
}

/// Write into `escaped` what follows the measurement of a verdict line with `tags`: `,k=v`
/// for each writable tag, escaped.
pub fn escape_tags(escaped: &mut String, tags: &[(String, String)]) {
    escaped.clear();
    for (k, v) in tags {
        if lineproto::name_is_writable(k) && lineproto::name_is_writable(v) {
            escaped.push(',');
            lineproto::write_tag_key(escaped, k);
            escaped.push('=');
            lineproto::write_tag_value(escaped, v);
        }
    }
}

/// Per encoding, the first encoding index of the metric its fields go to.
fn metrics(encodings: &[Encoding], default_measurement: &str) -> Vec<usize> {
    encodings
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let (m, _, connector) = target(e, default_measurement);
            if connector {
                return i;
            }
            encodings
                .iter()
                .position(|o| {
                    let (om, _, oc) = target(o, default_measurement);
                    !oc && om == m
                })
                .unwrap_or(i)
        })
        .collect()
}

/// The scalar a value is written as (`Some(x)` as `x`), if it has a line-protocol form.
#[inline]
fn writable_leaf(v: &Value) -> Option<&Value> {
    match v {
        Value::Unit | Value::Bool(_) | Value::Int(_) | Value::Str(_) => Some(v),
        Value::Float(f) if f.is_finite() => Some(v),
        Value::Some(x) => writable_leaf(x),
        _ => None,
    }
}

/// Append a scalar from [`writable_leaf`] in line-protocol form (what [`field_value`] and
/// [`lineproto::write_value`] write, without the intermediate [`FieldValue`]).
#[inline(always)]
fn write_leaf(line: &mut Vec<u8>, floats: &mut Floats, v: &Value) {
    match v {
        Value::Unit | Value::Bool(true) => line.extend_from_slice(b"true"),
        // Apart from `true`: a literal of known length is copied inline, not through memcpy.
        Value::Bool(false) => line.extend_from_slice(b"false"),
        Value::Int(i) => lineproto::write::write_int(line, *i),
        Value::Float(f) => floats.write(line, *f),
        Value::Str(s) => lineproto::write::write_string(line, s),
        _ => {}
    }
}

/// Floats written lately and their text, one slot per value by a hash of its bits: a value that
/// repeats (a constant output like `0.015`, a value written to two metrics of a step) is copied,
/// not formatted again (formatting a Float was the largest item of writing a line).
///
/// A value seen once is only noted (its bits), and its text kept the second time it comes: a
/// value that never repeats (a difference of two readings) costs no copy of its text. A slot
/// that served a copy since the last value went past it keeps its value once more (`keep`), so
/// such passing values do not evict a constant that comes every step.
#[derive(Debug)]
pub struct Floats {
    slots: [Slot; 16],
}

#[derive(Debug)]
struct Slot {
    bits: u64,
    /// Whether `text` is the text of `bits` (else only the bits are noted).
    ready: bool,
    /// Whether a copy was served since a value last went past.
    keep: bool,
    text: Vec<u8>,
}

/// The bits of a NaN: no slot of an unused [`Floats`] matches a finite value.
const NO_FLOAT: u64 = 0x7ff8_0000_0000_0001;

impl Default for Floats {
    fn default() -> Floats {
        Floats {
            slots: std::array::from_fn(|_| Slot {
                bits: NO_FLOAT,
                ready: false,
                keep: false,
                text: Vec::new(),
            }),
        }
    }
}

impl Floats {
    /// Append finite `f` as [`lineproto::write_float`] writes it.
    #[inline(always)]
    fn write(&mut self, line: &mut Vec<u8>, f: f64) {
        let bits = f.to_bits();
        let slot = (bits.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 60) as usize;
        let Some(s) = self.slots.get_mut(slot) else {
            lineproto::write_float(line, f);
            return;
        };
        if s.bits == bits {
            if s.ready {
                s.keep = true;
                line.extend_from_slice(&s.text);
                return;
            }
            // The second time: format and keep the text.
            let start = line.len();
            lineproto::write_float(line, f);
            if let Some(t) = line.get(start..) {
                s.text.clear();
                s.text.extend_from_slice(t);
                s.ready = true;
            }
            return;
        }
        lineproto::write_float(line, f);
        if s.keep {
            s.keep = false;
        } else {
            s.bits = bits;
            s.ready = false;
        }
    }
}

/// Whether `v` is a record or tuple with members: written as one field per member.
#[inline(always)]
fn has_members(v: &Value) -> bool {
    match v {
        Value::Record(fs) => !fs.is_empty(),
        Value::Tuple(xs) => !xs.is_empty(),
        _ => false,
    }
}

/// Calls `f` with each leaf member of `v` (see [`has_members`]) and its path (`a.b`, `_1`),
/// depth first, in field order. `path` is a buffer, empty on entry and on return.
fn each_member<'v>(v: &'v Value, path: &mut String, f: &mut dyn FnMut(&str, &'v Value)) {
    let at = path.len();
    let mut member = |path: &mut String, name: std::fmt::Arguments<'_>, x: &'v Value| {
        use std::fmt::Write as _;
        if at > 0 {
            path.push('.');
        }
        let _ = path.write_fmt(name);
        if has_members(x) {
            each_member(x, path, &mut *f);
        } else {
            f(path, x);
        }
        path.truncate(at);
    };
    match v {
        Value::Record(fs) => {
            for (k, x) in fs.iter() {
                member(path, format_args!("{k}"), x);
            }
        }
        Value::Tuple(xs) => {
            for (i, x) in xs.iter().enumerate() {
                member(path, format_args!("_{}", i + 1), x);
            }
        }
        _ => f(path, v),
    }
}

/// Writing one step: its encodings, the line of the metric being written, the dropped values.
/// A leaf is an output's value, or a member of a record or tuple value (named by its path).
/// The record path works on a [`Writer::reborrow`], so that this one never leaves the encoder
/// and stays in registers.
struct Writer<'a> {
    encodings: &'a [Encoding],
    default_measurement: &'a str,
    /// The output: a line is written straight into it, taken back when it gets no field.
    line: &'a mut Vec<u8>,
    floats: &'a mut Floats,
    /// A member's field key before escaping: the output's field and the member's path.
    name: &'a mut String,
    dropped: &'a mut Vec<Dropped>,
    /// Whether the line has a field yet.
    written: bool,
    /// Leaves without a line-protocol form are reported while the line is written (the
    /// one-metric case; otherwise while the metrics are found).
    report: bool,
}

impl Writer<'_> {
    /// A writer on the same line and buffers; its `written` goes back to this one after use.
    #[inline(always)]
    fn reborrow(&mut self) -> Writer<'_> {
        Writer {
            encodings: self.encodings,
            default_measurement: self.default_measurement,
            line: self.line,
            floats: self.floats,
            name: self.name,
            dropped: self.dropped,
            written: self.written,
            report: self.report,
        }
    }

    /// Leaf `v` of output `idx` opens metric `g` (first appearance order) when it has a
    /// line-protocol form (`leaf`: its [`writable_leaf`]), else it is dropped.
    #[inline(always)]
    fn open(
        &mut self,
        groups: &mut Vec<(usize, bool)>,
        g: usize,
        idx: usize,
        path: &str,
        v: &Value,
        leaf: Option<&Value>,
    ) {
        if leaf.is_none() {
            self.drop_value(idx, path, v);
        } else if !groups.iter().any(|&(m, _)| m == g) {
            groups.push((g, false));
        }
    }

    /// Append leaf `v` of output `idx` (`leaf`: its [`writable_leaf`]) to the line; `key` is the
    /// output's prepared names (the field key escaped, with `=`; `None`: not writable).
    #[inline(always)]
    fn put(
        &mut self,
        idx: usize,
        key: Option<&Names>,
        path: &str,
        v: &Value,
        leaf: Option<&Value>,
    ) {
        match (leaf, key) {
            (Some(v), Some((_, Some(key)))) => {
                if path.is_empty() {
                    self.line.extend_from_slice(key.as_bytes());
                } else {
                    let field = match self.encodings.get(idx) {
                        Some(Encoding::Field { field, .. } | Encoding::Default(field)) => {
                            Some(field)
                        }
                        _ => None,
                    };
                    if !member_key(self.line, self.name, field, path) {
                        return;
                    }
                }
                write_leaf(self.line, self.floats, v);
                self.written = true;
            }
            (None, _) if self.report => self.drop_value(idx, path, v),
            _ => {}
        }
    }

    #[inline(always)]
    fn drop_value(&mut self, idx: usize, path: &str, v: &Value) {
        let enc = self.encodings.get(idx);
        drop_value(self.dropped, enc, self.default_measurement, path, v);
    }
}

/// Append `,`, a member's field key and `=`: the output's field and the member's path (the
/// path alone for a connector, which has no `field`). False, with nothing appended, when the
/// name is not writable. `name` is a buffer.
#[inline(never)]
fn member_key(line: &mut Vec<u8>, name: &mut String, field: Option<&String>, path: &str) -> bool {
    name.clear();
    if let Some(field) = field {
        name.push_str(field);
        name.push('.');
    }
    name.push_str(path);
    if !lineproto::name_is_writable(name) {
        return false;
    }
    line.push(b',');
    lineproto::write_field_key(line, name);
    line.push(b'=');
    true
}

/// Why a leaf (of the output encoded as `enc`) has no line-protocol form, if it has none: the
/// output named by its field (a connector's by its measurement), a member by its path after a dot.
#[inline(never)]
fn drop_value(
    dropped: &mut Vec<Dropped>,
    enc: Option<&Encoding>,
    default_measurement: &str,
    path: &str,
    v: &Value,
) {
    if let (Err(reason), Some(enc)) = (field_value(v), enc) {
        let (measurement, field, connector) = target(enc, default_measurement);
        let output = if connector { measurement } else { field };
        dropped.push(Dropped {
            output: if path.is_empty() {
                output.to_string()
            } else {
                format!("{output}.{path}")
            },
            reason: reason.to_string(),
        });
    }
}

/// [`encode_prepared`]: metrics told apart by index, values written straight into the line.
/// A value is one field; a record or tuple is one field per member (the rare case, off the
/// scalar path).
#[inline]
fn encode<E: StepEvent>(
    scratch: &mut Scratch,
    prepared: &Prepared,
    ts: i64,
    events: &[E],
    tags: &str,
    out: &mut Vec<u8>,
) -> Vec<Dropped> {
    let Scratch {
        groups,
        path,
        name,
        floats,
        tags: _,
        last: _,
    } = scratch;
    let Prepared {
        encodings,
        default_measurement,
        names: prepared,
        metric,
        one_metric,
    } = prepared;
    let mut dropped = Vec::new();
    let mut w = Writer {
        encodings,
        default_measurement,
        line: out,
        floats,
        name,
        dropped: &mut dropped,
        written: false,
        report: false,
    };
    groups.clear();
    if let Some(g) = *one_metric {
        // One metric: dropped values are found (in event order) while it is written.
        groups.push((g, true));
    } else {
        // Metrics in first-appearance order of a written value; dropped values in event order.
        for e in events {
            let idx = e.output();
            let Some(&g) = metric.get(idx) else {
                continue;
            };
            let v = e.value();
            // A scalar is its own leaf; a record or tuple (no line-protocol form itself) is
            // its members.
            match writable_leaf(v) {
                None if has_members(v) => {
                    let (mut m, gs) = (w.reborrow(), &mut *groups);
                    each_member(v, path, &mut |p, x| {
                        m.open(gs, g, idx, p, x, writable_leaf(x));
                    });
                }
                leaf => w.open(groups, g, idx, "", v, leaf),
            }
        }
    }
    for &(g, report) in groups.iter() {
        let Some((Some(measurement), _)) = prepared.get(g) else {
            continue;
        };
        let start = w.line.len();
        w.line.extend_from_slice(measurement.as_bytes());
        w.line.extend_from_slice(tags.as_bytes());
        let fields_at = w.line.len();
        w.written = false;
        w.report = report;
        for e in events {
            let idx = e.output();
            if metric.get(idx) != Some(&g) {
                continue;
            }
            let key = prepared.get(idx);
            let v = e.value();
            match writable_leaf(v) {
                None if has_members(v) => {
                    let mut m = w.reborrow();
                    each_member(v, path, &mut |p, x| m.put(idx, key, p, x, writable_leaf(x)));
                    let written = m.written;
                    w.written = written;
                }
                leaf => w.put(idx, key, "", v, leaf),
            }
        }
        if w.written {
            end_line(w.line, fields_at, ts);
        } else {
            w.line.truncate(start);
        }
    }
    dropped
}

/// End a verdict line that has at least one field (its first field's comma at `fields_at`):
/// that comma made the space before the fields, then the timestamp and the newline.
#[inline]
fn end_line(line: &mut Vec<u8>, fields_at: usize, ts: i64) {
    if let Some(sep) = line.get_mut(fields_at) {
        *sep = b' ';
    }
    line.push(b' ');
    lineproto::write_timestamp(line, ts);
    line.push(b'\n');
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    /// A record of verdicts is one field per member, named by its path; a tuple's members are
    /// `_1`, `_2`; a connector metric uses the paths alone; a member without a line-protocol
    /// form is dropped by its path.
    #[test]
    fn records_and_tuples_are_one_field_per_member() {
        let verdict = Value::Record(Arc::from(vec![
            (Arc::from("final"), Value::Bool(false)),
            (
                Arc::from("inner"),
                Value::Tuple(Arc::from(vec![Value::Int(1), Value::Float(0.5)])),
            ),
            (Arc::from("value"), Value::Bool(true)),
        ]));
        let encodings = vec![
            Encoding::Default("check".into()),
            Encoding::Connector("verdict".into()),
        ];
        let mut out = Vec::new();
        let dropped = encode_step(
            7,
            &[(0, verdict.clone()), (1, verdict)],
            &encodings,
            "tessla",
            &[],
            &mut out,
        );
        assert!(dropped.is_empty(), "{dropped:?}");
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "tessla check.final=false,check.inner._1=1i,check.inner._2=0.5,check.value=true 7\n\
             verdict final=false,inner._1=1i,inner._2=0.5,value=true 7\n"
        );
        let bad = Value::Record(Arc::from(vec![(Arc::from("x"), Value::Float(f64::NAN))]));
        let mut out = Vec::new();
        let dropped = encode_step(1, &[(0, bad)], &encodings, "tessla", &[], &mut out);
        assert!(out.is_empty());
        assert_eq!(dropped.len(), 1);
        assert_eq!(dropped[0].output, "check.x");
    }

    /// The reused-scratch path writes what [`lineproto::LineWriter`] writes, escapes and unwritable names
    /// included, step after step.
    #[test]
    fn encode_step_with_writes_what_line_writer_writes() {
        let encodings = vec![
            Encoding::Default("a b".into()),
            Encoding::Default("c,d=e".into()),
            Encoding::Field {
                measurement: "act ion".into(),
                field: "speed".into(),
            },
            Encoding::Connector("verdict".into()),
            Encoding::Default("\\\\".into()),
            Encoding::Field {
                measurement: "#c".into(),
                field: "x".into(),
            },
            Encoding::Field {
                measurement: "act ion".into(),
                field: "s=\\".into(),
            },
        ];
        let tags = vec![
            ("robot".to_string(), "tb 3,x=1".to_string()),
            ("".to_string(), "v".to_string()),
            ("site".to_string(), "lab".to_string()),
        ];
        let events = vec![
            (0, Value::Float(0.1)),
            (2, Value::Int(-3)),
            (1, Value::Str(Arc::from("q\"u\\o"))),
            (3, Value::Bool(true)),
            (4, Value::Int(1)),
            (5, Value::Int(2)),
            (6, Value::Some(Arc::new(Value::Float(2.5e-9)))),
            (3, Value::None),
            (0, Value::Float(f64::NAN)),
        ];
        let (mut expected, mut expected_members) = (Vec::new(), Vec::new());
        let groups: [(&str, &[(usize, &str)]); 3] = [
            ("tessla", &[(0, "a b"), (1, "c,d=e"), (4, "\\\\")]),
            ("act ion", &[(2, "speed"), (6, "s=\\")]),
            ("verdict", &[(3, "value")]),
        ];
        for (m, fs) in groups {
            for wrapped in [false, true] {
                let mut w = LineWriter::new(m);
                for (k, v) in &tags {
                    w.tag(k, v);
                }
                for (i, f) in fs {
                    let key = match (wrapped, m) {
                        (false, _) => f.to_string(),
                        // An output whose own field cannot be written has no members either.
                        (true, _) if !lineproto::name_is_writable(f) => continue,
                        (true, "verdict") => "v".to_string(),
                        (true, _) => format!("{f}.v"),
                    };
                    if let Some((_, v)) = events.iter().find(|e| e.0 == *i)
                        && let Ok(Some(fv)) = field_value(v)
                    {
                        w.field(&key, &fv);
                    }
                }
                if let (Some(l), _) = w.finish(Some(42)) {
                    let to = if wrapped {
                        &mut expected_members
                    } else {
                        &mut expected
                    };
                    to.extend_from_slice(l.as_bytes());
                }
            }
        }
        let mut scratch = Scratch::default();
        for _ in 0..3 {
            let mut out = Vec::new();
            let d = encode_step_with(
                &mut scratch,
                42,
                &events,
                &encodings,
                "tessla",
                &tags,
                &mut out,
            );
            assert_eq!(
                String::from_utf8_lossy(&out),
                String::from_utf8_lossy(&expected)
            );
            assert_eq!(d.len(), 1, "{d:?}");
            // Record-wrapped, each value is a one-member record: one field `field.v` (a
            // connector's: `v`) with the same value, in the same metrics.
            let wrapped: Vec<(usize, Value)> = events
                .iter()
                .map(|(i, v)| {
                    (
                        *i,
                        Value::Record(Arc::from(vec![(Arc::from("v"), v.clone())])),
                    )
                })
                .collect();
            let mut members = Vec::new();
            let dm = encode_step_with(
                &mut scratch,
                42,
                &wrapped,
                &encodings,
                "tessla",
                &tags,
                &mut members,
            );
            assert_eq!(
                String::from_utf8_lossy(&members),
                String::from_utf8_lossy(&expected_members)
            );
            assert_eq!(dm.len(), 1, "{dm:?}");
            assert_eq!(dm[0].output, format!("{}.v", d[0].output));
        }
    }

    /// Outputs that all go to one metric (no annotations): the line and the dropped values, in
    /// event order, are those of the general path (the metrics found first).
    #[test]
    fn one_metric_steps_match_the_general_path() {
        let encodings: Vec<Encoding> = ["a", "b", "c", "d", "e"]
            .iter()
            .map(|n| Encoding::Default((*n).to_string()))
            .collect();
        let steps = [
            vec![
                (0, Value::Float(f64::NAN)),
                (1, Value::Int(3)),
                (2, Value::None),
                (3, Value::Error(tessla_engine::RuntimeError::DivisionByZero)),
                (4, Value::Float(0.25)),
                (9, Value::Int(1)),
            ],
            vec![(2, Value::Float(f64::INFINITY))],
            vec![(4, Value::Str(Arc::from("x\"y"))), (0, Value::Bool(true))],
        ];
        let mut scratch = Scratch::default();
        let prepared = Prepared::new(encodings, "m");
        let general_path = Prepared {
            one_metric: None,
            ..prepared.clone()
        };
        let mut n_dropped = 0;
        for events in &steps {
            let (mut fast, mut general) = (Vec::new(), Vec::new());
            let d = encode_prepared(&mut scratch, &prepared, 5, events, &[], &mut fast);
            let dg = encode_prepared(&mut scratch, &general_path, 5, events, &[], &mut general);
            assert_eq!(
                String::from_utf8_lossy(&fast),
                String::from_utf8_lossy(&general)
            );
            assert_eq!(d, dg);
            n_dropped += d.len();
        }
        // NaN, the error value and infinity.
        assert_eq!(n_dropped, 3);
        assert!(prepared.one_metric.is_some());
    }

    /// The float cache writes what `write_float` writes, whether a value is new, noted once,
    /// kept, or passing a kept slot; values that share a slot included.
    #[test]
    fn float_cache_writes_what_write_float_writes() {
        let mut floats = Floats::default();
        let mut x = 0.0226f64;
        for i in 0..20_000u32 {
            let constant = [0.015, 0.22, -0.22][(i % 7 % 3) as usize];
            x = (x * 1.000_37 + 1e-5) % 0.3;
            for f in [
                constant,
                x - 0.015,
                x * x,
                constant,
                f64::from(i % 5),
                -0.0,
                1e21,
            ] {
                let (mut ours, mut full) = (b"k=".to_vec(), String::from("k="));
                floats.write(&mut ours, f);
                lineproto::write_float(&mut full, f);
                assert_eq!(ours, full.as_bytes(), "{f:?} at {i}");
            }
        }
    }

    /// One scratch serving two sets of encodings with as many outputs in turn (instances on
    /// two spec versions): each step is written by its own encodings' names.
    #[test]
    fn a_scratch_shared_by_two_sets_of_encodings_writes_each_ones_names() {
        let set = |names: [&str; 2]| -> Vec<Encoding> {
            names
                .iter()
                .map(|n| Encoding::Default((*n).into()))
                .collect()
        };
        let (ab, cd) = (set(["a", "b"]), set(["c", "d"]));
        let (pab, pcd) = (
            Prepared::new(ab.clone(), "t"),
            Prepared::new(cd.clone(), "t"),
        );
        let events = [(0, Value::Int(1)), (1, Value::Int(2))];
        let mut scratch = Scratch::default();
        for _ in 0..2 {
            for (enc, prepared, line) in [
                (&ab, &pab, "t a=1i,b=2i 9\n"),
                (&cd, &pcd, "t c=1i,d=2i 9\n"),
            ] {
                let mut out = Vec::new();
                encode_prepared(&mut scratch, prepared, 9, &events, &[], &mut out);
                assert_eq!(String::from_utf8_lossy(&out), line);
                let mut out = Vec::new();
                encode_step_with(&mut scratch, 9, &events, enc, "t", &[], &mut out);
                assert_eq!(String::from_utf8_lossy(&out), line);
            }
        }
    }
}
