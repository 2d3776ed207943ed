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

fn field_value(v: &Value) -> Result<Option<FieldValue>, String> {
    Ok(Some(match v {
        Value::Unit => FieldValue::Bool(true),
        Value::Bool(b) => FieldValue::Bool(*b),
        Value::Int(i) => FieldValue::Int(*i),
        Value::BigInt(i) => {
            return Err(format!(
                "{i} does not fit a line-protocol integer (64 bits)"
            ));
        }
        Value::Float(f) if f.is_finite() => FieldValue::Float(*f),
        Value::Float(f) => return Err(format!("{f} is not valid line protocol")),
        Value::Str(s) => FieldValue::Str(s.to_string()),
        Value::Some(x) => return field_value(x),
        Value::None => return Ok(None),
        Value::Error(e) => return Err(format!("runtime error: {e}")),
        other => {
            return Err(format!(
                "a compound value has no line-protocol form: {other}"
            ));
        }
    }))
}

/// Buffers reused from step to step (no allocation per step once warm), and each output's
/// measurement and field key escaped once. A `Scratch` serves one set of encodings and one
/// default measurement: start a new one when they change (a reload).
#[derive(Debug, Default)]
pub struct Scratch {
    /// Per encoding: its measurement escaped (`None`: not writable) and `key=` escaped
    /// (`None`: not writable).
    prepared: Vec<(Option<String>, Option<String>)>,
    /// Metrics in first-appearance order: (the encoding index that opened it, is a connector
    /// metric).
    groups: Vec<(usize, bool)>,
    /// Every written field: (its metric's position in `groups`, its encoding index, its value).
    fields: Vec<(usize, usize, FieldValue)>,
    line: String,
}

/// Measurement, field key and whether it is a connector metric, for one encoding.
fn target<'a>(enc: &'a Encoding, default_measurement: &'a str) -> (&'a str, &'a str, bool) {
    match enc {
        Encoding::Connector(n) => (n.as_str(), "value", true),
        Encoding::Field { measurement, field } => (measurement.as_str(), field.as_str(), false),
        Encoding::Default(n) => (default_measurement, n.as_str(), false),
    }
}

fn prepare(enc: &Encoding, default_measurement: &str) -> (Option<String>, Option<String>) {
    let (measurement, field, _) = target(enc, default_measurement);
    let m = lineproto::measurement_is_writable(measurement).then(|| {
        let mut s = String::new();
        lineproto::write_measurement(&mut s, measurement);
        s
    });
    let k = lineproto::name_is_writable(field).then(|| {
        let mut s = String::new();
        lineproto::write_field_key(&mut s, field);
        s.push('=');
        s
    });
    (m, k)
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

/// [`encode_step`] with buffers and escaped names kept in `scratch` between steps. The line is
/// the one [`lineproto::LineWriter`] writes (a test compares them).
pub fn encode_step_with(
    scratch: &mut Scratch,
    ts: i64,
    events: &[(usize, Value)],
    encodings: &[Encoding],
    default_measurement: &str,
    tags: &[(String, String)],
    out: &mut Vec<u8>,
) -> Vec<Dropped> {
    let mut dropped = Vec::new();
    if scratch.prepared.len() != encodings.len() {
        scratch.prepared = encodings
            .iter()
            .map(|e| prepare(e, default_measurement))
            .collect();
    }
    let Scratch {
        prepared,
        groups,
        fields,
        line,
    } = scratch;
    groups.clear();
    fields.clear();
    for (idx, v) in events {
        let Some(enc) = encodings.get(*idx) else {
            continue;
        };
        let (measurement, field, connector) = target(enc, default_measurement);
        match field_value(v) {
            Ok(None) => {}
            Ok(Some(fv)) => {
                let found = if connector {
                    None
                } else {
                    groups.iter().position(|&(g, c)| {
                        !c && encodings
                            .get(g)
                            .is_some_and(|e| target(e, default_measurement).0 == measurement)
                    })
                };
                let g = found.unwrap_or_else(|| {
                    groups.push((*idx, connector));
                    groups.len() - 1
                });
                fields.push((g, *idx, fv));
            }
            Err(reason) => dropped.push(Dropped {
                output: if connector { measurement } else { field }.to_string(),
                reason,
            }),
        }
    }
    for (g, &(first, _)) in groups.iter().enumerate() {
        let Some((Some(measurement), _)) = prepared.get(first) else {
            continue;
        };
        line.clear();
        line.push_str(measurement);
        for (k, v) in tags {
            if lineproto::name_is_writable(k) && lineproto::name_is_writable(v) {
                line.push(',');
                lineproto::write_tag_key(line, k);
                line.push('=');
                lineproto::write_tag_value(line, v);
            }
        }
        let mut sep = ' ';
        for (_, i, v) in fields.iter().filter(|f| f.0 == g) {
            if let Some((_, Some(key))) = prepared.get(*i) {
                // Values are finite here (field_value refuses the others).
                line.push(sep);
                line.push_str(key);
                if lineproto::write_value(line, v).is_ok() {
                    sep = ',';
                } else {
                    line.truncate(line.len() - key.len() - 1);
                }
            }
        }
        if sep == ',' {
            line.push(' ');
            lineproto::write_timestamp(line, ts);
            line.push('\n');
            out.extend_from_slice(line.as_bytes());
        }
    }
    dropped
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

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
        let mut expected = Vec::new();
        let groups: [(&str, &[(usize, &str)]); 3] = [
            ("tessla", &[(0, "a b"), (1, "c,d=e"), (4, "\\\\")]),
            ("act ion", &[(2, "speed"), (6, "s=\\")]),
            ("verdict", &[(3, "value")]),
        ];
        for (m, fs) in groups {
            let mut w = LineWriter::new(m);
            for (k, v) in &tags {
                w.tag(k, v);
            }
            for (i, f) in fs {
                if let Some((_, v)) = events.iter().find(|e| e.0 == *i)
                    && let Ok(Some(fv)) = field_value(v)
                {
                    w.field(f, &fv);
                }
            }
            if let (Some(l), _) = w.finish(Some(42)) {
                expected.extend_from_slice(l.as_bytes());
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
        }
    }
}
