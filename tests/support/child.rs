//! The binary as a child process under a deadline: input written from a writer thread, stdout and
//! stderr collected by reader threads, the child killed (and the test failed, with its stderr) if
//! it has not exited by the deadline, and its peak resident memory (VmHWM) read from /proc while
//! it runs. Also the binary run once in a folder, the way a user runs it ([`run_in`]: its whole
//! `Output`), and the spec or trace files such a run reads ([`write`]).

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Output, Stdio};
use std::time::{Duration, Instant};

use super::BIN;

/// How a child run ended.
#[derive(Debug)]
pub struct Finished {
    pub stdout: Vec<u8>,
    pub stderr: String,
    /// Exit code; `None` when killed by a signal.
    pub code: Option<i32>,
    /// The largest VmHWM (peak RSS, KiB) read from /proc/<pid>/status before the child exited.
    pub peak_rss_kib: Option<u64>,
}

impl Finished {
    pub fn stdout_text(&self) -> String {
        String::from_utf8_lossy(&self.stdout).into_owned()
    }
}

/// The binary with `args` and all three pipes open, not started yet: an environment variable or
/// a folder for the child goes on this `Command` (never on the test process, whose other tests
/// run at the same time).
pub fn command(args: &[&str]) -> Command {
    let mut c = Command::new(BIN);
    c.args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    c
}

/// The binary started with `args`, all three pipes open.
pub fn spawn(args: &[&str]) -> Child {
    command(args).spawn().expect("spawn the binary")
}

/// The binary started with `args` (in `dir`, or in this process's folder), all three pipes open.
fn spawn_piped(args: &[&str], dir: Option<&Path>) -> Child {
    let mut c = command(args);
    if let Some(dir) = dir {
        c.current_dir(dir);
    }
    c.spawn().expect("spawn the binary")
}

/// Run the binary with `args`, `feed` writing its stdin (stdin is closed when `feed` returns);
/// panics if the child has not exited after `deadline`.
pub fn run_with<F>(args: &[&str], deadline: Duration, feed: F) -> Finished
where
    F: FnOnce(&mut ChildStdin) + Send + 'static,
{
    let mut child = spawn_piped(args, None);
    let pid = child.id();
    let mut stdin = child.stdin.take().expect("stdin");
    let writer = std::thread::spawn(move || {
        feed(&mut stdin);
        drop(stdin);
    });
    let mut out = child.stdout.take().expect("stdout");
    let mut err = child.stderr.take().expect("stderr");
    let out_reader = std::thread::spawn(move || {
        let mut v = Vec::new();
        let _ = out.read_to_end(&mut v);
        v
    });
    let err_reader = std::thread::spawn(move || {
        let mut v = Vec::new();
        let _ = err.read_to_end(&mut v);
        v
    });
    let start = Instant::now();
    let mut peak = None;
    let status = loop {
        if let Some(hwm) = vm_hwm_kib(pid) {
            peak = Some(peak.map_or(hwm, |p: u64| p.max(hwm)));
        }
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        if start.elapsed() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            let err = err_reader.join().unwrap_or_default();
            let tail = String::from_utf8_lossy(&err);
            let tail: String = tail
                .chars()
                .rev()
                .take(4000)
                .collect::<Vec<_>>()
                .into_iter()
                .rev()
                .collect();
            panic!("the child did not exit within {deadline:?} (killed); stderr tail:\n{tail}");
        }
        // Polling the deadline (and sampling memory), not synchronising on it.
        std::thread::sleep(Duration::from_millis(5));
    };
    let _ = writer.join();
    Finished {
        stdout: out_reader.join().unwrap_or_default(),
        stderr: String::from_utf8_lossy(&err_reader.join().unwrap_or_default()).into_owned(),
        code: status.code(),
        peak_rss_kib: peak,
    }
}

/// Run the binary with `args` and the bytes `input` on stdin.
pub fn run_bytes(args: &[&str], input: Vec<u8>, deadline: Duration) -> Finished {
    run_with(args, deadline, move |stdin| {
        // The child may stop reading (closed stdout, early exit): the test checks the result.
        let _ = stdin.write_all(&input);
    })
}

/// How long [`run_text`] lets the binary run before failing the test.
pub const DEADLINE: Duration = Duration::from_secs(120);

/// Run the binary with `args` over `input` (stdin closed at its end) within [`DEADLINE`]:
/// stdout, stderr, exit code (-1 when killed by a signal).
pub fn run_text(args: &[&str], input: &str) -> (String, String, i32) {
    let f = run_bytes(args, input.as_bytes().to_vec(), DEADLINE);
    (f.stdout_text(), f.stderr, f.code.unwrap_or(-1))
}

/// The package's root folder (where `cargo test` runs the tests).
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Run the binary in `dir` with `args`, `stdin` as its input.
pub fn run_in(dir: &Path, args: &[&str], stdin: &[u8]) -> Output {
    let mut child = spawn_piped(args, Some(dir));
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

/// VmHWM of process `pid` in KiB (None once it has exited or on non-Linux systems).
pub fn vm_hwm_kib(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()
}

/// Output lines grouped by the instance they belong to (the value of their `tag` tag; "" without
/// it), each instance's lines in output order.
pub fn per_instance(out: &str, tag: &str) -> std::collections::BTreeMap<String, Vec<String>> {
    let prefix = format!("{tag}=");
    let mut m = std::collections::BTreeMap::<String, Vec<String>>::new();
    for l in out.lines() {
        let value = l
            .split([',', ' '])
            .find_map(|p| p.strip_prefix(prefix.as_str()))
            .unwrap_or("")
            .to_string();
        m.entry(value).or_default().push(l.to_string());
    }
    m
}
