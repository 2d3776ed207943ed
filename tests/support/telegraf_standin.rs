//! A test-side stand-in for Telegraf around our processor, driven by a whole shipped `.conf`.
//! Written from reading Telegraf's Go source (influxdata/telegraf, 1.39 / 1.40-dev), not copied
//! from it; each part names the files it follows:
//!
//! - `inputs.mqtt_consumer` (`plugins/inputs/mqtt_consumer/mqtt_consumer.go`, `sample.conf`):
//!   subscribes with the conf's `qos`, `client_id` and `persistent_session` (clean session off);
//!   measurement `mqtt_consumer`, tag `topic` (`topic_tag`) plus the agent's `host` tag.
//! - `data_format = "json"` (`plugins/parsers/json/parser.go`, `json_flattener.go`, `filter/filter.go`):
//!   a top-level object is one metric, a top-level array one metric per element (an element that is
//!   not an object fails the whole message); nested keys joined with `_`, arrays indexed
//!   (`lidar` -> `lidar_0..`), `null` skipped, every number a float64, strings and booleans kept
//!   only when `json_string_fields` matches (Telegraf's filter: exact names unless a pattern holds
//!   `*`, `?` or `[`, then globs); invalid JSON (NaN, Infinity) drops the whole message. Time: the
//!   moment the message is parsed, or with `json_time_key` the key's value read as a float64
//!   (`internal/internal.go` `ParseTimestamp`; nanosecond times near 1.7e18 round to 256 ns);
//!   a message without the key is dropped. Fields come in Go map order, that is shuffled.
//! - `plugins/serializers/influx` (`influx.go`, `escape.go`): what `processors.execd` writes to the
//!   child and `outputs.socket_writer` / `outputs.influxdb` send: tags sorted, fields in the
//!   metric's order, keys escaped (tab, newline, form feed, return, comma, space, `=`; the
//!   measurement without `=`), floats `'f'` shortest, NaN/Inf fields dropped, strings with `\`
//!   and `"` escaped, a metric without fields dropped.
//! - `plugins/processors/execd/execd.go`, `models/running_processor.go`: metrics passing the
//!   processor's filter go to the child's stdin; what it prints is parsed (influx, the streaming
//!   reader of 1.33.3 and later: no line cap, a newline inside a string field is part of it; the
//!   scanner of 1.30.0 to 1.33.2 is [`read_stdout`]'s other model) and continues with only the
//!   tags it carries (no agent tags for processor-made metrics); other metrics skip the
//!   processor.
//! - Acknowledgement (v1.39.3, the same at head): `execd.go` `Add` lines 82-98 write the metric to
//!   the child's stdin and then `m.Accept()`, and `mqtt_consumer.go` `onDelivered` lines 219-236
//!   sends the PUBACK (with `persistent_session`) once every metric of the message is accepted or
//!   dropped: a message is acknowledged when it is in the pipe, not after the child answered or
//!   an output delivered. A failed write is dropped by `agent/agent.go` lines 658-662, which
//!   acknowledges it too (`metric/tracking.go`: delivered means "none rejected"). A dead child is
//!   restarted after `restart_delay` (`internal/process/process.go` lines 138-162); stopping
//!   closes its stdin, then SIGTERM after 5 s, SIGKILL after 5 more (`process_posix.go`). See
//!   [`Telegraf`].
//! - stderr is read line by line (`E! `/`W! `/`I! `/`D! `/`T! ` prefixes as levels,
//!   since 1.37.0; anything else an error `stderr: "<line>"`), at most 64 KiB a line
//!   (`bufio.Scanner`'s default; a longer line stops the reader for good).
//! - `plugins/inputs/socket_listener`, `plugins/outputs/socket_writer`: influx over UDP.
//! - `plugins/outputs/mqtt/mqtt.go` + `plugins/serializers/json/json.go`: one message per metric
//!   on the topic template (`{{ .Tag "k" }}`, `{{ .Name }}`; empty segments removed, a leading
//!   `/` kept), `qos` from the conf, payload Go's `json.Marshal` of
//!   `{"fields","name","tags","timestamp"}` (keys sorted, whole floats as `2`, `<>&` escaped)
//!   plus a newline, timestamp in `json_timestamp_units` (default 1 s, rounded down to a power
//!   of ten).
//! - `plugins/outputs/influxdb`: line protocol POSTed to `/write?db=<database>`; the database is
//!   created at start.
//! - Routing as `agent/agent.go` and `models/filter.go`: inputs' and outputs' `namepass`,
//!   `namedrop`, `tagpass`, `tagdrop`; processors before outputs; every output sees every metric
//!   its filter passes.
//!
//! Not modelled: batching, `flush_interval` and `metric_buffer_limit` (each metric is delivered
//! at once, none buffered or dropped by an output), the acknowledgement of a tracked metric that
//! skips the processor (acknowledged when handed to the outputs; Telegraf waits until every
//! output wrote it), Windows (a kill 5 s after stdin closed), aggregators. The simple
//! [`StandIn`] below subscribes with a clean session that acknowledges on receipt. A conf key
//! the stand-in does not know fails the test, so every key of a shipped conf is either honoured
//! or listed here as not modelled.
//!
//! Include with `#[path = "support/telegraf_standin.rs"] mod telegraf_standin;`.
#![allow(dead_code)]

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rumqttc::{Client, Event, MqttOptions, Packet, QoS};
use serde_json::Value;
use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::UdpSocket;
use std::process::{Child, ChildStdin, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// `json_timestamp_units = "1ms"`, in ns.
pub const MS: i64 = 1_000_000;

// ---------------------------------------------------------------- metrics

#[derive(Debug, Clone, PartialEq)]
pub enum Field {
    Float(f64),
    Int(i64),
    UInt(u64),
    Bool(bool),
    Str(String),
}

/// A Telegraf metric: tags sorted (Telegraf keeps them sorted), fields in the metric's order.
#[derive(Debug, Clone, PartialEq)]
pub struct Metric {
    pub name: String,
    pub tags: BTreeMap<String, String>,
    pub fields: Vec<(String, Field)>,
    pub time: i64,
}

pub fn now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i64)
}

// ---------------------------------------------------------------- filters (filter/filter.go)

/// Telegraf's name filter: exact names, or globs when any pattern holds `*`, `?` or `[`.
#[derive(Debug, Clone)]
pub struct NameFilter {
    exact: Vec<String>,
    globs: Option<globset::GlobSet>,
}

impl NameFilter {
    pub fn new(patterns: &[String]) -> NameFilter {
        if patterns.iter().any(|p| p.contains(['*', '?', '['])) {
            let mut b = globset::GlobSetBuilder::new();
            for p in patterns {
                b.add(globset::Glob::new(p).expect("a valid glob"));
            }
            NameFilter {
                exact: Vec::new(),
                globs: Some(b.build().expect("a valid glob set")),
            }
        } else {
            NameFilter {
                exact: patterns.to_vec(),
                globs: None,
            }
        }
    }

    pub fn matches(&self, name: &str) -> bool {
        match &self.globs {
            Some(g) => g.is_match(name),
            None => self.exact.iter().any(|e| e == name),
        }
    }
}

/// A plugin's metric selector (`models/filter.go`): namepass/namedrop on the measurement,
/// tagpass/tagdrop on tag values.
#[derive(Debug, Clone, Default)]
pub struct Selector {
    namepass: Option<NameFilter>,
    namedrop: Option<NameFilter>,
    tagpass: Vec<(String, NameFilter)>,
    tagdrop: Vec<(String, NameFilter)>,
}

