//! The robot's action through the real binary: `augmented` whenever the action's speed differs
//! from the robot's command, `reason` (`p1`, `p2`, `p1,p2`), the `unknown_speed_cap` while P1 is
//! `unknown` (margin and safe speed absent then), the lidar's known beam count (missing beams
//! filled as dropouts, odd counts), speeds sent as strings, each property spec running alone,
//! the paper's P2 listing through `trace` on the P2 spec, a spec without outputs, `check`'s
//! parameter list, and each action's `seq` and `valid_until`.

use crate::support::live_child;

use lineproto::{FieldValue, Metric, parse_record};
use live_child::run_all;

fn spec(name: &str) -> String {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("specs")
        .join(name)
        .display()
        .to_string()
}

/// A scan of `n` beams at `far` metres with `ahead` metres in the beams within 20 degrees of
/// straight ahead.
fn scan(n: usize, far: f64, ahead: f64) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let a = i as f64 * 360.0 / n as f64;
            if !(20.0..=340.0).contains(&a) {
                ahead
            } else {
                far
            }
        })
        .collect()
}

/// One robot message as Telegraf's JSON parser delivers it (`actualSpeed` a string).
fn message(expected: f64, actual: f64, beams: &[f64], ts: i64) -> String {
    let mut s = format!(
        "mqtt_consumer,host=tb3,topic=tessla expectedSpeed={expected},actualSpeed=\"{actual}\",expectedAngular=0,actualAngular=0"
    );
    for (i, b) in beams.iter().enumerate() {
        s.push_str(&format!(",lidar_{i}={b}"));
    }
    s.push_str(&format!(" {ts}\n"));
    s
}

/// Run with `args` (no pass-through added here), return the metrics named `name`.
fn metrics(args: &[&str], input: &str, name: &str) -> (Vec<Metric>, String) {
    let (out, err, code) = run_all(args, input);
    assert_eq!(code, 0, "{err}");
    let ms = out
        .lines()
        .filter_map(|l| parse_record(l.as_bytes()).ok().flatten())
        .filter(|m| m.measurement == name)
        .collect();
    (ms, err)
}

fn action(args: &[&str], input: &str) -> Metric {
    let mut all = vec!["--no-passthrough"];
    all.extend_from_slice(args);
    let (mut ms, err) = metrics(&all, input, "action");
    assert_eq!(ms.len(), 1, "one action expected; stderr:\n{err}");
    ms.remove(0)
}

fn float(m: &Metric, f: &str) -> f64 {
    match m.field(f) {
        Some(FieldValue::Float(x)) => *x,
        other => panic!("field {f}: {other:?} in {m:?}"),
    }
}

fn boolean(m: &Metric, f: &str) -> bool {
    match m.field(f) {
        Some(FieldValue::Bool(x)) => *x,
        other => panic!("field {f}: {other:?} in {m:?}"),
    }
}

fn string(m: &Metric, f: &str) -> Option<String> {
    match m.field(f) {
        Some(FieldValue::Str(x)) => Some(x.clone()),
        None => None,
        other => panic!("field {f}: {other:?} in {m:?}"),
    }
}

const TS: i64 = 1_700_000_000_000_000_000;

#[test]
fn an_obstacle_inside_the_braking_distance_at_full_speed_lowers_and_augments() {
    // Full command speed (0.22 m/s, also the actual speed), obstacle 0.2 m ahead:
    // Bdist = 0.22*0.5 + 0.22^2/(2*0.5) + 0.09 = 0.2484 m > 0.2 m.
    let a = action(&[], &message(0.22, 0.22, &scan(360, 2.0, 0.2), TS));
    assert_eq!(string(&a, "p1_status").as_deref(), Some("violated"));
    let speed = float(&a, "speed");
    // v*0.5 + v^2 + 0.09 = 0.2  =>  v = 0.5*(sqrt(0.25 + 0.44) - 0.5)
    let fit = 0.5 * ((0.25f64 + 2.0 * 0.11 / 0.5).sqrt() - 0.5);
    assert!((speed - fit).abs() < 1e-9, "{speed} vs {fit}");
    assert!(speed < 0.22);
    assert!(
        boolean(&a, "augmented"),
        "a lowered speed is an augmented action"
    );
    assert_eq!(string(&a, "reason").as_deref(), Some("p1"));
    assert!(float(&a, "p1_margin") < 0.0);
}

