//! Every shipped conf run by the real Telegraf (both pinned versions, built by
//! `tools/build-telegraf.sh`), against a real Mosquitto and InfluxDB 1.x, with the real binary
//! as its `processors.execd` child (or, for the UDP conf, beside it): the recorded robot run goes
//! in over MQTT as the robot's JSON, the actions come out on the robot's `action` topic and the
//! verdicts land in InfluxDB, and both match, value for value, an offline `run` over the very
//! records Telegraf fed the monitor (read back from InfluxDB, where the conf stores them too).
//! Also `telegraf --test` on each conf.

use crate::support::mqtt_client;
use crate::support::real_telegraf;
use crate::support::recorded;
use crate::support::servers;

use crate::support::BIN;
use real_telegraf::{
    Rewrite, Row, Telegraf, assert_no_error, broker, execd_args, offline, wait_subscribed,
};
use std::collections::BTreeMap;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Records of the recorded run the UDP test sends (a burst: UDP drops what a full socket
/// buffer cannot take, so it stays well inside it).
const UDP_RECORDS: usize = 100;

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
    replay_at(path, port, topic, "0");
}

/// As [`replay`], at `speed` times the recorded pace (`0`: as fast as possible).
pub(super) fn replay_at(path: &std::path::Path, port: u16, topic: &str, speed: &str) {
    let out = Command::new(BIN)
        .args(["replay", path.to_str().unwrap()])
        .args(["--broker", &format!("mqtt://127.0.0.1:{port}")])
        .args(["--topic", topic, "--speed", speed])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "replay: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `got` (through Telegraf) and `want` (offline) hold the same points: same times (after
/// `time_div`), tags and field values, in the same order. Telegraf's side may hold more: a
/// `delay` firing on the wall clock while a robot is silent (between records of other robots,
/// or after the last one) makes a point offline has not, at a time that is none of that
/// robot's records. Such points may carry only `timer_fields`; they are counted and returned.
fn assert_same(
    what: &str,
    got: &[Row],
    want: &[Row],
    time_div: i64,
    timer_fields: &[&str],
) -> usize {
    let record_times: std::collections::BTreeSet<(&BTreeMap<String, String>, i64)> =
        want.iter().map(|w| (&w.tags, w.time / time_div)).collect();
    let (got, timers): (Vec<&Row>, Vec<&Row>) = got
        .iter()
        .partition(|r| record_times.contains(&(&r.tags, r.time)));
    for t in &timers {
        assert!(
            t.fields.keys().all(|k| timer_fields.contains(&k.as_str())),
            "{what}: a point offline does not have, at no record's time: {t:?}"
        );
    }
    assert_eq!(
        got.len(),
        want.len(),
        "{what}: {} points through Telegraf, {} offline",
        got.len(),
        want.len()
    );
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert_eq!(g.time, w.time / time_div, "{what} #{i}: time");
        assert_eq!(g.tags, w.tags, "{what} #{i}: tags");
        assert_eq!(
            g.fields.keys().collect::<Vec<_>>(),
            w.fields.keys().collect::<Vec<_>>(),
            "{what} #{i}: fields"
        );
        for (k, gv) in &g.fields {
            assert!(
                real_telegraf::same_value(gv, &w.fields[k]),
                "{what} #{i} field {k}: {gv:?} through Telegraf, {:?} offline",
                w.fields[k]
            );
        }
    }
    timers.len()
}

/// Order rows by (tags, time), the order in which each instance saw them.
fn by_instance(mut rows: Vec<Row>) -> Vec<Row> {
    rows.sort_by(|a, b| (&a.tags, a.time).cmp(&(&b.tags, b.time)));
    rows
}

