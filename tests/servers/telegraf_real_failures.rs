//! The README's guarantee table, measured on the real Telegraf (both pinned versions) with the
//! shipped `telegraf/telegraf.conf`, a real Mosquitto and InfluxDB, and the real binary as its
//! child. Each robot message carries a sequence number (`seq`, a field the monitors ignore and
//! echo), so what was lost, answered or processed twice is counted from what reached InfluxDB:
//! the echo of every record the monitor answered lands there (measurement `mqtt_consumer`).
//!
//! - a child killed mid-run: the records lost while Telegraf restarts it (`restart_delay`);
//! - Telegraf stopped (SIGTERM) and crashed (SIGKILL, with and without its child, as systemd's
//!   `KillMode=mixed` kills it): whether `--state` is saved, what is lost and resent;
//! - the last output lines at a stop: none lost;
//! - a child that cannot start (a broken spec): Telegraf restarts it every `restart_delay` for
//!   as long as it runs, dropping and acknowledging every record meanwhile.

use crate::support::mqtt_client;
use crate::support::real_telegraf;
use crate::support::recorded;
use crate::support::servers;

use real_telegraf::{Rewrite, Telegraf, broker, wait_subscribed};
use std::collections::BTreeMap;
use std::time::{Duration, Instant};
use tessla_telegraf::replay::message::{MessageOptions, to_json};

/// The recorded run's messages as the robot's JSON, each with `"seq": k` added.
pub(super) fn messages(n: usize) -> Vec<Vec<u8>> {
    let text = std::fs::read_to_string(recorded::recorded_run_path()).unwrap();
    let recording = tessla_telegraf::replay::read_lp::read(&text, None);
    let options = MessageOptions {
        string_fields: vec!["actualSpeed".into()],
        time_key: None,
    };
    (0..n)
        .map(|k| {
            let sample = &recording.samples[k % recording.samples.len()];
            let mut json = to_json(sample, &options);
            json["seq"] = serde_json::json!(k);
            serde_json::to_vec(&json).unwrap()
        })
        .collect()
}

/// The `seq` of every record the monitor echoed into InfluxDB, with how often.
pub(super) fn echoed(influx: &servers::Influxd) -> BTreeMap<i64, usize> {
    let (status, v) = influx.query(Some("telegraf"), "SELECT seq FROM mqtt_consumer");
    assert_eq!(status, 200, "{v}");
    let mut out = BTreeMap::new();
    for row in v["results"][0]["series"][0]["values"]
        .as_array()
        .into_iter()
        .flatten()
    {
        *out.entry(row[1].as_f64().unwrap() as i64).or_insert(0) += 1;
    }
    out
}

fn count(influx: &servers::Influxd, q: &str) -> i64 {
    let (_, v) = influx.query(Some("telegraf"), q);
    v["results"][0]["series"][0]["values"][0][1]
        .as_i64()
        .unwrap_or(0)
}

