//! SIGHUP against the real binary: a changed spec (or included file) replaces the running one
//! mid-run, streams whose definition did not change keep their state (a `count` keeps
//! counting) and the reset ones are named; a broken spec (or one without outputs) is reported
//! with its diagnostic and the old one keeps running; the bundled spec reloads without changing
//! anything; state saved after a reload is the new spec's.

use crate::support::live_child;
use crate::support::recorded;
use crate::support::udp_ends;

use live_child::{LiveChild, run_all};
use std::path::Path;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

const MAIN_V1: &str = "include \"lib.tessla\"\nin x: Events[Int]\ndef c = count(x)\nout c\nout m\n";
const LIB_V1: &str = "def m = x + 1\n";
const MAIN_V2: &str = "include \"lib.tessla\"\nin x: Events[Int]\ndef c = count(x)\ndef n = count(x)\nout c\nout m\nout n\n";
const LIB_V2: &str = "def m = x * 2\n";

/// Send `x = v` at `ts` and wait for the output line of that step; returns it.
fn step(c: &mut LiveChild, ts: i64, v: i64) -> String {
    step_with(c, "tessla ", ts, v)
}

/// [`step`] for output lines starting with `prefix` (`tessla,` when they carry tags).
fn step_with(c: &mut LiveChild, prefix: &str, ts: i64, v: i64) -> String {
    c.write(&format!("m x={v}i {ts}\n"));
    let suffix = format!(" {ts}\n");
    c.wait_out(&format!("for the step at {ts}"), |l| {
        l.starts_with(prefix) && l.ends_with(&suffix)
    });
    c.out
        .iter()
        .rev()
        .find(|l| l.ends_with(&suffix))
        .cloned()
        .unwrap()
}

/// SIGHUP, then the first stderr line starting with `prefix` after it.
fn hangup(c: &mut LiveChild, prefix: &str) -> String {
    let from = c.err.len();
    c.signal("HUP");
    c.wait_err(&format!("starting {prefix}"), from, |l| {
        l.starts_with(prefix)
    })
}

#[test]
fn a_changed_spec_replaces_the_old_one_and_unchanged_streams_keep_state() {
    let dir = tempfile::tempdir().unwrap();
    let main = dir.path().join("main.tessla");
    let lib = dir.path().join("lib.tessla");
    let state = dir.path().join("state.json");
    std::fs::write(&main, MAIN_V1).unwrap();
    std::fs::write(&lib, LIB_V1).unwrap();
    let args = ["--spec", s(&main), "--no-passthrough", "--state", s(&state)];
    let mut c = LiveChild::spawn(&args);
    assert_eq!(step(&mut c, 10, 1), "tessla c=1i,m=2i 10\n");
    assert_eq!(step(&mut c, 20, 2), "tessla c=2i,m=3i 20\n");
    // Only the included file changes: `m` is reset (stateless anyway), `c` keeps counting.
    std::fs::write(&lib, LIB_V2).unwrap();
    let msg = hangup(&mut c, "I! reload:");
    assert!(msg.contains("reset: outputs m"), "{msg}");
    assert!(!msg.contains("outputs c") && !msg.contains(", c,"), "{msg}");
    assert_eq!(step(&mut c, 30, 5), "tessla c=3i,m=10i 30\n");
    // A new `count` starts from zero; `c` goes on.
    std::fs::write(&main, MAIN_V2).unwrap();
    let msg = hangup(&mut c, "I! reload:");
    assert!(msg.contains("reset: outputs n"), "{msg}");
    assert!(msg.contains("keep their state"), "{msg}");
    assert_eq!(step(&mut c, 40, 1), "tessla c=4i,m=2i,n=1i 40\n");
    c.signal("TERM");
    let (_, err, code) = c.finish();
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("I! SIGHUP: reloading"), "{err}");
    // The state saved is the reloaded spec's: a restart with it continues.
    let (out, err, code) = run_all(&args, "m x=3i 50\n");
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("I! state: restored 1 monitor instances"),
        "{err}"
    );
    assert_eq!(out, "tessla c=5i,m=6i,n=2i 50\n");
}

