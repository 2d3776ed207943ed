//! `telegraf/systemd/tessla-telegraf.conf`, the drop-in for Telegraf's systemd unit. Its
//! `ExecStartPre` and `ExecReload` lines are run here with `/bin/sh`, as systemd runs them (after
//! systemd's `$$` unescaping, in order, stopping at the first that fails), with the environment
//! its `EnvironmentFile` gives:
//! - the check fails the start on a broken spec (`TESSLA_SPEC`) or a bad `TESSLA_SET`, with the
//!   diagnostic on stderr, and passes on a good one and on the bundled monitors;
//! - `TESSLA_CHECK_ARGS` is read as a shell reads words: an argument with spaces survives;
//! - `systemctl reload telegraf` checks first: a broken spec leaves Telegraf (a stand-in process
//!   as `$MAINPID`) without its SIGHUP, a good one sends it;
//! - the spec is named once: `run` takes `TESSLA_SPEC` and `TESSLA_SET` from the environment
//!   Telegraf's child inherits;
//! - `make install` writes the drop-in with the binary's path under its PREFIX;
//! - the Debian package reloads systemd after install and removal, and tolerates no systemd;
//! - `systemd-analyze verify` accepts the unit with the drop-in (a missing `systemd-analyze`
//!   fails under REQUIRE_SERVERS=1).

use crate::support::servers;

use crate::support::BIN;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn dropin_path() -> PathBuf {
    root().join("telegraf/systemd/tessla-telegraf.conf")
}

/// The values of `key=` lines of the drop-in, in order (an empty one resets the list).
fn values(key: &str) -> Vec<String> {
    let text = std::fs::read_to_string(dropin_path()).unwrap();
    let prefix = format!("{key}=");
    text.lines()
        .filter_map(|l| l.strip_prefix(&prefix))
        .map(str::to_string)
        .collect()
}

/// The shell script of a `/bin/sh -c '...'` command line, `$$` read as systemd reads it, with
/// our binary in place of `/usr/bin/tessla-telegraf`.
fn script(line: &str) -> String {
    let script = line
        .strip_prefix("/bin/sh -c '")
        .and_then(|s| s.strip_suffix('\''))
        .unwrap_or_else(|| panic!("/bin/sh -c '...': {line}"));
    assert!(!script.contains('\''), "one quoted word: {script}");
    assert!(script.contains("/usr/bin/tessla-telegraf run"), "{script}");
    script
        .replace("$$", "$")
        .replace("/usr/bin/tessla-telegraf", BIN)
}

fn exec_start_pre() -> String {
    let pre = values("ExecStartPre");
    assert_eq!(pre.len(), 1, "{pre:?}");
    script(&pre[0])
}

/// Run a script with the variables /etc/default/tessla-telegraf sets.
fn sh(script: &str, spec: Option<&Path>, set: &str, args: &str) -> (Option<i32>, String) {
    let mut c = Command::new("/bin/sh");
    c.arg("-c").arg(script);
    c.env_remove("TESSLA_SPEC").env_remove("TESSLA_SET");
    c.env("TESSLA_CHECK_ARGS", args);
    if !set.is_empty() {
        c.env("TESSLA_SET", set);
    }
    if let Some(s) = spec {
        c.env("TESSLA_SPEC", s);
    }
    let out = c.output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn broken_spec(dir: &tempfile::TempDir) -> PathBuf {
    let bad = dir.path().join("monitors.tessla");
    std::fs::write(&bad, "in x: Events[Int]\ndef y := x +. 1\nout y\n").unwrap();
    bad
}

#[test]
fn the_dropin_fails_the_start_on_a_broken_spec() {
    let pre = exec_start_pre();
    let dir = tempfile::tempdir().unwrap();
    let bad = broken_spec(&dir);
    let (code, err) = sh(&pre, Some(&bad), "", "");
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("monitors.tessla:2:"),
        "the place is named: {err}"
    );

    let good = root().join("specs/robot.tessla");
    let (code, err) = sh(&pre, Some(&good), "", "");
    assert_eq!(code, Some(0), "{err}");
    assert!(err.is_empty(), "a good spec passes quietly: {err}");
    // The --set assignments the monitor will get (TESSLA_SET) are checked too, and so are
    // --set arguments in TESSLA_CHECK_ARGS.
    let (code, err) = sh(&pre, Some(&good), "delta=0.05 no_such_constant=1", "");
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("no_such_constant"), "{err}");
    let (code, err) = sh(&pre, Some(&good), "", "--set no_such_constant=1");
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("no_such_constant"), "{err}");

    // No spec configured: the bundled monitors, with TESSLA_SET.
    let (code, err) = sh(&pre, None, "", "");
    assert_eq!(code, Some(0), "{err}");
    let (code, err) = sh(&pre, None, "delta=oops", "");
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("delta"), "{err}");
}

