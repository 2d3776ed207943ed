//! A test-side stand-in for one Telegraf of `telegraf/fleet-nats/telegraf-p<N>.conf`, around the
//! real binary, speaking NATS through async-nats:
//!
//! - `inputs.nats_consumer` on `fleet.<N>.robots.*.telemetry` with a queue group of its own,
//!   `data_format = "json"`, `json_string_fields = ["actualSpeed"]`, `json_time_key = "time"`
//!   (`unix_ns`): measurement `mqtt_consumer` (`name_override`), tag `subject`; nested objects joined with `_`,
//!   arrays indexed, numbers as floats; written as Telegraf's influx serializer writes (tags
//!   sorted, shortest float form), `omit_hostname = true`;
//! - `processors.regex`: tag `robot` = the robot id of the subject;
//! - `processors.execd`: `tessla-telegraf run --instance-by robot --state nats://...`;
//! - `outputs.mqtt` through the gateway, `namepass = ["action"]`, `data_format = "json"`,
//!   `json_timestamp_units = "1ms"`: one message per action on `robots/<robot>/action`, i.e.
//!   NATS subject `robots.<robot>.action` (published here directly on that subject).
//!
//! Logs in as its sibling [`crate::nats_cluster`] says ([`crate::nats_cluster::Login`]);
//! bench/fleet_nats.rs uses both.

use influxdb_line_protocol::{FieldValue, parse_lines};
use serde_json::{Map, Value, json};
use std::collections::HashSet;
use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

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
        v => out.push((prefix.to_string(), v.clone())),
    }
}

fn escape(s: &str) -> String {
    s.replace(',', "\\,")
        .replace('=', "\\=")
        .replace(' ', "\\ ")
}

/// The robot id in `fleet.<N>.robots.<id>.telemetry` (processors.regex).
pub fn robot_of(subject: &str) -> Option<&str> {
    let mut parts = subject.split('.');
    let (Some("fleet"), Some(_), Some("robots"), Some(id), Some("telemetry"), None) = (
        parts.next(),
        parts.next(),
        parts.next(),
        parts.next(),
        parts.next(),
        parts.next(),
    ) else {
        return None;
    };
    Some(id)
}

/// The line the partition's Telegraf hands to the processor for one telemetry message.
pub fn telemetry_line(subject: &str, payload: &[u8]) -> Option<String> {
    let json: Value = serde_json::from_slice(payload).ok()?;
    let mut leaves = Vec::new();
    flatten("", &json, &mut leaves);
    let mut time = None;
    let mut fields = Vec::new();
    for (key, value) in leaves {
        if key == "time" {
            time = value.as_i64();
            continue;
        }
        let rendered = match value {
            Value::Number(n) => format!("{}", n.as_f64()?),
            Value::String(s) if key == "actualSpeed" => {
                format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
            }
            _ => continue,
        };
        fields.push((escape(&key), rendered));
    }
    if fields.is_empty() {
        return None;
    }
    fields.sort();
    let robot = robot_of(subject)?;
    let fields: Vec<String> = fields.iter().map(|(k, v)| format!("{k}={v}")).collect();
    Some(format!(
        "mqtt_consumer,robot={},subject={} {} {}",
        escape(robot),
        escape(subject),
        fields.join(","),
        time?
    ))
}

/// The robot and JSON message (`outputs.mqtt`, json, 1 ms) of one `action` line.
pub fn action_message(line: &str) -> Option<(String, String)> {
    if !line.starts_with("action,") {
        return None;
    }
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
    let robot = tags.get("robot")?.as_str()?.to_string();
    let message = json!({
        "fields": fields,
        "name": "action",
        "tags": tags,
        "timestamp": parsed.timestamp? / 1_000_000,
    });
    Some((robot, message.to_string()))
}

/// One published action: when, on which robot's subject, the JSON message.
pub type Published = (Instant, String, String);

/// What a stand-in has done so far, readable while it runs.
#[derive(Default)]
struct Progress {
    /// Records written to the processor's stdin.
    fed: AtomicUsize,
    /// Actions published.
    published: AtomicUsize,
    /// The last record written to the processor's stdin, and every line it wrote back.
    last_fed: Mutex<Option<String>>,
    written_back: Mutex<HashSet<String>>,
}

/// A running stand-in Telegraf of one partition.
pub struct NatsStandIn {
    pub name: String,
    child: Child,
    progress: Arc<Progress>,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    input: Option<JoinHandle<usize>>,
    output: Option<JoinHandle<Vec<Published>>>,
    stderr: Option<JoinHandle<String>>,
}

