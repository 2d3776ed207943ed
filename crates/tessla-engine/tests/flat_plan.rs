//! The flat plan (`runtime::flat`) computes what the general step computes: specs made of every
//! node form the plan has, run over random traces of scalars (NaN, ±0, infinities, integers at
//! the edge of 64 bits, silent inputs) once with the plan and once by the general step alone,
//! must send the same events; tuples and strings (values the plan moves and compares by
//! reference), and VAMOS primes, alike. The integer overflows in them make the plan hand steps to the
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

/// Both programs of `spec`: with its flat plan (and its calls), and general only.
fn both(spec: &str) -> (Arc<Program>, Arc<Program>) {
    let flat = Arc::new(Program::with_calls(load(spec).into_ir()));
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

/// Values the plan only moves or compares, by reference (tuples, strings): `==`, `!=`, `last`
/// (and a `last` of a `last`, kept from another kept slot), `on`, `merge`, `filter`, `count`,
/// `if`, `default` and `defaultFrom` with a tuple, `pure` of strings.
const VALUES: &str = "in p: Events[(Int, Int)]\nin q: Events[(Int, Int)]\nin s: Events[String]\n\
    in n: Events[Int]\nin b: Events[Bool]\n\
    def eqpq = p == q\ndef nepq = p != q\ndef lp = last(p, n)\ndef llp = last(lp, b)\n\
    def op = on(b, p)\ndef mp = merge(p, q)\ndef fp = filter(p, b)\ndef cp = count(p)\n\
    def ip = if b then p else q\ndef dp = default(p, (7, 7))\ndef dfp = defaultFrom(p, q)\n\
    def sa = s == \"a\"\ndef ls = last(s, b)\ndef eqlast = op == lp\ndef ps = pure(s)\n\
    out eqpq\nout nepq\nout lp\nout llp\nout op\nout mp\nout fp\nout cp\nout ip\n\
    out dp\nout dfp\nout sa\nout ls\nout eqlast\nout ps\n";

/// VAMOS `primes.tessla` (ista-vamos/shamon, experiments/tessla_compare): tuple inputs,
/// `resetCount`, `count`, `sum`, `on` and `==` of tuples.
const PRIMES: &str = "in primes1: Events[(Int, Int)]\nin primes2: Events[(Int, Int)]\n\
    in holes1: Events[Int]\nin holes2: Events[Int]\n\
    def dropped1 = merge(if resetCount(primes1, holes1) < last(holes1, primes1) \
    then 0 else sum(holes1), 0)\n\
    def dropped2 = merge(if resetCount(primes2, holes2) < last(holes2, primes2) \
    then 0 else sum(holes2), 0)\n\
    def pos1 = merge(count(primes1), 0) + dropped1\n\
    def pos2 = merge(count(primes2), 0) + dropped2\n\
    def positions_same = unitIf(pos1 == pos2)\n\
    def p1 = on(positions_same, primes1)\ndef p2 = on(positions_same, primes2)\n\
    out p1 == p2 as ok\nout pos1\nout pos2\n";

/// Nodes whose functions have no typed form, run by the plan as calls: a recursive user
/// function, a function value applied, natives on strings and floats, a Map counted in a
/// recursion through `last`, a Set folded, `slift` and `lift` of four arguments, `resetCount`,
/// an operator on values, `if` on a computed condition, `time` and `filter` of computed values,
/// error values (a missing key) sent and used as a condition (the general step's turn).
const CALLS: &str = "in x: Events[Float]\nin n: Events[Int]\nin b: Events[Bool]\n\
    in s: Events[String]\nin p: Events[(Int, Int)]\n\
    def fib(k: Int): Int = if k < 2 then k else fib(k - 1) + fib(k - 2)\n\
    def small = slift(n, (k: Int) => fib(if k < 0 then (0 - k) % 12 else k % 12))\n\
    def apply(f: (Int) => Int, v: Int) = f(v)\n\
    def twice = slift(n, (k: Int) => apply((v: Int) => v * 2 % 1000, k))\n\
    def len = slift(s, (t: String) => if t == \"a\" then 1 else if t == \"\" then 0 else 2)\ndef cat = String.concat(s, s)\n\
    def ab = abs(x)\ndef fl = sqrt(abs(x))\ndef ts = toString(n)\n\
    liftable def getCount(counts: Map[Int, Int], key: Int) = \
    if Map.contains(counts, key) then Map.get(counts, key) else 0\n\
    liftable def incCount(counts: Map[Int, Int], key: Int) = \
    Map.add(counts, key, getCount(counts, key) + 1)\n\
    def key = slift(n, (k: Int) => k % 5)\n\
    def counts: Events[Map[Int, Int]] = default(incCount(last(counts, key), key), Map.empty[Int, Int])\n\
    def size = Map.size(counts)\n\
    def seen = fold(key, Set.empty[Int], (acc: Set[Int], k: Int) => Set.add(acc, k))\n\
    def nseen = Set.size(seen)\n\
    def four = slift(x, n, b, s, (a: Float, k: Int, c: Bool, t: String) => \
    if c && t == \"a\" then k % 3 else 0)\n\
    def lfour = lift(x, n, b, s, (a: Option[Float], k: Option[Int], c: Option[Bool], t: Option[String]) => \
    if isSome(k) && isSome(c) then Some(true) else None[Bool])\n\
    def rc = resetCount(x, b)\n\
    def eqs = cat == s\ndef big = if size > 2 then len else nseen\n\
    def tl = time(len)\ndef fsz = filter(size, len > 0)\ndef lsz = last(size, x)\n\
    def mixed = merge(len, n)\ndef sum4 = reduce(len, (a: Int, v: Int) => a + v)\n\
    def fst = slift(p, (q: (Int, Int)) => q._1)\n\
    def bad = Map.get(counts, 7)\ndef iffy = if Map.get(counts, 7) > 0 then 1 else 2\n\
    out small\nout twice\nout len\nout cat\nout ab\nout fl\nout ts\nout counts\nout size\n\
    out seen\nout nseen\nout four\nout lfour\nout rc\nout eqs\nout big\nout tl\n\
    out fsz\nout lsz\nout mixed\nout sum4\nout fst\nout bad\nout iffy\n";

/// `delay`s: `period` (re-armed by its own events), one reset by an input whose
/// amount is sometimes not positive (an error value: the general step's turn), one of a
/// computed value's node; `count` and `time` of their events.
const DELAYS: &str = "in n: Events[Int]\nin b: Events[Bool]\n\
    def amount = slift(n, (k: Int) => k % 4)\ndef d = delay(amount, b)\n\
    def tick = period(3)\n\
    def c = count(tick)\ndef t = time(d)\n\
    def m = delay(const(2, String.concat(toString(n), \"!\")), n)\n\
    out d\nout tick\nout c\nout t\nout m\n";

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
            // Few distinct values, so that equal ones meet often.
            Type::Tuple(ts) => Value::Tuple(
                ts.iter()
                    .map(|_| Value::Int(self.below(3) as i64))
                    .collect::<Vec<_>>()
                    .into(),
            ),
            Type::String => Value::Str(["a", "b", ""][self.below(3) as usize].into()),
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
    for spec in [
        EVERY_FORM, RECURSION, MOVED, LIFTS, VALUES, PRIMES, CALLS, DELAYS,
    ] {
        let (flat, general) = both(spec);
        assert!(flat.step_plan().is_some(), "no plan for\n{spec}");
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

/// A plan of more than 256 slots (read from a slice) and smaller ones (read from a fixed
/// array) take turns on one thread's slots, step by step, and each sends what the general
/// step sends.
#[test]
fn plans_large_and_small_share_the_threads_slots() {
    let mut big = String::from("in x: Events[Float]\nin n: Events[Int]\ndef d0 = x +. 1.0\n");
    for i in 1..300 {
        big.push_str(&format!("def d{i} = d{} *. 0.5 +. x\n", i - 1));
    }
    big.push_str("def c = count(n)\nout d299\nout d150\nout c\n");
    let specs = [big.as_str(), EVERY_FORM, RECURSION];
    let programs: Vec<(Arc<Program>, Arc<Program>)> = specs.iter().map(|s| both(s)).collect();
    assert!(programs[0].0.nodes.len() > 300);
    assert!(programs.iter().all(|p| p.0.step_plan().is_some()));
    for seed in 1..=5u64 {
        let run = |flat: bool| {
            let mut rng = Rng(rand::SeedableRng::seed_from_u64(seed));
            let mut ms: Vec<Monitor> = programs
                .iter()
                .map(|p| Monitor::new(Arc::clone(if flat { &p.0 } else { &p.1 })))
                .collect();
            let mut out = Vec::new();
            for ts in 1..=200 {
                for (k, m) in ms.iter_mut().enumerate() {
                    let mut sink = |e: OutputEvent<'_>| {
                        out.push(format!("{k} {} {} {:?}", e.ts, e.output, e.value))
                    };
                    for (i, input) in m.program().inputs.clone().iter().enumerate() {
                        if rng.below(3) != 0 {
                            let v = rng.value(&input.ty);
                            m.push(ts, i, v, &mut sink).unwrap();
                        }
                    }
                    m.flush(&mut sink);
                }
            }
            out
        };
        let want = run(false);
        assert!(want.len() > 1000, "too few events: {}", want.len());
        assert_eq!(run(true), want, "seed {seed}");
    }
}

/// P2 (specs/lib/p2_tolerance.tessla): every node but the `filter` fires with its two inputs.
const P2: &str = "in e: Events[Float]\nin a: Events[Float]\n\
    def diff = e -. a\ndef violated = diff >. 0.02 || diff <. -.0.02\n\
    def corrected = e +. 0.5 *. diff\n\
    def action = if !violated then e else if corrected >. 0.22 then 0.22 \
    else if corrected <. -.0.22 then -.0.22 else corrected\n\
    def augmented = action != e\ndef sq = diff *. diff\n\
    def sum = fold(sq, 0.0, (acc: Float, x: Float) => acc +. x)\ndef n = count(sq)\n\
    def mse = filter(sum /. intToFloat(n), n > 0)\ndef t = time(diff)\n\
    def r = reduce(a, (x: Float, y: Float) => x +. y)\n\
    out diff\nout violated\nout action\nout augmented\nout mse\nout t\nout r\n";

/// The plan's straight block (the steps where every input has an event, run without presence
/// tests) sends what the general step sends, on traces where the inputs mostly come together
/// and sometimes apart (the block and the plan's loop take turns), with NaN and infinities.
#[test]
fn the_straight_block_sends_what_the_general_step_sends() {
    let (flat, general) = both(P2);
    let plan = flat.step_plan().expect("P2 has a plan");
    // Every node but the `filter` (its event depends on a value).
    assert_eq!(plan.straight_nodes(), flat.nodes.len() - 1);
    // Both inputs in 7 of 8 steps; else one of them.
    sends_alike(&flat, &general, 400, 2000, |rng, n| {
        let which = rng.below(16);
        (0..n as u64).map(|i| which >= 2 || which == i).collect()
    });
}

/// Every operator the straight block fuses with its operands' shape (`runtime::flat::fused`):
/// on floats, integers and booleans, node and node, node and constant, constant and node; the
/// `if`s of each shape, `!`, `-.`, `intToFloat`, integer `+` and `-` (which may overflow: the
/// general step's turn), an input of each kind, `fold`, `reduce`, `time`, `default`, `unitIf`.
const FUSED: &str = "in x: Events[Float]\nin y: Events[Float]\nin i: Events[Int]\n\
    in j: Events[Int]\nin b: Events[Bool]\nin c: Events[Bool]\n\
    def fa = x +. y\ndef fa1 = x +. 1.5\ndef fa2 = 2.5 +. y\n\
    def fs = x -. y\ndef fs1 = x -. 1.5\ndef fs2 = 2.5 -. y\n\
    def fm = x *. y\ndef fm1 = x *. 1.5\ndef fm2 = 2.5 *. y\n\
    def fd = x /. y\ndef fd1 = x /. 0.0\ndef fd2 = 2.5 /. y\n\
    def lt = x <. y\ndef lt1 = x <. 1.5\ndef lt2 = 2.5 <. y\n\
    def gt = x >. y\ndef gt1 = x >. 1.5\ndef gt2 = 2.5 >. y\n\
    def le = x <=. y\ndef le1 = x <=. 1.5\ndef le2 = 2.5 <=. y\n\
    def ge = x >=. y\ndef ge1 = x >=. 1.5\ndef ge2 = 2.5 >=. y\n\
    def fe = x == y\ndef fe1 = x == 0.0\ndef fe2 = 0.0 == y\n\
    def fn = x != y\ndef fn1 = x != 0.0\ndef fn2 = 0.0 != y\n\
    def il = i < j\ndef il1 = i < 3\ndef il2 = 3 < j\n\
    def ig = i > j\ndef ig1 = i > 3\ndef ig2 = 3 > j\n\
    def ile = i <= j\ndef ile1 = i <= 3\ndef ile2 = 3 <= j\n\
    def ige = i >= j\ndef ige1 = i >= 3\ndef ige2 = 3 >= j\n\
    def ie = i == j\ndef ie1 = i == 3\ndef ie2 = 3 == j\n\
    def ine = i != j\ndef ine1 = i != 3\ndef ine2 = 3 != j\n\
    def be = b == c\ndef bn = b != c\ndef ba = b && c\ndef bo = b || c\n\
    def ia = i + j\ndef is = i - 1\ndef nb = !b\ndef nx = -. x\ndef itf = intToFloat(i)\n\
    def t1 = if b then x else y\ndef t2 = if b then x else 1.5\ndef t3 = if b then 1.5 else y\n\
    def t4 = if b then 1.5 else 2.5\n\
    def sx = fold(x, 0.0, (acc: Float, v: Float) => acc +. v)\n\
    def ri = reduce(i, (acc: Int, v: Int) => acc + v)\ndef cnt = count(j)\n\
    def tm = time(y)\ndef dx = default(x, 0.5)\ndef u = unitIf(c)\n\
    out fa\nout fa1\nout fa2\nout fs\nout fs1\nout fs2\nout fm\nout fm1\nout fm2\n\
    out fd\nout fd1\nout fd2\nout lt\nout lt1\nout lt2\nout gt\nout gt1\nout gt2\n\
    out le\nout le1\nout le2\nout ge\nout ge1\nout ge2\nout fe\nout fe1\nout fe2\n\
    out fn\nout fn1\nout fn2\nout il\nout il1\nout il2\nout ig\nout ig1\nout ig2\n\
    out ile\nout ile1\nout ile2\nout ige\nout ige1\nout ige2\nout ie\nout ie1\nout ie2\n\
    out ine\nout ine1\nout ine2\nout be\nout bn\nout ba\nout bo\nout ia\nout is\n\
    out nb\nout nx\nout itf\nout t1\nout t2\nout t3\nout t4\nout sx\nout ri\nout cnt\n\
    out tm\nout dx\nout u\n";

/// The straight block's fused operators (every shape of each, on NaN, ±0, infinities and
/// integers at the edge of 64 bits) send what the general step sends, on traces where every
/// input mostly has an event (the block's steps) and sometimes one is silent (the loop's).
#[test]
fn every_fused_operator_sends_what_the_general_step_sends() {
    let (flat, general) = both(FUSED);
    let plan = flat.step_plan().expect("FUSED has a plan");
    // Every node but `unitIf`'s `filter`.
    assert_eq!(plan.straight_nodes(), flat.nodes.len() - 1);
    // Every input in 7 of 8 steps; else one is silent.
    sends_alike(&flat, &general, 200, 10_000, |rng, n| {
        let silent = rng.below(8 * n as u64);
        (0..n as u64).map(|i| silent != i).collect()
    });
}

/// `flat` and `general` send the same events on 20 seeded random traces of `steps` steps, with
/// at least `min` events each. `draw(rng, n)` draws, once per step, which of the `n` inputs have
/// an event in it (each of those gets a random value of its type).
fn sends_alike(
    flat: &Arc<Program>,
    general: &Arc<Program>,
    steps: i64,
    min: usize,
    draw: impl Fn(&mut Rng, usize) -> Vec<bool>,
) {
    for seed in 1..=20u64 {
        let run = |program: &Arc<Program>| {
            let mut rng = Rng(rand::SeedableRng::seed_from_u64(seed));
            let mut m = Monitor::new(Arc::clone(program));
            let mut out = Vec::new();
            let mut sink =
                |e: OutputEvent<'_>| out.push(format!("{} {} {:?}", e.ts, e.output, e.value));
            for ts in 1..=steps {
                let present = draw(&mut rng, program.inputs.len());
                for (i, input) in program.inputs.iter().enumerate() {
                    if present[i] {
                        let v = rng.value(&input.ty);
                        m.push(ts, i, v, &mut sink).unwrap();
                    }
                }
                m.flush(&mut sink);
            }
            out
        };
        let want = run(general);
        assert!(want.len() > min, "too few events: {}", want.len());
        assert_eq!(run(flat), want, "seed {seed}");
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
fn every_form_has_a_plan() {
    for spec in [
        // A delay.
        "in x: Events[Int]\ndef d = delay(x, x)\nout d\n",
        "in x: Events[Float]\ndef y = x *. 2.0\nout y\n",
        // Strings and tuples, moved and compared.
        "in s: Events[String]\ndef t = s\nout t\n",
        "in p: Events[(Int, Float)]\nin q: Events[(Int, Float)]\ndef e = p == q\nout e\n",
        // A list's size (a native on a value the plan only moves): a call.
        "in l: Events[List[Float]]\ndef n = List.size(l)\nout n\n",
    ] {
        assert!(load(spec).exec().plan().is_some(), "no plan for\n{spec}");
    }
}
