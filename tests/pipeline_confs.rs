//! Every shipped `.conf`, read whole, run end to end through the Telegraf stand-in (which
//! follows Telegraf's code, see its header): the robot's JSON over a real Mosquitto, the real
//! binary as `processors.execd` or over UDP, actions back over MQTT and every metric into a real
//! InfluxDB 1.x. Checks what the robot receives (Telegraf's exact JSON, one action per message,
//! on its own topic), what InfluxDB stores, what Telegraf would log from our stderr, and that the
//! UDP wiring cannot loop. Also the stand-in's own pieces against Telegraf's behaviour.

#[path = "support/mqtt_client.rs"]
mod mqtt_client;
#[path = "support/recorded.rs"]
mod recorded;
#[path = "support/servers.rs"]
mod servers;
#[path = "support/telegraf_standin.rs"]
mod telegraf_standin;

use rand::SeedableRng;
use recorded::BIN;
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::process::{Command, Stdio};
use std::time::Duration;
use telegraf_standin::*;

const RECORDS: usize = 30;

fn conf_text(name: &str) -> String {
    std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("telegraf")
            .join(name),
    )
    .unwrap()
}

/// The shipped conf `name` as a test runs it: the monitors' `--state` files in `dir` instead of
/// the systemd drop-in's StateDirectory (each test its own, as tests run at once).
fn runnable(name: &str, dir: &tempfile::TempDir) -> String {
    let text = conf_text(name);
    assert!(
        text.contains("\"--state\", \"/var/lib/tessla-telegraf/"),
        "{name} keeps the monitors' state"
    );
    text.replace(
        "/var/lib/tessla-telegraf/",
        &format!("{}/", dir.path().display()),
    )
}

fn endpoints(port: u16, influx: Option<&servers::Influxd>) -> Endpoints {
    Endpoints {
        mqtt_port: port,
        influx_url: influx.map(|i| i.url("")),
        udp: Vec::new(),
        programs: vec![("/usr/bin/tessla-telegraf".into(), BIN.into())],
        host: "robot-pc".into(),
        seed: 7,
    }
}

/// The first `n` records of the recorded run, as a file `replay` reads.
fn head(dir: &tempfile::TempDir, n: usize) -> std::path::PathBuf {
    let text = std::fs::read_to_string(recorded::recorded_run_path()).unwrap();
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .take(n)
        .collect();
    let path = dir.path().join("head.lp");
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    path
}