#[test]
fn check_args_are_read_as_shell_words() {
    let pre = exec_start_pre();
    let good = root().join("examples/first-spec/battery.tessla");
    // Each value with a space is one argument: split at the space, `one` would be a stray
    // argument and `'1` a bad time unit.
    let (code, err) = sh(
        &pre,
        Some(&good),
        "",
        "--tag 'site=lab one' --base-time \"1 ns\"",
    );
    assert_eq!(code, Some(0), "{err}");
    let (code, err) = sh(&pre, Some(&good), "", "--tag site=lab one");
    assert_eq!(code, Some(2), "unquoted, the space splits: {err}");
}

/// `systemctl reload telegraf`: the drop-in's ExecReload lines replace the unit's (`kill -HUP
/// $MAINPID`), run in order, and a failure stops the rest. A stand-in process plays Telegraf:
/// it must get its SIGHUP only when the spec passes.
#[test]
fn a_reload_with_a_broken_spec_is_refused_and_telegraf_keeps_running() {
    let reload = values("ExecReload");
    assert_eq!(reload.len(), 3, "{reload:?}");
    assert_eq!(reload[0], "", "the unit's own ExecReload is reset first");
    let check = script(&reload[1]);
    assert_eq!(check, exec_start_pre(), "the same check as at the start");
    assert_eq!(reload[2], "/bin/kill -HUP $MAINPID");

    let dir = tempfile::tempdir().unwrap();
    let bad = broken_spec(&dir);
    let good = root().join("specs/robot.tessla");
    for (spec, passes) in [(&bad, false), (&good, true)] {
        // With SIGHUP's default action even when this test runs with it ignored (under
        // `nohup`, which every child would inherit): `env` execs `sleep` in its own process.
        let mut telegraf = Command::new("env")
            .args(["--default-signal=HUP", "sleep", "60"])
            .stdin(Stdio::null())
            .spawn()
            .unwrap();
        let mainpid = telegraf.id().to_string();
        let (code, err) = sh(&check, Some(spec), "", "");
        if code == Some(0) {
            let status = Command::new("/bin/kill")
                .args(["-HUP", &mainpid])
                .status()
                .unwrap();
            assert!(status.success());
        }
        assert_eq!(code == Some(0), passes, "{}: {err}", spec.display());
        // The stand-in dies of SIGHUP only when the reload went through.
        let started = Instant::now();
        let mut ended = None;
        while started.elapsed() < Duration::from_secs(if passes { 30 } else { 1 }) {
            if let Some(s) = telegraf.try_wait().unwrap() {
                ended = Some(s);
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        // Not reaped yet when still running: end it (a no-op for one that died).
        let _ = telegraf.kill();
        let _ = telegraf.wait();
        if passes {
            use std::os::unix::process::ExitStatusExt;
            assert_eq!(ended.and_then(|s| s.signal()), Some(1), "SIGHUP sent");
        } else {
            assert!(ended.is_none(), "no SIGHUP after a failed check");
            assert!(err.contains("monitors.tessla:2:"), "{err}");
        }
    }
}

/// The spec is named once, in /etc/default/tessla-telegraf: Telegraf's execd child inherits
/// TESSLA_SPEC and TESSLA_SET and runs that spec with those parameters; --spec and --set on the
/// command line still win.
#[test]
fn run_takes_the_spec_and_its_parameters_from_the_environment() {
    let battery = root().join("examples/first-spec/battery.tessla");
    let input = "mqtt_consumer,topic=tessla battery=11.1 1700000000000000000\n";
    let run = |spec: Option<&Path>, set: &str, args: &[&str]| {
        let mut c = Command::new(BIN);
        c.args(["run", "--no-passthrough"]).args(args);
        c.env_remove("TESSLA_SPEC").env_remove("TESSLA_SET");
        if let Some(s) = spec {
            c.env("TESSLA_SPEC", s);
        }
        if !set.is_empty() {
            c.env("TESSLA_SET", set);
        }
        let mut child = c
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        std::io::Write::write_all(&mut child.stdin.take().unwrap(), input.as_bytes()).unwrap();
        let out = child.wait_with_output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        (
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (out, err) = run(Some(&battery), "", &[]);
    assert!(out.starts_with("battery_check low=false,"), "{out}");
    assert!(
        err.contains(&format!("I! spec from TESSLA_SPEC: {}", battery.display())),
        "{err}"
    );
    let (out, err) = run(Some(&battery), "low_voltage=11.2", &[]);
    assert!(out.starts_with("battery_check low=true,"), "{out}");
    assert!(
        err.contains("I! --set from TESSLA_SET: low_voltage=11.2"),
        "{err}"
    );
    // The command line wins over both.
    let (out, _) = run(
        Some(&battery),
        "low_voltage=11.2",
        &["--set", "low_voltage=11.0"],
    );
    assert!(out.starts_with("battery_check low=false,"), "{out}");
    let (out, _) = run(Some(&battery), "", &["--spec", "specs/robot.tessla"]);
    assert!(!out.contains("battery_check"), "{out}");
    // Empty, as an EnvironmentFile may leave it: the bundled monitors.
    let (out, err) = run(Some(Path::new("")), "", &[]);
    assert!(!out.contains("battery_check"), "{out}");
    assert!(!err.contains("TESSLA_SPEC"), "{err}");
}

/// `make install` writes the drop-in with the path it installed the binary to (PREFIX/bin), where
/// systemd finds drop-ins of units under PREFIX/lib/systemd/system; the package's copy names
/// /usr/bin (tools/deb-assets.sh copies the file as it is).
#[test]
fn make_install_points_the_dropin_at_its_binary() {
    let Some(make) = servers::require("make", "make") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(make)
        .current_dir(root())
        .args(["-s", "install-files", "PREFIX=/opt/tt"])
        .arg(format!("DESTDIR={}", dir.path().display()))
        .arg(format!("BIN={BIN}"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let installed = dir
        .path()
        .join("opt/tt/lib/systemd/system/telegraf.service.d/tessla-telegraf.conf");
    let text = std::fs::read_to_string(&installed).unwrap();
    assert!(!text.contains("/usr/bin/tessla-telegraf"), "{text}");
    assert_eq!(
        text.matches("/opt/tt/bin/tessla-telegraf run").count(),
        2,
        "the start and the reload check: {text}"
    );
    assert!(dir.path().join("opt/tt/bin/tessla-telegraf").exists());
    // Everything else is the shipped drop-in.
    let shipped = std::fs::read_to_string(dropin_path()).unwrap();
    assert_eq!(
        text,
        shipped.replace("/usr/bin/tessla-telegraf", "/opt/tt/bin/tessla-telegraf")
    );
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
    // without a Telegraf binary, with its own ExecReload (which the drop-in replaces).
    let unit = dir.path().join("telegraf.service");
    std::fs::write(
        &unit,
        "[Unit]\nDescription=Telegraf\n[Service]\nType=notify\nNotifyAccess=all\n\
         EnvironmentFile=-/etc/default/telegraf\nExecStart=/bin/true\n\
         ExecReload=/bin/kill -HUP $MAINPID\nKillMode=mixed\n\
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

/// The Debian package's maintainer scripts (`debian/postinst`, `debian/postrm`, named in
/// Cargo.toml's `[package.metadata.deb]`) reload systemd after install and removal, so the
/// drop-in takes effect or goes away, and tolerate a machine without systemd (a chroot, an
/// image build): run here with a `systemctl` that records its arguments, and with systemd's
/// run directory present or not.
#[test]
fn the_package_reloads_systemd_after_install_and_removal() {
    let cargo = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    assert!(cargo.contains("\nmaintainer-scripts = \"debian/\"\n"));
    let dir = tempfile::tempdir().unwrap();
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    let log = dir.path().join("systemctl.log");
    let run = |script: &str, arg: &str, systemd_runs: bool, systemctl_fails: bool| {
        let fake = bin.join("systemctl");
        std::fs::write(
            &fake,
            format!(
                "#!/bin/sh\necho \"$@\" >> {}\nexit {}\n",
                log.display(),
                i32::from(systemctl_fails)
            ),
        )
        .unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).unwrap();
        let run_dir = if systemd_runs {
            dir.path().display().to_string()
        } else {
            dir.path().join("absent").display().to_string()
        };
        let text = std::fs::read_to_string(root().join("debian").join(script)).unwrap();
        assert!(text.contains("[ -d /run/systemd/system ]"), "{text}");
        let text = text.replace("/run/systemd/system", &run_dir);
        let _ = std::fs::remove_file(&log);
        let out = Command::new("/bin/sh")
            .arg("-c")
            .arg(&text)
            .arg(script)
            .arg(arg)
            .env(
                "PATH",
                format!("{}:{}", bin.display(), std::env::var("PATH").unwrap()),
            )
            .output()
            .unwrap();
        let called = std::fs::read_to_string(&log).unwrap_or_default();
        (out.status.code(), called)
    };
    for (script, arg) in [
        ("postinst", "configure"),
        ("postrm", "remove"),
        ("postrm", "purge"),
    ] {
        let (code, called) = run(script, arg, true, false);
        assert_eq!(code, Some(0), "{script} {arg}");
        assert_eq!(called, "--system daemon-reload\n", "{script} {arg}");
        // A systemctl that fails (systemd not answering) does not fail the package.
        let (code, called) = run(script, arg, true, true);
        assert_eq!(code, Some(0), "{script} {arg}");
        assert_eq!(called, "--system daemon-reload\n");
        // No systemd: nothing to reload.
        let (code, called) = run(script, arg, false, false);
        assert_eq!(code, Some(0), "{script} {arg}");
        assert_eq!(called, "", "{script} {arg}");
    }
    // Not on an aborted upgrade.
    let (code, called) = run("postinst", "abort-upgrade", true, false);
    assert_eq!((code, called.as_str()), (Some(0), ""));
    // Executable, as dpkg needs them.
    use std::os::unix::fs::PermissionsExt;
    for script in ["postinst", "postrm"] {
        let mode = std::fs::metadata(root().join("debian").join(script))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o111, 0o111, "{script}");
    }
}
