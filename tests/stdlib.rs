//! The standard-library corpus, the user-style specs and the pending broken specs, each run
//! through the real binary as a child process.
//!
//! - `tests/fixtures/stdlib/<Module>/<case>.tessla` (one or more cases per library name, listed in
//!   `tests/fixtures/stdlib/NAMES.txt`) and `tests/fixtures/userspecs/<case>.tessla`: each runs as
//!   `tessla-telegraf trace SPEC <case>.input`; it passes when the exit code is 0 and the output
//!   lines equal `<case>.expected` (compared as a multiset: the order of simultaneous outputs is
//!   free, floats compare by value). A `<case>.error` file instead asks for a failing run whose
//!   stderr contains its first line (the outputs before the error are still compared).
//! - `tests/fixtures/broken-specs-pending/<case>.tessla`: specs TeSSLa rejects that we accept
//!   today. Each names the place of its error in a first-line comment
//!   `-- error at: <file>.tessla:LINE:COL`; it passes when `tessla-telegraf check` exits 2 naming
//!   that place.
//!
//! Every name of NAMES.txt must have a case, and every stdlib case must belong to a listed name.
//! Prints `N of M pass` and the first error line of each failure, and writes the same to
//! `target/stdlib-summary.txt` (and `target/broken-specs-pending-summary.txt`). Fails when a
//! case listed in `tests/stdlib-pass.txt` (or `tests/broken-specs-pending-pass.txt`) stops
//! passing; `UPDATE_STDLIB=1` (`make stdlib`) rewrites both lists from the current results (they
//! may only grow: a shrinking list is a regression to explain in the commit).

#[path = "support/child.rs"]
mod child;

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Duration;

/// How long one child run may take.
const CASE_LIMIT: Duration = Duration::from_secs(30);
/// Child processes run at once.
const WORKERS: usize = 4;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn fixtures() -> PathBuf {
    root().join("tests/fixtures")
}

/// One line of NAMES.txt: (module, name).
fn names() -> Vec<(String, String)> {
    let text = std::fs::read_to_string(fixtures().join("stdlib/NAMES.txt")).expect("NAMES.txt");
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|l| {
            // The signature column may itself hold `|` (the `|` operator): the first three
            // columns are split from the left, `since` from the right.
            let mut cols = l.splitn(4, '|').map(str::trim);
            let module = cols.next().unwrap_or_default().to_string();
            let name = cols.next().unwrap_or_default().to_string();
            let how = cols.next().unwrap_or_default();
            let since = cols.next().and_then(|rest| rest.rsplit_once('|'));
            assert!(
                !module.is_empty() && !name.is_empty() && !how.is_empty() && since.is_some(),
                "NAMES.txt: malformed line `{l}` (want `module | name | how | signature | since`)"
            );
            (module, name)
        })
        .collect()
}

/// The `.tessla` files of a folder (not recursive), sorted.
fn specs_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "tessla"))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
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

/// Non-blank, non-comment lines, normalised and sorted (a multiset).
fn lines(s: &str) -> Vec<String> {
    let mut v: Vec<String> = s
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with("--"))
        .map(normalise)
        .collect();
    v.sort();
    v
}

fn first_line(s: &str) -> String {
    s.lines()
        .map(str::trim)
        .find(|l| !l.is_empty())
        .unwrap_or("no output")
        .to_string()
}

