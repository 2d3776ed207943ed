//! Criterion guard of the record path's middle: binding a parsed metric to the spec's inputs
//! (`InputBinding::matches` + `extract`, value conversion) for the P2 record (two speeds, one a
//! string) and a full robot message with a 360-beam scan gathered by `lidar_*` into one list
//! (fields sorted, and in Telegraf's random order: `bind_lidar360_unordered`).
//! Run with `make bench` (or `cargo bench --bench binding`).

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use tessla_engine::LoadOptions;
use tessla_telegraf::telegraf::binding::bindings;

const P2_LINE: &str = "mqtt_consumer,host=turtlebot3,topic=tessla actualSpeed=\"0.0188\",expectedSpeed=0.015 1719231000123456789\n";

fn lidar_line() -> String {
    let mut s = String::from(
        "mqtt_consumer,host=turtlebot3,topic=tessla actualAngular=0.0002,actualSpeed=\"0.0188\",expectedAngular=0,expectedSpeed=0.015",
    );
    for i in 0..360 {
        let r = 0.12 + f64::from((i * 7919) % 3380) / 1000.0;
        s.push_str(&format!(",lidar_{i}={r}"));
    }
    s.push_str(" 1719231000123456789\n");
    s
}

/// `line` with its fields in a fixed pseudo-random order, as Telegraf writes them (Go map order).
fn unordered(line: &str) -> String {
    let (head, rest) = line.split_once(' ').unwrap();
    let (fields, ts) = rest.rsplit_once(' ').unwrap();
    let mut fields: Vec<&str> = fields.split(',').collect();
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    for i in (1..fields.len()).rev() {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        fields.swap(i, (seed % (i as u64 + 1)) as usize);
    }
    format!("{head} {} {ts}", fields.join(","))
}

fn bind(c: &mut Criterion, name: &str, line: &str) {
    let program = tessla_telegraf::bundled::load(&LoadOptions::default())
        .unwrap()
        .program;
    let bs = bindings(&program).unwrap();
    let metric = lineproto::parse_record(line.as_bytes()).unwrap().unwrap();
    let mut g = c.benchmark_group(format!("bind_{name}"));
    g.throughput(Throughput::Elements(1));
    g.bench_function("robot_spec_inputs", |b| {
        b.iter(|| {
            let mut n = 0usize;
            for bnd in &bs {
                if bnd.matches(black_box(&metric))
                    && let Some(Ok(v)) = bnd.extract(&metric)
                {
                    n += usize::from(!matches!(v, tessla_engine::Value::Unit));
                    black_box(v);
                }
            }
            n
        })
    });
    g.finish();
}

fn benches(c: &mut Criterion) {
    bind(c, "p2", P2_LINE);
    bind(c, "lidar360", &lidar_line());
    bind(c, "lidar360_unordered", &unordered(&lidar_line()));
}

criterion_group!(binding, benches);
criterion_main!(binding);
