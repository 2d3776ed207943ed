//! Fleet throughput on NATS and standby takeover time, for `make bench-nats` (BENCHMARKS.md,
//! "Fleet on NATS"). Starts a real 3-node nats-server cluster
//! (crates/test-support/src/nats_cluster.rs) with the shipped subject mapping for 1, 2 and 4
//! partitions, one stand-in Telegraf per partition (crates/test-support/src/nats_standin.rs)
//! running the release binary with
//! `--state nats://...?lease=p<N>`, and publishes the recorded run of `--robots` robots (JSON, as
//! the robots send it, straight onto `robots.<id>.telemetry`) as fast as the cluster takes it.
//!
//! - throughput: records / (first publish .. last action received by an observer), median of
//!   `--reps` runs per partition count;
//! - takeover: one partition with primary and standby, robots at their recorded pace (10 Hz);
//!   the time from the primary's SIGKILL (or SIGTERM) to the standby's first published action.
//!
//! Run: `cargo build --release && cargo run --release --example fleet_nats -- [--robots 64]
//!       [--reps 3] [--bin target/release/tessla-telegraf]`. Prints a markdown table.

// The tests' helpers (the dev-only crate test-support), of which this tool uses a part.
use test_support::{nats_cluster, nats_standin};

use influxdb_line_protocol::{FieldValue, parse_lines};
use nats_cluster::Cluster;
use nats_standin::NatsStandIn;
use serde_json::{Map, Value, json};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

struct Args {
    bin: String,
    robots: usize,
    reps: usize,
}

fn parse_args() -> Args {
    let mut a = Args {
        bin: "target/release/tessla-telegraf".into(),
        robots: 64,
        reps: 3,
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let v = it.next().unwrap_or_default();
        match k.as_str() {
            "--bin" => a.bin = v,
            "--robots" => a.robots = v.parse().expect("--robots N"),
            "--reps" => a.reps = v.parse().expect("--reps N"),
            _ => panic!("unknown argument {k} (known: --bin, --robots, --reps)"),
        }
    }
    a
}

/// The recorded run as the robot's JSON messages (actualSpeed as a string, `time` in ns).
fn messages() -> Vec<Vec<u8>> {
    let text = std::fs::read_to_string("tests/fixtures/robot/recorded_run.lp")
        .expect("run from the repository root");
    parse_lines(&text)
        .filter_map(Result::ok)
        .map(|line| {
            let mut m = Map::new();
            for (k, v) in &line.field_set {
                let value = match v {
                    FieldValue::F64(f) => json!(f),
                    FieldValue::I64(i) => json!(i),
                    FieldValue::U64(u) => json!(u),
                    FieldValue::Boolean(b) => json!(b),
                    FieldValue::String(s) => json!(s.to_string()),
                };
                m.insert(k.to_string(), value);
            }
            m.insert("time".into(), json!(line.timestamp.unwrap_or(0)));
            serde_json::to_vec(&Value::Object(m)).unwrap_or_default()
        })
        .collect()
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
}

/// Counts actions on `robots.*.action` until `expected` arrived or `timeout`; returns the
/// instant of the last one.
fn count_actions(
    url: String,
    expected: usize,
    timeout: Duration,
    seen: Arc<AtomicUsize>,
) -> (
    std::sync::mpsc::Receiver<()>,
    std::thread::JoinHandle<(usize, Instant)>,
) {
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let h = std::thread::spawn(move || {
        runtime().block_on(async move {
            use futures_util::StreamExt;
            let client = async_nats::connect(url.as_str()).await.unwrap();
            let mut sub = client.subscribe("robots.*.action").await.unwrap();
            client.flush().await.unwrap();
            ready_tx.send(()).unwrap();
            let (mut n, mut last) = (0, Instant::now());
            let deadline = tokio::time::Instant::now() + timeout;
            while n < expected {
                match tokio::time::timeout_at(deadline, sub.next()).await {
                    Ok(Some(_)) => {
                        n += 1;
                        seen.store(n, Ordering::Relaxed);
                        last = Instant::now();
                    }
                    _ => break,
                }
            }
            (n, last)
        })
    });
    (ready_rx, h)
}

/// Publish every robot's run: all robots' record i, then i+1, ...; paced at `period` per round,
/// or as fast as the processes answer (at most `WINDOW` records without their action yet, so
/// no subscriber falls behind far enough to be cut off as a slow consumer).
fn publish(
    url: &str,
    robots: usize,
    msgs: &[Vec<u8>],
    period: Option<Duration>,
    answered: Option<Arc<AtomicUsize>>,
) {
    const WINDOW: usize = 4000;
    runtime().block_on(async {
        let client = async_nats::connect(url).await.unwrap();
        let start = tokio::time::Instant::now();
        for (i, m) in msgs.iter().enumerate() {
            if let Some(p) = period {
                tokio::time::sleep_until(start + p * i as u32).await;
            }
            if let Some(done) = &answered {
                while i * robots > done.load(Ordering::Relaxed) + WINDOW {
                    client.flush().await.unwrap();
                    tokio::time::sleep(Duration::from_millis(1)).await;
                }
            }
            for r in 0..robots {
                client
                    .publish(format!("robots.robot{r}.telemetry"), m.clone().into())
                    .await
                    .unwrap();
            }
        }
        client.flush().await.unwrap();
    });
}

