//! The flat plan (`runtime::flat`) computes what the general step computes: specs made of every
//! node form the plan has, run over random traces of scalars (NaN, ±0, infinities, integers at
//! the edge of 64 bits, silent inputs) once with the plan and once by the general step alone,
//! must send the same events. The integer overflows in them make the plan hand steps to the
//! general step and take them back, so the turns are tested too.

use std::sync::Arc;
use tessla_engine::{LoadOptions, Monitor, OutputEvent, Program, Type, Value};
use tessla_syntax::include::MemResolver;

fn load(spec: &str) -> Program {
    let resolver = MemResolver {
        files: [("spec.tessla".to_string(), spec.to_string())].into(),
    };
    let loaded = tessla_engine::load_with("spec.tessla", &resolver, &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{}", e.render()));
    Arc::try_unwrap(loaded.program).unwrap_or_else(|_| panic!("a loaded program is not shared yet"))
}

/// Both programs of `spec`: with its flat plan, and general only.
fn both(spec: &str) -> (Arc<Program>, Arc<Program>) {
    let flat = Arc::new(load(spec));
    let general = Arc::new(Program::general_only(load(spec).into_ir()));
    (flat, general)
}

/// Every form the plan has: `last`, `default`, `defaultFrom`, `time`, `merge`, `filter`,
/// `reduce`, `fold` (one near `Int`'s limit, so it overflows into a big integer, and a product),
/// `count`, `unitIf`, `==`, `!=`, `-.`, `!`, `intToFloat`, `if`, integer and float operators
/// (`*`, `/`, `%` with zero divisors and overflow among them), `&&`.
const EVERY_FORM: &str = "in x: Events[Float]\nin y: Events[Float]\nin n: Events[Int]\n\
    in b: Events[Bool]\n\
    def lx = last(x, y)\ndef dx = default(x, 1.5)\ndef dfx = defaultFrom(x, y)\n\
    def tx = time(x)\ndef mxy = merge(x, y)\ndef fx = filter(x, b)\n\
    def rn = reduce(n, (a: Int, v: Int) => a + v)\n\
    def sn = fold(n, 9223372036854775000, (a: Int, v: Int) => a + v)\n\
    def cn = count(b)\ndef u = unitIf(b)\ndef eqn = n == sn\ndef nex = x != y\n\
    def neg = -. x\ndef notb = !b\ndef i2f = intToFloat(n)\n\
    def pick = if b then x else y\ndef sub = n - 3\ndef cmp = n <= rn\n\
    def andb = b && (x >. y)\ndef fl = x /. y\ndef lsn = last(sn, b)\n\
    def prod = n * rn\ndef quo = rn / (n % 7)\ndef rem = n % (n - 1)\n\
    def pr = fold(n, 1, (a: Int, v: Int) => a * v)\n\
    out lx\nout dx\nout dfx\nout tx\nout mxy\nout fx\nout rn\nout sn\nout cn\nout u\n\
    out eqn\nout nex\nout neg\nout notb\nout i2f\nout pick\nout sub\nout cmp\nout andb\n\
    out fl\nout lsn\nout prod\nout quo\nout rem\nout pr\n";

/// Constants, `nil`, an alias, and a recursion through `last` (a node read before it is
/// defined).
const RECURSION: &str = "in x: Events[Float]\nin n: Events[Int]\n\
    def c: Events[Int] = 7\ndef z: Events[Int] = nil\ndef m2 = merge(z, n)\n\
    def s: Events[Float] = default(last(s, x), 0.0) +. x\n\
    def big = fold(n, 0, (a: Int, v: Int) => a - v)\n\
    out c\nout m2\nout s\nout big\n";

/// Values the plan only moves (strings from constants: `const`, `if`, `filter`, `last`,
/// `merge`), and lifts whose value is one of their arguments (`first`, a lambda's parameter).
const MOVED: &str = "in x: Events[Float]\nin n: Events[Int]\nin b: Events[Bool]\n\
    def reason = filter(const(\"p2\", x), b)\n\
    def label = if b then \"yes\" else \"no\"\n\
    def said = last(label, x)\n\
    def either = merge(reason, const(\"n\", n))\n\
    def seq = first(count(x), n)\n\
    def kept = first(n, x)\n\
    def second = slift(x, n, (a: Float, v: Int) => v)\n\
    out reason\nout label\nout said\nout either\nout seq\nout kept\nout second\n";

/// Event lifts: `on`, `pure` (of floats, NaN and ±0 among them, and of integers), `firstEvent`,
/// `rising`, `falling`; their `nil` arguments are never evaluated.
const LIFTS: &str = "in x: Events[Float]\nin n: Events[Int]\nin b: Events[Bool]\n\
    def o = on(b, x)\ndef p = pure(x)\ndef pn = pure(n)\ndef fe = firstEvent(n)\n\
    def r = rising(b)\ndef f = falling(b)\n\
    out o\nout p\nout pn\nout fe\nout r\nout f\n";

/// A fixed-seed generator (ChaCha) of inputs, so a failure reproduces.
struct Rng(rand_chacha::ChaCha8Rng);

impl Rng {
    fn below(&mut self, n: u64) -> u64 {
        rand::RngCore::next_u64(&mut self.0) % n
    }

    fn value(&mut self, ty: &Type) -> Value {
        match ty {
            Type::Float => Value::Float(match self.below(8) {
                0 => f64::NAN,
                1 => -0.0,
                2 => 0.0,
                3 => f64::INFINITY,
                _ => (self.below(2001) as f64 - 1000.0) / 7.0,
            }),
            Type::Int => Value::Int(match self.below(6) {
                0 => i64::MAX - self.below(3) as i64,
                1 => i64::MIN + self.below(3) as i64,
                _ => self.below(2001) as i64 - 1000,
            }),
            Type::Bool => Value::Bool(self.below(2) == 0),
            other => panic!("no values of {other}"),
        }
    }
}

/// The events a program sends on a random trace, as text (`{:?}` tells -0.0 from 0.0).
fn outputs(program: &Arc<Program>, seed: u64, steps: usize) -> Vec<String> {
    let mut rng = Rng(rand::SeedableRng::seed_from_u64(seed));
    let mut m = Monitor::new(Arc::clone(program));
    let mut out = Vec::new();
    let mut sink = |e: OutputEvent<'_>| out.push(format!("{} {} {:?}", e.ts, e.output, e.value));
    let mut ts = 0;
    for _ in 0..steps {
        ts += 1 + rng.below(3) as i64;
        for (i, input) in program.inputs.iter().enumerate() {
            // Each input silent in about a third of the steps.
            if rng.below(3) != 0 {
                let v = rng.value(&input.ty);
                m.push(ts, i, v, &mut sink).unwrap();
            }
        }
        if rng.below(4) == 0 {
            m.flush(&mut sink);
        }
    }
    m.flush(&mut sink);
    out
}

#[test]
fn the_plan_sends_what_the_general_step_sends() {
    for spec in [EVERY_FORM, RECURSION, MOVED, LIFTS] {
        let (flat, general) = both(spec);
        assert!(flat.exec().plan().is_some(), "no plan for\n{spec}");
        assert!(general.exec().plan().is_none());
        for seed in 1..=40u64 {
            let want = outputs(&general, seed, 300);
            let got = outputs(&flat, seed, 300);
            assert!(
                want.len() > 300,
                "too few events to compare: {}",
                want.len()
            );
            assert_eq!(got, want, "seed {seed}, spec\n{spec}");
        }
    }
}

#[test]
fn overflow_hands_the_step_to_the_general_step() {
    // `sn` passes i64::MAX at once: a big integer, which the general step computes and keeps;
    // the plan then gives every step that reads it back to the general step.
    let spec = "in n: Events[Int]\n\
        def sn = fold(n, 9223372036854775800, (a: Int, v: Int) => a + v)\n\
        def d = intToFloat(n)\nout sn\nout d\n";
    let (flat, general) = both(spec);
    assert!(flat.exec().plan().is_some());
    for program in [&flat, &general] {
        let mut m = Monitor::new(Arc::clone(program));
        let mut out = Vec::new();
        let mut sink = |e: OutputEvent<'_>| out.push(format!("{} {}", e.ts, e.value));
        for (ts, v) in [(1, 5), (2, 10), (3, -20), (4, 1)] {
            m.push(ts, 0, Value::Int(v), &mut sink).unwrap();
            m.flush(&mut sink);
        }
        assert_eq!(
            out,
            [
                "0 9223372036854775800",
                "1 9223372036854775805",
                "1 5.0",
                "2 9223372036854775815",
                "2 10.0",
                "3 9223372036854775795",
                "3 -20.0",
                "4 9223372036854775796",
                "4 1.0",
            ]
        );
    }
}

#[test]
fn only_programs_of_scalars_without_delays_have_a_plan() {
    for spec in [
        // A list input.
        "in l: Events[List[Float]]\ndef n = List.size(l)\nout n\n",
        // A string.
        "in s: Events[String]\ndef t = s\nout t\n",
        // A delay.
        "in x: Events[Int]\ndef d = delay(x, x)\nout d\n",
    ] {
        assert!(load(spec).exec().plan().is_none(), "a plan for\n{spec}");
    }
    assert!(
        load("in x: Events[Float]\ndef y = x *. 2.0\nout y\n")
            .exec()
            .plan()
            .is_some()
    );
}
