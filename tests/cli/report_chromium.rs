//! `report`'s page as a browser shows it: headless Chromium (`chromium --headless`, Debian
//! package `chromium`, installed by `tools/setup.sh`) loads the page and each of its SVG plots
//! (`--dump-dom`: what the browser parsed, not our own text) and takes a screenshot of the page
//! (`--screenshot`), for three runs: the bundled robot spec over the recorded run, a user's own
//! spec (a battery alert, an alert count, a silence watchdog, an action), and that spec run as a
//! fleet of two robots on two spec versions. Asserted on what Chromium holds: every output of
//! the run in the outputs table and every plot file as an image on the page; single events as
//! markers, counts as steps; the robot spec's sections for the bundled run only; for the fleet
//! its per-robot and per-version splits and a series per robot. Each screenshot must be the
//! window's size and hold more than the same page with its plots removed (measured in the same
//! run), i.e. the plots are drawn. The screenshots stay in `<target>/report-screenshots/` for
//! review by eye. Without Chromium the test skips loudly (fails with `REQUIRE_SERVERS=1`).

use super::report_any_spec::{S, SPEC, T0, fleet_run};
use crate::support::child::{root, run_in, text, write};
use crate::support::recorded;
use crate::support::servers;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The window of the screenshots.
const WIDTH: u32 = 1100;
const HEIGHT: u32 = 2400;

/// Headless Chromium, each call with a profile folder of its own (tests run at once).
struct Browser {
    binary: PathBuf,
    profile: tempfile::TempDir,
}

impl Browser {
    fn find() -> Option<Browser> {
        let binary = servers::require("chromium", "chromium")?;
        Some(Browser {
            binary,
            profile: tempfile::tempdir().unwrap(),
        })
    }

    /// Chromium on `file` with `args`; its stdout. Fails the test after 120 s or on an error
    /// exit.
    fn run(&self, file: &Path, args: &[&str]) -> String {
        let out_path = self.profile.path().join("stdout");
        let mut child = Command::new(&self.binary)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--hide-scrollbars",
            ])
            .arg(format!("--user-data-dir={}", self.profile.path().display()))
            .args(args)
            .arg(format!("file://{}", file.display()))
            .stdin(Stdio::null())
            .stdout(std::fs::File::create(&out_path).unwrap())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(120);
        let status = loop {
            if let Some(status) = child.try_wait().unwrap() {
                break status;
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                let _ = child.wait();
                panic!("chromium {args:?} {} did not end in 120 s", file.display());
            }
            std::thread::sleep(Duration::from_millis(100));
        };
        assert!(
            status.success(),
            "chromium {args:?} {}: {status}",
            file.display()
        );
        std::fs::read_to_string(&out_path).unwrap_or_default()
    }

    /// The document Chromium made of `file`.
    fn dom(&self, file: &Path) -> String {
        let dom = self.run(file, &["--dump-dom"]);
        assert!(!dom.trim().is_empty(), "no DOM of {}", file.display());
        dom
    }

    /// A screenshot of `file` at `png`; its bytes.
    fn screenshot(&self, file: &Path, png: &Path) -> Vec<u8> {
        self.run(
            file,
            &[
                &format!("--window-size={WIDTH},{HEIGHT}"),
                &format!("--screenshot={}", png.display()),
            ],
        );
        std::fs::read(png).unwrap_or_else(|e| panic!("{}: {e}", png.display()))
    }
}

/// Where the screenshots stay for review: `<target>/report-screenshots/`.
fn shots_dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .unwrap()
        .join("report-screenshots");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A PNG's width and height (its IHDR chunk).
fn png_size(png: &[u8]) -> (u32, u32) {
    assert!(
        png.len() > 24 && png.starts_with(b"\x89PNG\r\n\x1a\n") && &png[12..16] == b"IHDR",
        "not a PNG"
    );
    let be = |at: usize| u32::from_be_bytes([png[at], png[at + 1], png[at + 2], png[at + 3]]);
    (be(16), be(20))
}

/// `report LP -o DIR` in `dir`; the report's folder.
fn report(dir: &Path, name: &str, lp: &str) -> PathBuf {
    write(dir, &format!("{name}.lp"), lp);
    let out = run_in(dir, &["report", &format!("{name}.lp"), "-o", name], b"");
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    dir.join(name)
}