impl NatsStandIn {
    /// Subscribe (returns once subscribed) and start `bin run ARGS` fed from the subscription.
    pub fn start(
        bin: &str,
        name: &str,
        nats_url: &str,
        partition: usize,
        args: &[String],
        login: &crate::nats_cluster::Login,
    ) -> NatsStandIn {
        let login = login.clone();
        let mut child = Command::new(bin)
            .arg("run")
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut stdin = child.stdin.take().unwrap();
        let stdout = child.stdout.take().unwrap();
        let mut stderr = child.stderr.take().unwrap();
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let (lines_tx, lines_rx) = mpsc::channel::<String>();
        let (ready_tx, ready_rx) = mpsc::channel::<async_nats::Client>();
        let url = nats_url.to_string();
        let subject = format!("fleet.{partition}.robots.*.telemetry");
        let queue = format!("tessla-p{partition}-{name}");
        // nats_consumer: the subscription, on a runtime thread of its own.
        std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap();
            rt.block_on(async move {
                use futures_util::StreamExt;
                let client = login.connect(url.as_str()).await.unwrap();
                let mut sub = client.queue_subscribe(subject, queue).await.unwrap();
                client.flush().await.unwrap();
                ready_tx.send(client.clone()).unwrap();
                let mut stopped = stopped;
                loop {
                    tokio::select! {
                        m = sub.next() => {
                            let Some(m) = m else { break };
                            if let Some(line) = telemetry_line(m.subject.as_str(), &m.payload)
                                && lines_tx.send(line).is_err()
                            {
                                break;
                            }
                        }
                        _ = &mut stopped => break,
                    }
                }
            });
        });
        let client = ready_rx
            .recv_timeout(Duration::from_secs(30))
            .expect("stand-in subscribed");
        let progress = Arc::new(Progress::default());
        let fed_progress = Arc::clone(&progress);
        let input = std::thread::spawn(move || {
            for line in lines_rx {
                if stdin.write_all(line.as_bytes()).is_err() || stdin.write_all(b"\n").is_err() {
                    break;
                }
                *fed_progress.last_fed.lock().unwrap() = Some(line);
                fed_progress.fed.fetch_add(1, Ordering::SeqCst);
            }
            fed_progress.fed.load(Ordering::SeqCst)
        });
        let out_progress = Arc::clone(&progress);
        // outputs.mqtt: each action on its robot's subject.
        let output = std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap();
            let mut published = Vec::new();
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                let action = action_message(&line);
                out_progress.written_back.lock().unwrap().insert(line);
                if let Some((robot, message)) = action {
                    let subject = format!("robots.{robot}.action");
                    rt.block_on(async {
                        let _ = client.publish(subject, message.clone().into()).await;
                        let _ = client.flush().await;
                    });
                    published.push((Instant::now(), robot, message));
                    out_progress.published.fetch_add(1, Ordering::SeqCst);
                }
            }
            published
        });
        let stderr = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = stderr.read_to_string(&mut s);
            s
        });
        NatsStandIn {
            name: name.to_string(),
            child,
            progress,
            stop: Some(stop),
            input: Some(input),
            output: Some(output),
            stderr: Some(stderr),
        }
    }

    /// Records written to the processor so far.
    pub fn fed(&self) -> usize {
        self.progress.fed.load(Ordering::SeqCst)
    }

    /// Actions published so far.
    pub fn published(&self) -> usize {
        self.progress.published.load(Ordering::SeqCst)
    }

    /// Whether the processor has written back (passed through) the last record fed to it, i.e.
    /// stepped every record it was given (a standby writes back nothing until it takes over).
    pub fn caught_up(&self) -> bool {
        let last = self.progress.last_fed.lock().unwrap().clone();
        last.is_some_and(|l| self.progress.written_back.lock().unwrap().contains(&l))
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Send `signal` (`KILL`, `TERM`) to the processor, as a machine dying or Telegraf stopping.
    pub fn signal(&self, signal: &str) {
        let ok = Command::new("kill")
            .args([format!("-{signal}"), self.child.id().to_string()])
            .status()
            .unwrap()
            .success();
        assert!(ok, "kill -{signal} {}", self.child.id());
    }

    /// Stop consuming and close the processor's stdin (Telegraf's stop); wait for its end:
    /// (exit status, records fed, actions published, stderr).
    pub fn finish(mut self) -> (ExitStatus, usize, Vec<Published>, String) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        let fed = self.input.take().unwrap().join().unwrap();
        let status = self.child.wait().unwrap();
        let published = self.output.take().unwrap().join().unwrap();
        let stderr = self.stderr.take().unwrap().join().unwrap();
        (status, fed, published, stderr)
    }
}

impl Drop for NatsStandIn {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
