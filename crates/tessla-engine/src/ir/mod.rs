//! The flat core IR: stream nodes in dependency order with typed value slots.
//!
//! Owns: [`Program`] (what the front end produces; the runtime runs it with its code compiled),
//! the metadata the bindings read ([`InputInfo`], [`OutputInfo`], [`Annotation`]) and value
//! [`Type`]s; its own operators (`op`: [`BinOp`], [`UnaryOp`], which the lowering maps the
//! syntax's onto); which operators have a fast-path node ([`scalar_op`]); the stable hashes node
//! identities are made of ([`text_hash`], [`mix`], and [`owner_key`], the owner the lowering
//! records per node); its listing (`print`, `tessla-telegraf check --ir`). The value code inside
//! nodes and the function table are data too (`code`); `runtime::exec` compiles them into
//! closures when the first monitor of a program is created. Two passes over the IR that the
//! lowering runs: constant folding of closed code (`fold`) and scheduling, the evaluation order
//! and the values kept across steps (`schedule`).

use crate::value::Value;
use std::hash::Hasher;

pub mod code;
pub mod fold;
pub mod op;
pub(crate) mod print;
pub mod schedule;
pub use code::{Callee, Code, FnId, Function, LiftFn, Prim};
pub use op::{BinOp, UnaryOp};

/// A value type, as reported by `check` and used by bindings to convert inputs.
#[derive(Debug, Clone, PartialEq)]
pub enum Type {
    Unit,
    Bool,
    Int,
    Float,
    String,
    Option(Box<Type>),
    List(Box<Type>),
    Tuple(Vec<Type>),
    Record(Vec<(String, Type)>),
    Events(Box<Type>),
    /// Not known: a type the IR cannot name (`Set`, `Map`, functions) or one the checker left
    /// open.
    Unknown,
}

impl std::fmt::Display for Type {
    /// TeSSLa's notation: `Float`, `Option[Int]`, `List[Float]`, `(Int, Bool)`, `{a: Int}`;
    /// a type that is not known prints as `?`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Type::Unit => f.write_str("Unit"),
            Type::Bool => f.write_str("Bool"),
            Type::Int => f.write_str("Int"),
            Type::Float => f.write_str("Float"),
            Type::String => f.write_str("String"),
            Type::Option(t) => write!(f, "Option[{t}]"),
            Type::List(t) => write!(f, "List[{t}]"),
            Type::Events(t) => write!(f, "Events[{t}]"),
            Type::Tuple(ts) => {
                let parts: Vec<String> = ts.iter().map(ToString::to_string).collect();
                write!(f, "({})", parts.join(", "))
            }
            Type::Record(fs) => {
                let parts: Vec<String> = fs.iter().map(|(n, t)| format!("{n}: {t}")).collect();
                write!(f, "{{{}}}", parts.join(", "))
            }
            Type::Unknown => f.write_str("?"),
        }
    }
}

impl Type {
    /// No part of the type is [`Type::Unknown`].
    pub fn is_known(&self) -> bool {
        match self {
            Type::Unknown => false,
            Type::Option(t) | Type::List(t) | Type::Events(t) => t.is_known(),
            Type::Tuple(ts) => ts.iter().all(Type::is_known),
            Type::Record(fs) => fs.iter().all(|(_, t)| t.is_known()),
            _ => true,
        }
    }
}

/// An annotation on an input or output (`@TelegrafIn("m", "", "f")`), with its arguments named by
/// the annotation declaration's parameters, in declaration order.
#[derive(Debug, Clone, PartialEq)]
pub struct Annotation {
    pub name: String,
    pub args: Vec<(String, Value)>,
}

#[derive(Debug, Clone)]
pub struct InputInfo {
    pub name: String,
    /// The element type (`Float` for `Events[Float]`).
    pub ty: Type,
    pub annotations: Vec<Annotation>,
}

#[derive(Debug, Clone)]
pub struct OutputInfo {
    pub name: String,
    /// The element type.
    pub ty: Type,
    pub annotations: Vec<Annotation>,
    /// `@raw out`: print the value only.
    pub raw: bool,
}

/// Index of a stream node in [`Program::nodes`].
pub type NodeId = usize;

/// An argument of a signal lift: a stream, or a constant (always defined, never an event).
#[derive(Clone, Debug)]
pub enum SArg {
    Stream(NodeId),
    Const(Value),
}

/// Operators with an inline fast path in the evaluator (see [`Node::Bin`]); their semantics are
/// in [`crate::runtime::ops`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScalarOp {
    FAdd,
    FSub,
    FMul,
    FDiv,
    FLt,
    FGt,
    FLe,
    FGe,
    IAdd,
    ISub,
    ILt,
    IGt,
    ILe,
    IGe,
    And,
    Or,
}