impl Selector {
    pub fn passes(&self, m: &Metric) -> bool {
        if let Some(f) = &self.namepass
            && !f.matches(&m.name)
        {
            return false;
        }
        if let Some(f) = &self.namedrop
            && f.matches(&m.name)
        {
            return false;
        }
        let tag_hit = |list: &[(String, NameFilter)]| {
            list.iter()
                .any(|(k, f)| m.tags.get(k).is_some_and(|v| f.matches(v)))
        };
        if !self.tagpass.is_empty() && !tag_hit(&self.tagpass) {
            return false;
        }
        self.tagdrop.is_empty() || !tag_hit(&self.tagdrop)
    }
}

// ---------------------------------------------------------------- JSON parser (plugins/parsers/json)

#[derive(Debug, Clone, Default)]
pub struct JsonParser {
    pub string_fields: Vec<String>,
    pub time_key: Option<String>,
    pub time_format: Option<String>,
}

fn flatten(prefix: &str, value: &Value, out: &mut BTreeMap<String, Value>) {
    let join = |k: &str| {
        if prefix.is_empty() {
            k.to_string()
        } else {
            format!("{prefix}_{k}")
        }
    };
    match value {
        Value::Object(map) => {
            for (k, v) in map {
                flatten(&join(k), v, out);
            }
        }
        Value::Array(items) => {
            for (i, v) in items.iter().enumerate() {
                flatten(&join(&i.to_string()), v, out);
            }
        }
        Value::Null => {}
        leaf => {
            out.insert(prefix.to_string(), leaf.clone());
        }
    }
}

/// `internal.ParseTimestamp` for the unix formats: a float64 taken exactly (as Go's `big.Rat`),
/// times the format's factor, rounded down; a string read exactly.
pub fn parse_unix_time(format: &str, v: &Value) -> Result<i64, String> {
    let factor: i128 = match format {
        "unix" => 1_000_000_000,
        "unix_ms" => 1_000_000,
        "unix_us" => 1_000,
        "unix_ns" => 1,
        other => return Err(format!("json_time_format {other:?} is not modelled")),
    };
    match v {
        Value::Number(n) => {
            let f = n.as_f64().ok_or("invalid number")?;
            if !f.is_finite() {
                return Err("invalid number".into());
            }
            // f = mantissa * 2^exp exactly.
            let bits = f.to_bits();
            let sign: i128 = if bits >> 63 == 1 { -1 } else { 1 };
            let exp_bits = ((bits >> 52) & 0x7ff) as i32;
            let frac = (bits & ((1u64 << 52) - 1)) as i128;
            let (mantissa, exp) = if exp_bits == 0 {
                (frac, -1074)
            } else {
                (frac | (1i128 << 52), exp_bits - 1075)
            };
            let scaled = sign * mantissa * factor;
            Ok(if exp >= 0 {
                (scaled << exp) as i64
            } else if exp > -127 {
                (scaled >> (-exp)) as i64
            } else {
                0
            })
        }
        Value::String(s) => {
            let s = s.trim();
            let (int, frac) = s.split_once('.').unwrap_or((s, ""));
            let int: i128 = int.parse().map_err(|_| "invalid number")?;
            let mut ns = int * factor;
            let mut scale = factor;
            for d in frac.chars() {
                scale /= 10;
                ns += d.to_digit(10).ok_or("invalid number")? as i128 * scale;
            }
            Ok(ns as i64)
        }
        _ => Err("unsupported type".into()),
    }
}

impl JsonParser {
    /// The metrics Telegraf makes of one message (`now` = the parse time), fields in Go map order
    /// (shuffled by `rng`), or the error for which Telegraf drops the whole message.
    pub fn parse(
        &self,
        payload: &[u8],
        tags: &BTreeMap<String, String>,
        now: i64,
        rng: &mut ChaCha8Rng,
    ) -> Result<Vec<Metric>, String> {
        let text = payload.trim_ascii();
        let text = text.strip_prefix(b"\xef\xbb\xbf").unwrap_or(text);
        if text.is_empty() {
            return Ok(Vec::new());
        }
        let json: Value = serde_json::from_slice(text).map_err(|e| e.to_string())?;
        match &json {
            Value::Object(_) => Ok(vec![self.object(&json, tags, now, rng)?]),
            Value::Array(items) => items
                .iter()
                .map(|item| match item {
                    Value::Object(_) => self.object(item, tags, now, rng),
                    _ => Err("must be an object or an array of objects".into()),
                })
                .collect(),
            Value::Null => Ok(Vec::new()),
            _ => Err("must be an object or an array of objects".into()),
        }
    }

    fn object(
        &self,
        json: &Value,
        tags: &BTreeMap<String, String>,
        now: i64,
        rng: &mut ChaCha8Rng,
    ) -> Result<Metric, String> {
        let mut leaves = BTreeMap::new();
        flatten("", json, &mut leaves);
        let mut time = now;
        if let Some(key) = &self.time_key {
            let format = self
                .time_format
                .as_deref()
                .ok_or("use of 'json_time_key' requires 'json_time_format'")?;
            let v = leaves
                .remove(key)
                .ok_or("'json_time_key' could not be found")?;
            time = parse_unix_time(format, &v)?;
        }
        let keep = NameFilter::new(&self.string_fields);
        let mut fields: Vec<(String, Field)> = leaves
            .into_iter()
            .filter_map(|(k, v)| match v {
                Value::Number(n) => n.as_f64().map(|f| (k, Field::Float(f))),
                Value::String(s) if keep.matches(&k) => Some((k, Field::Str(s))),
                Value::Bool(b) if keep.matches(&k) => Some((k, Field::Bool(b))),
                _ => None,
            })
            .collect();
        fields.shuffle(rng);
        Ok(Metric {
            name: "mqtt_consumer".into(),
            tags: tags.clone(),
            fields,
            time,
        })
    }
}

// ---------------------------------------------------------------- influx serializer

fn escape(s: &str, with_equals: bool) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '\t' => out.push_str("\\t"),
            '\n' => out.push_str("\\n"),
            '\x0c' => out.push_str("\\f"),
            '\r' => out.push_str("\\r"),
            ',' => out.push_str("\\,"),
            ' ' => out.push_str("\\ "),
            '=' if with_equals => out.push_str("\\="),
            c => out.push(c),
        }
    }
    out
}

/// One metric as Telegraf's influx serializer writes it (with its newline), or `None` when no
/// field can be written.
pub fn to_line(m: &Metric) -> Option<String> {
    let name = escape(&m.name, false);
    if name.is_empty() {
        return None;
    }
    let mut line = name;
    for (k, v) in &m.tags {
        let k = escape(k, true);
        let v = escape(v, true);
        let (k, v) = (k.trim_end_matches('\\'), v.trim_end_matches('\\'));
        if k.is_empty() || v.is_empty() {
            continue;
        }
        line.push_str(&format!(",{k}={v}"));
    }
    let mut fields = Vec::new();
    for (k, v) in &m.fields {
        let k = escape(k, true);
        if k.is_empty() {
            continue;
        }
        let value = match v {
            Field::Float(f) if !f.is_finite() => continue,
            Field::Float(f) => format!("{f}"),
            Field::Int(i) => format!("{i}i"),
            Field::UInt(u) => format!("{}i", (*u).min(i64::MAX as u64)),
            Field::Bool(b) => b.to_string(),
            Field::Str(s) => format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\"")),
        };
        fields.push(format!("{k}={value}"));
    }
    if fields.is_empty() {
        return None;
    }
    Some(format!("{line} {} {}\n", fields.join(","), m.time))
}

// ---------------------------------------------------------------- influx parser

