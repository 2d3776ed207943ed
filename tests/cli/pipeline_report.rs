//! `tessla-telegraf report`: the HTML and every SVG are well-formed XML, the plots are there,
//! and the MSE and violation counts in the table are the ones computed here independently.

use crate::support::recorded;

use std::path::Path;
use std::process::Command;

use crate::support::BIN;

const MS: i64 = 1_000_000;
const T0: i64 = 1_700_000_000_000_000_000;

/// A synthetic run shaped like our output: pass-through telemetry then the verdicts of a step.
/// Returns the text and the independently computed (MSE, P1 violated, P1 unknown, P2 violated,
/// augmented, spikes, dropouts).
fn synthetic_run() -> (String, f64, usize, usize, usize, usize, f64, f64) {
    let mut text = String::new();
    let (mut sq_sum, mut pairs) = (0.0, 0usize);
    let (mut p1_violated, mut p1_unknown, mut p2_violated, mut augmented) = (0, 0, 0, 0);
    let (mut spikes, mut dropouts) = (0.0, 0.0);
    for i in 0..50i64 {
        let t = T0 + i * 200 * MS;
        let expected = if i < 25 { 0.015 } else { 0.1 };
        // The robot is stuck between steps 30 and 39.
        let actual = if (30..40).contains(&i) {
            0.0
        } else {
            expected - 0.001 * (i % 3) as f64
        };
        // Every 7th message has no actualSpeed: it must not count in the MSE.
        if i % 7 == 3 {
            text.push_str(&format!(
                "mqtt_consumer,host=h,topic=tessla expectedSpeed={expected} {t}\n"
            ));
            continue;
        }
        // actualSpeed arrives as a string (json_string_fields), as in the paper's config.
        text.push_str(&format!(
            "mqtt_consumer,host=h,topic=tessla expectedSpeed={expected},actualSpeed=\"{actual}\",lidar_0=1.5 {t}\n"
        ));
        let diff: f64 = expected - actual;
        sq_sum += diff * diff;
        pairs += 1;
        let violated = diff.abs() > 0.02;
        let speed = if violated {
            (expected + 0.5 * diff).min(0.22)
        } else {
            expected
        };
        let status = match i {
            40..=44 => "violated",
            45..=46 => "unknown",
            _ => "ok",
        };
        let (s, d) = (if i % 10 == 5 { 2.0 } else { 0.0 }, (i % 4) as f64);
        p1_violated += usize::from(status == "violated");
        p1_unknown += usize::from(status == "unknown");
        p2_violated += usize::from(violated);
        augmented += usize::from(violated);
        spikes += s;
        dropouts += d;
        text.push_str(&format!("p2_diff value={diff} {t}\n"));
        text.push_str(&format!("p2_violated value={violated} {t}\n"));
        text.push_str(&format!("speed_mse value={} {t}\n", sq_sum / pairs as f64));
        text.push_str(&format!(
            "action speed={speed},augmented={violated},p1_status=\"{status}\",p1_margin={},p2_violated={violated},p3_spikes={s}i,p3_dropouts={d}i {t}\n",
            1.0 - 0.02 * i as f64
        ));
    }
    (
        text,
        sq_sum / pairs as f64,
        p1_violated,
        p1_unknown,
        p2_violated,
        augmented,
        spikes,
        dropouts,
    )
}

fn cell(doc: &roxmltree::Document<'_>, id: &str) -> f64 {
    let node = doc
        .descendants()
        .find(|n| n.attribute("id") == Some(id))
        .unwrap_or_else(|| panic!("no element with id {id}"));
    node.attribute("data-value")
        .unwrap_or_else(|| panic!("{id} has no data-value"))
        .parse()
        .unwrap()
}

