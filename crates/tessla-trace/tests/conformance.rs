//! TeSSLa's own conformance cases (`$TESSLA_SUITE` or `../shared/tessla-suite` beside the
//! workspace), run through the same code path as `tessla-telegraf trace`
//! ([`tessla_trace::run_with`]).
//!
//! Outputs are compared as sets of lines (`ts: name = value`) with floats compared by value.
//! Cases expecting errors pass when we report an error of that kind: a compile error (a syntax
//! error when TeSSLa reports "Invalid syntax") or a runtime error, with the outputs before it.
//! A case is "unsupported" when we stop on a feature the engine names as not supported.
//! Prints per-folder `N passed, N failed, N unsupported`, writes the workspace's
//! `target/conformance-summary.txt` and the reason for every case that does not pass to
//! `target/conformance-details.txt`. Fails when a case in this crate's
//! `tests/conformance-pass.txt` stops passing (`UPDATE_CONFORMANCE=1` rewrites that list). Each
//! case runs on its own thread with a time limit. Without the suite it skips, unless
//! `REQUIRE_TESSLA_SUITE=1`.

// Shared with the workspace root's snapshot test (tests/cli/state_suite.rs).
use test_support::tessla_suite;

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;
use tessla_syntax::diag::Category;
use tessla_trace::ErrorKind;

/// How long one case may run.
const CASE_LIMIT: Duration = Duration::from_secs(10);

#[derive(Debug, Clone, PartialEq)]
enum Outcome {
    Pass,
    Fail(String),
    /// The feature, as the engine or trace reader names it.
    Unsupported(String),
}

/// A line `ts: name = value` with a float value normalised, so `1.0E10` and `10000000000.0` match.
fn normalise(line: &str) -> String {
    let line = line.trim();
    if let Some((head, value)) = line.split_once(" = ")
        && let Ok(f) = value.trim().parse::<f64>()
        && value.contains(['.', 'E', 'e', 'N', 'I'])
    {
        return format!("{head} = {f:?}");
    }
    line.to_string()
}

fn lines(s: &str) -> BTreeSet<String> {
    s.lines()
        .filter(|l| !l.trim().is_empty())
        .map(normalise)
        .collect()
}

/// Why two output sets differ: the first few missing and unexpected lines.
fn difference(ours: &BTreeSet<String>, expected: &BTreeSet<String>) -> String {
    let missing: Vec<&str> = expected
        .difference(ours)
        .take(3)
        .map(|s| s.as_str())
        .collect();
    let extra: Vec<&str> = ours
        .difference(expected)
        .take(3)
        .map(|s| s.as_str())
        .collect();
    format!(
        "outputs differ ({} missing, {} unexpected); missing: {missing:?}; unexpected: {extra:?}",
        expected.difference(ours).count(),
        ours.difference(expected).count()
    )
}

fn run_case(dir: &Path, desc: &serde_json::Value) -> Outcome {
    let get = |k: &str| tessla_suite::file(dir, desc, k);
    let read = |k: &str| get(k).and_then(|p| std::fs::read_to_string(p).ok());
    let Some(spec) = get("spec") else {
        return Outcome::Fail("descriptor names no spec".into());
    };
    let options = tessla_suite::load_options(desc);
    let expected_errors = read("expectedErrors");
    let loaded = match tessla_engine::load_file(&spec, &options) {
        Ok(l) => l,
        Err(err) => {
            let errors: Vec<_> = err.diagnostics.iter().filter(|d| d.is_error()).collect();
            let first = errors
                .first()
                .map_or_else(|| "no message".to_string(), |d| d.one_line(&err.sources));
            let unsupported = errors.iter().find(|d| d.category == Category::Unsupported);
            return match (&expected_errors, unsupported) {
                (Some(_), Some(u))
                    if errors.iter().all(|d| d.category == Category::Unsupported) =>
                {
                    Outcome::Unsupported(u.message.clone())
                }
                (Some(want), _) => {
                    if want.contains("Invalid syntax")
                        && !errors.iter().any(|d| d.category == Category::Syntax)
                    {
                        Outcome::Fail(format!("expected a syntax error, got: {first}"))
                    } else {
                        Outcome::Pass
                    }
                }
                (None, Some(u)) => Outcome::Unsupported(u.message.clone()),
                (None, None) => Outcome::Fail(format!("compile error: {first}")),
            };
        }
    };
    if let Some(want) = expected_errors {
        let want = want.lines().next().unwrap_or("").to_string();
        return Outcome::Fail(format!("expected a compile error: {want}"));
    }
    let input_name = get("input").map_or_else(|| "input".to_string(), |p| p.display().to_string());
    let input = read("input").unwrap_or_default();
    // TeSSLa's test harness runs its interpreter with `-r` (reject undeclared inputs).
    let reject = tessla_trace::Options {
        reject_undeclared: true,
        ..Default::default()
    };
    let run = tessla_trace::run_with(&loaded.program, &input_name, &input, &reject);
    let expected = lines(&read("expectedOutput").unwrap_or_default());
    let ours = lines(&run.output);
    let expected_runtime = read("expectedRuntimeErrors");
    match (&run.error, &expected_runtime) {
        (Some(e), _) if e.kind == ErrorKind::Unsupported => {
            return Outcome::Unsupported(e.message.clone());
        }
        (Some(e), None) => return Outcome::Fail(format!("runtime error: {}", e.message)),
        (None, Some(want)) => {
            let want = want.lines().next().unwrap_or("").to_string();
            return Outcome::Fail(format!("expected a runtime error: {want}"));
        }
        _ => {}
    }
    if ours == expected {
        Outcome::Pass
    } else {
        Outcome::Fail(difference(&ours, &expected))
    }
}