/// Parse line protocol as Telegraf's influx parser does (`now` for a line without a time).
pub fn parse_influx(text: &str, now: i64) -> Vec<Result<Metric, String>> {
    influxdb_line_protocol::parse_lines(text)
        .map(|r| {
            let l = r.map_err(|e| e.to_string())?;
            let fields = l
                .field_set
                .iter()
                .map(|(k, v)| {
                    let f = match v {
                        influxdb_line_protocol::FieldValue::F64(f) => Field::Float(*f),
                        influxdb_line_protocol::FieldValue::I64(i) => Field::Int(*i),
                        influxdb_line_protocol::FieldValue::U64(u) => Field::UInt(*u),
                        influxdb_line_protocol::FieldValue::Boolean(b) => Field::Bool(*b),
                        influxdb_line_protocol::FieldValue::String(s) => Field::Str(s.to_string()),
                    };
                    (k.to_string(), f)
                })
                .collect();
            let tags = l
                .series
                .tag_set
                .iter()
                .flatten()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect();
            Ok(Metric {
                name: l.series.measurement.to_string(),
                tags,
                fields,
                time: l.timestamp.unwrap_or(now),
            })
        })
        .collect()
}

// ---------------------------------------------------------------- execd's stdout reader

/// Whether `record` (bytes up to a newline) is a whole line-protocol record: its newline is not
/// inside a string field value. Telegraf's streaming influx parser reads on past such a newline.
pub fn record_complete(record: &[u8]) -> bool {
    let (mut i, mut spaces, mut in_string) = (0, 0, false);
    while i < record.len() {
        let c = record[i];
        if c == b'\\' {
            i += 2;
            continue;
        }
        if in_string {
            in_string = c != b'"';
        } else if c == b' ' {
            spaces += 1;
        } else if c == b'"' && spaces == 1 && i > 0 && record[i - 1] == b'=' {
            in_string = true;
        }
        i += 1;
    }
    !in_string
}

/// How `processors.execd` reads the child's stdout (`execd.go` `cmdReadOut`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StdoutReader {
    /// Telegraf 1.33.3 and later with `data_format = "influx"` (PR #16535): the streaming
    /// parser, no line cap, a newline inside a string field is part of the value; a parse error
    /// skips that record.
    Streaming,
    /// Telegraf 1.30.0 to 1.33.2 (the parser arrived wrapped in a `RunningParser` and was not
    /// recognised): `bufio.Scanner` with a 256 KiB maximum, each line parsed alone; a longer line
    /// stops the reader for good (the child then blocks on a full pipe).
    Scanner,
}

/// What Telegraf reads from the child's stdout: the metrics, the parse errors, and whether the
/// reader stopped for good before the end.
pub fn read_stdout(bytes: &[u8], how: StdoutReader) -> (Vec<Metric>, usize, bool) {
    let (mut metrics, mut errors) = (Vec::new(), 0);
    let mut parse = |text: &[u8]| {
        for r in parse_influx(&String::from_utf8_lossy(text), now_ns()) {
            match r {
                Ok(m) => metrics.push(m),
                Err(_) => errors += 1,
            }
        }
    };
    let mut pending: Vec<u8> = Vec::new();
    for line in bytes.split_inclusive(|b| *b == b'\n') {
        match how {
            StdoutReader::Scanner => {
                let body = line.strip_suffix(b"\n").unwrap_or(line);
                if body.len() >= 262_144 {
                    return (metrics, errors, true);
                }
                parse(body);
            }
            StdoutReader::Streaming => {
                pending.extend_from_slice(line);
                if record_complete(&pending) {
                    parse(&pending);
                    pending.clear();
                }
            }
        }
    }
    if !pending.is_empty() {
        parse(&pending);
    }
    (metrics, errors, false)
}

// ---------------------------------------------------------------- JSON serializer

/// Go's `encoding/json` for a float64: `'f'` shortest in [1e-6, 1e21), else `'e'` with the
/// exponent's leading zero removed for negative single digits (`1e-7`, `1e+21`).
pub fn go_float(f: f64) -> String {
    let a = f.abs();
    if a == 0.0 || (1e-6..1e21).contains(&a) {
        return format!("{f}");
    }
    let e = format!("{f:e}");
    let (mantissa, exp) = e.split_once('e').unwrap_or((&e, "0"));
    match exp.strip_prefix('-') {
        Some(d) => format!("{mantissa}e-{d}"),
        None => format!("{mantissa}e+{exp:0>2}"),
    }
}

