//! Answer latency of a running `tessla-telegraf` for `make bench`: spawns the binary as Telegraf's
//! execd would (stdin and stdout pipes), writes P2 records at a fixed rate, and timestamps each
//! answer: the time from writing a record into the child's stdin to reading the verdict line
//! that carries the record's timestamp (pass-through stays on; the echo arrives first).
//!
//! Run: `cargo run --release --example latency -- --bin target/release/tessla-telegraf
//!       --rate 1000 --seconds 10 [--warmup 1000] -- run --spec bench/p2.tessla`
//! Prints one line: `rate=.. sent=.. answered=.. p50_us=.. p90_us=.. p99_us=.. p999_us=.. max_us=..`.
//! The first `--warmup` records (default: one second's worth) are sent but not counted.
//!
//! `latency --echo` is the floor to compare with: a child that does nothing but answer. It reads
//! what stdin has, and writes every whole line back at once, renamed so that it counts as the
//! answer (`mqtt_consumer` becomes `echo`): the pipes, the wake-ups and the scheduling of this
//! machine, without any work. Run: `cargo run --release --example latency -- --bin
//! target/release/examples/latency -- --echo`.

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

const T0: i64 = 1_700_000_000_000_000_000;
const PERIOD_NS: i64 = 10_000_000;

struct Args {
    bin: String,
    rate: u64,
    seconds: f64,
    warmup: Option<usize>,
    child_args: Vec<String>,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        bin: "target/release/tessla-telegraf".into(),
        rate: 1000,
        seconds: 10.0,
        warmup: None,
        child_args: Vec::new(),
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut val = |name: &str| it.next().ok_or(format!("{name} needs a value"));
        match arg.as_str() {
            "--bin" => a.bin = val("--bin")?,
            "--rate" => a.rate = val("--rate")?.parse().map_err(|e| format!("--rate: {e}"))?,
            "--seconds" => {
                a.seconds = val("--seconds")?
                    .parse()
                    .map_err(|e| format!("--seconds: {e}"))?
            }
            "--warmup" => {
                a.warmup = Some(
                    val("--warmup")?
                        .parse()
                        .map_err(|e| format!("--warmup: {e}"))?,
                )
            }
            "--" => {
                a.child_args = it.by_ref().collect();
            }
            other => return Err(format!("unknown argument `{other}`")),
        }
    }
    if a.rate == 0 {
        return Err("--rate must be positive".into());
    }
    Ok(a)
}

/// The verdict's timestamp: the last space-separated token of a line not echoing our input.
fn answer_ts(line: &str) -> Option<i64> {
    if line.starts_with("mqtt_consumer") {
        return None;
    }
    line.rsplit(' ').next()?.trim_end().parse().ok()
}

