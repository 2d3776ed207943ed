//! Hostile input against the real binary (`tessla-telegraf run`, the bundled robot monitors or a
//! small spec written here): each hostile line sits between valid robot records. For each case:
//! no panic, a normal exit (0) within a deadline, a warning naming the bad line's number, and the
//! verdict (`action` metric) of every valid neighbour present at its timestamp. Memory is bounded
//! where the input is large (peak RSS of the child read from /proc).

use crate::support::BIN;
use crate::support::child;
use crate::support::udp_ends;

use child::{Finished, run_bytes, run_with};
use std::io::Write;
use std::time::Duration;

const DEADLINE: Duration = Duration::from_secs(120);

/// A short valid robot record at `ts` (answered with an `action` metric at `ts`).
fn robot(ts: i64) -> String {
    format!(
        "mqtt_consumer,host=turtlebot3,topic=tessla actualAngular=0,actualSpeed=\"0.0188\",\
         expectedAngular=0,expectedSpeed=0.015,lidar_0=2.0,lidar_1=2.5 {ts}\n"
    )
}

/// Valid robot record at 1000, `bad` (line 2), valid robot record at 3000, through the bundled
/// monitors without pass-through.
fn sandwich(bad: &[u8]) -> Finished {
    let mut input = robot(1000).into_bytes();
    input.extend_from_slice(bad);
    input.extend_from_slice(robot(3000).as_bytes());
    run_bytes(&["run", "--no-passthrough"], input, DEADLINE)
}

/// The `action` line at `ts` in the output, if any.
fn action_at(f: &Finished, ts: i64) -> Option<String> {
    let suffix = format!(" {ts}");
    f.stdout_text()
        .lines()
        .find(|l| l.starts_with("action ") && l.ends_with(&suffix))
        .map(str::to_string)
}

/// Normal exit, no panic, a warning naming `line`, and the verdicts at `good` present.
fn assert_survived(f: &Finished, line: u64, good: &[i64]) {
    assert_eq!(f.code, Some(0), "exit code; stderr:\n{}", f.stderr);
    assert!(!f.stderr.contains("panicked"), "{}", f.stderr);
    let named = format!("line {line}");
    assert!(
        f.stderr
            .lines()
            .any(|l| l.starts_with("W! ") && l.contains(&named)),
        "no warning naming {named}:\n{}",
        f.stderr
    );
    for &ts in good {
        assert!(
            action_at(f, ts).is_some(),
            "no verdict at {ts}; stdout:\n{}\nstderr:\n{}",
            f.stdout_text(),
            f.stderr
        );
    }
    assert!(
        f.stderr.contains("I! summary:"),
        "no summary line: {}",
        f.stderr
    );
}

/// Every output line parses back as line protocol (no pass-through runs only).
fn assert_outputs_parse(f: &Finished) {
    for l in f.stdout.split(|&b| b == b'\n').filter(|l| !l.is_empty()) {
        let m = lineproto::parse_record(l).unwrap_or_else(|e| {
            panic!(
                "output {:?} does not parse: {e:?}",
                String::from_utf8_lossy(l)
            )
        });
        assert!(m.is_some());
    }
}

#[test]
fn a_truncated_last_line_is_reported_and_the_lines_before_it_answered() {
    let mut input = robot(1000);
    input.push_str(&robot(2000));
    input.push_str("mqtt_consumer,topic=tessla actualSpeed=\"0.0");
    let f = run_bytes(&["run", "--no-passthrough"], input.into_bytes(), DEADLINE);
    assert_survived(&f, 3, &[1000, 2000]);
    // A complete last line without its newline is a record like any other.
    let mut input = robot(1000);
    input.push_str(robot(2000).trim_end());
    let f = run_bytes(&["run", "--no-passthrough"], input.into_bytes(), DEADLINE);
    assert_eq!(f.code, Some(0), "{}", f.stderr);
    assert!(action_at(&f, 2000).is_some(), "{}", f.stdout_text());
}

