//! A test-side stand-in for the two Telegraf plugins around our processor, written down from
//! the research notes (telegraf.md §3.1 and §3.2), not from Telegraf's code:
//!
//! - `inputs.mqtt_consumer` with `data_format = "json"`: measurement `mqtt_consumer`, tag
//!   `topic` (plus the agent's `host` tag), nested objects joined with `_`, arrays indexed
//!   (`lidar` -> `lidar_0..`), every number a float, `null` skipped, strings and booleans kept
//!   only when listed in `json_string_fields`, time from `json_time_key` (`unix_ns`) or now.
//!   Written as Telegraf's influx serializer writes: tags sorted, floats in shortest decimal
//!   form without exponent, strings quoted with `\` and `"` escaped.
//! - `outputs.mqtt` with `data_format = "json"`: one message per metric,
//!   `{"fields":{..},"name":..,"tags":{..},"timestamp":..}` (keys sorted), timestamp in
//!   `json_timestamp_units`.
//!
//! [`StandIn`] wires both around the real binary over a real broker, as Telegraf would.
//!
//! Include with `#[path = "support/telegraf_standin.rs"] mod telegraf_standin;`, after
//! `#[path = "support/mqtt_client.rs"] mod mqtt_client;` (the stand-in's MQTT side).
#![allow(dead_code)]

use influxdb_line_protocol::{FieldValue, parse_lines};
use serde_json::{Map, Value, json};
use std::io::{BufRead, BufReader, Write};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::thread::JoinHandle;
use std::time::Duration;

/// `json_timestamp_units = "1ms"` of the stand-in's `outputs.mqtt`.
pub const MS: i64 = 1_000_000;

/// A stand-in Telegraf: `inputs.mqtt_consumer` on `topic` feeding `processors.execd` (the real
/// binary, `tessla-telegraf run`), whose `action` metrics `outputs.mqtt` publishes on topic
/// `action` as JSON.
pub struct StandIn {
    child: Child,
    input: JoinHandle<usize>,
    output: JoinHandle<usize>,
}

impl StandIn {
    /// Subscribe to `topic` on the broker at `port` (returns once subscribed) and feed the first
    /// `messages` messages to a new `bin run`; then its stdin closes (EOF, as when Telegraf stops).
    pub fn start(
        bin: &str,
        port: u16,
        topic: &str,
        cfg: ConsumerConfig,
        messages: usize,
    ) -> StandIn {
        let telemetry = crate::mqtt_client::subscribe(port, topic, "telegraf-in");
        let mut child = Command::new(bin)
            .arg("run")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stdout = child.stdout.take().unwrap();
        let output = std::thread::spawn(move || {
            let publisher = crate::mqtt_client::Publisher::connect(port, "telegraf-out");
            let mut published = 0usize;
            for line in BufReader::new(stdout).lines() {
                let line = line.unwrap();
                if line.starts_with("action ") || line.starts_with("action,") {
                    let message = line_to_message(&line, MS).expect("our action line parses");
                    publisher.publish("action", serde_json::to_vec(&message).unwrap());
                    published += 1;
                }
            }
            published
        });
        let mut stdin = child.stdin.take().unwrap();
        let topic = topic.to_string();
        let input = std::thread::spawn(move || {
            let mut fed = 0usize;
            while fed < messages {
                let Ok((_, payload)) = telemetry.recv_timeout(Duration::from_secs(60)) else {
                    break;
                };
                if let Some(line) = message_to_line(&topic, &payload, &cfg, 0) {
                    stdin.write_all(line.as_bytes()).unwrap();
                    stdin.write_all(b"\n").unwrap();
                }
                fed += 1;
            }
            fed
        });
        StandIn {
            child,
            input,
            output,
        }
    }

    /// Wait for the end: (messages fed to the processor, its exit status, actions published).
    pub fn finish(mut self) -> (usize, ExitStatus, usize) {
        let fed = self.input.join().unwrap();
        let status = self.child.wait().unwrap();
        let published = self.output.join().unwrap();
        (fed, status, published)
    }
}

/// The mqtt_consumer settings the stand-in honours.
#[derive(Debug, Clone)]
pub struct ConsumerConfig {
    pub host: String,
    /// Glob patterns (`*` at the end only) of string fields to keep.
    pub json_string_fields: Vec<String>,
    /// Key holding the time as integer ns (`json_time_format = "unix_ns"`).
    pub json_time_key: Option<String>,
}

fn glob_match(pattern: &str, name: &str) -> bool {
    match pattern.strip_suffix('*') {
        Some(prefix) => name.starts_with(prefix),
        None => pattern == name,
    }
}

