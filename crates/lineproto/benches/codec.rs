//! Codec throughput: splitting, parsing (the bare crate vs. our Telegraf-rule wrapper) and writing,
//! on a P2-shaped robot line (two speeds) and a 360-sample lidar line, as Telegraf's JSON parser
//! makes them.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use lineproto::{FieldValue, LineWriter, RecordSplitter, parse_record};
use std::hint::black_box;

fn p2_line() -> String {
    "mqtt_consumer,host=turtlebot3,topic=tessla actualSpeed=\"0.0188\",expectedSpeed=0.015 1719231000123456789\n".into()
}

fn lidar_line() -> String {
    let mut s = String::from(
        "mqtt_consumer,host=turtlebot3,topic=tessla actualAngular=0.0002,actualSpeed=\"0.0188\",expectedAngular=0,expectedSpeed=0.015",
    );
    for i in 0..360 {
        // deterministic, varied ranges like a real scan: 0.12 .. 3.5 m
        let r = 0.12 + f64::from((i * 7919) % 3380) / 1000.0;
        s.push_str(&format!(",lidar_{i}={r}"));
    }
    s.push_str(" 1719231000123456789\n");
    s
}

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

fn benches(c: &mut Criterion) {
    let p2 = p2_line();
    let lidar = lidar_line();
    bench_parse(c, "p2", &p2);
    bench_parse(c, "lidar360", &lidar);
    bench_split(c, "p2", &p2);
    bench_split(c, "lidar360", &lidar);
    bench_write(c);
}

criterion_group!(codec, benches);
criterion_main!(codec);
