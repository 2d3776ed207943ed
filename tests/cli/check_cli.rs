//! `check`'s counterparts of TeSSLa's `compile-core --list-in-streams / --list-out-streams`,
//! through the real binary.

use std::process::Command;

use crate::support::BIN;

fn check(args: &[&str], spec: &str) -> (Option<i32>, String, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("spec.tessla");
    std::fs::write(&path, spec).unwrap();
    let out = Command::new(BIN)
        .arg("check")
        .args(args)
        .arg(&path)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

const SPEC: &str = "in speed: Events[Float]\nin mode: Events[String]\n\
                    def fast = speed >. 1.0\nout fast\nout speed as v\n";

#[test]
fn list_in_and_out_streams_print_names_one_a_line() {
    assert_eq!(
        check(&["--list-in-streams"], SPEC),
        (Some(0), "speed\nmode\n".into(), String::new())
    );
    assert_eq!(
        check(&["--list-out-streams"], SPEC),
        (Some(0), "fast\nv\n".into(), String::new())
    );
    assert_eq!(
        check(&["--list-in-streams", "--list-out-streams"], SPEC).1,
        "speed\nmode\nfast\nv\n"
    );
    // A spec without outputs still lists its inputs; a broken spec is still exit 2.
    assert_eq!(
        check(&["--list-in-streams"], "in a: Events[Int]\n"),
        (Some(0), "a\n".into(), String::new())
    );
    let (code, out, err) = check(&["--list-out-streams"], "in a: Events[Int]\nout b\n");
    assert_eq!((code, out.as_str()), (Some(2), ""));
    assert!(err.contains("spec.tessla:2:5"), "{err}");
}

#[test]
fn a_base_time_of_an_unknown_unit_is_a_command_line_error() {
    let (code, out, err) = check(&["--base-time", "1foo"], SPEC);
    assert_eq!((code, out.as_str()), (Some(2), ""));
    assert!(err.contains("unknown unit in base time `1foo`"), "{err}");
}

/// `TESSLA_SET` (read by `run` and `check` without `--set`) splits at spaces outside string
/// literals: a string constant set there may hold spaces, as with `--set` on the command line.
#[test]
fn tessla_set_takes_a_string_with_spaces() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("spec.tessla");
    std::fs::write(
        &path,
        "in x: Events[Int]\ndef greeting = \"hi\"\ndef k = 1\n\
         def y = slift1(x, (v: Int) => String.concat(greeting, toString(v + k)))\nout y\n",
    )
    .unwrap();
    let mut child = Command::new(BIN)
        .args(["run", "--no-passthrough", "--spec"])
        .arg(&path)
        .env("TESSLA_SET", "greeting=\"hello \\\"big\\\" world \" k=2")
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    {
        use std::io::Write;
        let mut stdin = child.stdin.take().unwrap();
        stdin.write_all(b"m x=1i 1000\n").unwrap();
    }
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        "tessla y=\"hello \\\"big\\\" world 3\" 1000\n",
        "{err}"
    );
}

/// The `delay` trap (issue 47): a constant delay stream is one event at t = 0, so the watchdog
/// is armed once and the first message cancels it. `check` says where, and what to write; a
/// watchdog written right, and a one-shot timer reset by `()` only, are not warned about.
#[test]
fn check_warns_about_a_delay_armed_only_at_time_zero() {
    let spec = "in battery: Events[Float]\n\
                def max_silence = 2000000000\n\
                def silent = delay(max_silence, battery)\n\
                def watchdog = delay(const(max_silence, battery), battery)\n\
                def at_start = delay(const(5000000000, ()), ())\n\
                def never = delay(const(0, battery), battery)\n\
                out silent\nout watchdog\nout at_start\nout never\n";
    let (code, _, err) = check(&[], spec);
    assert_eq!(code, Some(0), "a warning, not an error: {err}");
    assert!(
        err.contains("warning: this `delay` is armed only at time 0"),
        "{err}"
    );
    assert!(err.contains("spec.tessla:3:14"), "the place: {err}");
    assert!(
        err.contains("write `delay(const(max_silence, battery), battery)`"),
        "what to write instead: {err}"
    );
    assert_eq!(
        err.matches("armed only at time 0").count(),
        1,
        "the watchdog and the timer at start are right: {err}"
    );
    assert!(
        err.contains("this `delay` waits 0 (a delay must be positive)") && err.contains(":6:"),
        "{err}"
    );
}
