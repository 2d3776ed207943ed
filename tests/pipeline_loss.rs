//! What is lost and what is resent when our child dies and when Telegraf stops, through the
//! Telegraf stand-in (which acknowledges a message when it is written to the child's stdin, as
//! Telegraf's `processors.execd` does, and restarts a dead child after `restart_delay`; see its
//! header), a real Mosquitto and the real binary, with `telegraf/telegraf.conf` as shipped. Each
//! robot message carries a sequence number; the child's echo says which messages it processed.
//! The counts are checked against the README's guarantee table ("Guarantees with the shipped
//! confs"), as is Mosquitto's queue for a persistent session while Telegraf is away
//! (`max_queued_messages`).

#[path = "support/mqtt_client.rs"]
mod mqtt_client;
#[path = "support/recorded.rs"]
mod recorded;
#[path = "support/servers.rs"]
mod servers;
#[path = "support/telegraf_standin.rs"]
mod telegraf_standin;

use recorded::BIN;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};
use telegraf_standin::*;

/// The robot's rate (5 Hz).
const PERIOD: Duration = Duration::from_millis(200);

/// `telegraf.conf` as shipped, its monitors' `--state` file in `dir` instead of the systemd
/// drop-in's StateDirectory.
fn conf_text(dir: &tempfile::TempDir) -> String {
    std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("telegraf/telegraf.conf"),
    )
    .unwrap()
    .replace(
        "/var/lib/tessla-telegraf/",
        &format!("{}/", dir.path().display()),
    )
}

fn endpoints(port: u16) -> Endpoints {
    Endpoints {
        mqtt_port: port,
        influx_url: None,
        udp: Vec::new(),
        programs: vec![("/usr/bin/tessla-telegraf".into(), BIN.into())],
        host: "robot-pc".into(),
        seed: 3,
    }
}

fn message(seq: usize) -> Vec<u8> {
    format!(r#"{{"expectedSpeed":0.2,"actualSpeed":"0.19","seq":{seq}}}"#).into_bytes()
}

/// The robot: `n` messages with QoS 1, one per `period` (none: as fast as it can).
fn robot(port: u16, n: usize, period: Option<Duration>) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let p = mqtt_client::Publisher::connect(port, "robot-loss");
        let start = Instant::now();
        for i in 0..n {
            if let Some(period) = period {
                let due = start + period * i as u32;
                std::thread::sleep(due.saturating_duration_since(Instant::now()));
            }
            p.publish("tessla", message(i));
        }
        // Let the client's connection send what it queued.
        std::thread::sleep(Duration::from_millis(500));
    })
}

/// How many times the child echoed each sequence number.
fn echoed(stats: &[&Stats]) -> BTreeMap<usize, usize> {
    let mut seen = BTreeMap::new();
    for s in stats {
        for m in &s.from_processor {
            if m.name != "mqtt_consumer" {
                continue;
            }
            let seq = m.fields.iter().find_map(|(k, v)| match (k.as_str(), v) {
                ("seq", Field::Float(f)) => Some(*f as usize),
                _ => None,
            });
            *seen.entry(seq.expect("the echo carries seq")).or_insert(0) += 1;
        }
    }
    seen
}