#[test]
fn the_issues_example_obstacle_at_15_cm_and_command_0_2() {
    let a = action(&[], &message(0.2, 0.2, &scan(360, 2.0, 0.15), TS));
    assert!((float(&a, "speed") - 0.1).abs() < 1e-9, "{a:?}");
    assert!(boolean(&a, "augmented"));
    assert_eq!(string(&a, "reason").as_deref(), Some("p1"));
}

#[test]
fn a_clear_way_and_a_tracking_robot_leave_the_command_alone() {
    let a = action(&[], &message(0.1, 0.1, &scan(360, 2.0, 2.0), TS));
    assert_eq!(float(&a, "speed"), 0.1);
    assert!(!boolean(&a, "augmented"));
    assert_eq!(string(&a, "reason"), None, "no reason without augmentation");
    assert_eq!(string(&a, "p1_status").as_deref(), Some("ok"));
}

#[test]
fn a_blinded_sector_caps_the_speed_and_reports_no_margin() {
    // Every beam within 20 degrees of straight ahead is an LDS-01 no-return (0.0).
    let input = message(0.2, 0.2, &scan(360, 2.0, 0.0), TS);
    let (ms, err) = metrics(&["--no-passthrough"], &input, "action");
    let a = &ms[0];
    assert_eq!(string(a, "p1_status").as_deref(), Some("unknown"), "{err}");
    assert_eq!(float(a, "speed"), 0.05, "unknown_speed_cap");
    assert!(boolean(a, "augmented"));
    assert_eq!(string(a, "reason").as_deref(), Some("p1"));
    assert!(
        a.field("p1_margin").is_none(),
        "no margin while unknown: {a:?}"
    );
    let (verdicts, _) = metrics(&["--no-passthrough"], &input, "tessla");
    assert!(
        verdicts[0].field("p1_margin").is_none(),
        "{:?}",
        verdicts[0]
    );
    assert!(
        verdicts[0].field("p1_safe_speed").is_none(),
        "{:?}",
        verdicts[0]
    );
    // The cap can be lifted.
    let a = action(&["--set", "unknown_speed_cap=0.22"], &input);
    assert_eq!(float(&a, "speed"), 0.2);
    assert!(!boolean(&a, "augmented"));
    // A command below the cap is left alone.
    let a = action(&[], &message(0.03, 0.03, &scan(360, 2.0, 0.0), TS));
    assert_eq!(float(&a, "speed"), 0.03);
    assert!(!boolean(&a, "augmented"));
}

#[test]
fn a_stuck_robot_gets_p2s_correction_and_with_an_obstacle_both_reasons() {
    let a = action(&[], &message(0.1, 0.0, &scan(360, 2.0, 2.0), TS));
    assert!((float(&a, "speed") - 0.15).abs() < 1e-12);
    assert!(boolean(&a, "augmented"));
    assert_eq!(string(&a, "reason").as_deref(), Some("p2"));
    assert!(boolean(&a, "p2_violated"));
    // Stuck in front of an obstacle 0.15 m ahead: P2 asks for 0.165, P1 allows about 0.1.
    let a = action(&[], &message(0.11, 0.0, &scan(360, 2.0, 0.15), TS));
    assert!((float(&a, "speed") - 0.1).abs() < 1e-9, "{a:?}");
    assert_eq!(string(&a, "reason").as_deref(), Some("p1,p2"));
    assert!(boolean(&a, "augmented"));
}

