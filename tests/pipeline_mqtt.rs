//! The MQTT round trip with real Mosquitto: `replay` publishes the recorded run on `tessla`; a
//! stand-in for Telegraf's mqtt_consumer turns each message into the line Telegraf would make
//! and pipes it into `tessla-telegraf run`; the `action` metrics go back out as outputs.mqtt
//! would publish them; the test, subscribed to `action`, gets every corrective action, in
//! order, with the values our binary computes for the recorded run directly.

#[path = "support/mqtt_client.rs"]
mod mqtt_client;
#[path = "support/recorded.rs"]
mod recorded;
#[path = "support/servers.rs"]
mod servers;
#[path = "support/telegraf_standin.rs"]
mod telegraf_standin;

use serde_json::Value;
use std::process::Command;
use std::time::Duration;
use telegraf_standin::{ConsumerConfig, MS, StandIn, line_to_message};

fn action_messages(output: &str) -> Vec<Value> {
    output
        .lines()
        .filter(|l| l.starts_with("action ") || l.starts_with("action,"))
        .map(|l| line_to_message(l, MS).unwrap())
        .collect()
}

#[test]
fn replayed_run_comes_back_as_the_same_actions() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let fixture = recorded::recorded_run_path();
    let input = std::fs::read_to_string(&fixture).unwrap();
    let records = input
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .count();
    // What our binary answers when fed the recorded run directly.
    let expected = action_messages(&recorded::run_binary(&input));
    assert!(!expected.is_empty(), "the recorded run causes actions");

    // Publish on the topic the recording came from, and let the stand-in add the same host
    // tag, so the binding sees the tags it saw in the direct run.
    let tag_of_first = |key: &str| {
        influxdb_line_protocol::parse_lines(&input)
            .flatten()
            .next()
            .and_then(|l| {
                l.series.tag_set.and_then(|tags| {
                    tags.iter()
                        .find(|(k, _)| k.as_str() == key)
                        .map(|(_, v)| v.to_string())
                })
            })
    };
    let topic = tag_of_first("topic").unwrap_or_else(|| "tessla".to_string());
    let host = tag_of_first("host").unwrap_or_else(|| "robot-pc".to_string());

    // The test's own subscriber to the robot's action topic.
    let actions = mqtt_client::subscribe(broker.port, "action", "robot");

    // Stand-in Telegraf: mqtt_consumer -> processors.execd (our binary) -> outputs.mqtt.
    let cfg = ConsumerConfig {
        host,
        json_string_fields: vec!["actualSpeed".into()],
        json_time_key: Some("time".into()),
    };
    let standin = StandIn::start(recorded::BIN, broker.port, &topic, cfg, records);

    let out = Command::new(recorded::BIN)
        .args([
            "replay",
            fixture.to_str().unwrap(),
            "--broker",
            &broker.url(),
        ])
        .args(["--topic", &topic, "--speed", "0", "--time-key", "time"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "replay: {}",
        String::from_utf8_lossy(&out.stderr)
    );

    let (fed, status, published) = standin.finish();
    assert_eq!(fed, records, "every recorded message reached the stand-in");
    assert!(status.success(), "run exited with {status}");
    assert_eq!(published, expected.len());

    let got: Vec<Value> = mqtt_client::collect(&actions, expected.len(), Duration::from_secs(20))
        .into_iter()
        .map(|(_, p)| serde_json::from_slice(&p).unwrap())
        .collect();
    assert_eq!(got.len(), expected.len(), "every action arrived");
    for (i, (g, e)) in got.iter().zip(&expected).enumerate() {
        assert_eq!(g["name"], "action");
        assert_eq!(g["fields"], e["fields"], "action {i}: fields");
        assert_eq!(g["timestamp"], e["timestamp"], "action {i}: time");
    }
    let augmented = got
        .iter()
        .filter(|m| m["fields"]["augmented"] == true)
        .count();
    assert!(augmented > 0, "the recorded run has corrective actions");
}
