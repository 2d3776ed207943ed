//! `report` for a user's own spec run as a fleet (issue 47), through the real binary: a battery
//! monitor with an alert, an alert count, a silence watchdog and an action, two robots tagged by
//! `--instance-by robot` and `--version-tag spec_version`, a status line and a record refused as
//! ahead of the clock in the file. The page lists every output with how it is drawn, single
//! events as marks, counts as steps, no robot-only section or warning; the summary totals the
//! steps over the robots and splits them per robot and version; a closed pipe ends it quietly.

use crate::support::child;

use crate::support::BIN;
use child::{root, run_in, text, write};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

pub(super) const SPEC: &str = r#"include "telegraf.tessla"
@TelegrafIn("mqtt_consumer", "", "battery")
in battery: Events[Float]
def low = battery <. 20.0
def was_low = default(prev(low), false)
def battery_alert = filter(low && !was_low, low && !was_low)
def alerts = count(battery_alert)
def command = const("return_to_dock", battery_alert)
def silent = delay(const(2000000000, battery), battery)
@TelegrafField("battery_check", "low") out low
@TelegrafField("battery_check", "battery_alert") out battery_alert
@TelegrafField("battery_check", "alerts") out alerts
@TelegrafField("battery_check", "silent") out silent
@TelegrafField("action", "command") out command
"#;

pub(super) const S: i64 = 1_000_000_000;
pub(super) const T0: i64 = 1_700_000_000 * S;