#[test]
fn a_10_mb_line_costs_only_itself_and_memory_stays_bounded() {
    // A robot record whose speed string is 10 MB: parsed, the value refused with a warning.
    let mut bad = b"mqtt_consumer,topic=tessla actualSpeed=\"".to_vec();
    bad.extend(std::iter::repeat_n(b'a', 10 << 20));
    bad.extend_from_slice(b"\" 2000\n");
    let f = sandwich(&bad);
    assert_survived(&f, 2, &[1000, 3000]);
    // 10 MB of garbage without a space.
    let f = sandwich(&[b"x".repeat(10 << 20), b"\n".to_vec()].concat());
    assert_survived(&f, 2, &[1000, 3000]);
    // Past the record limit (16 MiB): cut, reported, skipped; the splitter keeps at most the limit.
    let f = sandwich(&[b"y".repeat(20 << 20), b"\n".to_vec()].concat());
    assert_survived(&f, 2, &[1000, 3000]);
    assert!(f.stderr.contains("longer than the limit"), "{}", f.stderr);
    let peak = f.peak_rss_kib.expect("VmHWM");
    assert!(peak < 256 * 1024, "peak RSS {peak} KiB for a 20 MiB line");
}

/// A line past the record limit that arrives slowly: skipping it is reading input, not silence.
/// Before, the wall clock took the pauses inside the skipped line for a silent robot, so
/// `robot_silent` fired (its 1 s max_silence passed) and the next record came in late.
#[test]
fn a_20_mib_line_arriving_over_2_s_is_input_not_silence() {
    const CHUNKS: usize = 40;
    const CHUNK: usize = (20 << 20) / CHUNKS;
    let f = run_with(&["run", "--no-passthrough"], DEADLINE, |stdin| {
        // The first record and the start of the long line in one write: no pause between them.
        let mut first = robot(1000).into_bytes();
        first.extend(std::iter::repeat_n(b'y', CHUNK));
        let _ = stdin.write_all(&first);
        let _ = stdin.flush();
        for _ in 1..CHUNKS {
            std::thread::sleep(Duration::from_millis(55));
            let _ = stdin.write_all(&[b'y'; CHUNK]);
            let _ = stdin.flush();
        }
        std::thread::sleep(Duration::from_millis(55));
        let mut last = b"\n".to_vec();
        last.extend_from_slice(robot(3000).as_bytes());
        let _ = stdin.write_all(&last);
    });
    assert_survived(&f, 2, &[1000, 3000]);
    assert!(f.stderr.contains("longer than the limit"), "{}", f.stderr);
    let out = f.stdout_text();
    assert!(
        !out.lines().any(|l| l.contains("robot_silent=true")),
        "the link counted as silent while a line was arriving:\n{out}"
    );
    assert!(f.stderr.contains(" 0 late records"), "{}", f.stderr);
}

#[test]
fn invalid_utf8_is_reported_with_its_line() {
    // In a measurement, a tag and a string field.
    for bad in [
        &b"mqtt_\xff\xfe,topic=tessla expectedSpeed=0.1 2000\n"[..],
        b"mqtt_consumer,topic=te\xc3\x28 expectedSpeed=0.1 2000\n",
        b"mqtt_consumer,topic=tessla actualSpeed=\"0.\xff1\" 2000\n",
    ] {
        let f = sandwich(bad);
        assert_survived(&f, 2, &[1000, 3000]);
        assert_outputs_parse(&f);
    }
}

#[test]
fn nul_bytes_are_reported_with_their_line() {
    for bad in [
        &b"mqtt_consumer\0,topic=tessla expectedSpeed=0.1 2000\n"[..],
        b"\0\0\0\0\n",
        b"mqtt_consumer,topic=tessla actualSpeed=\"0\x001\" 2000\n",
    ] {
        let f = sandwich(bad);
        assert_survived(&f, 2, &[1000, 3000]);
        assert_outputs_parse(&f);
    }
}

