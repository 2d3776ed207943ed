//! The dashboards in telegraf/dashboards/ query only names the bundled spec actually emits:
//! every measurement, field and tag of every InfluxQL and Flux query appears in what our binary
//! prints for the recorded run (pass-through telemetry and verdicts). Renaming an output
//! therefore fails this test instead of silently blanking a panel. The fleet panels (measurement
//! `tessla_fleet`) are checked against what the binary prints for the fleet example
//! (`--fleet-spec specs/fleet/fleet.tessla` over tests/fixtures/fleet/three_robots.lp).

use crate::support::dashboards;
use crate::support::recorded;

use dashboards::{
    Emitted, Refs, flux_queries, flux_refs, influxql_queries, influxql_refs, is_fleet,
};

/// What the binary prints for the fleet example: the robots' own lines and the fleet level's.
fn fleet_example_output() -> String {
    let out = crate::support::fleet_example::output(&[]);
    assert!(out.lines().any(|l| l.starts_with("tessla_fleet ")), "{out}");
    out
}

fn set(names: &[&str]) -> std::collections::BTreeSet<String> {
    names.iter().map(|s| s.to_string()).collect()
}

#[test]
fn influxql_names_are_extracted() {
    let r = influxql_refs(
        "SELECT count(\"p2_violated\") AS \"n\", \"speed\" FROM \"action\" WHERE \"p2_violated\" = true \
         AND \"topic\" = 'tessla' AND $timeFilter GROUP BY time($__interval), \"host\" fill(0)",
    );
    assert_eq!(
        r,
        Refs {
            measurements: set(&["action"]),
            fields: set(&["p2_violated", "speed"]),
            keys: set(&["p2_violated", "topic", "host"]),
        }
    );
}

#[test]
fn flux_names_are_extracted() {
    let r = flux_refs(
        "from(bucket: v.bucket)\n |> filter(fn: (r) => r._measurement == \"action\" and r[\"topic\"] == \"x\")\n \
         |> filter(fn: (r) => r._field == \"speed\" or r._field == \"augmented\")\n \
         |> pivot(rowKey: [\"_time\"], columnKey: [\"_field\"], valueColumn: \"_value\")\n \
         |> filter(fn: (r) => r.augmented == true)\n |> keep(columns: [\"_time\", \"speed\"])",
    );
    assert_eq!(
        r,
        Refs {
            measurements: set(&["action"]),
            fields: set(&["speed", "augmented"]),
            keys: set(&["topic", "augmented", "speed"]),
        }
    );
}

#[test]
fn a_renamed_output_is_caught() {
    let emitted = Emitted::from_lines(
        "action speed=0.1,p1_margin=0.5 1\nmqtt_consumer,topic=t expectedSpeed=1 1\n",
    );
    let ok = influxql_refs("SELECT \"speed\" FROM \"action\" WHERE $timeFilter");
    assert!(emitted.missing(&ok).is_empty());
    let renamed = influxql_refs("SELECT \"p1_margin_m\" FROM \"action\" WHERE $timeFilter");
    assert_eq!(
        emitted.missing(&renamed),
        vec!["field \"p1_margin_m\" of \"action\"".to_string()]
    );
    let bad_tag =
        flux_refs("filter(fn: (r) => r._measurement == \"mqtt_consumer\" and r.robot == \"1\")");
    assert_eq!(
        emitted.missing(&bad_tag),
        vec!["tag or field \"robot\" of \"mqtt_consumer\"".to_string()]
    );
}

#[test]
fn dashboards_cover_the_issue_panels() {
    let influxql = influxql_queries();
    let flux = flux_queries();
    assert!(influxql.len() >= 7 && flux.len() >= 7);
    for queries in [&influxql, &flux] {
        let text: String = queries.iter().map(|(_, q)| q.as_str()).collect();
        for name in [
            "expectedSpeed",
            "actualSpeed",
            "augmented",
            "p1_margin",
            "p1_status",
            "p2_violated",
            "p3_spikes",
            "p3_dropouts",
            "speed_mse",
            "robot_silent",
        ] {
            assert!(text.contains(name), "a panel shows {name}");
        }
    }
}

