//! The step watchdog (`run --step-timeout`, README "Exit codes"): a step that makes no progress
//! for the bound ends the process with exit code 4 and an `E!` line saying what was stuck, so
//! that Telegraf, which never restarts a live child, restarts it. Through the real binary: a
//! step that really runs for centuries (a recursion of 2^60 calls), a stdout nobody reads,
//! `--step-timeout 0`, and a slow but live input, which is not a stall.

use std::io::{Read, Write};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

use crate::support::{BIN, child};

/// The bound the tests give: long enough that a busy machine never stalls a step this long by
/// itself, short enough to keep the tests quick.
const BOUND: Duration = Duration::from_secs(3);
/// What the watchdog may take beyond the bound: its sampling tick (an eighth of the bound), and
/// a very busy machine.
const SLACK: Duration = Duration::from_secs(30);

/// A spec whose step for `n=60` makes 2^60 calls at recursion depth 60 (centuries), and for
/// `n=3` eight.
const ENDLESS: &str = "in n: Events[Int]\n\
    def work(k: Int): Int = if k == 0 then 1 else work(k - 1) + work(k - 1)\n\
    def r = slift1(n, (k: Int) => work(k))\n\
    out r\n";

fn spec(dir: &tempfile::TempDir) -> String {
    let path = dir.path().join("endless.tessla");
    std::fs::write(&path, ENDLESS).unwrap();
    path.display().to_string()
}

fn spawn(args: &[&str]) -> Child {
    child::spawn(&[&["run"], args].concat())
}

/// Wait for the child's exit, at most `limit`; kill it past that. Returns the exit code (None:
/// still running at the limit, then killed) and how long it ran.
fn wait_at_most(child: &mut Child, started: Instant, limit: Duration) -> (Option<i32>, Duration) {
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return (status.code(), started.elapsed());
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            return (None, started.elapsed());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn stderr_of(child: &mut Child) -> String {
    let mut err = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut err);
    }
    err
}

#[test]
fn a_step_that_never_ends_exits_with_code_4_naming_the_record_and_instance() {
    let dir = tempfile::tempdir().unwrap();
    let spec = spec(&dir);
    let bound = format!("{}s", BOUND.as_secs());
    let mut child = spawn(&[
        "--spec",
        &spec,
        "--step-timeout",
        &bound,
        "--instance-by",
        "robot",
        "--threads",
        "1",
    ]);
    let mut stdin = child.stdin.take().unwrap();
    let started = Instant::now();
    // The first record is quick; the second never ends. stdin stays open, as under Telegraf.
    stdin
        .write_all(b"m,robot=a n=3i 1\nm,robot=b n=60i 2\n")
        .unwrap();
    stdin.flush().unwrap();
    let (code, took) = wait_at_most(&mut child, started, BOUND + SLACK);
    drop(stdin);
    let err = stderr_of(&mut child);
    assert_eq!(
        code,
        Some(4),
        "exit code 4 within the bound and slack: {err}"
    );
    assert!(took >= BOUND, "not before the bound: {took:?}");
    let line = err
        .lines()
        .find(|l| l.starts_with("E! step watchdog: no progress for "))
        .unwrap_or_else(|| panic!("no watchdog line: {err}"));
    assert!(
        line.contains("(--step-timeout 3s) while stepping records"),
        "{line}"
    );
    assert!(
        line.contains("last record: line 2 (instance robot=b)"),
        "{line}"
    );
    assert!(line.contains("exiting with code 4"), "{line}");
}

#[test]
fn a_stdout_nobody_reads_exits_with_code_4() {
    // The reader of our stdout never reads (as Telegraf blocked on its own full pipe): the echo
    // of the input fills the pipe and the write blocks.
    let bound = format!("{}s", BOUND.as_secs());
    let mut child = spawn(&["--step-timeout", &bound, "--max-ahead", "off"]);
    let mut stdin = child.stdin.take().unwrap();
    let started = Instant::now();
    let writer = std::thread::spawn(move || {
        let line =
            "mqtt_consumer,topic=tessla expectedSpeed=0.1,actualSpeed=0.1 1700000000000000000\n";
        for i in 0..100_000i64 {
            let l = line.replace(
                "1700000000000000000",
                &(1_700_000_000_000_000_000 + i).to_string(),
            );
            // Fails once the child has exited.
            if stdin.write_all(l.as_bytes()).is_err() {
                return;
            }
        }
        // Keep stdin open, as Telegraf does, until the child is gone.
        std::thread::sleep(BOUND + SLACK);
    });
    let (code, took) = wait_at_most(&mut child, started, BOUND + SLACK);
    let err = stderr_of(&mut child);
    assert_eq!(code, Some(4), "{err}");
    assert!(took >= BOUND, "{took:?}");
    assert!(
        err.contains("while writing outputs to stdout (its reader is not reading)"),
        "{err}"
    );
    drop(child.stdout.take());
    drop(writer);
}

#[test]
fn step_timeout_0_disables_the_watchdog() {
    let dir = tempfile::tempdir().unwrap();
    let spec = spec(&dir);
    let mut child = spawn(&["--spec", &spec, "--step-timeout", "0"]);
    let mut stdin = child.stdin.take().unwrap();
    let started = Instant::now();
    stdin.write_all(b"m n=60i 1\n").unwrap();
    stdin.flush().unwrap();
    // Well past a bound of 1 s (the shortest the other tests give), it still runs.
    let (code, _) = wait_at_most(&mut child, started, Duration::from_secs(4));
    assert_eq!(code, None, "still running (then killed)");
    drop(stdin);
}

#[test]
fn a_slow_input_is_not_a_stall() {
    // Records every 300 ms for 3 s with a 1 s bound: waiting for input is not a step.
    let mut child = spawn(&["--step-timeout", "1s", "--no-passthrough"]);
    let mut stdin = child.stdin.take().unwrap();
    let mut out = child.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = out.read_to_string(&mut s);
        s
    });
    let now = || {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos()
    };
    for i in 0..10 {
        let line = format!(
            "mqtt_consumer,topic=tessla expectedSpeed=0.1,actualSpeed=0.{i} {}\n",
            now()
        );
        stdin.write_all(line.as_bytes()).unwrap();
        stdin.flush().unwrap();
        std::thread::sleep(Duration::from_millis(300));
    }
    drop(stdin);
    let status = child.wait().unwrap();
    let text = reader.join().unwrap();
    let err = stderr_of(&mut child);
    assert_eq!(status.code(), Some(0), "{err}");
    assert_eq!(
        text.lines().filter(|l| l.starts_with("action ")).count(),
        10,
        "{text}"
    );
    assert!(!err.contains("watchdog"), "{err}");
}

#[test]
fn the_help_and_the_man_page_name_the_option_and_the_exit_code() {
    let help = Command::new(BIN).args(["run", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(help.contains("--step-timeout <DURATION>"), "{help}");
    assert!(help.contains("[default: 10s]"), "{help}");
    let man = Command::new(BIN).arg("manpage").output().unwrap();
    let man = String::from_utf8_lossy(&man.stdout);
    assert!(
        man.contains("step\\-timeout"),
        "the man page lists the option"
    );
    assert!(
        man.contains("EXIT CODES") || man.contains("Exit codes"),
        "{man}"
    );
    assert!(man.contains("4: "), "the man page lists exit code 4");
}
