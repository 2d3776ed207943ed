//! Snapshots over TeSSLa's conformance cases (`$TESSLA_SUITE` or `../shared/tessla-suite`):
//! for every case the engine runs, the monitor is saved after several prefixes of its input
//! (also in the middle of a step), through JSON, restored, and run on; the outputs must equal
//! those of the uninterrupted run. Also: a spec loaded twice has the same fingerprint (node
//! keys are deterministic). Skips without the suite, unless `REQUIRE_TESSLA_SUITE=1`.

use crate::support::tessla_suite;

use std::path::Path;
use std::sync::{Arc, mpsc};
use std::time::Duration;
use tessla_engine::snapshot::{self, Snapshot};
use tessla_engine::{Monitor, OutputEvent, Program, Value};
use tessla_telegraf::trace::reader;

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
    let get = |k: &str| tessla_suite::file(dir, desc, k);
    let options = tessla_suite::load_options(desc);
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
    let Some(root) = tessla_suite::suite_or_skip("state_suite") else {
        return;
    };
    let (mut cases_checked, mut cuts, mut skipped, mut unsaved) = (0, 0, 0, 0);
    let mut failures = Vec::new();
    for tessla_suite::Case { name, dir, desc } in tessla_suite::cases(&root) {
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
            Ok(Result_::Differs(why)) => failures.push(format!("{name}: {why}")),
            Err(mpsc::RecvTimeoutError::Timeout) => skipped += 1,
        }
    }
    eprintln!(
        "snapshots: {cases_checked} cases, {cuts} restores equal the uninterrupted run; {skipped} cases not run by the engine, {unsaved} with function values"
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(cases_checked > 50, "only {cases_checked} cases checked");
}
