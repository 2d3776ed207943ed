//! `run --state FILE` against the real binary: stopped mid-run (SIGTERM, SIGINT or stdin EOF)
//! and restarted, the outputs equal those of one uninterrupted run (bundled robot monitors over
//! the recorded run; a spec with `last`, `delay` and `count` per robot with `--instance-by`);
//! a missing file starts fresh; a corrupt file and one written for another spec are set aside
//! with a warning and the run goes on.

use crate::support::live_child;
use crate::support::recorded;
use crate::support::udp_ends;

use live_child::{LiveChild, run_all};
use std::path::{Path, PathBuf};

fn robot_lines() -> Vec<String> {
    std::fs::read_to_string(recorded::recorded_run_path())
        .unwrap()
        .lines()
        .map(|l| format!("{l}\n"))
        .collect()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Feed `lines` to a child started with `args`, wait until the last one is echoed (processed),
/// then stop it with `how` (`TERM`, `INT` or `EOF`). Returns stdout, stderr.
fn run_then_stop(args: &[&str], lines: &[String], how: &str) -> (String, String) {
    let mut c = LiveChild::spawn(args);
    c.write(&lines.concat());
    if how != "EOF" {
        let last = lines.last().unwrap().clone();
        c.wait_out("echoing the last record", |l| l == last);
        c.signal(how);
    }
    let (out, err, code) = c.finish();
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("I! state: saved"), "{err}");
    (out, err)
}

/// The outputs of one uninterrupted run and of runs stopped after each cut, with --state.
fn check_restarts(args: &[&str], lines: &[String], cuts: &[usize], how: &str) {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state.json");
    let (whole, err, code) = run_all(args, &lines.concat());
    assert_eq!(code, 0, "{err}");
    let mut with_state: Vec<&str> = args.to_vec();
    with_state.extend(["--state", s(&state)]);
    let mut got = String::new();
    let mut start = 0;
    for (i, &cut) in cuts.iter().chain([&lines.len()]).enumerate() {
        let (out, err) = run_then_stop(&with_state, &lines[start..cut], how);
        if i == 0 {
            assert!(err.contains("does not exist yet; starting fresh"), "{err}");
        } else {
            assert!(err.contains("I! state: restored"), "{err}");
        }
        got.push_str(&out);
        start = cut;
    }
    assert_eq!(
        by_instance(&got),
        by_instance(&whole),
        "restarted runs differ from one run"
    );
    assert!(whole.lines().count() > lines.len(), "the run has outputs");
}

/// The lines of each instance (by their `robot` tag) in order. Across instances the order
/// depends on when reads end (an instance's open step is evaluated at the end of a read), so
/// only each instance's own sequence is the same in any run.
fn by_instance(text: &str) -> std::collections::BTreeMap<String, Vec<String>> {
    let mut m = std::collections::BTreeMap::<String, Vec<String>>::new();
    for l in text.lines() {
        let robot = l
            .split(' ')
            .next()
            .and_then(|head| head.split(',').find_map(|t| t.strip_prefix("robot=")))
            .unwrap_or("")
            .to_string();
        m.entry(robot).or_default().push(l.to_string());
    }
    m
}

#[test]
fn robot_monitors_restarted_by_sigterm_continue_as_one_run() {
    check_restarts(&[], &robot_lines(), &[97, 150, 151], "TERM");
}

#[test]
fn robot_monitors_restarted_at_eof_continue_as_one_run() {
    check_restarts(&["--no-passthrough"], &robot_lines(), &[120], "EOF");
}

const SPEC: &str = "in x: Events[Int]\n\
    def c = count(x)\n\
    def prev = last(x, x)\n\
    def quiet = delay(const(5, x), x)\n\
    def quietAt = time(quiet)\n\
    def silences = count(quiet)\n\
    def sum: Events[Int] = default(last(sum, x), 0) + x\n\
    out c\nout prev\nout quietAt\nout silences\nout sum\n";

