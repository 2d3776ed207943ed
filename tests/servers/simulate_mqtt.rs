//! `simulate --broker` through a real Mosquitto and the real Telegraf (both pinned versions,
//! built by `tools/build-telegraf.sh`): the simulated robot publishes its messages on `tessla`
//! as the robot's JSON, with its time in them (`--time-key`); Telegraf runs the shipped
//! `telegraf/telegraf.conf` (its `json_time_key` variant) with our binary as its
//! `processors.execd` child and answers on `action`; the robot executes those actions. The run
//! through the broker must equal the in-process run.

use crate::support::mqtt_client;
use crate::support::real_telegraf;
use crate::support::servers;

use crate::support::BIN;
use real_telegraf::{
    Field, Rewrite, Telegraf, assert_no_error, broker, wait_subscribed, without_table,
};
use serde_json::Value;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// (speed, augmented) of every `action` line in a run's output.
fn actions(path: &std::path::Path) -> Vec<(f64, bool)> {
    real_telegraf::parse_lines(&std::fs::read_to_string(path).unwrap(), "action")
        .iter()
        .map(|a| {
            let speed = match &a.fields["speed"] {
                Field::Float(f) => *f,
                Field::Int(i) => *i as f64,
                other => panic!("speed: {other:?}"),
            };
            (speed, a.fields.get("augmented") == Some(&Field::Bool(true)))
        })
        .collect()
}

/// Run `cmd` to its end, killed (and the test failed, with Telegraf's log) after `timeout`.
fn output_within(cmd: &mut Command, timeout: Duration, telegraf: &Telegraf) -> Output {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let read = |mut r: Box<dyn std::io::Read + Send>| {
        std::thread::spawn(move || {
            let mut buf = Vec::new();
            let _ = r.read_to_end(&mut buf);
            buf
        })
    };
    let stdout = read(Box::new(child.stdout.take().unwrap()));
    let stderr = read(Box::new(child.stderr.take().unwrap()));
    let deadline = Instant::now() + timeout;
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "{cmd:?} still running after {timeout:?}: {}\nTelegraf {} log:\n{}",
                String::from_utf8_lossy(&stderr.join().unwrap()),
                telegraf.version,
                telegraf.log()
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    Output {
        status,
        stdout: stdout.join().unwrap(),
        stderr: stderr.join().unwrap(),
    }
}

