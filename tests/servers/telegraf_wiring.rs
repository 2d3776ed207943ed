//! The clone wiring (README, "Telegraf never re-parses the robot's record") through the real
//! Telegraf (both pinned versions, built by `tools/build-telegraf.sh`), `telegraf --once` on
//! `inputs.file` -> processors -> `outputs.file`:
//! - `processors.clone` (order 1) tags a copy of each robot metric, `processors.execd` (order 2)
//!   takes only the tagged copy (`tagpass`), removes the tag (`tagexclude`) and runs our binary
//!   with `--no-passthrough`: every robot record reaches the output once and unchanged, our
//!   verdicts and actions beside it are what an offline run computes, and the tag is on none;
//! - the same wiring with `influx_parser_type = "upstream"` gives the same output;
//! - `processors.starlark` running `bench/p2.star` (the in-Telegraf yardstick of `make
//!   bench-telegraf`) writes the same metrics as our binary running `specs/p2_tolerance.tessla`;
//! - why `telegraf.conf` keeps the echo: with a real Mosquitto and InfluxDB unreachable, the
//!   shipped conf answers every robot message, and the same conf with the clone wiring stops
//!   answering after a few (the record the clone keeps is acknowledged to the broker only once
//!   InfluxDB took it, and the broker sends at most `max_inflight_messages` unacknowledged).

use crate::support::real_telegraf::{self, Rewrite, Row, Telegraf, parse_lines};
use crate::support::{BIN, mqtt_client, recorded, servers};
use std::process::Command;
use std::time::Duration;

const T0: i64 = 1_700_000_000_000_000_000;
const N: usize = 60;

/// N robot records at 5 Hz: speeds within and beyond P2's tolerance, some corrections clipped.
fn records() -> String {
    let mut out = String::new();
    for i in 0..N {
        let expected = [0.2, 0.21, 0.1, -0.15, 0.0][i % 5];
        let actual = expected + [0.0, 0.01, -0.03, 0.05, -0.16, 0.025, -0.021][i % 7];
        out.push_str(&format!(
            "mqtt_consumer,host=tb3,topic=tessla expectedSpeed={expected},actualSpeed=\"{actual}\" {}\n",
            T0 + i as i64 * 200_000_000
        ));
    }
    out
}

fn spec() -> String {
    format!("{}/specs/p2_tolerance.tessla", env!("CARGO_MANIFEST_DIR"))
}

fn clone_wiring(parser: &str) -> String {
    format!(
        "[[processors.clone]]\n  order = 1\n  namepass = [\"mqtt_consumer\"]\n\
         [processors.clone.tags]\n    tessla_copy = \"1\"\n\
         [[processors.execd]]\n  order = 2\n  namepass = [\"mqtt_consumer\"]\n\
         command = [{BIN:?}, \"run\", \"--spec\", {:?}, \"--no-passthrough\", \"--log-level\", \"warn\"]\n{parser}\
         tagexclude = [\"tessla_copy\"]\n  [processors.execd.tagpass]\n    tessla_copy = [\"1\"]\n",
        spec()
    )
}

