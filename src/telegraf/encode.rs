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

use lineproto::{FieldValue, LineWriter};
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
        Value::Float(f) if f.is_finite() => FieldValue::Float(*f),
        Value::Float(f) => return Err(format!("{f} is not valid line protocol")),
        Value::Str(s) => FieldValue::Str(s.to_string()),
        Value::Some(x) => return field_value(x),
        Value::None => return Ok(None),
        Value::Error(e) => return Err(format!("runtime error {e:?}")),
        other => {
            return Err(format!(
                "a compound value has no line-protocol form: {other:?}"
            ));
        }
    }))
}

/// One metric being built: measurement, whether it is a connector metric, its fields.
type Group<'a> = (&'a str, bool, Vec<(&'a str, FieldValue)>);

/// Encode the events of one step (all at `ts`) into `out`; returns the dropped values.
pub fn encode_step(
    ts: i64,
    events: &[(usize, Value)],
    encodings: &[Encoding],
    default_measurement: &str,
    tags: &[(String, String)],
    out: &mut Vec<u8>,
) -> Vec<Dropped> {
    let mut dropped = Vec::new();
    // Metrics in first-appearance order: (measurement, is a connector metric, fields).
    let mut groups: Vec<Group<'_>> = Vec::new();
    for (idx, v) in events {
        let Some(enc) = encodings.get(*idx) else {
            continue;
        };
        let (measurement, field, connector) = match enc {
            Encoding::Connector(n) => (n.as_str(), "value", true),
            Encoding::Field { measurement, field } => (measurement.as_str(), field.as_str(), false),
            Encoding::Default(n) => (default_measurement, n.as_str(), false),
        };
        match field_value(v) {
            Ok(None) => {}
            Ok(Some(fv)) => match groups
                .iter_mut()
                .find(|(m, c, _)| !connector && !*c && *m == measurement)
            {
                Some(g) => g.2.push((field, fv)),
                None => {
                    // Sized for every event of the step: one allocation per metric.
                    let mut fields = Vec::with_capacity(if connector { 1 } else { events.len() });
                    fields.push((field, fv));
                    groups.push((measurement, connector, fields));
                }
            },
            Err(reason) => dropped.push(Dropped {
                output: if connector { measurement } else { field }.to_string(),
                reason,
            }),
        }
    }
    for (measurement, _, fields) in groups {
        let mut w = LineWriter::new(measurement);
        for (k, v) in tags {
            w.tag(k, v);
        }
        for (f, v) in &fields {
            w.field(f, v);
        }
        if let (Some(line), _) = w.finish(Some(ts)) {
            out.extend_from_slice(line.as_bytes());
        }
    }
    dropped
}