#[test]
fn a_robot_sequence_reports_every_augmented_action() {
    // A run: clear, stuck, obstacle, blinded, clear again.
    let steps = [
        (0.1, 0.1, scan(360, 2.0, 2.0), false, None),
        (0.1, 0.0, scan(360, 2.0, 2.0), true, Some("p2")),
        (0.2, 0.2, scan(360, 2.0, 0.15), true, Some("p1")),
        (0.2, 0.2, scan(360, 2.0, 0.0), true, Some("p1")),
        (0.1, 0.1, scan(360, 2.0, 2.0), false, None),
    ];
    let input: String = steps
        .iter()
        .enumerate()
        .map(|(i, (e, a, s, _, _))| message(*e, *a, s, TS + i as i64 * 200_000_000))
        .collect();
    let (ms, err) = metrics(&["--no-passthrough"], &input, "action");
    assert_eq!(ms.len(), steps.len(), "{err}");
    for (i, (m, (e, _, _, aug, why))) in ms.iter().zip(&steps).enumerate() {
        assert_eq!(int(m, "seq"), i as i64 + 1, "{m:?}");
        assert_eq!(boolean(m, "augmented"), *aug, "{m:?}");
        assert_eq!(boolean(m, "augmented"), float(m, "speed") != *e, "{m:?}");
        assert_eq!(string(m, "reason").as_deref(), *why, "{m:?}");
    }
}

#[test]
fn missing_trailing_beams_are_dropouts_at_their_own_angles() {
    // Beams 350..359 (the sector just right of straight ahead) missing, as when the robot's
    // JSON array ended in nulls that Telegraf's JSON parser dropped.
    let full = scan(360, 2.0, 1.0);
    let mut nulls = full.clone();
    for b in nulls.iter_mut().skip(350) {
        *b = 0.0;
    }
    let short = &full[..350];
    let (a, err) = metrics(
        &["--no-passthrough"],
        &message(0.1, 0.1, short, TS),
        "tessla",
    );
    let (b, _) = metrics(
        &["--no-passthrough"],
        &message(0.1, 0.1, &nulls, TS),
        "tessla",
    );
    assert_eq!(a, b, "a missing beam is a dropout, like a no-return");
    assert_eq!(a[0].field("p3_dropouts"), Some(&FieldValue::Int(10)));
    // A shorter scan is not misplaced: without the known length its beams would spread over
    // 360 degrees and the count would differ.
    assert!(!err.contains("more than"), "{err}");
    // A gap in the middle is a dropout too.
    let mut line = message(0.1, 0.1, &full, TS);
    line = line.replace(",lidar_100=2,", ",");
    let (c, _) = metrics(&["--no-passthrough"], &line, "tessla");
    assert_eq!(c[0].field("p3_dropouts"), Some(&FieldValue::Int(1)));
}

#[test]
fn odd_beam_counts_with_the_count_set_place_beams_right() {
    // A 359-beam scan under the default count is one missing beam: still read right.
    let (ms, _) = metrics(
        &["--no-passthrough"],
        &message(0.2, 0.2, &scan(359, 2.0, 0.15), TS),
        "action",
    );
    assert_eq!(string(&ms[0], "p1_status").as_deref(), Some("violated"));
    assert_eq!(ms[0].field("p3_dropouts"), Some(&FieldValue::Int(1)));
    for n in [45usize, 229, 361, 719] {
        let beams = scan(n, 2.0, 0.15);
        let count = format!("lidar_beams={n}");
        let (ms, err) = metrics(
            &["--no-passthrough", "--set", &count],
            &message(0.2, 0.2, &beams, TS),
            "action",
        );
        assert!(!err.contains("W!"), "n={n}: {err}");
        let a = &ms[0];
        assert_eq!(string(a, "p1_status").as_deref(), Some("violated"), "n={n}");
        assert!((float(a, "speed") - 0.1).abs() < 1e-9, "n={n}: {a:?}");
        assert_eq!(a.field("p3_dropouts"), Some(&FieldValue::Int(0)), "n={n}");
    }
}