/// Run one trace case; `Ok(())` or the first reason it fails.
fn run_trace_case(spec: &Path) -> Result<(), String> {
    let input = spec.with_extension("input");
    let expected = spec.with_extension("expected");
    let error = spec.with_extension("error");
    let want_out = std::fs::read_to_string(&expected)
        .map_err(|e| format!("cannot read {}: {e}", expected.display()))?;
    let want_err = std::fs::read_to_string(&error).ok().map(|s| first_line(&s));
    let spec_s = spec.display().to_string();
    let mut args = vec!["trace", spec_s.as_str()];
    // Without an input file the trace is empty (stdin, closed at once).
    let input_s = input.display().to_string();
    if input.exists() {
        args.push(input_s.as_str());
    }
    let f = child::run_bytes(&args, Vec::new(), CASE_LIMIT);
    if f.stderr.contains("panicked") {
        return Err(format!("panicked: {}", first_line(&f.stderr)));
    }
    match (&want_err, f.code) {
        (None, Some(0)) => {}
        (None, code) => {
            return Err(format!(
                "exit {code:?}: {}",
                first_line(&format!("{}\n{}", f.stderr, f.stdout_text()))
            ));
        }
        (Some(_), Some(0)) => return Err("expected a failing run, got exit 0".into()),
        (Some(want), _) => {
            if !f.stderr.contains(want.as_str()) {
                return Err(format!(
                    "expected an error containing `{want}`, got: {}",
                    first_line(&f.stderr)
                ));
            }
        }
    }
    let ours = lines(&f.stdout_text());
    let want = lines(&want_out);
    if ours == want {
        return Ok(());
    }
    let ours_set: BTreeSet<&String> = ours.iter().collect();
    let want_set: BTreeSet<&String> = want.iter().collect();
    let missing: Vec<&&String> = want_set.difference(&ours_set).take(2).collect();
    let extra: Vec<&&String> = ours_set.difference(&want_set).take(2).collect();
    Err(format!(
        "outputs differ ({} lines, want {}); missing {missing:?}, unexpected {extra:?}",
        ours.len(),
        want.len()
    ))
}

/// The place a pending broken spec names in its first comment (`-- error at: f.tessla:3:9`).
fn expected_place(spec: &Path) -> Option<String> {
    let text = std::fs::read_to_string(spec).ok()?;
    text.lines().find_map(|l| {
        l.trim()
            .strip_prefix("--")
            .and_then(|r| r.trim().strip_prefix("error at:"))
            .map(|p| p.trim().to_string())
    })
}

/// Run one pending broken spec through `check`; `Ok(())` when it exits 2 naming its place.
fn run_broken_case(spec: &Path) -> Result<(), String> {
    let place = expected_place(spec)
        .ok_or_else(|| "no `-- error at: FILE:LINE:COL` comment".to_string())?;
    let spec_s = spec.display().to_string();
    let f = child::run_bytes(&["check", spec_s.as_str()], Vec::new(), CASE_LIMIT);
    let text = format!("{}{}", f.stderr, f.stdout_text());
    if text.contains("panicked") {
        return Err(format!("panicked: {}", first_line(&f.stderr)));
    }
    if f.code != Some(2) {
        return Err(format!(
            "check exits {:?} (want 2): {}",
            f.code,
            first_line(&text)
        ));
    }
    if !text.contains(&format!("/{place}")) && !text.contains(&format!(" {place}")) {
        return Err(format!(
            "rejected, but not at {place}: {}",
            first_line(&text)
        ));
    }
    Ok(())
}

/// Run `f` over every case on [`WORKERS`] threads; a panic (a run over the deadline) fails the case.
fn run_all(
    cases: Vec<(String, PathBuf)>,
    f: fn(&Path) -> Result<(), String>,
) -> BTreeMap<String, Result<(), String>> {
    let queue = Mutex::new(cases);
    let results = Mutex::new(BTreeMap::new());
    std::thread::scope(|s| {
        for _ in 0..WORKERS {
            s.spawn(|| {
                loop {
                    let next = queue.lock().map(|mut q| q.pop()).unwrap_or(None);
                    let Some((id, path)) = next else { break };
                    let r = std::panic::catch_unwind(|| f(&path))
                        .unwrap_or_else(|_| Err("the child run failed or overran".into()));
                    if let Ok(mut m) = results.lock() {
                        m.insert(id, r);
                    }
                }
            });
        }
    });
    results.into_inner().unwrap_or_default()
}

