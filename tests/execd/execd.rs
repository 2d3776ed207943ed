//! The binary as Telegraf's `processors.execd` runs it: a child process on stdin/stdout.
//! Pass-through is byte-identical; outputs parse back; a bad line loses nothing else; a reply
//! arrives before the next record is written; EOF and SIGTERM flush and exit 0; the shipped
//! telegraf.conf's command runs as Telegraf would run it; UDP mode round-trips.

use crate::support::child::{run_text, spawn};
use crate::support::udp_ends;

use std::io::{BufRead, BufReader, Read, Write};
use std::process::Command;
use std::time::{Duration, Instant};

fn fixture_lines(n: usize) -> Vec<String> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/robot/recorded_run.lp");
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .take(n)
        .map(|l| format!("{l}\n"))
        .collect()
}

#[test]
fn passthrough_is_byte_identical_and_outputs_parse_back() {
    let lines = fixture_lines(20);
    let input: String = lines.concat();
    let (out, err, code) = run_text(&[], &input);
    assert_eq!(code, 0, "{err}");
    let echoed: Vec<&str> = out
        .split_inclusive('\n')
        .filter(|l| l.starts_with("mqtt_consumer"))
        .collect();
    assert_eq!(echoed, lines.iter().map(String::as_str).collect::<Vec<_>>());
    for l in out.split_inclusive('\n') {
        let m = lineproto::parse_record(l.as_bytes()).unwrap().unwrap();
        assert!(m.timestamp.is_some());
    }
    assert_eq!(out.lines().filter(|l| l.starts_with("action ")).count(), 20);
    assert!(err.contains("I! summary: 20 records"), "{err}");
}

#[test]
fn a_bad_line_costs_only_itself() {
    let lines = fixture_lines(6);
    let input = format!(
        "{}{}this is not line protocol\nm,t= f=1 5\n{}",
        lines[0],
        lines[1],
        lines[2..].concat()
    );
    let (out, err, code) = run_text(&["--no-passthrough"], &input);
    assert_eq!(code, 0);
    assert_eq!(
        out.lines().filter(|l| l.starts_with("action ")).count(),
        6,
        "{out}"
    );
    assert!(err.contains("line 3"), "the warning names the line: {err}");
    assert!(err.contains("line 4"), "{err}");
    assert!(err.contains("2 parse errors"), "{err}");
}

#[test]
fn each_record_is_answered_before_the_next_is_written() {
    let mut child = spawn(&["--no-passthrough"]);
    let mut stdin = child.stdin.take().unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    for l in fixture_lines(5) {
        stdin.write_all(l.as_bytes()).unwrap();
        stdin.flush().unwrap();
        let start = Instant::now();
        let mut got_action = false;
        while !got_action {
            let mut line = String::new();
            assert!(stdout.read_line(&mut line).unwrap() > 0, "stdout closed");
            got_action = line.starts_with("action ");
            assert!(start.elapsed() < Duration::from_secs(10), "no answer");
        }
    }
    drop(stdin);
    assert!(child.wait().unwrap().success());
}

#[test]
fn sigterm_flushes_and_exits_zero() {
    let mut child = spawn(&["--no-passthrough"]);
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(fixture_lines(1)[0].as_bytes()).unwrap();
    stdin.flush().unwrap();
    // Wait for the answer (the signal handlers are installed before input is read).
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut out = String::new();
    while !out.contains("action ") {
        assert!(stdout.read_line(&mut out).unwrap() > 0, "no answer: {out}");
    }
    let pid = child.id().to_string();
    assert!(
        Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .unwrap()
            .success()
    );
    stdout.read_to_string(&mut out).unwrap();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(0), "{err}");
    assert!(out.contains("action "), "{out}");
    assert!(err.contains("I! summary: 1 records"), "{err}");
}

