//! Criterion guard of the record path's middle: binding a parsed metric to the spec's inputs
//! (`InputBinding::matches` + `extract`, value conversion) for the P2 record (two speeds, one a
//! string) and a full robot message with a 360-beam scan gathered by `lidar_*` into one list
//! (fields sorted, and in Telegraf's random order: `bind_lidar360_unordered`).
//! Run with `make bench` (or `cargo bench --bench binding`).

use test_support::workload::{P2_LINE, lidar_line, unordered};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use tessla_telegraf::telegraf::binding::bindings;

fn bind(c: &mut Criterion, name: &str, line: &str) {
    let program =
        tessla_telegraf::bundled::load(&tessla_telegraf::natives::load_options().unwrap())
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