/// Print and record the results, rewrite or check the pass list at `list` (relative to the root).
fn report(title: &str, results: &BTreeMap<String, Result<(), String>>, list: &str, summary: &str) {
    let passed = results.values().filter(|r| r.is_ok()).count();
    let mut text = format!("{title}: {passed} of {} pass\n", results.len());
    for (id, r) in results {
        if let Err(why) = r {
            let _ = writeln!(text, "FAIL {id}: {why}");
        }
    }
    eprintln!("{text}");
    let target = root().join("target");
    let _ = std::fs::create_dir_all(&target);
    let _ = std::fs::write(target.join(summary), &text);

    let list_path = root().join(list);
    if std::env::var_os("UPDATE_STDLIB").is_some() {
        let body: String = results
            .iter()
            .filter(|(_, r)| r.is_ok())
            .map(|(id, _)| format!("{id}\n"))
            .collect();
        let head =
            format!("# Cases of {title} that pass; may only grow. Rewritten by `make stdlib`.\n");
        std::fs::write(&list_path, head + &body).expect("write the pass list");
        return;
    }
    let listed = std::fs::read_to_string(&list_path).unwrap_or_default();
    let regressions: Vec<String> = listed
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .filter_map(|l| match results.get(l) {
            Some(Ok(())) => None,
            Some(Err(why)) => Some(format!("{l}: {why}")),
            None => Some(format!("{l}: no such case")),
        })
        .collect();
    assert!(
        regressions.is_empty(),
        "cases listed in {list} now fail:\n{}",
        regressions.join("\n")
    );
}

#[test]
fn every_library_name_has_a_case() {
    let names = names();
    let dir = fixtures().join("stdlib");
    let mut cases: BTreeSet<(String, String)> = BTreeSet::new();
    let mut strays = Vec::new();
    let known: BTreeSet<&(String, String)> = names.iter().collect();
    let modules: BTreeSet<&String> = names.iter().map(|(m, _)| m).collect();
    for entry in std::fs::read_dir(&dir)
        .expect("tests/fixtures/stdlib")
        .flatten()
    {
        let folder = entry.file_name().to_string_lossy().into_owned();
        if entry.path().is_dir() && !modules.contains(&folder) {
            strays.push(format!("{folder}/ (no such module in NAMES.txt)"));
        }
    }
    for module in modules {
        for spec in specs_in(&dir.join(module)) {
            let s = stem(&spec);
            let name = s.split('.').next().unwrap_or_default().to_string();
            let key = (module.clone(), name);
            if !known.contains(&key) {
                strays.push(format!("{module}/{s}"));
            }
            assert!(
                spec.with_extension("expected").exists(),
                "{module}/{s}: no .expected file"
            );
            cases.insert(key);
        }
    }
    let missing: Vec<String> = names
        .iter()
        .filter(|k| !cases.contains(k))
        .map(|(m, n)| format!("{m}.{n}"))
        .collect();
    eprintln!(
        "{} names in NAMES.txt, {} with a case",
        names.len(),
        names.len() - missing.len()
    );
    assert!(
        missing.is_empty(),
        "names without a case:\n{}",
        missing.join("\n")
    );
    assert!(
        strays.is_empty(),
        "cases for names NAMES.txt does not list:\n{}",
        strays.join("\n")
    );
}

#[test]
fn library_and_user_specs() {
    let mut cases = Vec::new();
    let stdlib = fixtures().join("stdlib");
    let modules: BTreeSet<String> = names().into_iter().map(|(m, _)| m).collect();
    for module in &modules {
        for spec in specs_in(&stdlib.join(module)) {
            cases.push((format!("stdlib/{module}/{}", stem(&spec)), spec));
        }
    }
    for spec in specs_in(&fixtures().join("userspecs")) {
        cases.push((format!("userspecs/{}", stem(&spec)), spec));
    }
    assert!(!cases.is_empty(), "no cases found");
    let results = run_all(cases, run_trace_case);
    report(
        "library and user specs",
        &results,
        "tests/stdlib-pass.txt",
        "stdlib-summary.txt",
    );
}

#[test]
fn pending_broken_specs() {
    let cases: Vec<(String, PathBuf)> = specs_in(&fixtures().join("broken-specs-pending"))
        .into_iter()
        .map(|p| (stem(&p), p))
        .collect();
    assert!(!cases.is_empty(), "no pending broken specs found");
    let results = run_all(cases, run_broken_case);
    report(
        "pending broken specs",
        &results,
        "tests/broken-specs-pending-pass.txt",
        "broken-specs-pending-summary.txt",
    );
}