fn starlark(one_metric: bool) -> String {
    format!(
        "[[processors.starlark]]\n  namepass = [\"mqtt_consumer\"]\n  script = \"{}/bench/p2.star\"\n\
         [processors.starlark.constants]\n    one_metric = {one_metric}\n",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// `telegraf --once` with `processors` between the file of records and stdout: its stdout.
fn once(bin: &std::path::Path, input: &std::path::Path, processors: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("telegraf.conf");
    std::fs::write(
        &conf,
        format!(
            "[agent]\n  interval = \"1h\"\n  flush_interval = \"1h\"\n  omit_hostname = true\n  precision = \"1ns\"\n\
             skip_processors_after_aggregators = true\n\
             [[inputs.file]]\n  files = [{:?}]\n  data_format = \"influx\"\n{processors}\
             [[outputs.file]]\n  files = [\"stdout\"]\n  data_format = \"influx\"\n",
            input.display()
        ),
    )
    .unwrap();
    let out = Command::new(bin)
        .arg("--config")
        .arg(&conf)
        .arg("--once")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "telegraf --once failed:\n{stderr}");
    assert!(
        !stderr.contains(" E! "),
        "errors in Telegraf's log:\n{stderr}"
    );
    String::from_utf8(out.stdout).unwrap()
}

fn sorted(mut rows: Vec<Row>) -> Vec<Row> {
    rows.sort_by_key(|r| r.time);
    rows
}

#[test]
fn clone_wiring_passes_each_record_once_with_our_lines_and_starlark_writes_the_same() {
    let input = records();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("records.lp");
    std::fs::write(&path, &input).unwrap();
    let offline = real_telegraf::offline(&["--spec".to_string(), spec()], &input);
    let originals = sorted(parse_lines(&input, "mqtt_consumer"));
    let verdicts = sorted(parse_lines(&offline, "tessla"));
    let actions = sorted(parse_lines(&offline, "action"));
    assert_eq!(verdicts.len(), N, "a verdict metric for every record");
    assert_eq!(actions.len(), N, "an action for every record");
    assert!(
        actions.iter().any(|a| a
            .fields
            .get("reason")
            .is_some_and(|r| *r == real_telegraf::Field::Str("p2".into()))),
        "some actions are corrections"
    );
    for (version, bin) in real_telegraf::versions() {
        for (name, processors) in [
            ("clone", clone_wiring("")),
            (
                "clone, upstream parser",
                clone_wiring("  influx_parser_type = \"upstream\"\n"),
            ),
            ("starlark", starlark(false)),
        ] {
            let out = once(&bin, &path, &processors);
            assert!(
                !out.contains("tessla_copy"),
                "Telegraf {version}, {name}: the copy's tag leaked:\n{out}"
            );
            assert_eq!(
                out.lines().count(),
                3 * N,
                "Telegraf {version}, {name}: the record, the verdicts and the action, each once:\n{out}"
            );
            assert_eq!(
                sorted(parse_lines(&out, "mqtt_consumer")),
                originals,
                "Telegraf {version}, {name}: every record once, unchanged"
            );
            assert_eq!(
                sorted(parse_lines(&out, "tessla")),
                verdicts,
                "Telegraf {version}, {name}: the verdicts of an offline run"
            );
            assert_eq!(
                sorted(parse_lines(&out, "action")),
                actions,
                "Telegraf {version}, {name}: the actions of an offline run"
            );
        }
    }
}

#[test]
fn one_metric_spec_and_starlark_write_the_same_single_metric() {
    let input = records();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("records.lp");
    std::fs::write(&path, &input).unwrap();
    let one = format!("{}/bench/p2_one_metric.tessla", env!("CARGO_MANIFEST_DIR"));
    let offline = real_telegraf::offline(&["--spec".to_string(), one.clone()], &input);
    let actions = sorted(parse_lines(&offline, "action"));
    assert_eq!(actions.len(), N, "one metric for every record");
    assert_eq!(offline.lines().count(), N, "and nothing else");
    assert!(actions.iter().all(|a| a.fields.contains_key("p2_diff")));
    let wiring = clone_wiring("").replace(&spec(), &one);
    for (version, bin) in real_telegraf::versions() {
        for (name, processors) in [("clone", wiring.clone()), ("starlark", starlark(true))] {
            let out = once(&bin, &path, &processors);
            assert_eq!(
                out.lines().count(),
                2 * N,
                "Telegraf {version}, {name}: the record and one metric:\n{out}"
            );
            assert_eq!(
                sorted(parse_lines(&out, "mqtt_consumer")),
                sorted(parse_lines(&input, "mqtt_consumer")),
                "Telegraf {version}, {name}: every record once, unchanged"
            );
            assert_eq!(
                sorted(parse_lines(&out, "action")),
                actions,
                "Telegraf {version}, {name}: the one metric of an offline run"
            );
        }
    }
}

#[test]
fn with_influxdb_down_the_echo_answers_every_message_and_the_clone_wiring_stops() {
    let fixture = recorded::recorded_run_path();
    let records = std::fs::read_to_string(&fixture)
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .count();
    let text = real_telegraf::shipped("telegraf/telegraf.conf");
    for (version, bin) in real_telegraf::versions() {
        for clone in [false, true] {
            let Some(broker) = real_telegraf::broker() else {
                return;
            };
            let state = tempfile::tempdir().unwrap();
            // InfluxDB on a port where nothing listens: every write is refused.
            let down = format!("http://127.0.0.1:{}", servers::free_port());
            let mut conf = Rewrite::robot(crate::support::BIN, broker.port, Some(&down))
                .state_in(state.path())
                .apply(&text);
            if clone {
                conf = real_telegraf::clone_wiring(&conf).unwrap();
            }
            let actions = mqtt_client::subscribe(broker.port, "action", "robot");
            let telegraf = Telegraf::start(version, &bin, &conf, &[]);
            real_telegraf::wait_subscribed(&broker, "telegraf-tessla-in", "tessla", 0);
            super::telegraf_real::replay_at(&fixture, broker.port, "tessla", "0");
            let wait = Duration::from_secs(if clone { 15 } else { 60 });
            let got = mqtt_client::collect(&actions, records, wait);
            let log = telegraf.stop();
            if clone {
                assert!(
                    got.len() <= records / 4,
                    "Telegraf {version}, clone wiring: {} of {records} answered with InfluxDB down \
                     (expected the broker's in-flight window, 20)\n{log}",
                    got.len()
                );
            } else {
                assert_eq!(
                    got.len(),
                    records,
                    "Telegraf {version}, the echo: every message answered with InfluxDB down\n{log}"
                );
            }
        }
    }
}