#[test]
fn a_line_with_100k_fields_is_evaluated() {
    // 100k unbound fields and a lidar scan of 100k beams: a valid record, answered.
    let mut bad = String::from("mqtt_consumer,topic=tessla expectedSpeed=0.015");
    for i in 0..100_000 {
        bad.push_str(&format!(",f{i}=1,lidar_{i}=2"));
    }
    bad.push_str(" 2000\n");
    let f = sandwich(bad.as_bytes());
    assert_eq!(f.code, Some(0), "{}", f.stderr);
    for ts in [1000, 2000, 3000] {
        assert!(action_at(&f, ts).is_some(), "no verdict at {ts}");
    }
    // A beam index past the limit is refused with a warning, not a huge list.
    let f = sandwich(b"mqtt_consumer,topic=tessla lidar_4000000000=1 2000\n");
    assert_survived(&f, 2, &[1000, 3000]);
    assert!(f.peak_rss_kib.expect("VmHWM") < 256 * 1024);
}

#[test]
fn an_unbalanced_quote_costs_only_its_own_line() {
    let f = sandwich(b"mqtt_consumer,topic=tessla actualSpeed=\"0.01 2000\n");
    assert_survived(&f, 2, &[1000, 3000]);
    // Two unbalanced quotes far apart: each costs only its own line.
    let mut input = robot(1000);
    input.push_str("m s=\"open 1500\n");
    input.push_str(&robot(2000));
    input.push_str("m s=\"again 2500\n");
    input.push_str(&robot(3000));
    let f = run_bytes(&["run", "--no-passthrough"], input.into_bytes(), DEADLINE);
    assert_survived(&f, 2, &[1000, 2000, 3000]);
    assert!(f.stderr.contains("line 4"), "{}", f.stderr);
}

#[test]
fn newlines_inside_strings_escaped_or_raw_keep_the_record_whole() {
    // An escaped newline and a raw one in a string field: valid records, answered, passed
    // through byte for byte, and the line numbers after them still count physical lines.
    let mut input = robot(1000);
    input.push_str("mqtt_consumer,topic=tessla note=\"a\\nb\",expectedSpeed=0.015 2000\n");
    input.push_str("mqtt_consumer,topic=tessla note=\"two\nlines\",expectedSpeed=0.015 2500\n");
    input.push_str("garbage\n");
    input.push_str(&robot(3000));
    let f = run_bytes(&["run"], input.clone().into_bytes(), DEADLINE);
    assert_survived(&f, 5, &[1000, 2000, 2500, 3000]);
    let out = f.stdout_text();
    assert!(out.contains("note=\"two\nlines\""), "{out}");
    assert!(out.contains("note=\"a\\nb\""), "{out}");
}

#[test]
fn integers_beyond_64_bits_are_reported() {
    for bad in [
        "mqtt_consumer,topic=tessla expectedSpeed=9223372036854775808i 2000\n",
        "mqtt_consumer,topic=tessla expectedSpeed=18446744073709551616u 2000\n",
        "mqtt_consumer,topic=tessla expectedSpeed=-9223372036854775809i 2000\n",
    ] {
        let f = sandwich(bad.as_bytes());
        assert_survived(&f, 2, &[1000, 3000]);
    }
}

#[test]
fn nan_inf_and_1e400_values_are_reported() {
    for bad in [
        "mqtt_consumer,topic=tessla expectedSpeed=NaN 2000\n",
        "mqtt_consumer,topic=tessla expectedSpeed=inf 2000\n",
        "mqtt_consumer,topic=tessla expectedSpeed=-Inf 2000\n",
        "mqtt_consumer,topic=tessla expectedSpeed=1e400 2000\n",
    ] {
        let f = sandwich(bad.as_bytes());
        assert_survived(&f, 2, &[1000, 3000]);
        assert_outputs_parse(&f);
    }
    // As strings (the robot sends actualSpeed as one) they convert, and a NaN or infinite output
    // is dropped from the verdict with a warning, never written as invalid line protocol.
    for bad in ["NaN", "inf", "1e400"] {
        let line =
            format!("mqtt_consumer,topic=tessla actualSpeed=\"{bad}\",expectedSpeed=0.015 2000\n");
        let f = sandwich(line.as_bytes());
        assert_eq!(f.code, Some(0), "{}", f.stderr);
        assert!(f.stderr.contains("field dropped"), "{bad}: {}", f.stderr);
        assert_outputs_parse(&f);
        for ts in [1000, 2000, 3000] {
            assert!(action_at(&f, ts).is_some(), "{bad}: no verdict at {ts}");
        }
    }
}