#[test]
fn a_scan_longer_than_the_beam_count_is_warned_about_and_kept() {
    let beams = scan(361, 2.0, 0.15);
    let (ms, err) = metrics(
        &["--no-passthrough"],
        &message(0.2, 0.2, &beams, TS),
        "action",
    );
    assert!(
        err.contains("361 elements") && err.contains("--set lidar_beams=361"),
        "{err}"
    );
    assert_eq!(string(&ms[0], "p1_status").as_deref(), Some("violated"));
    // A robot whose scans fall far short of the count (a 180-beam lidar) is told, and its scans
    // are read at their own length.
    let beams = scan(180, 2.0, 0.15);
    let (ms, err) = metrics(
        &["--no-passthrough"],
        &message(0.2, 0.2, &beams, TS),
        "action",
    );
    assert!(
        err.contains("180 elements") && err.contains("--set lidar_beams=180"),
        "{err}"
    );
    assert!(err.contains("at most 180 elements"), "{err}");
    assert_eq!(string(&ms[0], "p1_status").as_deref(), Some("violated"));
    assert_eq!(ms[0].field("p3_dropouts"), Some(&FieldValue::Int(0)));
}

fn int(m: &Metric, f: &str) -> i64 {
    match m.field(f) {
        Some(FieldValue::Int(x)) => *x,
        other => panic!("field {f}: {other:?} in {m:?}"),
    }
}

/// Every action carries what a robot needs to refuse a stale or repeated one (README, "What a
/// robot must do with an action"): `seq`, counting the actions of its robot's monitor instance
/// from 1, and `valid_until`, its timestamp plus `action_validity` (400 ms, `--set`-able).
#[test]
fn every_action_carries_its_robots_sequence_number_and_validity() {
    // Two robots, interleaved, each with its own monitor instance and its own count.
    let beams = scan(360, 2.0, 2.0);
    let mut input = String::new();
    for i in 0..3i64 {
        for robot in ["tessla/a", "tessla/b"] {
            let ts = TS + i * 200_000_000 + i64::from(robot == "tessla/b");
            input.push_str(
                &message(0.1, 0.1, &beams, ts).replace("topic=tessla", &format!("topic={robot}")),
            );
        }
    }
    let (ms, err) = metrics(
        &[
            "--no-passthrough",
            "--instance-by",
            "topic",
            "--threads",
            "1",
        ],
        &input,
        "action",
    );
    assert_eq!(ms.len(), 6, "{err}");
    for (k, m) in ms.iter().enumerate() {
        let i = (k / 2) as i64;
        let ts = m.timestamp.unwrap();
        assert_eq!(int(m, "seq"), i + 1, "{m:?}");
        assert_eq!(int(m, "valid_until"), ts + 400_000_000, "{m:?}");
        let robot = if k % 2 == 0 { "tessla/a" } else { "tessla/b" };
        assert_eq!(m.tag("topic"), Some(robot), "{m:?}");
    }
    // The validity is a parameter of the spec.
    let one = message(0.1, 0.1, &beams, TS);
    let a = action(&["--set", "action_validity=1000000000"], &one);
    assert_eq!(int(&a, "valid_until"), TS + 1_000_000_000);
    let (out, err, code) = run_all(&["check", &spec("robot.tessla")], "");
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("  action_validity = 400000000"), "{out}");
    // Every property spec's action carries both as well.
    for s in [
        "p1_braking.tessla",
        "p2_tolerance.tessla",
        "p3_lidar.tessla",
    ] {
        let a = action(&["--spec", &spec(s)], &one);
        assert_eq!(int(&a, "seq"), 1, "{s}: {a:?}");
        assert_eq!(int(&a, "valid_until"), TS + 400_000_000, "{s}: {a:?}");
    }
    // A monitor restarted without --state counts from 1 again (the robot tells it by the newer
    // timestamp); with --state it continues.
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state.json");
    let state = state.to_str().unwrap();
    let first: String = (0..2)
        .map(|i| message(0.1, 0.1, &beams, TS + i * 200_000_000))
        .collect();
    let later = message(0.1, 0.1, &beams, TS + 400_000_000);
    let (ms, err) = metrics(&["--no-passthrough", "--state", state], &first, "action");
    assert_eq!(ms.len(), 2, "{err}");
    let a = action(&["--state", state], &later);
    assert_eq!(int(&a, "seq"), 3, "continued from the saved state");
    let a = action(&[], &later);
    assert_eq!(int(&a, "seq"), 1, "a fresh monitor");
    assert_eq!(int(&a, "valid_until"), TS + 800_000_000);
}

