//! The first hour of a new user (issue 24), through the real binary: the error texts that used
//! to mislead, `--version`, completions and the man page, `report` on any spec (and on the
//! robot's silent periods), the terminal view `make run` prints, and `make test`'s skip notice.

use crate::support::child;

use crate::support::BIN;
use child::{root, run_in, text, write};
use std::path::Path;
use std::process::{Command, Output};

fn run(args: &[&str], stdin: &[u8]) -> Output {
    run_in(&root(), args, stdin)
}

#[test]
fn a_nan_field_is_named_with_its_line_and_the_run_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let spec = write(
        dir.path(),
        "b.tessla",
        "in battery: Events[Float]\nout battery <. 20.0 as low\n",
    );
    let input = "robot battery=50.0 1000\nrobot battery=NaN 2000\nrobot battery=10.0 3000\n";
    let out = run(
        &["--no-passthrough", "--spec", spec.to_str().unwrap()],
        input.as_bytes(),
    );
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(
        err.contains("line 2") && err.contains("column 15"),
        "names the line and column: {err}"
    );
    assert!(
        err.contains("field `battery`: the value NaN is not a number line protocol accepts"),
        "{err}"
    );
    assert!(!err.contains("No fields were provided"), "{err}");
    let stdout = text(&out.stdout);
    assert!(
        stdout.contains("low=true"),
        "the next record is still read: {stdout}"
    );
}

#[test]
fn set_on_a_spec_without_constants_says_there_are_none() {
    let dir = tempfile::tempdir().unwrap();
    let spec = write(dir.path(), "x.tessla", "in x: Events[Int]\nout x\n");
    let out = run(&["check", spec.to_str().unwrap(), "--set", "nosuch=1"], b"");
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("no top-level constant `nosuch`"), "{err}");
    assert!(err.contains("the spec has no top-level constants"), "{err}");
    assert!(!err.contains("known constants:"), "{err}");
    // With constants, they are listed as before.
    let spec = write(
        dir.path(),
        "y.tessla",
        "in x: Events[Int]\ndef k = 3\nout x + k as y\n",
    );
    let out = run(&["check", spec.to_str().unwrap(), "--set", "nosuch=1"], b"");
    assert!(text(&out.stderr).contains("known constants: k"));
}

#[test]
fn a_bad_udp_address_names_the_flag_and_the_address_before_anything_else() {
    let out = run(&["run", "--udp-listen", "not-an-address"], b"");
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "a bad command line: {err}");
    let first = err.lines().next().unwrap_or("");
    assert!(
        first.starts_with("E! --udp-listen not-an-address: not a UDP address"),
        "{err}"
    );
    assert!(
        !err.contains("summary"),
        "no summary of a run that never started: {err}"
    );
    let out = run(
        &["run", "--udp-listen", "127.0.0.1:1653", "--udp-send", "x:y"],
        b"",
    );
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("--udp-send x:y: not a UDP address"), "{err}");
    // An address of no interface here (TEST-NET-1): it resolves but cannot be bound.
    let out = run(&["run", "--udp-listen", "192.0.2.1:1653"], b"");
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "an I/O error: {err}");
    assert!(
        err.starts_with("E! --udp-listen 192.0.2.1:1653: cannot listen there:"),
        "{err}"
    );
    assert!(!err.contains("summary"), "{err}");
}

#[test]
fn version_names_the_commit_and_tessla() {
    let out = run(&["--version"], b"");
    let v = text(&out.stdout);
    assert_eq!(out.status.code(), Some(0));
    assert!(v.starts_with("tessla-telegraf 0."), "{v}");
    assert!(
        v.contains("(commit ") && v.contains("implements TeSSLa 1.2)"),
        "{v}"
    );
    let commit = v
        .split("(commit ")
        .nth(1)
        .and_then(|r| r.split(';').next())
        .unwrap_or("");
    assert!(!commit.is_empty(), "{v}");
}