#[test]
fn every_dashboard_name_is_emitted_by_the_bundled_spec() {
    let (_, output) = recorded::recorded_output();
    let emitted = Emitted::from_lines(&output);
    let fleet_emitted = Emitted::from_lines(&fleet_example_output());
    let mut problems = Vec::new();
    let mut fleet_queries = 0;
    for (kind, queries, refs_of) in [
        (
            "InfluxQL",
            influxql_queries(),
            influxql_refs as fn(&str) -> Refs,
        ),
        ("Flux", flux_queries(), flux_refs as fn(&str) -> Refs),
    ] {
        for (panel, query) in queries {
            let refs = refs_of(&query);
            assert!(
                !refs.measurements.is_empty(),
                "{kind} {panel:?}: no measurement in {query}"
            );
            // A fleet panel reads what the fleet example writes, the others the robot spec's run.
            let emitted = if is_fleet(&query) {
                fleet_queries += 1;
                &fleet_emitted
            } else {
                &emitted
            };
            for missing in emitted.missing(&refs) {
                problems.push(format!(
                    "{kind} panel {panel:?} queries {missing}, not emitted"
                ));
            }
        }
    }
    assert!(
        problems.is_empty(),
        "{}\nemitted: {:#?}\nfleet: {:#?}",
        problems.join("\n"),
        emitted,
        fleet_emitted
    );
    // Three fleet panels in each dashboard (P2 count, closest distance, zone A occupancy).
    assert!(fleet_queries >= 6, "{fleet_queries} fleet queries");
}

/// The robot dashboard has a "Fleet" row, and both dashboards chart the fleet example's outputs
/// from `tessla_fleet`. A fleet series has no robot tag and no spec version (the fleet level
/// runs one spec over every robot), so fleet queries select neither; they name no robot tag.
#[test]
fn the_fleet_panels_show_the_examples_outputs_and_select_no_robot() {
    assert!(
        dashboards::row_titles(dashboards::ROBOT)
            .iter()
            .any(|t| t.starts_with("Fleet")),
        "a Fleet row in the robot dashboard"
    );
    for queries in [influxql_queries(), flux_queries()] {
        let fleet: Vec<&(String, String)> = queries.iter().filter(|(_, q)| is_fleet(q)).collect();
        for name in [
            "fleet_p2_violations",
            "closest_distance",
            "zone_a_occupancy",
        ] {
            assert!(
                fleet.iter().any(|(_, q)| q.contains(name)),
                "a fleet panel shows {name}: {fleet:#?}"
            );
        }
        for (panel, query) in fleet {
            for tag in ["topic", "robot", "spec_version"] {
                assert!(
                    !query.contains(&format!("\"{tag}\"")) && !query.contains(&format!("r.{tag}")),
                    "{panel:?}: the fleet has no {tag} tag: {query}"
                );
            }
        }
    }
}

/// `node tools/grafana-schema/check.mjs FILES...`, or `None` (after saying why, a failure with
/// `REQUIRE_SERVERS=1`) when the schema check is not installed (`tools/setup.sh` installs it).
fn grafana_schema_check(files: &[&std::path::Path]) -> Option<std::process::Output> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/grafana-schema");
    let installed = dir.join("node_modules/@grafana/schema").is_dir()
        && dir.join("node_modules/.bin/tsc").is_file();
    let node = crate::support::servers::require("node", "nodejs")?;
    if !installed {
        let hint = "tools/grafana-schema is not installed: run `bash tools/setup.sh` \
                    (or `cd tools/grafana-schema && npm ci`)";
        assert!(
            std::env::var("REQUIRE_SERVERS").map_or(true, |v| v != "1"),
            "REQUIRE_SERVERS=1 but {hint}"
        );
        eprintln!("SKIPPED: {hint}");
        return None;
    }
    Some(
        std::process::Command::new(node)
            .arg(dir.join("check.mjs"))
            .args(files)
            .output()
            .unwrap(),
    )
}