#[test]
fn a_broken_spec_is_reported_and_the_old_one_keeps_running() {
    let dir = tempfile::tempdir().unwrap();
    let main = dir.path().join("main.tessla");
    let lib = dir.path().join("lib.tessla");
    std::fs::write(&main, MAIN_V1).unwrap();
    std::fs::write(&lib, LIB_V1).unwrap();
    let mut c = LiveChild::spawn(&["--spec", s(&main), "--no-passthrough"]);
    assert_eq!(step(&mut c, 10, 1), "tessla c=1i,m=2i 10\n");
    // A syntax error in the included file, then a type error in the main file.
    std::fs::write(&lib, "def m = x +\n").unwrap();
    let from = c.err.len();
    let msg = hangup(&mut c, "E! reload:");
    assert!(msg.contains("the running spec stays in use"), "{msg}");
    let diag = c.wait_err("naming the file", from, |l| l.contains("lib.tessla:"));
    assert!(diag.starts_with("E! "), "{diag}");
    assert_eq!(step(&mut c, 20, 2), "tessla c=2i,m=3i 20\n");
    std::fs::write(&lib, LIB_V1).unwrap();
    std::fs::write(
        &main,
        "include \"lib.tessla\"\nin x: Events[Int]\ndef c = count(nosuch)\nout c\nout m\n",
    )
    .unwrap();
    let from = c.err.len();
    hangup(&mut c, "E! reload:");
    c.wait_err("naming the file", from, |l| l.contains("main.tessla:3"));
    assert_eq!(step(&mut c, 30, 3), "tessla c=3i,m=4i 30\n");
    // A spec that has lost its outputs would silently stop every verdict: refused too.
    std::fs::write(
        &main,
        "include \"lib.tessla\"\nin x: Events[Int]\ndef c = count(x)\n",
    )
    .unwrap();
    let msg = hangup(&mut c, "E! reload:");
    assert!(msg.contains("has no outputs"), "{msg}");
    assert!(msg.contains("the running spec stays in use"), "{msg}");
    assert_eq!(step(&mut c, 35, 3), "tessla c=4i,m=4i 35\n");
    // Fixed: the next reload takes it.
    std::fs::write(&main, MAIN_V1).unwrap();
    let msg = hangup(&mut c, "I! reload:");
    assert!(msg.contains("nothing changed"), "{msg}");
    assert_eq!(step(&mut c, 40, 4), "tessla c=5i,m=5i 40\n");
    let (_, err, code) = c.finish();
    assert_eq!(code, 0, "{err}");
}

#[test]
fn the_bundled_spec_reloads_without_changing_anything() {
    let lines: Vec<String> = std::fs::read_to_string(recorded::recorded_run_path())
        .unwrap()
        .lines()
        .map(|l| format!("{l}\n"))
        .collect();
    let (whole, err, code) = run_all(&[], &lines.concat());
    assert_eq!(code, 0, "{err}");
    let mut c = LiveChild::spawn(&[]);
    let (first, rest) = lines.split_at(120);
    c.write(&first.concat());
    let last = first.last().unwrap().clone();
    c.wait_out("echoing the last record", |l| l == last);
    let msg = hangup(&mut c, "I! reload:");
    assert!(msg.contains("nothing changed"), "{msg}");
    c.write(&rest.concat());
    let (out, err, code) = c.finish();
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("I! SIGHUP: reloading the bundled robot monitors"),
        "{err}"
    );
    // The reload's status metric, then exactly the uninterrupted run's lines.
    let (status, rest): (Vec<&str>, Vec<&str>) =
        out.lines().partition(|l| l.starts_with("tessla_spec,"));
    assert_eq!(status.len(), 1, "{out}");
    assert!(status[0].contains(",outcome=accepted,"), "{}", status[0]);
    let rest: String = rest.iter().map(|l| format!("{l}\n")).collect();
    assert_eq!(rest, whole);
}

#[test]
fn udp_mode_reloads_on_sighup() {
    let dir = tempfile::tempdir().unwrap();
    let main = dir.path().join("main.tessla");
    std::fs::write(dir.path().join("lib.tessla"), LIB_V1).unwrap();
    std::fs::write(&main, MAIN_V1).unwrap();
    let (recv, send_to, listen) = udp_ends::open(std::time::Duration::from_secs(30));
    let mut c = LiveChild::spawn(&[
        "--spec",
        s(&main),
        "--udp-listen",
        &listen,
        "--udp-send",
        &send_to,
        "--no-passthrough",
    ]);
    c.wait_err("udp: listening", 0, |l| l.contains("udp: listening on"));
    let sock = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut buf = vec![0u8; 65536];
    let mut ask = |datagram: &str| {
        sock.send_to(datagram.as_bytes(), &listen).unwrap();
        let n = recv.recv(&mut buf).unwrap();
        String::from_utf8_lossy(&buf[..n]).into_owned()
    };
    assert_eq!(ask("m x=1i 10\n"), "tessla c=1i,m=2i 10\n");
    std::fs::write(&main, MAIN_V2).unwrap();
    let msg = hangup(&mut c, "I! reload:");
    assert!(msg.contains("reset: outputs n"), "{msg}");
    // The reload's status metric comes as a datagram of its own, naming the reset output.
    let mut status_buf = vec![0u8; 65536];
    let n = recv.recv(&mut status_buf).unwrap();
    let status = String::from_utf8_lossy(&status_buf[..n]).into_owned();
    assert!(status.starts_with("tessla_spec,"), "{status}");
    assert!(status.contains("reset_outputs=\"n\""), "{status}");
    assert_eq!(ask("m x=1i 20\n"), "tessla c=2i,m=2i,n=1i 20\n");
    c.signal("TERM");
    let (_, err, code) = c.finish();
    assert_eq!(code, 0, "{err}");
}