fn args_for(cluster: &Cluster, p: usize) -> Vec<String> {
    vec![
        "--instance-by".into(),
        "robot".into(),
        "--state".into(),
        format!(
            "nats://{}/bench?lease=p{p}&ttl=2s&replicas=3",
            cluster.hosts()
        ),
        "--state-interval".into(),
        "5s".into(),
    ]
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn throughput(a: &Args, msgs: &[Vec<u8>], partitions: usize) -> f64 {
    let cluster = Cluster::start(&nats_cluster::mapping(partitions)).expect("nats-server");
    let standins: Vec<NatsStandIn> = (0..partitions)
        .map(|p| {
            NatsStandIn::start(
                &a.bin,
                &format!("p{p}"),
                &cluster.url(p % 3),
                p,
                &args_for(&cluster, p),
                &cluster.login("admin"),
            )
        })
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    let total = a.robots * msgs.len();
    let answered = Arc::new(AtomicUsize::new(0));
    let (ready, counter) = count_actions(
        cluster.url(0),
        total,
        Duration::from_secs(120),
        Arc::clone(&answered),
    );
    ready.recv().unwrap();
    let start = Instant::now();
    publish(&cluster.url(1), a.robots, msgs, None, Some(answered));
    let (n, last) = counter.join().unwrap();
    let logs: Vec<String> = standins.into_iter().map(|s| s.finish().3).collect();
    assert_eq!(
        n,
        total,
        "{partitions} partitions: {n} of {total} actions arrived; processes' logs:\n{}",
        logs.join("\n")
    );
    total as f64 / last.duration_since(start).as_secs_f64()
}

/// Kill the primary with `signal` 3 s into a paced run; ms to the standby's first action.
fn takeover(a: &Args, msgs: &[Vec<u8>], signal: &str) -> f64 {
    let cluster = Cluster::start(&nats_cluster::mapping(1)).expect("nats-server");
    let primary = NatsStandIn::start(
        &a.bin,
        "a",
        &cluster.url(0),
        0,
        &args_for(&cluster, 0),
        &cluster.login("admin"),
    );
    std::thread::sleep(Duration::from_millis(500));
    let standby = NatsStandIn::start(
        &a.bin,
        "b",
        &cluster.url(1),
        0,
        &args_for(&cluster, 0),
        &cluster.login("admin"),
    );
    let url = cluster.url(1);
    let robots = a.robots.min(16);
    let paced: Vec<Vec<u8>> = msgs.to_vec();
    let publisher = std::thread::spawn(move || {
        publish(
            &url,
            robots,
            &paced[..80],
            Some(Duration::from_millis(100)),
            None,
        )
    });
    std::thread::sleep(Duration::from_secs(3));
    primary.signal(signal);
    let killed = Instant::now();
    publisher.join().unwrap();
    std::thread::sleep(Duration::from_secs(3));
    let _ = primary.finish();
    let (_, _, published, err) = standby.finish();
    let first = published
        .iter()
        .map(|(t, _, _)| *t)
        .find(|t| *t > killed)
        .unwrap_or_else(|| panic!("the standby published nothing after the {signal}:\n{err}"));
    first.duration_since(killed).as_secs_f64() * 1000.0
}

/// The baseline of the same run: one process given the same records on stdin (no NATS, no
/// Telegraf stand-in), records/s.
fn baseline(a: &Args, msgs: &[Vec<u8>]) -> f64 {
    use std::io::Write;
    let mut input = String::new();
    for m in msgs {
        for r in 0..a.robots {
            let subject = format!("fleet.0.robots.robot{r}.telemetry");
            if let Some(line) = nats_standin::telemetry_line(&subject, m) {
                input.push_str(&line);
                input.push('\n');
            }
        }
    }
    let start = Instant::now();
    let mut child = std::process::Command::new(&a.bin)
        .args(["run", "--instance-by", "robot"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("the release binary (cargo build --release)");
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(input.as_bytes()).unwrap();
    drop(stdin);
    child.wait().unwrap();
    (a.robots * msgs.len()) as f64 / start.elapsed().as_secs_f64()
}

fn main() {
    let a = parse_args();
    let msgs = messages();
    let runs: Vec<f64> = (0..a.reps).map(|_| baseline(&a, &msgs)).collect();
    println!(
        "Baseline, one process on stdin (same records, no NATS): {:.0} records/s (median; runs: {})\n",
        median(runs.clone()),
        runs.iter()
            .map(|r| format!("{r:.0}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!(
        "| partitions | records | throughput (records/s, median of {}) |",
        a.reps
    );
    println!("|---|---|---|");
    for partitions in [1, 2, 4] {
        let runs: Vec<f64> = (0..a.reps)
            .map(|_| throughput(&a, &msgs, partitions))
            .collect();
        println!(
            "| {partitions} | {} | {:.0} (runs: {}) |",
            a.robots * msgs.len(),
            median(runs.clone()),
            runs.iter()
                .map(|r| format!("{r:.0}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    println!();
    println!(
        "| primary stopped by | takeover: kill -> standby's first action (ms, median of {}) |",
        a.reps
    );
    println!("|---|---|");
    for signal in ["KILL", "TERM"] {
        let runs: Vec<f64> = (0..a.reps).map(|_| takeover(&a, &msgs, signal)).collect();
        println!(
            "| SIG{signal} | {:.0} (runs: {}) |",
            median(runs.clone()),
            runs.iter()
                .map(|r| format!("{r:.0}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
}