/// Go's `encoding/json` for a string (HTML-safe: `<`, `>`, `&` escaped).
pub fn go_string(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            '\x08' => out.push_str("\\b"),
            '\x0c' => out.push_str("\\f"),
            '<' | '>' | '&' | '\u{2028}' | '\u{2029}' => {
                out.push_str(&format!("\\u{:04x}", c as u32))
            }
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// `json_timestamp_units` as Telegraf reads it: a Go duration, rounded down to a power of ten
/// (at least 1 ns; unset or zero: 1 s).
pub fn timestamp_units(text: Option<&str>) -> i64 {
    let ns = text.map(go_duration_ns).unwrap_or(0);
    if ns <= 0 {
        return 1_000_000_000;
    }
    let mut d = 1i64;
    while d * 10 <= ns {
        d *= 10;
    }
    d
}

/// A Go duration such as `1ms`, `500us`, `1s`, `1m30s`, in ns.
pub fn go_duration_ns(text: &str) -> i64 {
    let mut total = 0f64;
    let mut rest = text.trim();
    while !rest.is_empty() {
        let num_end = rest
            .find(|c: char| !(c.is_ascii_digit() || c == '.'))
            .unwrap_or(rest.len());
        let n: f64 = rest[..num_end].parse().expect("a Go duration");
        rest = &rest[num_end..];
        let unit_end = rest
            .find(|c: char| c.is_ascii_digit() || c == '.')
            .unwrap_or(rest.len());
        let unit = match &rest[..unit_end] {
            "ns" => 1.0,
            "us" | "µs" => 1e3,
            "ms" => 1e6,
            "s" => 1e9,
            "m" => 60e9,
            "h" => 3600e9,
            u => panic!("unknown Go duration unit {u:?} in {text:?}"),
        };
        total += n * unit;
        rest = &rest[unit_end..];
    }
    total as i64
}

/// The payload `outputs.mqtt` publishes for one metric with `data_format = "json"`: Go's
/// `json.Marshal` of the serializer's map, then a newline.
pub fn to_json(m: &Metric, unit_ns: i64) -> Vec<u8> {
    let mut fields: Vec<(&String, String)> = m
        .fields
        .iter()
        .filter_map(|(k, v)| {
            let text = match v {
                Field::Float(f) if !f.is_finite() => return None,
                Field::Float(f) => go_float(*f),
                Field::Int(i) => i.to_string(),
                Field::UInt(u) => u.to_string(),
                Field::Bool(b) => b.to_string(),
                Field::Str(s) => go_string(s),
            };
            Some((k, text))
        })
        .collect();
    fields.sort_by(|a, b| a.0.cmp(b.0));
    // A repeated key: the last value wins, as in Go's map.
    fields.dedup_by(|later, earlier| {
        if later.0 == earlier.0 {
            std::mem::swap(&mut later.1, &mut earlier.1);
            true
        } else {
            false
        }
    });
    let fields: Vec<String> = fields
        .iter()
        .map(|(k, v)| format!("{}:{v}", go_string(k)))
        .collect();
    let tags: Vec<String> = m
        .tags
        .iter()
        .map(|(k, v)| format!("{}:{}", go_string(k), go_string(v)))
        .collect();
    format!(
        "{{\"fields\":{{{}}},\"name\":{},\"tags\":{{{}}},\"timestamp\":{}}}\n",
        fields.join(","),
        go_string(&m.name),
        tags.join(","),
        m.time / unit_ns
    )
    .into_bytes()
}

/// The JSON message outputs.mqtt publishes for one line of our output, as a value (test side).
pub fn line_to_message(line: &str, unit_ns: i64) -> Option<Value> {
    let m = parse_influx(line, 0).into_iter().next()?.ok()?;
    serde_json::from_slice(&to_json(&m, unit_ns)).ok()
}

// ---------------------------------------------------------------- outputs.mqtt topic

/// Render `outputs.mqtt`'s topic template for `m` (the Go template subset the confs use).
pub fn render_topic(template: &str, m: &Metric) -> String {
    let mut out = String::new();
    let mut rest = template;
    while let Some(start) = rest.find("{{") {
        out.push_str(&rest[..start]);
        let end = rest[start..].find("}}").expect("a closed {{ }}") + start;
        let action = rest[start + 2..end].trim();
        if action == ".Name" || action == ".PluginName" {
            out.push_str(&m.name);
        } else if action == ".Hostname" {
            out.push_str(m.tags.get("host").map_or("", String::as_str));
        } else if let Some(arg) = action.strip_prefix(".Tag ") {
            let key = arg.trim().trim_matches('"');
            out.push_str(m.tags.get(key).map_or("", String::as_str));
        } else {
            panic!("topic template action {action:?} is not modelled");
        }
        rest = &rest[end + 2..];
    }
    out.push_str(rest);
    let parts: Vec<&str> = out.split('/').filter(|p| !p.is_empty()).collect();
    let topic = parts.join("/");
    if topic.is_empty() {
        return m.name.clone();
    }
    if out.starts_with('/') {
        format!("/{topic}")
    } else {
        topic
    }
}

// ---------------------------------------------------------------- stderr (processors.execd)

/// How Telegraf >= 1.37 logs one stderr line of the child: (level letter, message).
pub fn stderr_log(line: &str) -> (char, String) {
    for level in ['E', 'W', 'I', 'D', 'T'] {
        if let Some(msg) = line.strip_prefix(&format!("{level}! ")) {
            return (level, msg.to_string());
        }
    }
    ('E', format!("stderr: {line:?}"))
}

/// Telegraf's stderr reader (`bufio.Scanner`, 64 KiB): the lines it logs, and whether it
/// stopped for good at a longer line (after which a child that keeps writing blocks).
pub fn read_stderr(reader: impl Read) -> (Vec<String>, bool) {
    let mut lines = Vec::new();
    let mut r = BufReader::with_capacity(1 << 16, reader);
    let mut buf = Vec::new();
    loop {
        buf.clear();
        match r.read_until(b'\n', &mut buf) {
            Ok(0) | Err(_) => return (lines, false),
            Ok(_) => {
                if buf.last() == Some(&b'\n') {
                    buf.pop();
                }
                if buf.len() >= 65_536 {
                    return (lines, true);
                }
                lines.push(String::from_utf8_lossy(&buf).into_owned());
            }
        }
    }
}

// ---------------------------------------------------------------- the conf

/// Where the test's servers are: the conf's addresses are replaced by these.
#[derive(Debug, Clone)]
pub struct Endpoints {
    pub mqtt_port: u16,
    pub influx_url: Option<String>,
    /// UDP addresses of the conf (`udp://127.0.0.1:1653`) mapped to the test's (`127.0.0.1:N`).
    pub udp: Vec<(String, String)>,
    /// Program names of `command` mapped to paths (`tessla-telegraf` -> the test binary).
    pub programs: Vec<(String, String)>,
    /// The agent's `host` tag.
    pub host: String,
    /// Seed of the Go-map field order.
    pub seed: u64,
}

#[derive(Debug, Clone)]
enum Input {
    Mqtt {
        topics: Vec<String>,
        qos: QoS,
        client_id: Option<String>,
        persistent: bool,
        topic_tag: String,
        parser: JsonParser,
        select: Selector,
    },
    Udp {
        address: String,
        select: Selector,
    },
}

#[derive(Debug, Clone)]
struct Execd {
    command: Vec<String>,
    /// `restart_delay` (default 10 s, `execd.go` line 195).
    restart_delay: Duration,
    select: Selector,
}

#[derive(Debug, Clone)]
enum Output {
    Mqtt {
        topic: String,
        qos: QoS,
        unit_ns: i64,
        select: Selector,
    },
    Influx {
        url: String,
        database: String,
        select: Selector,
    },
    Udp {
        address: String,
        select: Selector,
    },
}

impl Output {
    fn select(&self) -> &Selector {
        match self {
            Output::Mqtt { select, .. }
            | Output::Influx { select, .. }
            | Output::Udp { select, .. } => select,
        }
    }
}

/// A shipped conf, read whole: every key honoured or known as not modelled.
#[derive(Debug, Clone)]
pub struct Conf {
    inputs: Vec<Input>,
    processors: Vec<Execd>,
    outputs: Vec<Output>,
}

const SELECTOR_KEYS: [&str; 4] = ["namepass", "namedrop", "tagpass", "tagdrop"];

fn strings(v: Option<&toml::Value>) -> Vec<String> {
    v.and_then(|v| v.as_array())
        .map(|a| {
            a.iter()
                .map(|x| x.as_str().expect("a string").to_string())
                .collect()
        })
        .unwrap_or_default()
}

fn check_keys(plugin: &str, t: &toml::Table, known: &[&str]) {
    for k in t.keys() {
        assert!(
            known.contains(&k.as_str()) || SELECTOR_KEYS.contains(&k.as_str()),
            "{plugin}: the stand-in does not model `{k}`"
        );
    }
}

fn selector(t: &toml::Table) -> Selector {
    let names = |k: &str| t.get(k).map(|_| NameFilter::new(&strings(t.get(k))));
    let tags = |k: &str| {
        t.get(k)
            .and_then(|v| v.as_table())
            .map(|tt| {
                tt.iter()
                    .map(|(key, v)| (key.clone(), NameFilter::new(&strings(Some(v)))))
                    .collect()
            })
            .unwrap_or_default()
    };
    Selector {
        namepass: names("namepass"),
        namedrop: names("namedrop"),
        tagpass: tags("tagpass"),
        tagdrop: tags("tagdrop"),
    }
}

fn qos(t: &toml::Table) -> QoS {
    match t.get("qos").and_then(|v| v.as_integer()).unwrap_or(0) {
        0 => QoS::AtMostOnce,
        1 => QoS::AtLeastOnce,
        _ => QoS::ExactlyOnce,
    }
}

fn plugins<'a>(v: &'a toml::Value, kind: &str, name: &str) -> Vec<&'a toml::Table> {
    v.get(kind)
        .and_then(|k| k.get(name))
        .and_then(|p| p.as_array())
        .map(|a| a.iter().filter_map(|t| t.as_table()).collect())
        .unwrap_or_default()
}

fn udp_address(text: &str, env: &Endpoints) -> String {
    env.udp
        .iter()
        .find(|(from, _)| from == text)
        .map(|(_, to)| to.clone())
        .unwrap_or_else(|| panic!("no test address for {text}"))
}