#[test]
fn timestamps_beyond_i64_are_reported() {
    for bad in [
        "mqtt_consumer,topic=tessla expectedSpeed=0.1 9223372036854775808\n",
        "mqtt_consumer,topic=tessla expectedSpeed=0.1 -9223372036854775809\n",
        "mqtt_consumer,topic=tessla expectedSpeed=0.1 99999999999999999999999\n",
    ] {
        let f = sandwich(bad.as_bytes());
        assert_survived(&f, 2, &[1000, 3000]);
    }
}

#[test]
fn a_missing_timestamp_gets_the_wall_clock_and_later_records_are_late() {
    // Without a timestamp the record is stamped with the wall clock (as Telegraf does) and
    // answered at that time; the record at 3000 after it is then late: reported with its line
    // and evaluated as a step of its own 1 ns after the wall-clock step (`--late shift`).
    let before = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as i64;
    let f = sandwich(b"mqtt_consumer,topic=tessla expectedSpeed=0.015,actualSpeed=\"0.01\"\n");
    assert_eq!(f.code, Some(0), "{}", f.stderr);
    assert!(action_at(&f, 1000).is_some());
    let stamped: Vec<i64> = f
        .stdout_text()
        .lines()
        .filter(|l| l.starts_with("action "))
        .filter_map(|l| l.rsplit(' ').next()?.parse().ok())
        .filter(|&ts| ts >= before)
        .collect();
    // The wall-clock record's action, and the late record's 1 ns after it.
    assert_eq!(stamped.len(), 2, "{}", f.stdout_text());
    assert_eq!(stamped[1], stamped[0] + 1, "{}", f.stdout_text());
    assert!(
        f.stderr.contains("line 3: timestamp 3000 is ")
            && f.stderr.contains("before its instance's last step"),
        "{}",
        f.stderr
    );
}

#[test]
fn decreasing_and_repeated_timestamps_are_reported_and_answered() {
    let mut input = robot(1000);
    input.push_str(&robot(2000));
    input.push_str(&robot(1500)); // decreasing: late, a step of its own at 2001
    input.push_str(&robot(3000));
    // Repeated timestamp, other values: a step of its own 1 ns later, every value evaluated.
    // (An exact repeat would be a redelivered message, dropped as a duplicate.)
    input.push_str(&robot(3000).replace("expectedSpeed=0.015", "expectedSpeed=0.02"));
    input.push_str(&robot(3000));
    input.push_str(&robot(4000));
    let f = run_bytes(&["run", "--no-passthrough"], input.into_bytes(), DEADLINE);
    assert_survived(&f, 3, &[1000, 2000, 2001, 3000, 3001, 4000]);
    assert!(f.stderr.contains("line 3: timestamp 1500"), "{}", f.stderr);
    assert!(!f.stderr.contains("second event"), "{}", f.stderr);
    assert!(f.stderr.contains(", 1 late records,"), "{}", f.stderr);
    assert!(f.stderr.contains(", 0 dropped values,"), "{}", f.stderr);
    // The warning names the robot by the record's measurement and tags (no --instance-by).
    assert!(
        f.stderr
            .contains("line 6 (mqtt_consumer,host=turtlebot3,topic=tessla): exact repeat"),
        "{}",
        f.stderr
    );
    assert!(f.stderr.contains(", 1 duplicates"), "{}", f.stderr);
    // --late drop: the late record's events are dropped, the rest answered.
    let mut input = robot(1000);
    input.push_str(&robot(500));
    input.push_str(&robot(3000));
    let f = run_bytes(
        &["run", "--no-passthrough", "--late", "drop"],
        input.into_bytes(),
        DEADLINE,
    );
    assert_survived(&f, 2, &[1000, 3000]);
}