/// What a shipped robot conf (MQTT in, execd, MQTT actions and InfluxDB out) did under the real
/// Telegraf, compared with the offline run: `topics` are the robots' topics, `action_topic` maps
/// one to where its actions go.
fn robot_conf_matches_offline(
    conf_path: &str,
    records_per_robot: usize,
    client_id: &str,
    subscription: &str,
    topics: &[&str],
    action_topic: impl Fn(&str) -> String,
) {
    for (version, bin) in real_telegraf::versions() {
        let Some(broker) = broker() else { return };
        let Some(influx) = servers::Influxd::start() else {
            return;
        };
        let state = tempfile::tempdir().unwrap();
        let text = real_telegraf::shipped(conf_path);
        let rewrite = Rewrite::robot(crate::support::BIN, broker.port, Some(&influx.url("")))
            .state_in(state.path());
        let conf = rewrite.apply(&text);
        let inboxes: Vec<_> = topics
            .iter()
            .map(|t| mqtt_client::subscribe(broker.port, &action_topic(t), &format!("robot-{t}")))
            .collect();
        let telegraf = Telegraf::start(version, &bin, &conf, &[]);
        wait_subscribed(&broker, client_id, subscription, 0);
        let dir = tempfile::tempdir().unwrap();
        let file = head(&dir, records_per_robot);
        for t in topics {
            replay(&file, broker.port, t);
        }
        let mut actions = Vec::new();
        for (t, inbox) in topics.iter().zip(&inboxes) {
            let got = mqtt_client::collect(inbox, records_per_robot, Duration::from_secs(60));
            assert_eq!(
                got.len(),
                records_per_robot,
                "Telegraf {version}: actions on {}; log:\n{}",
                action_topic(t),
                telegraf.log()
            );
            let rows: Vec<Row> = got
                .iter()
                .map(|(_, p)| real_telegraf::action_row(p))
                .collect();
            // What the robot needs to refuse a stale or repeated action, as it receives it:
            // its own sequence 1, 2, 3 ... in order, and a validity of 400 ms past the record
            // (the action's JSON timestamp is the record's, cut to ms).
            for (k, a) in rows.iter().enumerate() {
                assert_eq!(
                    a.fields.get("seq"),
                    Some(&real_telegraf::Field::Int(k as i64 + 1)),
                    "{t}: {a:?}"
                );
                let Some(real_telegraf::Field::Int(until)) = a.fields.get("valid_until") else {
                    panic!("{t}: no valid_until: {a:?}");
                };
                let from = until - 400_000_000;
                assert!(
                    from >= a.time * 1_000_000 && from < (a.time + 1) * 1_000_000,
                    "{t}: valid_until {until} for a record at {} ms",
                    a.time
                );
            }
            actions.extend(rows);
        }
        let log = telegraf.stop();
        // Our stderr reaches Telegraf's log: at the default level only the summary, which
        // Telegraf >= 1.37 logs at I!, older ones at E!.
        let ours: Vec<&str> = log
            .lines()
            .filter(|l| l.contains("[processors.execd]") && l.contains("summary:"))
            .collect();
        assert_eq!(ours.len(), 1, "{log}");
        let total = records_per_robot * topics.len();
        assert!(
            ours[0].contains(&format!("summary: {total} records,"))
                && ours[0].contains(" 0 parse errors, 0 late records,"),
            "{log}"
        );
        if version >= "v1.37.0" {
            assert!(ours[0].contains(" I! [processors.execd]"), "{}", ours[0]);
        }
        assert_no_error(version, &log);

        // What Telegraf fed the monitor, as InfluxDB keeps it (the conf stores it too).
        let records = real_telegraf::influx_rows(&influx, "telegraf", "mqtt_consumer");
        assert_eq!(records.len(), total, "robot records in InfluxDB");
        let input = real_telegraf::to_lines("mqtt_consumer", &records);
        let want = offline(&execd_args(&conf), &input);

        let want_actions = by_instance(real_telegraf::parse_lines(&want, "action"));
        assert_eq!(want_actions.len(), total);
        assert_same(
            &format!("Telegraf {version}: actions on MQTT"),
            &by_instance(actions),
            &want_actions,
            1_000_000,
            &[],
        );
        assert_same(
            &format!("Telegraf {version}: actions in InfluxDB"),
            &by_instance(real_telegraf::influx_rows(&influx, "telegraf", "action")),
            &want_actions,
            1,
            &[],
        );
        let want_verdicts = by_instance(real_telegraf::parse_lines(&want, "tessla"));
        assert_eq!(want_verdicts.len(), total);
        assert_same(
            &format!("Telegraf {version}: verdicts in InfluxDB"),
            &by_instance(real_telegraf::influx_rows(&influx, "telegraf", "tessla")),
            &want_verdicts,
            1,
            &["robot_silent"],
        );
        eprintln!(
            "Telegraf {version}: {conf_path}: {total} records, actions and verdicts as offline"
        );
    }
}

