//! Issue 46: the broker restarted under a running Telegraf with the shipped `telegraf/telegraf.conf`
//! (`mqtt_consumer` with QoS 1 and a persistent session), a Mosquitto with `persistence true`
//! (stopped with SIGTERM, so it saves its sessions, and started again on the same port and
//! database), a robot publishing at QoS 1 at 5 Hz, and the real binary as Telegraf's child. What
//! was answered is counted from the echoes in InfluxDB (each message's `seq`).

use super::telegraf_real_failures::{echoed, messages, robust_client};
use crate::support::real_telegraf::{self, Rewrite, Telegraf};
use crate::support::servers;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// A Mosquitto with `persistence true` in a folder of its own, which can be stopped the way
/// `systemctl stop` does (SIGTERM: it writes its database) and started again on the same port.
struct PersistentBroker {
    binary: PathBuf,
    port: u16,
    dir: tempfile::TempDir,
    child: Option<Child>,
}

impl PersistentBroker {
    fn start() -> Option<PersistentBroker> {
        let binary = servers::require("mosquitto", "mosquitto")?;
        let dir = tempfile::tempdir().unwrap();
        // Mosquitto started as root runs as user `mosquitto`: it must be able to write its
        // database here.
        std::fs::set_permissions(
            dir.path(),
            std::os::unix::fs::PermissionsExt::from_mode(0o777),
        )
        .unwrap();
        let port = servers::free_port();
        let conf = format!(
            "listener {port} 127.0.0.1\nallow_anonymous true\npersistence true\n\
             persistence_location {}/\nlog_dest stderr\nlog_type all\n",
            dir.path().display()
        );
        std::fs::write(dir.path().join("mosquitto.conf"), conf).unwrap();
        let mut b = PersistentBroker {
            binary,
            port,
            dir,
            child: None,
        };
        b.run();
        Some(b)
    }

    fn log_path(&self) -> PathBuf {
        self.dir.path().join("mosquitto.log")
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.log_path()).unwrap_or_default()
    }

    fn run(&mut self) {
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.log_path())
            .unwrap();
        let mut child = Command::new(&self.binary)
            .arg("-c")
            .arg(self.dir.path().join("mosquitto.conf"))
            .stdin(Stdio::null())
            .stdout(log.try_clone().unwrap())
            .stderr(log)
            .spawn()
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(30);
        while std::net::TcpStream::connect(("127.0.0.1", self.port)).is_err() {
            if let Ok(Some(status)) = child.try_wait() {
                panic!("mosquitto exited ({status}); log:\n{}", self.log());
            }
            assert!(Instant::now() < deadline, "mosquitto never listened");
            std::thread::sleep(Duration::from_millis(20));
        }
        self.child = Some(child);
    }

    /// SIGTERM and wait: Mosquitto saves its database (sessions, queued and in-flight messages).
    fn stop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = Command::new("kill")
                .args(["-TERM", &child.id().to_string()])
                .status();
            let _ = child.wait();
        }
    }

    fn mark(&self, what: &str) {
        if let Ok(mut f) = std::fs::OpenOptions::new()
            .append(true)
            .open(self.log_path())
        {
            let _ = writeln!(f, "---- test: {what}");
        }
    }
}

impl Drop for PersistentBroker {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// One run: 150 messages at 5 Hz; after message 50 the broker is stopped and started again 3 s
/// later (longer than the agent's 1 s `interval`: `mqtt_consumer` tries to reconnect in
/// `Gather` while the broker is down). Returns (the seqs answered, the number of them sent after
/// the restart, Telegraf's log, the broker's log).
fn run(version: &str, bin: &Path) -> Option<(usize, usize, String, String)> {
    const N: usize = 150;
    const AT: usize = 50;
    let mut broker = PersistentBroker::start()?;
    let influx = servers::Influxd::start()?;
    let state = tempfile::tempdir().unwrap();
    let conf = Rewrite::robot(crate::support::BIN, broker.port, Some(&influx.url("")))
        .state_in(state.path())
        .apply(&real_telegraf::shipped("telegraf/telegraf.conf"));
    let telegraf = Telegraf::start(version, bin, &conf, &[]);
    std::thread::sleep(Duration::from_secs(1));
    let stop = Arc::new(AtomicBool::new(false));
    let (robot, _) = robust_client(broker.port, "robot-out", None, stop.clone());
    let start = Instant::now();
    for (k, p) in messages(N).into_iter().enumerate() {
        let due = start + Duration::from_millis(200 * k as u64);
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        if k == AT {
            broker.mark("stop");
            broker.stop();
            std::thread::sleep(Duration::from_secs(3));
            broker.run();
            broker.mark("started again");
        }
        // The robot's client queues what it publishes while it reconnects.
        let _ = robot.try_publish("tessla", rumqttc::QoS::AtLeastOnce, false, p);
    }
    // Generous: whatever is still coming has 15 s to reach InfluxDB.
    let deadline = Instant::now() + Duration::from_secs(15);
    while echoed(&influx).len() < N && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(200));
    }
    let log = telegraf.stop();
    stop.store(true, Ordering::Relaxed);
    let seen = echoed(&influx);
    let after = seen.keys().filter(|&&s| s as usize >= AT).count();
    Some((seen.len(), after, log, broker.log()))
}

/// Issue 46, "the 1.33.3 persistence stall": Telegraf's, not ours. On 1.33.3 a reconnect that
/// fails while the broker is down (`Gather` calls `connect`, which on a network error cancels
/// the goroutine that reads the tracking accumulator's deliveries: `mqtt_consumer.go` lines
/// 183-193, meant for `Start`'s retry) leaves nobody to acknowledge: after the broker is back
/// Telegraf processes what the broker sends (our monitor answers it) but never sends a PUBACK,
/// so Mosquitto stops at `max_inflight_messages` (20) and sends nothing more. 1.38.0 and later
/// reconnect with paho's own auto-reconnect (telegraf PR #18452) and resume. The counts are
/// printed; a change on either pinned version fails the test.
#[test]
fn a_broker_restart_stalls_the_input_of_telegraf_1_33_3_after_20_messages_not_1_39_3() {
    for (version, bin) in real_telegraf::versions() {
        let Some((answered, after, log, blog)) = run(version, &bin) else {
            return;
        };
        let pubacks = blog
            .split("---- test: started again")
            .nth(1)
            .unwrap_or("")
            .matches("Received PUBACK from telegraf-tessla-in")
            .count();
        eprintln!(
            "Telegraf {version}: broker (persistence true) restarted after message 50 of 150, down 3 s: \
             {answered} answered, {after} of the 100 sent from the restart on; {pubacks} PUBACKs from Telegraf's input after the restart"
        );
        assert!(
            blog.contains("Saving in-memory database") && !blog.contains("Error saving"),
            "the broker saved its sessions:\n{blog}"
        );
        if version == "v1.33.3" {
            assert!(
                log.contains("[inputs.mqtt_consumer] Error in plugin: network Error"),
                "a reconnect failed while the broker was down:\n{log}"
            );
            assert!(
                after <= 20 && pubacks == 0,
                "Telegraf {version}: the stall (at most max_inflight_messages answered, none acknowledged) is gone: {after} answered, {pubacks} PUBACKs\n{log}"
            );
        } else {
            assert!(
                after >= 95 && pubacks >= 95,
                "Telegraf {version} resumes after the restart: {after} answered, {pubacks} PUBACKs\n{log}\n{blog}"
            );
        }
    }
}
