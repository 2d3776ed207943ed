//! The one-machine fleet (`examples/fleet-one-machine/`) started by its one documented command,
//! `start.sh`, with the real Telegraf (the newest pinned build) and the real nats-server, only
//! its ports, folder and binaries given through the environment the script documents: one
//! nats-server (state bucket and spec channel with `replicas=1`, the MQTT gateway, no TLS) and
//! two partitions with a standby each, four Telegrafs. Checked:
//!
//! - robots of both partitions (two each under the shipped mapping) publish the recorded run's
//!   head through the MQTT gateway, and each gets one action per record on its own
//!   `robots/<robot>/action`;
//! - `spec status` lists all four processes, live, two per partition, each with its own pid
//!   (its status key is unique per process);
//! - SIGTERM to the script stops every Telegraf, their monitors and the server (exit 0); no
//!   Telegraf logged an error.

use crate::support::BIN;
use crate::support::mqtt_client;
use crate::support::nats_cluster;
use crate::support::real_telegraf;
use crate::support::recorded;
use crate::support::servers::free_port;
use serde_json::Value;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Records each robot publishes.
const RECORDS: usize = 20;

/// The partition the shipped mapping (`{{partition(2,1)}}`, nats-server's FNV-1a of the robot
/// id modulo 2) gives `robot`.
fn partition_of(robot: &str) -> usize {
    let mut h: u32 = 2_166_136_261;
    for b in robot.bytes() {
        h ^= u32::from(b);
        h = h.wrapping_mul(16_777_619);
    }
    (h % 2) as usize
}

/// Four robot ids, two in each partition.
fn robot_ids() -> Vec<String> {
    let mut picked = Vec::new();
    let mut per = [0usize; 2];
    for k in 0.. {
        let id = format!("robot{k}");
        let p = partition_of(&id);
        if per[p] < 2 {
            per[p] += 1;
            picked.push(id);
        }
        if picked.len() == 4 {
            break;
        }
    }
    picked
}

/// `start.sh`, stopped with SIGTERM (and, if it does not exit, killed) on drop.
struct Fleet {
    child: Option<Child>,
    dir: tempfile::TempDir,
}

