//! Monitor snapshots: a monitor's state as plain serialisable data, keyed by stable stream
//! identities, and restoring it into a monitor of the same or of a changed program.
//!
//! Owns: stable node keys ([`node_keys`]) and the program fingerprint ([`fingerprint`]); the
//! serialisable value mirror ([`SValue`]); [`snapshot`] and [`restore`]. A restart restores into
//! the same program (every key matches); a spec reload restores into a new program, where the
//! streams whose key is unchanged keep their state and every other stream starts afresh
//! ([`changed_nodes`] lists those).
//!
//! A node's key is a hash of its structure, independent of node and function numbering: its
//! operator, constants and value code (the IR's text form, `crate::ir::print`, with program
//! functions named by their [`function_keys`]: a function's name, frame and body, mixed with the
//! keys of every function it reaches, so changing a called function changes its callers), its
//! owner (the name of the definition or output whose lowering made it, `Program::node_owners`,
//! so `def n = count(x)` added next to an equal `def c = count(x)` is a new stream that starts
//! afresh) and the keys of the nodes it reads. Lazy edges (`last`'s and `delay`'s first
//! argument, which may close a cycle) contribute the key computed over strict edges only. A
//! function value folded into a constant enters as `<fn>`. Hashes are FNV-1a 64 over explicit
//! little-endian bytes (stable across runs and platforms, unlike std's `RandomState`).
//!
//! Compatibility: keys are part of the saved state format. Any change to how they are computed
//! must bump the state format version (`VERSION` of the Telegraf binding's state module), so a
//! state written by an older build is refused with a warning naming both versions and its
//! instances start afresh, never restored under keys that mean something else. Version 2:
//! structural keys (value code and owners) replaced hashes of source text.
//!
//! What is not saved: function values (closures) held as stream values; such a stream starts
//! afresh after a restore ([`Snapshot::unsaved`] counts them).

use crate::ir::print::{Render, code, lift_fn};
use crate::ir::{Node, NodeId, Program, SArg};
/// The stable hashes keys are made of (defined with the IR, whose node owners use them too).
pub use crate::ir::{mix, text_hash};
use crate::runtime::exec;
use crate::runtime::monitor::{Monitor, RawState};
use crate::value::{Coll, RuntimeError, Value};
use serde::{Deserialize, Serialize};
use std::collections::{HashMap, HashSet};
use std::sync::Arc;

/// A value as plain data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum SValue {
    Unit,
    Bool(bool),
    Int(i64),
    Float(#[serde(with = "float")] f64),
    /// A list of floats only (a lidar scan): stored as bare numbers, a third of the size.
    Floats(Vec<Float>),
    Str(String),
    None,
    Some(Box<SValue>),
    /// An `Int` outside 64 bits, in decimal (added after the first format: older snapshots
    /// never hold one, so they still read).
    BigInt(String),
    List(Vec<SValue>),
    Tuple(Vec<SValue>),
    Record(Vec<(String, SValue)>),
    Set(Vec<SValue>),
    Map(Vec<(SValue, SValue)>),
    Error(SError),
    /// A set or map in Scala's hashed representation (`HashSet(...)`), elements in its order.
    HashSet(Vec<SValue>),
    HashMap(Vec<(SValue, SValue)>),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum SError {
    DivisionByZero,
    Overflow,
    GetSomeOfNone,
    IndexOutOfBounds,
    NonPositiveDelay,
    Other(String),
}

impl std::fmt::Display for SError {
    /// The message of the runtime error it stands for.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SError::DivisionByZero => RuntimeError::DivisionByZero.fmt(f),
            SError::Overflow => RuntimeError::Overflow.fmt(f),
            SError::GetSomeOfNone => RuntimeError::GetSomeOfNone.fmt(f),
            SError::IndexOutOfBounds => RuntimeError::IndexOutOfBounds.fmt(f),
            SError::NonPositiveDelay => RuntimeError::NonPositiveDelay.fmt(f),
            SError::Other(s) => f.write_str(s),
        }
    }
}

impl std::error::Error for SError {}