/// Two robots for 10 s, robot b silent from 3 s to 8 s; run as a fleet of version `version`.
pub(super) fn fleet_run(dir: &std::path::Path, version: &str) -> String {
    // The version tag is the spec's hash: a comment makes another version.
    let spec = write(
        dir,
        &format!("dock-{version}.tessla"),
        &format!("{SPEC}-- {version}\n"),
    );
    let mut input = String::new();
    for i in 0..10i64 {
        for (robot, off) in [("a", 0), ("b", 1)] {
            if robot == "b" && (4..8).contains(&i) {
                continue;
            }
            let battery = 30 - 3 * i - off;
            let t = T0 + i * S + off * 1000;
            input.push_str(&format!(
                "mqtt_consumer,robot={robot} battery={battery}.0 {t}\n"
            ));
        }
    }
    let out = run_in(
        &root(),
        &[
            "run",
            "--spec",
            spec.to_str().unwrap(),
            "--instance-by",
            "robot",
            "--version-tag",
            "spec_version",
            "--max-ahead",
            "off",
        ],
        input.as_bytes(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    text(&out.stdout)
}

#[test]
fn report_of_a_users_spec_fleet_shows_every_output_by_its_shape() {
    let dir = tempfile::tempdir().unwrap();
    let run = fleet_run(dir.path(), "v1");
    // A status line (wall clock) first, a record refused as ahead of the clock (passed through,
    // years in the future) in the middle: neither moves the run's clock nor counts as a step.
    let status = "tessla_spec,host=h,outcome=accepted,version=v1 revision=1i,from=0i,pid=1i \
                  1790000000000000000\n";
    let (head, _) = run.split_at(run.len() / 2);
    let head = &head[..=head.rfind('\n').unwrap()];
    let lp = format!(
        "{status}{head}mqtt_consumer,robot=a battery=1.0 1795890350000000000\n{}",
        &run[head.len()..]
    );
    write(dir.path(), "fleet.lp", &lp);
    let out = run_in(
        dir.path(),
        &["report", "fleet.lp", "-o", "r", "--summary"],
        b"",
    );
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(!err.contains("W!"), "no robot warning: {err}");
    let summary = text(&out.stdout);
    assert!(
        summary.contains("summary of fleet.lp: 16 steps over 9 s"),
        "steps totalled over both robots (10 + 6), the clock of the robots' time: {summary}"
    );
    assert!(
        summary.contains("1 status lines (tessla_spec), 1 records stamped ahead"),
        "{summary}"
    );
    assert!(summary.contains("steps per robot: a 10, b 6"), "{summary}");
    let html = std::fs::read_to_string(dir.path().join("r/index.html")).unwrap();
    let options = roxmltree::ParsingOptions {
        allow_dtd: true,
        ..Default::default()
    };
    roxmltree::Document::parse_with_options(&html, options).expect("well-formed page");
    assert!(!html.contains("Mean squared error"), "{html}");
    assert!(!html.contains("id=\"violations\""), "{html}");
    let row = |output: &str| {
        html.lines()
            .find(|l| l.starts_with(&format!("<tr id=\"output-{output}[robot=")))
            .unwrap_or_else(|| panic!("{output}: {html}"))
            .to_string()
    };
    assert!(row("alerts").contains("steps"), "a count as steps");
    for event in ["battery_alert", "command", "silent"] {
        assert!(
            row(event).contains("marks"),
            "{event}: single events as marks"
        );
    }
    assert!(
        row("low").contains("timeline"),
        "a Bool verdict as a timeline"
    );
    let verdicts = std::fs::read_to_string(dir.path().join("r/verdicts.svg")).unwrap();
    assert!(
        verdicts.contains(">\nreturn_to_dock (event)\n<"),
        "the action's command is marked: {verdicts}"
    );
    assert!(verdicts.matches("<polygon").count() >= 5, "{verdicts}");
    let outputs = std::fs::read_to_string(dir.path().join("r/outputs.svg")).unwrap();
    assert!(outputs.contains("alerts[robot=a"), "{outputs}");

    // A second version for robot b: the summary splits the steps per version too.
    let v2 = fleet_run(dir.path(), "v2");
    let b_v2: String = v2
        .lines()
        .filter(|l| l.contains("robot=b"))
        .map(|l| format!("{l}\n"))
        .collect();
    let a_v1: String = run
        .lines()
        .filter(|l| l.contains("robot=a"))
        .map(|l| format!("{l}\n"))
        .collect();
    write(dir.path(), "two.lp", &format!("{a_v1}{b_v2}"));
    let out = run_in(dir.path(), &["report", "--summary", "two.lp"], b"");
    let summary = text(&out.stdout);
    assert!(summary.contains("steps per spec_version: "), "{summary}");
}

#[test]
fn a_closed_pipe_ends_report_quietly() {
    // Thousands of verdict changes: more than a pipe holds, so the reader's close is met.
    let mut lp = String::new();
    for i in 0..6000i64 {
        lp.push_str(&format!("check ok={} {}\n", i % 2 == 0, T0 + i * S));
    }
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "long.lp", &lp);
    let mut child = Command::new(BIN)
        .args(["report", "--timeline", "--summary", path.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(first.contains("when each verdict changed"), "{first}");
    // The reader is gone (the pipe closed when it was dropped above).
    let out = child.wait_with_output().unwrap();
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(
        !err.contains("panicked") && !err.contains("Broken pipe"),
        "{err}"
    );
}

/// The README's first action (`examples/first-spec/dock.tessla`): `report` shows the command as
/// a mark and the count as steps, as the README says.
#[test]
fn the_first_action_is_reported_as_the_readme_says() {
    let dir = tempfile::tempdir().unwrap();
    let out = run_in(
        &root(),
        &[
            "run",
            "--no-passthrough",
            "--spec",
            "examples/first-spec/dock.tessla",
        ],
        &std::fs::read(root().join("examples/first-spec/battery.lp")).unwrap(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    write(dir.path(), "dock.lp", &text(&out.stdout));
    let out = run_in(dir.path(), &["report", "dock.lp", "-o", "r"], b"");
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let html = std::fs::read_to_string(dir.path().join("r/index.html")).unwrap();
    let row = |id: &str| {
        html.lines()
            .find(|l| l.contains(&format!("<tr id=\"output-{id}\">")))
            .unwrap_or_else(|| panic!("{id}: {html}"))
            .to_string()
    };
    assert!(row("command").contains("marks"), "{html}");
    assert!(row("alerts").contains("steps"), "{html}");
}