#[test]
fn a_spec_error_exits_2_before_reading_input() {
    let dir = tempfile::tempdir().unwrap();
    let spec = dir.path().join("bad.tessla");
    std::fs::write(&spec, "in x: Events[Float]\ndef y = x + 1.0\nout y\n").unwrap();
    let (_, err, code) = run_text(&["--spec", spec.to_str().unwrap()], "");
    assert_eq!(code, 2);
    assert!(err.contains("bad.tessla:2:9"), "{err}");
    assert!(err.contains("+."), "the fix is named: {err}");
}

#[test]
fn shipped_conf_command_runs_as_telegraf_would() {
    let conf = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("telegraf/telegraf.conf"),
    )
    .unwrap();
    let v: toml::Value = toml::from_str(&conf).unwrap();
    let execd = &v["processors"]["execd"][0];
    let cmd: Vec<String> = execd["command"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap().to_string())
        .collect();
    assert_eq!(cmd[0], "/usr/bin/tessla-telegraf");
    assert_eq!(execd["namepass"][0].as_str(), Some("mqtt_consumer"));
    // The monitors' state is kept in the systemd drop-in's StateDirectory; here in a temp dir.
    let state = "/var/lib/tessla-telegraf/telegraf.state";
    assert!(cmd.iter().any(|a| a == state), "{cmd:?}");
    assert!(
        cmd.windows(2).any(|w| w[0] == "--state-interval"),
        "{cmd:?}"
    );
    let dir = tempfile::tempdir().unwrap();
    let here = dir.path().join("telegraf.state");
    let args: Vec<&str> = cmd[1..]
        .iter()
        .map(|a| {
            if a == state {
                here.to_str().unwrap()
            } else {
                a
            }
        })
        .collect();
    let lines = fixture_lines(6);
    let (out, err, code) = run_text(&args, &lines[..3].concat());
    assert_eq!(code, 0, "{err}");
    assert_eq!(out.lines().filter(|l| l.starts_with("action ")).count(), 3);
    assert!(here.exists(), "the state was saved: {err}");
    // A restart (Telegraf's reload) continues the monitors: the next action is the 4th.
    let (out, err, code) = run_text(&args, &lines[3..].concat());
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("state: restored 1 monitor instances"), "{err}");
    let first = out.lines().find(|l| l.starts_with("action ")).unwrap();
    assert!(first.contains(",seq=4i,"), "{first}");
    // The action metric is what outputs.mqtt's namepass selects.
    let mqtt = &v["outputs"]["mqtt"][0];
    assert_eq!(mqtt["namepass"][0].as_str(), Some("action"));
    assert_eq!(mqtt["topic"].as_str(), Some("action"));
}

#[test]
fn udp_mode_round_trips() {
    let (recv, send_to, listen) = udp_ends::open(Duration::from_millis(500));
    let mut child = spawn(&[
        "--udp-listen",
        &listen,
        "--udp-send",
        &send_to,
        "--no-passthrough",
    ]);
    let sock = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let lines = fixture_lines(2);
    // Two records and a bad line in one datagram: the bad line costs only itself. The datagram
    // is resent until answered, since the child may not be listening yet.
    let datagram = format!("{}garbage\n{}", lines[0], lines[1]);
    let mut got = String::new();
    let mut buf = vec![0u8; 65536];
    let start = Instant::now();
    while got.lines().filter(|l| l.starts_with("action ")).count() < 2 {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "no UDP answer: {got}"
        );
        if got.is_empty() {
            sock.send_to(datagram.as_bytes(), &listen).unwrap();
        }
        if let Ok(n) = recv.recv(&mut buf) {
            got.push_str(&String::from_utf8_lossy(&buf[..n]));
        }
    }
    let pid = child.id().to_string();
    Command::new("kill").args(["-TERM", &pid]).status().unwrap();
    assert_eq!(child.wait().unwrap().code(), Some(0));
}

