//! The Grafana dashboards (telegraf/dashboards/) on what the real Telegraf writes into a real
//! InfluxDB 1.x through the shipped confs and through a user's own spec: every variable's query
//! lists the robots and spec versions that were sent, and every panel's query, with its
//! variables filled in as Grafana fills them (`${robot:regex}` escaped and joined as `(a|b)`,
//! "All" as `.*`, `$timeFilter`, `$__interval`), returns rows of a type the panel draws; a panel
//! that stays empty fails. Picking one robot keeps that robot's series only.
//!
//! Confs: telegraf.conf, telegraf-fleet.conf, telegraf-p0.conf (NATS, with an InfluxDB output
//! added) and a conf for a user's spec written here. Run with the newest pinned Telegraf build
//! only (the conf's wiring is what is tested here; tests/servers/telegraf_real.rs runs each
//! conf under both builds).

use super::telegraf_real_nats as nats;
use crate::support::dashboards;
use crate::support::nats_cluster;
use crate::support::real_telegraf;
use crate::support::recorded;
use crate::support::servers;

use crate::support::BIN;
use dashboards::{ANY_SPEC, Panel, Pick, ROBOT, fill, influxql_panels, variables};
use real_telegraf::{Rewrite, Telegraf, broker, wait_subscribed};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;
use std::time::{Duration, Instant};

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

/// Publish the file's records as the robot's JSON on `topic`, as fast as possible.
fn replay(path: &std::path::Path, port: u16, topic: &str, extra: &[&str]) {
    let out = Command::new(BIN)
        .args(["replay", path.to_str().unwrap()])
        .args(["--broker", &format!("mqtt://127.0.0.1:{port}")])
        .args(["--topic", topic, "--speed", "0"])
        .args(extra)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "replay: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Points of `measurement` with `field` in database `db`.
fn count(influx: &servers::Influxd, db: &str, measurement: &str, field: &str) -> u64 {
    let (_, json) = influx.query(
        Some(db),
        &format!("SELECT count(\"{field}\") FROM \"{measurement}\""),
    );
    json["results"][0]["series"][0]["values"][0][1]
        .as_u64()
        .unwrap_or(0)
}

/// Poll until `measurement` holds `want` points with `field` (Telegraf flushes every 100 ms).
fn wait_points(
    influx: &servers::Influxd,
    log: &dyn Fn() -> String,
    measurement: &str,
    field: &str,
    want: u64,
) {
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let got = count(influx, "telegraf", measurement, field);
        if got >= want {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "{got} of {want} {measurement}.{field} points in InfluxDB; Telegraf log:\n{}",
            log()
        );
        std::thread::sleep(Duration::from_millis(250));
    }
}

/// The values a variable's query lists (the first column, as Grafana takes it).
fn variable_values(
    influx: &servers::Influxd,
    file: &str,
    name: &str,
    picks: &BTreeMap<String, Pick>,
) -> BTreeSet<String> {
    let (_, query) = variables(file)
        .into_iter()
        .find(|(n, _)| n == name)
        .unwrap_or_else(|| panic!("{file} has no variable {name}"));
    let q = fill(&query, picks, (0, 0), "1s");
    let (status, json) = influx.query(Some("telegraf"), &q);
    assert_eq!(status, 200, "{q}: {json}");
    let result = &json["results"][0];
    assert!(result.get("error").is_none(), "{q}: {result}");
    let column = if q.starts_with("SHOW TAG VALUES") {
        1
    } else {
        0
    };
    result["series"]
        .as_array()
        .into_iter()
        .flatten()
        .flat_map(|s| s["values"].as_array().cloned().unwrap_or_default())
        .filter_map(|row| row[column].as_str().map(str::to_string))
        .collect()
}

/// What one panel query answered: its series' tags and the types of its non-null values
/// (`number`, `string`, `boolean`), one entry per value.
struct Answer {
    tags: Vec<BTreeMap<String, String>>,
    values: Vec<&'static str>,
}

fn run(influx: &servers::Influxd, q: &str) -> Answer {
    let (status, json) = influx.query(Some("telegraf"), q);
    assert_eq!(status, 200, "{q}: {json}");
    let result = &json["results"][0];
    assert!(result.get("error").is_none(), "{q}: {result}");
    let mut answer = Answer {
        tags: Vec::new(),
        values: Vec::new(),
    };
    for s in result["series"].as_array().into_iter().flatten() {
        let tags = s["tags"]
            .as_object()
            .map(|o| {
                o.iter()
                    .map(|(k, v)| (k.clone(), v.as_str().unwrap_or("").to_string()))
                    .collect()
            })
            .unwrap_or_default();
        answer.tags.push(tags);
        for row in s["values"].as_array().into_iter().flatten() {
            for v in row.as_array().into_iter().flatten().skip(1) {
                answer.values.push(match v {
                    Value::Number(_) => "number",
                    Value::String(_) => "string",
                    Value::Bool(_) => "boolean",
                    _ => continue,
                });
            }
        }
    }
    answer
}

