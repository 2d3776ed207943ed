//! The fleet on a real 3-node NATS cluster secured as shipped (`telegraf/fleet-nats/`: TLS on
//! client, route and MQTT connections, the users and permissions of `accounts.conf`, the
//! shipped subject mapping into 2 partitions; JetStream, MQTT gateway), with 2 partitions × (primary + standby) stand-in Telegrafs running
//! the real binary with `--state nats://...?lease=p<N>`. Robots replay the recorded run over MQTT
//! into the gateway (the real `replay` subcommand). Mid-run the primary of partition 0 is
//! SIGKILLed, the primary of partition 1 SIGTERMed, and one NATS node killed. Checked: each
//! standby takes over; the set of actions equals one uninterrupted process's over the same
//! records except records in flight (counted; at most `--state-interval` of the partition's
//! records after SIGKILL, none after SIGTERM); no action differs from it, so no monitor restarted
//! from zero (and the standby's first action of each robot carries the running counts).
//! Every process logs in as the shipped users: the monitors of partition N as `fleet-pN`
//! (password from a file, TLS with the test CA), each robot as itself over MQTT with TLS; no
//! password appears in any process's output.

use crate::support::child;
use crate::support::nats_cluster;
use crate::support::nats_standin;

use nats_cluster::{Cluster, Login};
use nats_standin::{NatsStandIn, Published, action_message, robot_of, telemetry_line};
use std::collections::{BTreeMap, BTreeSet};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::support::BIN;

const ROBOTS: usize = 6;
/// Replay speed: the recorded 30 s run in 10 s.
const SPEED: &str = "3";
const INTERVAL_S: u64 = 1;
const TTL: &str = "2s";
/// The bucket the shipped permissions (accounts.conf) let the monitors use.
const BUCKET: &str = "tessla_state";

fn robot_ids() -> Vec<String> {
    (0..ROBOTS).map(|k| format!("robot{k}")).collect()
}

fn fixture() -> String {
    format!(
        "{}/tests/fixtures/robot/recorded_run.lp",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// Telemetry (subject, payload) and actions (when, robot, message) seen by the observer.
type Seen = (Vec<(String, Vec<u8>)>, Vec<Published>);

/// What the harness sees on the cluster: every telemetry message after the mapping, every action.
struct Observer {
    /// Telemetry messages seen so far, per partition.
    seen: std::sync::Arc<[std::sync::atomic::AtomicUsize; 2]>,
    /// Actions seen so far.
    actions: std::sync::Arc<std::sync::atomic::AtomicUsize>,
    stop: tokio::sync::oneshot::Sender<()>,
    done: std::thread::JoinHandle<Seen>,
}

impl Observer {
    fn start(url: &str, login: &Login) -> Observer {
        let login = login.clone();
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let url = url.to_string();
        let seen: std::sync::Arc<[std::sync::atomic::AtomicUsize; 2]> = Default::default();
        let counts = std::sync::Arc::clone(&seen);
        let actions_seen: std::sync::Arc<std::sync::atomic::AtomicUsize> = Default::default();
        let action_count = std::sync::Arc::clone(&actions_seen);
        let done = std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap();
            rt.block_on(async move {
                use futures_util::StreamExt;
                let client = login.connect(url.as_str()).await.unwrap();
                let mut telemetry = client
                    .subscribe("fleet.*.robots.*.telemetry")
                    .await
                    .unwrap();
                let mut actions = client.subscribe("robots.*.action").await.unwrap();
                client.flush().await.unwrap();
                ready_tx.send(()).unwrap();
                let (mut t, mut a) = (Vec::new(), Vec::new());
                let mut stopped = stopped;
                loop {
                    tokio::select! {
                        Some(m) = telemetry.next() => {
                            if let Some(c) = m.subject.as_str().split('.').nth(1)
                                .and_then(|p| p.parse::<usize>().ok())
                                .and_then(|p| counts.get(p))
                            {
                                c.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                            }
                            t.push((m.subject.to_string(), m.payload.to_vec()));
                        }
                        Some(m) = actions.next() => {
                            let robot = m.subject.as_str().split('.').nth(1).unwrap_or("").to_string();
                            a.push((Instant::now(), robot, String::from_utf8_lossy(&m.payload).into_owned()));
                            action_count.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                        }
                        _ = &mut stopped => break,
                    }
                }
                (t, a)
            })
        });
        ready_rx.recv_timeout(Duration::from_secs(30)).unwrap();
        Observer {
            seen,
            actions: actions_seen,
            stop,
            done,
        }
    }

    /// Wait until partition `p` has had `n` telemetry messages; returns the time.
    fn wait_for(&self, p: usize, n: usize) -> Instant {
        let deadline = Instant::now() + Duration::from_secs(120);
        while self.seen[p].load(std::sync::atomic::Ordering::SeqCst) < n {
            assert!(
                Instant::now() < deadline,
                "partition {p} never reached {n} records"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        Instant::now()
    }

    fn actions(&self) -> usize {
        self.actions.load(std::sync::atomic::Ordering::SeqCst)
    }

    fn total(&self) -> usize {
        self.seen
            .iter()
            .map(|c| c.load(std::sync::atomic::Ordering::SeqCst))
            .sum()
    }

    fn finish(self) -> Seen {
        let _ = self.stop.send(());
        self.done.join().unwrap()
    }
}

/// The value of the lease key of `partition` (`host:pid` of its holder), if any.
fn lease_holder(url: &str, login: &Login, partition: usize) -> Option<String> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let client = login.connect(url).await.ok()?;
        let js = async_nats::jetstream::new(client);
        let kv = js.get_key_value(BUCKET).await.ok()?;
        let e = kv.entry(format!("lease.vp{partition}")).await.ok()??;
        (e.operation == async_nats::jetstream::kv::Operation::Put)
            .then(|| String::from_utf8_lossy(&e.value).into_owned())
    })
}

