//! Codec throughput: splitting, parsing (the bare crate vs. our Telegraf-rule wrapper) and writing,
//! on a P2-shaped robot line (two speeds) and a 360-sample lidar line, as Telegraf's JSON parser
//! makes them (fields sorted, and in the random order Telegraf writes them: `*_unordered`), and
//! float formatting (`Display` vs. [`lineproto::write_float`]).

use test_support::workload::{P2_LINE, lidar_line, unordered};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use lineproto::{
    FieldValue, LineWriter, Metric, RecordSplitter, parse_record, parse_record_into, write_float,
};
use std::hint::black_box;

fn bench_parse(c: &mut Criterion, name: &str, line: &str) {
    let mut g = c.benchmark_group(format!("parse_{name}"));
    g.throughput(Throughput::Bytes(line.len() as u64));
    g.bench_function("crate_parse_lines", |b| {
        b.iter(|| {
            let n = influxdb_line_protocol::parse_lines(black_box(line))
                .filter_map(Result::ok)
                .map(|p| p.field_set.len())
                .sum::<usize>();
            black_box(n)
        })
    });
    g.bench_function("lineproto_parse_record", |b| {
        b.iter(|| {
            let m = parse_record(black_box(line.as_bytes()));
            black_box(m.map(|m| m.map(|m| m.fields.len())))
        })
    });
    // As the step loop parses: into one reused metric (no key strings allocated).
    g.bench_function("lineproto_parse_record_into_reused", |b| {
        let mut m = Metric::default();
        b.iter(|| {
            let ok = parse_record_into(black_box(line.as_bytes()), &mut m);
            black_box((ok.is_ok(), m.fields.len()))
        })
    });
    g.finish();
}

fn bench_split(c: &mut Criterion, name: &str, line: &str) {
    let input = line.repeat(1000);
    let mut g = c.benchmark_group(format!("split_{name}"));
    g.throughput(Throughput::Bytes(input.len() as u64));
    // 4 KiB chunks cut most lidar records (5.7 KB) in two; 64 KiB is the stdio transport's read.
    for (label, size) in [
        ("splitter_4k_chunks", 4096),
        ("splitter_64k_chunks", 64 * 1024),
    ] {
        g.bench_function(label, |b| {
            b.iter(|| {
                let mut s = RecordSplitter::default();
                let mut n = 0;
                for chunk in input.as_bytes().chunks(size) {
                    s.push(chunk);
                    while let Some(r) = s.next_record() {
                        n += r.bytes.len();
                    }
                }
                black_box(n)
            })
        });
        // What the step loop does on one thread: records borrowed from the chunk.
        g.bench_function(format!("{label}_borrowed"), |b| {
            b.iter(|| {
                let mut s = RecordSplitter::default();
                let mut n = 0;
                for chunk in input.as_bytes().chunks(size) {
                    s.push_with(chunk, |r| n += r.bytes.len());
                }
                black_box(n)
            })
        });
    }
    g.finish();
}

fn bench_write(c: &mut Criterion) {
    let mut g = c.benchmark_group("write_action");
    g.throughput(Throughput::Elements(1));
    g.bench_function("line_writer", |b| {
        b.iter(|| {
            let mut w = LineWriter::new(black_box("action"));
            w.tag("host", "turtlebot3")
                .field("speed", &FieldValue::Float(black_box(0.2171)))
                .field("augmented", &FieldValue::Bool(true));
            black_box(w.finish(Some(1_719_231_000_123_456_789)))
        })
    });
    g.finish();
}

/// Output values as a P2 step makes them: differences and means of short decimals (16 to 17
/// digits) next to the short decimals themselves.
fn bench_format(c: &mut Criterion) {
    let values: Vec<f64> = (0..1000)
        .map(|i| {
            let a = f64::from(i % 97) / 1000.0;
            let b = f64::from(i % 89) / 10000.0 + 0.015;
            match i % 3 {
                0 => a - b,
                1 => (a - b) * (a - b) / f64::from(i + 1),
                _ => b,
            }
        })
        .collect();
    let mut g = c.benchmark_group("format_f64");
    g.throughput(Throughput::Elements(values.len() as u64));
    g.bench_function("display", |b| {
        let mut s = String::with_capacity(32 * 1024);
        b.iter(|| {
            use std::fmt::Write as _;
            s.clear();
            for v in &values {
                let _ = write!(s, "{}", black_box(*v));
            }
            black_box(s.len())
        })
    });
    g.bench_function("write_float", |b| {
        let mut s = String::with_capacity(32 * 1024);
        b.iter(|| {
            s.clear();
            for v in &values {
                write_float(&mut s, black_box(*v));
            }
            black_box(s.len())
        })
    });
    g.finish();
}

fn benches(c: &mut Criterion) {
    let p2 = P2_LINE.to_string();
    let lidar = lidar_line();
    bench_parse(c, "p2", &p2);
    bench_parse(c, "lidar360", &lidar);
    bench_split(c, "p2", &p2);
    bench_split(c, "lidar360", &lidar);
    let unordered = unordered(&lidar_line());
    bench_parse(c, "lidar360_unordered", &unordered);
    bench_split(c, "lidar360_unordered", &unordered);
    bench_write(c);
    bench_format(c);
}

criterion_group!(codec, benches);
criterion_main!(codec);
