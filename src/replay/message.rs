//! The robot's JSON message built from a recorded [`Sample`].
//!
//! The inverse of what Telegraf's `mqtt_consumer` JSON parser does (influxdata/telegraf,
//! `plugins/parsers/json/json_flattener.go`: an array `lidar` becomes fields `lidar_0`, `lidar_1`,
//! ..., a `null` is skipped): fields `lidar_<i>` are gathered into one array `lidar` (a missing
//! beam or a NaN becomes `null`, which the parser skips, so the beam arrives missing as it was
//! recorded); every other field keeps its name. Numbers stay numbers unless the field is listed as
//! a string field (the paper's robot sends `actualSpeed` as a string). Non-finite numbers become
//! `null`.

use super::{FieldValue, Sample, lidar_index};
use serde_json::{Map, Number, Value};

/// Choices that shape the message.
#[derive(Debug, Clone, Default)]
pub struct MessageOptions {
    /// Fields published as JSON strings (e.g. `actualSpeed`).
    pub string_fields: Vec<String>,
    /// Add the recorded timestamp (integer ns) under this key, for Telegraf's
    /// `json_time_key` with `json_time_format = "unix_ns"`.
    pub time_key: Option<String>,
}

/// The JSON object for one sample.
pub fn to_json(sample: &Sample, options: &MessageOptions) -> Value {
    let mut object = Map::new();
    let mut lidar: Vec<Value> = Vec::new();
    for (name, value) in &sample.fields {
        if let Some(index) = lidar_index(name) {
            if index >= lidar.len() {
                lidar.resize(index + 1, Value::Null);
            }
            if let Some(slot) = lidar.get_mut(index) {
                *slot = number_or_null(value);
            }
            continue;
        }
        let json = if options.string_fields.iter().any(|s| s == name) {
            Value::String(as_text(value))
        } else {
            match value {
                FieldValue::Str(s) => Value::String(s.clone()),
                FieldValue::Bool(b) => Value::Bool(*b),
                other => number_or_null(other),
            }
        };
        object.insert(name.clone(), json);
    }
    if !lidar.is_empty() {
        object.insert("lidar".into(), Value::Array(lidar));
    }
    if let (Some(key), Some(ns)) = (&options.time_key, sample.time_ns) {
        object.insert(key.clone(), Value::Number(ns.into()));
    }
    Value::Object(object)
}

fn number_or_null(value: &FieldValue) -> Value {
    match value {
        FieldValue::Float(v) => Number::from_f64(*v).map_or(Value::Null, Value::Number),
        FieldValue::Int(v) => Value::Number((*v).into()),
        FieldValue::UInt(v) => Value::Number((*v).into()),
        FieldValue::Bool(_) => Value::Null,
        // A recorded string that holds a number (a string `actualSpeed`) is still a number.
        FieldValue::Str(s) => s
            .trim()
            .parse::<f64>()
            .ok()
            .and_then(Number::from_f64)
            .map_or(Value::Null, Value::Number),
    }
}

fn as_text(value: &FieldValue) -> String {
    match value {
        FieldValue::Float(v) => v.to_string(),
        FieldValue::Int(v) => v.to_string(),
        FieldValue::UInt(v) => v.to_string(),
        FieldValue::Bool(b) => b.to_string(),
        FieldValue::Str(s) => s.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn sample(fields: Vec<(&str, FieldValue)>) -> Sample {
        Sample {
            line: 1,
            time_ns: Some(1_700_000_000_000_000_000),
            fields: fields
                .into_iter()
                .map(|(n, v)| (n.to_string(), v))
                .collect(),
        }
    }

    #[test]
    fn lidar_fields_become_an_array_with_gaps_as_null() {
        let s = sample(vec![
            ("expectedSpeed", FieldValue::Float(0.1)),
            ("lidar_0", FieldValue::Float(0.5)),
            ("lidar_3", FieldValue::Float(1.5)),
            ("lidar_1", FieldValue::Float(f64::NAN)),
        ]);
        let v = to_json(&s, &MessageOptions::default());
        assert_eq!(
            v,
            json!({"expectedSpeed": 0.1, "lidar": [0.5, null, null, 1.5]})
        );
    }

    #[test]
    fn string_fields_and_time_key() {
        let s = sample(vec![
            ("actualSpeed", FieldValue::Float(0.05)),
            ("expectedSpeed", FieldValue::Str("0.1".into())),
            ("ok", FieldValue::Bool(true)),
        ]);
        let options = MessageOptions {
            string_fields: vec!["actualSpeed".into()],
            time_key: Some("time".into()),
        };
        let v = to_json(&s, &options);
        assert_eq!(
            v,
            json!({"actualSpeed": "0.05", "expectedSpeed": "0.1", "ok": true,
                   "time": 1_700_000_000_000_000_000_i64})
        );
    }
}
