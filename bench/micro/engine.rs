//! Engine benchmarks (issue 2's targets): time per timestamp of a P2-shaped spec (two Float
//! inputs, a difference, a comparison, an if-then-else, two outputs; target <= 150 ns), and the
//! load time (parse, check, compile) of the bundled robot specs (target < 10 ms).
//! Run with `make bench`. The P2 step is measured twice: wall time, and on-CPU time of the
//! thread (robust when other jobs share the cores).

use criterion::measurement::{Measurement, ValueFormatter, WallTime};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::sync::Arc;
use tessla_engine::{LoadOptions, Monitor, OutputEvent, Value};
use tessla_syntax::include::MemResolver;

const P2: &str = "in expectedSpeed: Events[Float]\nin actualSpeed: Events[Float]\ndef delta = 0.02\n\
def diff = expectedSpeed -. actualSpeed\ndef violated = diff >. delta || diff <. -.delta\n\
def action = if violated then expectedSpeed +. 0.5 *. diff else expectedSpeed\nout violated\nout action\n";

fn p2_step(c: &mut Criterion) {
    p2_step_named(c, "p2 step (2 inputs, 2 outputs)");
}

fn p2_step_named<M: Measurement + 'static>(c: &mut Criterion<M>, name: &str) {
    let resolver = MemResolver {
        files: [("p2.tessla".to_string(), P2.to_string())].into(),
    };
    let loaded = tessla_engine::load_with("p2.tessla", &resolver, &LoadOptions::default()).unwrap();
    let program = loaded.program;
    c.bench_function(name, |b| {
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
                tessla_telegraf::bundled::load(&tessla_telegraf::natives::load_options().unwrap())
                    .unwrap()
                    .program
                    .nodes
                    .len(),
            )
        });
    });
}

/// On-CPU time of this thread (`CLOCK_THREAD_CPUTIME_ID`, nanoseconds): unlike wall time it
/// does not count time the thread waits for a core, so the figure stays meaningful on a shared,
/// loaded machine. Hand-written: criterion has no CPU-time measurement, and std exposes no
/// thread clock (declared here for 64-bit Linux rather than adding a `libc` dependency).
struct OnCpu;

#[repr(C)]
struct Timespec {
    tv_sec: i64,
    tv_nsec: i64,
}

unsafe extern "C" {
    fn clock_gettime(clock: i32, ts: *mut Timespec) -> i32;
}

fn on_cpu_ns() -> u64 {
    const CLOCK_THREAD_CPUTIME_ID: i32 = 3;
    let mut ts = Timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec for the duration of the call.
    let rc = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return 0;
    }
    (ts.tv_sec as u64) * 1_000_000_000 + ts.tv_nsec as u64
}

static WALL: WallTime = WallTime;

impl Measurement for OnCpu {
    type Intermediate = u64;
    type Value = u64;
    fn start(&self) -> u64 {
        on_cpu_ns()
    }
    fn end(&self, start: u64) -> u64 {
        on_cpu_ns().saturating_sub(start)
    }
    fn add(&self, a: &u64, b: &u64) -> u64 {
        a + b
    }
    fn zero(&self) -> u64 {
        0
    }
    fn to_f64(&self, v: &u64) -> f64 {
        *v as f64
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        WALL.formatter()
    }
}

criterion_group!(benches, p2_step, robot_load);
criterion_group! {
    name = on_cpu;
    config = Criterion::default().with_measurement(OnCpu);
    targets = p2_step_on_cpu
}

fn p2_step_on_cpu(c: &mut Criterion<OnCpu>) {
    p2_step_named(c, "p2 step, on-CPU time (2 inputs, 2 outputs)");
}
criterion_main!(benches, on_cpu);