/// The operators with an inline scalar fast path, and the operator each one stands for (which
/// operator the lowering may build a [`Node::Bin`] for). Inline: the evaluator asks it
/// for every operator it applies (`runtime::exec::binary`).
#[inline]
pub fn scalar_op(op: BinOp) -> Option<ScalarOp> {
    Some(match op {
        BinOp::FAdd => ScalarOp::FAdd,
        BinOp::FSub => ScalarOp::FSub,
        BinOp::FMul => ScalarOp::FMul,
        BinOp::FDiv => ScalarOp::FDiv,
        BinOp::FLt => ScalarOp::FLt,
        BinOp::FGt => ScalarOp::FGt,
        BinOp::FLe => ScalarOp::FLe,
        BinOp::FGe => ScalarOp::FGe,
        BinOp::Add => ScalarOp::IAdd,
        BinOp::Sub => ScalarOp::ISub,
        BinOp::Lt => ScalarOp::ILt,
        BinOp::Gt => ScalarOp::IGt,
        BinOp::Le => ScalarOp::ILe,
        BinOp::Ge => ScalarOp::IGe,
        BinOp::And => ScalarOp::And,
        BinOp::Or => ScalarOp::Or,
        _ => return None,
    })
}

/// A scalar operand or result of a [`ScalarOp`], copied out of a [`Value`] so the evaluator
/// can compute in registers and write the result straight into its slot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scalar {
    F(f64),
    I(i64),
    B(bool),
}

impl Scalar {
    #[inline]
    pub fn of(v: &Value) -> Option<Scalar> {
        match v {
            Value::Float(x) => Some(Scalar::F(*x)),
            Value::Int(x) => Some(Scalar::I(*x)),
            Value::Bool(x) => Some(Scalar::B(*x)),
            _ => None,
        }
    }

    #[inline]
    pub fn value(self) -> Value {
        match self {
            Scalar::F(x) => Value::Float(x),
            Scalar::I(x) => Value::Int(x),
            Scalar::B(x) => Value::Bool(x),
        }
    }
}

/// One stream node. Edges marked lazy may point forward (recursion); all others point to
/// nodes evaluated earlier in [`Program::order`].
#[derive(Clone)]
pub enum Node {
    Input(usize),
    Nil,
    /// One event at the first step (t = 0).
    Const(Value),
    /// The same events as another node (a reference made before that node existed).
    Alias(NodeId),
    Time(NodeId),
    /// `last(value, trigger)`; `value` is lazy.
    Last {
        value: NodeId,
        trigger: NodeId,
    },
    /// `delay(delay, reset)`; `delay` is lazy.
    Delay {
        delay: NodeId,
        reset: NodeId,
    },
    Default {
        stream: NodeId,
        value: Value,
    },
    DefaultFrom {
        stream: NodeId,
        from: NodeId,
    },
    /// Fires when an argument has an event; `f` sees which have one.
    Lift {
        args: Vec<NodeId>,
        f: LiftFn,
    },
    /// Signal lift: fires when an argument stream has an event and all have had one; `f` is
    /// code over the arguments' values (slot `i` = argument `i`).
    SLift {
        args: Vec<SArg>,
        f: Code,
    },
    /// A signal lift of a scalar operator, run inline on `Float`/`Int`/`Bool` operands; other
    /// operands (errors, strings) go through the general semantics of `bop`, the operator in
    /// the spec.
    Bin {
        op: ScalarOp,
        a: SArg,
        b: SArg,
        bop: BinOp,
    },
    /// A signal lift of `if cond then then else other`.
    Ite {
        cond: SArg,
        then: SArg,
        other: SArg,
    },
    /// Leftmost event wins.
    Merge(Vec<NodeId>),
    Filter {
        stream: NodeId,
        cond: NodeId,
    },
    /// `init` at t = 0, then `f(acc, x)` at each event of `stream` (`f` over slots 0, 1).
    Fold {
        stream: NodeId,
        init: Value,
        f: Code,
    },
    /// The first event, then `f(acc, x)`.
    Reduce {
        stream: NodeId,
        f: Code,
    },
}

impl std::fmt::Debug for Node {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Node::Input(i) => write!(f, "Input({i})"),
            Node::Nil => write!(f, "Nil"),
            Node::Const(v) => write!(f, "Const({v:?})"),
            Node::Alias(n) => write!(f, "Alias({n})"),
            Node::Time(n) => write!(f, "Time({n})"),
            Node::Last { value, trigger } => write!(f, "Last({value}, {trigger})"),
            Node::Delay { delay, reset } => write!(f, "Delay({delay}, {reset})"),
            Node::Default { stream, value } => write!(f, "Default({stream}, {value:?})"),
            Node::DefaultFrom { stream, from } => write!(f, "DefaultFrom({stream}, {from})"),
            Node::Lift { args, .. } => write!(f, "Lift({args:?})"),
            Node::SLift { args, .. } => write!(f, "SLift({args:?})"),
            Node::Bin { op, a, b, .. } => write!(f, "Bin({op:?}, {a:?}, {b:?})"),
            Node::Ite { cond, then, other } => write!(f, "Ite({cond:?}, {then:?}, {other:?})"),
            Node::Merge(a) => write!(f, "Merge({a:?})"),
            Node::Filter { stream, cond } => write!(f, "Filter({stream}, {cond})"),
            Node::Fold { stream, init, .. } => write!(f, "Fold({stream}, {init:?})"),
            Node::Reduce { stream, .. } => write!(f, "Reduce({stream})"),
        }
    }
}

