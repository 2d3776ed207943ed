//! The Telegraf version floor (1.33.3) and the tag escapes Telegraf does not undo, shown on the
//! real Telegraf: 1.33.2 (the last release below the floor, built by `tools/build-telegraf.sh`
//! for this test only) against the pinned 1.33.3 and 1.39.3, each running the real binary as
//! its `processors.execd` child, with a real Mosquitto; Telegraf's outputs go to its stdout.
//!
//! - Our output can hold lines longer than 256 KiB (the echo of a long record) and raw newlines
//!   inside string fields (the echo of what Telegraf's serializer writes: it escapes only `"`
//!   and `\` in string values). 1.33.3 and later read both whole; 1.30.0 to 1.33.2 read our
//!   stdout line by line with a 256 KiB cap, so the newline splits a record into two parse
//!   errors and the long line stops the reader for good.
//! - Telegraf's serializer writes a tab in a tag value as `\t`, its parser does not undo it: a
//!   tag with a tab comes back as a backslash and a `t`. (A topic cannot hold one: Mosquitto
//!   refuses control characters in topics.)

use crate::support::mqtt_client;
use crate::support::real_telegraf;

use crate::support::BIN;
use real_telegraf::{Telegraf, broker, wait_subscribed};
use std::time::{Duration, Instant};

/// The last release below the floor the README names.
const BELOW_FLOOR: &str = "v1.33.2";

/// A conf of the test's own: the robot's JSON on `tessla/#` in (with `note` kept as a string),
/// the bundled monitors as the execd child, every metric to Telegraf's stdout as `format`.
fn conf(port: u16, format: &str) -> String {
    format!(
        r#"[agent]
  interval = "1s"
  flush_interval = "100ms"
  omit_hostname = true
[[inputs.mqtt_consumer]]
  servers = ["tcp://127.0.0.1:{port}"]
  topics = ["tessla/#"]
  qos = 1
  client_id = "versions-in"
  data_format = "json"
  json_string_fields = ["actualSpeed", "note"]
  tag_keys = ["robot"]
[[processors.execd]]
  namepass = ["mqtt_consumer"]
  command = [{BIN:?}, "run"]
  restart_delay = "1s"
[[outputs.file]]
  files = ["stdout"]
  data_format = "{format}"
"#
    )
}

fn message(speed: f64, note: &str) -> Vec<u8> {
    serde_json::to_vec(&serde_json::json!({
        "expectedSpeed": speed,
        "actualSpeed": format!("{speed}"),
        "lidar": [1.0, 2.0, 3.0],
        "note": note,
    }))
    .unwrap()
}

/// What Telegraf `version` made of: a record whose string field holds a raw newline, one whose
/// echo is longer than 256 KiB, then a plain one. Returns (echoed records on stdout, actions
/// on stdout, Telegraf's log).
fn run(version: &str, bin: &std::path::Path) -> Option<(usize, usize, String)> {
    let broker = broker()?;
    let telegraf = Telegraf::start(version, bin, &conf(broker.port, "influx"), &[]);
    wait_subscribed(&broker, "versions-in", "tessla/#", 0);
    let publisher = mqtt_client::Publisher::connect(broker.port, "robot");
    publisher.publish("tessla/r1", message(0.1, "first line\nsecond line"));
    publisher.publish("tessla/r1", message(0.2, &"x".repeat(300 * 1024)));
    publisher.publish("tessla/r1", message(0.3, "plain"));
    // The monitor answers each at once; on the old reader nothing after the long line comes.
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline
        && telegraf
            .stdout()
            .lines()
            .filter(|l| l.starts_with("action"))
            .count()
            < 3
    {
        std::thread::sleep(Duration::from_millis(100));
    }
    let (log, out) = telegraf.stop_with_stdout();
    let echoed = out
        .lines()
        .filter(|l| l.starts_with("mqtt_consumer"))
        .count();
    let actions = out.lines().filter(|l| l.starts_with("action")).count();
    Some((echoed, actions, log))
}

#[test]
fn our_output_needs_the_streaming_reader_of_telegraf_1_33_3() {
    let Some(old) = real_telegraf::binary(BELOW_FLOOR) else {
        return;
    };
    let Some((echoed, actions, log)) = run(BELOW_FLOOR, &old) else {
        return;
    };
    // The raw newline: two halves, each a parse error; the long line: "token too long", and
    // Telegraf never reads our stdout again (the plain record after it is lost too).
    assert!(log.contains("metric parse error"), "{BELOW_FLOOR}:\n{log}");
    assert!(log.contains("token too long"), "{BELOW_FLOOR}:\n{log}");
    assert!(
        echoed < 3 && actions < 3,
        "{BELOW_FLOOR}: {echoed} echoed, {actions} actions\n{log}"
    );
    eprintln!(
        "Telegraf {BELOW_FLOOR}: of 3 records, {echoed} echoed and {actions} actions came back"
    );
    for (version, bin) in real_telegraf::versions() {
        let Some((echoed, actions, log)) = run(version, &bin) else {
            return;
        };
        assert_eq!((echoed, actions), (3, 3), "Telegraf {version}:\n{log}");
        assert!(
            !log.contains("metric parse error"),
            "Telegraf {version}:\n{log}"
        );
        assert!(
            !log.contains("token too long"),
            "Telegraf {version}:\n{log}"
        );
    }
}

#[test]
fn tag_escapes_telegraf_writes_but_does_not_read_back() {
    for (version, bin) in real_telegraf::versions() {
        let Some(broker) = broker() else { return };
        let telegraf = Telegraf::start(version, &bin, &conf(broker.port, "json"), &[]);
        wait_subscribed(&broker, "versions-in", "tessla/#", 0);
        let publisher = mqtt_client::Publisher::connect(broker.port, "robot");
        // Mosquitto refuses a topic with a control character (MQTT 3.1.1 4.7.3: it drops the
        // client), so the tab comes in a JSON value the parser makes a tag of (`tag_keys`).
        let mut m: serde_json::Value = serde_json::from_slice(&message(0.1, "n")).unwrap();
        m["robot"] = serde_json::json!("a\tb");
        publisher.publish("tessla/r1", serde_json::to_vec(&m).unwrap());
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline
            && !telegraf.stdout().lines().any(|l| l.contains("\"action\""))
        {
            std::thread::sleep(Duration::from_millis(100));
        }
        let (log, out) = telegraf.stop_with_stdout();
        let topics: Vec<String> = out
            .lines()
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
            .filter(|m| m["name"] == "mqtt_consumer")
            .filter_map(|m| m["tags"]["robot"].as_str().map(String::from))
            .collect();
        // Our echo: the bytes Telegraf wrote (`\t`), read back without unescaping.
        assert_eq!(
            topics,
            vec!["a\\tb".to_string()],
            "Telegraf {version}:\n{out}\n{log}"
        );
    }
}