impl SValue {
    /// `None` for a value holding a function (not serialisable).
    pub fn from_value(v: &Value) -> Option<SValue> {
        let list = |xs: &[Value]| {
            xs.iter()
                .map(SValue::from_value)
                .collect::<Option<Vec<_>>>()
        };
        Some(match v {
            Value::Unit => SValue::Unit,
            Value::Bool(b) => SValue::Bool(*b),
            Value::Int(i) => SValue::Int(*i),
            Value::BigInt(i) => SValue::BigInt(i.to_string()),
            Value::Float(f) => SValue::Float(*f),
            Value::Str(s) => SValue::Str(s.to_string()),
            Value::None => SValue::None,
            Value::Some(x) => SValue::Some(Box::new(SValue::from_value(x)?)),
            Value::List(xs)
                if !xs.is_empty() && xs.iter().all(|x| matches!(x, Value::Float(_))) =>
            {
                SValue::Floats(
                    xs.iter()
                        .map(|x| match x {
                            Value::Float(f) => Float(*f),
                            _ => Float(f64::NAN),
                        })
                        .collect(),
                )
            }
            Value::List(xs) => SValue::List(list(xs)?),
            Value::Tuple(xs) => SValue::Tuple(list(xs)?),
            Value::Set(xs) if xs.hashed => SValue::HashSet(list(xs)?),
            Value::Set(xs) => SValue::Set(list(xs)?),
            Value::Record(fs) => SValue::Record(
                fs.iter()
                    .map(|(k, v)| Some((k.to_string(), SValue::from_value(v)?)))
                    .collect::<Option<_>>()?,
            ),
            Value::Map(kvs) => {
                let entries = kvs
                    .iter()
                    .map(|(k, v)| Some((SValue::from_value(k)?, SValue::from_value(v)?)))
                    .collect::<Option<_>>()?;
                if kvs.hashed {
                    SValue::HashMap(entries)
                } else {
                    SValue::Map(entries)
                }
            }
            Value::Closure(_) => return None,
            Value::Error(e) => SValue::Error(match e {
                RuntimeError::DivisionByZero => SError::DivisionByZero,
                RuntimeError::Overflow => SError::Overflow,
                RuntimeError::GetSomeOfNone => SError::GetSomeOfNone,
                RuntimeError::IndexOutOfBounds => SError::IndexOutOfBounds,
                RuntimeError::NonPositiveDelay => SError::NonPositiveDelay,
                RuntimeError::Other(s) => SError::Other(s.to_string()),
            }),
        })
    }

    pub fn to_value(&self) -> Value {
        let list = |xs: &[SValue]| xs.iter().map(SValue::to_value).collect::<Vec<_>>();
        match self {
            SValue::Unit => Value::Unit,
            SValue::Bool(b) => Value::Bool(*b),
            SValue::Int(i) => Value::Int(*i),
            SValue::BigInt(i) => match i.parse::<num_bigint::BigInt>() {
                Ok(b) => Value::from_big(b),
                Err(_) => Value::Error(RuntimeError::Other(
                    format!("saved state holds a malformed integer `{i}`").into(),
                )),
            },
            SValue::Float(f) => Value::Float(*f),
            SValue::Str(s) => Value::Str(Arc::from(s.as_str())),
            SValue::None => Value::None,
            SValue::Some(x) => Value::Some(Arc::new(x.to_value())),
            SValue::List(xs) => Value::List(Arc::new(list(xs))),
            SValue::Floats(xs) => {
                Value::List(Arc::new(xs.iter().map(|f| Value::Float(f.0)).collect()))
            }
            SValue::Tuple(xs) => Value::Tuple(Arc::from(list(xs))),
            SValue::Set(xs) => Value::Set(Arc::new(Coll::new(list(xs), false))),
            SValue::HashSet(xs) => Value::Set(Arc::new(Coll::new(list(xs), true))),
            SValue::Record(fs) => Value::Record(
                fs.iter()
                    .map(|(k, v)| (Arc::from(k.as_str()), v.to_value()))
                    .collect(),
            ),
            SValue::Map(kvs) | SValue::HashMap(kvs) => Value::Map(Arc::new(Coll::new(
                kvs.iter()
                    .map(|(k, v)| (k.to_value(), v.to_value()))
                    .collect(),
                matches!(self, SValue::HashMap(_)),
            ))),
            SValue::Error(e) => Value::Error(match e {
                SError::DivisionByZero => RuntimeError::DivisionByZero,
                SError::Overflow => RuntimeError::Overflow,
                SError::GetSomeOfNone => RuntimeError::GetSomeOfNone,
                SError::IndexOutOfBounds => RuntimeError::IndexOutOfBounds,
                SError::NonPositiveDelay => RuntimeError::NonPositiveDelay,
                SError::Other(s) => RuntimeError::Other(Arc::from(s.as_str())),
            }),
        }
    }
}