/// With `--threads 2` the instances live in two threads: a reload reaches every one of them.
#[test]
fn a_reload_reaches_every_thread() {
    let dir = tempfile::tempdir().unwrap();
    let main = dir.path().join("main.tessla");
    let lib = dir.path().join("lib.tessla");
    std::fs::write(&main, MAIN_V1).unwrap();
    std::fs::write(&lib, LIB_V1).unwrap();
    let args = [
        "--spec",
        s(&main),
        "--no-passthrough",
        "--instance-by",
        "robot",
        "--threads",
        "2",
    ];
    let mut c = LiveChild::spawn(&args);
    let robots = 8;
    for r in 0..robots {
        c.write(&format!("m,robot=r{r} x=1i 10\n"));
    }
    for r in 0..robots {
        let want = format!("tessla,robot=r{r} c=1i,m=2i 10\n");
        c.wait_out(&format!("robot r{r} at 10"), |l| l == want);
    }
    std::fs::write(&lib, LIB_V2).unwrap();
    hangup(&mut c, "I! reload:");
    for r in 0..robots {
        c.write(&format!("m,robot=r{r} x=3i 20\n"));
    }
    for r in 0..robots {
        // The count kept its state; `m` is the new definition in every thread.
        let want = format!("tessla,robot=r{r} c=2i,m=6i 20\n");
        c.wait_out(&format!("robot r{r} at 20 under the new spec"), |l| {
            l == want
        });
    }
    let (_, err, code) = c.finish();
    assert_eq!(code, 0, "{err}");
}

/// The id `--version-tag` puts on a line (`spec_version=ID`).
fn version_of(line: &str) -> String {
    let tags = line.split(' ').next().unwrap();
    tags.split(',')
        .find_map(|t| t.strip_prefix("spec_version="))
        .unwrap_or_else(|| panic!("no version tag in {line}"))
        .to_string()
}

/// `--watch-spec`: an edit of an included file is reloaded without a signal; every output line
/// names the version that computed it, and each outcome is a `tessla_spec` status line (a
/// broken edit: refused, with the file and line in its reason, and the old version runs on).
#[test]
fn a_watched_spec_reloads_on_an_edit_and_outputs_name_their_version() {
    let dir = tempfile::tempdir().unwrap();
    let main = dir.path().join("main.tessla");
    let lib = dir.path().join("lib.tessla");
    std::fs::write(&main, MAIN_V1).unwrap();
    std::fs::write(&lib, LIB_V1).unwrap();
    let mut c = LiveChild::spawn(&[
        "--spec",
        s(&main),
        "--no-passthrough",
        "--watch-spec",
        "--version-tag",
        "spec_version",
    ]);
    let step_v = |c: &mut LiveChild, ts: i64, v: i64| step_with(c, "tessla,", ts, v);
    let first = step_v(&mut c, 10, 1);
    assert!(first.ends_with(" c=1i,m=2i 10\n"), "{first}");
    let v1 = version_of(&first);
    assert_eq!(v1.len(), 12, "{first}");
    // The watcher looks every second; keep the modification time visibly different.
    std::thread::sleep(std::time::Duration::from_millis(1100));
    let from = c.err.len();
    std::fs::write(&lib, LIB_V2).unwrap();
    let msg = c.wait_err("the watched reload", from, |l| l.starts_with("I! reload:"));
    assert!(msg.contains("reset: outputs m"), "{msg}");
    c.wait_out("the status line", |l| {
        l.starts_with("tessla_spec,") && l.contains(",outcome=accepted,")
    });
    let second = step_v(&mut c, 20, 5);
    assert!(second.ends_with(" c=2i,m=10i 20\n"), "{second}");
    let v2 = version_of(&second);
    assert_ne!(v1, v2);
    let status = c
        .out
        .iter()
        .find(|l| l.starts_with("tessla_spec,"))
        .unwrap();
    assert!(status.contains(&format!(",version={v2}")), "{status}");
    // A broken edit: refused everywhere it is looked at, the running version stays.
    std::thread::sleep(std::time::Duration::from_millis(1100));
    let from = c.err.len();
    std::fs::write(&lib, "def m = x +\n").unwrap();
    c.wait_err("the refusal", from, |l| l.starts_with("E! reload:"));
    c.wait_out("the refusal's status line", |l| {
        l.starts_with("tessla_spec,") && l.contains(",outcome=refused,")
    });
    let refused = c
        .out
        .iter()
        .find(|l| l.contains(",outcome=refused,"))
        .unwrap();
    assert!(refused.contains("lib.tessla"), "{refused}");
    let third = step_v(&mut c, 30, 1);
    assert_eq!(version_of(&third), v2);
    assert!(third.ends_with(" c=3i,m=2i 30\n"), "{third}");
    let (_, err, code) = c.finish();
    assert_eq!(code, 0, "{err}");
}