fn write_spec(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Two robots, gaps long enough for `quiet` (5 ns without `x`) to fire now and then.
fn robot_events() -> Vec<String> {
    let mut lines = Vec::new();
    let mut t = 100i64;
    for i in 0..60i64 {
        t += if i % 7 == 3 { 9 } else { 2 };
        let robot = if i % 3 == 0 { "b" } else { "a" };
        lines.push(format!("m,robot={robot} x={}i {t}\n", (i * i) % 11));
    }
    lines
}

#[test]
fn last_delay_and_count_per_robot_survive_restarts() {
    let dir = tempfile::tempdir().unwrap();
    let spec = write_spec(dir.path(), "spec.tessla", SPEC);
    let args = ["--spec", s(&spec), "--instance-by", "robot"];
    let lines = robot_events();
    check_restarts(&args, &lines, &[10, 11, 29, 45], "TERM");
    check_restarts(&args, &lines, &[20], "INT");
    check_restarts(&args, &lines, &[33], "EOF");
}

/// Enough robots that the save encodes them on several threads (512 and more per thread).
#[test]
fn thousands_of_robots_saved_in_parallel_continue_as_one_run() {
    let dir = tempfile::tempdir().unwrap();
    let spec = write_spec(dir.path(), "spec.tessla", SPEC);
    let args = [
        "--spec",
        s(&spec),
        "--instance-by",
        "robot",
        "--no-passthrough",
    ];
    let mut lines = Vec::new();
    for round in 0..4i64 {
        for r in 0..3000 {
            let t = 100 + round * 7 + (r % 3);
            lines.push(format!("m,robot=r{r} x={}i {t}\n", (r + round) % 11));
        }
    }
    check_restarts(&args, &lines, &[6000], "EOF");
}

/// Telegraf closes stdin, then sends SIGTERM 5 s later: a SIGTERM that arrives while the save
/// at EOF runs does not cut it short.
#[test]
fn a_sigterm_right_after_eof_does_not_cut_the_save() {
    let dir = tempfile::tempdir().unwrap();
    let spec = write_spec(dir.path(), "spec.tessla", SPEC);
    let state = dir.path().join("state.json");
    let args = [
        "--spec",
        s(&spec),
        "--instance-by",
        "robot",
        "--state",
        s(&state),
    ];
    let mut lines = Vec::new();
    for round in 0..2i64 {
        for r in 0..5000 {
            lines.push(format!("m,robot=r{r} x={}i {}\n", r % 11, 100 + round * 7));
        }
    }
    let mut c = LiveChild::spawn(&args);
    c.write(&lines.concat());
    let last = lines.last().unwrap().clone();
    c.wait_out("echoing the last record", |l| l == last);
    c.close_stdin();
    c.signal("TERM");
    let (_, err, code) = c.finish();
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("I! state: saved 5000 monitor instances"),
        "{err}"
    );
    let (_, err, code) = run_all(&args, "");
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("I! state: restored 5000 monitor instances"),
        "{err}"
    );
}

#[test]
fn the_state_file_is_json_with_a_versioned_header() {
    let dir = tempfile::tempdir().unwrap();
    let spec = write_spec(dir.path(), "spec.tessla", SPEC);
    let state = dir.path().join("st");
    let (_, err, code) = run_all(
        &[
            "--spec",
            s(&spec),
            "--instance-by",
            "robot",
            "--state",
            s(&state),
        ],
        &robot_events()[..5].concat(),
    );
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&state).unwrap()).unwrap();
    assert_eq!(v["magic"], "tessla-telegraf-state");
    assert_eq!(v["version"], 2);
    assert_eq!(v["instances"].as_array().unwrap().len(), 2);
    // No temporary file is left next to it.
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), 2, "{names:?}");
}

fn rejected_files(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().contains(".rejected-"))
        .collect()
}

#[test]
fn a_corrupt_state_file_is_set_aside_and_the_run_starts_fresh() {
    let dir = tempfile::tempdir().unwrap();
    let spec = write_spec(dir.path(), "spec.tessla", SPEC);
    let state = dir.path().join("state.json");
    // One thread, as --state always runs: the fresh run's order across robots is the same.
    let args = [
        "--spec",
        s(&spec),
        "--instance-by",
        "robot",
        "--threads",
        "1",
    ];
    let input = robot_events()[..20].concat();
    let (fresh, _, _) = run_all(&args, &input);
    for garbage in [
        &b"{\"magic\":\"tessla-telegraf-state\",\"vers"[..],
        b"\xff\xfe not json at all",
        b"{\"magic\":\"something-else\",\"version\":1,\"fingerprint\":\"0\"}",
        b"{\"magic\":\"tessla-telegraf-state\",\"version\":99,\"fingerprint\":\"0\"}",
    ] {
        std::fs::write(&state, garbage).unwrap();
        let mut with_state = args.to_vec();
        with_state.extend(["--state", s(&state)]);
        let (out, err, code) = run_all(&with_state, &input);
        assert_eq!(code, 0, "{err}");
        assert_eq!(out, fresh, "the run goes on as a fresh one");
        assert!(err.contains("W! state:"), "{err}");
        assert!(err.contains("renamed to"), "{err}");
        assert!(err.contains("starting fresh"), "{err}");
        let aside = rejected_files(dir.path());
        assert_eq!(aside.len(), 1, "{aside:?}");
        assert_eq!(std::fs::read(&aside[0]).unwrap(), garbage);
        std::fs::remove_file(&aside[0]).unwrap();
        // A good state file replaces it at the end of the run.
        assert!(err.contains("I! state: saved 2 monitor instances"), "{err}");
    }
}