#[test]
fn speeds_as_strings_give_the_same_action_as_numbers() {
    let beams = scan(360, 2.0, 0.5);
    let text = message(0.1, 0.05, &beams, TS);
    let strings = text.replace("expectedSpeed=0.1", "expectedSpeed=\"0.1\"");
    let numbers = text.replace("actualSpeed=\"0.05\"", "actualSpeed=0.05");
    let a = action(&[], &strings);
    assert_eq!(a, action(&[], &numbers));
    assert_eq!(string(&a, "reason").as_deref(), Some("p2"));
    assert!((float(&a, "speed") - 0.125).abs() < 1e-12);
}

#[test]
fn each_property_spec_runs_alone_over_the_robot_message() {
    let input = message(0.2, 0.2, &scan(360, 2.0, 0.15), TS);
    let p1 = spec("p1_braking.tessla");
    let a = action(&["--spec", &p1], &input);
    assert_eq!(string(&a, "p1_status").as_deref(), Some("violated"));
    assert_eq!(string(&a, "reason").as_deref(), Some("p1"));
    assert!(boolean(&a, "augmented"));
    // A stuck robot for P2.
    let input = message(0.2, 0.0, &scan(360, 2.0, 0.15), TS);
    let p2 = spec("p2_tolerance.tessla");
    let a = action(&["--spec", &p2], &input);
    assert_eq!(string(&a, "reason").as_deref(), Some("p2"));
    assert!(boolean(&a, "augmented"));
    assert!(
        (float(&a, "speed") - 0.22).abs() < 1e-12,
        "capped at max_speed"
    );
    let p3 = spec("p3_lidar.tessla");
    let a = action(&["--spec", &p3], &input);
    assert!(!boolean(&a, "augmented"));
    assert_eq!(float(&a, "speed"), 0.2);
    assert_eq!(a.field("p3_spikes"), Some(&FieldValue::Int(0)));
    // Each is a complete spec for `check` too, with only its own parameters.
    for (s, has, lacks) in [
        (&p1, "unknown_speed_cap", "delta"),
        (&p2, "delta", "gamma"),
        (&p3, "lidar_beams", "t_react"),
    ] {
        let (out, err, code) = run_all(&["check", s], "");
        assert_eq!(code, 0, "{err}");
        let params = out.split("parameters (`--set`):").nth(1).unwrap_or("");
        assert!(params.contains(&format!("  {has} = ")), "{s}: {out}");
        assert!(!params.contains(&format!("  {lacks} = ")), "{s}: {out}");
    }
}