#[test]
fn a_closed_stdout_ends_the_run_cleanly() {
    let mut child = spawn(&[]);
    drop(child.stdout.take());
    let mut stdin = child.stdin.take().unwrap();
    // Keep writing until the child notices that nobody reads its output and exits.
    for l in fixture_lines(50) {
        if stdin.write_all(l.as_bytes()).is_err() {
            break;
        }
        let _ = stdin.flush();
        std::thread::sleep(Duration::from_millis(5));
    }
    drop(stdin);
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

fn execd_fixture(name: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/execd")
        .join(name);
    std::fs::read_to_string(path).unwrap()
}

/// `tests/fixtures/execd/speed.out.lp` was checked by hand against `speed.tessla` over
/// `speed.lp`: 0.25 - 0.2 is 0.04999999999999999 in binary floating point; the second scan
/// has 3 beams (index 1 missing, NaN); the third record's tag `topic=other` binds only the
/// unannotated `mode`; the string's quotes are escaped.
#[test]
fn fixture_outputs_are_exact_and_parse_back_with_the_same_values() {
    let spec =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/execd/speed.tessla");
    let input = execd_fixture("speed.lp");
    let expected = execd_fixture("speed.out.lp");
    let spec = spec.to_str().unwrap();
    let (out, err, code) = run_text(&["--spec", spec, "--tag", "site=lab"], &input);
    assert_eq!(code, 0, "{err}");
    // Each record, byte for byte, then the outputs it causes (those of its own timestamp).
    let records: Vec<&str> = input.split_inclusive('\n').collect();
    let mut want = String::new();
    for r in &records {
        want.push_str(r);
        let ts = r.trim_end().rsplit_once(' ').unwrap().1;
        for l in expected.lines().filter(|l| l.ends_with(&format!(" {ts}"))) {
            want.push_str(l);
            want.push('\n');
        }
    }
    assert_eq!(out, want);
    // Values read back equal the ones the spec computes.
    let parsed: Vec<lineproto::Metric> = expected
        .lines()
        .map(|l| lineproto::parse_record(l.as_bytes()).unwrap().unwrap())
        .collect();
    let speed_diff = &parsed[0];
    assert_eq!(speed_diff.measurement, "speed_diff");
    assert_eq!(
        speed_diff.field("value"),
        Some(&lineproto::FieldValue::Float(0.25 - 0.2))
    );
    assert_eq!(parsed[1].tag("site"), Some("lab"));
    assert_eq!(
        parsed[4].field("late"),
        Some(&lineproto::FieldValue::Bool(true))
    );
    assert_eq!(
        parsed[6].field("mode"),
        Some(&lineproto::FieldValue::Str("say \"hi\", then go".into()))
    );
    assert!(err.contains("3 records, 8 events, 12 outputs"), "{err}");
}

#[test]
fn shipped_udp_conf_matches_the_udp_defaults() {
    let conf = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("telegraf/telegraf-udp.conf"),
    )
    .unwrap();
    let v: toml::Value = toml::from_str(&conf).unwrap();
    let writer = &v["outputs"]["socket_writer"][0];
    let listener = &v["inputs"]["socket_listener"][0];
    // Telegraf sends only robot metrics to us, so our outputs never loop back.
    assert_eq!(writer["namepass"][0].as_str(), Some("mqtt_consumer"));
    let to_us = writer["address"].as_str().unwrap();
    let from_us = listener["service_address"].as_str().unwrap();
    // Be Telegraf: receive where the conf's socket_listener listens, send where its socket_writer
    // sends; the monitor runs with its defaults (`--udp-listen` without an address).
    let recv = std::net::UdpSocket::bind(from_us.strip_prefix("udp://").unwrap()).unwrap();
    recv.set_read_timeout(Some(Duration::from_millis(300)))
        .unwrap();
    let mut child = spawn(&["run", "--udp-listen"]);
    let sock = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let line = fixture_lines(1).concat();
    let mut got = String::new();
    let mut buf = vec![0u8; 65536];
    let start = Instant::now();
    while !got.contains("action ") {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "no answer: {got}"
        );
        if got.is_empty() {
            sock.send_to(line.as_bytes(), to_us.strip_prefix("udp://").unwrap())
                .unwrap();
        }
        if let Ok(n) = recv.recv(&mut buf) {
            got.push_str(&String::from_utf8_lossy(&buf[..n]));
        }
    }
    let pid = child.id().to_string();
    Command::new("kill").args(["-TERM", &pid]).status().unwrap();
    assert_eq!(child.wait().unwrap().code(), Some(0));
}

