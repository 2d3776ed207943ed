//! `run --state FILE` against the real binary: stopped mid-run (SIGTERM, SIGINT or stdin EOF)
//! and restarted, the outputs equal those of one uninterrupted run (bundled robot monitors over
//! the recorded run; a spec with `last`, `delay` and `count` per robot with `--instance-by`);
//! a missing file starts fresh; a corrupt file, one of an older format version and one written
//! for other options are set aside with a warning and the run goes on; a restart with an
//! edited spec keeps every stream whose definition is unchanged, exactly as a SIGHUP reload.

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
///
/// Time moves only with the records (`--allowed-lateness off`): by the wall clock, a pause of
/// the busy machine before EOF or a signal would be silence, and would fire a run's last armed
/// delays in one run and not in the other (both are right; they are not the same run).
fn check_restarts(args: &[&str], lines: &[String], cuts: &[usize], how: &str) {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state.json");
    let mut args: Vec<&str> = args.to_vec();
    args.extend(["--allowed-lateness", "off"]);
    let (whole, err, code) = run_all(&args, &lines.concat());
    assert_eq!(code, 0, "{err}");
    let mut with_state: Vec<&str> = args.clone();
    with_state.extend(["--state", s(&state)]);
    let mut got = String::new();
    let mut start = 0;
    for (i, &cut) in cuts.iter().chain([&lines.len()]).enumerate() {
        let (out, err) = run_then_stop(&with_state, &lines[start..cut], how);
        if i == 0 {
            assert!(err.contains("does not exist yet; starting fresh"), "{err}");
        } else {
            assert!(err.contains("I! state: restored"), "{err}");
            // The same spec: nothing to say about streams starting afresh.
            assert!(!err.contains("saved by another program"), "{err}");
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
    assert_eq!(v["version"], 3);
    assert_eq!(v["instances"].as_array().unwrap().len(), 2);
    // The program the instances ran: its fingerprint and the key of every evaluated stream.
    let programs = v["programs"].as_array().unwrap();
    assert_eq!(programs.len(), 1);
    assert_eq!(programs[0]["fingerprint"].as_str().unwrap().len(), 16);
    let keys: Vec<u64> = programs[0]["keys"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k.as_u64().unwrap())
        .collect();
    assert!(
        keys.len() > 5 && keys.windows(2).all(|w| w[0] < w[1]),
        "{keys:?}"
    );
    for i in v["instances"].as_array().unwrap() {
        assert_eq!(i["program"], 0);
        for n in i["monitor"]["nodes"].as_array().unwrap() {
            assert!(keys.contains(&n["key"].as_u64().unwrap()), "{n}");
        }
    }
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

/// A file written in the previous format version (2) is refused, named with both versions,
/// and set aside; the run starts fresh.
#[test]
fn a_state_file_of_format_version_2_is_set_aside() {
    let dir = tempfile::tempdir().unwrap();
    let spec = write_spec(dir.path(), "spec.tessla", SPEC);
    let state = dir.path().join("state.json");
    // As version 2 wrote it: the fingerprint covered the spec, no program keys.
    let v2 = br#"{"magic":"tessla-telegraf-state","version":2,"fingerprint":"ec999a2360860b6b","written":1795398451,"instances":[{"key":["a"],"monitor":{"t0":102,"pending":null,"last_evaluated":102,"nodes":[{"key":6171799819722928710,"last":{"Int":0}}]}}]}
"#;
    std::fs::write(&state, v2).unwrap();
    let args = [
        "--spec",
        s(&spec),
        "--instance-by",
        "robot",
        "--threads",
        "1",
    ];
    let input = robot_events()[..12].concat();
    let (fresh, _, _) = run_all(&args, &input);
    let mut with_state = args.to_vec();
    with_state.extend(["--state", s(&state)]);
    let (out, err, code) = run_all(&with_state, &input);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains(&format!(
            "W! state: {} not used: written in state format version 2, this build reads version 3; renamed to",
            s(&state)
        )),
        "{err}"
    );
    assert!(err.contains("starting fresh"), "{err}");
    assert_eq!(out, fresh);
    let aside = rejected_files(dir.path());
    assert_eq!(aside.len(), 1, "{aside:?}");
    assert_eq!(std::fs::read(&aside[0]).unwrap(), v2);
}

/// Other --instance-by tags or another --base-time change what every saved value means: the
/// file is set aside with a warning and the run starts fresh.
#[test]
fn a_state_file_of_other_options_is_set_aside_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let spec = write_spec(dir.path(), "spec.tessla", SPEC);
    let state = dir.path().join("state.json");
    let input = robot_events()[..12].concat();
    let args = [
        "--spec",
        s(&spec),
        "--instance-by",
        "robot",
        "--threads",
        "1",
    ];
    let mut with_state = args.to_vec();
    with_state.extend(["--state", s(&state)]);
    let (fresh, _, _) = run_all(&args, &input);
    for (n, other) in [["--instance-by", "host"], ["--base-time", "1 us"]]
        .iter()
        .enumerate()
    {
        // A good file of this spec and these options...
        let (_, err, code) = run_all(&with_state, &input);
        assert_eq!(code, 0, "{err}");
        assert!(err.contains("I! state: saved 2"), "{err}");
        // ...refused by a run with another option.
        let mut changed = with_state.clone();
        changed.extend(other);
        let (out, err, code) = run_all(&changed, &input);
        assert_eq!(code, 0, "{err}");
        assert!(err.contains("W! state:"), "{err}");
        assert!(
            err.contains("written for other options")
                && err.contains("--set, --base-time and --instance-by must match"),
            "{err}"
        );
        assert!(!err.contains("I! state: restored"), "{err}");
        if other[0] == "--base-time" {
            assert_eq!(out, fresh);
        }
        assert_eq!(rejected_files(dir.path()).len(), n + 1);
        std::fs::remove_file(&state).unwrap();
    }
}

/// [`SPEC`] with `sum`'s definition changed (`2 * x` instead of `x`); `c`, `prev`, `quietAt`
/// and `silences` are unchanged.
const SPEC_EDITED: &str = "in x: Events[Int]\n\
    def c = count(x)\n\
    def prev = last(x, x)\n\
    def quiet = delay(const(5, x), x)\n\
    def quietAt = time(quiet)\n\
    def silences = count(quiet)\n\
    def sum: Events[Int] = default(last(sum, x), 0) + 2 * x\n\
    out c\nout prev\nout quietAt\nout silences\nout sum\n";

/// An output line: its robot, timestamp and fields.
fn fields(line: &str) -> (String, String, std::collections::BTreeMap<String, String>) {
    let mut parts = line.split(' ');
    let head = parts.next().unwrap();
    let body = parts.next().unwrap();
    let ts = parts.next().unwrap().to_string();
    let robot = head
        .split(',')
        .find_map(|t| t.strip_prefix("robot="))
        .unwrap()
        .to_string();
    let fields = body
        .split(',')
        .map(|f| {
            let (k, v) = f.split_once('=').unwrap();
            (k.to_string(), v.to_string())
        })
        .collect();
    (robot, ts, fields)
}

/// A restart with an edited spec (Telegraf restarted after the spec file changed): each
/// stream whose definition is unchanged continues exactly as in one uninterrupted run, the
/// changed output starts afresh (as a fresh run of the new spec), one line names it, and the
/// outputs are exactly those of a SIGHUP reload at the same point.
#[test]
fn a_restart_with_an_edited_spec_keeps_every_unchanged_stream() {
    let dir = tempfile::tempdir().unwrap();
    let spec = write_spec(dir.path(), "spec.tessla", SPEC);
    let state = dir.path().join("state.json");
    // Time moves with the records only, so a pause between the parts fires nothing.
    let args = [
        "--spec",
        s(&spec),
        "--instance-by",
        "robot",
        "--no-passthrough",
        "--allowed-lateness",
        "off",
        "--threads",
        "1",
    ];
    let lines = robot_events();
    let cut = 31;
    let (whole, err, code) = run_all(&args, &lines.concat());
    assert_eq!(code, 0, "{err}");
    let edited = write_spec(dir.path(), "edited.tessla", SPEC_EDITED);
    let mut fresh_args = args.to_vec();
    fresh_args[1] = s(&edited);
    let (fresh, err, code) = run_all(&fresh_args, &lines[cut..].concat());
    assert_eq!(code, 0, "{err}");

    // The restart: the first part with the spec, the rest after the spec file was edited.
    let mut with_state = args.to_vec();
    with_state.extend(["--state", s(&state)]);
    let (first, err, code) = run_all(&with_state, &lines[..cut].concat());
    assert_eq!(code, 0, "{err}");
    std::fs::write(&spec, SPEC_EDITED).unwrap();
    let (second, err, code) = run_all(&with_state, &lines[cut..].concat());
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("I! state: restored 2 monitor instances"),
        "{err}"
    );
    let notes: Vec<&str> = err
        .lines()
        .filter(|l| l.contains("holds state saved by another program"))
        .collect();
    assert_eq!(notes.len(), 1, "one line per restore:\n{err}");
    let note = notes[0];
    assert!(
        note.starts_with(&format!(
            "I! state: {} holds state saved by another program",
            s(&state)
        )),
        "{note}"
    );
    assert!(note.contains("reset: outputs sum, "), "{note}");
    for kept in ["c", "prev", "quietAt", "silences"] {
        assert!(!note.contains(&format!(" {kept},")), "{note}");
    }
    assert!(rejected_files(dir.path()).is_empty());

    // Per robot: the unchanged outputs are the uninterrupted run's, line for line; `sum` after
    // the restart is the fresh run's.
    let got = by_instance(&(first.clone() + &second));
    let whole = by_instance(&whole);
    let fresh = by_instance(&fresh);
    let first = by_instance(&first);
    assert_eq!(got.keys().collect::<Vec<_>>(), ["a", "b"]);
    for (robot, lines) in &got {
        let expected = &whole[robot];
        assert_eq!(lines.len(), expected.len(), "{robot}");
        let before = first[robot].len();
        assert_eq!(lines[..before], expected[..before], "{robot}");
        let mut sums = Vec::new();
        for (line, other) in lines.iter().zip(expected).skip(before) {
            let (_, ts, mut got) = fields(line);
            let (_, want_ts, mut want) = fields(other);
            assert_eq!(ts, want_ts, "{line} / {other}");
            if let Some(sum) = got.remove("sum") {
                sums.push(format!("{sum} {ts}"));
            }
            want.remove("sum");
            assert_eq!(got, want, "{line} / {other}");
        }
        let fresh_sums: Vec<String> = fresh[robot]
            .iter()
            .filter_map(|l| {
                let (_, ts, f) = fields(l);
                Some(format!("{} {ts}", f.get("sum")?))
            })
            .collect();
        assert!(!sums.is_empty());
        assert_eq!(sums, fresh_sums, "{robot}: `sum` starts afresh");
    }

    // A SIGHUP at the same point gives exactly these outputs.
    let hup_spec = write_spec(dir.path(), "hup.tessla", SPEC);
    let mut hup_args = args.to_vec();
    hup_args[1] = s(&hup_spec);
    let mut c = LiveChild::spawn(&hup_args);
    c.write(&lines[..cut].concat());
    let mut last = lines[cut - 1].trim_end().split(' ');
    let robot = last.next().unwrap().strip_prefix("m,robot=").unwrap();
    let last_ts = last.nth(1).unwrap();
    let prefix = format!("tessla,robot={robot} c=");
    let suffix = format!(" {last_ts}\n");
    c.wait_out("the last record's outputs", |l| {
        l.starts_with(&prefix) && l.ends_with(&suffix)
    });
    std::fs::write(&hup_spec, SPEC_EDITED).unwrap();
    let from = c.err.len();
    c.signal("HUP");
    let reload = c.wait_err("the reload", from, |l| {
        l.starts_with("I! reload: spec version")
    });
    assert!(reload.contains("reset: outputs sum, "), "{reload}");
    // The same wording as the restore's.
    assert_eq!(
        reload.split_once("instances; ").unwrap().1.trim_end(),
        note.split_once("restored by stream: ").unwrap().1
    );
    c.write(&lines[cut..].concat());
    let (hup, err, code) = c.finish();
    assert_eq!(code, 0, "{err}");
    // Besides the reload's status metric, the monitors' lines are the restart's.
    let mut hup = by_instance(&hup);
    let status = hup.remove("").unwrap_or_default();
    assert!(
        status.len() == 1 && status[0].starts_with("tessla_spec,"),
        "{status:?}"
    );
    assert_eq!(hup, got, "a restart with the edited spec is a reload");
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

/// A `--state` file in a folder that does not exist is said at start (issue 47), with what to
/// do, before any input is read: not at the end of a run whose state is then lost.
#[test]
fn a_state_folder_that_does_not_exist_stops_the_run_at_start() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("missing/robot.state");
    let out = std::process::Command::new(crate::support::BIN)
        .args(["run", "--state", s(&state)])
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{err}");
    let folder = dir.path().join("missing");
    assert!(
        err.contains(&format!(
            "E! state: --state {}: the folder {} does not exist: create it (`mkdir -p {}`",
            s(&state),
            s(&folder),
            s(&folder)
        )),
        "{err}"
    );
    assert!(!folder.exists(), "nothing is made behind the user's back");
}