/// Run one case on its own thread; a panic or a run over [`CASE_LIMIT`] is a failure.
fn run_limited(dir: PathBuf, desc: serde_json::Value) -> Outcome {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let r = std::panic::catch_unwind(|| run_case(&dir, &desc))
            .unwrap_or_else(|_| Outcome::Fail("panicked".into()));
        let _ = tx.send(r);
    });
    rx.recv_timeout(CASE_LIMIT)
        .unwrap_or_else(|_| Outcome::Fail(format!("no result within {} s", CASE_LIMIT.as_secs())))
}

#[derive(Default)]
struct Counts {
    passed: usize,
    failed: usize,
    unsupported: usize,
}

impl Counts {
    fn add(&mut self, o: &Outcome) {
        match o {
            Outcome::Pass => self.passed += 1,
            Outcome::Fail(_) => self.failed += 1,
            Outcome::Unsupported(_) => self.unsupported += 1,
        }
    }

    fn line(&self, name: &str) -> String {
        format!(
            "{name:<15} {:>4} passed, {:>4} failed, {:>4} unsupported\n",
            self.passed, self.failed, self.unsupported
        )
    }
}

#[test]
fn tessla_suite_conformance() {
    let Some(root) = tessla_suite::suite_or_skip("conformance") else {
        return;
    };
    let all = tessla_suite::cases(&root);
    assert!(!all.is_empty(), "no cases found under {}", root.display());
    let results: BTreeMap<String, Outcome> = all
        .into_iter()
        .map(|c| (c.name, run_limited(c.dir, c.desc)))
        .collect();

    let mut per_folder: BTreeMap<String, Counts> = BTreeMap::new();
    let mut total = Counts::default();
    let mut details = String::new();
    for (name, o) in &results {
        let folder = name.split('/').next().unwrap_or("").to_string();
        per_folder.entry(folder).or_default().add(o);
        total.add(o);
        match o {
            Outcome::Pass => {}
            Outcome::Fail(why) => {
                let _ = writeln!(details, "FAIL        {name}: {why}");
            }
            Outcome::Unsupported(what) => {
                let _ = writeln!(details, "UNSUPPORTED {name}: {what}");
            }
        }
    }
    let mut summary = String::new();
    for (folder, counts) in &per_folder {
        summary.push_str(&counts.line(folder));
    }
    summary.push_str(&total.line("total"));
    eprintln!("{summary}");
    let target = tessla_suite::workspace_root().join("target");
    let _ = std::fs::create_dir_all(&target);
    let _ = std::fs::write(target.join("conformance-summary.txt"), &summary);
    let _ = std::fs::write(target.join("conformance-details.txt"), &details);

    let list_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/conformance-pass.txt");
    if std::env::var_os("UPDATE_CONFORMANCE").is_some() {
        let text: String = results
            .iter()
            .filter(|(_, o)| **o == Outcome::Pass)
            .map(|(n, _)| format!("{n}\n"))
            .collect();
        std::fs::write(&list_path, text).unwrap();
        return;
    }
    let expected = std::fs::read_to_string(&list_path).unwrap_or_default();
    let regressions: Vec<String> = expected
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .filter_map(|l| match results.get(l) {
            Some(Outcome::Pass) => None,
            Some(Outcome::Fail(why)) => Some(format!("{l}: {why}")),
            Some(Outcome::Unsupported(what)) => Some(format!("{l}: unsupported: {what}")),
            None => Some(format!("{l}: no such case in the suite")),
        })
        .collect();
    assert!(
        regressions.is_empty(),
        "cases that passed before now fail:\n{}",
        regressions.join("\n")
    );
}