#[test]
fn a_state_file_of_another_spec_is_set_aside_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let spec = write_spec(dir.path(), "spec.tessla", SPEC);
    let other = write_spec(
        dir.path(),
        "other.tessla",
        "in x: Events[Int]\ndef c = count(x)\nout c\n",
    );
    let state = dir.path().join("state.json");
    let input = robot_events()[..12].concat();
    let (_, err, code) = run_all(
        &[
            "--spec",
            s(&other),
            "--instance-by",
            "robot",
            "--state",
            s(&state),
        ],
        &input,
    );
    assert_eq!(code, 0, "{err}");
    let args = [
        "--spec",
        s(&spec),
        "--instance-by",
        "robot",
        "--threads",
        "1",
    ];
    let (fresh, _, _) = run_all(&args, &input);
    let mut with_state = args.to_vec();
    with_state.extend(["--state", s(&state)]);
    let (out, err, code) = run_all(&with_state, &input);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("W! state:"), "{err}");
    assert!(err.contains("another spec"), "{err}");
    assert_eq!(out, fresh);
    assert_eq!(rejected_files(dir.path()).len(), 1);
    // Other --instance-by tags or --set values are "another spec" too.
    let (_, err, _) = run_all(
        &[
            "--spec",
            s(&spec),
            "--instance-by",
            "host",
            "--state",
            s(&state),
        ],
        &input,
    );
    assert!(err.contains("another spec"), "{err}");
    assert_eq!(rejected_files(dir.path()).len(), 2);
}

/// UDP mode (the connector's wiring): send one datagram, return the answer.
fn udp_round(args: &[&str], listen: &str, recv: &std::net::UdpSocket, datagram: &str) -> String {
    let mut c = LiveChild::spawn(args);
    c.wait_err("udp: listening", 0, |l| l.contains("udp: listening on"));
    let sock = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.send_to(datagram.as_bytes(), listen).unwrap();
    let mut buf = vec![0u8; 65536];
    let n = recv.recv(&mut buf).unwrap();
    c.signal("TERM");
    let (_, err, code) = c.finish();
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("I! state: saved 1 monitor instances"), "{err}");
    String::from_utf8_lossy(&buf[..n]).into_owned()
}

#[test]
fn udp_mode_saves_and_restores_state() {
    let dir = tempfile::tempdir().unwrap();
    let spec = write_spec(
        dir.path(),
        "spec.tessla",
        "in x: Events[Int]\ndef c = count(x)\nout c\n",
    );
    let state = dir.path().join("state.json");
    let (recv, send_to, listen) = udp_ends::open(std::time::Duration::from_secs(30));
    let args = [
        "--spec",
        s(&spec),
        "--udp-listen",
        &listen,
        "--udp-send",
        &send_to,
        "--no-passthrough",
        "--state",
        s(&state),
    ];
    assert_eq!(
        udp_round(&args, &listen, &recv, "m x=1i 10\nm x=1i 20\n"),
        "tessla c=1i 10\ntessla c=2i 20\n"
    );
    assert_eq!(
        udp_round(&args, &listen, &recv, "m x=1i 30\n"),
        "tessla c=3i 30\n"
    );
}

#[test]
fn state_interval_saves_while_running_so_a_kill_loses_nothing_saved() {
    let dir = tempfile::tempdir().unwrap();
    let spec = write_spec(
        dir.path(),
        "spec.tessla",
        "in x: Events[Int]\ndef c = count(x)\nout c\n",
    );
    let state = dir.path().join("state.json");
    let args = [
        "--spec",
        s(&spec),
        "--no-passthrough",
        "--state",
        s(&state),
        "--state-interval",
        "50ms",
        "--log-level",
        "debug",
    ];
    let mut c = LiveChild::spawn(&args);
    c.write("m x=1i 10\nm x=1i 20\nm x=1i 30\n");
    c.wait_out("for the step at 30", |l| l == "tessla c=3i 30\n");
    let from = c.err.len();
    c.wait_err("a periodic save", from, |l| {
        l.starts_with("D! state: saved 1")
    });
    // No goodbye: SIGKILL, as a crash.
    c.signal("KILL");
    let (_, err, _) = c.finish();
    assert!(!err.contains("I! state: saved"), "{err}");
    let (out, err, code) = run_all(&args[..5], "m x=1i 40\n");
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("I! state: restored 1"), "{err}");
    assert_eq!(out, "tessla c=4i 40\n");
}

#[test]
fn state_interval_needs_state() {
    let (_, err, code) = run_all(&["--state-interval", "1s"], "");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--state"), "{err}");
}