impl Node {
    /// Every node this one reads: the strict dependencies and the lazy ones (`last`'s and
    /// `delay`'s first argument, read from earlier steps).
    pub fn all_deps(&self) -> Vec<NodeId> {
        let mut d = self.strict_deps();
        match self {
            Node::Last { value, .. } => d.push(*value),
            Node::Delay { delay, .. } => d.push(*delay),
            _ => {}
        }
        d
    }

    /// Dependencies that must be evaluated before this node in the same step.
    pub fn strict_deps(&self) -> Vec<NodeId> {
        match self {
            Node::Input(_) | Node::Nil | Node::Const(_) => vec![],
            Node::Alias(n) | Node::Time(n) => vec![*n],
            Node::Last { trigger, .. } => vec![*trigger],
            Node::Delay { reset, .. } => vec![*reset],
            Node::Default { stream, .. } => vec![*stream],
            Node::DefaultFrom { stream, from } => vec![*stream, *from],
            Node::Lift { args, .. } | Node::Merge(args) => args.clone(),
            Node::SLift { args, .. } => args
                .iter()
                .filter_map(|a| match a {
                    SArg::Stream(n) => Some(*n),
                    SArg::Const(_) => None,
                })
                .collect(),
            Node::Filter { stream, cond } => vec![*stream, *cond],
            Node::Bin { a, b, .. } => stream_args(&[a, b]),
            Node::Ite { cond, then, other } => stream_args(&[cond, then, other]),
            Node::Fold { stream, .. } | Node::Reduce { stream, .. } => vec![*stream],
        }
    }
}

pub(crate) fn stream_args(args: &[&SArg]) -> Vec<NodeId> {
    args.iter()
        .filter_map(|a| match a {
            SArg::Stream(n) => Some(*n),
            SArg::Const(_) => None,
        })
        .collect()
}

/// A specification lowered to the IR: all data, as the lowering made it. The runtime wraps it
/// with its compiled code (`crate::runtime::exec::Program`, what monitors run).
#[derive(Debug)]
pub struct Program {
    pub inputs: Vec<InputInfo>,
    pub outputs: Vec<OutputInfo>,
    pub nodes: Vec<Node>,
    /// Per node: its owner, a hash of the name of the definition or output whose lowering made
    /// it ([`owner_key`]; part of a node's identity in `runtime::snapshot`).
    pub node_owners: Vec<u64>,
    /// Evaluation order of the nodes within a step (strict dependencies first).
    pub order: Vec<NodeId>,
    /// The node of each output.
    pub output_nodes: Vec<NodeId>,
    /// The `Delay` nodes (the monitor arms and fires only these).
    pub delays: Vec<NodeId>,
    /// Per node: its slot among the values a monitor keeps from earlier steps, or [`NO_SLOT`]
    /// when no node reads it across steps (see [`schedule::last_slots`]).
    pub last_slot: Vec<u32>,
    /// Number of slots in use in `last_slot`.
    pub n_last_slots: usize,
    /// The function table: named functions and lambdas that value code calls by index
    /// ([`Callee::Fn`], [`Code::Closure`]).
    pub functions: Vec<Function>,
}

/// `last_slot` of a node whose earlier values nobody reads.
pub const NO_SLOT: u32 = u32::MAX;

impl Program {
    pub fn input_index(&self, name: &str) -> Option<usize> {
        self.inputs.iter().position(|i| i.name == name)
    }
}

/// FNV-1a 64 of `s` (stable across runs and platforms, unlike std's `RandomState`).
pub fn text_hash(s: &str) -> u64 {
    let mut h = fnv::FnvHasher::default();
    h.write(s.as_bytes());
    h.finish()
}

/// Combine two hashes (order matters).
pub fn mix(a: u64, b: u64) -> u64 {
    let mut h = fnv::FnvHasher::default();
    h.write(&a.to_le_bytes());
    h.write(&b.to_le_bytes());
    h.finish()
}

/// The owner key of the nodes made while lowering the definition or output `name`
/// ([`Program::node_owners`]).
pub fn owner_key(name: &str) -> u64 {
    mix(text_hash("owner"), text_hash(name))
}