impl Fleet {
    fn out(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("start.out")).unwrap_or_default()
    }

    /// The script's output and every log in its folder, for a failure's message.
    fn logs(&self) -> String {
        let mut text = format!("start.sh said:\n{}\n", self.out());
        let mut names: Vec<_> = std::fs::read_dir(self.dir.path())
            .map(|d| d.flatten().map(|e| e.path()).collect())
            .unwrap_or_default();
        names.sort();
        for p in names {
            if p.extension().is_some_and(|e| e == "log") {
                let log = std::fs::read_to_string(&p).unwrap_or_default();
                let tail: Vec<&str> = log.lines().rev().take(30).collect();
                text.push_str(&format!("--- {} (last lines)\n", p.display()));
                for l in tail.iter().rev() {
                    text.push_str(l);
                    text.push('\n');
                }
            }
        }
        text
    }

    /// SIGTERM the script; its exit status once it stopped everything.
    fn stop(&mut self) -> Option<std::process::ExitStatus> {
        let mut child = self.child.take()?;
        let _ = Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status();
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            if let Ok(Some(status)) = child.try_wait() {
                return Some(status);
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                let _ = child.wait();
                return None;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for Fleet {
    fn drop(&mut self) {
        if let Some(child) = self.child.as_ref() {
            // What the script started, in case it does not get to stop them.
            let kids = real_telegraf::children_of(child.id());
            let grandkids: Vec<u32> = kids
                .iter()
                .flat_map(|k| real_telegraf::children_of(*k))
                .collect();
            if self.stop().is_none() {
                for pid in kids.iter().chain(&grandkids) {
                    let _ = Command::new("kill")
                        .args(["-KILL", &pid.to_string()])
                        .status();
                }
            }
        }
    }
}

fn spec_status(channel: &str, json: bool) -> (bool, String, String) {
    let mut cmd = Command::new(BIN);
    cmd.args(["spec", "status", "--channel", channel]);
    if json {
        cmd.arg("--json");
    }
    let out = cmd.output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The processes `spec status --json` lists.
fn processes(channel: &str) -> Vec<Value> {
    let (ok, out, err) = spec_status(channel, true);
    assert!(ok, "spec status: {err}");
    let v: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
    v["processes"].as_array().cloned().unwrap_or_default()
}

#[test]
fn one_machine_fleet_answers_both_partitions_and_spec_status_lists_four_processes() {
    let _one = nats_cluster::one_fleet_at_a_time();
    let Some(nats) = nats_cluster::require_nats_server() else {
        return;
    };
    let Some((version, telegraf)) = real_telegraf::versions().pop() else {
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let (nats_port, mqtt_port) = (free_port(), free_port());
    let child = Command::new("bash")
        .arg(root.join("examples/fleet-one-machine/start.sh"))
        .env("FLEET_DIR", dir.path())
        .env("FLEET_NATS_PORT", nats_port.to_string())
        .env("FLEET_MQTT_PORT", mqtt_port.to_string())
        .env("TELEGRAF", &telegraf)
        .env("NATS_SERVER", &nats)
        .env("TESSLA_TELEGRAF", BIN)
        .current_dir(root)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(dir.path().join("start.out")).unwrap())
        .stderr(std::fs::File::create(dir.path().join("start.err.log")).unwrap())
        .spawn()
        .unwrap();
    let mut fleet = Fleet {
        child: Some(child),
        dir,
    };
    let deadline = Instant::now() + Duration::from_secs(180);
    while !fleet.out().contains("fleet ready") {
        let exited = fleet
            .child
            .as_mut()
            .and_then(|c| c.try_wait().ok().flatten());
        assert!(
            exited.is_none(),
            "Telegraf {version}: start.sh exited ({exited:?}) before the fleet was ready:\n{}",
            fleet.logs()
        );
        assert!(
            Instant::now() < deadline,
            "Telegraf {version}: the fleet never got ready:\n{}",
            fleet.logs()
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    let channel = format!("nats://127.0.0.1:{nats_port}/tessla_specs");

    // The robots: each subscribed to its actions, then publishing the recorded run's head.
    let robots = robot_ids();
    let inboxes: Vec<_> = robots
        .iter()
        .map(|r| {
            mqtt_client::subscribe(
                mqtt_port,
                &format!("robots/{r}/action"),
                &format!("{r}-actions"),
            )
        })
        .collect();
    let text = std::fs::read_to_string(recorded::recorded_run_path()).unwrap();
    let head: Vec<&str> = text
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .take(RECORDS)
        .collect();
    let file = fleet.dir.path().join("head.lp");
    std::fs::write(&file, head.join("\n") + "\n").unwrap();
    for r in &robots {
        let out = Command::new(BIN)
            .args(["replay", file.to_str().unwrap()])
            .args(["--broker", &format!("mqtt://127.0.0.1:{mqtt_port}")])
            .args(["--topic", &format!("robots/{r}/telemetry")])
            .args(["--speed", "0", "--time-key", "time"])
            .args(["--string-field", "actualSpeed", "--qos", "0"])
            .args(["--client-id", r])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "replay of {r}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    for (r, inbox) in robots.iter().zip(&inboxes) {
        let got = mqtt_client::collect(inbox, RECORDS, Duration::from_secs(60));
        assert_eq!(
            got.len(),
            RECORDS,
            "Telegraf {version}: {r} (partition {}) got {} of its {RECORDS} actions:\n{}",
            partition_of(r),
            got.len(),
            fleet.logs()
        );
        for (_, payload) in &got {
            let row = real_telegraf::action_row(payload);
            assert_eq!(row.tags.get("robot"), Some(r), "{row:?}");
        }
    }

    // Four processes, two per partition, each its own key and pid, all live.
    let deadline = Instant::now() + Duration::from_secs(60);
    let listed = loop {
        let p = processes(&channel);
        if p.iter().filter(|p| p["state"] == "live").count() == 4 {
            break p;
        }
        assert!(
            Instant::now() < deadline,
            "Telegraf {version}: spec status never listed 4 live processes: {p:#?}\n{}",
            fleet.logs()
        );
        std::thread::sleep(Duration::from_millis(500));
    };
    assert_eq!(listed.len(), 4, "{listed:#?}");
    let mut partitions: Vec<&str> = listed
        .iter()
        .map(|p| p["partition"].as_str().unwrap_or(""))
        .collect();
    partitions.sort_unstable();
    assert_eq!(partitions, ["p0", "p0", "p1", "p1"], "{listed:#?}");
    let mut pids: Vec<u64> = listed.iter().filter_map(|p| p["pid"].as_u64()).collect();
    pids.sort_unstable();
    pids.dedup();
    assert_eq!(pids.len(), 4, "{listed:#?}");
    let mut keys: Vec<&str> = listed.iter().filter_map(|p| p["key"].as_str()).collect();
    keys.sort_unstable();
    keys.dedup();
    assert_eq!(keys.len(), 4, "{listed:#?}");
    let (ok, table, err) = spec_status(&channel, false);
    assert!(ok, "{err}");
    assert!(
        table.contains("Processes (4: 4 live, 0 silent, 0 stopped)"),
        "{table}"
    );

    eprintln!(
        "Telegraf {version}: one-machine fleet: {} robots answered ({RECORDS} actions each), spec status lists {} processes",
        robots.len(),
        listed.len()
    );
    // One command stops it all.
    let status = fleet.stop();
    assert_eq!(
        status.and_then(|s| s.code()),
        Some(0),
        "start.sh after SIGTERM:\n{}",
        fleet.logs()
    );
    for pid in &pids {
        assert!(
            !real_telegraf::alive(*pid as u32),
            "process {pid} outlived start.sh"
        );
    }
    for p in 0..2 {
        for m in ["a", "b"] {
            let log =
                std::fs::read_to_string(fleet.dir.path().join(format!("telegraf-p{p}-{m}.log")))
                    .unwrap_or_default();
            real_telegraf::assert_no_error(version, &log);
        }
    }
}
