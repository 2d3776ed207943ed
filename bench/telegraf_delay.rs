//! The robot-to-twin delay (`make bench-telegraf`, BENCHMARKS.md "Robot to action through
//! Telegraf"): the time from a robot's MQTT publish to its action arriving on the robot's
//! `action` topic, through a real Mosquitto, the real Telegraf (built by
//! `tools/build-telegraf.sh`) running a shipped conf with only its endpoints rewritten, and the
//! release binary as its `processors.execd` child. InfluxDB runs too, as the conf ships it.
//!
//! Each robot publishes the recorded run's messages (the robot's JSON, 360 lidar beams, QoS 1)
//! at `--hz` (5), the robots spread evenly over the period; actions are matched to publishes
//! in order, per robot. One robot runs `telegraf/telegraf.conf`, several run
//! `telegraf/telegraf-fleet.conf` (one topic per robot, one monitor instance each); `--conf
//! PATH` runs another conf of the same shape. The robots publish and subscribe to their actions
//! (QoS 1) on ONE connection, as a robot's MQTT client does: the broker then writes the PUBACK
//! of a publish and, soon after, the action on the same socket, which is where Nagle's
//! algorithm holds the second small write (about 40 ms, until the robot's delayed ACK) unless
//! the broker sets `set_tcp_nodelay true` (telegraf/mosquitto/mosquitto.conf; here the default,
//! `--tcp-nodelay off` runs Mosquitto's default). Several robots share that one connection.
//!
//! Run: `cargo build --release && cargo run --release --example telegraf_delay --
//!       [--robots 1] [--seconds 20] [--warmup 3] [--hz 5] [--telegraf v1.39.3] [--set KEY=VALUE]
//!       [--no-lidar] [--tcp-nodelay on|off] [--conf PATH] [--clone]`
//! `--clone` runs the conf with the clone wiring (README, "Telegraf never re-parses the robot's
//! record": processors.clone tags a copy, processors.execd takes only the copy and runs with
//! --no-passthrough) instead of the echo.
//! `--set agent.flush_interval=1s` (a key of the conf: `section.key`, the first table of that
//! section) tries a setting; `--no-lidar` sends the messages without their 360 beams (P1 and
//! P3 then judge an empty scan), to see what the lidar costs Telegraf. Prints one line: `robots=.. sent=.. answered=.. lost=..
//! p50_ms=.. p90_ms=.. p99_ms=.. max_ms=..` (the first `--warmup` seconds not counted).

// The tests' helpers, of which this tool uses a part, from the dev-only crate test-support:
// the servers and the real Telegraf (given the binary it runs, `BIN` below).
use test_support::{real_telegraf, servers};

use rumqttc::{Client, Event, MqttOptions, Packet, QoS};
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tessla_telegraf::replay::message::{MessageOptions, to_json};

/// The binary the conf runs (real_telegraf's rewrite names it).
pub const BIN: &str = "target/release/tessla-telegraf";

struct Args {
    robots: usize,
    seconds: f64,
    warmup: f64,
    hz: f64,
    version: String,
    sets: Vec<(String, String)>,
    /// Leave the 360 lidar beams out of the robot's messages (`--no-lidar`).
    no_lidar: bool,
    /// Mosquitto's `set_tcp_nodelay` (`--tcp-nodelay on|off`, on as shipped).
    nodelay: bool,
    /// The conf to run instead of the shipped one (`--conf PATH`).
    conf: Option<String>,
    /// Rewire the conf's processor to the clone wiring (`--clone`).
    clone: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        robots: 1,
        seconds: 20.0,
        warmup: 3.0,
        hz: 5.0,
        version: "v1.39.3".into(),
        sets: Vec::new(),
        no_lidar: false,
        nodelay: true,
        conf: None,
        clone: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut val = |name: &str| it.next().ok_or(format!("{name} needs a value"));
        match arg.as_str() {
            "--robots" => {
                a.robots = val("--robots")?
                    .parse()
                    .map_err(|e| format!("--robots: {e}"))?
            }
            "--seconds" => {
                a.seconds = val("--seconds")?
                    .parse()
                    .map_err(|e| format!("--seconds: {e}"))?
            }
            "--warmup" => {
                a.warmup = val("--warmup")?
                    .parse()
                    .map_err(|e| format!("--warmup: {e}"))?
            }
            "--hz" => a.hz = val("--hz")?.parse().map_err(|e| format!("--hz: {e}"))?,
            "--telegraf" => a.version = val("--telegraf")?,
            "--set" => {
                let kv = val("--set")?;
                let (k, v) = kv
                    .split_once('=')
                    .ok_or(format!("--set {kv}: expected section.key=value"))?;
                a.sets.push((k.to_string(), v.to_string()));
            }
            "--no-lidar" => a.no_lidar = true,
            "--tcp-nodelay" => {
                a.nodelay = match val("--tcp-nodelay")?.as_str() {
                    "on" => true,
                    "off" => false,
                    other => return Err(format!("--tcp-nodelay {other}: on or off")),
                }
            }
            "--conf" => a.conf = Some(val("--conf")?),
            "--clone" => a.clone = true,
            "--bench" => {}
            other => return Err(format!("unknown argument `{other}`")),
        }
    }
    if a.robots == 0 || a.hz <= 0.0 || a.seconds <= a.warmup {
        return Err("--robots and --hz must be positive, --seconds above --warmup".into());
    }
    Ok(a)
}

