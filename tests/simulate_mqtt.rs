//! `simulate --broker` through a real Mosquitto: the simulated robot publishes its messages on
//! `tessla`; the Telegraf stand-in (mqtt_consumer JSON -> `tessla-telegraf run` -> outputs.mqtt
//! JSON) answers on `action`; the robot executes those actions. With the message time carried
//! in the JSON (`--time-key`), the run through the broker must equal the in-process run.

#[path = "support/mqtt_client.rs"]
mod mqtt_client;
#[path = "support/recorded.rs"]
mod recorded;
#[path = "support/servers.rs"]
mod servers;
#[path = "support/telegraf_standin.rs"]
mod telegraf_standin;

use recorded::BIN;
use serde_json::Value;
use std::process::Command;
use telegraf_standin::{ConsumerConfig, StandIn, line_to_message};

/// (speed, augmented) of every `action` line in a run's output.
fn actions(path: &std::path::Path) -> Vec<(f64, bool)> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| l.starts_with("action ") || l.starts_with("action,"))
        .map(|l| {
            let m = line_to_message(l, 1).unwrap();
            (
                m["fields"]["speed"].as_f64().unwrap(),
                m["fields"]["augmented"] == true,
            )
        })
        .collect()
}

#[test]
fn simulated_robot_drives_the_pipeline_through_mosquitto() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    // 60 s of the bundled program: 121 messages.
    let messages = 121usize;
    let common = ["--duration", "60", "--json", "--seed", "3"];

    // Stand-in Telegraf: mqtt_consumer -> processors.execd (our binary) -> outputs.mqtt.
    let cfg = ConsumerConfig {
        host: "sim".into(),
        json_string_fields: vec!["actualSpeed".into()],
        json_time_key: Some("time".into()),
    };
    let standin = StandIn::start(BIN, broker.port, "tessla", cfg, messages);

    let dir = tempfile::tempdir().unwrap();
    let via_broker = dir.path().join("broker.lp");
    let out = Command::new(BIN)
        .arg("simulate")
        .args(common)
        .args(["--broker", &broker.url(), "--time-key", "time", "--output"])
        .arg(&via_broker)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "simulate --broker: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (fed, status, published) = standin.finish();
    assert_eq!(
        fed, messages,
        "every simulated message reached the stand-in"
    );
    assert!(status.success(), "run exited with {status}");
    assert_eq!(published, messages);

    let broker_summary: Value = serde_json::from_slice(&out.stdout).unwrap();
    let b = &broker_summary["augmented"];
    assert_eq!(b["messages"], messages);
    assert_eq!(b["actions"], messages, "every message was answered");
    assert!(
        broker_summary["default"].is_null(),
        "one run through the broker"
    );

    // The same run in-process.
    let in_process = dir.path().join("in-process.lp");
    let out = Command::new(BIN)
        .arg("simulate")
        .args(common)
        .arg("--output")
        .arg(&in_process)
        .output()
        .unwrap();
    assert!(out.status.success());
    let local: Value = serde_json::from_slice(&out.stdout).unwrap();
    let l = &local["augmented"];
    for key in [
        "mse",
        "interventions",
        "stuck_seconds",
        "distance",
        "spec_mse",
    ] {
        assert_eq!(
            b[key], l[key],
            "{key}: broker {} in-process {}",
            b[key], l[key]
        );
    }
    let (ab, al) = (actions(&via_broker), actions(&in_process));
    assert_eq!(ab.len(), messages);
    assert_eq!(ab, al, "the same actions, in order");
    assert!(
        ab.iter().any(|a| a.1),
        "the monitor intervened in the first 60 s"
    );
}

/// The MQTT twin judges each action as a robot must (README, "What a robot must do with an
/// action"): a stand-in monitor answers the robot's five messages with a fresh action, a
/// redelivery of it, a stale one, a restarted monitor's (seq 1 again, newer) and its next; the
/// twin executes three and counts one refused as repeated, one as stale and one restart.
#[test]
fn the_mqtt_twin_refuses_stale_and_repeated_actions_and_follows_a_restart() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let messages = mqtt_client::subscribe(broker.port, "tessla", "monitor-sub");
    let answers = std::thread::spawn({
        let port = broker.port;
        move || {
            let publisher = mqtt_client::Publisher::connect(port, "monitor-pub");
            let mut first_until = 0i64;
            for k in 0..5 {
                let Ok((_, payload)) = messages.recv_timeout(std::time::Duration::from_secs(20))
                else {
                    return k;
                };
                let msg: Value = serde_json::from_slice(&payload).unwrap();
                let t = msg["time"].as_i64().unwrap();
                // Valid for 2 s, so that the redelivery 0.5 s later is still valid (a repeat,
                // not a stale action).
                let fresh = t + 2_000_000_000;
                let (seq, until) = match k {
                    0 => {
                        first_until = fresh;
                        (1, fresh)
                    }
                    1 => (1, first_until), // the first action again
                    2 => (3, t - 1),       // already past its validity
                    3 => (1, fresh),       // a restarted monitor: seq 1, newer
                    _ => (2, fresh),
                };
                let action = serde_json::json!({
                    "name": "action",
                    "tags": {"topic": "tessla"},
                    "fields": {"speed": 0.05, "augmented": true, "seq": seq, "valid_until": until},
                    "timestamp": t / 1_000_000,
                });
                publisher.publish("action", action.to_string().into_bytes());
            }
            5
        }
    });
    let out = Command::new(BIN)
        .args([
            "simulate",
            "--duration",
            "2",
            "--json",
            "--action-timeout",
            "10",
        ])
        .args(["--broker", &broker.url(), "--time-key", "time"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "simulate --broker: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        answers.join().unwrap(),
        5,
        "the stand-in monitor answered every message"
    );
    let summary: Value = serde_json::from_slice(&out.stdout).unwrap();
    let a = &summary["augmented"];
    assert_eq!(a["messages"], 5, "{a}");
    assert_eq!(a["actions"], 5, "{a}");
    assert_eq!(a["refused_stale"], 1, "{a}");
    assert_eq!(a["refused_repeated"], 1, "{a}");
    assert_eq!(a["monitor_restarts"], 1, "{a}");
}

#[test]
fn unreachable_broker_exits_3() {
    let port = servers::free_port();
    let out = Command::new(BIN)
        .args(["simulate", "--duration", "1", "--action-timeout", "2"])
        .args(["--broker", &format!("mqtt://127.0.0.1:{port}")])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(3));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("127.0.0.1:{port}")), "{err}");
}
