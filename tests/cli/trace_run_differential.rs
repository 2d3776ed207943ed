//! Differential test of the two ways a spec meets its input: `trace` (TeSSLa's trace format, the
//! conformance path) and `run` (Telegraf's line protocol through the binding, the plugin's
//! path). Random specs (inputs of Int, Float and Bool bound with `@TelegrafIn`, chains of
//! lifted operators, `last`, `count`, `fold`, `merge`, `filter`, `default`, `prev`, `time`,
//! `if`; no `delay`, whose firing `run` ties to the wall clock) and random traces from a fixed
//! seed; every output event must be the same (timestamp, stream, value) on both sides.
//!
//! The traces fit both of `run`'s time models: all events of one timestamp are the fields of
//! one record, timestamps rise by more than 1 ns, the first record is at 0 (so `run`'s first
//! step, at its first record, is TeSSLa's step at 0), and `--no-passthrough`.

use crate::support::child;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::time::Duration;

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Ty {
    Int,
    Float,
    Bool,
}

impl Ty {
    fn tessla(self) -> &'static str {
        match self {
            Ty::Int => "Int",
            Ty::Float => "Float",
            Ty::Bool => "Bool",
        }
    }
}

/// A random spec: its text, its inputs (name, type) and its outputs' names.
struct Spec {
    text: String,
    inputs: Vec<(String, Ty)>,
}

fn pick<'a>(rng: &mut ChaCha8Rng, streams: &'a [(String, Ty)], ty: Ty) -> Option<&'a str> {
    let of: Vec<&str> = streams
        .iter()
        .filter(|(_, t)| *t == ty)
        .map(|(n, _)| n.as_str())
        .collect();
    (!of.is_empty()).then(|| of[rng.random_range(0..of.len())])
}

fn any<'a>(rng: &mut ChaCha8Rng, streams: &'a [(String, Ty)]) -> &'a str {
    &streams[rng.random_range(0..streams.len())].0
}

/// One derived stream over `streams`: its type and expression (`None` when the template needs
/// a type no stream has yet).
fn derived(rng: &mut ChaCha8Rng, streams: &[(String, Ty)]) -> Option<(Ty, String)> {
    let i = pick(rng, streams, Ty::Int);
    let j = pick(rng, streams, Ty::Int);
    let f = pick(rng, streams, Ty::Float);
    let g = pick(rng, streams, Ty::Float);
    let b = pick(rng, streams, Ty::Bool);
    let c = pick(rng, streams, Ty::Bool);
    let a = any(rng, streams);
    Some(match rng.random_range(0..24) {
        0 => (Ty::Int, format!("{} + {}", i?, j?)),
        1 => (Ty::Int, format!("{} - {}", i?, j?)),
        2 => (Ty::Int, format!("{} * 3", i?)),
        3 => (Ty::Int, format!("count({a})")),
        4 => (
            Ty::Int,
            format!("fold({}, 0, (s: Int, v: Int) => s + v)", i?),
        ),
        5 => (Ty::Int, format!("last({}, {a})", i?)),
        6 => (Ty::Int, format!("merge({}, {})", i?, j?)),
        7 => (Ty::Int, format!("filter({}, {})", i?, b?)),
        8 => (Ty::Int, format!("if {} then {} else {}", b?, i?, j?)),
        9 => (Ty::Int, format!("prev({})", i?)),
        10 => (Ty::Int, format!("default({}, 7)", i?)),
        11 => (Ty::Int, format!("time({a})")),
        12 => (Ty::Float, format!("{} +. {}", f?, g?)),
        13 => (Ty::Float, format!("{} *. 0.5", f?)),
        14 => (Ty::Float, format!("intToFloat({})", i?)),
        15 => (Ty::Float, format!("last({}, {a})", f?)),
        16 => (Ty::Float, format!("if {} then {} else {}", b?, f?, g?)),
        17 => (
            Ty::Float,
            format!("fold({}, 0.0, (s: Float, v: Float) => s +. v)", f?),
        ),
        18 => (Ty::Bool, format!("{} > {}", i?, j?)),
        19 => (Ty::Bool, format!("{} <. {}", f?, g?)),
        20 => (Ty::Bool, format!("{} && {}", b?, c?)),
        21 => (Ty::Bool, format!("!{}", b?)),
        22 => (Ty::Bool, format!("{} == {}", i?, j?)),
        _ => (Ty::Float, format!("merge({}, {})", f?, g?)),
    })
}

fn spec(rng: &mut ChaCha8Rng) -> Spec {
    let mut text = String::from("include \"Telegraf.tessla\"\n");
    let mut inputs = vec![("in0".to_string(), Ty::Int)];
    for k in 1..rng.random_range(1..=4) {
        let ty = [Ty::Int, Ty::Float, Ty::Bool][rng.random_range(0..3)];
        inputs.push((format!("in{k}"), ty));
    }
    for (n, t) in &inputs {
        text.push_str(&format!(
            "@TelegrafIn(\"m\", \"\", \"{n}\")\nin {n}: Events[{}]\n",
            t.tessla()
        ));
    }
    let mut streams = inputs.clone();
    let wanted = rng.random_range(2..10);
    let mut tries = 0;
    while streams.len() < inputs.len() + wanted && tries < 200 {
        tries += 1;
        if let Some((ty, expr)) = derived(rng, &streams) {
            let name = format!("d{}", streams.len());
            text.push_str(&format!("def {name}: Events[{}] = {expr}\n", ty.tessla()));
            streams.push((name, ty));
        }
    }
    // Every derived stream and one input are outputs, each its own metric.
    for (n, _) in streams.iter().skip(inputs.len()).chain(inputs.first()) {
        text.push_str(&format!("@TelegrafOut(\"{n}\")\nout {n}\n"));
    }
    Spec { text, inputs }
}

