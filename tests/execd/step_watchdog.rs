//! The step watchdog (`run --step-timeout`, README "Exit codes"): a step that makes no progress
//! for the bound ends the process with exit code 4 and an `E!` line saying what was stuck, so
//! that Telegraf, which never restarts a live child, restarts it. Through the real binary: a
//! step that really runs for centuries (a recursion of 2^60 calls), a stdout not read for longer
//! than the bound (backpressure: warned about and waited for, never an exit), `--step-timeout
//! 0`, and a slow but live input, which is not a stall.

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

/// Issue 46: a reader that does not read for longer than the bound (Telegraf parsing a huge
/// metric) is backpressure, not a hang: the child warns, waits, and once the reader reads again
/// every record is answered and it ends normally. Before the fix it exited with code 4 and lost
/// what was in the pipes.
#[test]
fn a_stdout_not_read_past_the_bound_is_waited_for_and_every_record_is_answered() {
    const RECORDS: i64 = 5_000;
    let bound = format!("{}s", BOUND.as_secs());
    let mut child = spawn(&["--step-timeout", &bound, "--max-ahead", "off"]);
    let mut stdin = child.stdin.take().unwrap();
    let writer = std::thread::spawn(move || {
        // About 1.2 MB of echo and outputs: far more than a pipe holds.
        for i in 0..RECORDS {
            let l = format!(
                "mqtt_consumer,topic=tessla expectedSpeed=0.1,actualSpeed=0.1 {}\n",
                1_700_000_000_000_000_000 + i
            );
            if stdin.write_all(l.as_bytes()).is_err() {
                return false;
            }
        }
        // Closing stdin is how Telegraf stops the child.
        true
    });
    // stderr line by line, so the test waits for the warning itself, not for a time.
    let err = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    let errs = std::thread::spawn(move || {
        use std::io::BufRead;
        for line in std::io::BufReader::new(err).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let mut log = Vec::new();
    let waited = Instant::now();
    while !log
        .iter()
        .any(|l: &String| l.starts_with("W! stdout: our reader has not read for"))
    {
        match rx.recv_timeout(Duration::from_millis(200)) {
            Ok(l) => log.push(l),
            Err(_) => {
                assert!(
                    child.try_wait().unwrap().is_none(),
                    "the child ended while its reader was not reading: {log:?}"
                );
                assert!(
                    waited.elapsed() < BOUND + SLACK,
                    "no warning about the blocked write: {log:?}"
                );
            }
        }
    }
    assert!(
        child.try_wait().unwrap().is_none(),
        "still running after the bound: {log:?}"
    );
    // The reader reads again: everything comes, and the child ends normally at the end of input.
    let mut out = String::new();
    child
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut out)
        .unwrap();
    let status = child.wait().unwrap();
    assert!(writer.join().unwrap(), "every record was written");
    errs.join().unwrap();
    log.extend(rx.try_iter());
    assert_eq!(status.code(), Some(0), "{log:?}");
    let count = |m: &str| out.lines().filter(|l| l.starts_with(m)).count() as i64;
    assert_eq!(
        count("mqtt_consumer,"),
        RECORDS,
        "every record passed through"
    );
    assert_eq!(count("tessla "), RECORDS, "every record answered");
    assert!(!log.iter().any(|l| l.starts_with("E! ")), "{log:?}");
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
