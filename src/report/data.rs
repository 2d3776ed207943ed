//! A run as read from line protocol: every record, owned, with its time in seconds since the
//! first timestamp. Records that do not parse are counted and skipped.
//!
//! Two kinds of lines are kept out of the run's clock and counts (counted apart): the status
//! metric `tessla_spec` (stamped with the wall clock, not the robot's time), and records that
//! `run` refused as stamped ahead of the clock (`--max-ahead`) and passed through with their
//! future stamps: a record more than [`AHEAD_S`] ahead of the run's clock so far, after which the
//! run's time comes back (or, at the end of the file, more than a day ahead).

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

/// The status metric's measurement (`crate::spec_feed::status::MEASUREMENT`, named here so the
/// report depends on no other layer).
pub const STATUS: &str = "tessla_spec";

/// `run`'s default `--max-ahead`, in seconds: a record this far beyond the run's clock that the
/// run's time then comes back from was refused as ahead and only passed through.
pub const AHEAD_S: i64 = 10;

/// Every record of a run, in file order.
#[derive(Debug, Clone, Default)]
pub struct Run {
    pub records: Vec<Record>,
    /// The first timestamp (ns since the epoch), if any record has one.
    pub start_ns: Option<i64>,
    /// Records that were not line protocol.
    pub skipped: usize,
    /// Status lines (`tessla_spec`) left out of the run.
    pub status_lines: usize,
    /// Records stamped ahead of the clock (refused by `run`) left out of the run.
    pub ahead: usize,
    /// Measurements that hold telemetry passed through, not the spec's outputs
    /// (`report --telemetry`; [`Run::parse`] sets `mqtt_consumer`).
    pub telemetry: Vec<String>,
}

/// A record as read, before its time is known.
struct Raw {
    measurement: String,
    tags: Vec<(String, String)>,
    fields: Vec<(String, Value)>,
    ns: Option<i64>,
}

impl Run {
    pub fn parse(text: &str) -> Run {
        let mut run = Run {
            telemetry: vec![TELEMETRY.to_string()],
            ..Run::default()
        };
        let mut raws: Vec<Raw> = Vec::new();
        for chunk in split_lines(text) {
            for parsed in parse_lines(chunk.trim_end_matches('\r')) {
                let Ok(line) = parsed else {
                    run.skipped += 1;
                    continue;
                };
                if line.series.measurement.as_str() == STATUS {
                    run.status_lines += 1;
                    continue;
                }
                raws.push(Raw {
                    measurement: line.series.measurement.to_string(),
                    tags: line
                        .series
                        .tag_set
                        .iter()
                        .flatten()
                        .map(|(k, v)| (k.to_string(), v.to_string()))
                        .collect(),
                    fields: line
                        .field_set
                        .iter()
                        .map(|(k, v)| (k.to_string(), convert(v)))
                        .collect(),
                    ns: line.timestamp,
                });
            }
        }
        let ahead = ahead_of_the_clock(&raws);
        let mut previous_t = 0.0;
        for (raw, ahead) in raws.into_iter().zip(ahead) {
            if ahead {
                run.ahead += 1;
                continue;
            }
            let t = match raw.ns {
                Some(ns) => {
                    let start = *run.start_ns.get_or_insert(ns);
                    (i128::from(ns) - i128::from(start)) as f64 / 1e9
                }
                None => previous_t,
            };
            previous_t = t;
            run.records.push(Record {
                measurement: raw.measurement,
                tags: raw.tags,
                fields: raw.fields,
                t,
            });
        }
        run
    }
}

/// Which records were refused as ahead of the clock: stamped more than [`AHEAD_S`] beyond the
/// latest time so far, with a later record back at or before that bound (the run's time came
/// back: the wall clock had not moved on), or, with none later, more than a day beyond it.
fn ahead_of_the_clock(raws: &[Raw]) -> Vec<bool> {
    const S: i64 = 1_000_000_000;
    // The earliest stamp after each record.
    let mut later_min = vec![i64::MAX; raws.len()];
    let mut min = i64::MAX;
    for (i, raw) in raws.iter().enumerate().rev() {
        later_min[i] = min;
        if let Some(ns) = raw.ns {
            min = min.min(ns);
        }
    }
    let mut clock: Option<i64> = None;
    let mut out = Vec::with_capacity(raws.len());
    for (raw, later) in raws.iter().zip(later_min) {
        let ahead = match (raw.ns, clock) {
            (Some(ns), Some(c)) => {
                let bound = c.saturating_add(AHEAD_S * S);
                ns > bound
                    && (later <= bound || (later == i64::MAX && ns > c.saturating_add(86_400 * S)))
            }
            _ => false,
        };
        if !ahead && let Some(ns) = raw.ns {
            clock = Some(clock.map_or(ns, |c| c.max(ns)));
        }
        out.push(ahead);
    }
    out
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

    #[test]
    fn status_lines_and_records_ahead_stay_out_of_the_clock() {
        let s = 1_000_000_000i64;
        let t0 = 1_700_000_000 * s;
        let wall = 1_790_000_000 * s;
        let run = Run::parse(&format!(
            "tessla_spec,host=h,outcome=accepted revision=1i {wall}\n\
             mqtt_consumer battery=12.0 {t0}\n\
             mqtt_consumer battery=11.0 {}\n\
             mqtt_consumer battery=10.0 {}\n\
             mqtt_consumer battery=9.0 {}\n\
             mqtt_consumer battery=8.0 {}\n",
            t0 + s,
            t0 + 3_000 * s,
            t0 + 2 * s,
            t0 + 60 * s,
        ));
        assert_eq!((run.status_lines, run.ahead), (1, 1));
        assert_eq!(run.start_ns, Some(t0));
        let times: Vec<f64> = run.records.iter().map(|r| r.t).collect();
        assert_eq!(times, [0.0, 1.0, 2.0, 60.0], "a real gap (to 60 s) stays");
        // The last record: more than a day ahead is refused, a minute is a gap.
        let end = |gap: i64| Run::parse(&format!("m x=1 {t0}\nm x=2 {}\n", t0 + gap * s)).ahead;
        assert_eq!((end(100_000), end(60)), (1, 0));
    }
}
