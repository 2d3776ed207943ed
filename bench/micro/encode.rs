//! Criterion guard of output formatting: one step's output events written as line protocol by
//! `encode::encode_step` (fresh buffers) and `encode_prepared` (the processor's reused buffers
//! and encodings prepared once per spec version),
//! for the P2 spec's default metric (five fields) and the robot spec's `action` metric with
//! instance tags (eight `@TelegrafField` fields of mixed types).
//! Run with `make bench` (or `cargo bench --bench encode`).

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use std::sync::Arc;
use tessla_engine::Value;
use tessla_telegraf::telegraf::encode::{
    Encoding, Prepared, Scratch, encode_prepared, encode_step,
};

fn p2(c: &mut Criterion) {
    let encodings: Vec<Encoding> = [
        "p2_diff",
        "p2_violated",
        "p2_action",
        "p2_augmented",
        "speed_mse",
    ]
    .iter()
    .map(|n| Encoding::Default((*n).to_string()))
    .collect();
    let events = vec![
        (0, Value::Float(-0.0038)),
        (1, Value::Bool(false)),
        (2, Value::Float(0.015)),
        (3, Value::Bool(false)),
        (4, Value::Float(0.000_118_345_000_000_000_02)),
    ];
    let mut out = Vec::with_capacity(4096);
    let mut g = c.benchmark_group("encode_step");
    g.throughput(Throughput::Elements(1));
    g.bench_function("p2_default_metric", |b| {
        b.iter(|| {
            out.clear();
            let d = encode_step(
                1_719_231_000_123_456_789,
                black_box(&events),
                &encodings,
                "tessla",
                &[],
                &mut out,
            );
            black_box((d, out.len()))
        })
    });
    // The processor's path: buffers kept between steps, names escaped once.
    let mut scratch = Scratch::default();
    let prepared = Prepared::new(encodings.clone(), "tessla");
    g.bench_function("p2_default_metric_reused", |b| {
        b.iter(|| {
            out.clear();
            let d = encode_prepared(
                &mut scratch,
                &prepared,
                1_719_231_000_123_456_789,
                black_box(&events),
                &[],
                &mut out,
            );
            black_box((d, out.len()))
        })
    });
    let action = |f: &str| Encoding::Field {
        measurement: "action".into(),
        field: f.into(),
    };
    let encodings: Vec<Encoding> = [
        "speed",
        "augmented",
        "p1_status",
        "p1_margin",
        "p2_violated",
        "p3_spikes",
        "p3_dropouts",
        "speed_mse",
    ]
    .iter()
    .map(|f| action(f))
    .collect();
    let events = vec![
        (0, Value::Float(0.0575)),
        (1, Value::Bool(true)),
        (2, Value::Str(Arc::from("ok"))),
        (3, Value::Float(0.41)),
        (4, Value::Bool(true)),
        (5, Value::Int(0)),
        (6, Value::Int(3)),
        (7, Value::Some(Arc::new(Value::Float(0.0012)))),
    ];
    let tags = vec![
        ("robot".to_string(), "tb3-00042".to_string()),
        ("site".to_string(), "lab".to_string()),
    ];
    g.bench_function("robot_action_metric", |b| {
        b.iter(|| {
            out.clear();
            let d = encode_step(
                1_719_231_000_123_456_789,
                black_box(&events),
                &encodings,
                "tessla",
                &tags,
                &mut out,
            );
            black_box((d, out.len()))
        })
    });
    let mut scratch = Scratch::default();
    let prepared = Prepared::new(encodings.clone(), "tessla");
    g.bench_function("robot_action_metric_reused", |b| {
        b.iter(|| {
            out.clear();
            let d = encode_prepared(
                &mut scratch,
                &prepared,
                1_719_231_000_123_456_789,
                black_box(&events),
                &tags,
                &mut out,
            );
            black_box((d, out.len()))
        })
    });
    g.finish();
}

criterion_group!(encode, p2);
criterion_main!(encode);
