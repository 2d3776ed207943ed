//! Snapshots: a monitor saved mid-run (through JSON) and restored continues exactly as the
//! uninterrupted monitor; restored into a changed spec, unchanged streams keep their state.

use std::sync::Arc;
use tessla_engine::snapshot::{self, Snapshot};
use tessla_engine::{Monitor, OutputEvent, Program, Value};
use tessla_syntax::include::MemResolver;

fn load(spec: &str) -> Arc<Program> {
    let resolver = MemResolver {
        files: [("spec.tessla".to_string(), spec.to_string())].into(),
    };
    tessla_engine::load_with("spec.tessla", &resolver, &Default::default())
        .map_err(|e| e.render())
        .unwrap()
        .program
}

/// Feed `events` (ts, input, value) to `m`, flushing after each; output lines `ts: name = value`.
fn feed(m: &mut Monitor, events: &[(i64, &str, Value)]) -> Vec<String> {
    let program = Arc::clone(m.program());
    let mut out = Vec::new();
    let mut sink = |e: OutputEvent<'_>| {
        out.push(format!(
            "{}: {} = {}",
            e.ts, program.outputs[e.output].name, e.value
        ))
    };
    for (ts, name, v) in events {
        let i = program.input_index(name).unwrap();
        m.push(*ts, i, v.clone(), &mut sink).unwrap();
        m.flush(&mut sink);
    }
    out
}

const SPEC: &str = "in x: Events[Int]\nin r: Events[Unit]\n\
    def c = count(x)\n\
    def prev = last(x, x)\n\
    def s: Events[Int] = default(last(s, x), 0) + x\n\
    def f = intToFloat(x) /. 3.0\n\
    def d = delay(const(5, r), r)\n\
    def tick = count(d)\n\
    out c\nout prev\nout s\nout f\nout d\nout tick\n";

fn events() -> Vec<(i64, &'static str, Value)> {
    let mut ev = Vec::new();
    for t in 1..=20i64 {
        ev.push((t * 3, "x", Value::Int(t * t % 7)));
        if t % 4 == 0 {
            ev.push((t * 3 + 1, "r", Value::Unit));
        }
    }
    ev
}

fn json_roundtrip(s: &Snapshot) -> Snapshot {
    let text = serde_json::to_string(s).unwrap();
    serde_json::from_str(&text).unwrap()
}

#[test]
fn a_restored_monitor_continues_as_the_uninterrupted_one() {
    let program = load(SPEC);
    let ev = events();
    let mut whole = Monitor::starting_at(Arc::clone(&program), 1);
    let expected = feed(&mut whole, &ev);
    for cut in [1, 5, 11, ev.len() - 1] {
        let mut first = Monitor::starting_at(Arc::clone(&program), 1);
        let mut got = feed(&mut first, &ev[..cut]);
        let snap = json_roundtrip(&snapshot::snapshot(&first));
        assert_eq!(snap.unsaved, 0);
        let mut second = snapshot::restore(Arc::clone(&program), &snap);
        got.extend(feed(&mut second, &ev[cut..]));
        assert_eq!(got, expected, "cut after {cut} events");
    }
}

#[test]
fn node_keys_do_not_depend_on_numbering_and_see_operators() {
    let a = load(
        "in x: Events[Int]\nin y: Events[Int]\ndef p = x + y\ndef c = count(x)\nout p\nout c\n",
    );
    // Same streams, defined in another order.
    let b = load(
        "in x: Events[Int]\nin y: Events[Int]\ndef c = count(x)\ndef p = x + y\nout c\nout p\n",
    );
    assert!(snapshot::changed_nodes(&a, &b).is_empty());
    // Another operator with the same arguments is another stream.
    let c = load(
        "in x: Events[Int]\nin y: Events[Int]\ndef p = x * y\ndef c = count(x)\nout p\nout c\n",
    );
    let changed = snapshot::changed_nodes(&a, &c);
    assert!(!changed.is_empty());
    let out_p = c.output_nodes[c.outputs.iter().position(|o| o.name == "p").unwrap()];
    let out_c = c.output_nodes[c.outputs.iter().position(|o| o.name == "c").unwrap()];
    assert!(changed.contains(&out_p));
    assert!(!changed.contains(&out_c));
    assert_ne!(snapshot::fingerprint(&a), snapshot::fingerprint(&c));
}