/// The fleet lines (`tessla_fleet`, the fleet's actions) of an output, in order.
fn fleet_lines(out: &str) -> Vec<String> {
    out.lines()
        .filter(|l| l.starts_with("tessla_fleet") || l.starts_with("action,source=fleet"))
        .map(str::to_string)
        .collect()
}

/// The fleet lines of runs of `args` over `lines` cut at `cuts`, each ended at EOF, with
/// `--state state`, and each run's stderr; `edit(i, state)` is called before run `i`.
fn fleet_runs(
    args: &[&str],
    state: &Path,
    lines: &[String],
    cuts: &[usize],
    edit: &dyn Fn(usize, &Path),
) -> (Vec<String>, Vec<String>) {
    let mut with_state: Vec<&str> = args.to_vec();
    with_state.extend(["--state", s(state)]);
    let (mut got, mut errs) = (Vec::new(), Vec::new());
    let mut start = 0;
    for (i, &cut) in cuts.iter().chain([&lines.len()]).enumerate() {
        edit(i, state);
        let (out, err, code) = run_all(&with_state, &lines[start..cut].concat());
        assert_eq!(code, 0, "{err}");
        assert!(err.contains("I! state: saved"), "{err}");
        got.extend(fleet_lines(&out));
        errs.push(err);
        start = cut;
    }
    (got, errs)
}