impl Conf {
    /// Read `text` (a whole `.conf`), pointing its servers at `env`'s.
    pub fn read(text: &str, env: &Endpoints) -> Conf {
        let v: toml::Value = toml::from_str(text).expect("the conf is TOML");
        let top: Vec<&String> = v.as_table().unwrap().keys().collect();
        for k in top {
            assert!(
                ["agent", "inputs", "processors", "outputs"].contains(&k.as_str()),
                "the stand-in does not model [{k}]"
            );
        }
        if let Some(agent) = v.get("agent").and_then(|a| a.as_table()) {
            check_keys(
                "agent",
                agent,
                &[
                    "interval",
                    "flush_interval",
                    "skip_processors_after_aggregators",
                    "metric_buffer_limit",
                ],
            );
        }
        for (kind, names) in [
            ("inputs", &["mqtt_consumer", "socket_listener"][..]),
            ("processors", &["execd"][..]),
            ("outputs", &["mqtt", "influxdb", "socket_writer"][..]),
        ] {
            if let Some(t) = v.get(kind).and_then(|t| t.as_table()) {
                for k in t.keys() {
                    assert!(
                        names.contains(&k.as_str()),
                        "[[{kind}.{k}]] is not modelled"
                    );
                }
            }
        }
        let mut inputs = Vec::new();
        for t in plugins(&v, "inputs", "mqtt_consumer") {
            check_keys(
                "inputs.mqtt_consumer",
                t,
                &[
                    "servers",
                    "topics",
                    "qos",
                    "persistent_session",
                    "client_id",
                    "data_format",
                    "json_string_fields",
                    "json_time_key",
                    "json_time_format",
                ],
            );
            assert_eq!(t["data_format"].as_str(), Some("json"));
            inputs.push(Input::Mqtt {
                topics: strings(t.get("topics")),
                qos: qos(t),
                client_id: t
                    .get("client_id")
                    .and_then(|c| c.as_str())
                    .map(str::to_string),
                persistent: t
                    .get("persistent_session")
                    .and_then(|p| p.as_bool())
                    .unwrap_or(false),
                topic_tag: "topic".into(),
                parser: JsonParser {
                    string_fields: strings(t.get("json_string_fields")),
                    time_key: t
                        .get("json_time_key")
                        .and_then(|k| k.as_str())
                        .map(str::to_string),
                    time_format: t
                        .get("json_time_format")
                        .and_then(|k| k.as_str())
                        .map(str::to_string),
                },
                select: selector(t),
            });
        }
        for t in plugins(&v, "inputs", "socket_listener") {
            check_keys(
                "inputs.socket_listener",
                t,
                &["service_address", "data_format"],
            );
            assert_eq!(t["data_format"].as_str(), Some("influx"));
            inputs.push(Input::Udp {
                address: udp_address(t["service_address"].as_str().unwrap(), env),
                select: selector(t),
            });
        }
        let processors = plugins(&v, "processors", "execd")
            .into_iter()
            .map(|t| {
                check_keys("processors.execd", t, &["command", "restart_delay"]);
                let mut command = strings(t.get("command"));
                if let Some((_, path)) = env.programs.iter().find(|(p, _)| *p == command[0]) {
                    command[0] = path.clone();
                }
                let restart_delay = Duration::from_nanos(
                    t.get("restart_delay")
                        .and_then(|d| d.as_str())
                        .map_or(10_000_000_000, go_duration_ns) as u64,
                );
                Execd {
                    command,
                    restart_delay,
                    select: selector(t),
                }
            })
            .collect();
        let mut outputs = Vec::new();
        for t in plugins(&v, "outputs", "mqtt") {
            check_keys(
                "outputs.mqtt",
                t,
                &[
                    "servers",
                    "topic",
                    "qos",
                    "data_format",
                    "json_timestamp_units",
                    "metric_batch_size",
                    "flush_interval",
                ],
            );
            assert_eq!(t["data_format"].as_str(), Some("json"));
            outputs.push(Output::Mqtt {
                topic: t["topic"].as_str().unwrap().to_string(),
                qos: qos(t),
                unit_ns: timestamp_units(t.get("json_timestamp_units").and_then(|u| u.as_str())),
                select: selector(t),
            });
        }
        for t in plugins(&v, "outputs", "influxdb") {
            check_keys("outputs.influxdb", t, &["urls", "database"]);
            if let Some(url) = &env.influx_url {
                outputs.push(Output::Influx {
                    url: url.clone(),
                    database: t
                        .get("database")
                        .and_then(|d| d.as_str())
                        .unwrap_or("telegraf")
                        .to_string(),
                    select: selector(t),
                });
            }
        }
        for t in plugins(&v, "outputs", "socket_writer") {
            check_keys("outputs.socket_writer", t, &["address", "data_format"]);
            assert_eq!(t["data_format"].as_str(), Some("influx"));
            outputs.push(Output::Udp {
                address: udp_address(t["address"].as_str().unwrap(), env),
                select: selector(t),
            });
        }
        Conf {
            inputs,
            processors,
            outputs,
        }
    }

    /// The topics the conf's `outputs.mqtt` publish `m` on (none when their filters drop it).
    pub fn mqtt_topics(&self, m: &Metric) -> Vec<String> {
        self.outputs
            .iter()
            .filter_map(|o| match o {
                Output::Mqtt { topic, select, .. } if select.passes(m) => {
                    Some(render_topic(topic, m))
                }
                _ => None,
            })
            .collect()
    }

    /// Whether a metric an input made reaches the processors (the inputs' own filters).
    pub fn input_accepts(&self, input: usize, m: &Metric) -> bool {
        match &self.inputs[input] {
            Input::Mqtt { select, .. } | Input::Udp { select, .. } => select.passes(m),
        }
    }
}

// ---------------------------------------------------------------- the running stand-in

/// What a run saw.
#[derive(Debug, Default)]
pub struct Stats {
    /// Metrics each output delivered, in conf order (mqtt, influxdb, socket_writer).
    pub delivered: Vec<usize>,
    /// Metrics written to the processor's child (each acknowledged at that moment).
    pub to_processor: usize,
    /// Metrics the processor failed to write (no child, or a broken pipe): Telegraf logs the
    /// error and drops each, which also acknowledges it (see [`Telegraf`]).
    pub dropped_at_write: usize,
    /// Every metric the children printed, in order (the echo, verdicts, actions).
    pub from_processor: Vec<Metric>,
    /// Times the child was restarted after it exited (`restart_delay`).
    pub restarts: usize,
    /// Messages acknowledged to the broker (PUBACK), with `persistent_session`.
    pub acked: usize,
    /// Messages received from the broker.
    pub received: usize,
    /// Messages the JSON parser rejected (Telegraf logs an error and drops each).
    pub parse_errors: usize,
    /// The child's stderr as Telegraf logs it.
    pub stderr: Vec<(char, String)>,
    pub child_status: Option<ExitStatus>,
    /// The signal the stop had to send because the child was still running 5 s after its
    /// stdin closed (`"SIGTERM"`), or 5 s after that (`"SIGKILL"`).
    pub signalled: Option<&'static str>,
}

struct Shared {
    stop: AtomicBool,
    /// Telegraf is stopping its processors: a child that exits is not restarted.
    quitting: AtomicBool,
    delivered: Vec<AtomicUsize>,
    to_processor: AtomicUsize,
    dropped_at_write: AtomicUsize,
    from_processor: Mutex<Vec<Metric>>,
    restarts: AtomicUsize,
    acked: AtomicUsize,
    received: AtomicUsize,
    parse_errors: AtomicUsize,
    stderr: Mutex<Vec<(char, String)>>,
    /// The running child's stdin; `None` between its exit and its restart.
    stdin: Mutex<Option<ChildStdin>>,
    child_pid: AtomicU32,
    side: Mutex<Vec<JoinHandle<()>>>,
    /// Messages taken from the broker and not yet delivered (tracked).
    undelivered: AtomicUsize,
}