/// Set `section.key = value` in the conf text: replaces the key's line in the first table of
/// that section, or adds it after the table's header.
fn set_key(conf: &str, dotted: &str, value: &str) -> Result<String, String> {
    let (section, key) = dotted
        .rsplit_once('.')
        .ok_or(format!("{dotted}: expected section.key"))?;
    let headers = [format!("[{section}]"), format!("[[{section}]]")];
    let mut out = Vec::new();
    let mut in_section = false;
    let mut done = false;
    for line in conf.lines() {
        let t = line.trim();
        if t.starts_with('[') {
            if in_section && !done {
                return Err(format!("{dotted}: not set"));
            }
            in_section = !done && headers.iter().any(|h| t == h);
            out.push(line.to_string());
            if in_section {
                out.push(format!("  {key} = {value}"));
                done = true;
            }
            continue;
        }
        if in_section && t.split('=').next().is_some_and(|k| k.trim() == key) {
            continue;
        }
        out.push(line.to_string());
    }
    if !done {
        return Err(format!("{dotted}: no section [{section}] in the conf"));
    }
    Ok(out.join("\n") + "\n")
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

fn main() {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("telegraf_delay: {e}");
            std::process::exit(2);
        }
    };
    if let Err(e) = run(&args) {
        eprintln!("telegraf_delay: {e}");
        std::process::exit(1);
    }
}