#[test]
fn main_conf_under_real_telegraf_matches_an_offline_run() {
    robot_conf_matches_offline(
        "telegraf/telegraf.conf",
        300,
        "telegraf-tessla-in",
        "tessla",
        &["tessla"],
        |_| "action".to_string(),
    );
}

#[test]
fn fleet_conf_under_real_telegraf_matches_an_offline_run() {
    robot_conf_matches_offline(
        "telegraf/telegraf-fleet.conf",
        100,
        "telegraf-tessla-fleet-in",
        "tessla/+",
        &["tessla/r1", "tessla/r2", "tessla/r3"],
        |t| format!("{t}/action"),
    );
}

#[test]
fn udp_conf_under_real_telegraf_matches_an_offline_run() {
    let text = real_telegraf::shipped("telegraf/telegraf-udp.conf");
    // The monitor runs beside Telegraf, as the conf's header says.
    let header = text
        .lines()
        .find_map(|l| {
            l.trim_start_matches('#')
                .trim()
                .strip_prefix("tessla-telegraf run ")
        })
        .expect("the conf's header gives the monitor's command")
        .to_string();
    for (version, bin) in real_telegraf::versions() {
        let Some(broker) = broker() else { return };
        let Some(influx) = servers::Influxd::start() else {
            return;
        };
        let monitor_addr = format!("127.0.0.1:{}", servers::free_port());
        let telegraf_addr = format!("127.0.0.1:{}", servers::free_port());
        let state = tempfile::tempdir().unwrap();
        let args: Vec<String> = header
            .replace("127.0.0.1:1653", &monitor_addr)
            .replace("127.0.0.1:1654", &telegraf_addr)
            .replace(
                "/var/lib/tessla-telegraf",
                &state.path().display().to_string(),
            )
            .split_whitespace()
            .map(String::from)
            .collect();
        let mut monitor = Monitor(
            Command::new(BIN)
                .arg("run")
                .args(&args)
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        );
        let conf = Rewrite::robot_without_binary(broker.port, Some(&influx.url("")))
            .replace("udp://127.0.0.1:1653", format!("udp://{monitor_addr}"))
            .replace("udp://127.0.0.1:1654", format!("udp://{telegraf_addr}"))
            .apply(&text);
        let robot = mqtt_client::subscribe(broker.port, "action", "robot");
        let telegraf = Telegraf::start(version, &bin, &conf, &[]);
        wait_subscribed(&broker, "telegraf-tessla-udp-in", "tessla", 0);
        let dir = tempfile::tempdir().unwrap();
        // At 5 times the robot's pace (25 Hz): a burst would overflow the socket buffers,
        // and UDP drops what they cannot take, unnoticed (README, the guarantee table).
        replay_at(&head(&dir, UDP_RECORDS), broker.port, "tessla", "5");
        let got = mqtt_client::collect(&robot, UDP_RECORDS, Duration::from_secs(60));
        assert_eq!(
            got.len(),
            UDP_RECORDS,
            "Telegraf {version}: {}",
            telegraf.log()
        );
        // What comes back over UDP is an input's metric: Telegraf adds its `host` tag.
        let strip_host = |mut rows: Vec<Row>| {
            for r in &mut rows {
                assert!(
                    r.tags.remove("host").is_some(),
                    "the agent's host tag: {r:?}"
                );
            }
            rows
        };
        let actions: Vec<Row> = strip_host(
            got.iter()
                .map(|(_, p)| real_telegraf::action_row(p))
                .collect(),
        );
        let log = telegraf.stop();
        assert_no_error(version, &log);
        // The monitor's own end: stdin is not its input in UDP mode; SIGTERM stops it.
        let _ = Command::new("kill")
            .args(["-TERM", &monitor.0.id().to_string()])
            .status();
        let status = monitor.0.wait().unwrap();
        assert!(status.success(), "the UDP monitor: {status}");

        let records = real_telegraf::influx_rows(&influx, "telegraf", "mqtt_consumer");
        assert_eq!(
            records.len(),
            UDP_RECORDS,
            "no record came back into the loop"
        );
        let want = offline(
            &args
                .iter()
                .filter(|a| !a.starts_with("--udp") && !a.starts_with("127.0.0.1:"))
                .cloned()
                .collect::<Vec<_>>(),
            &real_telegraf::to_lines("mqtt_consumer", &records),
        );
        let want_actions = real_telegraf::parse_lines(&want, "action");
        assert_same(
            &format!("Telegraf {version} UDP: actions on MQTT"),
            &actions,
            &want_actions,
            1_000_000,
            &[],
        );
        assert_same(
            &format!("Telegraf {version} UDP: verdicts in InfluxDB"),
            &strip_host(real_telegraf::influx_rows(&influx, "telegraf", "tessla")),
            &real_telegraf::parse_lines(&want, "tessla"),
            1,
            &["robot_silent"],
        );
    }
}

