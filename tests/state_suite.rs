//! Snapshots over TeSSLa's conformance cases (`$TESSLA_SUITE` or `../shared/tessla-suite`):
//! for every case the engine runs, the monitor is saved after several prefixes of its input
//! (also in the middle of a step), through JSON, restored, and run on; the outputs must equal
//! those of the uninterrupted run. Also: a spec loaded twice has the same fingerprint (node
//! keys are deterministic). Skips without the suite, unless `REQUIRE_TESSLA_SUITE=1`.

use std::path::{Path, PathBuf};
use std::sync::{Arc, mpsc};
use std::time::Duration;
use tessla_engine::snapshot::{self, Snapshot};
use tessla_engine::{LoadOptions, Monitor, OutputEvent, Program, Value};
use tessla_telegraf::trace::reader;

fn suite() -> Option<PathBuf> {
    let dir = std::env::var_os("TESSLA_SUITE")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/tessla-suite"));
    dir.is_dir().then_some(dir)
}

/// Every `*.json` descriptor with a `spec` (`_.ext` = the file named like the descriptor).
fn cases(root: &Path) -> Vec<(PathBuf, serde_json::Value)> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            let Some(mut v) = (p.extension().is_some_and(|x| x == "json"))
                .then(|| std::fs::read_to_string(&p).ok())
                .flatten()
                .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
                .filter(|v| v.get("spec").is_some())
            else {
                continue;
            };
            let stem = p.file_stem().unwrap().to_string_lossy().into_owned();
            for val in v.as_object_mut().unwrap().values_mut() {
                if let Some(ext) = val.as_str().and_then(|s| s.strip_prefix("_.")) {
                    *val = serde_json::Value::String(format!("{stem}.{ext}"));
                }
            }
            out.push((p, v));
        }
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

type Ev = (i64, usize, Value);

/// Push `events` into `m`; the output lines, and whether an input error stopped it.
fn feed(m: &mut Monitor, program: &Program, events: &[Ev], out: &mut Vec<String>) -> bool {
    let mut sink = |e: OutputEvent<'_>| {
        out.push(format!(
            "{}: {} = {}",
            e.ts, program.outputs[e.output].name, e.value
        ))
    };
    for (ts, input, v) in events {
        if m.push(*ts, *input, v.clone(), &mut sink).is_err() {
            return true;
        }
    }
    false
}

fn finish(m: &mut Monitor, program: &Program, out: &mut Vec<String>) {
    m.flush(&mut |e: OutputEvent<'_>| {
        out.push(format!(
            "{}: {} = {}",
            e.ts, program.outputs[e.output].name, e.value
        ))
    });
}

enum Result_ {
    Checked(usize),
    Skipped,
    Unsaved,
    Differs(String),
}

fn check_case(dir: &Path, desc: &serde_json::Value) -> Result_ {
    let get = |k: &str| desc.get(k).and_then(|v| v.as_str()).map(|f| dir.join(f));
    let options = LoadOptions {
        base_time: desc
            .get("baseTime")
            .and_then(|v| v.as_str())
            .map(str::to_string),
        overrides: Vec::new(),
        time_units_need_base: true,
    };
    let Some(spec) = get("spec") else {
        return Result_::Skipped;
    };
    let Ok(loaded) = tessla_engine::load_file(&spec, &options) else {
        return Result_::Skipped;
    };
    let program: Arc<Program> = loaded.program;
    let again = tessla_engine::load_file(&spec, &options).unwrap().program;
    if snapshot::fingerprint(&program) != snapshot::fingerprint(&again) {
        return Result_::Differs("two loads of the spec have different fingerprints".into());
    }
    let text = get("input")
        .and_then(|p| std::fs::read_to_string(p).ok())
        .unwrap_or_default();
    let mut events: Vec<Ev> = Vec::new();
    for e in reader::events(&text, &program) {
        match e {
            Ok(e) => events.push((e.ts, e.input, e.value)),
            Err(_) => break,
        }
    }
    let mut whole_m = Monitor::new(Arc::clone(&program));
    let mut whole = Vec::new();
    let stopped = feed(&mut whole_m, &program, &events, &mut whole);
    if !stopped {
        finish(&mut whole_m, &program, &mut whole);
    }
    let n = events.len();
    let mut cuts: Vec<usize> = (1..=12).map(|k| k * n / 13).filter(|&k| k > 0).collect();
    cuts.dedup();
    let mut checked = 0;
    for cut in cuts {
        let mut m = Monitor::new(Arc::clone(&program));
        let mut got = Vec::new();
        if feed(&mut m, &program, &events[..cut], &mut got) {
            continue;
        }
        let snap = snapshot::snapshot(&m);
        if snap.unsaved > 0 {
            return Result_::Unsaved;
        }
        let json = serde_json::to_string(&snap).unwrap();
        let back: Snapshot = serde_json::from_str(&json).unwrap();
        let mut m = snapshot::restore(Arc::clone(&again), &back);
        let stopped = feed(&mut m, &again, &events[cut..], &mut got);
        if !stopped {
            finish(&mut m, &again, &mut got);
        }
        if got != whole {
            let at = got.iter().zip(&whole).position(|(a, b)| a != b);
            return Result_::Differs(format!(
                "cut after {cut} of {n} events: first difference at output {at:?}: {:?} vs {:?}",
                at.and_then(|i| got.get(i)),
                at.and_then(|i| whole.get(i))
            ));
        }
        checked += 1;
    }
    Result_::Checked(checked)
}

#[test]
fn restored_monitors_continue_every_suite_case_exactly() {
    let Some(root) = suite() else {
        assert!(
            std::env::var_os("REQUIRE_TESSLA_SUITE").is_none(),
            "REQUIRE_TESSLA_SUITE is set but the suite is missing"
        );
        eprintln!("tessla suite not found; skipped");
        return;
    };
    let (mut cases_checked, mut cuts, mut skipped, mut unsaved) = (0, 0, 0, 0);
    let mut failures = Vec::new();
    for (path, desc) in cases(&root) {
        let dir = path.parent().unwrap().to_path_buf();
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send(check_case(&dir, &desc));
        });
        match rx.recv_timeout(Duration::from_secs(20)) {
            Ok(Result_::Checked(k)) => {
                cases_checked += 1;
                cuts += k;
            }
            Ok(Result_::Skipped) | Err(mpsc::RecvTimeoutError::Disconnected) => skipped += 1,
            Ok(Result_::Unsaved) => unsaved += 1,
            Ok(Result_::Differs(why)) => failures.push(format!("{}: {why}", path.display())),
            Err(mpsc::RecvTimeoutError::Timeout) => skipped += 1,
        }
    }
    eprintln!(
        "snapshots: {cases_checked} cases, {cuts} restores equal the uninterrupted run; {skipped} cases not run by the engine, {unsaved} with function values"
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(cases_checked > 50, "only {cases_checked} cases checked");
}