#[test]
fn a_changed_spec_keeps_the_state_of_unchanged_streams() {
    let old = load("in x: Events[Int]\ndef c = count(x)\ndef m = x + 1\nout c\nout m\n");
    let new = load(
        "in x: Events[Int]\ndef c = count(x)\ndef m = x * 2\ndef n = count(x)\nout c\nout m\ndef total = c + n\nout total\n",
    );
    let mut m = Monitor::starting_at(Arc::clone(&old), 0);
    feed(&mut m, &[(1, "x", Value::Int(1)), (2, "x", Value::Int(2))]);
    let snap = json_roundtrip(&snapshot::snapshot(&m));
    let mut m2 = snapshot::restore(Arc::clone(&new), &snap);
    let out = feed(&mut m2, &[(3, "x", Value::Int(5))]);
    // `c` keeps counting (3), `n` (new, same text as `c` but another def) starts from 0.
    assert!(out.contains(&"3: c = 3".to_string()), "{out:?}");
    assert!(out.contains(&"3: m = 10".to_string()), "{out:?}");
    assert!(out.contains(&"3: total = 4".to_string()), "{out:?}");
}

#[test]
fn floats_errors_and_collections_survive_json() {
    let vals = [
        Value::Float(f64::NAN),
        Value::Float(f64::NEG_INFINITY),
        Value::Float(-0.0),
        Value::Float(0.1 + 0.2),
        Value::Float(f64::MIN_POSITIVE / 3.0),
        Value::List(Arc::new(vec![
            Value::Float(2.003),
            Value::Float(f64::NAN),
            Value::Float(f64::INFINITY),
        ])),
        Value::List(Arc::new(vec![Value::Float(1.0), Value::Int(1)])),
        Value::Error(tessla_engine::RuntimeError::Other("boom".into())),
        Value::Some(Arc::new(Value::List(Arc::new(vec![Value::Str(
            "é\n".into(),
        )])))),
    ];
    for v in vals {
        let s = snapshot::SValue::from_value(&v).unwrap();
        let back: snapshot::SValue =
            serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
        assert_eq!(back.to_value().to_string(), v.to_string());
        if let (Value::Float(a), Value::Float(b)) = (back.to_value(), &v) {
            assert_eq!(a.to_bits(), b.to_bits(), "{b} is restored exactly");
        }
    }
}

/// The output node of `name` in `p`.
fn out_node(p: &Program, name: &str) -> usize {
    p.output_nodes[p.outputs.iter().position(|o| o.name == name).unwrap()]
}

#[test]
fn node_keys_see_the_code_of_the_functions_they_call() {
    let spec = |f_body: &str, first: &str, second: &str| {
        load(&format!(
            "in x: Events[Int]\ndef f(a: Int): Int = {f_body}\ndef g(a: Int): Int = a * 2\n\
             def h(a: Int): Int = f(a) * 3\n\
             def y = slift1(x, f)\ndef z = slift1(x, g)\ndef w = slift1(x, h)\n\
             out {first}\nout {second}\nout w\n"
        ))
    };
    let a = spec("a + 1", "y", "z");
    // The functions are lowered in another order (other indices): the same streams.
    let b = spec("a + 1", "z", "y");
    assert!(snapshot::changed_nodes(&a, &b).is_empty());
    // `f` changes: `y` and `w` (through `h`) are new streams, `z` is not.
    let c = spec("a + 2", "y", "z");
    let changed = snapshot::changed_nodes(&a, &c);
    assert!(changed.contains(&out_node(&c, "y")), "{changed:?}");
    assert!(changed.contains(&out_node(&c, "w")), "{changed:?}");
    assert!(!changed.contains(&out_node(&c, "z")), "{changed:?}");
}
