//! The fleet level (`--fleet-spec`, docs/fleet.md) with the real binary as a child process: the
//! example's fleet outputs over a three-robot fixture, line for line, the same on one thread and
//! on two; a robot silent past `--fleet-silence` leaves the maps at its last time plus the
//! bound; a fleet spec that does not check, an input that is no robot output and an input of the
//! wrong type are refused at start-up (exit 2) with file, line and column; with `--version-tag`
//! fleet lines carry the fleet spec's own version.

use crate::support::child::{root, run_text, write};

fn fleet_lines(out: &str) -> Vec<&str> {
    out.lines()
        .filter(|l| l.starts_with("tessla_fleet") || l.starts_with("action,"))
        .collect()
}

fn run_example(threads: &str) -> String {
    crate::support::fleet_example::output(&["--threads", threads])
}

/// The example's fleet outputs are exactly the expected file's lines (P2 count, closest pair,
/// zone A occupancy, one slow-down action per robot in zone A while two are in it), whether the
/// robots' instances run on one thread or two.
#[test]
fn example_fleet_outputs_line_for_line_on_one_and_two_threads() {
    let want =
        std::fs::read_to_string(root().join("tests/fixtures/fleet/three_robots.expected")).unwrap();
    let want: Vec<&str> = want.lines().collect();
    assert!(want.len() > 40, "the expected file is too short");
    let one = run_example("1");
    assert_eq!(fleet_lines(&one), want);
    let two = run_example("2");
    assert_eq!(fleet_lines(&two), want);
    // The robots' own outputs are still written, and the records passed through.
    assert!(
        one.lines()
            .any(|l| l.starts_with("tessla,") && l.contains("p2_violated="))
    );
    assert!(one.lines().any(|l| l.starts_with("mqtt_consumer,")));
    // The slow-down reaches both robots in zone A, never the one outside it.
    assert!(
        want.iter()
            .any(|l| l.starts_with("action,source=fleet,topic=tessla/tb3-1 "))
    );
    assert!(
        want.iter()
            .any(|l| l.starts_with("action,source=fleet,topic=tessla/tb3-2 "))
    );
    assert!(!want.iter().any(|l| l.contains("tb3-3")));
}

/// Robot c falls silent after its third record; a and b go on. The fleet keeps c in its maps
/// until c's last time plus `--fleet-silence` (1 s here), then counts two robots.
#[test]
fn a_silent_robot_leaves_the_fleet_after_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    let robot = write(
        dir.path(),
        "robot.tessla",
        "@TelegrafIn(\"m\", \"\", \"v\")\nin v: Events[Int]\nout v as value\n",
    );
    let fleet = write(
        dir.path(),
        "fleet.tessla",
        "in value: Events[Map[String, Int]]\nout Map.size(value) as robots\n",
    );
    let mut input = String::new();
    for k in 0..20i64 {
        let ts = 1_000_000_000 + k * 200_000_000;
        for (r, off) in [("a", 0), ("b", 1), ("c", 2)] {
            if r == "c" && k > 2 {
                continue;
            }
            input.push_str(&format!("m,robot={r} v={k}i {}\n", ts + off));
        }
    }
    let (out, err, code) = run_text(
        &[
            "--spec",
            robot.to_str().unwrap(),
            "--instance-by",
            "robot",
            "--fleet-spec",
            fleet.to_str().unwrap(),
            "--fleet-silence",
            "1s",
            "--max-ahead",
            "off",
            "--allowed-lateness",
            "off",
            "--no-passthrough",
        ],
        &input,
    );
    assert_eq!(code, 0, "{err}");
    let lines = fleet_lines(&out);
    // c's last record is at 1.4 s + 2 ns: it leaves at 2.4 s + 2 ns, with the map at 2 robots.
    assert!(
        lines.contains(&"tessla_fleet robots=3i 1000000002"),
        "{lines:#?}"
    );
    assert!(
        lines.contains(&"tessla_fleet robots=2i 2400000002"),
        "{lines:#?}"
    );
    let after: Vec<&&str> = lines
        .iter()
        .filter(|l| l.ends_with(|c: char| c.is_ascii_digit()))
        .filter(|l| {
            let ts: i64 = l.rsplit(' ').next().unwrap().parse().unwrap();
            ts > 2_400_000_002
        })
        .collect();
    assert!(after.iter().all(|l| l.contains("robots=2i")), "{after:#?}");
}

/// The tag value of `tag` in a line-protocol line, if it has one.
fn tag_of<'a>(line: &'a str, tag: &str) -> Option<&'a str> {
    let head = line.split(' ').next()?;
    head.split(',')
        .skip(1)
        .find_map(|kv| kv.strip_prefix(tag)?.strip_prefix('='))
}