/// Publish the file's records as the robot's JSON messages on `topic`, as fast as possible.
fn replay(path: &std::path::Path, port: u16, topic: &str) {
    let out = Command::new(BIN)
        .args(["replay", path.to_str().unwrap()])
        .args(["--broker", &format!("mqtt://127.0.0.1:{port}")])
        .args(["--topic", topic, "--speed", "0"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "replay: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn influx_count(influx: &servers::Influxd, q: &str) -> Vec<(Value, i64)> {
    let (status, v) = influx.query(Some("telegraf"), q);
    assert_eq!(status, 200, "{v}");
    v["results"][0]["series"]
        .as_array()
        .map(|series| {
            series
                .iter()
                .map(|s| (s["tags"].clone(), s["values"][0][1].as_i64().unwrap()))
                .collect()
        })
        .unwrap_or_default()
}

/// The robot's actions: each payload exactly as Telegraf's JSON serializer writes it.
fn actions(rx: &std::sync::mpsc::Receiver<(std::time::Instant, Vec<u8>)>, n: usize) -> Vec<Value> {
    mqtt_client::collect(rx, n, Duration::from_secs(20))
        .into_iter()
        .map(|(_, p)| {
            let text = String::from_utf8(p).unwrap();
            assert!(text.starts_with("{\"fields\":{"), "{text}");
            assert!(
                text.ends_with("}\n"),
                "one JSON object and a newline: {text:?}"
            );
            assert!(text.contains("},\"name\":\"action\",\"tags\":{"), "{text}");
            serde_json::from_str(&text).unwrap()
        })
        .collect()
}

/// Telegraf >= 1.37 logs our stderr at the levels we give; a clean run says only where its
/// `--state` started from (a fresh start or the instances restored), its save at the end, and
/// the summary.
fn assert_quiet(stats: &Stats, records: usize) {
    assert_eq!(stats.stderr.len(), 3, "{:?}", stats.stderr);
    let (level, msg) = &stats.stderr[0];
    assert_eq!(*level, 'I');
    assert!(
        msg.starts_with("state: ")
            && (msg.ends_with(" does not exist yet; starting fresh")
                || msg.contains(": restored ")
                || msg.starts_with("state: restored ")),
        "{msg}"
    );
    let (level, msg) = &stats.stderr[1];
    assert_eq!(*level, 'I');
    assert!(msg.starts_with("state: saved "), "{msg}");
    let (level, msg) = &stats.stderr[2];
    assert_eq!(*level, 'I');
    assert!(
        msg.starts_with(&format!("summary: {records} records,")),
        "{msg}"
    );
    assert!(msg.contains(" 0 parse errors, 0 late records,"), "{msg}");
}

#[test]
fn main_conf_as_shipped_end_to_end() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let Some(influx) = servers::Influxd::start() else {
        return;
    };
    let env = endpoints(broker.port, Some(&influx));
    let dir = tempfile::tempdir().unwrap();
    let conf = Conf::read(&runnable("telegraf.conf", &dir), &env);
    let robot = mqtt_client::subscribe(broker.port, "action", "robot");
    let telegraf = Telegraf::start(&conf, &env);
    let t0 = now_ns();
    replay(&head(&dir, RECORDS), broker.port, "tessla");
    let got = actions(&robot, RECORDS);
    let t1 = now_ns();
    let stats = telegraf.stop();
    assert!(stats.child_status.is_some_and(|s| s.success()));
    assert_eq!(got.len(), RECORDS, "one action per robot message");
    for a in &got {
        // Processor-made metrics carry only the tags the child wrote: none here.
        assert_eq!(a["tags"], json!({}));
        // No json_time_key: the time Telegraf parsed the message, in ms (json_timestamp_units).
        let ms = a["timestamp"].as_i64().unwrap();
        assert!(
            ms >= t0 / MS && ms <= t1 / MS,
            "{ms} not in [{t0}, {t1}] ns"
        );
        assert!(a["fields"]["speed"].is_number() && a["fields"]["augmented"].is_boolean());
    }
    // What a robot needs to refuse a stale or repeated action: its sequence number in order,
    // and the time it is valid until, 400 ms after the action's (ns; the timestamp is in ms).
    for (i, a) in got.iter().enumerate() {
        assert_eq!(a["fields"]["seq"], i + 1, "{a}");
        let until = a["fields"]["valid_until"].as_i64().unwrap();
        let ms = a["timestamp"].as_i64().unwrap();
        assert!(
            (0..MS).contains(&(until - 400_000_000 - ms * MS)),
            "{until} vs {ms} ms: {a}"
        );
    }
    let distinct: std::collections::BTreeSet<i64> = got
        .iter()
        .map(|a| a["timestamp"].as_i64().unwrap())
        .collect();
    assert!(distinct.len() > 1, "ms units tell actions apart");
    assert_quiet(&stats, RECORDS);
    // The robot metric (passed through once), the verdicts and the action, each point once.
    let robot_points = influx_count(&influx, "SELECT count(expectedSpeed) FROM mqtt_consumer");
    assert_eq!(robot_points[0].1, RECORDS as i64);
    assert_eq!(robot_points[0].0, Value::Null);
    let action_points = influx_count(&influx, "SELECT count(speed) FROM action");
    assert_eq!(action_points[0].1, RECORDS as i64);
    let verdicts = influx_count(&influx, "SELECT count(p2_violated) FROM tessla");
    assert_eq!(verdicts[0].1, RECORDS as i64);
}

#[test]
fn main_conf_with_the_robots_time_rounds_as_telegraf() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let Some(influx) = servers::Influxd::start() else {
        return;
    };
    let env = endpoints(broker.port, Some(&influx));
    // The variant the conf's comment describes.
    let dir = tempfile::tempdir().unwrap();
    let text = runnable("telegraf.conf", &dir).replace(
        "  json_string_fields = [\"actualSpeed\"]\n",
        "  json_string_fields = [\"actualSpeed\"]\n  json_time_key = \"time\"\n  json_time_format = \"unix_ns\"\n",
    );
    let conf = Conf::read(&text, &env);
    let robot = mqtt_client::subscribe(broker.port, "action", "robot");
    let telegraf = Telegraf::start(&conf, &env);
    let publisher = mqtt_client::Publisher::connect(broker.port, "robot-pub");
    // 129 ns past a multiple of 256: float64 rounds it up to the next multiple.
    let message = |i: usize, ns: i64| {
        format!(r#"{{"expectedSpeed":0.{i}5,"actualSpeed":"0.{i}4","lidar":[1,2,3],"time":{ns}}}"#)
            .into_bytes()
    };
    publisher.publish("tessla", message(0, 1_700_000_000_000_000_129));
    publisher.publish("tessla", message(1, 1_700_000_000_200_000_001));
    // The second message again, as QoS 1 redelivers it: Telegraf parses it again (another field
    // order), the monitor drops the exact duplicate.
    publisher.publish("tessla", message(1, 1_700_000_000_200_000_001));
    let got = actions(&robot, 2);
    let stats = telegraf.stop();
    assert_eq!(got.len(), 2);
    assert!(
        robot.recv_timeout(Duration::from_secs(1)).is_err(),
        "no action for the duplicate"
    );
    assert_eq!(got[0]["timestamp"], 1_700_000_000_000i64);
    assert_eq!(got[1]["timestamp"], 1_700_000_000_200i64);
    let (level, summary) = stats.stderr.last().unwrap();
    assert_eq!(*level, 'I');
    assert!(
        summary.starts_with("summary: 3 records,") && summary.ends_with(", 1 duplicates"),
        "{summary}"
    );
    assert!(stats.stderr.iter().all(|(l, _)| *l == 'I' || *l == 'W'));
    let (_, v) = influx.query(Some("telegraf"), "SELECT expectedSpeed FROM mqtt_consumer");
    let times: Vec<i64> = v["results"][0]["series"][0]["values"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r[0].as_i64().unwrap())
        .collect();
    assert_eq!(
        times,
        vec![1_700_000_000_000_000_256, 1_700_000_000_200_000_000]
    );
}

#[test]
fn fleet_conf_as_shipped_end_to_end() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let Some(influx) = servers::Influxd::start() else {
        return;
    };
    let env = endpoints(broker.port, Some(&influx));
    let dir = tempfile::tempdir().unwrap();
    let conf = Conf::read(&runnable("telegraf-fleet.conf", &dir), &env);
    let robots = ["tessla/r1", "tessla/r2", "tessla/r3"];
    let inboxes: Vec<_> = robots
        .iter()
        .map(|r| mqtt_client::subscribe(broker.port, &format!("{r}/action"), r))
        .collect();
    // Anything on the wrong topic would land here.
    let stray = mqtt_client::subscribe(broker.port, "#", "watcher");
    let telegraf = Telegraf::start(&conf, &env);
    let file = head(&dir, 10);
    for r in robots {
        replay(&file, broker.port, r);
    }
    for (r, inbox) in robots.iter().zip(&inboxes) {
        let got = actions(inbox, 10);
        assert_eq!(got.len(), 10, "{r}");
        for a in got {
            assert_eq!(a["tags"], json!({ "topic": r }));
        }
    }
    let stats = telegraf.stop();
    assert_quiet(&stats, 30);
    assert!(
        stats.stderr[2].1.ends_with(", 3 instances, 0 evicted"),
        "{:?}",
        stats.stderr
    );
    assert!(
        stats.stderr[1]
            .1
            .starts_with("state: saved 3 monitor instances"),
        "{:?}",
        stats.stderr
    );
    let topics: std::collections::BTreeSet<String> = std::iter::from_fn(|| {
        stray
            .recv_timeout(Duration::from_millis(300))
            .ok()
            .map(|(_, p)| p)
    })
    .filter_map(|p| serde_json::from_slice::<Value>(&p).ok())
    .filter(|v| v["name"] == "action")
    .map(|v| v["tags"]["topic"].as_str().unwrap_or("").to_string())
    .collect();
    assert_eq!(topics.len(), 3, "{topics:?}");
    let per_robot = influx_count(&influx, "SELECT count(speed) FROM action GROUP BY topic");
    assert_eq!(per_robot.len(), 3);
    for (tags, n) in per_robot {
        assert_eq!(n, 10, "{tags}");
    }
    // An action without a `topic` tag is not published (Telegraf would use "/action").
    let mut m = Metric {
        name: "action".into(),
        tags: BTreeMap::new(),
        fields: vec![("speed".into(), Field::Float(0.1))],
        time: 1,
    };
    assert!(conf.mqtt_topics(&m).is_empty());
    assert_eq!(
        render_topic("{{ .Tag \"topic\" }}/action", &m),
        "/action",
        "what Telegraf would do without the tagpass"
    );
    m.tags.insert("topic".into(), "tessla/r9".into());
    assert_eq!(conf.mqtt_topics(&m), vec!["tessla/r9/action".to_string()]);
}