/// A float in a [`SValue::Floats`] list (same encoding as [`SValue::Float`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Float(#[serde(with = "float")] pub f64);

/// Floats as numbers when finite (exact with serde_json's `float_roundtrip`), else as the
/// strings `NaN`, `inf`, `-inf` (JSON has no numbers for them).
mod float {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    #[derive(Serialize, Deserialize)]
    #[serde(untagged)]
    enum Repr {
        Num(f64),
        Word(String),
    }

    pub fn serialize<S: Serializer>(f: &f64, s: S) -> Result<S::Ok, S::Error> {
        if f.is_finite() {
            s.serialize_f64(*f)
        } else if f.is_nan() {
            s.serialize_str("NaN")
        } else if *f > 0.0 {
            s.serialize_str("inf")
        } else {
            s.serialize_str("-inf")
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        match Repr::deserialize(d)? {
            Repr::Num(f) => Ok(f),
            Repr::Word(w) => match w.as_str() {
                "NaN" => Ok(f64::NAN),
                "inf" => Ok(f64::INFINITY),
                "-inf" => Ok(f64::NEG_INFINITY),
                other => Err(serde::de::Error::custom(format!(
                    "`{other}` is not a float"
                ))),
            },
        }
    }
}

/// The state of one stream node that has any.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NodeState {
    /// The node's key ([`node_keys`]).
    pub key: u64,
    /// Its latest value from earlier steps.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last: Option<SValue>,
    /// Its armed delay target (`delay` nodes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<i64>,
}

/// One monitor's state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Snapshot {
    /// Where the implicit first step is (TeSSLa time 0).
    pub t0: i64,
    /// The open step collecting inputs, if any.
    pub pending: Option<i64>,
    pub last_evaluated: Option<i64>,
    /// Events of the open step, by input name.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub inputs: Vec<(String, SValue)>,
    pub nodes: Vec<NodeState>,
    /// Streams whose value could not be saved (function values); not written.
    #[serde(skip)]
    pub unsaved: usize,
}

/// The operator and constants of a node, without node numbers.
/// A constant as it enters a node's key (`<fn>` for a closure, which has no stable text).
fn const_text(v: &Value) -> String {
    SValue::from_value(v).map_or_else(|| "<fn>".to_string(), |s| format!("{s:?}"))
}

/// `head` followed by each argument: `_` for a stream, the value for a constant.
fn with_args<'a>(mut head: String, args: impl IntoIterator<Item = &'a SArg>) -> String {
    for a in args {
        match a {
            SArg::Stream(_) => head.push_str(" _"),
            SArg::Const(v) => {
                head.push(' ');
                head.push_str(&const_text(v));
            }
        }
    }
    head
}

fn shape(program: &Program, fkeys: &[u64], node: &Node) -> String {
    let c = const_text;
    let function = |f: usize| format!("fn#{:016x}", fkeys.get(f).copied().unwrap_or(0));
    let r = Render {
        value: &const_text,
        function: &function,
    };
    match node {
        Node::Input(k) => match program.inputs.get(*k) {
            Some(i) => format!("in {}: {}", i.name, i.ty),
            None => format!("in #{k}"),
        },
        Node::Nil => "nil".into(),
        Node::Const(v) => format!("const {}", c(v)),
        Node::Alias(_) => "alias".into(),
        Node::Time(_) => "time".into(),
        Node::Last { .. } => "last".into(),
        Node::Delay { .. } => "delay".into(),
        Node::Default { value, .. } => format!("default {}", c(value)),
        Node::DefaultFrom { .. } => "defaultFrom".into(),
        Node::Lift { args, f } => format!("lift/{} {}", args.len(), lift_fn(&r, f)),
        Node::SLift { args, f } => with_args(format!("slift {{ {} }}", code(&r, f)), args),
        Node::Bin { op, a, b, .. } => with_args(format!("bin {op:?}"), [a, b]),
        Node::Ite { cond, then, other } => with_args("ite".to_string(), [cond, then, other]),
        Node::Merge(a) => format!("merge/{}", a.len()),
        Node::Filter { .. } => "filter".into(),
        Node::Fold { init, f, .. } => format!("fold {} {{ {} }}", c(init), code(&r, f)),
        Node::Reduce { f, .. } => format!("reduce {{ {} }}", code(&r, f)),
    }
}

