//! `telegraf/systemd/tessla-telegraf.conf`, the drop-in for Telegraf's systemd unit: its
//! `ExecStartPre` (run here with `/bin/sh`, as systemd would, after systemd's `$$` unescaping)
//! fails on a broken spec with the diagnostic on stderr, passes on a good one and, without
//! `TESSLA_SPEC`, checks that the binary runs; `systemd-analyze verify` accepts the unit with the
//! drop-in (a missing `systemd-analyze` fails under REQUIRE_SERVERS=1).

#[path = "support/recorded.rs"]
mod recorded;
#[path = "support/servers.rs"]
mod servers;

use recorded::BIN;
use std::path::{Path, PathBuf};
use std::process::Command;

fn dropin_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("telegraf/systemd/tessla-telegraf.conf")
}

/// The shell script of the drop-in's `ExecStartPre=/bin/sh -c '...'`, `$$` read as systemd
/// reads it, with our binary in place of `/usr/bin/tessla-telegraf`.
fn exec_start_pre() -> String {
    let text = std::fs::read_to_string(dropin_path()).unwrap();
    let line = text
        .lines()
        .find_map(|l| l.strip_prefix("ExecStartPre="))
        .expect("the drop-in has an ExecStartPre");
    let script = line
        .strip_prefix("/bin/sh -c '")
        .and_then(|s| s.strip_suffix('\''))
        .expect("ExecStartPre=/bin/sh -c '...'");
    assert!(!script.contains('\''), "one quoted word: {script}");
    assert!(
        script.contains("/usr/bin/tessla-telegraf check"),
        "{script}"
    );
    script
        .replace("$$", "$")
        .replace("/usr/bin/tessla-telegraf", BIN)
}

fn run(spec: Option<&Path>, args: &str) -> (Option<i32>, String) {
    let mut c = Command::new("/bin/sh");
    c.arg("-c").arg(exec_start_pre());
    c.env("TESSLA_CHECK_ARGS", args);
    match spec {
        Some(s) => c.env("TESSLA_SPEC", s),
        None => c.env("TESSLA_SPEC", ""),
    };
    let out = c.output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn the_dropin_fails_the_start_on_a_broken_spec() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("monitors.tessla");
    std::fs::write(&bad, "in x: Events[Int]\ndef y := x +. 1\nout y\n").unwrap();
    let (code, err) = run(Some(&bad), "");
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("monitors.tessla:2:"),
        "the place is named: {err}"
    );

    let good = Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/robot.tessla");
    let (code, err) = run(Some(&good), "");
    assert_eq!(code, Some(0), "{err}");
    // The --set arguments of the conf's command are checked too.
    let (code, err) = run(Some(&good), "--set no_such_constant=1");
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("no_such_constant"), "{err}");

    // No spec configured (the bundled monitors): the binary must run.
    let (code, err) = run(None, "");
    assert_eq!(code, Some(0), "{err}");
}

#[test]
fn systemd_accepts_the_dropin() {
    let Some(analyze) = servers::require("systemd-analyze", "systemd") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().join("telegraf.service.d");
    std::fs::create_dir(&d).unwrap();
    std::fs::copy(dropin_path(), d.join("tessla-telegraf.conf")).unwrap();
    // Telegraf's unit (scripts/telegraf.service), reduced to what verify needs to load it
    // without a Telegraf binary.
    let unit = dir.path().join("telegraf.service");
    std::fs::write(
        &unit,
        "[Unit]\nDescription=Telegraf\n[Service]\nType=notify\nNotifyAccess=all\n\
         EnvironmentFile=-/etc/default/telegraf\nExecStart=/bin/true\nKillMode=mixed\n\
         [Install]\nWantedBy=multi-user.target\n",
    )
    .unwrap();
    let out = Command::new(analyze)
        .arg("verify")
        .arg(&unit)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    let ours: Vec<&str> = err
        .lines()
        .filter(|l| l.contains("tessla-telegraf.conf") || l.contains("telegraf.service:"))
        .collect();
    assert!(ours.is_empty(), "{err}");
    assert!(out.status.success(), "{err}");
}