/// The `<tr id="output-...">` row of the outputs table whose id starts with `output-{name}`
/// (an instance's row goes on with `[robot=...]`), as Chromium holds it.
fn rows<'a>(dom: &'a str, name: &str) -> Vec<&'a str> {
    let start = format!("<tr id=\"output-{name}");
    dom.lines()
        .filter(|l| {
            l.starts_with(&start)
                && l[start.len()..]
                    .chars()
                    .next()
                    .is_some_and(|c| c == '"' || c == '[')
        })
        .collect()
}

/// Checks common to every page: each SVG in the folder is an image of the page and a document
/// Chromium parses as an `<svg>` with drawing in it; the screenshot is the window's size and
/// holds more than the page without its plots. Returns the page's DOM and each plot's.
fn check_page(browser: &Browser, dir: &Path, name: &str) -> (String, Vec<(String, String)>) {
    let page = dir.join("index.html");
    let dom = browser.dom(&page);
    assert!(dom.contains("<h1>Run report</h1>"), "{dom}");
    let mut svgs: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".svg"))
        .collect();
    svgs.sort();
    assert!(!svgs.is_empty(), "{name}: no plot");
    let mut plots = Vec::new();
    for svg in &svgs {
        assert!(
            dom.contains(&format!("<img src=\"{svg}\"")),
            "{name}: {svg} is not on the page:\n{dom}"
        );
        let doc = browser.dom(&dir.join(svg));
        assert!(doc.trim_start().starts_with("<svg"), "{name}/{svg}: {doc}");
        assert!(
            doc.contains("<polyline") || doc.contains("<circle") || doc.contains("<polygon"),
            "{name}/{svg}: nothing drawn"
        );
        plots.push((svg.clone(), doc));
    }
    let shots = shots_dir();
    let shot = browser.screenshot(&page, &shots.join(format!("{name}.png")));
    assert_eq!(png_size(&shot), (WIDTH, HEIGHT), "{name}");
    // The same page with its plots gone (broken images): the baseline of this run.
    let bare = dir.join("bare");
    std::fs::create_dir_all(&bare).unwrap();
    std::fs::copy(&page, bare.join("index.html")).unwrap();
    let without = browser.screenshot(
        &bare.join("index.html"),
        &bare.join(format!("{name}-without-plots.png")),
    );
    assert!(
        shot.len() > without.len() + without.len() / 4,
        "{name}: the screenshot ({} bytes) holds hardly more than the page without plots ({} bytes)",
        shot.len(),
        without.len()
    );
    eprintln!(
        "{name}: {} plots; screenshot {} bytes (without plots {}) in {}",
        svgs.len(),
        shot.len(),
        without.len(),
        shots.join(format!("{name}.png")).display()
    );
    (dom, plots)
}

/// Whether a `<polyline>` of `svg` is drawn as steps: every segment level or upright, with at
/// least one of each.
fn has_steps(svg: &str) -> bool {
    svg.split("<polyline").skip(1).any(|p| {
        let Some(points) = p
            .split("points=\"")
            .nth(1)
            .and_then(|r| r.split('"').next())
        else {
            return false;
        };
        let xy: Vec<(f64, f64)> = points
            .split_whitespace()
            .filter_map(|pt| {
                let (x, y) = pt.split_once(',')?;
                Some((x.parse().ok()?, y.parse().ok()?))
            })
            .collect();
        let segments: Vec<_> = xy.windows(2).filter(|w| w[0] != w[1]).collect();
        let level = segments.iter().filter(|w| w[0].1 == w[1].1).count();
        let upright = segments.iter().filter(|w| w[0].0 == w[1].0).count();
        !segments.is_empty() && level + upright == segments.len() && level > 0 && upright > 0
    })
}