fn flatten(prefix: &str, value: &Value, out: &mut Vec<(String, Value)>) {
    match value {
        Value::Object(map) => {
            for (k, v) in map {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}_{k}")
                };
                flatten(&key, v, out);
            }
        }
        Value::Array(items) => {
            for (i, v) in items.iter().enumerate() {
                flatten(&format!("{prefix}_{i}"), v, out);
            }
        }
        Value::Null => {}
        leaf => out.push((prefix.to_string(), leaf.clone())),
    }
}

fn escape_key(s: &str) -> String {
    s.replace(',', "\\,")
        .replace('=', "\\=")
        .replace(' ', "\\ ")
}

/// The line Telegraf's JSON parser and influx serializer make of one MQTT message, or `None`
/// when the message has no field left (Telegraf drops such a metric).
pub fn message_to_line(
    topic: &str,
    payload: &[u8],
    cfg: &ConsumerConfig,
    now_ns: i64,
) -> Option<String> {
    let json: Value = serde_json::from_slice(payload).ok()?;
    let mut leaves = Vec::new();
    flatten("", &json, &mut leaves);
    let mut time = now_ns;
    let mut fields: Vec<(String, String)> = Vec::new();
    for (key, value) in leaves {
        if cfg.json_time_key.as_deref() == Some(key.as_str()) {
            if let Some(ns) = value.as_i64() {
                time = ns;
            }
            continue;
        }
        let keep_text = cfg.json_string_fields.iter().any(|p| glob_match(p, &key));
        let rendered = match value {
            Value::Number(n) => {
                let f = n.as_f64()?;
                format!("{f}")
            }
            Value::String(s) if keep_text => {
                format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
            }
            Value::Bool(b) if keep_text => b.to_string(),
            _ => continue,
        };
        fields.push((escape_key(&key), rendered));
    }
    if fields.is_empty() {
        return None;
    }
    fields.sort();
    let mut tags = [("host", cfg.host.clone()), ("topic", topic.to_string())];
    tags.sort();
    let tag_text: String = tags
        .iter()
        .map(|(k, v)| format!(",{k}={}", escape_key(v)))
        .collect();
    let field_text: Vec<String> = fields.iter().map(|(k, v)| format!("{k}={v}")).collect();
    Some(format!(
        "mqtt_consumer{tag_text} {} {time}",
        field_text.join(",")
    ))
}

/// The JSON message outputs.mqtt publishes for one line-protocol metric.
pub fn line_to_message(line: &str, timestamp_unit_ns: i64) -> Option<Value> {
    let parsed = parse_lines(line).next()?.ok()?;
    let mut fields = Map::new();
    for (k, v) in &parsed.field_set {
        let value = match v {
            FieldValue::F64(f) => json!(f),
            FieldValue::I64(i) => json!(i),
            FieldValue::U64(u) => json!(u),
            FieldValue::Boolean(b) => json!(b),
            FieldValue::String(s) => json!(s.to_string()),
        };
        fields.insert(k.to_string(), value);
    }
    let mut tags = Map::new();
    for (k, v) in parsed.series.tag_set.iter().flatten() {
        tags.insert(k.to_string(), json!(v.to_string()));
    }
    Some(json!({
        "fields": fields,
        "name": parsed.series.measurement.to_string(),
        "tags": tags,
        "timestamp": parsed.timestamp.unwrap_or(0) / timestamp_unit_ns,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> ConsumerConfig {
        ConsumerConfig {
            host: "h".into(),
            json_string_fields: vec!["actualSpeed".into()],
            json_time_key: Some("time".into()),
        }
    }

    #[test]
    fn robot_message_as_telegraf_makes_it() {
        let payload = br#"{"expectedSpeed":0.1,"actualSpeed":"0.05","mode":"auto","ok":true,
                           "lidar":[0.5,null,2],"pose":{"x":1},"time":1700000000000000000}"#;
        let line = message_to_line("tessla", payload, &cfg(), 5).unwrap();
        assert_eq!(
            line,
            "mqtt_consumer,host=h,topic=tessla actualSpeed=\"0.05\",expectedSpeed=0.1,lidar_0=0.5,lidar_2=2,pose_x=1 1700000000000000000"
        );
        assert_eq!(message_to_line("t", br#"{"mode":"x"}"#, &cfg(), 5), None);
    }

    #[test]
    fn action_metric_as_outputs_mqtt_publishes_it() {
        let v = line_to_message(
            "action,robot=1 speed=0.1,augmented=true,p1_status=\"ok\",p3_spikes=2i 1500000000",
            1_000_000,
        )
        .unwrap();
        assert_eq!(
            v,
            json!({"fields": {"speed": 0.1, "augmented": true, "p1_status": "ok", "p3_spikes": 2},
                   "name": "action", "tags": {"robot": "1"}, "timestamp": 1500})
        );
    }
}