/// Run every panel of `file` with `picks`; returns, per panel title, how many values of a type
/// the panel draws its queries returned, and checks `each_series` on every series' tags.
fn panels_answer(
    influx: &servers::Influxd,
    file: &str,
    picks: &BTreeMap<String, Pick>,
    range: (i64, i64),
    each_series: impl Fn(&BTreeMap<String, String>) -> bool,
) -> Vec<(Panel, Vec<usize>)> {
    let mut out = Vec::new();
    // The fleet panels read `tessla_fleet`, which a robot conf does not write (--fleet-spec):
    // tests/cli/pipeline_dashboards.rs checks them against the fleet example's output.
    for panel in influxql_panels(file)
        .into_iter()
        .filter(|p| !p.queries.iter().any(|q| dashboards::is_fleet(q)))
    {
        let mut per_query = Vec::new();
        for q in &panel.queries {
            let concrete = fill(q, picks, range, "1s");
            let a = run(influx, &concrete);
            for t in &a.tags {
                assert!(
                    each_series(t),
                    "{}: a series {t:?} of {concrete}",
                    panel.title
                );
            }
            per_query.push(
                a.values
                    .iter()
                    .filter(|t| !panel.drops.iter().any(|d| d == *t))
                    .count(),
            );
        }
        out.push((panel, per_query));
    }
    out
}

fn picks(list: &[(&str, Pick)]) -> BTreeMap<String, Pick> {
    list.iter()
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect()
}

/// Nanoseconds since the epoch.
fn now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as i64
}

/// Every query of every panel answered (`allow_empty`: queries, by their text, that may not).
fn assert_all_answer(what: &str, answers: &[(Panel, Vec<usize>)], allow_empty: &[&str]) {
    let mut empty = Vec::new();
    for (panel, counts) in answers {
        assert!(
            counts.iter().any(|c| *c > 0),
            "{what}: panel {:?} stays empty: {:?}",
            panel.title,
            panel.queries
        );
        for (q, c) in panel.queries.iter().zip(counts) {
            if *c == 0 && !allow_empty.iter().any(|a| q.contains(a)) {
                empty.push(format!("{:?}: {q}", panel.title));
            }
        }
    }
    assert!(
        empty.is_empty(),
        "{what}: empty queries:\n{}",
        empty.join("\n")
    );
}

/// The query that may stay empty on the recorded run: actions augmented for P1 and P2 at once
/// (reason `p1,p2`), which the recorded run never has (43 for `p1`, 60 for `p2`); its panel
/// answers with the other reasons.
const NEVER_IN_THE_RECORDED_RUN: &[&str] = &["'p1,p2'"];

