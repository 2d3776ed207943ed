//! The recorded robot run (tests/fixtures/robot/, written by ROBOT's generator) and our binary's
//! output for it (`tessla-telegraf run` with the bundled spec, pass-through on).

use std::io::Write;
use std::path::PathBuf;
use std::process::{Command, Stdio};

use super::BIN;

/// The recorded-run fixture: tests/fixtures/robot/recorded_run.lp (the name the Makefile uses),
/// else the largest `.lp` file in that folder.
pub fn recorded_run_path() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/robot");
    let preferred = dir.join("recorded_run.lp");
    if preferred.is_file() {
        return preferred;
    }
    let mut candidates: Vec<(u64, PathBuf)> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e} (the recorded-run fixture is missing)",
                dir.display()
            )
        })
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "lp"))
        .map(|p| (std::fs::metadata(&p).map(|m| m.len()).unwrap_or(0), p))
        .collect();
    candidates.sort();
    candidates
        .pop()
        .unwrap_or_else(|| panic!("no .lp recorded run in {}", dir.display()))
        .1
}

/// Run `tessla-telegraf run` (bundled spec) over `input`; its stdout.
pub fn run_binary(input: &str) -> String {
    let mut child = Command::new(BIN)
        .arg("run")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let input = input.to_string();
    let writer = std::thread::spawn(move || {
        let _ = stdin.write_all(input.as_bytes());
    });
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap();
    assert!(
        out.status.success(),
        "tessla-telegraf run failed ({}): {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// The recorded run's text and our output for it.
pub fn recorded_output() -> (String, String) {
    let path = recorded_run_path();
    let input = std::fs::read_to_string(&path).unwrap();
    let output = run_binary(&input);
    (input, output)
}
