//! TeSSLa's own conformance cases (`$TESSLA_SUITE` or `../shared/tessla-suite`), run through the
//! same code path as `tessla-telegraf trace`. Outputs are compared as sets of lines with floats
//! compared by value; cases expecting errors pass when we report an error of that kind.
//! Prints per-folder figures and writes `target/conformance-summary.txt`. Fails when a case in
//! `tests/conformance-pass.txt` stops passing (`UPDATE_CONFORMANCE=1` rewrites that list).
//! Without the suite it skips, unless `REQUIRE_TESSLA_SUITE=1`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;
use tessla_engine::LoadOptions;

fn suite() -> Option<PathBuf> {
    let dir = std::env::var_os("TESSLA_SUITE")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/tessla-suite"));
    dir.is_dir().then_some(dir)
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Outcome {
    Pass,
    Fail,
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

fn run_case(dir: &Path, desc: &serde_json::Value) -> Outcome {
    let get = |k: &str| desc.get(k).and_then(|v| v.as_str()).map(|f| dir.join(f));
    let Some(spec) = get("spec") else {
        return Outcome::Fail;
    };
    let options = LoadOptions {
        base_time: desc
            .get("baseTime")
            .and_then(|v| v.as_str())
            .map(str::to_string),
        overrides: Vec::new(),
    };
    let loaded = tessla_engine::load_file(&spec, &options);
    let expects_compile_error = get("expectedErrors").is_some();
    let loaded = match loaded {
        Ok(l) => l,
        Err(_) => {
            return if expects_compile_error {
                Outcome::Pass
            } else {
                Outcome::Fail
            };
        }
    };
    if expects_compile_error {
        return Outcome::Fail;
    }
    let input = get("input")
        .and_then(|p| std::fs::read_to_string(p).ok())
        .unwrap_or_default();
    let run = tessla_telegraf::trace::run(&loaded.program, &input);
    let expected = get("expectedOutput")
        .and_then(|p| std::fs::read_to_string(p).ok())
        .unwrap_or_default();
    let expects_runtime_error = get("expectedRuntimeErrors").is_some();
    if expects_runtime_error != run.error.is_some() {
        return Outcome::Fail;
    }
    if expects_runtime_error {
        // Outputs before the error must match those TeSSLa printed (as a set).
        return if lines(&run.output).is_subset(&lines(&expected))
            || lines(&expected).is_subset(&lines(&run.output))
        {
            Outcome::Pass
        } else {
            Outcome::Fail
        };
    }
    if lines(&run.output) == lines(&expected) {
        Outcome::Pass
    } else {
        Outcome::Fail
    }
}

fn cases(root: &Path) -> Vec<(String, PathBuf, serde_json::Value)> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "json")
                && let Ok(t) = std::fs::read_to_string(&p)
                && let Ok(mut v) = serde_json::from_str::<serde_json::Value>(&t)
                && v.get("spec").is_some()
            {
                let stem = p
                    .file_stem()
                    .and_then(|s| s.to_str())
                    .unwrap_or("")
                    .to_string();
                // `_.tessla` in a descriptor means "the file named like the descriptor".
                if let Some(obj) = v.as_object_mut() {
                    for val in obj.values_mut() {
                        if let Some(s) = val.as_str()
                            && let Some(ext) = s.strip_prefix("_.")
                        {
                            *val = serde_json::Value::String(format!("{stem}.{ext}"));
                        }
                    }
                }
                let rel = p.strip_prefix(root).unwrap_or(&p).with_extension("");
                out.push((rel.display().to_string(), d.clone(), v));
            }
        }
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

#[test]
fn tessla_suite_conformance() {
    let Some(root) = suite() else {
        assert!(
            std::env::var_os("REQUIRE_TESSLA_SUITE").is_none(),
            "REQUIRE_TESSLA_SUITE is set but the TeSSLa suite was not found (set TESSLA_SUITE or put it at ../shared/tessla-suite)"
        );
        eprintln!("conformance: TeSSLa suite not found; skipped (set TESSLA_SUITE)");
        return;
    };
    let all = cases(&root);
    assert!(!all.is_empty(), "no cases found under {}", root.display());
    let mut results: BTreeMap<String, Outcome> = BTreeMap::new();
    for (name, dir, desc) in all {
        // Each case runs on its own thread with a time limit, so a hang cannot hang the test.
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let r = std::panic::catch_unwind(|| run_case(&dir, &desc)).unwrap_or(Outcome::Fail);
            let _ = tx.send(r);
        });
        let outcome = rx
            .recv_timeout(Duration::from_secs(10))
            .unwrap_or(Outcome::Fail);
        results.insert(name, outcome);
    }
    let mut per_folder: BTreeMap<String, (usize, usize)> = BTreeMap::new();
    for (name, o) in &results {
        let folder = name.split('/').next().unwrap_or("").to_string();
        let e = per_folder.entry(folder).or_default();
        match o {
            Outcome::Pass => e.0 += 1,
            Outcome::Fail => e.1 += 1,
        }
    }
    let mut summary = String::new();
    let (mut p, mut f) = (0, 0);
    for (folder, (ok, bad)) in &per_folder {
        summary.push_str(&format!("{folder:<12} {ok:>4} passed, {bad:>4} failed\n"));
        p += ok;
        f += bad;
    }
    summary.push_str(&format!("{:<12} {p:>4} passed, {f:>4} failed\n", "total"));
    eprintln!("{summary}");
    let target = Path::new(env!("CARGO_MANIFEST_DIR")).join("target");
    let _ = std::fs::create_dir_all(&target);
    let _ = std::fs::write(target.join("conformance-summary.txt"), &summary);

    let list_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/conformance-pass.txt");
    let passing: Vec<&String> = results
        .iter()
        .filter(|(_, o)| **o == Outcome::Pass)
        .map(|(n, _)| n)
        .collect();
    if std::env::var_os("UPDATE_CONFORMANCE").is_some() {
        let text: String = passing.iter().map(|n| format!("{n}\n")).collect();
        std::fs::write(&list_path, text).unwrap();
        return;
    }
    let expected = std::fs::read_to_string(&list_path).unwrap_or_default();
    let regressions: Vec<&str> = expected
        .lines()
        .filter(|l| !l.trim().is_empty())
        .filter(|l| results.get(*l) != Some(&Outcome::Pass))
        .collect();
    assert!(
        regressions.is_empty(),
        "cases that passed before now fail:\n{}",
        regressions.join("\n")
    );
}