fn wait_until(what: &str, timeout: Duration, mut f: impl FnMut() -> bool) {
    let until = Instant::now() + timeout;
    while !f() {
        assert!(Instant::now() < until, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// The child is SIGKILLed mid-stream: Telegraf acknowledged every message when it wrote it, so
/// the broker resends nothing; the messages that arrive while the child is down (about
/// `restart_delay` x 5 Hz) fail to be written, are dropped and acknowledged all the same.
#[test]
fn a_killed_child_loses_the_restart_delay_and_nothing_is_resent() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let env = endpoints(broker.port);
    let state_dir = tempfile::tempdir().unwrap();
    let text = conf_text(&state_dir);
    let conf = Conf::read(&text, &env);
    let delay: f64 = text
        .lines()
        .find_map(|l| l.trim().strip_prefix("restart_delay = "))
        .map(|d| go_duration_ns(d.trim_matches('"')) as f64 / 1e9)
        .expect("the conf sets restart_delay");
    let telegraf = Telegraf::start(&conf, &env);
    const N: usize = 40;
    let robot = robot(broker.port, N, Some(PERIOD));
    wait_until("15 messages written", Duration::from_secs(30), || {
        telegraf.to_processor() >= 15
    });
    let pid = telegraf.child_pid();
    let killed_at = Instant::now();
    let status = std::process::Command::new("kill")
        .args(["-KILL", &pid.to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    wait_until("the restart", Duration::from_secs(30), || {
        telegraf.restarts() == 1
    });
    let gap = killed_at.elapsed().as_secs_f64();
    robot.join().unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let stats = telegraf.stop();
    let seen = echoed(&[&stats]);
    let lost: Vec<usize> = (0..N).filter(|i| !seen.contains_key(i)).collect();
    let resent: Vec<usize> = seen
        .iter()
        .filter(|(_, c)| **c > 1)
        .map(|(s, _)| *s)
        .collect();
    eprintln!(
        "restart_delay {delay} s, child down {gap:.2} s: lost {} ({lost:?}), dropped at write {}, written and not answered {}, resent {}",
        lost.len(),
        stats.dropped_at_write,
        stats.to_processor - seen.len(),
        resent.len()
    );
    // Nothing is resent: every message was acknowledged, the dropped ones included.
    assert!(resent.is_empty(), "{resent:?}");
    assert_eq!(stats.received, N, "the broker sent each message once");
    assert_eq!(stats.acked, N, "each one acknowledged");
    assert_eq!(stats.restarts, 1);
    // Lost: what failed to be written while the child was down, plus what was in the pipe or
    // read but not answered when it died: at 5 Hz at most the message written just before the
    // kill (the kill follows the 15th write at once).
    let in_pipe = stats.to_processor - seen.len();
    assert_eq!(lost.len(), stats.dropped_at_write + in_pipe, "{lost:?}");
    assert!(in_pipe <= 1, "{in_pipe} written and never answered");
    // One stretch of messages, about the child's down time at 5 Hz.
    assert!(lost.windows(2).all(|w| w[1] == w[0] + 1), "{lost:?}");
    let expected = gap / PERIOD.as_secs_f64();
    assert!(
        (lost.len() as f64 - expected).abs() <= 1.5,
        "lost {} for {gap:.2} s down ({expected:.1} expected)",
        lost.len()
    );
    assert!(
        lost.len() as f64 <= delay / PERIOD.as_secs_f64() + 2.0,
        "the shipped restart_delay bounds the loss: {lost:?}"
    );
    // The restarted child answers the rest.
    assert!(seen.contains_key(&(N - 1)));
}

/// Telegraf stops mid-stream and starts again (same persistent session): the broker kept what
/// arrived meanwhile (nothing lost) and resends what Telegraf received but had not acknowledged
/// when its input stopped; Telegraf had already written those to the child, so they are
/// processed twice (a fresh child has no memory of them).
#[test]
fn a_telegraf_stop_loses_nothing_and_resends_the_unacknowledged() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let env = endpoints(broker.port);
    let state_dir = tempfile::tempdir().unwrap();
    let conf = Conf::read(&conf_text(&state_dir), &env);
    let first = Telegraf::start(&conf, &env);
    // A burst, as after the robot reconnects: many messages in flight at the stop.
    const N: usize = 600;
    let robot = robot(broker.port, N, None);
    wait_until("200 messages written", Duration::from_secs(60), || {
        first.to_processor() >= 200
    });
    let one = first.stop();
    let stopped_at = Instant::now();
    robot.join().unwrap();
    // Away for a moment; the broker queues for the persistent session.
    std::thread::sleep(Duration::from_millis(500));
    let second = Telegraf::start(&conf, &env);
    let away = stopped_at.elapsed();
    wait_until("every message", Duration::from_secs(60), || {
        one.to_processor + second.to_processor() >= N + (one.received - one.acked)
    });
    std::thread::sleep(Duration::from_millis(300));
    let two = second.stop();
    let seen = echoed(&[&one, &two]);
    let lost: Vec<usize> = (0..N).filter(|i| !seen.contains_key(i)).collect();
    let resent: Vec<usize> = seen
        .iter()
        .filter(|(_, c)| **c > 1)
        .map(|(s, _)| *s)
        .collect();
    let unacked = one.received - one.acked;
    eprintln!(
        "away {away:?}: first run received {}, acknowledged {}; lost {}, resent {} ({resent:?})",
        one.received,
        one.acked,
        lost.len(),
        resent.len()
    );
    assert!(lost.is_empty(), "{lost:?}");
    // Everything the first run received was written to its child before stdin closed.
    assert_eq!(one.to_processor, one.received);
    assert_eq!(one.dropped_at_write, 0);
    // Resent: exactly what was received and not acknowledged, each processed twice; at most
    // mqtt_consumer's max_undelivered_messages (1000) are taken and not delivered at a time.
    assert_eq!(resent.len(), unacked, "{resent:?}");
    assert!(unacked <= MAX_UNDELIVERED, "{unacked}");
    assert!(seen.values().all(|c| *c <= 2));
    assert_eq!(two.received, N - one.received + unacked);
    assert_eq!(
        one.child_status.map(|s| s.success()),
        Some(true),
        "the child ends at stdin EOF"
    );
    assert_eq!(one.signalled, None);
}

/// While Telegraf is away the broker queues for its persistent session up to
/// `max_queued_messages`; past it the newest messages are dropped (the oldest are kept).
#[test]
fn the_broker_keeps_the_oldest_max_queued_messages_while_telegraf_is_away() {
    const QUEUE: usize = 10;
    // `max_queued_messages` set (`persistence false`, as the test servers).
    let Some(broker) = servers::Mosquitto::start_with(&format!("max_queued_messages {QUEUE}\n"))
    else {
        return;
    };
    let env = endpoints(broker.port);
    let state_dir = tempfile::tempdir().unwrap();
    let conf = Conf::read(&conf_text(&state_dir), &env);
    // The first start makes the session; then Telegraf goes away.
    Telegraf::start(&conf, &env).stop();
    const N: usize = 50;
    robot(broker.port, N, None).join().unwrap();
    let telegraf = Telegraf::start(&conf, &env);
    std::thread::sleep(Duration::from_secs(2));
    let stats = telegraf.stop();
    let seen = echoed(&[&stats]);
    let kept: Vec<usize> = seen.keys().copied().collect();
    eprintln!("max_queued_messages {QUEUE}: kept {kept:?}");
    assert_eq!(kept, (0..kept.len()).collect::<Vec<_>>(), "the oldest kept");
    assert_eq!(kept.len(), QUEUE, "{kept:?}");
}
