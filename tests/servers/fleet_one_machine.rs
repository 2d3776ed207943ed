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
//!   Telegraf logged an error;
//! - `start.sh --fleet`: the fleet example end to end (docs/fleet.md's walkthrough), its
//!   fleet lines, the coordinated slow-downs on the robots' MQTT topics, both partitions
//!   joined, and the fleet level handed over when its holder's Telegraf gets SIGTERM.

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

/// `start.sh ARGS` with its ports, folder and binaries from the environment, once it said
/// "fleet ready".
fn launch(nats: &Path, version: &str, telegraf: &Path, args: &[&str]) -> (Fleet, u16, u16) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let (nats_port, mqtt_port) = (free_port(), free_port());
    let child = Command::new("bash")
        .arg(root.join("examples/fleet-one-machine/start.sh"))
        .args(args)
        .env("FLEET_DIR", dir.path())
        .env("FLEET_NATS_PORT", nats_port.to_string())
        .env("FLEET_MQTT_PORT", mqtt_port.to_string())
        .env("TELEGRAF", telegraf)
        .env("NATS_SERVER", nats)
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
    (fleet, nats_port, mqtt_port)
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
    let (mut fleet, nats_port, mqtt_port) = launch(&nats, version, &telegraf, &[]);
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

/// The Telegrafs `start.sh` runs (its children whose command line names a `telegraf-p*.conf`),
/// each with the log it writes (`telegraf-p<N>-<member>.log`, from its environment).
fn telegrafs(fleet: &Fleet) -> Vec<(u32, String)> {
    let Some(child) = fleet.child.as_ref() else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for pid in real_telegraf::children_of(child.id()) {
        let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
        if !String::from_utf8_lossy(&cmdline).contains("telegraf-p") {
            continue;
        }
        let environ = std::fs::read(format!("/proc/{pid}/environ")).unwrap_or_default();
        let var = |name: &str| {
            environ
                .split(|b| *b == 0)
                .find_map(|kv| kv.strip_prefix(format!("{name}=").as_bytes()))
                .map(|v| String::from_utf8_lossy(v).into_owned())
                .unwrap_or_default()
        };
        out.push((
            pid,
            format!(
                "telegraf-p{}-{}.log",
                var("FLEET_PARTITION"),
                var("TESSLA_MEMBER")
            ),
        ));
    }
    out
}

/// Every line of the fleet's output files (`fleet-p<N>-<member>.lp`), each file in order.
fn fleet_output(fleet: &Fleet) -> Vec<String> {
    let mut names: Vec<_> = std::fs::read_dir(fleet.dir.path())
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    names.sort();
    names
        .iter()
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("fleet-p") && n.ends_with(".lp"))
        })
        .flat_map(|p| {
            std::fs::read_to_string(p)
                .unwrap_or_default()
                .lines()
                .map(str::to_string)
                .collect::<Vec<_>>()
        })
        .collect()
}

/// A field's value in a line-protocol line (`name=value` in its field set), as text.
fn field<'a>(line: &'a str, name: &str) -> Option<&'a str> {
    let fields = line.split(' ').nth(1)?;
    fields
        .split(',')
        .find_map(|kv| kv.strip_prefix(name)?.strip_prefix('='))
}