fn check_svg(path: &Path, min_lines: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    let doc = roxmltree::Document::parse(&text)
        .unwrap_or_else(|e| panic!("{} is not well-formed: {e}", path.display()));
    assert_eq!(doc.root_element().tag_name().name(), "svg");
    let polylines = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "polyline" || n.tag_name().name() == "path")
        .count();
    assert!(
        polylines >= min_lines,
        "{}: {polylines} lines",
        path.display()
    );
    text
}

#[test]
fn report_is_well_formed_with_independent_numbers() {
    let (text, mse, p1v, p1u, p2v, aug, spikes, dropouts) = synthetic_run();
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("out.lp");
    std::fs::write(&input, &text).unwrap();
    let out_dir = dir.path().join("report");
    let out = Command::new(BIN)
        .args([
            "report",
            input.to_str().unwrap(),
            "-o",
            out_dir.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("index.html"),
        "prints what it wrote: {stdout}"
    );

    let html = std::fs::read_to_string(out_dir.join("index.html")).unwrap();
    let doc = roxmltree::Document::parse_with_options(
        &html,
        roxmltree::ParsingOptions {
            allow_dtd: true,
            ..Default::default()
        },
    )
    .expect("index.html is well-formed");
    let computed = cell(&doc, "mse-telemetry");
    assert!(
        (computed - mse).abs() <= 1e-12 * mse.max(1e-12),
        "{computed} vs {mse}"
    );
    let spec_mse = cell(&doc, "mse-spec");
    assert!((spec_mse - mse).abs() <= 1e-12 * mse.max(1e-12));
    assert_eq!(cell(&doc, "p1-violated"), p1v as f64);
    assert_eq!(cell(&doc, "p1-unknown"), p1u as f64);
    assert_eq!(cell(&doc, "p2-violated"), p2v as f64);
    assert_eq!(cell(&doc, "augmented"), aug as f64);
    assert_eq!(cell(&doc, "p3-spikes"), spikes);
    assert_eq!(cell(&doc, "p3-dropouts"), dropouts);
    assert!(
        p2v > 0 && p1v > 0 && spikes > 0.0,
        "the data exercises every count"
    );

    let images: Vec<&str> = doc
        .descendants()
        .filter(|n| n.tag_name().name() == "img")
        .filter_map(|n| n.attribute("src"))
        .collect();
    assert_eq!(
        images,
        vec![
            "speeds.svg",
            "p1.svg",
            "p3.svg",
            "mse.svg",
            "outputs.svg",
            "verdicts.svg"
        ]
    );
    let speeds = check_svg(&out_dir.join("speeds.svg"), 3);
    assert!(speeds.contains("expected speed") && speeds.contains("augmented action"));
    assert!(
        speeds.contains("time [s]"),
        "axis labels are written as text"
    );
    let p1 = check_svg(&out_dir.join("p1.svg"), 1);
    assert!(p1.contains("status violated") && p1.contains("status unknown"));
    // P1 status markers: one circle per step in the legend's colours.
    let p1_doc = roxmltree::Document::parse(&p1).unwrap();
    let circles = p1_doc
        .descendants()
        .filter(|n| n.tag_name().name() == "circle")
        .count();
    assert!(circles >= p1v + p1u, "{circles} status markers");
    check_svg(&out_dir.join("p3.svg"), 2);
    check_svg(&out_dir.join("mse.svg"), 2);
}

#[test]
fn report_of_empty_input_still_renders() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("empty.lp");
    std::fs::write(&input, "# nothing\n").unwrap();
    let out_dir = dir.path().join("r");
    let out = Command::new(BIN)
        .args([
            "report",
            input.to_str().unwrap(),
            "-o",
            out_dir.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(out_dir.join("index.html")).unwrap();
    assert!(html.contains("no outputs of a spec"), "{html}");
    assert!(
        !html.contains("Mean squared error"),
        "no robot section: {html}"
    );
    // Nothing to plot: no chart is drawn, and the page shows none.
    for svg in ["speeds.svg", "p1.svg", "p3.svg", "mse.svg", "outputs.svg"] {
        assert!(!out_dir.join(svg).exists(), "{svg} drawn without data");
    }
    assert!(!html.contains("<img"), "{html}");
}

#[test]
fn report_of_missing_file_fails_with_its_name() {
    let out = Command::new(BIN)
        .args(["report", "/nonexistent/out.lp", "-o", "/tmp/unused-report"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/out.lp"));
}

/// MSE of the recorded run's telemetry, computed here from the fixture itself: records that
/// carry both speeds (a string actualSpeed counts when it holds a number).
fn fixture_mse(input: &str) -> (f64, usize) {
    let (mut sum, mut n) = (0.0, 0usize);
    for line in influxdb_line_protocol::parse_lines(input).flatten() {
        let number = |name: &str| {
            line.field_value(name).and_then(|v| match v {
                influxdb_line_protocol::FieldValue::F64(f) => Some(*f),
                influxdb_line_protocol::FieldValue::I64(i) => Some(*i as f64),
                influxdb_line_protocol::FieldValue::String(s) => s.trim().parse().ok(),
                _ => None,
            })
        };
        if let (Some(e), Some(a)) = (number("expectedSpeed"), number("actualSpeed")) {
            sum += (e - a) * (e - a);
            n += 1;
        }
    }
    (sum / n as f64, n)
}

#[test]
fn report_of_the_recorded_run() {
    let (input, output) = recorded::recorded_output();
    let dir = tempfile::tempdir().unwrap();
    let out_lp = dir.path().join("out.lp");
    std::fs::write(&out_lp, &output).unwrap();
    let out_dir = dir.path().join("report");
    let out = Command::new(BIN)
        .args([
            "report",
            out_lp.to_str().unwrap(),
            "-o",
            out_dir.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(out_dir.join("index.html")).unwrap();
    let doc = roxmltree::Document::parse_with_options(
        &html,
        roxmltree::ParsingOptions {
            allow_dtd: true,
            ..Default::default()
        },
    )
    .expect("index.html is well-formed");
    let (mse, pairs) = fixture_mse(&input);
    assert!(pairs > 0, "the fixture carries both speeds");
    let shown = cell(&doc, "mse-telemetry");
    assert!(
        (shown - mse).abs() <= 1e-9 * mse.max(1e-12),
        "report {shown} vs fixture {mse}"
    );
    // Violation counts: count the action metrics of our output here.
    let actions: Vec<_> = influxdb_line_protocol::parse_lines(&output)
        .flatten()
        .filter(|l| l.series.measurement.as_str() == "action")
        .collect();
    let count = |f: &dyn Fn(&influxdb_line_protocol::ParsedLine<'_>) -> bool| {
        actions.iter().filter(|l| f(l)).count() as f64
    };
    let is_true = |l: &influxdb_line_protocol::ParsedLine<'_>, name: &str| {
        matches!(
            l.field_value(name),
            Some(influxdb_line_protocol::FieldValue::Boolean(true))
        )
    };
    let status_is = |l: &influxdb_line_protocol::ParsedLine<'_>, s: &str| matches!(l.field_value("p1_status"), Some(influxdb_line_protocol::FieldValue::String(v)) if v.as_str() == s);
    assert_eq!(cell(&doc, "augmented"), count(&|l| is_true(l, "augmented")));
    let p1v = cell(&doc, "p1-violated");
    assert_eq!(p1v, count(&|l| status_is(l, "violated")));
    assert!(p1v > 0.0, "the obstacle run violates P1");
    assert!(
        cell(&doc, "p1-unknown") > 0.0,
        "the blinded sector makes P1 unknown"
    );
    assert!(
        cell(&doc, "p3-spikes") > 0.0,
        "the injected dust spikes are counted"
    );
    for svg in ["speeds.svg", "p1.svg", "p3.svg", "mse.svg"] {
        check_svg(&out_dir.join(svg), 2);
    }
}
