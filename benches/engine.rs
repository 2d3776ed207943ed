//! Engine benchmarks (issue 2's targets): time per timestamp of a P2-shaped spec (two Float
//! inputs, a difference, a comparison, an if-then-else, two outputs; target <= 150 ns), and the
//! load time (parse, check, compile) of the bundled robot specs (target < 10 ms).
//! Run with `make bench`.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::sync::Arc;
use tessla_engine::{LoadOptions, Monitor, OutputEvent, Value};
use tessla_syntax::include::MemResolver;

const P2: &str = "in expectedSpeed: Events[Float]\nin actualSpeed: Events[Float]\ndef delta = 0.02\n\
def diff = expectedSpeed -. actualSpeed\ndef violated = diff >. delta || diff <. -.delta\n\
def action = if violated then expectedSpeed +. 0.5 *. diff else expectedSpeed\nout violated\nout action\n";

fn p2_step(c: &mut Criterion) {
    let resolver = MemResolver {
        files: [("p2.tessla".to_string(), P2.to_string())].into(),
    };
    let loaded = tessla_engine::load_with("p2.tessla", &resolver, &LoadOptions::default()).unwrap();
    let program = loaded.program;
    c.bench_function("p2 step (2 inputs, 2 outputs)", |b| {
        let mut m = Monitor::new(Arc::clone(&program));
        let mut ts = 0i64;
        let mut outs = 0usize;
        let mut sink = |e: OutputEvent<'_>| {
            black_box(e.value);
            outs += 1;
        };
        b.iter(|| {
            ts += 1;
            let x = (ts % 100) as f64 / 1000.0;
            let _ = m.push(ts, 0, Value::Float(0.1), &mut sink);
            let _ = m.push(ts, 1, Value::Float(x), &mut sink);
        });
    });
}

fn robot_load(c: &mut Criterion) {
    c.bench_function("load bundled robot specs", |b| {
        b.iter(|| {
            black_box(
                tessla_telegraf::bundled::load(&LoadOptions::default())
                    .unwrap()
                    .program
                    .nodes
                    .len(),
            )
        });
    });
}

criterion_group!(benches, p2_step, robot_load);
criterion_main!(benches);
