//! The MQTT round trip through the real Telegraf (both pinned versions, built by
//! `tools/build-telegraf.sh`) and a real Mosquitto: `replay` publishes the recorded run on
//! `tessla` as the robot's JSON, with the robot's time in it; Telegraf runs the shipped
//! `telegraf/telegraf.conf` (its `json_time_key` variant, so that each record keeps its recorded
//! time) with our binary as its `processors.execd` child, and its `outputs.mqtt` publishes the
//! actions on `action`; the test, subscribed to `action`, gets every corrective action, once, in
//! order, with the tags and values our binary computes for the recorded run directly.

use crate::support::mqtt_client;
use crate::support::real_telegraf;
use crate::support::recorded;

use crate::support::BIN;
use real_telegraf::{
    Field, Rewrite, Row, Telegraf, assert_no_error, broker, wait_subscribed, without_table,
};
use std::process::Command;
use std::time::{Duration, Instant};

#[test]
fn replayed_run_comes_back_as_the_same_actions() {
    let fixture = recorded::recorded_run_path();
    let input = std::fs::read_to_string(&fixture).unwrap();
    let records = input
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .count();
    // What our binary answers when fed the recorded run directly.
    let expected: Vec<Row> = real_telegraf::parse_lines(&recorded::run_binary(&input), "action");
    // One action a record: so every action arriving means every record reached the monitor.
    assert_eq!(
        expected.len(),
        records,
        "an action for every recorded message"
    );
    assert!(
        expected
            .iter()
            .any(|e| e.fields.get("augmented") == Some(&Field::Bool(true))),
        "the recorded run has corrective actions"
    );

    // Publish on the topic the recording came from, and let Telegraf add the same host tag
    // (the agent's `hostname`), so the monitor sees the tags it saw in the direct run.
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

    let text = real_telegraf::shipped("telegraf/telegraf.conf");
    let versions = real_telegraf::versions();
    for (version, bin) in versions {
        let started = Instant::now();
        let Some(broker) = broker() else { return };
        let state = tempfile::tempdir().unwrap();
        // The shipped conf on the test's broker, its --state in a temporary folder, with:
        // - the robot's own time (the variant the conf's comment describes), as the recording
        //   has it: the recorded times (multiples of 200 ms) are exact as Telegraf's float64;
        // - the recording's host and topic;
        // - no InfluxDB (the table left out: this checks the MQTT round trip).
        let conf = without_table(
            &Rewrite::robot(crate::support::BIN, broker.port, None)
                .state_in(state.path())
                .robots_time()
                .replace("[agent]\n", format!("[agent]\n  hostname = {host:?}\n"))
                .replace(
                    "  topics = [\"tessla\"]\n",
                    format!("  topics = [{topic:?}]\n"),
                )
                .apply(&text),
            "[[outputs.influxdb]]",
        );

        // The test's own subscriber to the robot's action topic.
        let actions = mqtt_client::subscribe(broker.port, "action", "robot");
        let telegraf = Telegraf::start(version, &bin, &conf, &[]);
        wait_subscribed(&broker, "telegraf-tessla-in", &topic, 0);

        let out = Command::new(BIN)
            .args(["replay", fixture.to_str().unwrap()])
            .args(["--broker", &broker.url()])
            .args(["--topic", &topic, "--speed", "0", "--time-key", "time"])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "replay: {}\nTelegraf {version} log:\n{}",
            String::from_utf8_lossy(&out.stderr),
            telegraf.log()
        );

        let got = mqtt_client::collect(&actions, expected.len(), Duration::from_secs(60));
        assert_eq!(
            got.len(),
            expected.len(),
            "Telegraf {version}: every action arrived; its log:\n{}",
            telegraf.log()
        );
        // Each action once: nothing more comes (a resent or doubled action would).
        if let Ok((_, extra)) = actions.recv_timeout(Duration::from_secs(2)) {
            panic!(
                "Telegraf {version}: an action beyond the {} expected: {}\nits log:\n{}",
                expected.len(),
                String::from_utf8_lossy(&extra),
                telegraf.log()
            );
        }
        let log = telegraf.stop();
        assert_no_error(version, &log);
        let summary = real_telegraf::summary(version, &log);
        assert!(
            summary.contains(&format!("summary: {records} records,"))
                && summary.contains(" 0 parse errors, 0 late records,")
                && summary.contains(" 0 duplicates"),
            "Telegraf {version}: all {records} records reached the monitor, once: {summary}"
        );

        for (i, ((_, payload), e)) in got.iter().zip(&expected).enumerate() {
            let g = real_telegraf::action_row(payload);
            assert_eq!(
                g.time,
                e.time / 1_000_000,
                "Telegraf {version}: action {i}: time"
            );
            assert_eq!(g.tags, e.tags, "Telegraf {version}: action {i}: tags");
            assert_eq!(
                g.fields.keys().collect::<Vec<_>>(),
                e.fields.keys().collect::<Vec<_>>(),
                "Telegraf {version}: action {i}: fields"
            );
            for (k, gv) in &g.fields {
                assert!(
                    real_telegraf::same_value(gv, &e.fields[k]),
                    "Telegraf {version}: action {i} field {k}: {gv:?} through Telegraf, {:?} directly",
                    e.fields[k]
                );
            }
        }
        eprintln!(
            "Telegraf {version}: {records} records replayed, {} actions as the direct run, in {:.1?}",
            expected.len(),
            started.elapsed()
        );
    }
}
