//! Engine semantics on small specs: closures over enclosing parameters, recursion, liftable
//! functions, modules, collections, time literal conversion and stream functions. Each test
//! loads a spec from memory, feeds events through a `Monitor` and checks the output lines.

use std::sync::Arc;
use tessla_engine::{LoadOptions, Loaded, Monitor, OutputEvent, Value};
use tessla_syntax::include::MemResolver;

fn load(spec: &str, base_time: Option<&str>) -> Result<Loaded, String> {
    let resolver = MemResolver {
        files: [("spec.tessla".to_string(), spec.to_string())].into(),
    };
    let options = LoadOptions {
        base_time: base_time.map(str::to_string),
        overrides: Vec::new(),
        time_units_need_base: false,
        ..Default::default()
    };
    tessla_engine::load_with("spec.tessla", &resolver, &options).map_err(|e| e.render())
}

/// Run `spec` over `(ts, input, value)` events; output lines `ts: name = value`, sorted per step.
fn run(spec: &str, events: &[(i64, &str, Value)]) -> Vec<String> {
    let loaded = load(spec, None).unwrap();
    let program = Arc::clone(&loaded.program);
    let mut m = Monitor::new(Arc::clone(&program));
    let mut out: Vec<(i64, String)> = Vec::new();
    let mut sink = |e: OutputEvent<'_>| {
        out.push((
            e.ts,
            format!("{}: {} = {}", e.ts, program.outputs[e.output].name, e.value),
        ));
    };
    for (ts, name, v) in events {
        let i = program.input_index(name).unwrap();
        m.push(*ts, i, v.clone(), &mut sink).unwrap();
    }
    m.flush(&mut sink);
    out.sort();
    out.into_iter().map(|(_, l)| l).collect()
}

fn int(i: i64) -> Value {
    Value::Int(i)
}

#[test]
fn nested_functions_see_the_enclosing_parameters() {
    let spec = "in x: Events[Int]\n\
        def f(a: Int) = {\n  def g(b: Int) = a * 10 + b\n  g(3)\n}\n\
        def y := slift1(x, f)\nout y\n";
    assert_eq!(
        run(spec, &[(1, "x", int(4)), (2, "x", int(7))]),
        ["1: y = 43", "2: y = 73"]
    );
}

#[test]
fn returned_closures_keep_their_captured_values() {
    let spec = "in x: Events[Int]\n\
        def pow(b: Int): (Int) => Int = {\n\
          def prod(n: Int): Int = if n <= 1 then b else prod(n - 1) * b\n  prod\n}\n\
        out slift2(x, x, (a: Int, n: Int) => pow(a)(n)) as y\n";
    assert_eq!(
        run(spec, &[(1, "x", int(2)), (2, "x", int(3))]),
        ["1: y = 4", "2: y = 27"]
    );
}

#[test]
fn recursive_calls_with_constant_arguments_run_at_evaluation_time() {
    let spec = "in x: Events[Int]\n\
        def f(n: Int): Int = if n < 5 then 0 else f(3) + 1\nout slift1(x, f) as y\n";
    assert_eq!(
        run(spec, &[(1, "x", int(9)), (2, "x", int(1))]),
        ["1: y = 1", "2: y = 0"]
    );
}

#[test]
fn liftable_functions_are_signal_lifted_on_streams() {
    let spec = "in x: Events[Int]\nin y: Events[Int]\n\
        liftable def second(a: Int, b: Int): Int := b\nout second(x, y) as s\n";
    // No event before both streams have a value.
    assert_eq!(
        run(
            spec,
            &[(1, "y", int(42)), (2, "x", int(23)), (3, "y", int(13))]
        ),
        ["2: s = 42", "3: s = 13"]
    );
}

#[test]
fn static_if_on_a_parameter_expands_the_function() {
    let spec = "in x: Events[Int]\n\
        def foo(c: Bool) = static if c then x + 42 else x + 5\n\
        out foo(true) as a\nout foo(false) as b\n";
    assert_eq!(run(spec, &[(1, "x", int(0))]), ["1: a = 42", "1: b = 5"]);
}

