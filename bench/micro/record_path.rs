//! Criterion guard of the whole record path inside the process: `Processor::record` on one record
//! (split record in, parse, bind, engine step, output formatting, pass-through) for the P2
//! workload's record with bench/p2.tessla, and a full robot message (360 beams) with the bundled
//! robot spec, its fields sorted and in Telegraf's random order (`*_unordered`). The timestamp
//! advances every iteration, as in a real run. `p2_spec_p2_record_watched` is the P2 case with the
//! step watchdog's marks on, as `run` always has them (`--step-timeout`): its difference from
//! `p2_spec_p2_record` is what the watchdog costs a record.
//! Run with `make bench` (or `cargo bench --bench record_path`).

use test_support::workload::{P2_LINE, lidar_line, unordered};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use lineproto::Record;
use std::hint::black_box;
use std::path::Path;
use tessla_engine::LoadOptions;
use tessla_telegraf::processor::{Options, Processor};

/// Overwrite the record's 19-digit timestamp (just before its newline) with `ts`.
fn set_ts(bytes: &mut [u8], ts: u64) {
    let end = bytes.len() - 1;
    let mut t = ts;
    for b in bytes[end - 19..end].iter_mut().rev() {
        *b = b'0' + (t % 10) as u8;
        t /= 10;
    }
}

fn run(c: &mut Criterion, name: &str, mut proc: Processor, line: &str) {
    let mut rec = Record {
        bytes: line.as_bytes().to_vec(),
        line: 1,
        oversized: false,
    };
    let mut out = Vec::with_capacity(1 << 20);
    let mut ts = 1_719_231_000_000_000_000u64;
    let mut g = c.benchmark_group("record_path");
    g.throughput(Throughput::Elements(1));
    g.bench_function(name, |b| {
        b.iter(|| {
            ts += 10_000_000;
            set_ts(&mut rec.bytes, ts);
            proc.record(black_box(&rec), &mut out);
            if out.len() > (1 << 19) {
                out.clear();
            }
        })
    });
    g.finish();
}

fn benches(c: &mut Criterion) {
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("bench/p2.tessla");
    let p2 = tessla_engine::load_file(&spec, &LoadOptions::default())
        .unwrap()
        .program;
    run(
        c,
        "p2_spec_p2_record",
        Processor::new(p2.clone(), Options::default()).unwrap(),
        P2_LINE,
    );
    let mut watched = Processor::new(p2, Options::default()).unwrap();
    let watch = tessla_telegraf::watchdog::Watch::default();
    watched.watch_with(watch.lane());
    run(c, "p2_spec_p2_record_watched", watched, P2_LINE);
    let robot = tessla_telegraf::bundled::load(&tessla_telegraf::natives::load_options().unwrap())
        .unwrap()
        .program;
    run(
        c,
        "robot_spec_lidar360_record",
        Processor::new(robot.clone(), Options::default()).unwrap(),
        &lidar_line(),
    );
    run(
        c,
        "robot_spec_lidar360_record_unordered",
        Processor::new(robot, Options::default()).unwrap(),
        &unordered(&lidar_line()),
    );
}

criterion_group!(record_path, benches);
criterion_main!(record_path);
