//! The NATS fleet confs (`telegraf/fleet-nats/telegraf-p0.conf`, `telegraf-p1.conf`) run by the
//! real Telegraf (both pinned versions, built by `tools/build-telegraf.sh`) against the real
//! 3-node nats-server cluster secured as shipped (TLS, the users of `accounts.conf`, the shipped
//! subject mapping into 2 partitions, the MQTT gateway), with the real binary as each Telegraf's
//! `processors.execd` child. Only the endpoints are rewritten: the hosts `nats-N` become the
//! nodes' loopback ports, the CA path the test CA, `/usr/bin/tessla-telegraf` our binary.
//!
//! Per partition two Telegrafs run the same conf, as its header says: `a` (started first, takes
//! the partition's lease) and `b` (the standby), `TESSLA_MEMBER` different, `FLEET_PASSWORD` the
//! partition user's password. Robots (chosen so that the shipped mapping puts two in each
//! partition) publish the recorded run as the robot's JSON through the MQTT gateway at the
//! recorded pace, each as its own user over TLS (QoS 0, as the README asks), and subscribe, as
//! themselves, to their `robots/<robot>/action` (QoS 1: see [`ACTION_QOS`]). Checked:
//!
//! - every action equals, value for value, the action of an offline `run` with the conf's execd
//!   arguments (less `--state`, `--state-interval`) over the same records, made from the
//!   recorded lines with the tags `processors.regex` gives them (`robot`, `subject`): the conf
//!   takes the robot's own time (`json_time_key`), so the records' times are the recorded ones;
//! - exactly one Telegraf of each partition steps the monitors: the lease key names the child
//!   of the Telegraf started first (also after the standbys started); the partition that keeps
//!   its primary gets every action once (none missing, none doubled) and its standby's monitor
//!   steps nothing (its summary: 0 records); no action is doubled before the kill;
//! - a takeover: the primary of partition 0 is SIGKILLed mid-run (after a periodic save)
//!   together with its child (as systemd's `KillMode=mixed` kills what is left of a dead unit);
//!   the standby takes the lease within the lease TTL (plus 3 s of slack for a loaded machine),
//!   restores the saved state (some buffered records "already covered"), and its robots' actions
//!   continue to their last record; the records lost and answered twice are counted and
//!   printed, each at most one `--state-interval` of the partition's records (README);
//! - no error in any Telegraf's log (Telegraf's "file already closed" at a stop is counted);
//! - `telegraf --test --test-wait 2` exits 0 on each rewritten partition conf, with
//!   `inputs.nats_consumer` started and no error logged (Telegraf's `--test` exits 0 even when
//!   an input fails to start).
//!
//! Waits are bounded and generous (a busy 2-core machine); a failure shows the Telegraf logs.
//! Without nats-server or a Telegraf build the test skips loudly (fails with `REQUIRE_SERVERS=1`).

use crate::support::nats_cluster;
use crate::support::real_telegraf;
use crate::support::recorded;

use crate::support::BIN;
use nats_cluster::{Cluster, Login};
use real_telegraf::{Rewrite, Row, execd_args, offline};
use rumqttc::{Client, Event, MqttOptions, Packet, QoS, TlsConfiguration, Transport};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Robots in the fleet: two per partition under the shipped mapping.
const ROBOTS: usize = 4;
/// Records each robot publishes (the recorded run's first ones), at the recorded pace (5 Hz):
/// 15 s, so that the kill comes after a periodic save (`--state-interval 5s`) and the takeover
/// (lease TTL 3 s) with the robots still publishing.
const RECORDS: usize = 75;
/// The primary of partition 0 is killed once its robots have this many actions each (7 s in).
const KILL_AFTER: usize = 35;
/// The conf's lease TTL (`ttl=3s`) and `--state-interval` (5 s).
const TTL: Duration = Duration::from_secs(3);
const STATE_INTERVAL_S: usize = 5;
/// The robots' subscription to their actions: QoS 1, as a robot should (the gateway keeps an
/// action until the robot acknowledges it); `accounts.conf` lets a robot subscribe to
/// `$MQTT.sub.>`, where the gateway's JetStream consumer delivers it.
const ACTION_QOS: QoS = QoS::AtLeastOnce;
/// The bucket of the shipped confs.
const BUCKET: &str = "tessla_state";

/// The partition the shipped mapping (`{{partition(2,1)}}`: nats-server's FNV-1a of the robot
/// id, modulo 2) gives `robot`. Checked by the run: partition 1's primary steps exactly its
/// robots' records (its summary), partition 0's standby answers its robots after the kill.
pub(super) fn partition_of(robot: &str) -> usize {
    let mut h: u32 = 2_166_136_261;
    for b in robot.bytes() {
        h ^= u32::from(b);
        h = h.wrapping_mul(16_777_619);
    }
    (h % 2) as usize
}

