//! `tessla-telegraf trace SPEC [TRACE]` as a user runs it: TeSSLa's output format on stdout,
//! errors on stderr, exit codes 0 (ok), 1 (runtime or trace error), 2 (spec error), 3 (I/O).

use crate::support::child;

use crate::support::BIN;
use child::{root, run_in, text};
use std::io::Write;
use std::process::{Command, Output, Stdio};

/// `name` with `text` in this test run's folder of specs and traces.
fn temp(name: &str, text: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("tessla-trace-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    child::write(&dir, name, text)
}

/// `tessla-telegraf trace SPEC ARGS...` with `stdin` as its input.
fn trace(spec: &str, args: &[&str], stdin: &str) -> Output {
    let all: Vec<&str> = ["trace", spec]
        .into_iter()
        .chain(args.iter().copied())
        .collect();
    run_in(&root(), &all, stdin.as_bytes())
}

#[test]
fn reads_stdin_and_prints_tessla_outputs() {
    let spec = temp("sum.tessla", "in x: Events[Int]\ndef s := x + 1\nout s\n");
    let out = trace(
        spec.to_str().unwrap(),
        &[],
        "1: x = 1\n-- comment\n4: x = 0x10\n",
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(text(&out.stdout), "1: s = 2\n4: s = 17\n");
}

#[test]
fn reads_a_trace_file() {
    let spec = temp("id.tessla", "in x: Events[String]\nout x\n");
    let input = temp("id.input", "2: x = \"a ${1 + 1}\"\n");
    let out = trace(spec.to_str().unwrap(), &[input.to_str().unwrap()], "");
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(text(&out.stdout), "2: x = a 2\n");
}

#[test]
fn a_runtime_error_keeps_earlier_outputs_and_exits_1() {
    let spec = temp("div.tessla", "in x: Events[Int]\nout 10 / x as q\n");
    let out = trace(
        spec.to_str().unwrap(),
        &[],
        "1: x = 2\n2: x = 0\n3: x = 5\n",
    );
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(text(&out.stdout), "1: q = 5\n");
    assert!(
        text(&out.stderr).contains("Division by zero (t = 2)"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn a_bad_trace_line_names_its_place_and_exits_1() {
    let spec = temp("bad.tessla", "in x: Events[Int]\nout x\n");
    // As in TeSSLa, the step still pending at the bad line (t = 2) is not evaluated.
    let out = trace(
        spec.to_str().unwrap(),
        &[],
        "1: x = 1\n2: x = 2\n3: x = \"no\"\n",
    );
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(text(&out.stdout), "1: x = 1\n");
    assert!(
        text(&out.stderr).contains("<stdin>:3: input x: \"no\" is not of type Int."),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn a_spec_error_exits_2_with_place_and_fix() {
    let spec = temp("broken.tessla", "in x\nout x\n");
    let out = trace(spec.to_str().unwrap(), &[], "");
    assert_eq!(out.status.code(), Some(2));
    let err = text(&out.stderr);
    assert!(err.contains("broken.tessla:1:5"), "{err}");
    assert!(err.contains("help: an input needs its type"), "{err}");
}

#[test]
fn a_missing_trace_file_exits_3() {
    let spec = temp("ok.tessla", "in x: Events[Int]\nout x\n");
    let out = trace(spec.to_str().unwrap(), &["/nonexistent/trace.input"], "");
    assert_eq!(out.status.code(), Some(3));
    assert!(text(&out.stderr).contains("/nonexistent/trace.input"));
}

#[test]
fn outputs_of_a_live_feed_appear_before_the_feed_ends() {
    use std::io::{BufRead, BufReader};
    let spec = temp("live.tessla", "in x: Events[Int]\nout x\n");
    let mut child = Command::new(BIN)
        .arg("trace")
        .arg(&spec)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    // Step 1 is complete once an event at t = 2 arrives; the feed then pauses.
    stdin.write_all(b"1: x = 7\n2: x = 8\n").unwrap();
    stdin.flush().unwrap();
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        let mut lines = BufReader::new(stdout).lines();
        let first = lines.next().and_then(Result::ok);
        let _ = tx.send(first);
        lines.map_while(Result::ok).collect::<Vec<_>>()
    });
    let first = rx.recv_timeout(std::time::Duration::from_secs(10));
    drop(stdin);
    let rest = reader.join().unwrap();
    let status = child.wait().unwrap();
    assert_eq!(first, Ok(Some("1: x = 7".to_string())));
    assert_eq!(rest, ["2: x = 8"]);
    assert_eq!(status.code(), Some(0));
}

#[test]
fn time_units_need_a_base_time_as_in_tessla() {
    // TeSSLa's interpreter rejects a time literal when the trace has no base time; `run` keeps
    // Telegraf's 1 ns.
    let spec = temp(
        "units.tessla",
        "in x: Events[Int]\ndef d := delay(const(2 s, x), x)\nout d\n",
    );
    let s = spec.to_str().unwrap();
    let out = trace(s, &[], "1: x = 1\n5: x = 2\n");
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(
        text(&out.stderr).contains("no base time is set"),
        "{}",
        text(&out.stderr)
    );
    let out = trace(s, &["--base-time", "1 s"], "1: x = 1\n5: x = 2\n");
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(text(&out.stdout), "3: d = ()\n");
}

#[test]
fn base_time_has_tesslas_short_name() {
    let spec = temp(
        "units_t.tessla",
        "in x: Events[Int]\ndef d := delay(const(2 s, x), x)\nout d\n",
    );
    let out = trace(
        spec.to_str().unwrap(),
        &["-t", "1 s"],
        "1: x = 1\n5: x = 2\n",
    );
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(text(&out.stdout), "3: d = ()\n");
}

#[test]
fn undeclared_inputs_are_ignored_unless_rejected() {
    let spec = temp("undeclared.tessla", "in speed: Events[Int]\nout speed\n");
    let s = spec.to_str().unwrap();
    let input = "1: speed = 1\n2: speed = 2\n3: sped = 3\n3: battery = 90\n4: speed = 4\n";
    let out = trace(s, &[], input);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(
        text(&out.stdout),
        "1: speed = 1\n2: speed = 2\n4: speed = 4\n"
    );
    for flag in ["-r", "--reject-undeclared-inputs"] {
        let out = trace(s, &[flag], input);
        // As in TeSSLa, the step pending at the error (t = 2) is not written.
        assert_eq!(out.status.code(), Some(1), "{flag}");
        assert_eq!(text(&out.stdout), "1: speed = 1\n", "{flag}");
        let err = text(&out.stderr);
        assert!(
            err.contains("<stdin>:3: Undeclared input stream sped (did you mean `speed`?)"),
            "{flag}: {err}"
        );
    }
}

#[test]
fn stop_on_stops_at_the_streams_first_event() {
    let spec = temp(
        "stop.tessla",
        "in x: Events[Int]\ndef alarm := filter(x, x > 2)\nout alarm\n",
    );
    let s = spec.to_str().unwrap();
    let input = "1: x = 1\n2: x = 3\n3: x = 5\n";
    for flag in ["-S", "--stop-on"] {
        let out = trace(s, &[flag, "alarm"], input);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
        assert_eq!(text(&out.stdout), "2: alarm = 3\n", "{flag}");
    }
    let out = trace(s, &["-S", "alarn"], input);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("did you mean `alarm`?"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn abort_at_counts_events_as_tessla_does() {
    let spec = temp("abort.tessla", "in x: Events[Int]\nout x\n");
    let s = spec.to_str().unwrap();
    let input = "1: x = 1\n-- a comment is no event\n2: x = 2\n3: x = 3\n4: x = 4\n";
    for flag in ["-a", "--abort-at"] {
        let out = trace(s, &[flag, "1"], input);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
        assert_eq!(text(&out.stdout), "1: x = 1\n2: x = 2\n", "{flag}");
    }
    let out = trace(s, &["-a", "-1"], input);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
}

#[test]
fn csv_traces_from_a_file_and_stdin() {
    let spec = temp(
        "csv.tessla",
        "in a: Events[Int]\nin b: Events[String]\nout a\nout b\n",
    );
    let s = spec.to_str().unwrap();
    let csv = "ts,a,b,c\n1,5,\"x, y\",\n2,,\"z\",7\n3,6,,\n";
    let want = "1: a = 5\n1: b = x, y\n2: b = z\n3: a = 6\n";
    let sorted = |o: &Output| {
        let mut l: Vec<String> = text(&o.stdout).lines().map(str::to_string).collect();
        l.sort();
        l.join("\n") + "\n"
    };
    let out = trace(s, &["--csv"], csv);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(sorted(&out), want);
    let file = temp("trace.csv", csv);
    let out = trace(s, &["--csv", file.to_str().unwrap()], "");
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(sorted(&out), want);
    // The undeclared column `c` is ignored, or rejected with -r.
    let out = trace(s, &["--csv", "-r"], csv);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr).contains("<stdin>:3: Undeclared input stream c"),
        "{}",
        text(&out.stderr)
    );
    let out = trace(s, &["--csv"], "1,2\n");
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out.stderr).contains("<stdin>:1: No header row found"));
}

#[test]
fn ctf_needs_a_trace_directory_with_metadata() {
    let spec = temp("ctf.tessla", "in x: Events[Int]\nout x\n");
    let s = spec.to_str().unwrap();
    let out = trace(s, &["--ctf"], "");
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("--ctf needs a trace"));
    // A directory without a `metadata` file is not a CTF trace (tests/cli/trace_ctf.rs reads real ones).
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("tessla-ctf-empty-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = trace(s, &["--ctf", dir.to_str().unwrap()], "");
    assert_eq!(out.status.code(), Some(3));
    assert!(
        text(&out.stderr).contains("metadata") && text(&out.stderr).contains("No such file"),
        "{}",
        text(&out.stderr)
    );
    let out = trace(s, &["--ctf", "--csv", dir.to_str().unwrap()], "");
    assert_eq!(out.status.code(), Some(2));
}