#[test]
fn the_papers_p2_listing_runs_through_trace_on_the_p2_spec_alone() {
    // The paper's Listing "Input Trace to P2 monitor": its events and times as printed; the
    // paper writes the speeds as integers, which a TeSSLa trace reads as Int, and the P2 spec's
    // inputs are Float (m/s), so each value gets `.0`.
    let paper = "0: actualSpeed = 0\n0: expectedSpeed = 1\n2: actualSpeed = 5\n2: expectedSpeed = 1\n\
                 4: actualSpeed = 2\n4: expectedSpeed = 5\n6: actualSpeed = 3\n6: expectedSpeed = 3\n\
                 8: actualSpeed = 1\n8: expectedSpeed = 4\n";
    let listing: String = paper.lines().map(|l| format!("{l}.0\n")).collect();
    let listing = listing.as_str();
    let p2 = spec("p2_tolerance.tessla");
    // The paper's units are abstract: lift the Burger's 0.22 m/s limit to see the raw actions.
    let (out, err, code) = run_all(&["trace", &p2, "--set", "max_speed=100.0"], listing);
    assert_eq!(code, 0, "{err}");
    // diff = e - a; violated = |diff| > 0.02; action = e + 0.5 * diff when violated, else e.
    let expect = [
        "0: p2_diff = 1.0",
        "0: p2_violated = true",
        "0: p2_action = 1.5",
        "2: p2_diff = -4.0",
        "2: p2_violated = true",
        "2: p2_action = -1.0",
        "4: p2_diff = 3.0",
        "4: p2_action = 6.5",
        "6: p2_diff = 0.0",
        "6: p2_violated = false",
        "6: p2_action = 3.0",
        "6: p2_augmented = false",
        "8: p2_diff = 3.0",
        "8: p2_action = 5.5",
        "8: p2_augmented = true",
    ];
    for e in expect {
        assert!(out.lines().any(|l| l == e), "missing `{e}` in:\n{out}");
    }
    // The running MSE after five steps: (1 + 16 + 9 + 0 + 9) / 5 = 7.
    assert!(out.lines().any(|l| l == "8: speed_mse = 7.0"), "{out}");
    // With the shipped parameters every correction stops at the Burger's 0.22 m/s.
    let (out, err, code) = run_all(&["trace", &p2], listing);
    assert_eq!(code, 0, "{err}");
    assert!(out.lines().any(|l| l == "4: p2_action = 0.22"), "{out}");
    assert!(out.lines().any(|l| l == "2: p2_action = -0.22"), "{out}");
}

#[test]
fn a_spec_without_outputs_is_a_spec_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("silent.tessla");
    std::fs::write(&path, "in x: Events[Int]\ndef y = x + 1\n").unwrap();
    let p = path.to_str().unwrap();
    let (_, err, code) = run_all(&["check", p], "");
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("no outputs") && err.contains("silent.tessla"),
        "{err}"
    );
    let (_, err, code) = run_all(&["trace", p], "1: x = 1\n");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("no outputs"), "{err}");
    let (out, err, code) = run_all(&["run", "--spec", p], "m x=1 1\n");
    assert_eq!(code, 2, "{err}");
    assert!(out.is_empty(), "nothing is read or written: {out}");
    assert!(err.contains("no outputs"), "{err}");
}

#[test]
fn a_library_of_definitions_checks_with_library() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lib.tessla");
    std::fs::write(
        &path,
        "module Checks {\n  def above(x: Events[Int], limit: Int): Events[Bool] = x > limit\n}\n\
         def twice(x: Int): Int = 2 * x\n",
    )
    .unwrap();
    let p = path.to_str().unwrap();
    // Without the flag the hint names it.
    let (_, err, code) = run_all(&["check", p], "");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("check --library"), "{err}");
    let (out, err, code) = run_all(&["check", "--library", p], "");
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("library: 2 definitions in 1 modules checked"),
        "{out}"
    );
    // A library is still checked: a wrong definition is an error.
    std::fs::write(&path, "def twice(x: Int): Int = 2 * x + true\n").unwrap();
    let (_, err, code) = run_all(&["check", "--library", p], "");
    assert_eq!(code, 2, "{err}");
}

#[test]
fn check_lists_only_parameters_under_set() {
    let (out, err, code) = run_all(&["check", &spec("robot.tessla"), "--set", "delta=0.03"], "");
    assert_eq!(code, 0, "{err}");
    let params: Vec<&str> = out
        .split("parameters (`--set`):\n")
        .nth(1)
        .unwrap()
        .lines()
        .take_while(|l| l.starts_with("  "))
        .collect();
    let names: Vec<&str> = params
        .iter()
        .map(|l| l.trim().split(' ').next().unwrap())
        .collect();
    for p in [
        "delta",
        "gain",
        "max_speed",
        "gamma",
        "range_min",
        "range_max",
        "lidar_beams",
        "t_react",
        "decel",
        "margin",
        "half_track",
        "min_valid_fraction",
        "unknown_speed_cap",
        "max_silence",
        "action_validity",
    ] {
        assert!(names.contains(&p), "{p} missing: {names:?}");
    }
    assert_eq!(names.len(), 15, "only parameters: {names:?}");
    assert!(
        params
            .iter()
            .any(|l| l.contains("delta = 0.03 (--set; spec 0.02)") && l.contains("m/s")),
        "{params:?}"
    );
}