#[test]
fn shifts_follow_unbounded_integer_semantics() {
    let spec = "in x: Events[Int]\nin y: Events[Int]\n\
        def l := x << y\ndef r := x >> y\nout l\nout r\n";
    assert_eq!(
        run(
            spec,
            &[(1, "x", int(-2)), (1, "y", int(-4)), (2, "y", int(2))]
        ),
        ["1: l = -1", "1: r = -32", "2: l = -8", "2: r = -1"]
    );
    // A result beyond 64 bits is a larger integer (TeSSLa's Int is unbounded), not a
    // wrapped value.
    let lines = run(spec, &[(1, "x", int(3)), (1, "y", int(63))]);
    assert_eq!(lines[0], "1: l = 27670116110564327424");
}

#[test]
fn reset_count_and_on() {
    let spec = "in x: Events[Unit]\nin y: Events[Int]\n\
        def z := resetCount(x, y)\nout z\nout on(x, y) as o\n";
    let u = Value::Unit;
    assert_eq!(
        run(
            spec,
            &[
                (1, "x", u.clone()),
                (2, "y", int(7)),
                (3, "x", u.clone()),
                (4, "x", u.clone()),
                (4, "y", int(8)),
            ]
        ),
        [
            "0: z = 0", "1: z = 1", "2: z = 0", "3: o = 7", "3: z = 1", "4: o = 8", "4: z = 1"
        ]
    );
}

#[test]
fn sets_and_maps() {
    let spec = "in x: Events[Int]\n\
        def s := Set.collect(x)\n\
        def m := Map.add(Map.empty[Int, String], 1, \"one\")\n\
        out Set.size(s) as n\nout Set.fold(s, 0, Operators.add) as total\n\
        out Map.get(m, 1) as g\n";
    assert_eq!(
        run(
            spec,
            &[(1, "x", int(5)), (2, "x", int(5)), (3, "x", int(2))]
        ),
        [
            "0: g = one",
            "0: n = 0",
            "0: total = 0",
            "1: n = 1",
            "1: total = 5",
            "2: n = 1",
            "2: total = 5",
            "3: n = 2",
            "3: total = 7"
        ]
    );
}

#[test]
fn module_members_see_each_other_and_can_be_imported() {
    let spec = "in x: Events[Int]\n\
        module Foo {\n  liftable def double(a: Int) = 2 * a\n  def bar = double(x)\n}\n\
        module Baz {\n  def k = 7\n}\nimport Baz\n\
        out Foo.bar as b\nout k\n";
    assert_eq!(run(spec, &[(1, "x", int(21))]), ["0: k = 7", "1: b = 42"]);
}

#[test]
fn time_literals_convert_to_the_base_time_as_tessla_does() {
    let spec = "out 100ms as a\nout 1min as b\n";
    let loaded = load(spec, Some("33333 µs")).unwrap();
    let mut m = Monitor::new(Arc::clone(&loaded.program));
    let mut got = Vec::new();
    m.flush(&mut |e: OutputEvent<'_>| got.push(e.value.clone()));
    got.sort_by_key(|v| v.to_string());
    assert_eq!(got, [int(1800), int(3)]);
    // Below one base time unit, or not a whole number of the base's unit: compile errors.
    assert!(load("out 1ms as a\n", Some("33333 µs")).is_err());
    assert!(load("out 100s as a\n", Some("1 min")).is_err());
}

#[test]
fn spec_errors_are_reported_not_panicked() {
    let e = load(
        "in x: Events[Int]\nout lift1(x, (a: Option[Int], b: Option[Int]) => b)\n",
        None,
    )
    .unwrap_err();
    assert!(e.contains("takes 2 arguments"), "{e}");
    let e = load("def foo := extern(\"foo\")\nout foo\n", None).unwrap_err();
    assert!(e.contains("type annotation"), "{e}");
}

#[test]
fn output_types_are_inferred_from_operators_and_declarations() {
    let spec = "in a: Events[Float]\nin b: Events[Int]\n\
        def d = a -. 1.0\ndef v = d >. 0.0 || b > 3\ndef w = if v then d else a\n\
        def n: Events[Int] = count(a)\nout d\nout v\nout w\nout n\nout b + 1 as c\n";
    let loaded = load(spec, None).unwrap();
    let types: Vec<String> = loaded
        .program
        .outputs
        .iter()
        .map(|o| format!("{} {}", o.name, o.ty))
        .collect();
    assert_eq!(types, ["d Float", "v Bool", "w Float", "n Int", "c Int"]);
}

/// One instance of the bundled robot monitors keeps only the values read across steps: far
/// fewer slots than nodes, and a few kilobytes at most (the fleet keeps 10,000 instances).
#[test]
fn robot_monitor_instance_state_is_small() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../specs/robot.tessla");
    let options = LoadOptions {
        base_time: Some("1 ns".into()),
        overrides: Vec::new(),
        time_units_need_base: false,
        ..Default::default()
    };
    let loaded = tessla_engine::load_file(&root, &options).expect("robot spec loads");
    let p = &loaded.program;
    let m = Monitor::new(p.clone());
    let bytes = m.state_bytes();
    println!(
        "robot spec: {} nodes, {} kept across steps, {} delays; state {} bytes per instance",
        p.nodes.len(),
        p.n_last_slots,
        p.delays.len(),
        bytes
    );
    assert!(p.n_last_slots < p.nodes.len());
    assert_eq!(
        bytes,
        std::mem::size_of::<Monitor>()
            + (p.inputs.len() + p.n_last_slots) * std::mem::size_of::<Option<Value>>()
            + p.delays.len() * std::mem::size_of::<Option<i64>>()
    );
    assert!(bytes < 4096, "{bytes} bytes per instance");
}

