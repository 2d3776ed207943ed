//! A readable listing of a [`Program`] (`tessla-telegraf check --ir SPEC`): inputs, the
//! function table, the nodes in evaluation order with their arguments and value code, outputs,
//! and the slots kept across steps.
//!
//! Owns: [`Program::ir`] and the text form of value code ([`Render`], [`code`], [`lift_fn`]),
//! which `runtime::snapshot` also hashes (with functions named by their structural key instead
//! of their index). In code, `$i` is slot `i` of the frame (a node's argument `i`, or a
//! function's captured slots then parameters), `fK` is function `K` of the table, natives are
//! named as the builtins table names them; lazy arguments (read from earlier steps) are marked
//! `lazy`. A function value folded into a constant prints as `<function>`.

use super::code::{Callee, Code, FnId, LiftFn, Prim};
use super::{NO_SLOT, Node, NodeId, Program, SArg};
use crate::value::Value;
use std::fmt;

/// The listing of a program, see [`Program::ir`].
pub struct IrListing<'a>(&'a Program);

impl Program {
    /// A readable listing of the program (implements `Display`).
    pub fn ir(&self) -> IrListing<'_> {
        IrListing(self)
    }
}

/// How constants and function references are written.
pub struct Render<'a> {
    pub value: &'a dyn Fn(&Value) -> String,
    pub function: &'a dyn Fn(FnId) -> String,
}

/// The listing's way: values as `Debug` shows them, functions as `fK`.
fn listing_render<'a>() -> Render<'a> {
    Render {
        value: &|v| format!("{v:?}"),
        function: &|f| format!("f{f}"),
    }
}

fn args(r: &Render<'_>, args: &[Code]) -> String {
    args.iter()
        .map(|a| code(r, a))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The text of value code (deep code grows the stack on the heap, as lowering does).
pub fn code(r: &Render<'_>, c: &Code) -> String {
    stacker::maybe_grow(64 * 1024, 1024 * 1024, || code_here(r, c))
}

fn code_here(r: &Render<'_>, c: &Code) -> String {
    match c {
        Code::Const(v) => (r.value)(v),
        Code::Slot(i) => format!("${i}"),
        Code::If(parts) => {
            let [c, t, e] = &**parts;
            format!(
                "(if {} then {} else {})",
                code(r, c),
                code(r, t),
                code(r, e)
            )
        }
        Code::Logic { and, args } => {
            let [a, b] = &**args;
            let op = if *and { "&&" } else { "||" };
            format!("({} {op} {})", code(r, a), code(r, b))
        }
        Code::Closure { fun, captured: 0 } => format!("fn {}", (r.function)(*fun)),
        Code::Closure { fun, captured } => {
            format!("fn {}[$0..${}]", (r.function)(*fun), captured - 1)
        }
        Code::Apply(callee, a) => match (&**callee, &a[..]) {
            (Callee::Prim(Prim::Binary(op)), [x, y]) => {
                format!("({} {} {})", code(r, x), op.symbol(), code(r, y))
            }
            (Callee::Prim(Prim::Unary(op)), [x]) => format!("{}{}", op.symbol(), code(r, x)),
            (Callee::Prim(Prim::Tuple), _) => format!("({})", args(r, a)),
            (Callee::Prim(Prim::Record(names)), _) => {
                let fields: Vec<String> = names
                    .iter()
                    .zip(a.iter())
                    .map(|(n, x)| format!("{n} = {}", code(r, x)))
                    .collect();
                format!("{{{}}}", fields.join(", "))
            }
            (Callee::Prim(Prim::Member(name)), [x]) => format!("{}.{name}", code(r, x)),
            (Callee::Prim(Prim::Format(Some(spec))), _) => {
                format!("format({spec:?}, {})", args(r, a))
            }
            (Callee::Prim(Prim::Format(None)), _) => format!("toString({})", args(r, a)),
            (Callee::Prim(p), _) => format!("{}({})", prim_name(p), args(r, a)),
            (Callee::Native { name, .. }, _) => format!("{name}({})", args(r, a)),
            (Callee::Fn(f), _) => format!("{}({})", (r.function)(*f), args(r, a)),
            (Callee::Value, [f, rest @ ..]) => format!("{}({})", code(r, f), args(r, rest)),
            (Callee::Value, []) => "call()".into(),
        },
    }
}

fn prim_name(p: &Prim) -> &'static str {
    match p {
        Prim::Binary(_) => "binary",
        Prim::Unary(_) => "unary",
        Prim::Tuple => "tuple",
        Prim::Record(_) => "record",
        Prim::Member(_) => "member",
        Prim::Format(_) => "format",
        Prim::Concat => "concat",
        Prim::Ite => "ite",
        Prim::IsOne => "isOne",
        Prim::ResetCount => "resetCountStep",
        Prim::SetAdd => "setAdd",
        Prim::SetAddRemove => "setAddRemove",
    }
}