#[test]
fn dashboards_check_against_grafanas_schema() {
    let ours = [
        dashboards::dashboards_dir().join(dashboards::ROBOT),
        dashboards::dashboards_dir().join(dashboards::ANY_SPEC),
    ];
    let refs: Vec<&std::path::Path> = ours.iter().map(|p| p.as_path()).collect();
    let Some(out) = grafana_schema_check(&refs) else {
        return;
    };
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    // The check can fail: a misspelt variable option and a width that is not a number.
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(&ours[1]).unwrap();
    let mut bad: serde_json::Value = serde_json::from_str(&text).unwrap();
    bad["templating"]["list"][0]["multy"] = serde_json::Value::Bool(true);
    bad["panels"][0]["gridPos"]["w"] = serde_json::Value::String("wide".into());
    let path = dir.path().join("bad.json");
    std::fs::write(&path, bad.to_string()).unwrap();
    let out = grafana_schema_check(&[path.as_path()]).unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("'\"multy\"' does not exist"), "{err}");
    assert!(
        err.contains("Type 'string' is not assignable to type 'number'"),
        "{err}"
    );
}

#[test]
fn every_robot_panel_selects_robots_and_versions_and_names_no_topic() {
    // Fleet panels are the exception, checked by
    // the_fleet_panels_show_the_examples_outputs_and_select_no_robot.
    for (panel, query) in influxql_queries().into_iter().filter(|(_, q)| !is_fleet(q)) {
        assert!(
            dashboards::without_selection(&query).is_some(),
            "{panel:?}: no robot selection in {query}"
        );
        assert!(
            query.contains(" GROUP BY ") && query.contains("\"robot\""),
            "{panel:?}: not one series per robot: {query}"
        );
        assert!(
            !query.contains("\"topic\" = '"),
            "{panel:?}: a fixed topic: {query}"
        );
    }
    // The InfluxDB 2 template: no fixed topic either, and every chart of both dashboards
    // selects by the robot variable (the `robot` or `topic` tag) and, on our outputs, by the
    // spec version (the robot's own telemetry has no version).
    let robot = "filter(fn: (r) => v.robot == \"All\" or r.robot == v.robot or r.topic == v.robot)";
    let version =
        "filter(fn: (r) => v.spec_version == \"All\" or r.spec_version == v.spec_version)";
    let any_spec = dashboards::flux_any_spec_queries();
    assert!(any_spec.len() >= 4, "the any-spec dashboard's charts");
    for (chart, query) in flux_queries()
        .into_iter()
        .filter(|(_, q)| !is_fleet(q))
        .chain(any_spec.clone())
    {
        let fixed = query.replace(" == v.robot", "");
        assert!(
            !fixed.contains("r.topic ==") && !fixed.contains("r[\"topic\"] =="),
            "{chart:?}: a fixed topic: {query}"
        );
        assert!(
            query.contains(robot),
            "{chart:?}: no robot selection: {query}"
        );
        assert!(
            query.contains("\"mqtt_consumer\"") || query.contains(version),
            "{chart:?}: no spec-version selection: {query}"
        );
    }
    // The any-spec dashboard names no output: the measurement and the field are variables.
    for (chart, query) in any_spec {
        assert!(
            query.contains("r._measurement == v.measurement and r._field == v.field"),
            "{chart:?}: not the chosen measurement and field: {query}"
        );
    }
    let template = dashboards::read_json("influxdb2-template.json");
    let variables: Vec<&str> = template
        .as_array()
        .expect("a template is an array")
        .iter()
        .filter(|r| r["kind"] == "Variable")
        .filter_map(|r| r["spec"]["name"].as_str())
        .collect();
    for v in ["bucket", "robot", "spec_version", "measurement", "field"] {
        assert!(
            variables.contains(&v),
            "variable {v} in the template: {variables:?}"
        );
    }
}
