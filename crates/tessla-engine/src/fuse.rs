//! Fusion of signal-lift chains: `slift(f, slift(g, a, b), c)` becomes one node
//! `slift(a, b, c)` whose function computes `f(g(a, b), c)`.
//!
//! Owns: the rewrite and the fused closures. It is exact for signal lifts of pure functions:
//! the inner lift has an event exactly when one of its streams has one and all have a value, and
//! its value is always `g` of the latest values, so the fused node fires at the same steps with
//! the same values. It saves the evaluator one node (store, clone, dispatch) per operator, which
//! dominates the cost of arithmetic specs. Trees are bounded (operators and streams), so a value
//! used many times is recomputed only within that bound.

use crate::ir::{Func, NodeId, SArg};
use crate::value::{RuntimeError, Value};
use std::sync::Arc;

/// Most operators in a fused tree (each is one function call per event).
pub const MAX_CALLS: usize = 16;
/// Most distinct streams a fused node may read.
pub const MAX_STREAMS: usize = 8;

/// An argument of a function in a fused tree.
pub enum Operand {
    /// The value of the fused node's stream argument at this index.
    Arg(usize),
    Const(Value),
    /// A function applied to operands.
    Call(Func, Vec<Operand>),
}

impl Operand {
    fn eval(&self, flat: &[Value]) -> Value {
        match self {
            Operand::Arg(i) => flat
                .get(*i)
                .cloned()
                .unwrap_or_else(|| Value::Error(RuntimeError::Other("fused argument".into()))),
            Operand::Const(v) => v.clone(),
            Operand::Call(f, ops) => call(f, ops, flat),
        }
    }
}

/// `f` applied to operands; the arguments live on the stack for up to 3 operands.
fn call(f: &Func, ops: &[Operand], flat: &[Value]) -> Value {
    match ops {
        [a] => f(&[a.eval(flat)]),
        [a, b] => f(&[a.eval(flat), b.eval(flat)]),
        [a, b, c] => f(&[a.eval(flat), b.eval(flat), c.eval(flat)]),
        _ => f(&ops.iter().map(|o| o.eval(flat)).collect::<Vec<_>>()),
    }
}

/// A signal lift that may inline its argument lifts.
pub struct Inner<'a> {
    pub args: &'a [SArg],
    pub f: &'a Func,
    /// Function calls in `f` (1 unless `f` is itself fused).
    pub calls: usize,
}

/// Try to fuse `slift(args, f)`, where `inner(n)` describes stream `n` if it is a signal lift.
/// Returns the fused node's stream arguments, function and call count, or `None` when nothing
/// can be inlined within the bounds.
pub fn fuse<'a>(
    args: &[SArg],
    f: &Func,
    inner: impl Fn(NodeId) -> Option<Inner<'a>>,
) -> Option<(Vec<SArg>, Func, usize)> {
    let mut flat: Vec<NodeId> = Vec::new();
    let slot = |n: NodeId, flat: &mut Vec<NodeId>| match flat.iter().position(|m| *m == n) {
        Some(i) => i,
        None => {
            flat.push(n);
            flat.len() - 1
        }
    };
    let mut ops = Vec::with_capacity(args.len());
    let mut calls = 1;
    let mut fused_any = false;
    for a in args {
        match a {
            SArg::Const(v) => ops.push(Operand::Const(v.clone())),
            SArg::Stream(n) => match inner(*n) {
                Some(i) if calls + i.calls <= MAX_CALLS => {
                    let inner_ops = i
                        .args
                        .iter()
                        .map(|ia| match ia {
                            SArg::Const(v) => Operand::Const(v.clone()),
                            SArg::Stream(m) => Operand::Arg(slot(*m, &mut flat)),
                        })
                        .collect();
                    ops.push(Operand::Call(i.f.clone(), inner_ops));
                    calls += i.calls;
                    fused_any = true;
                }
                _ => ops.push(Operand::Arg(slot(*n, &mut flat))),
            },
        }
    }
    if !fused_any || flat.len() > MAX_STREAMS {
        return None;
    }
    let f = f.clone();
    let fused: Func = Arc::new(move |vals: &[Value]| call(&f, &ops, vals));
    Some((flat.into_iter().map(SArg::Stream).collect(), fused, calls))
}