/// The text of a `lift` node's function.
pub fn lift_fn(r: &Render<'_>, f: &LiftFn) -> String {
    match f {
        LiftFn::Options(c) => format!("options {{ {} }}", code(r, c)),
        LiftFn::First => "first".into(),
        LiftFn::On => "on".into(),
        LiftFn::Distinct => "distinct".into(),
        LiftFn::FirstOnly => "firstOnly".into(),
        LiftFn::Edge(true) => "rising".into(),
        LiftFn::Edge(false) => "falling".into(),
        LiftFn::ResetTag => "resetTag".into(),
        LiftFn::AddRemove => "addRemove".into(),
    }
}

fn sarg(a: &SArg) -> String {
    match a {
        SArg::Stream(n) => format!("n{n}"),
        SArg::Const(v) => format!("{v:?}"),
    }
}

fn list(ns: &[NodeId]) -> String {
    ns.iter()
        .map(|n| format!("n{n}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// One node as `kind(arguments)`, its value code in braces.
fn node(p: &Program, n: &Node) -> String {
    let r = listing_render();
    match n {
        Node::Input(i) => format!(
            "input {}",
            p.inputs.get(*i).map_or("?", |x| x.name.as_str())
        ),
        Node::Nil => "nil".into(),
        Node::Const(v) => format!("const {v:?}"),
        Node::Alias(a) => format!("alias n{a}"),
        Node::Time(a) => format!("time(n{a})"),
        Node::Last { value, trigger } => format!("last(n{value} lazy, n{trigger})"),
        Node::Delay { delay, reset } => format!("delay(n{delay} lazy, n{reset})"),
        Node::Default { stream, value } => format!("default(n{stream}, {value:?})"),
        Node::DefaultFrom { stream, from } => format!("defaultFrom(n{stream}, n{from})"),
        Node::Lift { args, f } => format!("lift({}) {}", list(args), lift_fn(&r, f)),
        Node::SLift { args, f } => format!(
            "slift({}) {{ {} }}",
            args.iter().map(sarg).collect::<Vec<_>>().join(", "),
            code(&r, f)
        ),
        Node::Bin { op, a, b, .. } => format!("{op:?}({}, {})", sarg(a), sarg(b)),
        Node::Ite { cond, then, other } => {
            format!("ite({}, {}, {})", sarg(cond), sarg(then), sarg(other))
        }
        Node::Merge(args) => format!("merge({})", list(args)),
        Node::Filter { stream, cond } => format!("filter(n{stream}, n{cond})"),
        Node::Fold { stream, init, f } => {
            format!("fold(n{stream}, {init:?}) {{ {} }}", code(&r, f))
        }
        Node::Reduce { stream, f } => format!("reduce(n{stream}) {{ {} }}", code(&r, f)),
    }
}

impl fmt::Display for IrListing<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = self.0;
        for i in &p.inputs {
            writeln!(f, "in  {}: Events[{}]", i.name, i.ty)?;
        }
        if !p.functions.is_empty() {
            writeln!(f, "-- {} functions:", p.functions.len())?;
            let r = listing_render();
            for (k, fun) in p.functions.iter().enumerate() {
                let body = fun
                    .body
                    .as_ref()
                    .map_or_else(|| "<not lowered>".to_string(), |b| code(&r, b));
                writeln!(f, "f{k} {}/{} = {body}", fun.name, fun.frame)?;
            }
        }
        writeln!(
            f,
            "-- {} nodes, {} evaluated per step, in this order:",
            p.nodes.len(),
            p.order.len()
        )?;
        for &n in &p.order {
            let Some(node_) = p.nodes.get(n) else {
                continue;
            };
            let slot = match p.last_slot.get(n) {
                Some(&s) if s != NO_SLOT => format!("  [kept: slot {s}]"),
                _ => String::new(),
            };
            writeln!(f, "n{n} = {}{slot}", node(p, node_))?;
        }
        for (o, n) in p.outputs.iter().zip(&p.output_nodes) {
            writeln!(f, "out {}: Events[{}] = n{n}", o.name, o.ty)?;
        }
        Ok(())
    }
}
