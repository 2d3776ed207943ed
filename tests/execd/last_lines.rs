//! The last lines at a normal end reach a slow reader. Telegraf's `processors.execd` closes its
//! end of our stdout pipe once the child has exited (`Cmd.Wait`), so lines still unread in the
//! pipe when we exit would be lost; at stdin's EOF (and SIGTERM) the binary waits, at most 2 s,
//! until the pipe holds no unread bytes. The reader here does as Telegraf: it reads slowly and
//! stops reading once the child has exited.

use std::io::{Read, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::support::child;

/// `n` robot records (a few hundred bytes of output each, under the pipe's 64 KiB in all).
fn records(n: usize) -> String {
    (0..n)
        .map(|i| {
            format!(
                "mqtt_consumer,topic=tessla expectedSpeed=0.1,actualSpeed=\"0.0{}\" {}\n",
                i % 10,
                1_700_000_000_000_000_000i64 + i as i64 * 200_000_000
            )
        })
        .collect()
}

/// Run with `args`, write `input` and close stdin; then read `chunk` bytes every `pause`, as
/// Telegraf does after the child's exit only until it exits. Returns (what was read before the
/// exit, exit code, time from stdin's close to the exit, stderr).
fn run_slow_reader(
    args: &[&str],
    input: &str,
    chunk: usize,
    pause: Duration,
) -> (String, Option<i32>, Duration, String) {
    let mut child = child::spawn(&[&["run"], args].concat());
    let mut stdin = child.stdin.take().unwrap();
    let mut stdout = child.stdout.take().unwrap();
    let mut stderr = child.stderr.take().unwrap();
    let err = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    stdin.write_all(input.as_bytes()).unwrap();
    // Let the child answer everything before the reader starts.
    std::thread::sleep(Duration::from_millis(500));
    drop(stdin);
    let closed = Instant::now();
    let exited = Arc::new(AtomicBool::new(false));
    let reader = std::thread::spawn({
        let exited = exited.clone();
        move || {
            let mut got = Vec::new();
            let mut buf = vec![0u8; chunk];
            // Telegraf's Cmd.Wait closes the pipe once the child has exited: no read after it.
            while !exited.load(Ordering::SeqCst) {
                match stdout.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => got.extend_from_slice(&buf[..n]),
                }
                let paused = Instant::now();
                while paused.elapsed() < pause && !exited.load(Ordering::SeqCst) {
                    std::thread::sleep(Duration::from_millis(5).min(pause));
                }
            }
            String::from_utf8_lossy(&got).into_owned()
        }
    });
    let status = child.wait().unwrap();
    let took = closed.elapsed();
    exited.store(true, Ordering::SeqCst);
    let got = reader.join().unwrap();
    (got, status.code(), took, err.join().unwrap())
}

#[test]
fn a_slow_reader_gets_every_line_written_before_the_end() {
    let input = records(40);
    // What the run writes, read at once.
    let (expected, err, code) = child::run_text(&["run", "--no-passthrough"], &input);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        expected
            .lines()
            .filter(|l| l.starts_with("action "))
            .count(),
        40
    );
    assert!(expected.len() < 60_000, "fits the pipe: {}", expected.len());
    // 1 KiB every 20 ms: about 0.5 s for the lot, all of it after stdin closed.
    let (got, code, took, err) = run_slow_reader(
        &["--no-passthrough"],
        &input,
        1024,
        Duration::from_millis(20),
    );
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(got, expected, "every line, read before the exit");
    assert!(took < Duration::from_secs(2), "{took:?}");
    assert!(!err.contains("still unread"), "{err}");
}

#[test]
fn a_reader_that_stops_reading_costs_at_most_two_seconds() {
    // The reader reads one byte, then nothing for a minute: the run ends about 2 s after stdin
    // closed, says what was left unread, and still exits 0.
    let (_, code, took, err) = run_slow_reader(
        &["--no-passthrough"],
        &records(10),
        1,
        Duration::from_secs(60),
    );
    assert_eq!(code, Some(0), "{err}");
    assert!(
        took >= Duration::from_millis(1900) && took < Duration::from_secs(20),
        "{took:?}"
    );
    assert!(
        err.contains("W! stdout: ")
            && err.contains(" bytes still unread by the reader after 2 s; exiting anyway"),
        "{err}"
    );
}

#[test]
fn output_to_a_file_is_not_waited_for() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.lp");
    let started = Instant::now();
    let out = child::command(&["run", "--no-passthrough"])
        .stdout(std::fs::File::create(&path).unwrap())
        .spawn()
        .and_then(|mut c| {
            c.stdin.take().unwrap().write_all(records(5).as_bytes())?;
            c.wait_with_output()
        })
        .unwrap();
    assert!(out.status.success());
    assert!(started.elapsed() < Duration::from_secs(2));
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(text.lines().filter(|l| l.starts_with("action ")).count(), 5);
}
