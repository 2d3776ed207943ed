//! The binary run to its end from a test, the way a user runs it once: in a given folder, with
//! bytes on stdin, its whole `Output` (stdout, stderr, exit status) returned; and the spec or
//! trace files such a run reads, written first. For a run under a deadline or with its memory
//! measured see `child.rs`; for a long-running child see `live_child.rs`.
//!
//! Include with `#[path = "support/run.rs"] mod run;`.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

pub const BIN: &str = env!("CARGO_BIN_EXE_tessla-telegraf");

/// The package's root folder (where `cargo test` runs the tests).
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Run the binary in `dir` with `args`, `stdin` as its input.
pub fn run_in(dir: &Path, args: &[&str], stdin: &[u8]) -> Output {
    let mut child = Command::new(BIN)
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn the binary");
    // Written from a thread while the output is read, so a large input cannot deadlock on a
    // full pipe; a child that exits before reading (a bad command line, a spec error) closes
    // the pipe, which is not a failure.
    let writer = child.stdin.take().map(|mut input| {
        let bytes = stdin.to_vec();
        std::thread::spawn(move || {
            let _ = std::io::Write::write_all(&mut input, &bytes);
        })
    });
    let out = child.wait_with_output().expect("wait for the binary");
    if let Some(w) = writer {
        let _ = w.join();
    }
    out
}

/// Output bytes as text (invalid UTF-8 replaced).
pub fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Write `content` to `dir/name`; returns the path.
pub fn write(dir: &Path, name: &str, content: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, content).expect("write a test file");
    p
}
