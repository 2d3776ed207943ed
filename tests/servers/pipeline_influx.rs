//! Our output in a real InfluxDB 1.x: every line we print is accepted by its /write API (its
//! parser is an independent check of our line protocol), every point is stored, and each
//! InfluxQL dashboard panel query answers what the points say (worked out here without InfluxDB).
//! The fleet example's output (`--fleet-spec`) too: its fleet panels answer what `tessla_fleet`
//! holds.

use crate::support::dashboards;
use crate::support::recorded;
use crate::support::servers;

use dashboards::{
    Expected, Pick, Point, expected_answer, fill, influxql_queries, is_fleet, points,
    without_selection,
};
use serde_json::Value;

const DB: &str = "tessla";

/// Rows of all series of an answer, or (for aggregates) the sum of column 1.
fn answer(json: &Value, aggregate: bool) -> Expected {
    let result = &json["results"][0];
    assert!(result.get("error").is_none(), "InfluxDB error: {result}");
    let series = result["series"].as_array().cloned().unwrap_or_default();
    if aggregate {
        let sum = series
            .iter()
            .flat_map(|s| s["values"].as_array().cloned().unwrap_or_default())
            .map(|row| row[1].as_f64().unwrap_or(0.0))
            .sum();
        Expected::Aggregate(sum)
    } else {
        Expected::Rows(
            series
                .iter()
                .map(|s| s["values"].as_array().map_or(0, Vec::len))
                .sum(),
        )
    }
}

/// Write `output` to a fresh InfluxDB, check it all arrived, run every panel query; the
/// queries that returned data (`None`: no InfluxDB here).
fn check_output_in_influxdb(output: &str) -> Option<Vec<String>> {
    let influx = servers::Influxd::start()?;
    let (status, json) = influx.query(None, &format!("CREATE DATABASE \"{DB}\""));
    assert_eq!(status, 200, "{json}");

    // Write in batches of 1000 lines, as Telegraf's outputs.influxdb does by default.
    let lines: Vec<&str> = output.lines().collect();
    assert!(!lines.is_empty(), "nothing to write");
    for batch in lines.chunks(1000) {
        let body = batch.join("\n") + "\n";
        let (status, text) = influx.write(DB, &body);
        assert_eq!(status, 204, "InfluxDB rejected our output: {text}");
    }

    // Every point is stored: per measurement, as many rows as distinct points.
    let pts: Vec<Point> = points(output);
    let mut measurements: Vec<&str> = pts.iter().map(|p| p.measurement.as_str()).collect();
    measurements.dedup();
    measurements.sort_unstable();
    measurements.dedup();
    for m in measurements {
        let want = pts.iter().filter(|p| p.measurement == m).count();
        let (status, json) = influx.query(Some(DB), &format!("SELECT * FROM \"{m}\""));
        assert_eq!(status, 200);
        assert_eq!(answer(&json, false), Expected::Rows(want), "points of {m}");
    }

    let first = pts.iter().map(|p| p.time).min().unwrap();
    let last = pts.iter().map(|p| p.time).max().unwrap();
    let mut answered = Vec::new();
    for (panel, query) in influxql_queries() {
        // All robots and versions: the selection matches every point (absent tags too). A fleet
        // panel has no selection: one series for the fleet.
        let plain = if is_fleet(&query) {
            query.clone()
        } else {
            without_selection(&query).expect("a robot and version selection")
        };
        let want = expected_answer(&plain, &pts);
        let picks = [("robot", Pick::All), ("spec_version", Pick::All)]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect();
        let concrete = fill(&query, &picks, (first, last), "1s");
        let (status, json) = influx.query(Some(DB), &concrete);
        assert_eq!(status, 200, "{panel}: {concrete}: {json}");
        let got = answer(&json, matches!(want, Expected::Aggregate(_)));
        assert_eq!(got, want, "panel {panel:?}: {concrete}");
        if got != Expected::Rows(0) && got != Expected::Aggregate(0.0) {
            answered.push(query);
        }
    }
    drop(influx);
    Some(answered)
}

/// Output shaped as ours: pass-through telemetry (string actualSpeed, lidar fields, Telegraf's
/// tags) followed by the `action` metric of each step.
fn synthetic_output() -> String {
    let t0: i64 = 1_700_000_000_000_000_000;
    let mut out = String::new();
    let mut sq = 0.0;
    for i in 0..120i64 {
        let t = t0 + i * 200_000_000;
        let expected = if i < 60 { 0.015 } else { 0.1 };
        let actual = if (70..80).contains(&i) { 0.0 } else { expected };
        out.push_str(&format!(
            "mqtt_consumer,host=robot-pc,topic=tessla actualSpeed=\"{actual}\",expectedSpeed={expected},lidar_0=1.5,lidar_1=0 {t}\n"
        ));
        let diff: f64 = expected - actual;
        sq += diff * diff;
        let violated = diff.abs() > 0.02;
        let status = match i {
            90..=99 => "violated",
            100..=104 => "unknown",
            _ => "ok",
        };
        out.push_str(&format!(
            "action augmented={violated},p1_margin={},p1_status=\"{status}\",p2_violated={violated},p3_dropouts={}i,p3_spikes={}i,speed={},speed_mse={} {t}\n",
            1.2 - 0.01 * i as f64,
            i % 3,
            if i % 25 == 7 { 1 } else { 0 },
            if violated { expected + 0.5 * diff } else { expected },
            sq / (i + 1) as f64
        ));
    }
    out
}

#[test]
fn synthetic_output_is_stored_and_every_panel_answers() {
    if let Some(answered) = check_output_in_influxdb(&synthetic_output()) {
        assert!(answered.len() >= 8, "only {answered:#?} returned data");
    }
}

#[test]
fn recorded_run_output_is_stored_and_every_panel_answers() {
    let (_, output) = recorded::recorded_output();
    if let Some(answered) = check_output_in_influxdb(&output) {
        assert!(answered.len() >= 8, "only {answered:#?} returned data");
    }
}

/// The fleet example (tests/fixtures/fleet/three_robots.lp through `--fleet-spec
/// specs/fleet/fleet.tessla`) in a real InfluxDB: every fleet panel returns what `tessla_fleet`
/// holds, and each has data.
#[test]
fn fleet_example_output_is_stored_and_every_fleet_panel_answers() {
    let output = crate::support::fleet_example::output(&[]);
    let Some(answered) = check_output_in_influxdb(&output) else {
        return;
    };
    let fleet: Vec<&String> = answered.iter().filter(|q| is_fleet(q)).collect();
    for name in [
        "fleet_p2_violations",
        "closest_distance",
        "zone_a_occupancy",
    ] {
        assert!(
            fleet.iter().any(|q| q.contains(name)),
            "no data for {name}: {fleet:#?}"
        );
    }
}