#[test]
fn the_summary_and_the_report_show_reasons_and_the_cap() {
    let fixture = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/robot/recorded_run.lp");
    let input = std::fs::read_to_string(fixture).unwrap();
    let (out, err, code) = run_all(&["--no-passthrough"], &input);
    assert_eq!(code, 0, "{err}");
    // What `make run` prints after the verdicts and actions.
    let (summary, err, code) = run_all(&["report", "--summary", "-"], &out);
    assert_eq!(code, 0, "{err}");
    for part in [
        "300 steps",
        "P1 braking distance: 36 violated, 6 unknown",
        "P2 speed tolerance: 60 violated of 300",
        "augmented; why: p1 ",
        "capped at unknown_speed_cap while P1 was unknown: 6",
        "final MSE expected/actual speed: 3.756353e-4",
    ] {
        assert!(summary.contains(part), "`{part}` missing in:\n{summary}");
    }
    let dir = tempfile::tempdir().unwrap();
    let lp = dir.path().join("run.lp");
    std::fs::write(&lp, &out).unwrap();
    let report = dir.path().join("report");
    let (_, err, code) = run_all(
        &[
            "report",
            lp.to_str().unwrap(),
            "-o",
            report.to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    assert!(html.contains("id=\"reason-p1\""), "{html}");
    assert!(html.contains("id=\"reason-p1-p2\""), "{html}");
    assert!(html.contains("id=\"capped\" data-value=\"6e0\""), "{html}");
    let speeds = std::fs::read_to_string(report.join("speeds.svg")).unwrap();
    for label in ["augmented: p1", "augmented: p2", "capped: P1 unknown"] {
        assert!(speeds.contains(label), "the speeds plot marks `{label}`");
    }
}

/// Issue 46: a robot whose link dropped sends its queued messages late, after a newer one (or a
/// silence) moved its monitor's clock. Each late message is a step of its own just after the
/// clock, but its action's `valid_until` counts from the message's own time, so a robot's gate
/// refuses it as stale; before the fix it counted from the shifted step, up to 1.25 s too late.
#[test]
fn a_late_messages_action_is_valid_until_its_own_time_plus_the_validity() {
    let beams = scan(360, 2.0, 2.0);
    let ms = 1_000_000i64;
    // Two messages, a silence past max_silence (robot_silent fires), one after the link came back,
    // then the queue the robot's client sent late, in order.
    let mut times = vec![TS, TS + 200 * ms, TS + 2_000 * ms];
    times.extend((2..=9).map(|i| TS + i * 200 * ms));
    let input: String = times
        .iter()
        .map(|&t| message(0.1, 0.1, &beams, t))
        .collect();
    for s in [
        "robot.tessla",
        "p1_braking.tessla",
        "p2_tolerance.tessla",
        "p3_lidar.tessla",
    ] {
        let (actions, err) = metrics(&["--spec", &spec(s), "--no-passthrough"], &input, "action");
        assert_eq!(actions.len(), times.len(), "{s}: {err}");
        assert!(err.contains("8 late records"), "{s}: {err}");
        for (k, (a, &own)) in actions.iter().zip(&times).enumerate() {
            let at = a.timestamp.unwrap();
            assert_eq!(int(a, "valid_until"), own + 400 * ms, "{s}: {a:?}");
            if k < 3 {
                assert_eq!(at, own, "{s}: {a:?}");
            } else {
                // Late: stepped after the clock; all but the newest (1.8 s, valid until 2.2 s)
                // already stale by the monitor's own clock.
                assert!(at > TS + 2_000 * ms, "{s}: {a:?}");
                let stale = own < TS + 1_600 * ms + 1;
                assert_eq!(int(a, "valid_until") < at, stale, "{s}: {a:?}");
            }
        }
    }
    // `trace` and a spec without @TelegrafTime events: the action's own time, as before.
    let (out, err, code) = run_all(&["check", &spec("robot.tessla")], "");
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("message_time"), "{out}");
}
