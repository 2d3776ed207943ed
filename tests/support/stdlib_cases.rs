//! What the library-corpus runners share (`tests/cli/stdlib.rs`, `tests/cli/prelude.rs`): the corpus's
//! names (NAMES.txt) and case files, one trace case through the real binary with its outputs
//! compared as a multiset (floats by value), a pool of worker threads, and the pass-list check
//! (`UPDATE_STDLIB=1` rewrites the list instead).
//!
//! Runs the binary through its sibling `child`.

use super::child;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Duration;

/// How long one child run may take.
pub const CASE_LIMIT: Duration = Duration::from_secs(30);
/// Child processes run at once.
pub const WORKERS: usize = 4;

pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

pub fn fixtures() -> PathBuf {
    root().join("tests/fixtures")
}

/// One line of NAMES.txt: (module, name).
pub fn names() -> Vec<(String, String)> {
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
pub fn specs_in(dir: &Path) -> Vec<PathBuf> {
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

pub fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// A line `ts: name = value` with a float value normalised, so `1.0E10` and `10000000000.0` match.
pub fn normalise(line: &str) -> String {
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
pub fn lines(s: &str) -> Vec<String> {
    let mut v: Vec<String> = s
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with("--"))
        .map(normalise)
        .collect();
    v.sort();
    v
}

pub fn first_line(s: &str) -> String {
    s.lines()
        .map(str::trim)
        .find(|l| !l.is_empty())
        .unwrap_or("no output")
        .to_string()
}

/// Run one trace case; `Ok(())` or the first reason it fails.
pub fn run_trace_case(spec: &Path) -> Result<(), String> {
    run_case_as(spec, spec)
}

/// Run the case of `case` (its `.input`, `.expected` and `.error` files) with the spec file `spec`
/// (the case's own, or a copy with more definitions around it).
pub fn run_case_as(case: &Path, spec: &Path) -> Result<(), String> {
    let input = case.with_extension("input");
    let expected = case.with_extension("expected");
    let error = case.with_extension("error");
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

/// Run `f` over every case on [`WORKERS`] threads; a panic (a run over the deadline) fails the case.
pub fn run_all(
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
pub fn report(
    title: &str,
    results: &BTreeMap<String, Result<(), String>>,
    list: &str,
    summary: &str,
) {
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

/// Every library case (`stdlib/<Module>/<case>`, modules as NAMES.txt lists them) and every user
/// spec (`userspecs/<case>`), with its spec file.
pub fn library_and_user_cases() -> Vec<(String, PathBuf)> {
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
    cases
}