/// `--set` of an unknown name lists only the parameters (defs whose value is a literal).
#[test]
fn set_lists_only_parameters_as_known_constants() {
    let resolver = MemResolver {
        files: [(
            "spec.tessla".to_string(),
            "in x: Events[Float]\ndef delta = 0.5\ndef n = -3\ndef d = x -. delta\nout d\n"
                .to_string(),
        )]
        .into(),
    };
    let options = LoadOptions {
        base_time: None,
        overrides: vec![("nope".into(), "1".into())],
        time_units_need_base: false,
        ..Default::default()
    };
    let e = tessla_engine::load_with("spec.tessla", &resolver, &options)
        .unwrap_err()
        .render();
    assert!(e.contains("known constants: delta, n"), "{e}");
    assert!(!e.contains(", d"), "{e}");
}

/// `--set delta=-0.5` sets the Float -0.5 (in the spec language it would be `-.0.5`).
#[test]
fn set_accepts_a_negative_float() {
    let resolver = MemResolver {
        files: [(
            "spec.tessla".to_string(),
            "in x: Events[Float]\ndef delta = 0.5\nout x +. delta as y\n".to_string(),
        )]
        .into(),
    };
    let options = LoadOptions {
        base_time: None,
        overrides: vec![("delta".into(), "-0.5".into())],
        time_units_need_base: false,
        ..Default::default()
    };
    let loaded = tessla_engine::load_with("spec.tessla", &resolver, &options).unwrap();
    let mut m = Monitor::new(loaded.program.clone());
    let mut got = Vec::new();
    m.push(1, 0, Value::Float(2.0), &mut |_| {}).unwrap();
    m.flush(&mut |e: OutputEvent<'_>| got.push(e.value.clone()));
    assert_eq!(got, vec![Value::Float(1.5)]);
}

/// `Option.map` / `OptionUtils.map` and `Option.flatMap` apply a function inside an Option.
#[test]
fn option_map_and_flat_map() {
    let spec = "in x: Events[Int]\n\
        out Option.map(Some(x), (v: Int) => v * 2) as m\n\
        out OptionUtils.map(None[Int], (v: Int) => v) as n\n\
        out Option.flatMap(Some(x), (v: Int) => if v > 1 then Some(v) else None[Int]) as f\n";
    assert_eq!(
        run(spec, &[(1, "x", int(1)), (2, "x", int(5))]),
        vec![
            "0: n = None",
            "1: f = None",
            "1: m = Some(2)",
            "2: f = Some(5)",
            "2: m = Some(10)"
        ]
    );
}

/// A generic function taking a function, expanded inside a lambda, builds lambdas that capture
/// the lambda's parameters (the expansion runs in the caller's frame).
#[test]
fn lambdas_in_expanded_functions_capture_the_callers_frame() {
    let spec = "def flat[T, U](opt: Option[T], f: (T) => Option[U]): Option[U] =\n\
          if isNone(opt) then None[U] else f(getSome(opt))\n\
        def map2[T, U, V](o1: Option[T], o2: Option[U], f: (T, U) => V) =\n\
          flat(o1, (v1: T) => OptionUtils.map(o2, (v2: U) => f(v1, v2)))\n\
        in x: Events[Int]\n\
        out lift1(x, (v: Option[Int]) => map2(v, Some(1), (a: Int, b: Int) => a + b)) as a\n";
    assert_eq!(
        run(spec, &[(1, "x", int(3)), (2, "x", int(10))]),
        vec!["1: a = 4", "2: a = 11"]
    );
}