#[test]
fn duplicate_field_keys_are_reported_and_the_last_wins_as_in_telegraf() {
    let spec = "in x: Events[Int]\nout x\n";
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.tessla");
    std::fs::write(&path, spec).unwrap();
    let input = b"m x=1i 1000\nm x=2i,x=3i 2000\nm x=4i 3000\n".to_vec();
    let f = run_bytes(
        &["run", "--spec", path.to_str().unwrap(), "--no-passthrough"],
        input,
        DEADLINE,
    );
    assert_eq!(f.code, Some(0), "{}", f.stderr);
    assert_eq!(
        f.stdout_text(),
        "tessla x=1i 1000\ntessla x=3i 2000\ntessla x=4i 3000\n"
    );
    assert!(
        f.stderr
            .contains("line 2 (m): 1 field value(s) overwritten"),
        "{}",
        f.stderr
    );
    // A repeated key among 100k fields (the key resolution was quadratic: minutes).
    let mut line = String::from("m x=5i");
    for i in 0..100_000 {
        line.push_str(&format!(",f{i}=1i"));
    }
    line.push_str(",x=6i 2000\n");
    let input = [
        b"m x=1i 1000\n".to_vec(),
        line.into_bytes(),
        b"m x=4i 3000\n".to_vec(),
    ]
    .concat();
    let f = run_bytes(
        &["run", "--spec", path.to_str().unwrap(), "--no-passthrough"],
        input,
        Duration::from_secs(60),
    );
    assert_eq!(
        f.stdout_text(),
        "tessla x=1i 1000\ntessla x=6i 2000\ntessla x=4i 3000\n"
    );
}

#[test]
fn a_field_of_the_wrong_type_is_reported_and_skipped() {
    for bad in [
        "mqtt_consumer,topic=tessla expectedSpeed=\"fast\" 2000\n",
        "mqtt_consumer,topic=tessla expectedSpeed=true 2000\n",
        "mqtt_consumer,topic=tessla lidar_0=\"far\",lidar_1=F 2000\n",
    ] {
        let f = sandwich(bad.as_bytes());
        if bad.contains("lidar") {
            // Beams that are not numbers become NaN (a dropout), as documented; answered.
            assert_eq!(f.code, Some(0), "{}", f.stderr);
            assert!(action_at(&f, 2000).is_some(), "{}", f.stdout_text());
        } else {
            assert_survived(&f, 2, &[1000, 3000]);
            assert!(f.stderr.contains("expectedSpeed"), "{}", f.stderr);
        }
    }
}