/// With `--version-tag`, fleet lines carry the fleet spec's version: the id its file would have
/// as a robot spec (the same file run with `--spec` tags its lines with it), not the robot
/// spec's; a changed fleet spec is another version.
#[test]
fn fleet_lines_carry_the_fleet_specs_version() {
    let dir = tempfile::tempdir().unwrap();
    let robot = write(
        dir.path(),
        "robot.tessla",
        "@TelegrafIn(\"m\", \"\", \"v\")\nin v: Events[Int]\nout v as value\n",
    );
    let text = "in value: Events[Map[String, Int]]\nout default(Map.size(value), 0) as robots\n";
    let fleet = write(dir.path(), "fleet.tessla", text);
    let changed = write(dir.path(), "changed.tessla", &format!("{text}-- changed\n"));
    let input = "m,robot=a v=1i 100\nm,robot=b v=2i 200\nm,robot=a v=3i 3000000000\n";
    let run = |fleet: &std::path::Path| {
        let (out, err, code) = run_text(
            &[
                "--spec",
                robot.to_str().unwrap(),
                "--instance-by",
                "robot",
                "--fleet-spec",
                fleet.to_str().unwrap(),
                "--version-tag",
                "spec_version",
                "--max-ahead",
                "off",
                "--allowed-lateness",
                "off",
                "--no-passthrough",
            ],
            input,
        );
        assert_eq!(code, 0, "{err}");
        out
    };
    let versions = |out: &str, prefix: &str| {
        let mut v: Vec<String> = out
            .lines()
            .filter(|l| l.starts_with(prefix))
            .map(|l| tag_of(l, "spec_version").unwrap_or("").to_string())
            .collect();
        v.dedup();
        v
    };
    let out = run(&fleet);
    let fleet_v = versions(&out, "tessla_fleet");
    let robot_v = versions(&out, "tessla,");
    assert_eq!(fleet_v.len(), 1, "{out}");
    assert_eq!(robot_v.len(), 1, "{out}");
    assert_eq!(fleet_v[0].len(), 12, "{out}");
    assert_ne!(fleet_v, robot_v, "{out}");
    assert!(
        out.contains(&format!(
            "tessla_fleet,spec_version={} robots=2i 200",
            fleet_v[0]
        )),
        "{out}"
    );
    // The fleet spec run as a robot spec: its lines carry the same version.
    let (alone, err, code) = run_text(
        &[
            "--spec",
            fleet.to_str().unwrap(),
            "--version-tag",
            "spec_version",
            "--no-passthrough",
        ],
        "m v=1i 100\n",
    );
    assert_eq!(code, 0, "{err}");
    assert_eq!(versions(&alone, "tessla,"), fleet_v, "{alone}");
    // Another text is another version; without --version-tag no version tag.
    let other = run(&changed);
    let other_v = versions(&other, "tessla_fleet");
    assert_eq!(other_v.len(), 1, "{other}");
    assert_ne!(other_v, fleet_v, "{other}");
    let (plain, err, code) = run_text(
        &[
            "--spec",
            robot.to_str().unwrap(),
            "--instance-by",
            "robot",
            "--fleet-spec",
            fleet.to_str().unwrap(),
            "--no-passthrough",
        ],
        input,
    );
    assert_eq!(code, 0, "{err}");
    assert!(plain.contains("tessla_fleet robots=2i 200\n"), "{plain}");
}

fn refused(fleet_text: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let fleet = write(dir.path(), "fleet.tessla", fleet_text);
    let robot = root().join("specs/fleet/robot.tessla");
    let (_, err, code) = run_text(
        &[
            "--spec",
            robot.to_str().unwrap(),
            "--instance-by",
            "topic",
            "--fleet-spec",
            fleet.to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 2, "{err}");
    err
}

#[test]
fn a_fleet_spec_that_does_not_check_is_refused_with_its_place() {
    let err = refused("in p2_violated: Events[Map[String, Bool]]\nout p2_violated +\n");
    assert!(err.contains("fleet.tessla:3:1"), "{err}");
}

#[test]
fn a_fleet_input_that_is_no_robot_output_is_named() {
    let err = refused("in speed: Events[Map[String, Float]]\nout speed\n");
    assert!(
        err.contains("fleet spec input `speed` is not an output of the robot spec (its outputs: p2_violated, position)"),
        "{err}"
    );
    assert!(err.contains("fleet.tessla:1:4"), "{err}");
}

#[test]
fn a_fleet_input_of_the_wrong_type_is_named() {
    let err = refused("in p2_violated: Events[Map[String, Int]]\nout p2_violated\n");
    assert!(
        err.contains("robot output `p2_violated` is Events[Bool], so the fleet reads it as Events[Map[String, Bool]]"),
        "{err}"
    );
    assert!(err.contains("fleet.tessla:1:17"), "{err}");
    let err = refused("in position: Events[Bool]\nout position\n");
    assert!(err.contains("has type Events[Bool]"), "{err}");
}