/// A shipped robot conf under the real Telegraf: `topics` the robots publish on, `robots` the
/// values the robot variable must list (the `--instance-by` tag's values; none without it).
fn robot_dashboard_on(
    conf_path: &str,
    client_id: &str,
    subscription: &str,
    topics: &[&str],
    records: usize,
    robots: &[&str],
    versions: usize,
) {
    let Some((version, bin)) = real_telegraf::versions().pop() else {
        return;
    };
    let Some(broker) = broker() else { return };
    let Some(influx) = servers::Influxd::start() else {
        return;
    };
    let state = tempfile::tempdir().unwrap();
    let conf = Rewrite::robot(crate::support::BIN, broker.port, Some(&influx.url("")))
        .state_in(state.path())
        .apply(&real_telegraf::shipped(conf_path));
    // The dashboard's time range: from the start to a minute past the end (Telegraf's time).
    let start = now_ns() - 60_000_000_000;
    let telegraf = Telegraf::start(version, &bin, &conf, &[]);
    wait_subscribed(&broker, client_id, subscription, 0);
    let dir = tempfile::tempdir().unwrap();
    let file = head(&dir, records);
    for t in topics {
        replay(&file, broker.port, t, &[]);
    }
    wait_points(
        &influx,
        &|| telegraf.log(),
        "action",
        "speed",
        (records * topics.len()) as u64,
    );

    let range = (start, now_ns() + 60_000_000_000);
    let all = picks(&[("robot", Pick::All), ("spec_version", Pick::All)]);
    let listed = variable_values(&influx, ROBOT, "robot", &all);
    let want: BTreeSet<String> = robots.iter().map(|s| s.to_string()).collect();
    assert_eq!(listed, want, "{conf_path}: the robot variable");
    let listed_versions = variable_values(&influx, ROBOT, "spec_version", &all);
    assert_eq!(
        listed_versions.len(),
        versions,
        "{conf_path}: {listed_versions:?}"
    );

    let answers = panels_answer(&influx, ROBOT, &all, range, |_| true);
    assert_all_answer(conf_path, &answers, NEVER_IN_THE_RECORDED_RUN);

    // One robot (the last one) and its spec version: its series only, and every panel answers.
    if let Some(one) = robots.last() {
        let mut chosen = vec![("robot", Pick::Values(vec![one.to_string()]))];
        if let Some(v) = listed_versions.iter().next() {
            chosen.push(("spec_version", Pick::Values(vec![v.clone()])));
        } else {
            chosen.push(("spec_version", Pick::All));
        }
        let answers = panels_answer(&influx, ROBOT, &picks(&chosen), range, |tags| {
            tags.get("topic").map(String::as_str) == Some(*one)
                || tags.get("robot").map(String::as_str) == Some(*one)
        });
        assert_all_answer(
            &format!("{conf_path}, robot {one}"),
            &answers,
            NEVER_IN_THE_RECORDED_RUN,
        );
        // Two robots: both appear, as separate series.
        if robots.len() >= 2 {
            let two: Vec<String> = robots[..2].iter().map(|s| s.to_string()).collect();
            let answers = panels_answer(
                &influx,
                ROBOT,
                &picks(&[
                    ("robot", Pick::Values(two.clone())),
                    ("spec_version", Pick::All),
                ]),
                range,
                |tags| two.iter().any(|r| tags.get("topic") == Some(r)),
            );
            assert_all_answer(
                &format!("{conf_path}, robots {two:?}"),
                &answers,
                NEVER_IN_THE_RECORDED_RUN,
            );
        }
    }
    let log = telegraf.stop();
    real_telegraf::assert_no_error(version, &log);
}

#[test]
fn robot_dashboard_on_the_main_conf_under_real_telegraf() {
    // One robot, no --instance-by: the robot variable lists nothing and All shows the robot.
    robot_dashboard_on(
        "telegraf/telegraf.conf",
        "telegraf-tessla-in",
        "tessla",
        &["tessla"],
        300,
        &[],
        0,
    );
}

#[test]
fn robot_dashboard_on_the_fleet_conf_under_real_telegraf() {
    robot_dashboard_on(
        "telegraf/telegraf-fleet.conf",
        "telegraf-tessla-fleet-in",
        "tessla/+",
        &["tessla/r1", "tessla/r2", "tessla/r3"],
        300,
        &["tessla/r1", "tessla/r2", "tessla/r3"],
        1,
    );
}

