//! A wiring that feeds an input nothing says so, once: after the first 1,000 records, after
//! 10 seconds, or at the end of the input, whichever comes first, a warning names the input and
//! its @TelegrafIn, lists what was seen and the nearest match; a field that is present but never
//! converts is reported the same way with the fix. Through the real binary.

use crate::support::live_child;

use live_child::{LiveChild, run_all};

fn spec(name: &str) -> String {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("specs")
        .join(name)
        .display()
        .to_string()
}

fn warnings(err: &str) -> Vec<&str> {
    err.lines().filter(|l| l.starts_with("W! input")).collect()
}

#[test]
fn a_misnamed_field_is_named_with_what_was_seen_and_the_nearest_match() {
    let p2 = spec("p2_tolerance.tessla");
    let input = "mqtt_consumer,host=tb3,topic=tessla expectedSpeed=0.1,actual_speed=0.05 1\n";
    let (_, err, code) = run_all(&["--spec", &p2, "--no-passthrough"], input);
    assert_eq!(code, 0, "{err}");
    let w = warnings(&err);
    assert_eq!(w.len(), 1, "{err}");
    let w = w[0];
    for part in [
        "input `actualSpeed`",
        "@TelegrafIn(\"mqtt_consumer\", \"\", \"actualSpeed\")",
        "matched nothing",
        "mqtt_consumer,host=tb3,topic=tessla fields actual_speed, expectedSpeed",
        "did you mean `actual_speed`?",
        "json_string_fields",
    ] {
        assert!(w.contains(part), "`{part}` missing in {w}");
    }
}

#[test]
fn a_json_string_dropped_by_telegraf_points_at_json_string_fields() {
    // The robot sends actualSpeed as a string; without json_string_fields Telegraf's JSON parser
    // drops it, so the metric has expectedSpeed only.
    let input = "mqtt_consumer,host=tb3,topic=tessla expectedSpeed=0.1 1\n";
    let (_, err, _) = run_all(&["--no-passthrough"], input);
    let w: Vec<&str> = warnings(&err)
        .into_iter()
        .filter(|l| l.contains("`actualSpeed`"))
        .collect();
    assert_eq!(w.len(), 1, "{err}");
    assert!(w[0].contains("json_string_fields"), "{}", w[0]);
}

#[test]
fn a_wrong_measurement_and_a_wrong_tag_are_named() {
    let input = "mqtt,host=tb3 expectedSpeed=0.1,actualSpeed=0.1 1\n";
    let (_, err, _) = run_all(&["--spec", &spec("p2_tolerance.tessla")], input);
    let w = warnings(&err);
    assert_eq!(w.len(), 2, "{err}");
    assert!(
        w.iter()
            .all(|l| l.contains("no metric named `mqtt_consumer`")
                && l.contains("did you mean `mqtt`?")),
        "{err}"
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tagged.tessla");
    std::fs::write(
        &path,
        "def @TelegrafIn(measurement: String, tags: String, field: String)\n\
         @TelegrafIn(\"m\", \"topic=robot1\", \"x\")\nin x: Events[Float]\nout x\n",
    )
    .unwrap();
    let input = "m,topic=robot2 x=1 1\nm,topic=robot3 x=2 2\n";
    let (_, err, _) = run_all(&["--spec", path.to_str().unwrap()], input);
    let w = warnings(&err);
    assert_eq!(w.len(), 1, "{err}");
    assert!(
        w[0].contains("no metric carries the tags topic=robot1")
            && w[0].contains("m,topic=robot2 | m,topic=robot3 fields x"),
        "{}",
        w[0]
    );
}

#[test]
fn a_field_that_never_converts_is_reported_once_with_the_fix() {
    let mut input = String::new();
    for i in 0..50 {
        input.push_str(&format!(
            "mqtt_consumer expectedSpeed=0.1,actualSpeed=\"fast\" {}\n",
            i + 1
        ));
    }
    let (_, err, _) = run_all(&["--spec", &spec("p2_tolerance.tessla")], &input);
    let w = warnings(&err);
    assert_eq!(w.len(), 1, "{err}");
    for part in [
        "input `actualSpeed`",
        "came 50 times",
        "never converted to Float",
        "\"fast\"",
        "fix: send a number",
    ] {
        assert!(w[0].contains(part), "`{part}` missing in {}", w[0]);
    }
}

#[test]
fn the_warning_comes_after_1000_records_while_the_input_goes_on() {
    let mut c = LiveChild::spawn(&["--spec", &spec("p2_tolerance.tessla"), "--no-passthrough"]);
    let mut batch = String::new();
    for i in 0..999 {
        batch.push_str(&format!(
            "mqtt_consumer expectedSpeed=0.1,speed=0.1 {}\n",
            i + 1
        ));
    }
    c.write(&batch);
    c.write("mqtt_consumer expectedSpeed=0.1,speed=0.1 1000\n");
    let w = c.wait_err("the unmatched-input warning", 0, |l| {
        l.starts_with("W! input `actualSpeed`")
    });
    assert!(w.contains("in the first 1000 records"), "{w}");
    // Once: more records, no second warning.
    c.write("mqtt_consumer expectedSpeed=0.1,speed=0.1 1001\n");
    let (_, err, code) = c.finish();
    assert_eq!(code, 0);
    assert_eq!(warnings(&err).len(), 1, "{err}");
}

#[test]
fn the_warning_comes_after_10_seconds_of_a_slow_input() {
    let mut c = LiveChild::spawn(&["--spec", &spec("p2_tolerance.tessla"), "--no-passthrough"]);
    c.write("mqtt_consumer expectedSpeed=0.1,speed=0.1 1\n");
    std::thread::sleep(std::time::Duration::from_millis(10_200));
    c.write("mqtt_consumer expectedSpeed=0.1,speed=0.1 2\n");
    let w = c.wait_err("the unmatched-input warning", 0, |l| {
        l.starts_with("W! input `actualSpeed`")
    });
    assert!(w.contains("in 2 records"), "{w}");
    let (_, err, _) = c.finish();
    assert_eq!(warnings(&err).len(), 1, "{err}");
}

#[test]
fn a_well_wired_run_warns_about_nothing() {
    let input = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/robot/recorded_run.lp"),
    )
    .unwrap();
    let (_, err, code) = run_all(&["--no-passthrough"], &input);
    assert_eq!(code, 0);
    assert!(warnings(&err).is_empty(), "{err}");
}

/// With `--threads 2` the instances live in two threads, but a miswired input is still warned
/// about once: only the first thread's records are watched.
#[test]
fn a_misnamed_field_is_reported_once_over_threads() {
    let p2 = spec("p2_tolerance.tessla");
    let mut input = String::new();
    for i in 0..3000 {
        input.push_str(&format!(
            "mqtt_consumer,host=tb3,topic=robot{} expectedSpeed=0.1,actual_speed=0.05 {}\n",
            i % 8,
            i + 1
        ));
    }
    let args = [
        "--spec",
        &p2,
        "--no-passthrough",
        "--instance-by",
        "topic",
        "--threads",
        "2",
    ];
    let (_, err, code) = run_all(&args, &input);
    assert_eq!(code, 0, "{err}");
    let w = warnings(&err);
    assert_eq!(w.len(), 1, "{err}");
    assert!(w[0].contains("did you mean `actual_speed`?"), "{}", w[0]);
}
