//! A run as read from line protocol: every record, owned, with its time in seconds since the
//! first timestamp. Records that do not parse are counted and skipped.

use influxdb_line_protocol::{FieldValue as LpValue, parse_lines, split_lines};

/// A field value of a record.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Float(f64),
    Int(i64),
    Bool(bool),
    Str(String),
}

impl Value {
    /// The value as a number: floats and ints, booleans as 0/1, strings that hold a number.
    pub fn as_f64(&self) -> Option<f64> {
        let v = match self {
            Value::Float(v) => *v,
            Value::Int(v) => *v as f64,
            Value::Bool(b) => f64::from(u8::from(*b)),
            Value::Str(s) => s.trim().parse().ok()?,
        };
        v.is_finite().then_some(v)
    }

    /// The value as a truth value: booleans, numbers (non-zero), `"true"`/`"false"`.
    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(b) => Some(*b),
            Value::Float(v) => Some(*v != 0.0),
            Value::Int(v) => Some(*v != 0),
            Value::Str(s) => match s.as_str() {
                "true" => Some(true),
                "false" => Some(false),
                _ => None,
            },
        }
    }

    /// The value as text (strings as they are, others printed).
    pub fn as_text(&self) -> String {
        match self {
            Value::Str(s) => s.clone(),
            Value::Float(v) => v.to_string(),
            Value::Int(v) => v.to_string(),
            Value::Bool(b) => b.to_string(),
        }
    }
}

/// One line-protocol record.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    pub measurement: String,
    pub tags: Vec<(String, String)>,
    pub fields: Vec<(String, Value)>,
    /// Seconds since the run's first timestamp (records without one take the previous time).
    pub t: f64,
}

impl Record {
    pub fn field(&self, name: &str) -> Option<&Value> {
        self.fields.iter().find(|(n, _)| n == name).map(|(_, v)| v)
    }
}

/// The measurement that carries the robot's telemetry by default (Telegraf's MQTT input).
pub const TELEMETRY: &str = "mqtt_consumer";

/// Every record of a run, in file order.
#[derive(Debug, Clone, Default)]
pub struct Run {
    pub records: Vec<Record>,
    /// The first timestamp (ns since the epoch), if any record has one.
    pub start_ns: Option<i64>,
    /// Records that were not line protocol.
    pub skipped: usize,
    /// Measurements that hold telemetry passed through, not the spec's outputs
    /// (`report --telemetry`; [`Run::parse`] sets `mqtt_consumer`).
    pub telemetry: Vec<String>,
}

impl Run {
    pub fn parse(text: &str) -> Run {
        let mut run = Run {
            telemetry: vec![TELEMETRY.to_string()],
            ..Run::default()
        };
        let mut previous_t = 0.0;
        for chunk in split_lines(text) {
            for parsed in parse_lines(chunk.trim_end_matches('\r')) {
                let Ok(line) = parsed else {
                    run.skipped += 1;
                    continue;
                };
                let t = match line.timestamp {
                    Some(ns) => {
                        let start = *run.start_ns.get_or_insert(ns);
                        (i128::from(ns) - i128::from(start)) as f64 / 1e9
                    }
                    None => previous_t,
                };
                previous_t = t;
                let tags = line
                    .series
                    .tag_set
                    .iter()
                    .flatten()
                    .map(|(k, v)| (k.to_string(), v.to_string()))
                    .collect();
                let fields = line
                    .field_set
                    .iter()
                    .map(|(k, v)| (k.to_string(), convert(v)))
                    .collect();
                run.records.push(Record {
                    measurement: line.series.measurement.to_string(),
                    tags,
                    fields,
                    t,
                });
            }
        }
        run
    }
}

fn convert(value: &LpValue<'_>) -> Value {
    match value {
        LpValue::I64(v) => Value::Int(*v),
        LpValue::U64(v) => Value::Int(i64::try_from(*v).unwrap_or(i64::MAX)),
        LpValue::F64(v) => Value::Float(*v),
        LpValue::String(s) => Value::Str(s.to_string()),
        LpValue::Boolean(b) => Value::Bool(*b),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_are_relative_to_the_first_timestamp() {
        let run = Run::parse(
            "mqtt_consumer,topic=tessla expectedSpeed=0.1,actualSpeed=\"0.05\" 1000000000\n\
             bad line\n\
             action speed=0.1,p1_status=\"ok\",augmented=true 1500000000\n",
        );
        assert_eq!(run.skipped, 1);
        assert_eq!(run.records.len(), 2);
        assert_eq!(run.records[0].t, 0.0);
        assert_eq!(run.records[1].t, 0.5);
        assert_eq!(run.records[0].tags, vec![("topic".into(), "tessla".into())]);
        assert_eq!(
            run.records[0].field("actualSpeed").and_then(Value::as_f64),
            Some(0.05)
        );
        assert_eq!(
            run.records[1].field("augmented").and_then(Value::as_bool),
            Some(true)
        );
        assert_eq!(
            run.records[1].field("p1_status").map(Value::as_text),
            Some("ok".into())
        );
    }
}