/// A user's spec (examples/first-spec/battery.tessla, then dock.tessla: a Bool verdict, a Float
/// total, a watchdog that fires once, a count and a text action) for two robots, through a
/// conf written here: the robot's own time, `--instance-by topic`, `--version-tag`.
#[test]
fn any_spec_dashboard_on_a_users_spec_under_real_telegraf() {
    let Some((version, bin)) = real_telegraf::versions().pop() else {
        return;
    };
    let Some(broker) = broker() else { return };
    let Some(influx) = servers::Influxd::start() else {
        return;
    };
    let spec = |name: &str| {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("examples/first-spec")
            .join(name)
            .display()
            .to_string()
    };
    let execd = |order: u32, name: &str| {
        format!(
            "[[processors.execd]]\n  order = {order}\n  namepass = [\"mqtt_consumer\"]\n  \
             command = [{BIN:?}, \"run\", \"--spec\", {:?}, \"--instance-by\", \"topic\", \
             \"--version-tag\", \"spec_version\"]\n  restart_delay = \"1s\"\n\n",
            spec(name)
        )
    };
    let conf = format!(
        "[agent]\n  interval = \"1s\"\n  flush_interval = \"100ms\"\n  \
         skip_processors_after_aggregators = true\n\n\
         [[inputs.mqtt_consumer]]\n  servers = [\"tcp://127.0.0.1:{}\"]\n  topics = [\"tessla/+\"]\n  \
         qos = 1\n  client_id = \"telegraf-first-spec\"\n  data_format = \"json\"\n  \
         json_time_key = \"time\"\n  json_time_format = \"unix_ns\"\n\n{}{}\
         [[outputs.influxdb]]\n  urls = [\"{}\"]\n  database = \"telegraf\"\n",
        broker.port,
        execd(1, "battery.tessla"),
        execd(2, "dock.tessla"),
        influx.url("")
    );
    let telegraf = Telegraf::start(version, &bin, &conf, &[]);
    wait_subscribed(&broker, "telegraf-first-spec", "tessla/+", 0);
    let battery = spec("battery.lp");
    let robots = ["tessla/r1", "tessla/r2"];
    for r in robots {
        replay(
            std::path::Path::new(&battery),
            broker.port,
            r,
            &["--time-key", "time"],
        );
    }
    // battery.lp: 7 records a robot, the battery falls below 11 V once: one command, and
    // alerts 0 at the first record and 1 at the fall.
    wait_points(
        &influx,
        &|| telegraf.log(),
        "battery_check",
        "total_drop",
        14,
    );
    wait_points(&influx, &|| telegraf.log(), "battery_check", "alerts", 4);
    // The robot's own time: 1700000000 s to 1700000010 s.
    let range = (1_699_999_990_000_000_000, 1_700_000_020_000_000_000);
    wait_points(&influx, &|| telegraf.log(), "action", "command", 2);

    let none = picks(&[]);
    let measurements = variable_values(&influx, ANY_SPEC, "measurement", &none);
    for m in ["battery_check", "action", "mqtt_consumer"] {
        assert!(measurements.contains(m), "{measurements:?}");
    }
    let on = |m: &str| {
        picks(&[
            ("measurement", Pick::Raw(m.to_string())),
            ("robot", Pick::All),
            ("spec_version", Pick::All),
        ])
    };
    let fields = variable_values(&influx, ANY_SPEC, "field", &on("battery_check"));
    let want: BTreeSet<String> = ["alerts", "low", "silent", "total_drop"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    assert_eq!(fields, want);
    let listed = variable_values(&influx, ANY_SPEC, "robot", &on("battery_check"));
    assert_eq!(listed, robots.iter().map(|s| s.to_string()).collect());
    let versions = variable_values(&influx, ANY_SPEC, "spec_version", &on("battery_check"));
    assert_eq!(versions.len(), 2, "one version per spec: {versions:?}");

    // battery_check, every output, `alerts` as the count: every panel draws something.
    let mut chosen = on("battery_check");
    chosen.insert("field".into(), Pick::All);
    chosen.insert("counts".into(), Pick::Values(vec!["alerts".into()]));
    let answers = panels_answer(&influx, ANY_SPEC, &chosen, range, |_| true);
    assert_all_answer("battery_check", &answers, &[]);
    // One robot only.
    chosen.insert("robot".into(), Pick::Values(vec!["tessla/r2".into()]));
    let answers = panels_answer(&influx, ANY_SPEC, &chosen, range, |t| {
        t.get("topic").map(String::as_str) == Some("tessla/r2")
    });
    assert_all_answer("battery_check, robot tessla/r2", &answers, &[]);
    // The watchdog alone (one event per robot, at 5 s): seen as a point and in the timeline.
    chosen.insert("robot".into(), Pick::All);
    chosen.insert("field".into(), Pick::Values(vec!["silent".into()]));
    let answers = panels_answer(&influx, ANY_SPEC, &chosen, range, |_| true);
    for (panel, counts) in &answers {
        let drawn: usize = counts.iter().sum();
        if panel.title.starts_with("Bool") || panel.title.starts_with("Events") {
            assert_eq!(drawn, 2, "{}: one `silent` per robot", panel.title);
        }
    }
    // The action: a text output only; the numbers and counts panels do not apply to it.
    let mut chosen = on("action");
    chosen.insert("field".into(), Pick::All);
    chosen.insert("counts".into(), Pick::All);
    let answers = panels_answer(&influx, ANY_SPEC, &chosen, range, |_| true);
    for (panel, counts) in &answers {
        let drawn: usize = counts.iter().sum();
        if panel.drops.iter().any(|d| d == "string") {
            assert_eq!(drawn, 0, "{}: action has text only", panel.title);
        } else {
            assert!(drawn >= 2, "{}: the command of each robot", panel.title);
        }
    }
    let log = telegraf.stop();
    real_telegraf::assert_no_error(version, &log);
}

/// The NATS partition conf (telegraf/fleet-nats/telegraf-p0.conf, rewritten onto the test's
/// secured 3-node cluster as tests/servers/telegraf_real_nats.rs does) with an InfluxDB output
/// added, as a user who wants the dashboards adds one (the shipped NATS confs write actions to
/// MQTT only). Partition 0's two robots publish through the MQTT gateway. The robot variable
/// lists them (tag `robot`); every panel answers. Not applicable: the telemetry query of the
/// speeds panel (`mqtt_consumer`), since the conf runs `--no-passthrough` (no robot record
/// reaches an output); the panel answers with the actions.
#[test]
fn robot_dashboard_on_a_nats_partition_conf_under_real_telegraf() {
    let _fleet = nats_cluster::one_fleet_at_a_time();
    let Some((version, bin)) = real_telegraf::versions().pop() else {
        return;
    };
    let Some(influx) = servers::Influxd::start() else {
        return;
    };
    let robots = nats::robot_ids();
    let Some(cluster) =
        nats_cluster::Cluster::start_secured(&nats_cluster::shipped_mapping(), &robots)
    else {
        return;
    };
    let ours: Vec<String> = robots
        .iter()
        .filter(|r| nats::partition_of(r) == 0)
        .cloned()
        .collect();
    // 70 records (14 s at the recorded pace): P2 violations from record 61. The first P1
    // violation (record 265) and P1 `unknown` (251) come later: the main and fleet confs' tests
    // cover those queries; here their panels answer with P2's.
    let records = nats::recorded_head(70);
    let conf = format!(
        "{}\n[[outputs.influxdb]]\n  urls = [\"{}\"]\n  database = \"telegraf\"\n",
        nats::rewritten(0, &cluster),
        influx.url("")
    );
    nats::warm_up_mqtt(&cluster, &records[0]);
    let env = [
        ("FLEET_PASSWORD", cluster.password("fleet-p0")),
        ("TESSLA_MEMBER", "a".to_string()),
    ];
    let env: Vec<(&str, &str)> = env.iter().map(|(k, v)| (*k, v.as_str())).collect();
    let member = nats::Member::start("p0-a", version, &bin, &conf, &env);
    let mut leases = nats::Leases::new(&cluster);
    leases.wait_for(0, member.monitor(), Duration::from_secs(60), &|| {
        member.log()
    });
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("head.lp");
    std::fs::write(&file, records.join("\n") + "\n").unwrap();
    let mut publishers: Vec<std::process::Child> = ours
        .iter()
        .enumerate()
        .map(|(k, id)| nats::robot(&cluster, k % 3, id, &file))
        .collect();
    for p in &mut publishers {
        let status = p.wait().unwrap();
        assert!(status.success(), "a robot's replay failed");
    }
    wait_points(
        &influx,
        &|| member.log(),
        "action",
        "speed",
        (records.len() * ours.len()) as u64,
    );
    // The robot's own time (json_time_key): the recorded run's, a minute either side.
    let time_of = |line: &String| -> i64 {
        line.rsplit(' ')
            .next()
            .and_then(|t| t.parse().ok())
            .unwrap()
    };
    let range = (
        time_of(&records[0]) - 60_000_000_000,
        time_of(&records[records.len() - 1]) + 60_000_000_000,
    );
    let all = picks(&[("robot", Pick::All), ("spec_version", Pick::All)]);
    let listed = variable_values(&influx, ROBOT, "robot", &all);
    assert_eq!(listed, ours.iter().cloned().collect::<BTreeSet<_>>());
    let versions = variable_values(&influx, ROBOT, "spec_version", &all);
    assert_eq!(versions.len(), 1, "{versions:?}");
    let mut allowed = NEVER_IN_THE_RECORDED_RUN.to_vec();
    allowed.extend(["FROM \"mqtt_consumer\"", "'violated'", "'unknown'", "'p1'"]);
    let answers = panels_answer(&influx, ROBOT, &all, range, |_| true);
    assert_all_answer("telegraf-p0.conf", &answers, &allowed);
    let one = ours[0].clone();
    let chosen = picks(&[
        ("robot", Pick::Values(vec![one.clone()])),
        ("spec_version", Pick::All),
    ]);
    let answers = panels_answer(&influx, ROBOT, &chosen, range, |t| {
        t.get("robot") == Some(&one)
    });
    assert_all_answer(
        &format!("telegraf-p0.conf, robot {one}"),
        &answers,
        &allowed,
    );
}