#[test]
fn completions_and_the_man_page_come_from_the_command_line() {
    for (shell, marker) in [
        ("bash", "complete -F _tessla__telegraf"),
        ("zsh", "#compdef tessla-telegraf"),
        ("fish", "complete -c tessla-telegraf"),
    ] {
        let out = run(&["completions", shell], b"");
        let script = text(&out.stdout);
        assert_eq!(out.status.code(), Some(0), "{shell}");
        assert!(script.contains(marker), "{shell}: {script}");
        assert!(
            script.contains("udp-listen"),
            "{shell} completes run's options"
        );
    }
    let out = run(&["manpage"], b"");
    let page = text(&out.stdout);
    assert_eq!(out.status.code(), Some(0));
    assert!(
        page.starts_with(".ie \\n(.g") || page.contains(".TH tessla-telegraf"),
        "{page}"
    );
    assert!(page.contains(".TH tessla-telegraf 1"), "{page}");
    assert!(page.contains("report"), "the subcommands are listed");
}

/// The battery example's output (the book, "Your first spec").
fn battery_run() -> String {
    let out = run(
        &[
            "run",
            "--no-passthrough",
            "--spec",
            "examples/first-spec/battery.tessla",
        ],
        &std::fs::read(root().join("examples/first-spec/battery.lp")).unwrap(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    text(&out.stdout)
}

#[test]
fn report_works_for_any_spec_without_the_robot_sections() {
    let dir = tempfile::tempdir().unwrap();
    let lp = write(dir.path(), "battery.lp", &battery_run());
    // Without -o: the folder `report` in the current folder.
    let out = run_in(dir.path(), &["report", "battery.lp"], b"");
    let err = text(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(
        !err.contains("W!"),
        "another spec's run is not the robot's: no warning about its outputs: {err}"
    );
    let report = dir.path().join("report");
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    assert!(
        html.contains("id=\"verdict-low-false\" data-value=\"5e0\""),
        "{html}"
    );
    assert!(
        html.contains("id=\"verdict-low-true\" data-value=\"2e0\""),
        "{html}"
    );
    assert!(
        !html.contains("id=\"p1-violated\""),
        "no robot rows: {html}"
    );
    assert!(
        !html.contains("Mean squared error") && !html.contains("no data"),
        "no robot MSE section: {html}"
    );
    // Every output is listed with how it is drawn: the count-free `silent` as marks.
    for (id, kind) in [
        ("output-low", "timeline"),
        ("output-silent", "marks"),
        ("output-total_drop", "line"),
    ] {
        let row = html
            .lines()
            .find(|l| l.contains(&format!("id=\"{id}\"")))
            .unwrap_or_else(|| panic!("{id}: {html}"));
        assert!(row.contains(kind), "{row}");
    }
    assert!(html.contains("data-value=\"7\">7 steps"), "{html}");
    assert!(
        !report.join("speeds.svg").exists(),
        "no robot plot without its data"
    );
    let outputs = std::fs::read_to_string(report.join("outputs.svg")).unwrap();
    assert!(outputs.contains("total_drop"), "numeric outputs plotted");
    let verdicts = std::fs::read_to_string(report.join("verdicts.svg")).unwrap();
    // A timeline: a row per verdict, its values as bands, the single event as a mark.
    for label in [
        ">\nlow\n<",
        ">\nsilent\n<",
        ">\ntrue (event)\n<",
        ">\nfalse\n<",
    ] {
        assert!(verdicts.contains(label), "{label:?} in {verdicts}");
    }
    assert!(verdicts.contains("<polygon"), "the event is a marker");
    for svg in [&outputs, &verdicts] {
        assert!(
            !svg.contains(">-0<") && !svg.contains(">-0.0<"),
            "no -0 label"
        );
        roxmltree::Document::parse(svg).expect("well-formed SVG");
    }
    // The summary counts the verdicts of any spec.
    let out = run(&["report", "--summary", lp.to_str().unwrap()], b"");
    let summary = text(&out.stdout);
    assert!(
        summary.contains("low: false 5, true 2 (steps per value)"),
        "{summary}"
    );
    assert!(!summary.contains("P1 braking"), "{summary}");
    assert!(!summary.contains("-0"), "{summary}");
}

#[test]
fn report_leaves_out_the_telemetry_it_is_told_of() {
    // The battery run with pass-through: the input measurement `robot` is telemetry.
    let dir = tempfile::tempdir().unwrap();
    let spec = write(
        dir.path(),
        "b.tessla",
        "in battery: Events[Float]\nout battery <. 11.0 as low\n",
    );
    let input = "robot battery=12.0 1000000000\nrobot battery=10.0 2000000000\n";
    let out = run(&["run", "--spec", spec.to_str().unwrap()], input.as_bytes());
    let lp = write(dir.path(), "run.lp", &text(&out.stdout));
    let summary = |extra: &[&str]| {
        let mut args = vec!["report", "--summary", lp.to_str().unwrap()];
        args.extend_from_slice(extra);
        text(&run(&args, b"").stdout)
    };
    let with_robot = summary(&[]);
    assert!(with_robot.contains("low: false 1, true 1"), "{with_robot}");
    let timeline = text(
        &run(
            &[
                "report",
                "--timeline",
                lp.to_str().unwrap(),
                "--telemetry",
                "robot",
            ],
            b"",
        )
        .stdout,
    );
    assert!(timeline.contains("1.0 s low true"), "{timeline}");
    let report_dir = dir.path().join("r");
    let out = run(
        &[
            "report",
            lp.to_str().unwrap(),
            "-o",
            report_dir.to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(out.status.code(), Some(0));
    let outputs = std::fs::read_to_string(report_dir.join("outputs.svg")).unwrap();
    assert!(
        outputs.contains("battery"),
        "without --telemetry, `robot` counts as output"
    );
    let out = run(
        &[
            "report",
            lp.to_str().unwrap(),
            "-o",
            report_dir.to_str().unwrap(),
            "--telemetry",
            "robot",
        ],
        b"",
    );
    assert_eq!(out.status.code(), Some(0));
    assert!(
        !report_dir.join("outputs.svg").exists(),
        "--telemetry robot leaves `battery` out: no numeric output is left to plot"
    );
}

const T0: i64 = 1_700_000_000_000_000_000;
const S: i64 = 1_000_000_000;

/// A robot run with two silent periods (5 s from 10 s, 3 s from 30 s), shaped like our output.
fn silent_run() -> String {
    let mut out = String::new();
    for i in 0..50i64 {
        let t = T0 + i * S;
        let silent = (10..15).contains(&i) || (30..33).contains(&i);
        out.push_str(&format!(
            "mqtt_consumer expectedSpeed=0.1,actualSpeed=\"0.1\" {t}\n\
             tessla p2_violated=false,p1_status=\"ok\",p1_margin=1.5,p3_spikes=0i,p3_dropouts=0i,speed_mse=0,robot_silent={silent} {t}\n\
             action speed=0.1,augmented=false,p1_status=\"ok\" {t}\n"
        ));
    }
    out
}

#[test]
fn report_counts_the_silent_periods_and_shades_them() {
    let dir = tempfile::tempdir().unwrap();
    let lp = write(dir.path(), "run.lp", &silent_run());
    let out = run(&["report", "--summary", lp.to_str().unwrap()], b"");
    let summary = text(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(
        summary.contains("robot silent: 2 periods, 8 s in all, longest 5 s"),
        "{summary}"
    );
    let o = dir.path().join("r");
    let out = run(
        &["report", lp.to_str().unwrap(), "-o", o.to_str().unwrap()],
        b"",
    );
    assert!(text(&out.stderr).contains("robot silent 2 times, 8 s"));
    let html = std::fs::read_to_string(o.join("index.html")).unwrap();
    assert!(
        html.contains("id=\"silent-periods\" data-value=\"2e0\""),
        "{html}"
    );
    for plot in ["speeds.svg", "p1.svg", "p3.svg"] {
        let svg = std::fs::read_to_string(o.join(plot)).unwrap();
        assert!(
            svg.contains("robot silent"),
            "{plot} shows the silent periods"
        );
    }
    // The timeline shows when the robot went silent and came back.
    let out = run(&["report", "--timeline", lp.to_str().unwrap()], b"");
    let timeline = text(&out.stdout);
    assert!(timeline.contains("10.0 s robot_silent true"), "{timeline}");
    assert!(timeline.contains("15.0 s robot_silent false"), "{timeline}");
}

/// Points of every `<polyline>` in an SVG, and the legend box (the white rectangle with a
/// border that is not the whole image).
/// A box `(x0, y0, x1, y1)` and the points of each line, in SVG pixels.
type Box4 = (f64, f64, f64, f64);
type Lines = Vec<Vec<(f64, f64)>>;

fn legend_and_lines(svg: &str) -> (Box4, Lines) {
    let doc = roxmltree::Document::parse(svg).expect("well-formed SVG");
    let num = |n: roxmltree::Node<'_, '_>, a: &str| {
        n.attribute(a)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    let legend = doc
        .descendants()
        .filter(|n| n.has_tag_name("rect") && n.attribute("stroke") == Some("#000000"))
        .map(|n| {
            (
                num(n, "x"),
                num(n, "y"),
                num(n, "x") + num(n, "width"),
                num(n, "y") + num(n, "height"),
            )
        })
        .next_back()
        .expect("a legend box");
    let lines = doc
        .descendants()
        .filter(|n| n.has_tag_name("polyline"))
        .map(|n| {
            n.attribute("points")
                .unwrap_or("")
                .split_whitespace()
                .filter_map(|p| {
                    let (x, y) = p.split_once(',')?;
                    Some((x.parse().ok()?, y.parse().ok()?))
                })
                .collect()
        })
        .collect();
    (legend, lines)
}

#[test]
fn the_legend_stays_clear_of_the_data() {
    let fixture = std::fs::read(root().join("tests/fixtures/robot/recorded_run.lp")).unwrap();
    let out = run(&["run"], &fixture);
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "out.lp", &text(&out.stdout));
    let out = run_in(dir.path(), &["report", "out.lp", "-o", "r"], b"");
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    for plot in ["speeds.svg", "p1.svg", "p3.svg", "mse.svg"] {
        let svg = std::fs::read_to_string(dir.path().join("r").join(plot)).unwrap();
        let ((x0, y0, x1, y1), lines) = legend_and_lines(&svg);
        assert!(x1 > x0 + 50.0 && y1 > y0, "{plot}: a legend box");
        // Every line that starts left of the legend (the data, the axes) stays left of it.
        for points in lines.iter().filter(|p| p.iter().any(|(x, _)| *x < x0)) {
            assert!(
                points.iter().all(|(x, _)| *x < x0),
                "{plot}: a line reaches into the legend at x >= {x0}: {points:?}"
            );
        }
    }
}

/// What `make run` prints after building: the fixture through `run`, then the terminal view.
fn make_run_screen() -> String {
    let fixture = std::fs::read(root().join("tests/fixtures/robot/recorded_run.lp")).unwrap();
    let out = run(&["run", "--no-passthrough"], &fixture);
    assert_eq!(out.status.code(), Some(0));
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("target")).unwrap();
    write(dir.path(), "target/run.lp", &text(&out.stdout));
    let lines = text(&out.stdout).lines().count();
    let out = run_in(
        dir.path(),
        &["report", "--timeline", "--summary", "target/run.lp"],
        b"",
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    format!(
        "{}full line protocol ({lines} lines, as Telegraf gets it): target/run.lp\n",
        text(&out.stdout)
    )
}

#[test]
fn make_run_fits_one_screen_and_the_readme_shows_it() {
    let screen = make_run_screen();
    let lines: Vec<&str> = screen.lines().collect();
    assert!(lines.len() <= 60, "{} lines:\n{screen}", lines.len());
    for l in &lines {
        assert!(l.chars().count() <= 80, "wider than 80: {l}");
    }
    for part in [
        "p1_status unknown",
        "augmented, reason p2: 30 actions",
        "P2 speed tolerance: 60 violated of 300",
        "full line protocol (600 lines",
    ] {
        assert!(screen.contains(part), "`{part}` missing:\n{screen}");
    }
    let makefile = std::fs::read_to_string(root().join("Makefile")).unwrap();
    assert!(
        makefile.contains("report --timeline --summary target/run.lp"),
        "make run prints what this test checks"
    );
    // The book's block under "`make run` prints" (Getting started) is the real output.
    let page = std::fs::read_to_string(root().join("docs/book/src/getting-started.md")).unwrap();
    let block = page
        .split("<!-- make run output -->\n```\n")
        .nth(1)
        .and_then(|r| r.split("```").next())
        .expect("getting-started.md shows make run's output after <!-- make run output -->");
    assert_eq!(
        block, screen,
        "the book's make run block (getting-started.md) is out of date: `make readme-run` rewrites it"
    );
}

#[test]
fn make_test_says_loudly_what_it_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let script = root().join("tools/test-skips.sh");
    let banner = || {
        Command::new("bash")
            .arg(&script)
            .arg(dir.path())
            .output()
            .unwrap()
    };
    let out = banner();
    assert_eq!(out.status.code(), Some(0));
    assert_eq!(text(&out.stdout), "make test: no suite was skipped\n");
    write(
        dir.path(),
        "conformance",
        "TeSSLa suite not found at /x (set TESSLA_SUITE)\n",
    );
    write(dir.path(), "suite_parse", "TeSSLa suite not found\n");
    let out = banner();
    let said = text(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "a skip alone does not fail");
    assert!(said.contains("SKIPPED, NOT PASSED: 2 suite(s)"), "{said}");
    assert!(
        said.contains("  - conformance: TeSSLa suite not found at /x (set TESSLA_SUITE)"),
        "{said}"
    );
    assert!(
        said.contains("TESSLA_SUITE=/path/to/tessla-suite make test"),
        "{said}"
    );
    assert!(!said.contains("tools/setup.sh"), "{said}");
    // A missing server or tool (crates/test-support/src/servers.rs leaves `needs-<program>`)
    // says how to install it.
    write(dir.path(), "needs-babeltrace2", "`babeltrace2` not found\n");
    let out = banner();
    let said = text(&out.stdout);
    assert!(said.contains("SKIPPED, NOT PASSED: 3 suite(s)"), "{said}");
    assert!(
        said.contains("  - needs-babeltrace2: `babeltrace2` not found"),
        "{said}"
    );
    assert!(said.contains("bash tools/setup.sh"), "{said}");
    let makefile = std::fs::read_to_string(root().join("Makefile")).unwrap();
    assert!(makefile.contains("bash tools/test-skips.sh $(SKIP_DIR); exit $$status"));
}

#[test]
fn replay_skips_a_line_that_is_not_utf8_and_reads_on() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("run.lp");
    std::fs::write(
        &p,
        b"mqtt_consumer expectedSpeed=0.1 1000\nmqtt_consumer note=\"\xff\" 2000\nmqtt_consumer expectedSpeed=0.2 3000\n",
    )
    .unwrap();
    // No broker on port 1: the file is read (and its bad line reported) before connecting.
    let out = run(
        &[
            "replay",
            p.to_str().unwrap(),
            "--broker",
            "mqtt://127.0.0.1:1",
        ],
        b"",
    );
    let err = text(&out.stderr);
    assert!(
        err.contains("run.lp: skipped line 2: not UTF-8 (a bad byte at column 21)"),
        "{err}"
    );
    assert!(!err.contains("stream did not contain valid UTF-8"), "{err}");
    assert!(err.contains("cannot reach MQTT broker"), "{err}");
    assert_eq!(out.status.code(), Some(3), "{err}");
}

/// Link `name` of the repository into `dir`.
fn link(dir: &Path, name: &str) {
    let target = dir.join(name);
    if let Some(parent) = target.parent() {
        std::fs::create_dir_all(parent).unwrap();
    }
    std::os::unix::fs::symlink(root().join(name), target).unwrap();
}

#[test]
fn the_package_assets_hold_man_page_completions_docs_and_a_systemd_drop_in() {
    // A copy of the repository's layout with a Telegraf systemd drop-in added, as another
    // change may add one under telegraf/systemd/.
    let dir = tempfile::tempdir().unwrap();
    for name in ["specs", "docs", "examples", "README.md", "tools"] {
        link(dir.path(), name);
    }
    for name in [
        "telegraf.conf",
        "telegraf-fleet.conf",
        "telegraf-udp.conf",
        "dashboards",
    ] {
        link(dir.path(), &format!("telegraf/{name}"));
    }
    let systemd = dir.path().join("telegraf/systemd");
    std::fs::create_dir_all(&systemd).unwrap();
    write(
        &systemd,
        "tessla-telegraf.conf",
        "[Service]\nEnvironment=X=1\n",
    );
    let out = Command::new("bash")
        .arg("tools/deb-assets.sh")
        .arg(BIN)
        .arg("staged")
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let staged = dir.path().join("staged/usr");
    for file in [
        "share/man/man1/tessla-telegraf.1.gz",
        "share/bash-completion/completions/tessla-telegraf",
        "share/zsh/vendor-completions/_tessla-telegraf",
        "share/fish/vendor_completions.d/tessla-telegraf.fish",
        "share/tessla-telegraf/telegraf.tessla",
        // Where examples/first-spec/telegraf.conf names them.
        "share/tessla-telegraf/first-spec/dock.tessla",
        "share/tessla-telegraf/first-spec/battery.tessla",
        "share/doc/tessla-telegraf/README.md",
        "share/doc/tessla-telegraf/book/first-spec.md",
        "share/doc/tessla-telegraf/fleet.md",
        "share/doc/tessla-telegraf/telegraf/telegraf.conf",
        "share/doc/tessla-telegraf/telegraf/dashboards/grafana-influxql.json",
        "share/doc/tessla-telegraf/examples/first-spec/battery.tessla",
        "share/doc/tessla-telegraf/examples/message.lp",
        "lib/systemd/system/telegraf.service.d/tessla-telegraf.conf",
    ] {
        let p = staged.join(file);
        assert!(p.is_file(), "{file} is staged");
        assert!(std::fs::metadata(&p).unwrap().len() > 0, "{file} is empty");
    }
}

#[test]
fn check_lists_the_constants_of_a_spec_whose_annotations_are_bundled() {
    // No telegraf.tessla beside the spec: the bundled annotations serve the include, and the
    // spec's constants are still listed.
    let dir = tempfile::tempdir().unwrap();
    let spec = write(
        dir.path(),
        "b.tessla",
        "include \"telegraf.tessla\"\n@TelegrafIn(\"\", \"\", \"battery\")\nin battery: Events[Float]\n\
         -- Below this, go home.\ndef low_voltage = 11.0\nout battery <. low_voltage as low\n",
    );
    let out = run_in(dir.path(), &["check", spec.to_str().unwrap()], b"");
    let said = text(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(
        said.contains("parameters (`--set`):\n  low_voltage = 11.0  -- Below this, go home."),
        "{said}"
    );
}

#[test]
fn the_first_spec_pitfalls_quote_what_check_says() {
    let dir = tempfile::tempdir().unwrap();
    let readme = std::fs::read_to_string(root().join("docs/book/src/first-spec.md")).unwrap();
    let readme = readme.split_whitespace().collect::<Vec<_>>().join(" ");
    for (spec, says) in [
        (
            "in battery: Events[Float]\nout battery < 11.0 as low\n",
            vec![
                "`<` is not defined for Float in TeSSLa 1.2",
                "use `<.` for Float",
            ],
        ),
        (
            "in battery: Events[Float]\nout sum(battery) as total\n",
            vec![
                "argument 1 of `sum`: expected Events[Int], found Events[Float]",
                "fold",
            ],
        ),
        (
            "in battery: Events[Float]\ndef max_silence = 2000000000\n\
             out delay(max_silence, battery) as silent\n",
            vec![
                "this `delay` is armed only at time 0",
                "write `delay(const(max_silence, battery), battery)`",
            ],
        ),
    ] {
        let p = write(dir.path(), "p.tessla", spec);
        let out = run(&["check", p.to_str().unwrap()], b"");
        let err = text(&out.stderr);
        let code = if spec.contains("delay") { 0 } else { 2 };
        assert_eq!(out.status.code(), Some(code), "{err}");
        for s in says {
            assert!(err.contains(s), "check says `{s}`: {err}");
            assert!(readme.contains(s), "first-spec.md quotes `{s}`");
        }
    }
}