#[test]
fn simulated_robot_drives_the_pipeline_through_mosquitto() {
    // 60 s of the bundled program: 121 messages.
    let messages = 121usize;
    let common = ["--duration", "60", "--json", "--seed", "3"];

    // The same run in-process, for each version to equal.
    let dir = tempfile::tempdir().unwrap();
    let in_process = dir.path().join("in-process.lp");
    let out = Command::new(BIN)
        .arg("simulate")
        .args(common)
        .arg("--output")
        .arg(&in_process)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "simulate: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let local: Value = serde_json::from_slice(&out.stdout).unwrap();
    let l = &local["augmented"];
    let al = actions(&in_process);
    assert!(
        al.iter().any(|a| a.1),
        "the monitor intervened in the first 60 s"
    );

    let text = real_telegraf::shipped("telegraf/telegraf.conf");
    for (version, bin) in real_telegraf::versions() {
        let started = Instant::now();
        let Some(broker) = broker() else { return };
        let state = tempfile::tempdir().unwrap();
        // The shipped conf on the test's broker, its --state in a temporary folder, with:
        // - the robot's own time (the variant the conf's comment describes): the simulated
        //   times (multiples of 500 ms) are exact as Telegraf's float64;
        // - the simulated robot's host, `sim` (the agent's `hostname`);
        // - no InfluxDB (the table left out: this checks the MQTT round trip).
        let conf = without_table(
            &Rewrite::robot(crate::support::BIN, broker.port, None)
                .state_in(state.path())
                .robots_time()
                .replace("[agent]\n", "[agent]\n  hostname = \"sim\"\n")
                .apply(&text),
            "[[outputs.influxdb]]",
        );
        // The test's own subscriber to `action`: how many Telegraf published.
        let published = mqtt_client::subscribe(broker.port, "action", "watch");
        let telegraf = Telegraf::start(version, &bin, &conf, &[]);
        wait_subscribed(&broker, "telegraf-tessla-in", "tessla", 0);

        let via_broker = dir.path().join(format!("broker-{version}.lp"));
        // Lock-step: each message waits for its action (at most --action-timeout); the whole
        // run is bounded too.
        let out = output_within(
            Command::new(BIN)
                .arg("simulate")
                .args(common)
                .args(["--broker", &broker.url(), "--time-key", "time"])
                .args(["--action-timeout", "20", "--output"])
                .arg(&via_broker),
            Duration::from_secs(300),
            &telegraf,
        );
        assert!(
            out.status.success(),
            "simulate --broker: {}\nTelegraf {version} log:\n{}",
            String::from_utf8_lossy(&out.stderr),
            telegraf.log()
        );
        let got = mqtt_client::collect(&published, messages, Duration::from_secs(30));
        assert_eq!(
            got.len(),
            messages,
            "Telegraf {version}: an action for every message; its log:\n{}",
            telegraf.log()
        );
        if let Ok((_, extra)) = published.recv_timeout(Duration::from_secs(2)) {
            panic!(
                "Telegraf {version}: an action beyond the {messages} expected: {}\nits log:\n{}",
                String::from_utf8_lossy(&extra),
                telegraf.log()
            );
        }
        let log = telegraf.stop();
        assert_no_error(version, &log);
        let summary = real_telegraf::summary(version, &log);
        assert!(
            summary.contains(&format!("summary: {messages} records,"))
                && summary.contains(" 0 parse errors, 0 late records,")
                && summary.contains(" 0 duplicates"),
            "Telegraf {version}: all {messages} records reached the monitor, once: {summary}"
        );

        let broker_summary: Value = serde_json::from_slice(&out.stdout).unwrap();
        let b = &broker_summary["augmented"];
        assert_eq!(b["messages"], messages, "Telegraf {version}: {b}");
        assert_eq!(
            b["actions"], messages,
            "Telegraf {version}: every message was answered: {b}"
        );
        assert!(
            broker_summary["default"].is_null(),
            "one run through the broker"
        );
        // The same outcome as in-process; through the real pipeline, too, no action reached
        // the robot stale or twice (the robot refuses those, `src/simulate/gate.rs`).
        for key in [
            "mse",
            "interventions",
            "stuck_seconds",
            "distance",
            "spec_mse",
            "refused_stale",
            "refused_repeated",
            "monitor_restarts",
        ] {
            assert_eq!(
                b[key], l[key],
                "Telegraf {version}: {key}: broker {} in-process {}",
                b[key], l[key]
            );
        }
        for key in ["refused_stale", "refused_repeated", "monitor_restarts"] {
            assert_eq!(b[key], 0, "Telegraf {version}: {key}: {b}");
        }
        let ab = actions(&via_broker);
        assert_eq!(ab.len(), messages, "Telegraf {version}");
        assert_eq!(ab, al, "Telegraf {version}: the same actions, in order");
        eprintln!(
            "Telegraf {version}: {messages} simulated messages, the in-process run's outcome, in {:.1?}",
            started.elapsed()
        );
    }
}

/// The MQTT twin judges each action as a robot must (README, "What a robot must do with an
/// action"): the test, as the monitor, answers the robot's five messages with a fresh action, a
/// redelivery of it, a stale one, a restarted monitor's (seq 1 again, newer) and its next; the
/// twin executes three and counts one refused as repeated, one as stale and one restart.
/// No Telegraf here: the real pipeline makes such a sequence only under failures (a broker down,
/// a monitor restarted without `--state`); what is tested is the twin's judgement of it.
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
        "the test's monitor answered every message"
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