/// The UDP-mode monitor, killed if the test fails before it stops it.
struct Monitor(std::process::Child);

impl Drop for Monitor {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The first spec's conf as shipped (README, "Your first spec"), only its endpoints and
/// install paths rewritten: two robots' JSON on tessla/r1 and tessla/r2, `topic_parsing` makes
/// the `robot` tag, one dock.tessla monitor per robot (`--instance-by robot`); each robot gets
/// its own `return_to_dock` on tessla/<robot>/action, and InfluxDB holds the records, the
/// verdicts and the actions, value for value as an offline run over those records.
#[test]
fn first_spec_example_conf_under_real_telegraf_answers_each_robot_and_fills_influxdb() {
    let text = real_telegraf::shipped("examples/first-spec/telegraf.conf");
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let robots = ["r1", "r2"];
    for (version, bin) in real_telegraf::versions() {
        let Some(broker) = broker() else { return };
        let Some(influx) = servers::Influxd::start() else {
            return;
        };
        let state = tempfile::tempdir().unwrap();
        let conf = Rewrite::robot(crate::support::BIN, broker.port, Some(&influx.url("")))
            .replace(
                "/usr/share/tessla-telegraf/first-spec/",
                format!("{}/", root.join("examples/first-spec").display()),
            )
            .state_in(state.path())
            .apply(&text);
        let inboxes: Vec<_> = robots
            .iter()
            .map(|r| {
                mqtt_client::subscribe(
                    broker.port,
                    &format!("tessla/{r}/action"),
                    &format!("robot-{r}"),
                )
            })
            .collect();
        let telegraf = Telegraf::start(version, &bin, &conf, &[]);
        wait_subscribed(&broker, "", "tessla/+", 0);
        let battery = root.join("examples/first-spec/battery.lp");
        let sent = std::fs::read_to_string(&battery)
            .unwrap()
            .lines()
            .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
            .count();
        for r in robots {
            replay(&battery, broker.port, &format!("tessla/{r}"));
        }
        // One fall below low_voltage in battery.lp: one action per robot, on its own topic.
        let mut actions = Vec::new();
        for (r, inbox) in robots.iter().zip(&inboxes) {
            let got = mqtt_client::collect(inbox, 1, Duration::from_secs(60));
            assert_eq!(
                got.len(),
                1,
                "Telegraf {version}: no action on tessla/{r}/action; log:\n{}",
                telegraf.log()
            );
            let row = real_telegraf::action_row(&got[0].1);
            assert_eq!(
                row.tags.get("robot").map(String::as_str),
                Some(*r),
                "{row:?}"
            );
            assert_eq!(
                row.fields.get("command"),
                Some(&real_telegraf::Field::Str("return_to_dock".into())),
                "{row:?}"
            );
            actions.push(row);
        }
        let total = sent * robots.len();
        let count = |m: &str| real_telegraf::influx_rows(&influx, "telegraf", m).len();
        let wait_rows = |m: &str, n: usize| {
            let deadline = Instant::now() + Duration::from_secs(60);
            while count(m) < n {
                assert!(
                    Instant::now() < deadline,
                    "Telegraf {version}: InfluxDB never held {n} rows of {m} (it has {}); log:\n{}",
                    count(m),
                    telegraf.log()
                );
                std::thread::sleep(Duration::from_millis(200));
            }
        };
        wait_rows("mqtt_consumer", total);
        wait_rows("action", robots.len());
        let records = real_telegraf::influx_rows(&influx, "telegraf", "mqtt_consumer");
        assert_eq!(records.len(), total, "robot records in InfluxDB");
        for r in &records {
            let robot = r.tags.get("robot").map(String::as_str).unwrap_or("");
            assert!(
                robots.contains(&robot),
                "a record without its robot tag: {r:?}"
            );
            assert_eq!(
                r.tags.get("topic"),
                Some(&format!("tessla/{robot}")),
                "{r:?}"
            );
            assert!(!r.tags.contains_key("tessla_copy"), "{r:?}");
        }
        let want = offline(
            &execd_args(&conf),
            &real_telegraf::to_lines("mqtt_consumer", &records),
        );
        let want_checks = by_instance(real_telegraf::parse_lines(&want, "battery_check"));
        // alerts=0 at the first record, alerts=1 at the fall: per robot.
        assert_eq!(want_checks.len(), 2 * robots.len(), "{want}");
        wait_rows("battery_check", want_checks.len());
        let log = telegraf.stop();
        assert_no_error(version, &log);
        // Nothing extra arrived on the robots' topics (one fall, one action each).
        for (r, inbox) in robots.iter().zip(&inboxes) {
            assert!(
                inbox.try_recv().is_err(),
                "Telegraf {version}: a second action on tessla/{r}/action"
            );
        }
        let want_actions = by_instance(real_telegraf::parse_lines(&want, "action"));
        assert_eq!(want_actions.len(), robots.len(), "{want}");
        assert_same(
            &format!("Telegraf {version}: actions on MQTT"),
            &by_instance(actions),
            &want_actions,
            1_000_000,
            &[],
        );
        assert_same(
            &format!("Telegraf {version}: actions in InfluxDB"),
            &by_instance(real_telegraf::influx_rows(&influx, "telegraf", "action")),
            &want_actions,
            1,
            &[],
        );
        assert_same(
            &format!("Telegraf {version}: battery_check in InfluxDB"),
            &by_instance(real_telegraf::influx_rows(
                &influx,
                "telegraf",
                "battery_check",
            )),
            &want_checks,
            1,
            &[],
        );
    }
}

#[test]
fn main_conf_with_the_robots_time_rounds_as_telegraf_and_drops_a_redelivery() {
    for (version, bin) in real_telegraf::versions() {
        let Some(broker) = broker() else { return };
        let Some(influx) = servers::Influxd::start() else {
            return;
        };
        let state = tempfile::tempdir().unwrap();
        let text = real_telegraf::shipped("telegraf/telegraf.conf");
        let rewrite = Rewrite::robot(crate::support::BIN, broker.port, Some(&influx.url("")))
            // The variant the conf's comment describes.
            .robots_time()
            .state_in(state.path());
        let conf = rewrite.apply(&text);
        let robot = mqtt_client::subscribe(broker.port, "action", "robot");
        let telegraf = Telegraf::start(version, &bin, &conf, &[]);
        wait_subscribed(&broker, "telegraf-tessla-in", "tessla", 0);
        let publisher = mqtt_client::Publisher::connect(broker.port, "robot-pub");
        // 129 ns past a multiple of 256: float64 rounds it up to the next multiple.
        let message = |i: usize, ns: i64| {
            format!(
                r#"{{"expectedSpeed":0.{i}5,"actualSpeed":"0.{i}4","lidar":[1,2,3],"time":{ns}}}"#
            )
            .into_bytes()
        };
        publisher.publish("tessla", message(0, 1_700_000_000_000_000_129));
        publisher.publish("tessla", message(1, 1_700_000_000_200_000_001));
        // The second message again, as a QoS 1 redelivery: Telegraf parses it again (another
        // field order), the monitor drops the exact duplicate.
        publisher.publish("tessla", message(1, 1_700_000_000_200_000_001));
        let got = mqtt_client::collect(&robot, 2, Duration::from_secs(30));
        assert_eq!(got.len(), 2, "{}", telegraf.log());
        assert!(
            robot.recv_timeout(Duration::from_secs(1)).is_err(),
            "Telegraf {version}: no action for the duplicate"
        );
        let log = telegraf.stop();
        let actions: Vec<Row> = got
            .iter()
            .map(|(_, p)| real_telegraf::action_row(p))
            .collect();
        assert_eq!(actions[0].time, 1_700_000_000_000);
        assert_eq!(actions[1].time, 1_700_000_000_200);
        let summary = log
            .lines()
            .find(|l| l.contains("summary:"))
            .unwrap_or_else(|| panic!("Telegraf {version}: no summary\n{log}"));
        assert!(
            summary.contains("summary: 3 records,") && summary.contains(" 1 duplicates"),
            "{summary}"
        );
        let times: Vec<i64> = real_telegraf::influx_rows(&influx, "telegraf", "mqtt_consumer")
            .iter()
            .map(|r| r.time)
            .collect();
        assert_eq!(
            times,
            vec![1_700_000_000_000_000_256, 1_700_000_000_200_000_000],
            "Telegraf {version}: the robot's ns times as float64"
        );
    }
}

#[test]
fn every_mqtt_conf_passes_telegraf_test() {
    for (version, bin) in real_telegraf::versions() {
        let Some(broker) = broker() else { return };
        let state = tempfile::tempdir().unwrap();
        for path in [
            "telegraf/telegraf.conf",
            "telegraf/telegraf-fleet.conf",
            "telegraf/telegraf-udp.conf",
            "examples/first-spec/telegraf.conf",
        ] {
            let text = real_telegraf::shipped(path);
            let mut r = Rewrite::new().replace(
                "tcp://127.0.0.1:1883",
                format!("tcp://127.0.0.1:{}", broker.port),
            );
            for (from, to) in [
                ("\"/usr/bin/tessla-telegraf\"", format!("{BIN:?}")),
                (
                    "/var/lib/tessla-telegraf",
                    state.path().display().to_string(),
                ),
                (
                    "/usr/share/tessla-telegraf/first-spec/",
                    format!("{}/examples/first-spec/", env!("CARGO_MANIFEST_DIR")),
                ),
                (
                    "udp://127.0.0.1:1654",
                    format!("udp://127.0.0.1:{}", servers::free_port()),
                ),
            ] {
                if text.contains(from) {
                    r = r.replace(from, to);
                }
            }
            let dir = tempfile::tempdir().unwrap();
            let conf = dir.path().join("telegraf.conf");
            std::fs::write(&conf, r.apply(&text)).unwrap();
            let bin_dir = std::path::Path::new(BIN).parent().unwrap();
            let out = Command::new(&bin)
                .arg("--config")
                .arg(&conf)
                .args(["--test", "--test-wait", "2"])
                .current_dir(env!("CARGO_MANIFEST_DIR"))
                .env(
                    "PATH",
                    format!(
                        "{}:{}",
                        bin_dir.display(),
                        std::env::var("PATH").unwrap_or_default()
                    ),
                )
                .output()
                .unwrap();
            let log = String::from_utf8_lossy(&out.stderr);
            assert!(
                out.status.success(),
                "Telegraf {version} --test {path}:\n{log}"
            );
            // --test exits 0 even when an input fails to start: its log must not say so.
            assert!(
                !log.contains("E! [agent] Starting input") && !log.contains("Error running agent"),
                "Telegraf {version} --test {path}:\n{log}"
            );
            assert!(log.contains("Loaded inputs:"), "{log}");
        }
    }
}

#[test]
fn the_udp_conf_without_its_namedrop_loops_as_the_connector_wiring_did() {
    // The control for the UDP test: the UDP conf without its namedrop, and a peer that echoes
    // what it gets (what the connector's pass-through did): one robot message circulates.
    let text = real_telegraf::shipped("telegraf/telegraf-udp.conf");
    let looped = text.replace("  namedrop = [\"mqtt_consumer\"]\n", "");
    assert_ne!(looped, text, "the conf's namedrop");
    for (version, bin) in real_telegraf::versions() {
        let Some(broker) = broker() else { return };
        let echo = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let telegraf_addr = format!("127.0.0.1:{}", servers::free_port());
        let conf = Rewrite::new()
            .replace(
                "tcp://127.0.0.1:1883",
                format!("tcp://127.0.0.1:{}", broker.port),
            )
            .replace(
                "udp://127.0.0.1:1653",
                format!("udp://{}", echo.local_addr().unwrap()),
            )
            .replace("udp://127.0.0.1:1654", format!("udp://{telegraf_addr}"))
            .replace("[[outputs.influxdb]]", "[[outputs.discard]]")
            .replace("  urls = [\"http://127.0.0.1:8086\"]\n", "")
            .replace("  database = \"telegraf\"\n", "")
            .apply(&looped);
        let telegraf = Telegraf::start(version, &bin, &conf, &[]);
        wait_subscribed(&broker, "telegraf-tessla-udp-in", "tessla", 0);
        echo.set_read_timeout(Some(Duration::from_millis(50)))
            .unwrap();
        let publisher = mqtt_client::Publisher::connect(broker.port, "robot-pub");
        publisher.publish("tessla", br#"{"expectedSpeed":0.1}"#.to_vec());
        let mut buf = vec![0u8; 65_536];
        let mut sent = 0;
        let until = Instant::now() + Duration::from_secs(2);
        while Instant::now() < until {
            if let Ok(n) = echo.recv(&mut buf) {
                sent += 1;
                let _ = echo.send_to(&buf[..n], &telegraf_addr);
            }
        }
        let _ = telegraf.stop();
        // One lap per flush of socket_writer (flush_interval 100 ms): 20 laps in 2 s.
        assert!(
            sent >= 5,
            "Telegraf {version}: one message sent {sent} times: the loop"
        );
    }
}

#[test]
fn our_longest_stderr_line_passes_telegrafs_reader() {
    // Telegraf reads the child's stderr line by line with a bufio.Scanner (64 KiB a line; a
    // longer one stops the reader for good). A bad --tag of 100 KB is quoted in our message:
    // it is cut below the limit, and what follows still reaches Telegraf's log.
    let long = "v".repeat(100_000);
    for (version, bin) in real_telegraf::versions() {
        let Some(broker) = broker() else { return };
        let conf = Rewrite::robot(crate::support::BIN, broker.port, None)
            .replace("/var/lib/tessla-telegraf", "/tmp")
            .replace("\"run\"", format!("\"run\", \"--tag\", \"{long}\""))
            .replace("[[outputs.influxdb]]", "[[outputs.discard]]")
            .replace("  urls = [\"http://127.0.0.1:8086\"]\n", "")
            .replace("  database = \"telegraf\"\n", "")
            .apply(&real_telegraf::shipped("telegraf/telegraf.conf"));
        let telegraf = Telegraf::start(version, &bin, &conf, &[]);
        // The child exits with code 2 at once, and is restarted every second.
        telegraf.wait_for(
            |log| log.matches("Restarting in 1s").count() >= 2,
            Duration::from_secs(30),
            "two restarts",
        );
        let log = telegraf.stop();
        assert!(
            !log.contains("token too long"),
            "Telegraf {version}:\n{log}"
        );
        let ours: Vec<&str> = log
            .lines()
            .filter(|l| {
                l.contains("[processors.execd]")
                    && l.contains("--tag")
                    && !l.contains("Starting process")
            })
            .collect();
        assert!(
            ours.len() >= 2,
            "Telegraf {version}: our message at each start:\n{log}"
        );
        assert!(
            ours.iter().all(|l| l.len() < 65_536 + 200),
            "{}",
            ours[0].len()
        );
    }
}