fn wait_for_holder(url: &str, login: &Login, partition: usize, pid: u32) {
    let deadline = Instant::now() + Duration::from_secs(30);
    while Instant::now() < deadline {
        if lease_holder(url, login, partition).is_some_and(|h| h.ends_with(&format!(":{pid}"))) {
            return;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    panic!("partition {partition}: process {pid} never held the lease");
}

/// `--broker mqtts://...` of node 0's MQTT gateway and the test CA.
fn mqtt_tls(cluster: &Cluster) -> [String; 4] {
    [
        "--broker".into(),
        format!("mqtts://127.0.0.1:{}", cluster.nodes[0].ports.mqtt),
        "--tls-ca".into(),
        cluster.certs().join("ca.pem").display().to_string(),
    ]
}

fn robot(cluster: &Cluster, k: usize) -> Child {
    let id = format!("robot{k}");
    Command::new(BIN)
        .args([
            "replay",
            &fixture(),
            "--topic",
            &format!("robots/robot{k}/telemetry"),
            "--speed",
            SPEED,
            "--time-key",
            "time",
            "--string-field",
            "actualSpeed",
            // QoS 0: the 2.9 gateway stores every QoS 1 publish in JetStream and drops the
            // client when that store is unavailable for 4 s (a node loss may cause that).
            "--qos",
            "0",
            "--client-id",
            &format!("robot{k}"),
        ])
        .args(mqtt_tls(cluster))
        .args(["--username", &id, "--password-env", "ROBOT_PASSWORD"])
        .env("ROBOT_PASSWORD", cluster.password(&id))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Until the MQTT gateway accepts a client (its first connection sets up its JetStream streams).
fn warm_up_mqtt(cluster: &Cluster) {
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("one.lp");
    let first = std::fs::read_to_string(fixture()).unwrap();
    std::fs::write(&one, first.lines().next().unwrap()).unwrap();
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let out = Command::new(BIN)
            .args(["replay", one.to_str().unwrap(), "--topic", "warmup/robot"])
            .args(mqtt_tls(cluster))
            .args(["--username", "admin", "--password-env", "ADMIN_PASSWORD"])
            .env("ADMIN_PASSWORD", cluster.password("admin"))
            .output()
            .unwrap();
        if out.status.success() {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "the MQTT gateway never accepted a client: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        std::thread::sleep(Duration::from_millis(500));
    }
}

/// The actions one uninterrupted process computes from `lines`: robot -> messages.
fn reference(lines: &[String]) -> BTreeSet<(String, String)> {
    let input = lines.join("\n") + "\n";
    let (out, err, code) = child::run_text(
        &["run", "--no-passthrough", "--instance-by", "robot"],
        &input,
    );
    assert_eq!(code, 0, "{err}");
    out.lines().filter_map(action_message).collect()
}

fn timestamp(message: &str) -> i64 {
    serde_json::from_str::<serde_json::Value>(message).unwrap()["timestamp"]
        .as_i64()
        .unwrap()
}

#[test]
fn standbys_take_over_killed_primaries_with_the_monitor_state() {
    let _fleet = nats_cluster::one_fleet_at_a_time();
    let Some(mut cluster) = Cluster::start_secured(&nats_cluster::shipped_mapping(), &robot_ids())
    else {
        return;
    };
    let admin = cluster.login("admin");
    let observer = Observer::start(&cluster.url(1), &admin);
    // Each partition's password in a file (password-file=PATH), as a deployment keeps it.
    for p in 0..2 {
        std::fs::write(
            cluster.dir().join(format!("fleet-p{p}.password")),
            cluster.password(&format!("fleet-p{p}")) + "\n",
        )
        .unwrap();
    }
    let args = |p: usize| -> Vec<String> {
        vec![
            "--instance-by".into(),
            "robot".into(),
            "--state".into(),
            format!(
                "nats://{}/{BUCKET}?lease=p{p}&ttl={TTL}&replicas=3&user=fleet-p{p}&password-file={}&tls-ca={}",
                cluster.hosts(),
                cluster.dir().join(format!("fleet-p{p}.password")).display(),
                cluster.certs().join("ca.pem").display()
            ),
            "--state-interval".into(),
            format!("{INTERVAL_S}s"),
        ]
    };
    // Primaries first (each takes its partition's lease), then the standbys.
    let mut primaries = Vec::new();
    for p in 0..2 {
        let s = NatsStandIn::start(
            BIN,
            &format!("p{p}-a"),
            &cluster.url(0),
            p,
            &args(p),
            &cluster.login(&format!("fleet-p{p}")),
        );
        wait_for_holder(&cluster.url(0), &admin, p, s.pid());
        primaries.push(s);
    }
    let standbys: Vec<NatsStandIn> = (0..2)
        .map(|p| {
            NatsStandIn::start(
                BIN,
                &format!("p{p}-b"),
                &cluster.url(1),
                p,
                &args(p),
                &cluster.login(&format!("fleet-p{p}")),
            )
        })
        .collect();

    warm_up_mqtt(&cluster);
    let robots: Vec<Child> = (0..ROBOTS).map(|k| robot(&cluster, k)).collect();
    // Kill points by progress (the robots' start-up time varies): a partition has 3 robots
    // when the hash splits them evenly; its records so far are counted by the observer.
    let killed_at = observer.wait_for(0, 300);
    primaries[0].signal("KILL");
    let termed_at = observer.wait_for(1, 400);
    primaries[1].signal("TERM");
    while observer.total() < ROBOTS * 300 * 7 / 10 {
        std::thread::sleep(Duration::from_millis(5));
    }
    cluster.kill(2);
    let node_lost_at = Instant::now();
    let passwords: Vec<String> = ["fleet-p0", "fleet-p1", "admin"]
        .iter()
        .map(|u| u.to_string())
        .chain(robot_ids())
        .map(|u| cluster.password(&u))
        .collect();
    for r in robots {
        let out = r.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success(),
            "a robot's replay failed: {}\n{err}",
            out.status
        );
        assert!(!passwords.iter().any(|p| err.contains(p.as_str())), "{err}");
    }
    // Waited for, never slept on: each standby has taken over, been given every record of its
    // partition and stepped them all.
    let deadline = Instant::now() + Duration::from_secs(120);
    while !standbys.iter().enumerate().all(|(p, s)| {
        s.caught_up() && s.fed() == observer.seen[p].load(std::sync::atomic::Ordering::SeqCst)
    }) {
        assert!(
            Instant::now() < deadline,
            "the standbys never stepped every record of their partitions"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // Then every action published has reached the observer, unless the cluster lost some with
    // its node (at most once): those count as lost below.
    let published = || -> usize {
        primaries
            .iter()
            .chain(&standbys)
            .map(|s| s.published())
            .sum()
    };
    let deadline = Instant::now() + Duration::from_secs(10);
    while observer.actions() < published() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }

    let mut finished = Vec::new();
    for s in primaries.into_iter().chain(standbys) {
        let name = s.name.clone();
        let (status, fed, published, stderr) = s.finish();
        eprintln!(
            "--- {name}: {status}, {fed} records fed, {} actions\n{stderr}",
            published.len()
        );
        assert!(
            !passwords.iter().any(|p| stderr.contains(p.as_str())),
            "a password in {name}'s output"
        );
        finished.push((name, status, published, stderr));
    }
    let (telemetry, actions) = observer.finish();
    // Measured, not asserted: the longest pause between two actions (any robot) in the 10 s
    // after the NATS node was killed, against the longest one before the first kill.
    let longest_gap = |from: Instant, to: Instant| -> Duration {
        let mut times: Vec<Instant> = actions
            .iter()
            .map(|(t, _, _)| *t)
            .filter(|t| *t >= from && *t <= to)
            .collect();
        times.sort();
        times
            .windows(2)
            .map(|w| w[1] - w[0])
            .max()
            .unwrap_or_default()
    };
    let first_action = actions
        .iter()
        .map(|(t, _, _)| *t)
        .min()
        .unwrap_or(killed_at);
    eprintln!(
        "longest pause between actions: {} ms in the 10 s after the NATS node was killed, {} ms before any kill",
        longest_gap(node_lost_at, node_lost_at + Duration::from_secs(10)).as_millis(),
        longest_gap(first_action, killed_at).as_millis()
    );

    // Which partition each robot's records went to (the mapping), and the reference run.
    let mut partition_of = BTreeMap::new();
    let mut records_per_partition = [0usize; 2];
    let mut lines = Vec::new();
    for (subject, payload) in &telemetry {
        let p: usize = subject
            .split('.')
            .nth(1)
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("subject {subject}"));
        let robot = robot_of(subject).unwrap().to_string();
        assert_eq!(*partition_of.entry(robot).or_insert(p), p, "a robot moved");
        records_per_partition[p] += 1;
        lines.push(
            telemetry_line(subject, payload)
                .unwrap_or_else(|| panic!("{subject}: {}", String::from_utf8_lossy(payload))),
        );
    }
    assert_eq!(
        telemetry.len(),
        ROBOTS * 300,
        "every record reached the cluster once"
    );
    assert!(
        partition_of.values().any(|&p| p == 0) && partition_of.values().any(|&p| p == 1),
        "both partitions have robots: {partition_of:?}"
    );
    let expected = reference(&lines);
    let observed: BTreeSet<(String, String)> = actions
        .iter()
        .map(|(_, r, m)| (r.clone(), m.clone()))
        .collect();

    // Nothing an uninterrupted run would not have sent: no monitor restarted from zero.
    let extra: Vec<_> = observed.difference(&expected).collect();
    assert!(
        extra.is_empty(),
        "actions no uninterrupted run sends: {extra:?}"
    );
    // Records in flight at the kills: actions missing, per partition.
    let mut lost = [0usize; 2];
    for (robot, _) in expected.difference(&observed) {
        lost[partition_of[robot]] += 1;
    }
    let duplicates = actions.len() - observed.len();
    // Partition 0's records per --state-interval: its robots × 10 records/s × speed.
    let robots_p0 = partition_of.values().filter(|&&p| p == 0).count();
    let bound = robots_p0 * 10 * 3 * INTERVAL_S as usize;
    eprintln!(
        "records per partition {records_per_partition:?}; actions expected {}, observed {} (+{duplicates} repeated); lost after SIGKILL {} (bound {bound}), after SIGTERM {}",
        expected.len(),
        observed.len(),
        lost[0],
        lost[1]
    );
    assert!(lost[0] <= bound, "SIGKILL lost {} > {bound}", lost[0]);
    assert_eq!(lost[1], 0, "SIGTERM lost actions");

    // Each standby took over, continuing every robot of its partition mid-run.
    for (p, kill) in [(0usize, killed_at), (1, termed_at)] {
        let (_, _, published, stderr) = &finished[2 + p];
        let first: Option<&Published> = published.first();
        let Some((when, _, _)) = first else {
            panic!("standby of partition {p} published nothing:\n{stderr}");
        };
        eprintln!(
            "partition {p}: takeover {} ms after the {}",
            when.duration_since(kill).as_millis(),
            if p == 0 { "SIGKILL" } else { "SIGTERM" }
        );
        assert!(stderr.contains("lease: holding partition"), "{stderr}");
        for (robot, _) in partition_of.iter().filter(|(_, q)| **q == p) {
            let (_, _, message) = published
                .iter()
                .find(|(_, r, _)| r == robot)
                .unwrap_or_else(|| panic!("standby {p} sent nothing for {robot}"));
            assert!(expected.contains(&(robot.clone(), message.clone())));
            let first_ts = expected
                .iter()
                .filter(|(r, _)| r == robot)
                .map(|(_, m)| timestamp(m))
                .min()
                .unwrap();
            assert!(
                timestamp(message) > first_ts,
                "{robot}: the standby's first action is the run's first: {message}"
            );
        }
    }
    // The killed primary published only until its kill; the terminated one saved and released.
    assert!(
        finished[1].3.contains("lease: released partition p1"),
        "{}",
        finished[1].3
    );
}