/// The lazy dependencies of a node (may point forward).
fn lazy_deps(node: &Node) -> Vec<NodeId> {
    match node {
        Node::Last { value, .. } => vec![*value],
        Node::Delay { delay, .. } => vec![*delay],
        _ => Vec::new(),
    }
}

/// The structural key of every function of the program's table: its name, frame and body
/// (calls and closures naming functions by name), mixed with the same hashes of every function
/// it reaches (in sorted order, so numbering does not matter).
pub fn function_keys(program: &Program) -> Vec<u64> {
    let fns = &program.functions;
    let name = |f: usize| {
        fns.get(f)
            .map_or_else(|| "fn ?".to_string(), |x| format!("fn {}", x.name))
    };
    let r = Render {
        value: &const_text,
        function: &name,
    };
    let own: Vec<u64> = fns
        .iter()
        .map(|f| {
            let body = f.body.as_ref().map_or_else(String::new, |b| code(&r, b));
            text_hash(&format!("{}/{} = {body}", f.name, f.frame))
        })
        .collect();
    (0..fns.len())
        .map(|i| {
            let mut seen = HashSet::from([i]);
            let mut todo = Vec::new();
            if let Some(b) = fns.get(i).and_then(|f| f.body.as_ref()) {
                b.functions(&mut todo);
            }
            while let Some(g) = todo.pop() {
                if seen.insert(g)
                    && let Some(b) = fns.get(g).and_then(|f| f.body.as_ref())
                {
                    b.functions(&mut todo);
                }
            }
            let mut reached: Vec<u64> = seen
                .into_iter()
                .filter(|&g| g != i)
                .filter_map(|g| own.get(g).copied())
                .collect();
            reached.sort_unstable();
            reached
                .into_iter()
                .fold(own.get(i).copied().unwrap_or(0), mix)
        })
        .collect()
}

/// The stable key of every node (0 for nodes never evaluated: not in `Program::order`).
pub fn node_keys(program: &Program) -> Vec<u64> {
    let n = program.nodes.len();
    let fkeys = function_keys(program);
    let base: Vec<u64> = program
        .nodes
        .iter()
        .enumerate()
        .map(|(i, node)| {
            let owner = program.node_owners.get(i).copied().unwrap_or(0);
            mix(text_hash(&shape(program, &fkeys, node)), owner)
        })
        .collect();
    // Strict dependencies come earlier in `order`, so one pass in that order sees them done.
    let pass = |lazy_from: Option<&[u64]>| {
        let mut keys = vec![0u64; n];
        for &i in &program.order {
            let Some(node) = program.nodes.get(i) else {
                continue;
            };
            let mut k = base.get(i).copied().unwrap_or(0);
            for d in node.strict_deps() {
                k = mix(k, keys.get(d).copied().unwrap_or(0));
            }
            if let Some(shallow) = lazy_from {
                for d in lazy_deps(node) {
                    k = mix(k, shallow.get(d).copied().unwrap_or(0));
                }
            }
            if let Some(slot) = keys.get_mut(i) {
                *slot = k;
            }
        }
        keys
    };
    let shallow = pass(None);
    pass(Some(&shallow))
}

/// A hash of the whole program: its keys, inputs and outputs (names and types).
pub fn fingerprint(program: &Program) -> u64 {
    let mut h = text_hash("tessla-program");
    for k in node_keys(program) {
        h = mix(h, k);
    }
    for i in &program.inputs {
        h = mix(h, text_hash(&format!("in {}: {}", i.name, i.ty)));
    }
    for (o, n) in program.outputs.iter().zip(&program.output_nodes) {
        h = mix(h, text_hash(&format!("out {}: {} @{n}", o.name, o.ty)));
    }
    h
}