/// The fleet example end to end through the real Telegraf, by the walkthrough's commands
/// (docs/fleet.md, "Walkthrough: the example on two partitions through Telegraf"):
/// `start.sh --fleet`, `simulate --shared-floor 4`, one `replay` per robot to the MQTT gateway
/// at recorded pace. The fleet level over both partitions writes its lines (P2 violations,
/// closest distance, zone A occupancy, with sane values), both partitions join, the
/// coordinated slow-downs reach the zone-A robots (tb3-1 in p0, tb3-2 in p1) on their own MQTT
/// topics; SIGTERM to the Telegraf holding the fleet lease hands the fleet level to another
/// process, whose lines go on, each fleet step written once.
#[test]
fn fleet_example_runs_end_to_end_through_telegraf_and_survives_its_holders_sigterm() {
    let _one = nats_cluster::one_fleet_at_a_time();
    let Some(nats) = nats_cluster::require_nats_server() else {
        return;
    };
    let Some((version, telegraf)) = real_telegraf::versions().pop() else {
        return;
    };
    let (mut fleet, _, mqtt_port) = launch(&nats, version, &telegraf, &["--fleet"]);
    let dir = fleet.dir.path().to_path_buf();
    let zone_a = ["tb3-1", "tb3-2"];
    let inboxes: Vec<_> = zone_a
        .iter()
        .map(|r| {
            mqtt_client::subscribe(
                mqtt_port,
                &format!("robots/{r}/action"),
                &format!("{r}-actions"),
            )
        })
        .collect();

    // tessla-telegraf simulate --shared-floor 4 --output floor.lp
    let floor = dir.join("floor.lp");
    let out = Command::new(BIN)
        .args(["simulate", "--shared-floor", "4", "--output"])
        .arg(&floor)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&floor).unwrap();
    let mut replays = Vec::new();
    for r in 1..=4 {
        // grep "topic=tessla/tb3-$r " floor.lp > tb3-$r.lp
        let own: String = text
            .lines()
            .filter(|l| l.contains(&format!("topic=tessla/tb3-{r} ")))
            .map(|l| format!("{l}\n"))
            .collect();
        assert!(!own.is_empty(), "no records of tb3-{r}");
        let file = dir.join(format!("tb3-{r}.lp"));
        std::fs::write(&file, own).unwrap();
        // tessla-telegraf replay tb3-$r.lp --broker ... --topic robots/tb3-$r/telemetry
        //   --time-key time --speed 1 &
        replays.push(
            Command::new(BIN)
                .arg("replay")
                .arg(&file)
                .args(["--broker", &format!("mqtt://127.0.0.1:{mqtt_port}")])
                .args(["--topic", &format!("robots/tb3-{r}/telemetry")])
                .args(["--time-key", "time", "--speed", "1"])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap(),
        );
    }
    let steps = |lines: &[String]| {
        lines
            .iter()
            .filter(|l| l.starts_with("tessla_fleet,"))
            .count()
    };

    // The fleet level runs: its holder is one of the four, and it writes lines.
    let deadline = Instant::now() + Duration::from_secs(90);
    let (holder, holder_log) = loop {
        let held: Vec<(u32, String)> = telegrafs(&fleet)
            .into_iter()
            .filter(|(_, log)| {
                std::fs::read_to_string(dir.join(log))
                    .unwrap_or_default()
                    .contains("fleet: holding the fleet level")
            })
            .collect();
        if held.len() == 1 && steps(&fleet_output(&fleet)) >= 40 {
            break held[0].clone();
        }
        assert!(
            Instant::now() < deadline,
            "Telegraf {version}: no fleet holder writing lines ({held:?}, {} steps):\n{}",
            steps(&fleet_output(&fleet)),
            fleet.logs()
        );
        std::thread::sleep(Duration::from_millis(200));
    };

    // SIGTERM to the holder's Telegraf: another process takes the fleet level over.
    let before = steps(&fleet_output(&fleet));
    let _ = Command::new("kill")
        .args(["-TERM", &holder.to_string()])
        .status();
    let deadline = Instant::now() + Duration::from_secs(90);
    let successor = loop {
        let next = telegrafs(&fleet).into_iter().find(|(pid, log)| {
            *pid != holder
                && std::fs::read_to_string(dir.join(log))
                    .unwrap_or_default()
                    .contains("fleet: holding the fleet level")
        });
        if let Some(n) = next
            && steps(&fleet_output(&fleet)) >= before + 40
        {
            break n;
        }
        assert!(
            Instant::now() < deadline,
            "Telegraf {version}: nobody took the fleet level over from {holder_log} \
             ({} steps, {before} before the SIGTERM):\n{}",
            steps(&fleet_output(&fleet)),
            fleet.logs()
        );
        std::thread::sleep(Duration::from_millis(200));
    };
    assert!(
        !real_telegraf::alive(holder),
        "{holder_log} outlived SIGTERM"
    );
    for mut r in replays {
        let status = r.wait().unwrap();
        assert!(status.success(), "a replay failed: {status:?}");
    }

    // The slow-downs reached both zone-A robots, from the fleet.
    for (r, inbox) in zone_a.iter().zip(&inboxes) {
        let got = mqtt_client::collect(inbox, 3, Duration::from_secs(30));
        assert!(
            !got.is_empty(),
            "Telegraf {version}: {r} got no fleet slow-down:\n{}",
            fleet.logs()
        );
        for (_, payload) in &got {
            let row = real_telegraf::action_row(payload);
            assert_eq!(
                row.tags.get("robot").map(String::as_str),
                Some(*r),
                "{row:?}"
            );
            assert_eq!(
                row.tags.get("source").map(String::as_str),
                Some("fleet"),
                "{row:?}"
            );
            assert!(row.fields.contains_key("speed_limit"), "{row:?}");
            assert!(row.fields.contains_key("valid_until"), "{row:?}");
        }
    }

    // The fleet's lines: both partitions joined; P2 count, closest distance and zone A
    // occupancy within what four robots on one floor can give; every step written once.
    let lines = fleet_output(&fleet);
    for p in ["p0", "p1"] {
        assert!(
            lines.iter().any(|l| l.starts_with(&format!(
                "tessla_fleet_status,partition={p} state=\"live\",event=\"joined\""
            ))),
            "partition {p} never joined: {lines:#?}"
        );
    }
    let fleet_lines: Vec<&String> = lines
        .iter()
        .filter(|l| l.starts_with("tessla_fleet,"))
        .collect();
    let values = |name: &str| -> Vec<f64> {
        fleet_lines
            .iter()
            .filter_map(|l| field(l, name))
            .map(|v| v.trim_end_matches('i').parse::<f64>().unwrap())
            .collect()
    };
    let p2 = values("fleet_p2_violations");
    let closest = values("closest_distance");
    let zone = values("zone_a_occupancy");
    assert!(!p2.is_empty() && !closest.is_empty() && !zone.is_empty());
    assert!(p2.iter().all(|v| (0.0..=4.0).contains(v)), "{p2:?}");
    assert!(zone.iter().all(|v| (0.0..=4.0).contains(v)), "{zone:?}");
    assert!(zone.contains(&2.0), "{zone:?}");
    assert!(closest.iter().all(|v| *v > 0.0 && *v < 10.0), "{closest:?}");
    assert!(closest.iter().any(|v| *v < 0.5), "{closest:?}");
    let mut stamps: Vec<&str> = fleet_lines
        .iter()
        .filter_map(|l| l.rsplit(' ').next())
        .collect();
    let n = stamps.len();
    stamps.sort_unstable();
    stamps.dedup();
    assert_eq!(stamps.len(), n, "a fleet step written twice");
    eprintln!(
        "Telegraf {version}: fleet example through Telegraf: {n} fleet steps ({before} before SIGTERM to {holder_log}, then {}), slow-downs to {zone_a:?}",
        successor.1
    );
    let status = fleet.stop();
    assert_eq!(
        status.and_then(|s| s.code()),
        Some(0),
        "start.sh after SIGTERM:\n{}",
        fleet.logs()
    );
}
