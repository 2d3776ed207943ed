//! The fleet example run once, as docs/fleet.md shows it: `run --spec specs/fleet/robot.tessla
//! --instance-by topic --fleet-spec specs/fleet/fleet.tessla` over
//! tests/fixtures/fleet/three_robots.lp, for the tests that read its output (the line-for-line
//! test, the dashboards' fleet panels, InfluxDB).

use super::child::{root, run_text};

/// The fixture the example runs on.
const FIXTURE: &str = "tests/fixtures/fleet/three_robots.lp";

/// The example's whole output (robot lines, passed records, fleet lines) with `extra` options
/// after the documented ones (`--threads 2`); asserts it exits 0.
pub fn output(extra: &[&str]) -> String {
    let input = std::fs::read_to_string(root().join(FIXTURE)).expect("the fleet fixture");
    output_over(&input, extra)
}

/// The example's command (the robot and fleet specs, as documented, then `extra`) over `input`
/// instead of the fixture (e.g. `simulate --shared-floor`'s records); asserts it exits 0.
pub fn output_over(input: &str, extra: &[&str]) -> String {
    let robot = root().join("specs/fleet/robot.tessla");
    let fleet = root().join("specs/fleet/fleet.tessla");
    let mut args = vec![
        "--spec",
        robot.to_str().unwrap(),
        "--instance-by",
        "topic",
        "--fleet-spec",
        fleet.to_str().unwrap(),
        "--max-ahead",
        "off",
        "--allowed-lateness",
        "off",
    ];
    args.extend_from_slice(extra);
    let (out, err, code) = run_text(&args, input);
    assert_eq!(code, 0, "the fleet example: {err}");
    out
}
