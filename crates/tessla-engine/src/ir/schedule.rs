//! Scheduling a lowered program, an IR-to-IR pass: the order nodes are evaluated in within a
//! step, and which nodes' values must be kept across steps.
//!
//! Owns: [`order`] (strict dependencies first; only what an output reads; a cycle not through
//! a lazy argument is an error, [`Cycle`], which the lowering reports as a diagnostic) and
//! [`last_slots`] (the slots a monitor instance keeps).

use crate::ir::{NO_SLOT, Node, NodeId, SArg, stream_args};

/// A cycle of strict dependencies (no `last`/`delay` in between): its nodes, in order.
#[derive(Debug)]
pub struct Cycle(pub Vec<NodeId>);

impl std::fmt::Display for Cycle {
    /// The message of the lowering's diagnostic for it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("a stream depends on itself without `last` or `delay` in between")
    }
}

impl std::error::Error for Cycle {}

/// Evaluation order: strict dependencies first; a cycle not through `last`/`delay` is an error.
pub fn order(nodes: &[Node], roots: &[NodeId]) -> Result<Vec<NodeId>, Cycle> {
    let n = nodes.len();
    let mut state = vec![0u8; n];
    let mut order = Vec::with_capacity(n);
    // Only nodes an output reads (directly, or lazily through `last`/`delay`) are evaluated;
    // others (leftovers of macro expansion) are left out.
    let mut reachable = vec![false; n];
    let mut todo: Vec<NodeId> = roots.iter().copied().filter(|r| *r < n).collect();
    while let Some(x) = todo.pop() {
        if std::mem::replace(&mut reachable[x], true) {
            continue;
        }
        todo.extend(nodes[x].all_deps().into_iter().filter(|d| *d < n));
    }
    for start in 0..n {
        if state[start] != 0 || !reachable[start] {
            continue;
        }
        let mut stack: Vec<(NodeId, usize)> = vec![(start, 0)];
        state[start] = 1;
        while let Some(&mut (node, ref mut idx)) = stack.last_mut() {
            let deps = nodes[node].strict_deps();
            if let Some(&d) = deps.get(*idx) {
                *idx += 1;
                match state.get(d) {
                    Some(0) => {
                        state[d] = 1;
                        stack.push((d, 0));
                    }
                    Some(1) => {
                        let from = stack.iter().position(|(x, _)| *x == d).unwrap_or(0);
                        return Err(Cycle(stack[from..].iter().map(|(x, _)| *x).collect()));
                    }
                    _ => {}
                }
            } else {
                state[node] = 2;
                order.push(node);
                stack.pop();
            }
        }
    }
    Ok(order)
}

/// Mark the stream arguments of a signal lift when there are at least two.
fn mark_all(mark: &mut impl FnMut(NodeId), args: &[&SArg]) {
    let streams = stream_args(args);
    if streams.len() >= 2 {
        for n in streams {
            mark(n);
        }
    }
}

/// Which nodes' latest values must persist between steps: the lazy argument of `last`, the
/// arguments of signal lifts (they use the latest value of silent arguments), the condition of
/// `filter`, both arguments of `defaultFrom`, and `fold`/`reduce` accumulators. Returns the slot
/// of each node (or [`NO_SLOT`]) and the number of slots; a monitor instance stores only these.
pub fn last_slots(nodes: &[Node], order: &[NodeId]) -> (Vec<u32>, usize) {
    let mut need = vec![false; nodes.len()];
    let mut mark = |n: NodeId| {
        if let Some(x) = need.get_mut(n) {
            *x = true;
        }
    };
    for &i in order {
        match nodes.get(i) {
            Some(Node::Last { value, .. }) => mark(*value),
            Some(Node::DefaultFrom { stream, from }) => {
                mark(*stream);
                mark(*from);
            }
            // A lift reads the latest value of a silent argument only when it has two or more
            // stream arguments: with one, it fires only with that argument's event.
            Some(Node::SLift { args, .. }) => {
                let streams: Vec<&SArg> = args.iter().collect();
                mark_all(&mut mark, &streams);
            }
            Some(Node::Filter { cond, .. }) => mark(*cond),
            Some(Node::Bin { a, b, .. }) => mark_all(&mut mark, &[a, b]),
            Some(Node::Ite { cond, then, other }) => mark_all(&mut mark, &[cond, then, other]),
            Some(Node::Fold { .. } | Node::Reduce { .. }) => mark(i),
            _ => {}
        }
    }
    let mut next = 0u32;
    let slots = need
        .iter()
        .map(|&n| {
            if n {
                next += 1;
                next - 1
            } else {
                NO_SLOT
            }
        })
        .collect();
    (slots, next as usize)
}