/// `ROBOTS` robot ids, half in each partition.
pub(super) fn robot_ids() -> Vec<String> {
    let mut picked = Vec::new();
    let mut per = [0usize; 2];
    for k in 0.. {
        let id = format!("robot{k}");
        let p = partition_of(&id);
        if per[p] < ROBOTS / 2 {
            per[p] += 1;
            picked.push(id);
        }
        if picked.len() == ROBOTS {
            break;
        }
    }
    picked
}

/// The first `n` records of the recorded run.
pub(super) fn recorded_head(n: usize) -> Vec<String> {
    let text = std::fs::read_to_string(recorded::recorded_run_path()).unwrap();
    let lines: Vec<String> = text
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .take(n)
        .map(String::from)
        .collect();
    assert_eq!(
        lines.len(),
        n,
        "the recorded run is shorter than {n} records"
    );
    lines
}

/// The partition conf `p` with its endpoints moved onto the test cluster.
pub(super) fn rewritten(p: usize, cluster: &Cluster) -> String {
    let text = real_telegraf::shipped(&format!("telegraf/fleet-nats/telegraf-p{p}.conf"));
    let ca = cluster.certs().join("ca.pem").display().to_string();
    let mut r = Rewrite::new()
        // The --state URL's hosts first (they also contain "nats-1:4222" etc.).
        .replace(
            "nats://nats-1:4222,nats-2:4222,nats-3:4222/",
            format!("nats://{}/", cluster.hosts()),
        )
        .replace("/etc/telegraf/certs/ca.pem", ca)
        .replace("\"/usr/bin/tessla-telegraf\"", format!("{BIN:?}"));
    for n in 0..3 {
        r = r
            .replace(&format!("nats://nats-{}:4222", n + 1), cluster.url(n))
            .replace(
                &format!("ssl://nats-{}:8883", n + 1),
                format!("ssl://127.0.0.1:{}", cluster.nodes[n].ports.mqtt),
            );
    }
    let conf = r.apply(&text);
    assert!(
        !conf.contains("nats-1") && !conf.contains("nats-2") && !conf.contains("nats-3"),
        "a host of the shipped conf is left:\n{conf}"
    );
    conf
}

/// One Telegraf of a partition: `telegraf --config FILE` in a temporary folder, its log
/// (stderr) kept there. (`real_telegraf::Telegraf::start` waits for a "Connected" line, which
/// `inputs.nats_consumer` never logs: it says "Started the NATS consumer service" once
/// connected and subscribed.) Killed with its children on drop.
pub(super) struct Member {
    name: String,
    version: String,
    child: Option<Child>,
    dir: tempfile::TempDir,
}

impl Member {
    pub(super) fn start(
        name: &str,
        version: &str,
        binary: &Path,
        conf: &str,
        env: &[(&str, &str)],
    ) -> Member {
        let dir = tempfile::tempdir().unwrap();
        let conf_path = dir.path().join("telegraf.conf");
        std::fs::write(&conf_path, conf).unwrap();
        let child = Command::new(binary)
            .arg("--config")
            .arg(&conf_path)
            .envs(env.iter().copied())
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .stdin(Stdio::null())
            .stdout(std::fs::File::create(dir.path().join("telegraf.out")).unwrap())
            .stderr(std::fs::File::create(dir.path().join("telegraf.log")).unwrap())
            .spawn()
            .unwrap_or_else(|e| panic!("{}: {e}", binary.display()));
        let m = Member {
            name: name.to_string(),
            version: version.to_string(),
            child: Some(child),
            dir,
        };
        m.wait_for(
            |log| {
                log.lines().any(|l| {
                    l.contains("[inputs.nats_consumer]")
                        && l.contains("Started the NATS consumer service")
                })
            },
            Duration::from_secs(60),
            "inputs.nats_consumer connected and subscribed",
        );
        m
    }

    fn pid(&self) -> u32 {
        self.child.as_ref().map(|c| c.id()).unwrap_or(0)
    }