fn percentile(sorted: &[u64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted.get(i).copied().unwrap_or(0) as f64 / 1000.0
}

/// `--echo`: answer every whole line read at once (see the module doc).
fn echo() -> std::io::Result<()> {
    use std::io::Read;
    let (mut input, mut output) = (std::io::stdin().lock(), std::io::stdout().lock());
    let mut buf = vec![0u8; 64 * 1024];
    let (mut have, mut out) = (0usize, Vec::new());
    loop {
        let n = input.read(buf.get_mut(have..).unwrap_or_default())?;
        if n == 0 {
            return Ok(());
        }
        have += n;
        let filled = buf.get(..have).unwrap_or_default();
        let whole = filled
            .iter()
            .rposition(|&b| b == b'\n')
            .map_or(0, |i| i + 1);
        for line in filled
            .get(..whole)
            .unwrap_or_default()
            .split_inclusive(|&b| b == b'\n')
        {
            out.extend_from_slice(b"echo");
            out.extend_from_slice(line.strip_prefix(b"mqtt_consumer").unwrap_or(line));
        }
        output.write_all(&out)?;
        output.flush()?;
        out.clear();
        buf.copy_within(whole..have, 0);
        have -= whole;
        if have == buf.len() {
            buf.resize(buf.len() * 2, 0);
        }
    }
}

fn main() {
    if std::env::args().nth(1).as_deref() == Some("--echo") {
        if let Err(e) = echo() {
            eprintln!("latency --echo: {e}");
            std::process::exit(1);
        }
        return;
    }
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("latency: {e}");
            std::process::exit(2);
        }
    };
    let n = (args.rate as f64 * args.seconds) as usize;
    let warmup = args.warmup.unwrap_or(args.rate as usize).min(n);
    let mut child = match Command::new(&args.bin)
        .args(&args.child_args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
    {
        Ok(c) => c,
        Err(e) => {
            eprintln!("latency: cannot start {}: {e}", args.bin);
            std::process::exit(3);
        }
    };
    let (Some(mut stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
        eprintln!("latency: no pipes to the child");
        std::process::exit(3);
    };
    let sent: Arc<Vec<AtomicU64>> = Arc::new((0..n).map(|_| AtomicU64::new(0)).collect());
    let got: Arc<Vec<AtomicU64>> = Arc::new((0..n).map(|_| AtomicU64::new(0)).collect());
    let start = Instant::now();
    let reader = {
        let got = Arc::clone(&got);
        std::thread::spawn(move || {
            let mut r = BufReader::new(stdout);
            let mut line = String::new();
            let mut answered = 0usize;
            loop {
                line.clear();
                match r.read_line(&mut line) {
                    Ok(0) | Err(_) => break,
                    Ok(_) => {}
                }
                let at = start.elapsed().as_nanos() as u64;
                if let Some(ts) = answer_ts(&line) {
                    let i = ((ts - T0) / PERIOD_NS) as usize;
                    if let Some(slot) = got.get(i)
                        && slot.load(Ordering::Relaxed) == 0
                    {
                        slot.store(at, Ordering::Relaxed);
                        answered += 1;
                    }
                }
            }
            answered
        })
    };
    let interval = Duration::from_nanos(1_000_000_000 / args.rate);
    for i in 0..n {
        let due = start + interval * i as u32 + Duration::from_millis(50);
        // Sleep most of the way, then spin: thread::sleep alone overshoots by tens of µs.
        loop {
            let now = Instant::now();
            if now >= due {
                break;
            }
            let left = due - now;
            if left > Duration::from_micros(300) {
                std::thread::sleep(left - Duration::from_micros(200));
            } else {
                std::hint::spin_loop();
            }
        }
        let ts = T0 + i as i64 * PERIOD_NS;
        let (exp, act) = (0.1, 0.1 + ((i % 50) as f64 - 25.0) / 1000.0);
        let line = format!(
            "mqtt_consumer,host=turtlebot3,topic=tessla actualSpeed=\"{act}\",expectedSpeed={exp} {ts}\n"
        );
        if let Some(slot) = sent.get(i) {
            slot.store(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
        }
        if stdin.write_all(line.as_bytes()).is_err() {
            eprintln!("latency: the child closed its stdin after {i} records");
            break;
        }
    }
    drop(stdin);
    let answered = reader.join().unwrap_or(0);
    let _ = child.wait();
    let mut lat: Vec<u64> = (warmup..n)
        .filter_map(|i| {
            let s = sent.get(i)?.load(Ordering::Relaxed);
            let g = got.get(i)?.load(Ordering::Relaxed);
            (g > 0).then(|| g.saturating_sub(s))
        })
        .collect();
    lat.sort_unstable();
    println!(
        "rate={} sent={} answered={} measured={} p50_us={:.1} p90_us={:.1} p99_us={:.1} p999_us={:.1} max_us={:.1}",
        args.rate,
        n,
        answered,
        lat.len(),
        percentile(&lat, 0.50),
        percentile(&lat, 0.90),
        percentile(&lat, 0.99),
        percentile(&lat, 0.999),
        percentile(&lat, 1.0),
    );
}