/// The UDP-mode monitor, killed if the test fails before it stops it.
struct Monitor(std::process::Child);

impl Drop for Monitor {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn udp_conf_as_shipped_end_to_end_and_loop_free() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let Some(influx) = servers::Influxd::start() else {
        return;
    };
    let monitor_addr = format!("127.0.0.1:{}", servers::free_port());
    let telegraf_addr = format!("127.0.0.1:{}", servers::free_port());
    let mut env = endpoints(broker.port, Some(&influx));
    env.udp = vec![
        ("udp://127.0.0.1:1653".into(), monitor_addr.clone()),
        ("udp://127.0.0.1:1654".into(), telegraf_addr.clone()),
    ];
    let text = conf_text("telegraf-udp.conf");
    // The command the conf's header gives, on the test's ports and with its state in a temp dir.
    let header = "tessla-telegraf run --udp-listen 127.0.0.1:1653 --udp-send 127.0.0.1:1654 \
                  --state /var/lib/tessla-telegraf/telegraf-udp.state --state-interval 30s";
    assert!(text.contains(header));
    let conf = Conf::read(&text, &env);
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("telegraf-udp.state");
    let mut monitor = Monitor(
        Command::new(BIN)
            .args(["run", "--udp-listen", &monitor_addr])
            .args(["--udp-send", &telegraf_addr])
            .arg("--state")
            .arg(&state)
            .args(["--state-interval", "30s"])
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let robot = mqtt_client::subscribe(broker.port, "action", "robot");
    let telegraf = Telegraf::start(&conf, &env);
    replay(&head(&dir, RECORDS), broker.port, "tessla");
    let got = actions(&robot, RECORDS);
    assert_eq!(got.len(), RECORDS);
    // Routed as Telegraf routes: nothing keeps circulating. The socket_writer sent each robot
    // metric once, and a little later still has.
    let mut outputs = telegraf.delivered();
    while outputs[1] < 3 * RECORDS {
        std::thread::sleep(Duration::from_millis(50));
        outputs = telegraf.delivered();
    }
    // The robot has stopped: max_silence (1 s) + the allowed lateness (250 ms) after its last
    // message, the link's verdict `robot_silent=true` arrives, once, on the socket_listener's
    // route (to InfluxDB, not to the robot).
    std::thread::sleep(Duration::from_millis(1500));
    let settled = telegraf.delivered();
    assert_eq!(
        settled,
        vec![outputs[0], outputs[1] + 1, outputs[2]],
        "the silence verdict, once"
    );
    std::thread::sleep(Duration::from_millis(1500));
    assert_eq!(
        telegraf.delivered(),
        settled,
        "metrics still flowing: a loop"
    );
    let stats = telegraf.stop();
    // Conf order: mqtt (actions), influxdb (all), socket_writer (robot metrics).
    assert_eq!(stats.delivered[0], RECORDS);
    assert_eq!(stats.delivered[2], RECORDS);
    // Robot metrics + verdicts + actions, each once, and the silence verdict: no echo comes
    // back in UDP mode.
    assert_eq!(stats.delivered[1], 3 * RECORDS + 1);
    // Even an echoed robot metric would stop at the socket_listener.
    let echoed = Metric {
        name: "mqtt_consumer".into(),
        tags: BTreeMap::new(),
        fields: vec![("expectedSpeed".into(), Field::Float(0.1))],
        time: 1,
    };
    assert!(conf.input_accepts(0, &echoed));
    assert!(!conf.input_accepts(1, &echoed));
    Command::new("kill")
        .args(["-TERM", &monitor.0.id().to_string()])
        .status()
        .unwrap();
    let status = monitor.0.wait().unwrap();
    let mut err = String::new();
    std::io::Read::read_to_string(&mut monitor.0.stderr.take().unwrap(), &mut err).unwrap();
    assert!(status.success(), "{err}");
    assert!(err.contains("I! state: saved 1 monitor instances"), "{err}");
    assert!(state.exists());
    assert!(
        err.contains(&format!("summary: {RECORDS} records,")),
        "{err}"
    );
    let robot_points = influx_count(&influx, "SELECT count(expectedSpeed) FROM mqtt_consumer");
    assert_eq!(robot_points[0].1, RECORDS as i64);
}

#[test]
fn every_shipped_conf_is_read_whole_and_sets_the_guarantees() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("telegraf");
    let mut n = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "conf") {
            continue;
        }
        n += 1;
        let text = std::fs::read_to_string(&path).unwrap();
        let mut env = endpoints(1883, None);
        env.udp = vec![
            ("udp://127.0.0.1:1653".into(), "127.0.0.1:1653".into()),
            ("udp://127.0.0.1:1654".into(), "127.0.0.1:1654".into()),
        ];
        // Every key known to the stand-in (it panics on any other).
        Conf::read(&text, &env);
        let v: toml::Value = toml::from_str(&text).unwrap();
        let name = path.display();
        for c in v["inputs"]["mqtt_consumer"].as_array().unwrap() {
            assert_eq!(c["qos"].as_integer(), Some(1), "{name}");
            assert_eq!(c["persistent_session"].as_bool(), Some(true), "{name}");
            assert!(
                c["client_id"].as_str().is_some_and(|s| !s.is_empty()),
                "{name}"
            );
        }
        for o in v["outputs"]["mqtt"].as_array().unwrap() {
            assert_eq!(o["qos"].as_integer(), Some(1), "{name}");
            assert_eq!(o["json_timestamp_units"].as_str(), Some("1ms"), "{name}");
        }
        if let Some(execd) = v.get("processors").and_then(|p| p.get("execd")) {
            check_execd(&execd[0], "1s", 50_000, &name.to_string());
        }
    }
    assert_eq!(n, 3);
}