/// Wait until InfluxDB holds `n` echoed records (Telegraf flushes every 100 ms).
fn wait_echoed(influx: &servers::Influxd, n: usize, log: impl Fn() -> String) {
    let deadline = Instant::now() + Duration::from_secs(60);
    while echoed(influx).values().sum::<usize>() < n {
        assert!(
            Instant::now() < deadline,
            "only {} of {n} records reached InfluxDB; Telegraf's log:\n{}",
            echoed(influx).values().sum::<usize>(),
            log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

struct Setup {
    broker: servers::Mosquitto,
    influx: servers::Influxd,
    state: tempfile::TempDir,
    conf: String,
}

fn setup(edit: impl Fn(String) -> String) -> Option<Setup> {
    let broker = broker()?;
    let influx = servers::Influxd::start()?;
    let state = tempfile::tempdir().unwrap();
    let text = real_telegraf::shipped("telegraf/telegraf.conf");
    let rewrite = Rewrite::robot(crate::support::BIN, broker.port, Some(&influx.url("")))
        .state_in(state.path());
    let conf = edit(rewrite.apply(&text));
    Some(Setup {
        broker,
        influx,
        state,
        conf,
    })
}

/// Publish `payloads` at `hz` on `tessla`, calling `at(k)` before message k.
fn publish_at(port: u16, payloads: &[Vec<u8>], hz: f64, mut at: impl FnMut(usize)) {
    let publisher = mqtt_client::Publisher::connect(port, "robot");
    let start = Instant::now();
    let period = Duration::from_secs_f64(1.0 / hz);
    for (k, p) in payloads.iter().enumerate() {
        at(k);
        let due = start + period.mul_f64(k as f64);
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        publisher.publish("tessla", p.clone());
    }
}

#[test]
fn a_child_killed_mid_run_loses_about_restart_delay_of_records_all_acknowledged() {
    for (version, bin) in real_telegraf::versions() {
        let Some(s) = setup(|c| c) else { return };
        let telegraf = Telegraf::start(version, &bin, &s.conf, &[]);
        wait_subscribed(&s.broker, "telegraf-tessla-in", "tessla", 0);
        let first = telegraf.wait_child(&[], Duration::from_secs(10));
        let n = 60;
        let kill_at = 20;
        publish_at(s.broker.port, &messages(n), 5.0, |k| {
            if k == kill_at {
                let _ = std::process::Command::new("kill")
                    .args(["-KILL", &first.to_string()])
                    .status();
            }
        });
        let second = telegraf.wait_child(&[first], Duration::from_secs(10));
        assert_ne!(first, second);
        // Everything after the gap is answered.
        let deadline = Instant::now() + Duration::from_secs(30);
        while !echoed(&s.influx).contains_key(&(n as i64 - 1)) {
            assert!(Instant::now() < deadline, "{}", telegraf.log());
            std::thread::sleep(Duration::from_millis(100));
        }
        let log = telegraf.stop();
        let seen = echoed(&s.influx);
        let lost: Vec<i64> = (0..n as i64).filter(|k| !seen.contains_key(k)).collect();
        assert!(
            seen.values().all(|&c| c == 1),
            "none processed twice: {seen:?}"
        );
        // One stretch: from the kill until the new child ran (restart_delay = 1 s at 5 Hz),
        // plus at most the message written just before the kill.
        assert!(
            !lost.is_empty() && lost.len() <= 8,
            "Telegraf {version}: lost {lost:?}\n{log}"
        );
        assert!(
            lost.windows(2).all(|w| w[1] == w[0] + 1),
            "one stretch: {lost:?}"
        );
        assert!(lost[0] >= kill_at as i64 - 1, "{lost:?}");
        assert!(log.contains("Restarting in 1s"), "{log}");
        // All acknowledged: a Telegraf started again on the same session gets nothing resent.
        let again = Telegraf::start(version, &bin, &s.conf, &[]);
        std::thread::sleep(Duration::from_secs(2));
        let log2 = again.stop();
        assert_eq!(echoed(&s.influx), seen, "nothing resent:\n{log2}");
        eprintln!(
            "Telegraf {version}: child killed at message {kill_at} of {n} at 5 Hz, restart_delay 1s: lost {} ({:?}..={:?})",
            lost.len(),
            lost.first(),
            lost.last()
        );
    }
}

#[test]
fn a_stop_loses_no_output_line_and_resends_only_what_was_not_acknowledged() {
    for (version, bin) in real_telegraf::versions() {
        let Some(s) = setup(|c| c) else { return };
        let telegraf = Telegraf::start(version, &bin, &s.conf, &[]);
        wait_subscribed(&s.broker, "telegraf-tessla-in", "tessla", 0);
        let n = 300;
        // A burst, and Telegraf stopped while it is still being processed.
        let payloads = messages(n);
        let publisher = mqtt_client::Publisher::connect(s.broker.port, "robot");
        for p in &payloads {
            publisher.publish("tessla", p.clone());
        }
        let deadline = Instant::now() + Duration::from_secs(30);
        while echoed(&s.influx).len() < 20 {
            assert!(Instant::now() < deadline, "{}", telegraf.log());
            std::thread::sleep(Duration::from_millis(20));
        }
        let log = telegraf.stop();
        let first_run = echoed(&s.influx);
        // Telegraf 1.33.3 can panic at this stop: the input disconnects first, then a record
        // the processor still holds is delivered and paho acknowledges it on the closed client
        // ("panic: send on closed channel" in paho's ackFunc, from mqtt_consumer's onDelivered).
        // It then exits without flushing its outputs.
        let panicked = log.contains("panic: ");
        // Our summary (stderr, written last) reached Telegraf's log.
        let summaries = log.lines().filter(|l| l.contains("summary:")).count();
        // Every record the monitor answered has its verdict and action too: no last line lost.
        let records = first_run.values().sum::<usize>() as i64;
        let verdicts = count(&s.influx, "SELECT count(p2_violated) FROM tessla");
        let actions = count(&s.influx, "SELECT count(speed) FROM action");
        let lost_lines = (records - verdicts) + (records - actions) + (1 - summaries as i64);
        if !panicked {
            assert_eq!(summaries, 1, "Telegraf {version}: our summary\n{log}");
            assert_eq!(verdicts, records, "Telegraf {version}: verdicts\n{log}");
            assert_eq!(actions, records, "Telegraf {version}: actions\n{log}");
        }
        // Started again on the same session: the rest arrives.
        let broker_log_len = s.broker.log().lines().count();
        let again = Telegraf::start(version, &bin, &s.conf, &[]);
        wait_subscribed(&s.broker, "telegraf-tessla-in", "tessla", broker_log_len);
        let deadline = Instant::now() + Duration::from_secs(60);
        while !echoed(&s.influx).contains_key(&(n as i64 - 1)) {
            assert!(Instant::now() < deadline, "{}", again.log());
            std::thread::sleep(Duration::from_millis(100));
        }
        let log2 = again.stop();
        let both = echoed(&s.influx);
        let lost: Vec<i64> = (0..n as i64).filter(|k| !both.contains_key(k)).collect();
        if !panicked {
            assert!(
                lost.is_empty(),
                "Telegraf {version}: lost {lost:?}\n{log}\n{log2}"
            );
        }
        let twice = both.values().filter(|&&c| c > 1).count();
        eprintln!(
            "Telegraf {version}: stopped during a burst of {n}: {} answered before the stop, {twice} processed again after it, {} records and {lost_lines} output lines lost{}",
            first_run.len(),
            lost.len(),
            if panicked {
                " (Telegraf panicked at the stop)"
            } else {
                ""
            }
        );
    }
}

#[test]
fn a_broken_spec_is_restarted_every_restart_delay_and_its_records_are_acknowledged_and_lost() {
    for (version, bin) in real_telegraf::versions() {
        let dir = tempfile::tempdir().unwrap();
        let spec = dir.path().join("broken.tessla");
        std::fs::write(&spec, "in x: Events[Int]\nout y = x +\n").unwrap();
        let spec_arg = format!("{:?}", spec.display().to_string());
        let Some(s) =
            setup(|c| c.replacen("\"run\"", &format!("\"run\", \"--spec\", {spec_arg}"), 1))
        else {
            return;
        };
        let telegraf = Telegraf::start(version, &bin, &s.conf, &[]);
        wait_subscribed(&s.broker, "telegraf-tessla-in", "tessla", 0);
        publish_at(s.broker.port, &messages(15), 5.0, |_| {});
        // The last messages reach Telegraf (which drops them and acknowledges them), and
        // three restarts, however busy the machine: waited for, not assumed after the sleep.
        std::thread::sleep(Duration::from_secs(1));
        telegraf.wait_for(
            |log| log.matches("Restarting in 1s").count() >= 3,
            Duration::from_secs(60),
            "three restarts",
        );
        let log = telegraf.stop();
        let restarts = log.matches("Restarting in 1s").count();
        // Our diagnostic reaches Telegraf's log, with the file, line and column.
        assert!(log.contains("broken.tessla:2:"), "{log}");
        assert!(echoed(&s.influx).is_empty());
        // Acknowledged: a Telegraf with a good spec on the same session gets none of them.
        let good = s.conf.replace(&format!(", \"--spec\", {spec_arg}"), "");
        let again = Telegraf::start(version, &bin, &good, &[]);
        std::thread::sleep(Duration::from_secs(2));
        let _ = again.stop();
        assert!(
            echoed(&s.influx).is_empty(),
            "Telegraf {version}: dropped records were acknowledged"
        );
        eprintln!(
            "Telegraf {version}: broken spec restarted {restarts} times while 15 records came at 5 Hz, all acknowledged and lost"
        );
    }
}

/// The state file the conf's `--state` names, in the test's state folder.
fn state_file(s: &Setup) -> std::path::PathBuf {
    let v: toml::Value = toml::from_str(&s.conf).unwrap();
    let command: Vec<String> = v["processors"]["execd"][0]["command"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap().to_string())
        .collect();
    let i = command
        .iter()
        .position(|a| a == "--state")
        .expect("the shipped conf keeps the monitors' state (--state)");
    let path = std::path::PathBuf::from(&command[i + 1]);
    assert!(path.starts_with(s.state.path()), "{}", path.display());
    path
}

fn modified(path: &std::path::Path) -> Option<std::time::SystemTime> {
    std::fs::metadata(path).and_then(|m| m.modified()).ok()
}

/// Publish a burst of `n` records and wait until the monitor has answered them all.
fn feed(s: &Setup, telegraf: &Telegraf, n: usize) {
    let before = echoed(&s.influx).values().sum::<usize>();
    let publisher = mqtt_client::Publisher::connect(s.broker.port, "robot");
    for p in messages(n) {
        publisher.publish("tessla", p);
    }
    wait_echoed(&s.influx, before + n, || telegraf.log());
}

/// How the next Telegraf's monitor starts: the `state:` line it logs.
fn next_start(s: &Setup, version: &str, bin: &std::path::Path) -> String {
    let since = s.broker.log().lines().count();
    let t = Telegraf::start(version, bin, &s.conf, &[]);
    wait_subscribed(&s.broker, "telegraf-tessla-in", "tessla", since);
    t.wait_for(
        |l| l.contains("state: "),
        Duration::from_secs(30),
        "the monitor's state line",
    );
    let log = t.stop();
    log.lines()
        .find(|l| l.contains("state: "))
        .unwrap_or_default()
        .to_string()
}

/// The shipped conf under Telegraf `version`, its monitor fed 20 records: the set-up, the path
/// of its state file, the running Telegraf.
fn fed(version: &str, bin: &std::path::Path) -> Option<(Setup, std::path::PathBuf, Telegraf)> {
    let s = setup(|c| c)?;
    let path = state_file(&s);
    let telegraf = Telegraf::start(version, bin, &s.conf, &[]);
    wait_subscribed(&s.broker, "telegraf-tessla-in", "tessla", 0);
    feed(&s, &telegraf, 20);
    Some((s, path, telegraf))
}

#[test]
fn telegraf_stopped_or_crashed_and_the_state_it_leaves() {
    for (version, bin) in real_telegraf::versions() {
        // Stopped (systemctl stop: SIGTERM to Telegraf, which closes our stdin): saved.
        let Some((s, path, telegraf)) = fed(version, &bin) else {
            return;
        };
        let log = telegraf.stop();
        assert!(
            path.is_file(),
            "Telegraf {version}: SIGTERM: no state saved\n{log}"
        );
        let line = next_start(&s, version, &bin);
        assert!(line.contains("restored 1 monitor instances"), "{line}");

        // Crashed alone (SIGKILL to Telegraf; without systemd the child lives on): the child
        // reads EOF on its stdin, saves and exits by itself.
        let Some((s, path, telegraf)) = fed(version, &bin) else {
            return;
        };
        let child = telegraf.wait_child(&[], Duration::from_secs(5));
        let _ = telegraf.crash();
        let deadline = Instant::now() + Duration::from_secs(20);
        while real_telegraf::alive(child) {
            assert!(Instant::now() < deadline, "the orphaned child never exited");
            std::thread::sleep(Duration::from_millis(20));
        }
        assert!(
            path.is_file(),
            "Telegraf {version}: SIGKILL alone: no state saved"
        );
        let line = next_start(&s, version, &bin);
        assert!(line.contains("restored 1 monitor instances"), "{line}");

        // Crashed under systemd (KillMode=mixed: when Telegraf dies, the rest of its cgroup,
        // our child, is SIGKILLed at once): only the last --state-interval save is there.
        let Some((s, path, telegraf)) = fed(version, &bin) else {
            return;
        };
        let child = telegraf.wait_child(&[], Duration::from_secs(5));
        let _ = std::process::Command::new("kill")
            .args(["-KILL", &child.to_string()])
            .status();
        let _ = telegraf.crash();
        let saved = modified(&path);
        let line = next_start(&s, version, &bin);
        eprintln!(
            "Telegraf {version}: SIGTERM: saved; SIGKILL alone: saved by the orphaned child; SIGKILL with the child (KillMode=mixed): {} -> next start: {line}",
            if saved.is_some() {
                "the last periodic save"
            } else {
                "nothing saved (run shorter than --state-interval)"
            }
        );
        if saved.is_none() {
            assert!(line.contains("starting fresh"), "{line}");
        }
    }
}

#[test]
fn while_telegraf_is_away_the_broker_keeps_the_oldest_max_queued_messages() {
    const QUEUE: usize = 10;
    const N: usize = 50;
    for (version, bin) in real_telegraf::versions() {
        // The broker as the test servers run it (`persistence false`) with a small queue.
        let Some(broker) = real_telegraf::broker_with(&format!("max_queued_messages {QUEUE}\n"))
        else {
            return;
        };
        let Some(influx) = servers::Influxd::start() else {
            return;
        };
        let state = tempfile::tempdir().unwrap();
        let conf = Rewrite::robot(crate::support::BIN, broker.port, Some(&influx.url("")))
            .state_in(state.path())
            .apply(&real_telegraf::shipped("telegraf/telegraf.conf"));
        let s = Setup {
            broker,
            influx,
            state,
            conf,
        };
        // The first start makes the persistent session; then Telegraf goes away.
        let first = Telegraf::start(version, &bin, &s.conf, &[]);
        wait_subscribed(&s.broker, "telegraf-tessla-in", "tessla", 0);
        let _ = first.stop();
        let publisher = mqtt_client::Publisher::connect(s.broker.port, "robot");
        for p in messages(N) {
            publisher.publish("tessla", p);
        }
        std::thread::sleep(Duration::from_millis(500));
        let since = s.broker.log().lines().count();
        let again = Telegraf::start(version, &bin, &s.conf, &[]);
        wait_subscribed(&s.broker, "telegraf-tessla-in", "tessla", since);
        wait_echoed(&s.influx, QUEUE, || again.log());
        std::thread::sleep(Duration::from_secs(1));
        let log = again.stop();
        let seen: Vec<i64> = echoed(&s.influx).keys().copied().collect();
        assert_eq!(
            seen,
            (0..QUEUE as i64).collect::<Vec<_>>(),
            "Telegraf {version}: the oldest {QUEUE} kept, the newer dropped\n{log}"
        );
        assert!(
            s.broker
                .log()
                .contains("Outgoing messages are being dropped"),
            "the broker says so"
        );
    }
}

/// A spec whose step for `n = 60` makes 2^60 calls (centuries), for `n = 3` eight.
const ENDLESS: &str = "in n: Events[Int]\n\
    def work(k: Int): Int = if k == 0 then 1 else work(k - 1) + work(k - 1)\n\
    @TelegrafField(\"work\", \"r\") out slift1(n, (k: Int) => work(k)) as r\n";

#[test]
fn a_hung_child_ends_itself_by_its_watchdog_and_telegraf_restarts_it() {
    for (version, bin) in real_telegraf::versions() {
        let dir = tempfile::tempdir().unwrap();
        let spec = dir.path().join("endless.tessla");
        std::fs::write(&spec, format!("include \"telegraf.tessla\"\n{ENDLESS}")).unwrap();
        let spec_arg = format!("{:?}", spec.display().to_string());
        let with = |timeout: &str| {
            let timeout = timeout.to_string();
            let spec_arg = spec_arg.clone();
            move |c: String| {
                c.replacen(
                    "\"run\"",
                    &format!("\"run\", \"--spec\", {spec_arg}, \"--step-timeout\", \"{timeout}\""),
                    1,
                )
            }
        };
        // With the watchdog (3 s here, 10 s by default): the child exits with code 4 and
        // Telegraf starts a new one, which answers the next record.
        let Some(s) = setup(with("3s")) else { return };
        let telegraf = Telegraf::start(version, &bin, &s.conf, &[]);
        wait_subscribed(&s.broker, "telegraf-tessla-in", "tessla", 0);
        let first = telegraf.wait_child(&[], Duration::from_secs(10));
        let publisher = mqtt_client::Publisher::connect(s.broker.port, "robot");
        let hung_at = Instant::now();
        publisher.publish("tessla", br#"{"n": 60}"#.to_vec());
        let second = telegraf.wait_child(&[first], Duration::from_secs(60));
        let restarted_after = hung_at.elapsed();
        assert!(!real_telegraf::alive(first));
        publisher.publish("tessla", br#"{"n": 3}"#.to_vec());
        let deadline = Instant::now() + Duration::from_secs(30);
        while count(&s.influx, "SELECT count(r) FROM work") < 1 {
            assert!(Instant::now() < deadline, "{}", telegraf.log());
            std::thread::sleep(Duration::from_millis(100));
        }
        let log = telegraf.stop();
        assert!(log.contains("exit status 4"), "Telegraf {version}:\n{log}");
        assert!(
            log.contains("step-timeout") || log.contains("no progress"),
            "{log}"
        );
        assert!(second != first);
        eprintln!(
            "Telegraf {version}: a hung step (watchdog 3 s): new child after {restarted_after:?}"
        );

        // Without it (--step-timeout 0): Telegraf never restarts a live child; the next
        // records wait in the pipe, unanswered.
        let Some(s) = setup(with("0")) else { return };
        let telegraf = Telegraf::start(version, &bin, &s.conf, &[]);
        wait_subscribed(&s.broker, "telegraf-tessla-in", "tessla", 0);
        let child = telegraf.wait_child(&[], Duration::from_secs(10));
        let publisher = mqtt_client::Publisher::connect(s.broker.port, "robot");
        publisher.publish("tessla", br#"{"n": 60}"#.to_vec());
        for _ in 0..5 {
            publisher.publish("tessla", br#"{"n": 3}"#.to_vec());
        }
        std::thread::sleep(Duration::from_secs(8));
        assert_eq!(
            telegraf.children(),
            vec![child],
            "Telegraf {version}: the same child"
        );
        assert_eq!(count(&s.influx, "SELECT count(r) FROM work"), 0);
        // Telegraf's stop closes our stdin and SIGKILLs us 10 s later.
        let _ = telegraf.stop();
    }
}

/// A client of the test's own that survives the broker going away: it connects again and again
/// (a robot's client does), subscribing anew each time when `subscribe` names a topic. Every
/// message received is sent with its arrival (ns since the epoch).
pub(super) fn robust_client(
    port: u16,
    id: &str,
    subscribe: Option<&str>,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> (rumqttc::Client, std::sync::mpsc::Receiver<(i64, Vec<u8>)>) {
    use rumqttc::{Event, MqttOptions, Packet, QoS};
    let mut o = MqttOptions::new(id, "127.0.0.1", port);
    o.set_max_packet_size(1 << 20, 1 << 20);
    o.set_keep_alive(Duration::from_secs(5));
    let (client, mut connection) = rumqttc::Client::new(o, 4096);
    let (tx, rx) = std::sync::mpsc::channel();
    let topic = subscribe.map(String::from);
    let sub = client.clone();
    std::thread::spawn(move || {
        while !stop.load(std::sync::atomic::Ordering::Relaxed) {
            match connection.recv_timeout(Duration::from_millis(200)) {
                Ok(Ok(Event::Incoming(Packet::ConnAck(_)))) => {
                    if let Some(t) = &topic {
                        let _ = sub.try_subscribe(t, QoS::AtLeastOnce);
                    }
                }
                Ok(Ok(Event::Incoming(Packet::Publish(p)))) => {
                    let _ = tx.send((real_telegraf_now(), p.payload.to_vec()));
                }
                Ok(Ok(_)) => {}
                Ok(Err(_)) => std::thread::sleep(Duration::from_millis(200)),
                Err(_) => {}
            }
        }
    });
    (client, rx)
}

fn real_telegraf_now() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as i64)
        .unwrap_or(0)
}

fn mosquitto_on(port: u16) -> servers::Server {
    let binary = servers::require("mosquitto", "mosquitto").expect("mosquitto");
    servers::Server::start(
        &binary,
        &["-c"],
        tempfile::tempdir().unwrap(),
        port,
        "mosquitto.conf",
        &format!(
            "listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\nlog_dest stderr\n"
        ),
    )
}

/// What the broker tests share: InfluxDB, a Mosquitto of the test's own (to kill and start
/// again) on a free port, a state folder and the shipped `telegraf.conf` pointed at them (with the
/// robot's own time in each message when `robots_time`). `None` without the servers.
fn broker_run(
    robots_time: bool,
) -> Option<(
    servers::Influxd,
    u16,
    servers::Server,
    tempfile::TempDir,
    String,
)> {
    servers::require("mosquitto", "mosquitto")?;
    let influx = servers::Influxd::start()?;
    let port = servers::free_port();
    let broker = mosquitto_on(port);
    let state = tempfile::tempdir().unwrap();
    let mut rewrite =
        Rewrite::robot(crate::support::BIN, port, Some(&influx.url(""))).state_in(state.path());
    if robots_time {
        rewrite = rewrite.robots_time();
    }
    let conf = rewrite.apply(&real_telegraf::shipped("telegraf/telegraf.conf"));
    Some((influx, port, broker, state, conf))
}

#[test]
fn the_broker_down_for_30_s_makes_late_and_repeated_actions_the_robot_refuses() {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use tessla_telegraf::simulate::closed_loop::Action;
    use tessla_telegraf::simulate::gate::{Gate, Verdict};
    for (version, bin) in real_telegraf::versions() {
        let Some((_influx, port, broker, _state, conf)) = broker_run(false) else {
            return;
        };
        let stop = Arc::new(AtomicBool::new(false));
        let (_robot_in, actions) = robust_client(port, "robot-in", Some("action"), stop.clone());
        let telegraf = Telegraf::start(version, &bin, &conf, &[]);
        std::thread::sleep(Duration::from_secs(1));
        let (robot_out, _) = robust_client(port, "robot-out", None, stop.clone());
        let payloads = messages(45 * 5);
        let start = Instant::now();
        let mut broker = Some(broker);
        let mut back_at = i64::MAX;
        for (k, p) in payloads.iter().enumerate() {
            let due = start + Duration::from_millis(200 * k as u64);
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
            if k == 5 * 5 {
                drop(broker.take()); // the broker dies (killed)
            }
            if k == 35 * 5 {
                broker = Some(mosquitto_on(port)); // back, 30 s later, without the sessions
                back_at = real_telegraf_now();
            }
            // The robot's client queues what it publishes while it reconnects.
            let _ = robot_out.try_publish("tessla", rumqttc::QoS::AtLeastOnce, false, p.clone());
        }
        std::thread::sleep(Duration::from_secs(5));
        let log = telegraf.stop();
        stop.store(true, Ordering::Relaxed);
        let mut gate = Gate::default();
        let (mut late, mut seen, mut twice) = (0, std::collections::BTreeSet::new(), 0);
        let (mut received, mut after, mut first_after) = (0, 0, i64::MAX);
        while let Ok((at, payload)) = actions.try_recv() {
            received += 1;
            if at > back_at {
                after += 1;
                first_after = first_after.min(at - back_at);
            }
            let row = real_telegraf::action_row(&payload);
            let int = |k: &str| match row.fields.get(k) {
                Some(real_telegraf::Field::Int(i)) => Some(*i),
                _ => None,
            };
            let (seq, until) = (int("seq"), int("valid_until"));
            if until.is_some_and(|u| at > u) {
                late += 1;
            }
            if let Some(s) = seq
                && !seen.insert(s)
            {
                twice += 1;
            }
            let action = Action {
                speed: 0.0,
                augmented: false,
                speed_mse: None,
                seq,
                valid_until: until,
                time_ns: Some(row.time * 1_000_000),
            };
            let verdict = gate.judge(&action, at);
            if until.is_some_and(|u| at > u) {
                assert_eq!(verdict, Verdict::RefusedStale);
            }
        }
        assert!(
            after > 0,
            "Telegraf {version}: no action after the broker came back\n{log}"
        );
        assert_eq!(gate.refused_stale, late, "every late action is refused");
        eprintln!(
            "Telegraf {version}: broker down 30 s at 5 Hz: {received} actions reached the robot ({after} after it came back, the first {:.1} s after), {late} late (refused as stale), {twice} repeated, {} refused as repeated, {} monitor restarts",
            first_after as f64 / 1e9,
            gate.refused_repeated,
            gate.monitor_restarts
        );
    }
}

/// Issue 46: a robot that publishes at QoS 1 and takes its actions on one connection, with its own
/// time in each message (`json_time_key`), whose link drops for 1.3 s three times (its client
/// queues and sends the queue late) and whose broker is down for 10 s. A silence moves the
/// monitor's clock (`robot_silent` fires), so the queued messages come late and are stepped after
/// it; their actions must still be valid only until their own message's time plus 400 ms. Every
/// action's `valid_until` is checked against the robot's own record of what it sent (it must be
/// a sent message's time plus the validity: a validity counted from a moved clock is not), and
/// the robot's gate must refuse every action it receives past that time: zero stale actions
/// applied.
#[test]
fn link_gaps_and_a_broker_outage_let_no_stale_action_through_the_robots_gate() {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use tessla_telegraf::simulate::closed_loop::Action;
    use tessla_telegraf::simulate::gate::{Gate, Verdict};
    const VALIDITY: i64 = 400_000_000;
    for (version, bin) in real_telegraf::versions() {
        let Some((_influx, port, broker, _state, conf)) = broker_run(true) else {
            return;
        };
        let stop = Arc::new(AtomicBool::new(false));
        let telegraf = Telegraf::start(version, &bin, &conf, &[]);
        std::thread::sleep(Duration::from_secs(1));
        // One connection: the robot publishes on it and receives its actions on it.
        let (robot, actions) = robust_client(port, "robot", Some("action"), stop.clone());
        let payloads = messages(32 * 5);
        let start = Instant::now();
        let mut broker = Some(broker);
        let mut sent = std::collections::BTreeSet::new();
        let mut queue: Vec<Vec<u8>> = Vec::new();
        // Link gaps of 1.3 s at 4 s, 8 s and 12 s; the broker down from 18 s to 28 s.
        let gap = |k: usize| [20usize, 40, 60].iter().any(|&g| (g..g + 7).contains(&k));
        for (k, p) in payloads.iter().enumerate() {
            let due = start + Duration::from_millis(200 * k as u64);
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
            if k == 18 * 5 {
                drop(broker.take());
            }
            if k == 28 * 5 {
                broker = Some(mosquitto_on(port));
            }
            // The robot's time, as Telegraf's float64 reading keeps it exactly (a multiple of 4 µs).
            let t = real_telegraf_now() / 4096 * 4096;
            sent.insert(t);
            let mut json: serde_json::Value = serde_json::from_slice(p).unwrap();
            json["time"] = serde_json::json!(t);
            let payload = serde_json::to_vec(&json).unwrap();
            if gap(k) {
                queue.push(payload);
                continue;
            }
            for q in queue.drain(..).chain(std::iter::once(payload)) {
                let _ = robot.try_publish("tessla", rumqttc::QoS::AtLeastOnce, false, q);
            }
        }
        std::thread::sleep(Duration::from_secs(5));
        let log = telegraf.stop();
        stop.store(true, Ordering::Relaxed);
        let mut gate = Gate::default();
        let (mut received, mut stale, mut applied) = (0, 0, 0);
        let mut not_a_message = Vec::new();
        while let Ok((at, payload)) = actions.try_recv() {
            received += 1;
            let row = real_telegraf::action_row(&payload);
            let int = |k: &str| match row.fields.get(k) {
                Some(real_telegraf::Field::Int(i)) => Some(*i),
                _ => None,
            };
            let (seq, until) = (int("seq"), int("valid_until"));
            let Some(until) = until else {
                panic!("Telegraf {version}: an action without valid_until: {row:?}");
            };
            if !sent.contains(&(until - VALIDITY)) {
                not_a_message.push(until);
            }
            let action = Action {
                speed: 0.0,
                augmented: false,
                speed_mse: None,
                seq,
                valid_until: Some(until),
                time_ns: Some(row.time * 1_000_000),
            };
            let verdict = gate.judge(&action, at);
            // The data behind the action is its message's: older than the validity, refused.
            if at > until {
                stale += 1;
                assert_eq!(verdict, Verdict::RefusedStale, "Telegraf {version}");
            } else if matches!(verdict, Verdict::Accepted | Verdict::Restarted) {
                applied += 1;
                assert!(at - (until - VALIDITY) <= VALIDITY, "Telegraf {version}");
            }
        }
        assert!(
            not_a_message.is_empty(),
            "Telegraf {version}: {} actions valid until a time no message had plus 400 ms (a moved clock's): {not_a_message:?}\n{log}",
            not_a_message.len()
        );
        assert!(
            received > 60 && applied > 40,
            "Telegraf {version}: {received} actions, {applied} applied\n{log}"
        );
        assert!(
            log.contains("late record"),
            "Telegraf {version}: the link gaps made no late record: the test did not test\n{log}"
        );
        assert_eq!(gate.refused_stale, stale, "every stale action is refused");
        eprintln!(
            "Telegraf {version}: 3 link gaps of 1.3 s and the broker down 10 s at 5 Hz: {received} actions reached the robot, {applied} applied, {stale} stale (all refused), 0 stale applied"
        );
    }
}

/// Issue 46: one huge record (a scan of 60,000 beams, about 0.5 MB) among ordinary ones, with a
/// step watchdog of 2 s. Whatever Telegraf does with it (the echo it re-parses in time growing
/// with the square of the field count, seconds for this one), the monitor does not take the
/// blocked write for a hung step: the same child answers every record after it.
#[test]
fn a_huge_record_costs_its_own_time_and_every_record_after_it_is_answered() {
    for (version, bin) in real_telegraf::versions() {
        let Some(s) =
            setup(|c: String| c.replacen("\"run\"", "\"run\", \"--step-timeout\", \"2s\"", 1))
        else {
            return;
        };
        let telegraf = Telegraf::start(version, &bin, &s.conf, &[]);
        wait_subscribed(&s.broker, "telegraf-tessla-in", "tessla", 0);
        let child = telegraf.wait_child(&[], Duration::from_secs(10));
        let mut payloads = messages(31);
        let mut huge: serde_json::Value = serde_json::from_slice(&payloads[10]).unwrap();
        huge["lidar"] = serde_json::json!(vec![1.5f64; 60_000]);
        payloads[10] = serde_json::to_vec(&huge).unwrap();
        publish_at(s.broker.port, &payloads, 5.0, |_| {});
        wait_echoed(&s.influx, 31, || telegraf.log());
        let deadline = Instant::now() + Duration::from_secs(60);
        while count(&s.influx, "SELECT count(seq) FROM action") < 31 {
            assert!(
                Instant::now() < deadline,
                "Telegraf {version}: {} of 31 actions\n{}",
                count(&s.influx, "SELECT count(seq) FROM action"),
                telegraf.log()
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        assert_eq!(
            telegraf.children(),
            vec![child],
            "Telegraf {version}: the same child"
        );
        let log = telegraf.stop();
        assert!(!log.contains("exit status 4"), "Telegraf {version}:\n{log}");
        assert_eq!(echoed(&s.influx).values().sum::<usize>(), 31);
    }
}
