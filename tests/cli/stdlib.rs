//! The standard-library corpus and the user-style specs, each run through the real binary as a
//! child process.
//!
//! - `tests/fixtures/stdlib/<Module>/<case>.tessla` (one or more cases per library name, listed in
//!   `tests/fixtures/stdlib/NAMES.txt`) and `tests/fixtures/userspecs/<case>.tessla`: each runs as
//!   `tessla-telegraf trace SPEC <case>.input`; it passes when the exit code is 0 and the output
//!   lines equal `<case>.expected` (compared as a multiset: the order of simultaneous outputs is
//!   free, floats compare by value). A `<case>.error` file instead asks for a failing run whose
//!   stderr contains its first line (the outputs before the error are still compared).
//!
//! Every name of NAMES.txt must have a case, and every stdlib case must belong to a listed name.
//! Prints `N of M pass` and the first error line of each failure, and writes the same to
//! `target/stdlib-summary.txt`. Fails when a case listed in `tests/stdlib-pass.txt` stops
//! passing; `UPDATE_STDLIB=1` (`make stdlib`) rewrites the list from the current results (it
//! may only grow: a shrinking list is a regression to explain in the commit).

use crate::support::stdlib_cases;

use std::collections::BTreeSet;
use stdlib_cases::{
    fixtures, library_and_user_cases, names, report, run_all, run_trace_case, specs_in, stem,
};

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
    let cases = library_and_user_cases();
    let results = run_all(cases, run_trace_case);
    report(
        "library and user specs",
        &results,
        "tests/stdlib-pass.txt",
        "stdlib-summary.txt",
    );
}