#[test]
fn a_million_robots_stay_within_max_instances() {
    // Distinct robot tags streamed from a writer thread, one instance per robot, at most 1000
    // kept: memory stays bounded and every eviction is counted. 200k by default (a debug build
    // takes minutes for a million on a busy machine); HOSTILE_ROBOTS=1000000 for the full run
    // (docs/book/src/reliability-record.md).
    let robots: u64 = std::env::var("HOSTILE_ROBOTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200_000);
    let f = run_with(
        &[
            "run",
            "--no-passthrough",
            "--instance-by",
            "robot",
            "--max-instances",
            "1000",
        ],
        Duration::from_secs(600),
        move |stdin| {
            let mut w = std::io::BufWriter::with_capacity(1 << 16, stdin);
            for i in 0..robots {
                let line = format!(
                    "mqtt_consumer,topic=tessla,robot=r{i} expectedSpeed=0.015,actualSpeed=\"0.02\" {}\n",
                    1000 + i
                );
                if w.write_all(line.as_bytes()).is_err() {
                    return;
                }
            }
            let _ = w.flush();
        },
    );
    assert_eq!(f.code, Some(0), "{}", f.stderr);
    let evicted = robots - 1000;
    assert!(
        f.stderr
            .contains(&format!("{robots} instances, {evicted} evicted")),
        "{}",
        f.stderr
    );
    assert!(
        f.stderr
            .contains("evicted (least recently used, --max-instances 1000)")
    );
    let peak = f.peak_rss_kib.expect("VmHWM");
    eprintln!("{robots} robots, --max-instances 1000: peak RSS {peak} KiB");
    assert!(peak < 200 * 1024, "peak RSS {peak} KiB");
    // Every robot was answered (tagged with its robot), the last one too.
    let out = f.stdout_text();
    assert_eq!(
        out.lines().filter(|l| l.starts_with("action,")).count() as u64,
        robots
    );
    assert!(out.contains(&format!("robot=r{} ", robots - 1)));
}

mod udp {
    use super::*;
    use std::net::UdpSocket;
    use std::time::Instant;

    /// The monitor in UDP mode: listening on a free port, sending to our socket.
    struct Monitor {
        child: std::process::Child,
        listen: String,
        recv: UdpSocket,
        send: UdpSocket,
    }

    impl Monitor {
        fn start() -> Monitor {
            let (recv, send_to, listen) = udp_ends::open(Duration::from_millis(200));
            let child = std::process::Command::new(BIN)
                .args([
                    "run",
                    "--udp-listen",
                    &listen,
                    "--udp-send",
                    &send_to,
                    "--no-passthrough",
                ])
                .stdin(std::process::Stdio::null())
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap();
            let send = UdpSocket::bind("127.0.0.1:0").unwrap();
            let mut m = Monitor {
                child,
                listen,
                recv,
                send,
            };
            // Ready when a probe record is answered (resent until the child listens).
            m.exchange(robot(1).as_bytes(), 1);
            m
        }

        /// Send `datagram` (resending while nothing came back) until `want` action lines came.
        fn exchange(&mut self, datagram: &[u8], want: usize) -> String {
            let mut got = String::new();
            let mut buf = vec![0u8; 65536];
            let start = Instant::now();
            let mut sent = false;
            while got.lines().filter(|l| l.starts_with("action ")).count() < want {
                assert!(
                    start.elapsed() < Duration::from_secs(30),
                    "no UDP answer: {got}"
                );
                if !sent || got.is_empty() && want == 1 && datagram.len() < 1000 {
                    self.send.send_to(datagram, &self.listen).unwrap();
                    sent = true;
                }
                if let Ok(n) = self.recv.recv(&mut buf) {
                    got.push_str(&String::from_utf8_lossy(&buf[..n]));
                }
            }
            got
        }

        /// SIGTERM; the exit code and stderr (a failed test kills the child on drop).
        fn stop(mut self) -> (Option<i32>, String) {
            let pid = self.child.id().to_string();
            std::process::Command::new("kill")
                .args(["-TERM", &pid])
                .status()
                .unwrap();
            let start = Instant::now();
            let status = loop {
                if let Some(status) = self.child.try_wait().unwrap() {
                    break status;
                }
                assert!(start.elapsed() < Duration::from_secs(30), "no exit");
                std::thread::sleep(Duration::from_millis(10));
            };
            let mut err = String::new();
            if let Some(mut e) = self.child.stderr.take() {
                let _ = std::io::Read::read_to_string(&mut e, &mut err);
            }
            (status.code(), err)
        }
    }

    impl Drop for Monitor {
        fn drop(&mut self) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }

    #[test]
    fn empty_huge_and_mixed_datagrams() {
        let mut m = Monitor::start();
        // Empty datagram: nothing to do, the monitor goes on.
        m.send.send_to(b"", &m.listen).unwrap();
        // 64 KiB - 29 bytes (the largest UDP payload over IPv4) of one garbage line.
        let huge = [b"z".repeat(65_507 - 1), b"\n".to_vec()].concat();
        m.send.send_to(&huge, &m.listen).unwrap();
        // A near-maximal datagram holding one valid record (a scan of ~6000 beams): answered.
        let mut big =
            String::from("mqtt_consumer,topic=tessla expectedSpeed=0.015,actualSpeed=\"0.02\"");
        let mut i = 0;
        while big.len() < 65_400 {
            big.push_str(&format!(",lidar_{i}=2.5"));
            i += 1;
        }
        big.push_str(" 5000\n");
        assert!(big.len() <= 65_507);
        let got = m.exchange(big.as_bytes(), 1);
        assert!(got.contains(" 5000\n"), "{got}");
        // Good, bad, good in one datagram: both good lines answered.
        let mixed = format!(
            "{}not line protocol\nmqtt_consumer,topic=tessla actualSpeed=\"x 1\n{}",
            robot(100_000),
            robot(100_001)
        );
        let got = m.exchange(mixed.as_bytes(), 2);
        assert!(
            got.contains(" 100000\n") && got.contains(" 100001\n"),
            "{got}"
        );
        let (code, err) = m.stop();
        assert_eq!(code, Some(0), "{err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(
            err.contains("W! line 1") && err.contains("line 2") && err.contains("line 3"),
            "{err}"
        );
    }
}

/// The warning that output `name`'s value at `ts` was dropped for a recursion too deep.
fn assert_too_deep(stderr: &str, name: &str, ts: i64) {
    let want = format!(
        "W! output `{name}` at {ts}: runtime error: function calls nested more than 100000 deep"
    );
    assert!(
        stderr.lines().any(|l| l.starts_with(&want)),
        "{want} missing:\n{stderr}"
    );
}

/// A recursive function in the spec that a record drives too deep (or that never ends): that
/// output is an error value, dropped with a warning naming it and the record's time, and the
/// process lives on. The records before and after are answered, on the main thread and on the
/// workers of `--threads 2` (whose stacks are smaller). Before, the stack overflowed: the
/// process aborted and lost what it had not written yet.
#[test]
fn a_recursion_too_deep_for_a_record_drops_that_value_and_the_run_goes_on() {
    let spec = "in x: Events[Int]\n\
        def depth(n: Int): Int = if n <= 0 then 0 else 1 + depth(n - 1)\n\
        def forever(n: Int): Int = forever(n)\n\
        def d = slift1(x, depth)\n\
        def never = filter(slift1(x, forever), x < 0)\n\
        out d\nout never\n";
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.tessla");
    std::fs::write(&path, spec).unwrap();
    let mut input = String::new();
    for r in ["a", "b", "c", "d"] {
        input.push_str(&format!(
            "m,robot={r} x=10i 1000\nm,robot={r} x=10000000i 2000\nm,robot={r} x=-1i 3000\nm,robot={r} x=5000i 4000\n"
        ));
    }
    for threads in ["1", "2"] {
        let f = run_bytes(
            &[
                "run",
                "--spec",
                path.to_str().unwrap(),
                "--no-passthrough",
                "--instance-by",
                "robot",
                "--threads",
                threads,
            ],
            input.clone().into_bytes(),
            DEADLINE,
        );
        assert_eq!(f.code, Some(0), "{}", f.stderr);
        let out = f.stdout_text();
        for r in ["a", "b", "c", "d"] {
            for want in [
                format!("tessla,robot={r} d=10i 1000"),
                format!("tessla,robot={r} d=0i 3000"),
                format!("tessla,robot={r} d=5000i 4000"),
            ] {
                assert!(out.lines().any(|l| l == want), "{want} missing:\n{out}");
            }
        }
        assert!(
            !out.lines().any(|l| l.ends_with(" 2000")),
            "a value at 2000:\n{out}"
        );
        assert_too_deep(&f.stderr, "d", 2000);
        assert_too_deep(&f.stderr, "never", 3000);
    }
}

/// The same recursion in a constant, which the spec's loading folds: the constant is the error
/// value, each output computed from it is dropped with a warning, the others are answered, and
/// memory stays bounded. Before, the fold grew its stack on the heap without end (24 GB, then
/// the kernel killed the process).
#[test]
fn a_constant_that_recurses_forever_is_an_error_value_not_an_endless_load() {
    let spec = "in x: Events[Int]\n\
        def forever(n: Int): Int = forever(n)\n\
        def broken = x + forever(1)\n\
        out broken\nout x\n";
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.tessla");
    std::fs::write(&path, spec).unwrap();
    let f = run_bytes(
        &["run", "--spec", path.to_str().unwrap(), "--no-passthrough"],
        b"m x=1i 1000\nm x=2i 2000\n".to_vec(),
        DEADLINE,
    );
    assert_eq!(f.code, Some(0), "{}", f.stderr);
    assert_eq!(f.stdout_text(), "tessla x=1i 1000\ntessla x=2i 2000\n");
    assert_too_deep(&f.stderr, "broken", 1000);
    let peak = f.peak_rss_kib.unwrap_or(0);
    assert!(peak < 1024 * 1024, "peak RSS {peak} KiB");
}
