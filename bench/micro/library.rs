//! What a library costs (issue 14): the P2 step with and without 400 definitions that no output
//! uses (library functions of the prelude, helpers, helper applications), and the load time of
//! both. Unused definitions are checked at load but never lowered, so the program, and with it
//! the per-event cost, is the same: the setup asserts the two programs have the same nodes, and
//! the two step figures come from the same run (`make bench`).

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::sync::Arc;
use tessla_engine::{LoadOptions, Monitor, OutputEvent, Program, Value};
use tessla_syntax::include::MemResolver;

const P2: &str = "in expectedSpeed: Events[Float]\nin actualSpeed: Events[Float]\ndef delta = 0.02\n\
def diff = expectedSpeed -. actualSpeed\ndef violated = diff >. delta || diff <. -.delta\n\
def action = if violated then expectedSpeed +. 0.5 *. diff else expectedSpeed\nout violated\nout action\n";

/// P2 followed by 400 definitions no output reads.
fn with_library() -> String {
    let mut s = P2.to_string();
    s.push_str("module Unused {\n");
    for i in 0..100 {
        s.push_str(&format!(
            "  def c{i} = count(expectedSpeed) + {i}\n\
             \x20 def d{i} = default(actualSpeed, {i}.0) +. expectedSpeed\n\
             \x20 def f{i}(x: Events[Float]): Events[Float] = x *. {i}.5 +. prev(x)\n\
             \x20 def g{i} = f{i}(actualSpeed)\n"
        ));
    }
    s.push_str("}\n");
    s
}

fn load(text: &str) -> Arc<Program> {
    let resolver = MemResolver {
        files: [("spec.tessla".to_string(), text.to_string())].into(),
    };
    match tessla_engine::load_with("spec.tessla", &resolver, &LoadOptions::default()) {
        Ok(l) => l.program,
        Err(e) => panic!("the benchmark spec does not load:\n{}", e.render()),
    }
}

fn step(c: &mut Criterion, name: &str, program: Arc<Program>) {
    c.bench_function(name, |b| {
        let mut m = Monitor::new(Arc::clone(&program));
        let mut ts = 0i64;
        let mut sink = |e: OutputEvent<'_>| {
            black_box(e.value);
        };
        b.iter(|| {
            ts += 1;
            let x = (ts % 100) as f64 / 1000.0;
            let _ = m.push(ts, 0, Value::Float(0.1), &mut sink);
            let _ = m.push(ts, 1, Value::Float(x), &mut sink);
        });
    });
}

fn library(c: &mut Criterion) {
    let lib = with_library();
    let alone = load(P2);
    let with = load(&lib);
    assert_eq!(
        alone.nodes.len(),
        with.nodes.len(),
        "unused definitions must not be lowered"
    );
    step(c, "p2 step, spec alone", alone);
    step(c, "p2 step, spec + 400 unused definitions", with);
    c.bench_function("load p2 spec alone", |b| b.iter(|| black_box(load(P2))));
    c.bench_function("load p2 spec + 400 unused definitions", |b| {
        b.iter(|| black_box(load(&lib)))
    });
}

criterion_group!(benches, library);
criterion_main!(benches);