    pub(super) fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("telegraf.log")).unwrap_or_default()
    }

    fn wait_for(&self, ready: impl Fn(&str) -> bool, timeout: Duration, what: &str) {
        let deadline = Instant::now() + timeout;
        loop {
            let log = self.log();
            if ready(&log) {
                return;
            }
            assert!(
                real_telegraf::alive(self.pid()),
                "Telegraf {} ({}) exited while waiting for {what}; its log:\n{log}",
                self.version,
                self.name
            );
            assert!(
                Instant::now() < deadline,
                "Telegraf {} ({}) never showed {what} within {timeout:?}; its log:\n{log}",
                self.version,
                self.name
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The execd child (the monitor), once Telegraf has started it.
    pub(super) fn monitor(&self) -> u32 {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            if let Some(&pid) = real_telegraf::children_of(self.pid()).first() {
                return pid;
            }
            assert!(
                Instant::now() < deadline,
                "Telegraf {} ({}) started no monitor within 60 s; its log:\n{}",
                self.version,
                self.name,
                self.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// SIGKILL Telegraf and its children at once (a crash under `KillMode=mixed`); returns the
    /// log and when the signals were sent.
    fn kill_with_children(mut self) -> (String, Instant) {
        let mut pids = vec![self.pid()];
        pids.extend(real_telegraf::children_of(self.pid()));
        let pids: Vec<String> = pids.iter().map(u32::to_string).collect();
        let at = Instant::now();
        let status = Command::new("kill")
            .arg("-KILL")
            .args(&pids)
            .status()
            .unwrap();
        assert!(status.success(), "kill -KILL {pids:?}");
        let child = self.child.as_mut().unwrap();
        let _ = child.wait();
        self.child = None;
        (self.log(), at)
    }

    /// SIGTERM, as systemd stops Telegraf; waits (at most 60 s) and returns the exit status
    /// and the log.
    fn stop(mut self) -> (std::process::ExitStatus, String) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.pid().to_string()])
            .status();
        let deadline = Instant::now() + Duration::from_secs(60);
        let child = self.child.as_mut().unwrap();
        loop {
            if let Some(status) = child.try_wait().unwrap() {
                self.child = None;
                return (status, self.log());
            }
            assert!(
                Instant::now() < deadline,
                "Telegraf {} ({}) did not stop within 60 s of SIGTERM; its log:\n{}",
                self.version,
                self.name,
                self.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Member {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let kids = real_telegraf::children_of(child.id());
            let _ = child.kill();
            let _ = child.wait();
            for pid in kids {
                let _ = Command::new("kill")
                    .args(["-KILL", &pid.to_string()])
                    .status();
            }
        }
    }
}

/// Every action a robot receives: (when, robot, payload).
type Inbox = Arc<Mutex<Vec<(Instant, String, Vec<u8>)>>>;

/// `robot` subscribes, as itself over TLS, to `robots/<robot>/action` on node `n`'s MQTT
/// gateway; its messages go to `inbox`. Returns once subscribed (retried: the gateway may be
/// busy setting up its streams).
fn subscribe_actions(cluster: &Cluster, n: usize, robot: &str, inbox: &Inbox, tag: &str) {
    let mut last = String::new();
    for attempt in 0..3 {
        let mut o = MqttOptions::new(
            format!("{robot}-actions-{tag}-{attempt}"),
            "127.0.0.1",
            cluster.nodes[n].ports.mqtt,
        );
        o.set_credentials(robot, cluster.password(robot));
        o.set_keep_alive(Duration::from_secs(30));
        o.set_max_packet_size(1 << 20, 1 << 20);
        o.set_transport(Transport::tls_with_config(TlsConfiguration::Simple {
            ca: std::fs::read(cluster.certs().join("ca.pem")).unwrap(),
            alpn: None,
            client_auth: None,
        }));
        let (client, mut connection) = Client::new(o, 1024);
        client
            .subscribe(format!("robots/{robot}/action"), ACTION_QOS)
            .unwrap();
        let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<(), String>>();
        let inbox = Arc::clone(inbox);
        let id = robot.to_string();
        std::thread::spawn(move || {
            let _client: Client = client;
            let mut ready = false;
            for event in connection.iter() {
                match event {
                    Ok(Event::Incoming(Packet::SubAck(ack))) => {
                        let ok = ack
                            .return_codes
                            .iter()
                            .all(|c| matches!(c, rumqttc::SubscribeReasonCode::Success(_)));
                        ready = true;
                        let _ = ready_tx.send(if ok {
                            Ok(())
                        } else {
                            Err(format!("subscription refused: {:?}", ack.return_codes))
                        });
                    }
                    Ok(Event::Incoming(Packet::Publish(p))) => {
                        inbox.lock().unwrap().push((
                            Instant::now(),
                            id.clone(),
                            p.payload.to_vec(),
                        ));
                    }
                    Ok(_) => {}
                    Err(e) => {
                        if !ready {
                            let _ = ready_tx.send(Err(format!("{e:?}")));
                        }
                        return;
                    }
                }
            }
        });
        match ready_rx.recv_timeout(Duration::from_secs(30)) {
            Ok(Ok(())) => return,
            Ok(Err(e)) => last = e,
            Err(e) => last = e.to_string(),
        }
        std::thread::sleep(Duration::from_millis(500 * (attempt + 1)));
    }
    let log: Vec<String> = cluster
        .log(n)
        .lines()
        .filter(|l| l.contains("[ERR]") || l.contains("[WRN]") || l.contains(robot))
        .map(String::from)
        .collect();
    panic!(
        "{robot} could not subscribe to its actions (robots/{robot}/action, {ACTION_QOS:?}) on node {n}'s \
         MQTT gateway: {last}; the node's log says:\n{}",
        log.join("\n")
    );
}

/// `--broker mqtts://...` of node `n`'s MQTT gateway and the test CA.
fn gateway(cluster: &Cluster, n: usize) -> [String; 4] {
    [
        "--broker".into(),
        format!("mqtts://127.0.0.1:{}", cluster.nodes[n].ports.mqtt),
        "--tls-ca".into(),
        cluster.certs().join("ca.pem").display().to_string(),
    ]
}

/// Until the MQTT gateway of every node accepts a client (its first connection sets up its
/// JetStream streams).
pub(super) fn warm_up_mqtt(cluster: &Cluster, first_record: &str) {
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("one.lp");
    std::fs::write(&one, format!("{first_record}\n")).unwrap();
    for n in 0..3 {
        let deadline = Instant::now() + Duration::from_secs(90);
        loop {
            let out = Command::new(BIN)
                .args(["replay", one.to_str().unwrap(), "--topic", "warmup/robot"])
                .args(gateway(cluster, n))
                .args(["--username", "admin", "--password-env", "ADMIN_PASSWORD"])
                .env("ADMIN_PASSWORD", cluster.password("admin"))
                .output()
                .unwrap();
            if out.status.success() {
                break;
            }
            assert!(
                Instant::now() < deadline,
                "the MQTT gateway of node {n} never accepted a client: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            std::thread::sleep(Duration::from_millis(500));
        }
    }
}

/// A robot publishing `file` at the recorded pace as its JSON (time under `time`, actualSpeed
/// as a string, QoS 0 as the README asks of robots) on `robots/<robot>/telemetry`.
pub(super) fn robot(cluster: &Cluster, n: usize, id: &str, file: &Path) -> Child {
    Command::new(BIN)
        .args(["replay", file.to_str().unwrap()])
        .args(["--topic", &format!("robots/{id}/telemetry")])
        .args(["--speed", "1", "--time-key", "time"])
        .args(["--string-field", "actualSpeed", "--qos", "0"])
        .args(["--client-id", id])
        .args(gateway(cluster, n))
        .args(["--username", id, "--password-env", "ROBOT_PASSWORD"])
        .env("ROBOT_PASSWORD", cluster.password(id))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// The partitions' lease keys, read as admin over one connection (kept between reads, so that
/// a takeover is timed to a poll, not to a TLS handshake).
pub(super) struct Leases {
    rt: tokio::runtime::Runtime,
    url: String,
    login: Login,
    kv: Option<async_nats::jetstream::kv::Store>,
}

impl Leases {
    pub(super) fn new(cluster: &Cluster) -> Leases {
        Leases {
            rt: tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap(),
            url: cluster.url(1),
            login: cluster.login("admin"),
            kv: None,
        }
    }

    /// The holder (`host:pid`) of `partition`'s lease, if any (`None` also while the bucket
    /// cannot be read).
    fn holder(&mut self, partition: usize) -> Option<String> {
        let (url, login) = (&self.url, &self.login);
        let kv = &mut self.kv;
        self.rt.block_on(async {
            if kv.is_none() {
                let client = login.connect(url.as_str()).await.ok()?;
                let js = async_nats::jetstream::new(client);
                *kv = Some(js.get_key_value(BUCKET).await.ok()?);
            }
            let entry = tokio::time::timeout(
                Duration::from_secs(5),
                kv.as_ref()?.entry(format!("lease.vp{partition}")),
            )
            .await;
            let Ok(Ok(entry)) = entry else {
                *kv = None;
                return None;
            };
            let e = entry?;
            (e.operation == async_nats::jetstream::kv::Operation::Put)
                .then(|| String::from_utf8_lossy(&e.value).into_owned())
        })
    }

    /// Wait until monitor `pid` holds `partition`'s lease; returns when it was first seen.
    pub(super) fn wait_for(
        &mut self,
        partition: usize,
        pid: u32,
        timeout: Duration,
        logs: &dyn Fn() -> String,
    ) -> Instant {
        let deadline = Instant::now() + timeout;
        let mut last = None;
        loop {
            last = self.holder(partition).or(last);
            if last
                .as_deref()
                .is_some_and(|h| h.ends_with(&format!(":{pid}")))
            {
                return Instant::now();
            }
            assert!(
                Instant::now() < deadline,
                "partition p{partition}: monitor {pid} did not hold the lease within {timeout:?} \
                 (holder: {last:?}); logs:\n{}",
                logs()
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// The actions an offline run gives for `robots`' records: robot -> (time in ms -> row).
fn expected_actions(
    conf: &str,
    robots: &[String],
    records: &[String],
) -> BTreeMap<String, BTreeMap<i64, Row>> {
    let mut input = String::new();
    for id in robots {
        let subject = format!("fleet.{}.robots.{id}.telemetry", partition_of(id));
        for line in records {
            let rest = line
                .strip_prefix("mqtt_consumer,host=turtlebot3,topic=tessla ")
                .expect("a recorded line with the recorder's tags");
            // What processors.regex hands the monitor: the subject tag of nats_consumer and
            // the robot tag made from it (no host: omit_hostname).
            input.push_str(&format!(
                "mqtt_consumer,robot={id},subject={subject} {rest}\n"
            ));
        }
    }
    let out = offline(&execd_args(conf), &input);
    let mut want: BTreeMap<String, BTreeMap<i64, Row>> = BTreeMap::new();
    for row in real_telegraf::parse_lines(&out, "action") {
        let robot = row.tags["robot"].clone();
        let ms = row.time / 1_000_000;
        assert_eq!(row.time % 1_000_000, 0, "{row:?}");
        assert!(
            want.entry(robot).or_default().insert(ms, row).is_none(),
            "two offline actions in one ms"
        );
    }
    for id in robots {
        assert_eq!(
            want.get(id).map(BTreeMap::len),
            Some(records.len()),
            "offline: one action per record of {id}"
        );
    }
    want
}

/// The lines of a Telegraf log that report an error. Telegraf < 1.37 logs every line of its
/// execd child's stderr at E!, so our own I! and W! lines are not errors.
fn errors_in(log: &str) -> Vec<&str> {
    log.lines()
        .filter(|l| {
            l.contains(" E! ")
                && !l.contains("[processors.execd] stderr: \"I! ")
                && !l.contains("[processors.execd] stderr: \"W! ")
        })
        .collect()
}

/// Whether an action as received (JSON, ms) is the offline one, value for value.
fn same_action(got: &Row, want: &Row) -> Result<(), String> {
    if got.tags != want.tags {
        return Err(format!("tags {:?} != offline {:?}", got.tags, want.tags));
    }
    if got.fields.keys().ne(want.fields.keys()) {
        return Err(format!(
            "fields {:?} != offline {:?}",
            got.fields.keys().collect::<Vec<_>>(),
            want.fields.keys().collect::<Vec<_>>()
        ));
    }
    for (k, g) in &got.fields {
        if !real_telegraf::same_value(g, &want.fields[k]) {
            return Err(format!("field {k}: {g:?} != offline {:?}", want.fields[k]));
        }
    }
    Ok(())
}

#[test]
fn fleet_nats_confs_under_real_telegraf_take_over_and_match_an_offline_run() {
    // Each starts a cluster and several Telegrafs on a 2-core machine.
    let _fleet = nats_cluster::one_fleet_at_a_time();
    for (version, bin) in real_telegraf::versions() {
        let started = Instant::now();
        let robots = robot_ids();
        let Some(cluster) = Cluster::start_secured(&nats_cluster::shipped_mapping(), &robots)
        else {
            return;
        };
        let records = recorded_head(RECORDS);
        let confs: Vec<String> = (0..2).map(|p| rewritten(p, &cluster)).collect();
        warm_up_mqtt(&cluster, &records[0]);

        let inbox: Inbox = Arc::default();
        for (k, id) in robots.iter().enumerate() {
            subscribe_actions(&cluster, (k + 1) % 3, id, &inbox, version);
        }

        // Primaries first, each taking its partition's lease, then the standbys.
        let env = |p: usize, member: &'static str| -> Vec<(&'static str, String)> {
            vec![
                ("FLEET_PASSWORD", cluster.password(&format!("fleet-p{p}"))),
                ("TESSLA_MEMBER", member.to_string()),
            ]
        };
        let start = |p: usize, member: &'static str| -> Member {
            let env = env(p, member);
            let env: Vec<(&str, &str)> = env.iter().map(|(k, v)| (*k, v.as_str())).collect();
            Member::start(&format!("p{p}-{member}"), version, &bin, &confs[p], &env)
        };
        let mut leases = Leases::new(&cluster);
        let mut primaries: Vec<Option<Member>> = Vec::new();
        let mut primary_monitors = Vec::new();
        for p in 0..2 {
            let m = start(p, "a");
            let monitor = m.monitor();
            leases.wait_for(p, monitor, Duration::from_secs(60), &|| m.log());
            primary_monitors.push(monitor);
            primaries.push(Some(m));
        }
        let standbys: Vec<Member> = (0..2).map(|p| start(p, "b")).collect();
        let standby_monitors: Vec<u32> = standbys.iter().map(Member::monitor).collect();
        // Each standby's monitor has connected and found the lease held.
        for s in &standbys {
            s.wait_for(
                |log| log.contains("standing by"),
                Duration::from_secs(60),
                "its monitor standing by",
            );
        }
        let all_logs = |primaries: &[Option<Member>], standbys: &[Member]| -> String {
            primaries
                .iter()
                .flatten()
                .chain(standbys)
                .map(|m| format!("--- Telegraf {} {}:\n{}", m.version, m.name, m.log()))
                .collect::<Vec<_>>()
                .join("\n")
        };
        for (p, monitor) in primary_monitors.iter().enumerate() {
            let holder = leases.holder(p);
            assert!(
                holder
                    .as_deref()
                    .is_some_and(|h| h.ends_with(&format!(":{monitor}"))),
                "p{p}: the lease moved to {holder:?} when the standby started; logs:\n{}",
                all_logs(&primaries, &standbys)
            );
        }

        // The robots, each on a gateway of its own node.
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("head.lp");
        std::fs::write(&file, records.join("\n") + "\n").unwrap();
        let publishers: Vec<Child> = robots
            .iter()
            .enumerate()
            .map(|(k, id)| robot(&cluster, k % 3, id, &file))
            .collect();
        let publishing = Instant::now();
        let count_p = |p: usize| {
            inbox
                .lock()
                .unwrap()
                .iter()
                .filter(|(_, r, _)| partition_of(r) == p)
                .count()
        };
        let deadline = Instant::now() + Duration::from_secs(120);
        while count_p(0) < KILL_AFTER * ROBOTS / 2 {
            assert!(
                Instant::now() < deadline,
                "Telegraf {version}: partition 0's robots got {} actions in 120 s; logs:\n{}",
                count_p(0),
                all_logs(&primaries, &standbys)
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        // The crash: partition 0's primary and its monitor, SIGKILLed together.
        let before_kill = inbox.lock().unwrap().len();
        let (killed_log, killed_at) = primaries[0].take().unwrap().kill_with_children();
        let taken_at = leases.wait_for(
            0,
            standby_monitors[0],
            TTL + Duration::from_secs(30),
            &|| {
                format!(
                    "--- killed p0-a:\n{killed_log}\n{}",
                    all_logs(&primaries, &standbys)
                )
            },
        );
        let takeover = taken_at - killed_at;

        for (id, r) in robots.iter().zip(publishers) {
            let out = r.wait_with_output().unwrap();
            assert!(
                out.status.success(),
                "robot {id}'s replay failed: {}\n{}",
                out.status,
                String::from_utf8_lossy(&out.stderr)
            );
        }
        let published = Instant::now();
        // Every robot's last record answered (or 60 s without it), then a quiet second for
        // repeats still in flight.
        let last_ms = {
            let t: i64 = records[RECORDS - 1]
                .rsplit(' ')
                .next()
                .unwrap()
                .parse()
                .unwrap();
            t / 1_000_000
        };
        let answered_last = |id: &str| {
            inbox
                .lock()
                .unwrap()
                .iter()
                .any(|(_, r, p)| r == id && real_telegraf::action_row(p).time == last_ms)
        };
        let deadline = Instant::now() + Duration::from_secs(60);
        while !robots.iter().all(|r| answered_last(r)) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(50));
        }
        std::thread::sleep(Duration::from_secs(1));

        // Stop the survivors as systemd does (p1's standby first, so that it never steps);
        // each saves and releases.
        let mut logs = format!("--- Telegraf {version} p0-a (killed):\n{killed_log}\n");
        let mut stopped = Vec::new();
        let mut standbys = standbys.into_iter();
        let (p0b, p1b) = (standbys.next().unwrap(), standbys.next().unwrap());
        let p1a = primaries[1].take().unwrap();
        for m in [p1b, p1a, p0b] {
            let name = m.name.clone();
            let (status, log) = m.stop();
            logs.push_str(&format!(
                "--- Telegraf {version} {name} ({status}):\n{log}\n"
            ));
            stopped.push((name, status, log));
        }
        let actions = std::mem::take(&mut *inbox.lock().unwrap());
        assert!(
            stopped.iter().all(|(_, s, _)| s.success()),
            "a Telegraf did not exit 0 at SIGTERM:\n{logs}"
        );

        // Every action against the offline run.
        let want = expected_actions(&confs[0], &robots, &records);
        let mut got: BTreeMap<String, BTreeMap<i64, Vec<(Instant, Row)>>> = BTreeMap::new();
        for (at, id, payload) in &actions {
            let row = real_telegraf::action_row(payload);
            assert_eq!(
                row.tags.get("robot"),
                Some(id),
                "an action on robots/{id}/action for another robot: {}",
                String::from_utf8_lossy(payload)
            );
            got.entry(id.clone())
                .or_default()
                .entry(row.time)
                .or_default()
                .push((*at, row));
        }
        let mut lost = [0usize; 2];
        let mut doubled = [0usize; 2];
        let mut doubled_before_kill = 0;
        for id in &robots {
            let p = partition_of(id);
            let mine = got.get(id).cloned().unwrap_or_default();
            for (ms, copies) in &mine {
                let Some(w) = want[id].get(ms) else {
                    panic!(
                        "Telegraf {version}: {id} got an action for no record of its own \
                         (time {ms} ms): {:?}\n{logs}",
                        copies[0].1
                    );
                };
                for (_, g) in copies {
                    if let Err(e) = same_action(g, w) {
                        panic!(
                            "Telegraf {version}: {id}'s action at {ms} ms differs from the \
                             offline run: {e}\nreceived {g:?}\noffline {w:?}\n{logs}"
                        );
                    }
                }
                doubled[p] += copies.len() - 1;
                doubled_before_kill += copies
                    .iter()
                    .filter(|(at, _)| *at < killed_at)
                    .count()
                    .saturating_sub(1);
            }
            lost[p] += want[id].keys().filter(|ms| !mine.contains_key(ms)).count();
        }
        // The first action of each robot of partition 0 after the takeover, and the pause.
        let resumed = actions
            .iter()
            .filter(|(at, r, _)| partition_of(r) == 0 && *at > taken_at)
            .map(|(at, _, _)| *at)
            .min();
        let mut p0_times: Vec<Instant> = actions
            .iter()
            .filter(|(_, r, _)| partition_of(r) == 0)
            .map(|(at, _, _)| *at)
            .collect();
        p0_times.sort();
        let pause = p0_times
            .windows(2)
            .map(|w| w[1] - w[0])
            .max()
            .unwrap_or_default();
        let per_partition = RECORDS * ROBOTS / 2;
        eprintln!(
            "Telegraf {version}: {ROBOTS} robots x {RECORDS} records ({per_partition} per partition); \
             {} actions received ({before_kill} before the kill); p0's primary killed {} ms after \
             the robots started; lease taken by the standby {} ms after the kill (TTL {} ms); \
             p0's actions resumed {} ms after the kill, longest pause between p0 actions {} ms; \
             p0: {} lost, {} answered twice; p1 (primary kept): {} lost, {} answered twice; \
             run took {:.1} s (publishing {:.1} s)",
            actions.len(),
            (killed_at - publishing).as_millis(),
            takeover.as_millis(),
            TTL.as_millis(),
            resumed.map_or("never".to_string(), |r| (r - killed_at)
                .as_millis()
                .to_string()),
            pause.as_millis(),
            lost[0],
            doubled[0],
            lost[1],
            doubled[1],
            started.elapsed().as_secs_f64(),
            (published - publishing).as_secs_f64(),
        );

        // One stepper per partition: the partition that kept its primary answered every record
        // once, and nothing was doubled before the kill.
        assert_eq!(
            (lost[1], doubled[1]),
            (0, 0),
            "Telegraf {version}: partition 1 (no kill): records lost, answered twice\n{logs}"
        );
        assert_eq!(
            doubled_before_kill, 0,
            "Telegraf {version}: actions doubled before the kill: two Telegrafs stepped\n{logs}"
        );
        // The takeover: within the lease TTL (plus slack for a loaded machine), the robots'
        // actions continue to their last record, at most --state-interval of records lost.
        assert!(
            takeover <= TTL + Duration::from_secs(3),
            "Telegraf {version}: takeover took {takeover:?} (TTL {TTL:?})\n{logs}"
        );
        for id in robots.iter().filter(|r| partition_of(r) == 0) {
            assert!(
                got.get(id).is_some_and(|m| m.contains_key(&last_ms)),
                "Telegraf {version}: {id}'s actions did not continue after the takeover\n{logs}"
            );
        }
        // A partition's records in one --state-interval: 2 robots at 5 Hz.
        let bound = STATE_INTERVAL_S * 5 * ROBOTS / 2;
        assert!(
            lost[0] <= bound,
            "Telegraf {version}: {} of p0's records lost at the takeover (bound {bound})\n{logs}",
            lost[0]
        );
        assert!(
            doubled[0] <= bound + 10,
            "Telegraf {version}: {} of p0's actions sent twice (records since the last save \
             at most {bound})\n{logs}",
            doubled[0]
        );
        // What the monitors say through Telegraf's log (our stderr; Telegraf < 1.37 logs
        // every line of it at E!). The standby of p0 took over from the saved state: the kill
        // came after a periodic save, so some of its buffered records were already covered.
        let log_of = |name: &str| &stopped.iter().find(|(n, _, _)| n == name).unwrap().2;
        let took_over = log_of("p0-b")
            .lines()
            .find_map(|l| l.split("lease: holding partition p0; replayed ").nth(1))
            .unwrap_or_else(|| panic!("Telegraf {version}: p0-b never took over\n{logs}"));
        let covered: usize = took_over
            .split(" buffered records (")
            .nth(1)
            .and_then(|r| r.split(' ').next())
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("{took_over}"));
        assert!(
            covered > 0,
            "Telegraf {version}: p0-b restored nothing from the saved state: {took_over}\n{logs}"
        );
        // p1's standby never stepped; its primary stepped every record of p1. The summary is a
        // monitor's last line, which Telegraf may fail to read at a stop ("file already
        // closed"): when it is missing, that is said, not failed.
        for (name, stepped) in [("p1-b", 0), ("p1-a", per_partition)] {
            let summary = log_of(name).lines().find(|l| l.contains("summary: "));
            match summary {
                Some(l) => assert!(
                    l.contains(&format!("summary: {stepped} records,")),
                    "Telegraf {version}: {name} should have stepped {stepped} records: {l}\n{logs}"
                ),
                None => eprintln!(
                    "Telegraf {version}: {name}'s summary line is missing from Telegraf's log"
                ),
            }
        }
        assert!(
            !log_of("p1-b").contains("lease: holding partition"),
            "Telegraf {version}: p1's standby took the lease\n{logs}"
        );
        // No error from Telegraf or a monitor; Telegraf's "file already closed" at a stop
        // (its execd reads the child's pipes after Cmd.Wait closed them) is counted, not failed.
        let closed = logs
            .lines()
            .filter(|l| l.contains(" E! ") && l.contains("file already closed"))
            .count();
        let errors: Vec<&str> = errors_in(&logs)
            .into_iter()
            .filter(|l| !l.contains("file already closed"))
            .collect();
        assert!(
            errors.is_empty(),
            "Telegraf {version}: errors logged:\n{}\n{logs}",
            errors.join("\n")
        );
        if closed > 0 {
            eprintln!(
                "Telegraf {version}: {closed} \"file already closed\" errors at the stops \
                 (Telegraf's execd read the child's pipes after Cmd.Wait closed them)"
            );
        }
    }
}

#[test]
fn fleet_nats_confs_pass_telegraf_test() {
    // Each starts a cluster and several Telegrafs on a 2-core machine.
    let _fleet = nats_cluster::one_fleet_at_a_time();
    let versions = real_telegraf::versions();
    if versions.is_empty() {
        return;
    }
    let Some(cluster) = Cluster::start_secured(&nats_cluster::shipped_mapping(), &robot_ids())
    else {
        return;
    };
    for (version, bin) in versions {
        for p in 0..2 {
            let dir = tempfile::tempdir().unwrap();
            let conf: PathBuf = dir.path().join("telegraf.conf");
            std::fs::write(&conf, rewritten(p, &cluster)).unwrap();
            let mut child = Command::new(&bin)
                .arg("--config")
                .arg(&conf)
                .args(["--test", "--test-wait", "2"])
                .env("FLEET_PASSWORD", cluster.password(&format!("fleet-p{p}")))
                .env("TESSLA_MEMBER", "test")
                .stdin(Stdio::null())
                .stdout(std::fs::File::create(dir.path().join("out")).unwrap())
                .stderr(std::fs::File::create(dir.path().join("err")).unwrap())
                .spawn()
                .unwrap();
            let deadline = Instant::now() + Duration::from_secs(120);
            let status = loop {
                if let Some(s) = child.try_wait().unwrap() {
                    break Some(s);
                }
                if Instant::now() > deadline {
                    let _ = child.kill();
                    let _ = child.wait();
                    break None;
                }
                std::thread::sleep(Duration::from_millis(50));
            };
            let out = std::fs::read_to_string(dir.path().join("out")).unwrap_or_default();
            let err = std::fs::read_to_string(dir.path().join("err")).unwrap_or_default();
            assert!(
                status.is_some_and(|s| s.success()),
                "Telegraf {version} --test on telegraf-p{p}.conf: {status:?} (none: still running \
                 after 120 s)\nstdout:\n{out}\nstderr:\n{err}"
            );
            // `--test` exits 0 even when an input cannot start (Telegraf's testStartInputs
            // logs "E! [agent] Starting input ..." and goes on without it): the input must
            // have connected and subscribed, and nothing may be logged as an error.
            let errors = errors_in(&err);
            assert!(
                errors.is_empty() && err.contains("Started the NATS consumer service"),
                "Telegraf {version} --test on telegraf-p{p}.conf exited 0, but its input did \
                 not start or an error was logged:\n{}\nstderr:\n{err}",
                errors.join("\n")
            );
            eprintln!(
                "Telegraf {version}: --test --test-wait 2 on telegraf-p{p}.conf: exit 0, \
                 nats_consumer started, no error"
            );
        }
    }
}