/// One MQTT message's tracking (`metric/tracking.go`): the metrics made of it, and the PUBACK
/// sent when the last of them is accepted or dropped (`mqtt_consumer.go` `onDelivered`: the
/// message is acknowledged when `Delivered()`, that is when no metric was rejected; a drop is
/// not a rejection). Only with `persistent_session` (the client's auto-acknowledge is off then);
/// nothing is sent once the input has stopped.
struct Delivery {
    publish: rumqttc::Publish,
    client: Client,
    /// `persistent_session`: acknowledge (else the client acknowledged on receipt).
    ack: bool,
    left: AtomicUsize,
    shared: Arc<Shared>,
}

impl Delivery {
    fn done(&self) {
        if self.left.fetch_sub(1, Ordering::SeqCst) != 1 {
            return;
        }
        // The semaphore slot of max_undelivered_messages is given back (onDelivered).
        self.shared.undelivered.fetch_sub(1, Ordering::SeqCst);
        if self.ack && !self.shared.stop.load(Ordering::SeqCst) {
            let _ = self.client.try_ack(&self.publish);
            self.shared.acked.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// `max_undelivered_messages` (mqtt_consumer.go line 32): `onMessage` blocks while this many
/// messages are not yet delivered.
pub const MAX_UNDELIVERED: usize = 1000;

type Tracked = (Metric, Option<Arc<Delivery>>);

fn done(t: &Option<Arc<Delivery>>) {
    if let Some(d) = t {
        d.done();
    }
}

/// Telegraf running a conf: inputs -> processors (execd, the real binary) -> outputs.
///
/// Acknowledgement and restarts as Telegraf keeps them (v1.39.3):
/// - `plugins/processors/execd/execd.go` `Add` (lines 82-98): the metric is serialised, written
///   to the child's stdin, then `m.Accept()`: a message counts as delivered once it is in the
///   pipe, and `mqtt_consumer` sends its PUBACK then (`onDelivered`, lines 219-236).
/// - `agent/agent.go` `runProcessors` (lines 658-662): when `Add` fails (the child is gone,
///   a broken pipe) the error is logged and the metric dropped, `m.Drop()`, which also counts
///   as delivered (`metric/tracking.go`: `Delivered()` is "no metric rejected").
/// - `internal/process/process.go` `cmdLoop` (lines 138-162): a child that exits, for any
///   reason, is started again after `restart_delay` (default 10 s, `execd.go` line 195); the
///   stand-in models the gap (writes fail and are dropped) and the fresh pipes.
/// - `mqtt_consumer` takes at most `max_undelivered_messages` (1000) messages that are not yet
///   delivered (`onMessage` waits on a semaphore, lines 136 and 239).
/// - Stopping (`Process.Stop`, lines 81-91; `process_posix.go` `gracefulStop`): inputs stop
///   first (`mqtt_consumer.Stop`: disconnect; later acknowledgements are never sent), the
///   processor drains its channel into the child, then stdin is closed; SIGTERM follows after
///   5 s and SIGKILL 5 s later (Windows, `process_windows.go`: a kill after 5 s, not modelled).
pub struct Telegraf {
    shared: Arc<Shared>,
    inputs: Vec<JoinHandle<()>>,
    processor: Option<JoinHandle<()>>,
    supervisor: Option<JoinHandle<(Option<ExitStatus>, Option<&'static str>)>>,
    outputs: Option<JoinHandle<()>>,
    to_processors: Option<Sender<Tracked>>,
}

fn mqtt_options(id: &str, port: u16) -> MqttOptions {
    let mut o = MqttOptions::new(id, "127.0.0.1", port);
    o.set_max_packet_size(1 << 20, 1 << 20);
    o.set_keep_alive(Duration::from_secs(30));
    o
}

static CLIENTS: AtomicUsize = AtomicUsize::new(0);

fn random_id() -> String {
    format!(
        "standin-{}-{}",
        std::process::id(),
        CLIENTS.fetch_add(1, Ordering::Relaxed)
    )
}

/// Start the execd child: its stdout parsed into `out_tx` (and kept in `from_processor`), its
/// stderr logged, its stdin put where the processor writes.
fn spawn_child(command: &[String], shared: &Arc<Shared>, out_tx: &Sender<Tracked>) -> Child {
    let mut c = Command::new(&command[0])
        .args(&command[1..])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the execd command starts");
    let stdout = c.stdout.take().unwrap();
    let stderr = c.stderr.take().unwrap();
    *shared.stdin.lock().unwrap() = c.stdin.take();
    shared.child_pid.store(c.id(), Ordering::SeqCst);
    let tx = out_tx.clone();
    let sh = shared.clone();
    // Telegraf >= 1.33.3: the streaming reader (see [`StdoutReader`]).
    let out = std::thread::spawn(move || {
        let mut r = BufReader::new(stdout);
        let mut record = Vec::new();
        while r.read_until(b'\n', &mut record).unwrap_or(0) > 0 {
            if !record_complete(&record) {
                continue;
            }
            let text = String::from_utf8_lossy(&record).into_owned();
            for m in parse_influx(&text, now_ns()).into_iter().flatten() {
                sh.from_processor.lock().unwrap().push(m.clone());
                let _ = tx.send((m, None));
            }
            record.clear();
        }
    });
    let sh = shared.clone();
    let err = std::thread::spawn(move || {
        let (lines, _) = read_stderr(stderr);
        let mut log = sh.stderr.lock().unwrap();
        log.extend(lines.iter().map(|l| stderr_log(l)));
    });
    shared.side.lock().unwrap().extend([out, err]);
    c
}

/// `internal/process`: wait for the child; restart it after `delay` unless Telegraf is
/// stopping; when stopping, SIGTERM after 5 s and SIGKILL 5 s later.
fn supervise(
    mut child: Child,
    command: Vec<String>,
    delay: Duration,
    shared: Arc<Shared>,
    out_tx: Sender<Tracked>,
) -> (Option<ExitStatus>, Option<&'static str>) {
    loop {
        let mut quit_since: Option<std::time::Instant> = None;
        let mut signalled = None;
        let status = loop {
            if let Ok(Some(s)) = child.try_wait() {
                break s;
            }
            if shared.quitting.load(Ordering::SeqCst) {
                let since = *quit_since.get_or_insert_with(std::time::Instant::now);
                let pid = child.id().to_string();
                if signalled.is_none() && since.elapsed() >= Duration::from_secs(5) {
                    let _ = Command::new("kill").args(["-TERM", &pid]).status();
                    signalled = Some("SIGTERM");
                } else if signalled == Some("SIGTERM") && since.elapsed() >= Duration::from_secs(10)
                {
                    let _ = child.kill();
                    signalled = Some("SIGKILL");
                }
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        if shared.quitting.load(Ordering::SeqCst) {
            return (Some(status), signalled);
        }
        // Exited on its own: after Wait the old pipe is closed, every write fails.
        shared.stdin.lock().unwrap().take();
        let until = std::time::Instant::now() + delay;
        while std::time::Instant::now() < until {
            if shared.quitting.load(Ordering::SeqCst) {
                return (Some(status), None);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        shared.restarts.fetch_add(1, Ordering::Relaxed);
        child = spawn_child(&command, &shared, &out_tx);
    }
}

impl Telegraf {
    /// Start everything `conf` holds; returns once every MQTT subscription is confirmed.
    pub fn start(conf: &Conf, env: &Endpoints) -> Telegraf {
        let shared = Arc::new(Shared {
            stop: AtomicBool::new(false),
            quitting: AtomicBool::new(false),
            delivered: conf.outputs.iter().map(|_| AtomicUsize::new(0)).collect(),
            to_processor: AtomicUsize::new(0),
            dropped_at_write: AtomicUsize::new(0),
            from_processor: Mutex::new(Vec::new()),
            restarts: AtomicUsize::new(0),
            acked: AtomicUsize::new(0),
            received: AtomicUsize::new(0),
            parse_errors: AtomicUsize::new(0),
            stderr: Mutex::new(Vec::new()),
            stdin: Mutex::new(None),
            child_pid: AtomicU32::new(0),
            side: Mutex::new(Vec::new()),
            undelivered: AtomicUsize::new(0),
        });
        let (out_tx, out_rx) = channel::<Tracked>();
        let outputs = Some(start_outputs(conf, env, out_rx, shared.clone()));
        let (proc_tx, proc_rx) = channel::<Tracked>();
        let mut supervisor = None;
        let processor = match conf.processors.first() {
            Some(execd) => {
                assert!(conf.processors.len() == 1, "one execd is modelled");
                let child = spawn_child(&execd.command, &shared, &out_tx);
                let (command, delay) = (execd.command.clone(), execd.restart_delay);
                let (sh, tx) = (shared.clone(), out_tx.clone());
                supervisor = Some(std::thread::spawn(move || {
                    supervise(child, command, delay, sh, tx)
                }));
                let select = execd.select.clone();
                let tx = out_tx.clone();
                let sh = shared.clone();
                Some(std::thread::spawn(move || {
                    for (m, t) in proc_rx {
                        if select.passes(&m) {
                            // Serialise, write, then Accept; a failed write is dropped (both
                            // count as delivered).
                            if let Some(line) = to_line(&m) {
                                let mut stdin = sh.stdin.lock().unwrap();
                                let written = stdin
                                    .as_mut()
                                    .is_some_and(|s| s.write_all(line.as_bytes()).is_ok());
                                drop(stdin);
                                if written {
                                    sh.to_processor.fetch_add(1, Ordering::Relaxed);
                                } else {
                                    sh.dropped_at_write.fetch_add(1, Ordering::Relaxed);
                                }
                            }
                            done(&t);
                        } else {
                            let _ = tx.send((m, t));
                        }
                    }
                }))
            }
            None => {
                let tx = out_tx.clone();
                Some(std::thread::spawn(move || {
                    for m in proc_rx {
                        let _ = tx.send(m);
                    }
                }))
            }
        };
        drop(out_tx);
        let mut inputs = Vec::new();
        for (n, input) in conf.inputs.iter().enumerate() {
            let tx = proc_tx.clone();
            let sh = shared.clone();
            match input.clone() {
                Input::Mqtt {
                    topics,
                    qos,
                    client_id,
                    persistent,
                    topic_tag,
                    parser,
                    select,
                } => {
                    let id = client_id.unwrap_or_else(random_id);
                    let mut o = mqtt_options(&id, env.mqtt_port);
                    o.set_clean_session(!persistent);
                    // `SetAutoAckDisabled(m.PersistentSession)` (mqtt_consumer.go line 338).
                    o.set_manual_acks(persistent);
                    let (client, mut connection) = Client::new(o, 1024);
                    for t in &topics {
                        client.subscribe(t, qos).unwrap();
                    }
                    let (ready_tx, ready_rx) = channel();
                    let host = env.host.clone();
                    let mut rng = ChaCha8Rng::seed_from_u64(env.seed.wrapping_add(n as u64));
                    inputs.push(std::thread::spawn(move || {
                        let mut acks = 0;
                        while !sh.stop.load(Ordering::SeqCst) {
                            let Ok(event) = connection.recv_timeout(Duration::from_millis(20))
                            else {
                                continue;
                            };
                            match event {
                                Ok(Event::Incoming(Packet::SubAck(_))) => {
                                    acks += 1;
                                    if acks == topics.len() {
                                        let _ = ready_tx.send(());
                                    }
                                }
                                Ok(Event::Incoming(Packet::Publish(p))) => {
                                    // onMessage takes a semaphore slot first.
                                    while sh.undelivered.load(Ordering::SeqCst) >= MAX_UNDELIVERED
                                        && !sh.stop.load(Ordering::SeqCst)
                                    {
                                        std::thread::sleep(Duration::from_millis(1));
                                    }
                                    sh.received.fetch_add(1, Ordering::Relaxed);
                                    let mut tags = BTreeMap::new();
                                    tags.insert("host".to_string(), host.clone());
                                    tags.insert(topic_tag.clone(), p.topic.to_string());
                                    let parsed =
                                        parser.parse(&p.payload, &tags, now_ns(), &mut rng);
                                    let ms = match parsed {
                                        Ok(ms) if !ms.is_empty() => ms,
                                        // No metric: acknowledged at once (onMessage).
                                        other => {
                                            if other.is_err() {
                                                sh.parse_errors.fetch_add(1, Ordering::Relaxed);
                                            }
                                            if persistent {
                                                let _ = client.try_ack(&p);
                                                sh.acked.fetch_add(1, Ordering::Relaxed);
                                            }
                                            continue;
                                        }
                                    };
                                    sh.undelivered.fetch_add(1, Ordering::SeqCst);
                                    let track = Some(Arc::new(Delivery {
                                        publish: p.clone(),
                                        client: client.clone(),
                                        ack: persistent,
                                        left: AtomicUsize::new(ms.len()),
                                        shared: sh.clone(),
                                    }));
                                    for m in ms {
                                        // A metric the input's filter drops is dropped.
                                        if !select.passes(&m) {
                                            done(&track);
                                        } else if tx.send((m, track.clone())).is_err() {
                                            return;
                                        }
                                    }
                                }
                                Ok(_) => {}
                                Err(_) => std::thread::sleep(Duration::from_millis(50)),
                            }
                        }
                        // mqtt_consumer.Stop: disconnect; the session stays with the broker.
                        let _ = client.try_disconnect();
                        let until = std::time::Instant::now() + Duration::from_millis(200);
                        while std::time::Instant::now() < until {
                            if let Ok(Err(_)) = connection.recv_timeout(Duration::from_millis(20)) {
                                break;
                            }
                        }
                    }));
                    ready_rx
                        .recv_timeout(Duration::from_secs(10))
                        .expect("mqtt_consumer subscribed");
                }
                Input::Udp { address, select } => {
                    let sock = UdpSocket::bind(&address).expect("socket_listener binds");
                    sock.set_read_timeout(Some(Duration::from_millis(50)))
                        .unwrap();
                    inputs.push(std::thread::spawn(move || {
                        let mut buf = vec![0u8; 65_536];
                        while !sh.stop.load(Ordering::SeqCst) {
                            let Ok(n) = sock.recv(&mut buf) else {
                                continue;
                            };
                            let text = String::from_utf8_lossy(&buf[..n]).into_owned();
                            for m in parse_influx(&text, now_ns()).into_iter().flatten() {
                                if select.passes(&m) && tx.send((m, None)).is_err() {
                                    return;
                                }
                            }
                        }
                    }));
                }
            }
        }
        Telegraf {
            shared,
            inputs,
            processor,
            supervisor,
            outputs,
            to_processors: Some(proc_tx),
        }
    }

    /// Metrics delivered so far by each output.
    pub fn delivered(&self) -> Vec<usize> {
        self.shared
            .delivered
            .iter()
            .map(|d| d.load(Ordering::Relaxed))
            .collect()
    }

    /// The running child's process id (0 before the first start).
    pub fn child_pid(&self) -> u32 {
        self.shared.child_pid.load(Ordering::SeqCst)
    }

    /// Metrics written to the child so far.
    pub fn to_processor(&self) -> usize {
        self.shared.to_processor.load(Ordering::Relaxed)
    }

    /// Child restarts so far.
    pub fn restarts(&self) -> usize {
        self.shared.restarts.load(Ordering::Relaxed)
    }

    /// Stop as Telegraf does: inputs first (no acknowledgement after that), then the processor
    /// drains what is queued into the child and closes its stdin (EOF; SIGTERM after 5 s,
    /// SIGKILL after 10 s); outputs deliver what is left.
    pub fn stop(mut self) -> Stats {
        self.shared.stop.store(true, Ordering::SeqCst);
        for h in self.inputs.drain(..) {
            let _ = h.join();
        }
        self.to_processors.take();
        if let Some(p) = self.processor.take() {
            let _ = p.join();
        }
        self.shared.quitting.store(true, Ordering::SeqCst);
        self.shared.stdin.lock().unwrap().take();
        let (status, signalled) = self
            .supervisor
            .take()
            .map(|s| s.join().unwrap())
            .unwrap_or((None, None));
        let side: Vec<JoinHandle<()>> = self.shared.side.lock().unwrap().drain(..).collect();
        for h in side {
            let _ = h.join();
        }
        if let Some(o) = self.outputs.take() {
            let _ = o.join();
        }
        Stats {
            delivered: self.delivered(),
            to_processor: self.shared.to_processor.load(Ordering::Relaxed),
            dropped_at_write: self.shared.dropped_at_write.load(Ordering::Relaxed),
            from_processor: std::mem::take(&mut *self.shared.from_processor.lock().unwrap()),
            restarts: self.shared.restarts.load(Ordering::Relaxed),
            acked: self.shared.acked.load(Ordering::Relaxed),
            received: self.shared.received.load(Ordering::Relaxed),
            parse_errors: self.shared.parse_errors.load(Ordering::Relaxed),
            stderr: self.shared.stderr.lock().unwrap().clone(),
            child_status: status,
            signalled,
        }
    }
}

fn start_outputs(
    conf: &Conf,
    env: &Endpoints,
    rx: Receiver<Tracked>,
    shared: Arc<Shared>,
) -> JoinHandle<()> {
    enum Live {
        Mqtt(Client, String, QoS, i64),
        Influx(ureq::Agent, String),
        Udp(UdpSocket),
    }
    let mut live = Vec::new();
    for o in &conf.outputs {
        live.push(match o {
            Output::Mqtt {
                topic,
                qos,
                unit_ns,
                ..
            } => {
                let client =
                    crate::mqtt_client::connect_with(mqtt_options(&random_id(), env.mqtt_port));
                Live::Mqtt(client, topic.clone(), *qos, *unit_ns)
            }
            Output::Influx { url, database, .. } => {
                let agent: ureq::Agent = ureq::Agent::config_builder()
                    .http_status_as_error(false)
                    .timeout_global(Some(Duration::from_secs(30)))
                    .build()
                    .into();
                agent
                    .post(&format!("{url}/query"))
                    .query("q", format!("CREATE DATABASE \"{database}\""))
                    .send_empty()
                    .expect("influxdb answers");
                Live::Influx(agent, format!("{url}/write?db={database}&precision=ns"))
            }
            Output::Udp { address, .. } => {
                let s = UdpSocket::bind("127.0.0.1:0").unwrap();
                s.connect(address).unwrap();
                Live::Udp(s)
            }
        });
    }
    let selects: Vec<Selector> = conf.outputs.iter().map(|o| o.select().clone()).collect();
    std::thread::spawn(move || {
        for (m, track) in rx {
            // A tracked metric that skipped the processor: accepted once the outputs had it.
            done(&track);
            for (i, (out, select)) in live.iter().zip(&selects).enumerate() {
                if !select.passes(&m) {
                    continue;
                }
                let sent = match out {
                    Live::Mqtt(client, template, qos, unit) => client
                        .publish(render_topic(template, &m), *qos, false, to_json(&m, *unit))
                        .is_ok(),
                    Live::Influx(agent, url) => to_line(&m).is_some_and(|line| {
                        agent
                            .post(url)
                            .send(line.as_bytes())
                            .is_ok_and(|r| r.status().as_u16() == 204)
                    }),
                    Live::Udp(s) => to_line(&m).is_some_and(|line| s.send(line.as_bytes()).is_ok()),
                };
                if sent {
                    shared.delivered[i].fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    })
}

// ---------------------------------------------------------------- the simple stand-in

/// The mqtt_consumer settings of [`StandIn`].
#[derive(Debug, Clone)]
pub struct ConsumerConfig {
    pub host: String,
    /// Telegraf filter patterns of string fields to keep.
    pub json_string_fields: Vec<String>,
    /// Key holding the time in ns (`json_time_format = "unix_ns"`); `None`: the parse time.
    pub json_time_key: Option<String>,
}

/// The lines Telegraf's JSON parser and influx serializer make of one MQTT message (fields in
/// Go map order, from `seed`); none when Telegraf drops the message or its metrics have no field.
pub fn message_to_lines(
    topic: &str,
    payload: &[u8],
    cfg: &ConsumerConfig,
    now_ns: i64,
    seed: u64,
) -> Vec<String> {
    let parser = JsonParser {
        string_fields: cfg.json_string_fields.clone(),
        time_key: cfg.json_time_key.clone(),
        time_format: Some("unix_ns".into()),
    };
    let mut tags = BTreeMap::new();
    tags.insert("host".to_string(), cfg.host.clone());
    tags.insert("topic".to_string(), topic.to_string());
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    parser
        .parse(payload, &tags, now_ns, &mut rng)
        .unwrap_or_default()
        .iter()
        .filter_map(to_line)
        .collect()
}

/// A fixed pipeline: `inputs.mqtt_consumer` on one topic -> `processors.execd` (`bin run`) ->
/// `outputs.mqtt` (topic `action`, `json_timestamp_units = "1ms"`), for a known number of
/// messages; then the child's stdin closes (EOF, as when Telegraf stops).
pub struct StandIn {
    child: Child,
    input: JoinHandle<usize>,
    output: JoinHandle<usize>,
    stderr: JoinHandle<Vec<String>>,
}

impl StandIn {
    /// Subscribe to `topic` on the broker at `port` (returns once subscribed) and feed the first
    /// `messages` messages to a new `bin run`.
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
        let stderr = child.stderr.take().unwrap();
        let stderr = std::thread::spawn(move || read_stderr(stderr).0);
        let output = std::thread::spawn(move || {
            let publisher = crate::mqtt_client::Publisher::connect(port, "telegraf-out");
            let mut published = 0usize;
            for line in BufReader::new(stdout).lines() {
                let line = line.unwrap();
                for m in parse_influx(&line, now_ns()).into_iter().flatten() {
                    if m.name == "action" {
                        publisher.publish("action", to_json(&m, MS));
                        published += 1;
                    }
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
                for line in message_to_lines(&topic, &payload, &cfg, now_ns(), fed as u64) {
                    stdin.write_all(line.as_bytes()).unwrap();
                }
                fed += 1;
            }
            fed
        });
        StandIn {
            child,
            input,
            output,
            stderr,
        }
    }

    /// Wait for the end: (messages fed to the processor, its exit status, actions published).
    pub fn finish(mut self) -> (usize, ExitStatus, usize) {
        let fed = self.input.join().unwrap();
        let status = self.child.wait().unwrap();
        let published = self.output.join().unwrap();
        let _ = self.stderr.join();
        (fed, status, published)
    }
}