/// An execd block as the README's guarantees need it: an absolute command path (systemd's
/// PATH), the restart_delay chosen for 5 Hz, and with --instance-by a --max-instances whose
/// save at a stop fits Telegraf's budget (README, "Restarts and reloads").
fn check_execd(execd: &toml::Value, delay: &str, max_instances: u64, name: &str) {
    let cmd: Vec<&str> = execd["command"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap())
        .collect();
    assert_eq!(cmd[0], "/usr/bin/tessla-telegraf", "{name}");
    assert_eq!(execd["restart_delay"].as_str(), Some(delay), "{name}");
    if cmd.contains(&"--instance-by") {
        let at = cmd.iter().position(|a| *a == "--max-instances");
        let n: u64 = at
            .and_then(|i| cmd.get(i + 1))
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("{name}: --max-instances is set"));
        assert!(n <= max_instances, "{name}: {n}");
    }
}

#[test]
fn the_nats_confs_bound_what_a_stop_saves() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("telegraf/fleet-nats");
    let mut n = 0;
    for part in ["telegraf-p0.conf", "telegraf-p1.conf"] {
        let text = std::fs::read_to_string(dir.join(part)).unwrap();
        let v: toml::Value = toml::from_str(&text).unwrap();
        check_execd(&v["processors"]["execd"][0], "2s", 10_000, part);
        n += 1;
    }
    assert_eq!(n, 2);
}