fn run(args: &Args) -> Result<(), String> {
    if !std::path::Path::new(BIN).is_file() {
        return Err(format!(
            "{BIN} not built: run `cargo build --release` first"
        ));
    }
    let telegraf_bin = real_telegraf::binary(&args.version)
        .ok_or(format!("Telegraf {} not built", args.version))?;
    let broker = real_telegraf::broker_with(&format!(
        "max_queued_messages 100000\nset_tcp_nodelay {}\n",
        args.nodelay
    ))
    .ok_or("mosquitto missing")?;
    let influx = servers::Influxd::start().ok_or("influxd missing")?;
    let fleet = args.robots > 1;
    let (conf_path, client_id, subscription) = if fleet {
        (
            "telegraf/telegraf-fleet.conf",
            "telegraf-tessla-fleet-in",
            "tessla/+",
        )
    } else {
        ("telegraf/telegraf.conf", "telegraf-tessla-in", "tessla")
    };
    let state = tempfile::tempdir().map_err(|e| e.to_string())?;
    let text = match &args.conf {
        Some(path) => std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?,
        None => real_telegraf::shipped(conf_path),
    };
    let rewrite = real_telegraf::Rewrite::robot(BIN, broker.port, Some(&influx.url("")))
        .state_in(state.path());
    let mut conf = rewrite.apply(&text);
    if args.clone {
        conf = real_telegraf::clone_wiring(&conf)?;
    }
    for (k, v) in &args.sets {
        conf = set_key(&conf, k, v)?;
    }
    let topics: Vec<String> = if fleet {
        (0..args.robots).map(|i| format!("tessla/r{i}")).collect()
    } else {
        vec!["tessla".to_string()]
    };

    // The messages: the recorded run's, as the robot's JSON.
    let recorded = std::fs::read_to_string("tests/fixtures/robot/recorded_run.lp")
        .map_err(|e| format!("tests/fixtures/robot/recorded_run.lp: {e}"))?;
    let recording = tessla_telegraf::replay::read_lp::read(&recorded, None);
    let options = MessageOptions {
        string_fields: vec!["actualSpeed".into()],
        time_key: None,
    };
    let payloads: Vec<Vec<u8>> = recording
        .samples
        .iter()
        .map(|s| {
            let mut s = s.clone();
            if args.no_lidar {
                s.fields.retain(|(name, _)| !name.starts_with("lidar_"));
            }
            serde_json::to_vec(&to_json(&s, &options)).unwrap_or_default()
        })
        .collect();

    // Publish instants per robot, matched in order by the actions' arrivals.
    let sent: Arc<Vec<Mutex<VecDeque<Instant>>>> = Arc::new(
        (0..args.robots)
            .map(|_| Mutex::new(VecDeque::new()))
            .collect(),
    );
    let delays: Arc<Mutex<Vec<(Instant, f64)>>> = Arc::new(Mutex::new(Vec::new()));

    let sub_filter = if fleet {
        "tessla/+/action".to_string()
    } else {
        "action".to_string()
    };
    // The robots' one connection: their actions' subscription and their publishes.
    let mut opts = MqttOptions::new("delay-robots", "127.0.0.1", broker.port);
    opts.set_max_packet_size(1 << 20, 1 << 20);
    opts.set_inflight(u16::MAX);
    let (publisher, mut sub_conn) = Client::new(opts, 65536);
    publisher
        .subscribe(&sub_filter, QoS::AtLeastOnce)
        .map_err(|e| e.to_string())?;
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    {
        let sent = sent.clone();
        let delays = delays.clone();
        let fleet_topics = fleet;
        std::thread::spawn(move || {
            for event in sub_conn.iter() {
                match event {
                    Ok(Event::Incoming(Packet::SubAck(_))) => {
                        let _ = ready_tx.send(());
                    }
                    Ok(Event::Incoming(Packet::Publish(p))) => {
                        let now = Instant::now();
                        let robot = if fleet_topics {
                            p.topic
                                .strip_prefix("tessla/r")
                                .and_then(|r| r.strip_suffix("/action"))
                                .and_then(|r| r.parse::<usize>().ok())
                        } else {
                            Some(0)
                        };
                        let Some(robot) = robot else { continue };
                        let Some(queue) = sent.get(robot) else {
                            continue;
                        };
                        let at = queue.lock().ok().and_then(|mut q| q.pop_front());
                        if let Some(at) = at
                            && let Ok(mut d) = delays.lock()
                        {
                            d.push((at, now.duration_since(at).as_secs_f64() * 1e3));
                        }
                    }
                    Ok(_) => {}
                    Err(_) => return,
                }
            }
        });
    }
    ready_rx
        .recv_timeout(Duration::from_secs(10))
        .map_err(|_| "no SUBACK for the action subscriber")?;

    let telegraf = real_telegraf::Telegraf::start(&args.version, &telegraf_bin, &conf, &[]);
    real_telegraf::wait_subscribed(&broker, client_id, subscription, 0);

    let period = Duration::from_secs_f64(1.0 / args.hz);
    let start = Instant::now();
    let end = start + Duration::from_secs_f64(args.seconds);
    let counted_from = start + Duration::from_secs_f64(args.warmup);
    let mut tick = 0u64;
    let mut published = 0usize;
    'outer: loop {
        for (robot, topic) in topics.iter().enumerate() {
            let due = start
                + period.mul_f64(tick as f64)
                + period.mul_f64(robot as f64 / args.robots as f64);
            if due >= end {
                break 'outer;
            }
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
            let payload = payloads[(tick as usize) % payloads.len()].clone();
            if let Ok(mut q) = sent[robot].lock() {
                q.push_back(Instant::now());
            }
            publisher
                .publish(topic, QoS::AtLeastOnce, false, payload)
                .map_err(|e| e.to_string())?;
            published += 1;
        }
        tick += 1;
    }
    // Let the last actions arrive.
    std::thread::sleep(Duration::from_secs(2));
    let log = telegraf.stop();
    let got = delays.lock().map_err(|e| e.to_string())?.clone();
    let answered = got.len();
    let mut counted: Vec<f64> = got
        .iter()
        .filter(|(at, _)| *at >= counted_from)
        .map(|(_, d)| *d)
        .collect();
    counted.sort_by(f64::total_cmp);
    let errors = log.lines().filter(|l| l.contains(" E! ")).count();
    println!(
        "telegraf={} robots={} hz={} lidar={} tcp_nodelay={} sent={} answered={} lost={} counted={} p50_ms={:.2} p90_ms={:.2} p99_ms={:.2} max_ms={:.2} telegraf_errors={}",
        args.version,
        args.robots,
        args.hz,
        !args.no_lidar,
        args.nodelay,
        published,
        answered,
        published.saturating_sub(answered),
        counted.len(),
        percentile(&counted, 0.5),
        percentile(&counted, 0.9),
        percentile(&counted, 0.99),
        counted.last().copied().unwrap_or(f64::NAN),
        errors,
    );
    if errors > 0 {
        eprintln!("Telegraf's errors:");
        for l in log.lines().filter(|l| l.contains(" E! ")).take(10) {
            eprintln!("  {l}");
        }
    }
    Ok(())
}