/// A random trace for `inputs`: (timestamp, events) steps, the first at 0, each with at least
/// one event; the same steps as TeSSLa's trace text and as line protocol (one record a step).
fn traces(rng: &mut ChaCha8Rng, inputs: &[(String, Ty)]) -> (String, String) {
    let (mut tessla, mut lp) = (String::new(), String::new());
    let mut ts: i64 = 0;
    for step in 0..rng.random_range(1..40) {
        if step > 0 {
            ts += rng.random_range(2..1000);
        }
        let mut fields = Vec::new();
        for (n, t) in inputs {
            if !fields.is_empty() && rng.random_bool(0.4) {
                continue;
            }
            let (value, field) = match t {
                Ty::Int => {
                    let v: i64 = rng.random_range(-5..=20);
                    (v.to_string(), format!("{v}i"))
                }
                // Quarters: exact in binary, the same number on both paths.
                Ty::Float => {
                    let v = f64::from(rng.random_range(-20..=40)) / 4.0;
                    (format!("{v:?}"), format!("{v:?}"))
                }
                Ty::Bool => {
                    let v = rng.random_bool(0.5);
                    (v.to_string(), v.to_string())
                }
            };
            tessla.push_str(&format!("{ts}: {n} = {value}\n"));
            fields.push(format!("{n}={field}"));
        }
        lp.push_str(&format!("m {} {ts}\n", fields.join(",")));
    }
    (tessla, lp)
}

/// An output value, comparable across the two formats (floats by value).
#[derive(Debug, Clone, PartialEq, PartialOrd)]
enum V {
    Int(i64),
    Float(f64),
    Bool(bool),
}

/// A value as TeSSLa prints it (`3`, `3.0`, `true`) or as a line-protocol field (`3i`, `3`).
fn value(text: &str, line_protocol: bool) -> V {
    let t = text.trim();
    let int = if line_protocol {
        t.strip_suffix('i').and_then(|i| i.parse().ok())
    } else {
        t.parse().ok()
    };
    match (t, int) {
        ("true", _) => V::Bool(true),
        ("false", _) => V::Bool(false),
        (_, Some(i)) => V::Int(i),
        _ => V::Float(t.parse().unwrap_or_else(|_| panic!("value `{t}`"))),
    }
}

type Event = (i64, String, V);

fn sorted(mut v: Vec<Event>) -> Vec<Event> {
    v.sort_by(|a, b| {
        (a.0, &a.1)
            .cmp(&(b.0, &b.1))
            .then(a.2.partial_cmp(&b.2).unwrap_or(std::cmp::Ordering::Equal))
    });
    v
}

/// `TS: name = value` lines.
fn trace_events(out: &str) -> Vec<Event> {
    sorted(
        out.lines()
            .map(|l| {
                let (ts, rest) = l.split_once(':').unwrap();
                let (name, v) = rest.split_once('=').unwrap();
                (
                    ts.parse().unwrap(),
                    name.trim().to_string(),
                    value(v, false),
                )
            })
            .collect(),
    )
}

/// `name value=V TS` lines.
fn run_events(out: &str) -> Vec<Event> {
    sorted(
        out.lines()
            .map(|l| {
                let mut parts = l.split(' ');
                let (name, field, ts) = (parts.next(), parts.next(), parts.next());
                let v = field.and_then(|f| f.strip_prefix("value=")).unwrap();
                (
                    ts.unwrap().parse().unwrap(),
                    name.unwrap().to_string(),
                    value(v, true),
                )
            })
            .collect(),
    )
}

fn same(a: &[Event], b: &[Event]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(x, y)| {
            x.0 == y.0
                && x.1 == y.1
                && match (&x.2, &y.2) {
                    (V::Float(p), V::Float(q)) => (p - q).abs() <= 1e-9 * p.abs().max(1.0),
                    (p, q) => p == q,
                }
        })
}

#[test]
fn trace_and_run_agree_on_every_output_event_of_random_specs() {
    let mut rng = ChaCha8Rng::seed_from_u64(23);
    let dir = tempfile::tempdir().unwrap();
    let deadline = Duration::from_secs(60);
    let (mut cases, mut events) = (0, 0);
    for case in 0..150 {
        let s = spec(&mut rng);
        let (tessla, lp) = traces(&mut rng, &s.inputs);
        let path = dir.path().join(format!("case{case}.tessla"));
        std::fs::write(&path, &s.text).unwrap();
        let p = path.to_str().unwrap();
        let t = child::run_bytes(&["trace", p], tessla.clone().into_bytes(), deadline);
        assert_eq!(
            t.code,
            Some(0),
            "trace, case {case}:\n{}\n{}",
            s.text,
            t.stderr
        );
        let r = child::run_bytes(
            &[
                "run",
                "--spec",
                p,
                "--no-passthrough",
                "--log-level",
                "warn",
            ],
            lp.clone().into_bytes(),
            deadline,
        );
        assert_eq!(
            r.code,
            Some(0),
            "run, case {case}:\n{}\n{}",
            s.text,
            r.stderr
        );
        let (te, re) = (trace_events(&t.stdout_text()), run_events(&r.stdout_text()));
        assert!(
            same(&te, &re),
            "case {case} differs\nspec:\n{}\ntrace input:\n{tessla}\nline protocol:\n{lp}\n\
             trace: {te:?}\nrun:   {re:?}",
            s.text
        );
        cases += 1;
        events += te.len();
    }
    // The generator must produce real work, not empty outputs.
    assert_eq!(cases, 150);
    eprintln!("{cases} random specs, {events} output events, trace and run agree");
    assert!(events > 3000, "only {events} output events");
}