/// The nodes of `new` (evaluated ones) whose key `old` has no node with: they start afresh
/// when a monitor of `old` is restored into `new`.
pub fn changed_nodes(old: &Program, new: &Program) -> Vec<NodeId> {
    let known: HashSet<u64> = node_keys(old).into_iter().collect();
    let keys = node_keys(new);
    let mut out: Vec<NodeId> = new
        .order
        .iter()
        .copied()
        .filter(|&i| keys.get(i).is_some_and(|k| !known.contains(k)))
        .collect();
    out.sort_unstable();
    out
}

/// The state of `monitor`, keyed by node keys.
pub fn snapshot(monitor: &Monitor) -> Snapshot {
    snapshot_with_keys(monitor, &node_keys(monitor.program()))
}

/// [`snapshot`] with the program's keys computed once by the caller (many instances).
pub fn snapshot_with_keys(monitor: &Monitor, keys: &[u64]) -> Snapshot {
    let raw = monitor.raw_state();
    let program = monitor.program();
    let mut unsaved = 0;
    let inputs = raw
        .inputs
        .iter()
        .enumerate()
        .filter_map(|(k, v)| {
            let v = v.as_ref()?;
            let name = program.inputs.get(k)?.name.clone();
            match SValue::from_value(v) {
                Some(s) => Some((name, s)),
                None => {
                    unsaved += 1;
                    None
                }
            }
        })
        .collect();
    let mut seen = HashSet::new();
    let mut nodes = Vec::new();
    for (i, &key) in keys.iter().enumerate() {
        let last = raw.last.get(i).and_then(Option::as_ref);
        let target = raw.targets.get(i).copied().flatten();
        if (last.is_none() && target.is_none()) || !seen.insert(key) {
            continue;
        }
        let last = match last.map(SValue::from_value) {
            Some(None) => {
                unsaved += 1;
                continue;
            }
            Some(Some(s)) => Some(s),
            None => None,
        };
        nodes.push(NodeState { key, last, target });
    }
    Snapshot {
        t0: raw.t0,
        pending: raw.pending,
        last_evaluated: raw.last_evaluated,
        inputs,
        nodes,
        unsaved,
    }
}

/// A monitor of `program` continuing from `snap`. Nodes whose key `snap` lacks start afresh:
/// after the first step, a constant, a `default` or a `fold` holds its initial value (as if
/// its only event were the one at TeSSLa time 0), every other stream has no value yet.
pub fn restore(program: Arc<exec::Program>, snap: &Snapshot) -> Monitor {
    let keys = node_keys(&program);
    restore_with_keys(program, snap, &keys)
}

/// [`restore`] with the program's keys computed once by the caller (many instances).
pub fn restore_with_keys(program: Arc<exec::Program>, snap: &Snapshot, keys: &[u64]) -> Monitor {
    let by_key: HashMap<u64, &NodeState> = snap.nodes.iter().map(|s| (s.key, s)).collect();
    let started = snap.last_evaluated.is_some();
    let n = program.nodes.len();
    let mut last = vec![None; n];
    let mut targets = vec![None; n];
    for (i, key) in keys.iter().enumerate().take(n) {
        match by_key.get(key) {
            Some(s) => {
                last[i] = s.last.as_ref().map(SValue::to_value);
                targets[i] = s.target;
            }
            None if started => {
                last[i] = match program.nodes.get(i) {
                    Some(Node::Const(v)) => Some(v.clone()),
                    Some(Node::Default { value, .. }) => Some(value.clone()),
                    Some(Node::Fold { init, .. }) => Some(init.clone()),
                    _ => None,
                };
            }
            None => {}
        }
    }
    let mut inputs = vec![None; program.inputs.len()];
    for (name, v) in &snap.inputs {
        if let Some(k) = program.input_index(name)
            && let Some(slot) = inputs.get_mut(k)
        {
            *slot = Some(v.to_value());
        }
    }
    let pending = if snap.pending.is_some() && inputs.iter().any(Option::is_some) {
        snap.pending
    } else {
        // An open step without inputs would be an empty step: leave it closed.
        None
    };
    Monitor::from_raw_state(
        program,
        RawState {
            t0: snap.t0,
            pending,
            last_evaluated: snap.last_evaluated,
            inputs,
            last,
            targets,
        },
    )
}