#[test]
fn report_pages_in_headless_chromium_show_every_output_by_its_shape() {
    let Some(browser) = Browser::find() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();

    // The bundled robot spec over the recorded run: the robot's sections and charts.
    let (_, output) = recorded::recorded_output();
    let bundled = report(dir.path(), "bundled", &output);
    let (dom, plots) = check_page(&browser, &bundled, "bundled");
    for part in [
        "id=\"mse\"",
        "<img src=\"speeds.svg\"",
        "<img src=\"p1.svg\"",
    ] {
        assert!(dom.contains(part), "bundled: {part} missing:\n{dom}");
    }
    let speeds = &plots.iter().find(|(n, _)| n == "speeds.svg").unwrap().1;
    assert!(speeds.contains("<polyline"), "the speeds are drawn");

    // A user's own spec, one robot: every output, events as marks, the count as steps, none
    // of the robot spec's sections.
    let mut input = String::new();
    for i in 0..10i64 {
        if (4..8).contains(&i) {
            continue;
        }
        input.push_str(&format!(
            "mqtt_consumer battery={}.0 {}\n",
            30 - 3 * i,
            T0 + i * S
        ));
    }
    let spec = write(dir.path(), "battery.tessla", SPEC);
    let out = run_in(
        &root(),
        &["run", "--no-passthrough", "--spec", spec.to_str().unwrap()],
        input.as_bytes(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let users = report(dir.path(), "users-spec", &text(&out.stdout));
    let (dom, plots) = check_page(&browser, &users, "users-spec");
    for (output, shape) in [
        ("low", "timeline"),
        ("battery_alert", "marks"),
        ("command", "marks"),
        ("silent", "marks"),
        ("alerts", "steps"),
    ] {
        let found = rows(&dom, output);
        assert_eq!(found.len(), 1, "users-spec: the row of {output}:\n{dom}");
        assert!(
            found[0].contains(shape),
            "{output} as {shape}: {}",
            found[0]
        );
    }
    for robot_only in [
        "Mean squared error",
        "id=\"violations\"",
        "Robot silent",
        "speeds.svg",
        "Per instance",
    ] {
        assert!(
            !dom.contains(robot_only),
            "users-spec: {robot_only}:\n{dom}"
        );
    }
    let verdicts = &plots.iter().find(|(n, _)| n == "verdicts.svg").unwrap().1;
    // A mark per event (battery_alert, command, silent: one each) and one per legend entry.
    assert!(
        verdicts.matches("<polygon").count() >= 3,
        "single events as markers: {verdicts}"
    );
    for name in ["battery_alert", "command", "silent", "low"] {
        assert!(verdicts.contains(name), "{name} in verdicts.svg");
    }
    let numeric = &plots.iter().find(|(n, _)| n == "outputs.svg").unwrap().1;
    assert!(numeric.contains("alerts"), "{numeric}");
    assert!(has_steps(numeric), "the count as steps: {numeric}");

    // The spec as a fleet: robot a on version v1, robot b on v2.
    let v1 = fleet_run(dir.path(), "v1");
    let v2 = fleet_run(dir.path(), "v2");
    let pick = |run: &str, robot: &str| -> String {
        run.lines()
            .filter(|l| l.contains(&format!("robot={robot}")))
            .map(|l| format!("{l}\n"))
            .collect()
    };
    let fleet = report(
        dir.path(),
        "fleet",
        &format!("{}{}", pick(&v1, "a"), pick(&v2, "b")),
    );
    let (dom, plots) = check_page(&browser, &fleet, "fleet");
    assert!(
        dom.contains("<table id=\"splits\">"),
        "fleet: no splits:\n{dom}"
    );
    let splits: Vec<&str> = dom.lines().filter(|l| l.contains("id=\"split-")).collect();
    for want in ["split-robot-a", "split-robot-b"] {
        assert!(
            splits.iter().any(|l| l.contains(want)),
            "fleet: {want} in {splits:#?}"
        );
    }
    let versions = splits
        .iter()
        .filter(|l| l.contains("id=\"split-spec_version-"))
        .count();
    assert_eq!(versions, 2, "fleet: a split per version: {splits:#?}");
    // Robot b alone falls silent (3 s to 8 s).
    for (output, robots) in [
        ("alerts", &["a", "b"][..]),
        ("battery_alert", &["a", "b"]),
        ("command", &["a", "b"]),
        ("low", &["a", "b"]),
        ("silent", &["b"]),
    ] {
        let found = rows(&dom, output);
        for robot in robots {
            assert!(
                found.iter().any(|r| r.contains(&format!("[robot={robot}"))),
                "fleet: {output} of robot {robot}: {found:#?}"
            );
        }
    }
    let numeric = &plots.iter().find(|(n, _)| n == "outputs.svg").unwrap().1;
    for robot in ["a", "b"] {
        assert!(
            numeric.contains(&format!("alerts[robot={robot}")),
            "fleet: a series per robot: {numeric}"
        );
    }
    assert!(has_steps(numeric), "fleet: counts as steps");
}