/// A fixed-seed generator (ChaCha), so the garbage is the same on every run.
struct Rng(rand_chacha::ChaCha8Rng);
impl Rng {
    fn next(&mut self) -> u64 {
        rand::RngCore::next_u64(&mut self.0)
    }
}

#[test]
fn garbage_never_makes_it_panic() {
    let good = fixture_lines(10);
    let alphabet: &[u8] =
        b" ,=\"\\\n\t\r0123456789.eE+-_iutfTF#\x00\xff\xc3mqtt_consumer lidar_ topic";
    let mut rng = Rng(rand::SeedableRng::seed_from_u64(0x9e37_79b9));
    let mut input: Vec<u8> = Vec::new();
    for (n, g) in good.iter().enumerate() {
        // A mutated copy of a real record: bytes replaced, cut or duplicated.
        let mut bad = g.as_bytes().to_vec();
        for _ in 0..(1 + rng.next() % 8) {
            let i = (rng.next() as usize) % bad.len();
            bad[i] = alphabet[(rng.next() as usize) % alphabet.len()];
        }
        bad.truncate(1 + (rng.next() as usize) % bad.len());
        input.extend_from_slice(&bad);
        input.push(b'\n');
        // Pure noise.
        for _ in 0..(rng.next() % 200) {
            input.push(alphabet[(rng.next() as usize) % alphabet.len()]);
        }
        input.push(b'\n');
        // Absurd values: huge indices and numbers.
        input.extend_from_slice(
            format!(
                "mqtt_consumer lidar_99999999999=1,expectedSpeed=1e400,actualSpeed=\"NaN\" {n}\n"
            )
            .as_bytes(),
        );
        // A good record.
        input.extend_from_slice(g.as_bytes());
    }
    let mut child = spawn(&["--late", "drop"]);
    let mut stdin = child.stdin.take().unwrap();
    let w = std::thread::spawn(move || {
        let _ = stdin.write_all(&input);
    });
    let out = child.wait_with_output().unwrap();
    w.join().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    // Everything written parses back.
    for l in String::from_utf8_lossy(&out.stdout).lines() {
        assert!(lineproto::parse_record(l.as_bytes()).is_ok(), "{l}");
    }
    assert!(err.contains("parse error"), "{err}");
    // Every good record got through, whatever garbage came before it (an unbalanced quote
    // costs only its own line).
    let stdout = String::from_utf8_lossy(&out.stdout);
    let echoed: Vec<&str> = stdout.split_inclusive('\n').collect();
    for g in &good {
        assert!(echoed.contains(&g.as_str()), "lost: {g}");
    }
}

#[test]
/// A record or tuple output, literal (TeSSLa's object: one output per member) or a stream of
/// record values (split when written), is one field per member named by its path.
fn a_record_of_verdicts_is_one_field_per_member() {
    let dir = tempfile::tempdir().unwrap();
    let spec = dir.path().join("verdicts.tessla");
    std::fs::write(
        &spec,
        "in speed: Events[Float]\n\
         def check = {value = speed <=. 0.22, final = speed >. 1.0}\n\
         def bounds = (speed -. 0.1, speed +. 0.1)\n\
         def verdict = if speed >. 1.0 then {value = false, final = true} else {value = true, final = false}\n\
         out check\nout bounds\nout verdict\n",
    )
    .unwrap();
    let (out, err, code) = run_text(
        &["--spec", spec.to_str().unwrap(), "--no-passthrough"],
        "m speed=0.5 10\nm speed=2 20\n",
    );
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("0 dropped values"),
        "nothing is dropped: {err}"
    );
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(
        lines,
        [
            "tessla check.value=false,check.final=false,bounds._1=0.4,bounds._2=0.6,\
             verdict.final=false,verdict.value=true 10",
            "tessla check.value=false,check.final=true,bounds._1=1.9,bounds._2=2.1,\
             verdict.final=true,verdict.value=false 20",
        ]
    );
}