// ------------------------------------------------------------ the stand-in against Telegraf

fn parse(payload: &str, keep: &[&str], time_key: Option<&str>) -> Result<Vec<Metric>, String> {
    let parser = JsonParser {
        string_fields: keep.iter().map(|s| s.to_string()).collect(),
        time_key: time_key.map(str::to_string),
        time_format: time_key.map(|_| "unix_ns".to_string()),
    };
    let mut tags = BTreeMap::new();
    tags.insert("topic".to_string(), "t".to_string());
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    parser.parse(payload.as_bytes(), &tags, 5, &mut rng)
}

fn sorted_line(m: &Metric) -> String {
    let mut m = m.clone();
    m.fields.sort_by(|a, b| a.0.cmp(&b.0));
    to_line(&m).unwrap()
}

#[test]
fn json_parser_as_telegraf() {
    let ms = parse(
        r#"{"expectedSpeed":0.1,"actualSpeed":"0.05","mode":"auto","ok":true,
            "lidar":[0.5,null,2],"pose":{"x":1},"a b=c,d":3,"time":1700000000000000000}"#,
        &["actualSpeed", "o?"],
        Some("time"),
    )
    .unwrap();
    assert_eq!(
        sorted_line(&ms[0]),
        "mqtt_consumer,topic=t a\\ b\\=c\\,d=3,actualSpeed=\"0.05\",expectedSpeed=0.1,lidar_0=0.5,lidar_2=2,ok=true,pose_x=1 1700000000000000000\n"
    );
    // Without json_time_key: the parse time.
    let ms = parse(r#"{"a":1}"#, &[], None).unwrap();
    assert_eq!(ms[0].time, 5);
    // A top-level array: one metric per object; anything else in it fails the message.
    let ms = parse(r#"[{"a":1},{"a":2,"b":3}]"#, &[], None).unwrap();
    assert_eq!(ms.len(), 2);
    assert_eq!(sorted_line(&ms[1]), "mqtt_consumer,topic=t a=2,b=3 5\n");
    assert!(parse(r#"[{"a":1},2]"#, &[], None).is_err());
    // NaN and Infinity are not JSON: Telegraf drops the whole message.
    assert!(parse(r#"{"a":NaN,"b":1}"#, &[], None).is_err());
    assert!(parse(r#"{"a":Infinity}"#, &[], None).is_err());
    // With json_time_key, a message without the key is dropped.
    assert!(parse(r#"{"a":1}"#, &[], Some("time")).is_err());
    // Filters: exact names unless a pattern holds `*`, `?` or `[`.
    let f = NameFilter::new(&["lidar_[0-2]".to_string(), "*Speed".to_string()]);
    assert!(f.matches("lidar_1") && !f.matches("lidar_3") && f.matches("actualSpeed"));
    assert!(!NameFilter::new(&["{a,b}".to_string()]).matches("a"));
}

#[test]
fn field_order_is_go_map_order() {
    let payload = r#"{"a":1,"b":2,"c":3,"d":4,"e":5,"f":6,"g":7,"h":8}"#;
    let orders: std::collections::BTreeSet<Vec<String>> = (0..20)
        .map(|seed| {
            let cfg = ConsumerConfig {
                host: "h".into(),
                json_string_fields: Vec::new(),
                json_time_key: None,
            };
            let line = &message_to_lines("t", payload.as_bytes(), &cfg, 1, seed)[0];
            line.split(' ')
                .nth(1)
                .unwrap()
                .split(',')
                .map(str::to_string)
                .collect()
        })
        .collect();
    assert!(orders.len() > 10, "fields shuffled per message");
}

#[test]
fn float64_times_round_as_telegraf() {
    let t = |v: Value| parse_unix_time("unix_ns", &v).unwrap();
    // Spacing of float64 near 1.7e18 is 256 ns.
    assert_eq!(
        t(json!(1_700_000_000_000_000_127i64)),
        1_700_000_000_000_000_000
    );
    assert_eq!(
        t(json!(1_700_000_000_000_000_129i64)),
        1_700_000_000_000_000_256
    );
    assert_eq!(t(json!("1700000000000000129")), 1_700_000_000_000_000_129);
    assert_eq!(
        parse_unix_time("unix_ms", &json!(1_700_000_000_123i64)).unwrap(),
        1_700_000_000_123_000_000
    );
    assert_eq!(parse_unix_time("unix", &json!(1.5)).unwrap(), 1_500_000_000);
}

#[test]
fn json_serializer_as_telegraf() {
    let m = Metric {
        name: "action".into(),
        tags: [("topic".to_string(), "a<b".to_string())].into(),
        fields: vec![
            ("speed".into(), Field::Float(2.0)),
            ("augmented".into(), Field::Bool(true)),
            ("tiny".into(), Field::Float(1e-7)),
            ("huge".into(), Field::Float(1e21)),
            ("n".into(), Field::Int(-3)),
            ("note".into(), Field::Str("say \"hi\"\n&".into())),
            ("nan".into(), Field::Float(f64::NAN)),
        ],
        time: 1_500_999_999,
    };
    assert_eq!(
        String::from_utf8(to_json(&m, MS)).unwrap(),
        "{\"fields\":{\"augmented\":true,\"huge\":1e+21,\"n\":-3,\"note\":\"say \\\"hi\\\"\\n\\u0026\",\"speed\":2,\"tiny\":1e-7},\"name\":\"action\",\"tags\":{\"topic\":\"a\\u003cb\"},\"timestamp\":1500}\n"
    );
    assert_eq!(timestamp_units(None), 1_000_000_000);
    assert_eq!(timestamp_units(Some("1ms")), MS);
    assert_eq!(timestamp_units(Some("25ms")), 10 * MS);
    assert_eq!(go_float(0.000001), "0.000001");
    assert_eq!(go_float(123456.5), "123456.5");
}

#[test]
fn influx_serializer_escapes_as_telegraf() {
    let m = Metric {
        name: "a b,c=d".into(),
        tags: [("k ey".to_string(), "v=1\\".to_string())].into(),
        fields: vec![
            ("f\tx".into(), Field::Str("q\"\\".into())),
            ("u".into(), Field::UInt(u64::MAX)),
            ("nan".into(), Field::Float(f64::NAN)),
        ],
        time: 3,
    };
    assert_eq!(
        to_line(&m).unwrap(),
        "a\\ b\\,c=d,k\\ ey=v\\=1 f\\tx=\"q\\\"\\\\\",u=9223372036854775807i 3\n"
    );
    let empty = Metric {
        fields: vec![("nan".into(), Field::Float(f64::NAN))],
        ..m
    };
    assert_eq!(to_line(&empty), None);
}

#[test]
fn our_longest_stderr_line_passes_telegrafs_reader() {
    // Telegraf's reader stops for good at a line of 64 KiB or more.
    let (lines, stopped) = read_stderr(
        &[
            b"E! short\n".as_slice(),
            &vec![b'x'; 70_000],
            b"\nI! lost\n",
        ]
        .concat()[..],
    );
    assert!(stopped);
    assert_eq!(lines, vec!["E! short".to_string()]);
    // A message of 100 KB (a bad --tag quotes it) is cut below the limit, and what follows is read.
    let long = "v".repeat(100_000);
    let out = Command::new(BIN)
        .args(["run", "--tag", &long])
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert_ne!(out.status.code(), Some(0));
    let (lines, stopped) = read_stderr(&out.stderr[..]);
    assert!(!stopped, "Telegraf would stop reading our stderr");
    assert!(!lines.is_empty());
    assert!(
        lines
            .iter()
            .all(|l| l.len() < 65_536 && stderr_log(l).0 == 'E'),
        "{}",
        lines.len()
    );
}

#[test]
fn the_routing_catches_the_loop_of_the_old_udp_wiring() {
    // The control for the test above: the UDP conf without its namedrop, and a monitor that
    // echoes its input (what pass-through did): one robot message circulates for ever.
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let echo = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let telegraf_addr = format!("127.0.0.1:{}", servers::free_port());
    let mut env = endpoints(broker.port, None);
    env.udp = vec![
        (
            "udp://127.0.0.1:1653".into(),
            echo.local_addr().unwrap().to_string(),
        ),
        ("udp://127.0.0.1:1654".into(), telegraf_addr.clone()),
    ];
    let text = conf_text("telegraf-udp.conf").replace("  namedrop = [\"mqtt_consumer\"]\n", "");
    let conf = Conf::read(&text, &env);
    let telegraf = Telegraf::start(&conf, &env);
    echo.set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let stop2 = stop.clone();
    let echoer = std::thread::spawn(move || {
        let mut buf = vec![0u8; 65_536];
        while !stop2.load(std::sync::atomic::Ordering::Relaxed) {
            if let Ok(n) = echo.recv(&mut buf) {
                let _ = echo.send_to(&buf[..n], &telegraf_addr);
            }
        }
    });
    let publisher = mqtt_client::Publisher::connect(broker.port, "robot-pub");
    publisher.publish("tessla", br#"{"expectedSpeed":0.1}"#.to_vec());
    std::thread::sleep(Duration::from_millis(1000));
    let sent = telegraf.delivered()[1];
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    echoer.join().unwrap();
    telegraf.stop();
    assert!(sent > 50, "one message sent {sent} times: the loop");
}

#[test]
fn main_conf_gets_what_the_robot_sent_while_telegraf_was_away() {
    // QoS 1, persistent session, fixed client id: the broker keeps the robot's messages for
    // Telegraf while it is stopped and hands them over when it is back.
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let env = endpoints(broker.port, None);
    let dir = tempfile::tempdir().unwrap();
    let conf = Conf::read(&runnable("telegraf.conf", &dir), &env);
    let robot = mqtt_client::subscribe(broker.port, "action", "robot");
    let file = head(&dir, 5);
    // The first start makes the session; then Telegraf goes away.
    Telegraf::start(&conf, &env).stop();
    replay(&file, broker.port, "tessla");
    let telegraf = Telegraf::start(&conf, &env);
    let got = actions(&robot, 5);
    let stats = telegraf.stop();
    assert_eq!(got.len(), 5, "every message sent while Telegraf was away");
    assert_quiet(&stats, 5);
    // Without the persistent session (Telegraf's default) they are lost.
    let text = runnable("telegraf.conf", &dir)
        .replace("persistent_session = true", "persistent_session = false");
    let conf = Conf::read(&text, &env);
    Telegraf::start(&conf, &env).stop();
    replay(&file, broker.port, "tessla");
    let telegraf = Telegraf::start(&conf, &env);
    std::thread::sleep(Duration::from_millis(500));
    let stats = telegraf.stop();
    assert!(robot.recv_timeout(Duration::from_millis(500)).is_err());
    assert_eq!(stats.to_processor, 0);
}