/// With `--fleet-spec` in one process the state file holds the fleet level too (docs/fleet.md,
/// "Fleet state in `--state`"): the fleet example's records cut into runs with `--state` give
/// the fleet lines of one uninterrupted run, line for line (its maps, pending changes, robot
/// clocks, its monitor and its actions' `seq` go on). A state file without the fleet level
/// (earlier versions) still loads: the instances are restored and the fleet's maps rebuilt
/// from the robots' next events, which changes the fleet lines after the restart.
#[test]
fn the_fleet_level_in_one_process_survives_restarts_line_for_line() {
    let dir = tempfile::tempdir().unwrap();
    let root = crate::support::child::root();
    let robot = root.join("specs/fleet/robot.tessla");
    let fleet = root.join("specs/fleet/fleet.tessla");
    let args = [
        "--spec",
        s(&robot),
        "--instance-by",
        "topic",
        "--fleet-spec",
        s(&fleet),
        "--max-ahead",
        "off",
        "--allowed-lateness",
        "off",
        "--no-passthrough",
    ];
    let lines: Vec<String> =
        std::fs::read_to_string(root.join("tests/fixtures/fleet/three_robots.lp"))
            .unwrap()
            .lines()
            .map(|l| format!("{l}\n"))
            .collect();
    let (whole, err, code) = run_all(&args, &lines.concat());
    assert_eq!(code, 0, "{err}");
    let want = fleet_lines(&whole);
    assert!(want.len() > 40, "the fleet has outputs: {whole}");
    // Cuts between rounds and inside one (robot 1 of a round in one run, 2 and 3 in the next).
    for (k, cuts) in [&[21][..], &[7, 31, 40]].into_iter().enumerate() {
        let state = dir.path().join(format!("state-{k}.json"));
        let (got, errs) = fleet_runs(&args, &state, &lines, cuts, &|_, _| {});
        for err in errs.iter().skip(1) {
            assert!(
                err.contains("I! state: restored the fleet level (3 robots) from"),
                "{err}"
            );
        }
        assert_eq!(
            got, want,
            "cut at {cuts:?}: the fleet lines differ from one run"
        );
    }
    // An earlier version's file: the same without `"fleet"`.
    let state = dir.path().join("state-old.json");
    let drop_fleet = |i: usize, path: &Path| {
        if i == 0 {
            return;
        }
        let mut v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        assert!(
            v.as_object_mut().unwrap().remove("fleet").is_some(),
            "the state file holds the fleet level"
        );
        std::fs::write(path, serde_json::to_vec(&v).unwrap()).unwrap();
    };
    let (got, errs) = fleet_runs(&args, &state, &lines, &[21], &drop_fleet);
    assert!(
        errs[1].contains("I! state: restored 3 monitor instances"),
        "{}",
        errs[1]
    );
    assert!(!errs[1].contains("fleet level"), "{}", errs[1]);
    assert_ne!(
        got, want,
        "without the fleet level a restart rebuilds the maps"
    );
}
