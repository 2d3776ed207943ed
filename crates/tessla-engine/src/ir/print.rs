//! A readable listing of a [`Program`] (`tessla-telegraf check --ir SPEC`): inputs, the nodes
//! in evaluation order with their arguments, outputs, and the slots kept across steps.
//!
//! Owns: [`Program::ir`]. Functions inside nodes are closures and print as `<fn>`; lazy
//! arguments (read from earlier steps) are marked `lazy`.

use super::{NO_SLOT, Node, NodeId, Program, SArg};
use std::fmt;

/// The listing of a program, see [`Program::ir`].
pub struct IrListing<'a>(&'a Program);

impl Program {
    /// A readable listing of the program (implements `Display`).
    pub fn ir(&self) -> IrListing<'_> {
        IrListing(self)
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

/// One node as `kind(arguments)`.
fn node(p: &Program, n: &Node) -> String {
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
        Node::Lift { args, .. } => format!("lift({}, <fn>)", list(args)),
        Node::SLift { args, .. } => format!(
            "slift({}, <fn>)",
            args.iter().map(sarg).collect::<Vec<_>>().join(", ")
        ),
        Node::Bin { op, a, b, .. } => format!("{op:?}({}, {})", sarg(a), sarg(b)),
        Node::Ite { cond, then, other } => {
            format!("ite({}, {}, {})", sarg(cond), sarg(then), sarg(other))
        }
        Node::Merge(args) => format!("merge({})", list(args)),
        Node::Filter { stream, cond } => format!("filter(n{stream}, n{cond})"),
        Node::Fold { stream, init, .. } => format!("fold(n{stream}, {init:?}, <fn>)"),
        Node::Reduce { stream, .. } => format!("reduce(n{stream}, <fn>)"),
    }
}

impl fmt::Display for IrListing<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = self.0;
        for i in &p.inputs {
            writeln!(f, "in  {}: Events[{}]", i.name, i.ty)?;
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

#[cfg(test)]
mod tests {
    #[test]
    fn a_program_lists_its_nodes_in_order() {
        let spec = "in x: Events[Int]\ndef c = x + 1\ndef l = last(c, x)\nout c\nout l";
        let loaded = crate::load_with(
            "spec.tessla",
            &tessla_syntax::include::MemResolver {
                files: [("spec.tessla".to_string(), spec.to_string())].into(),
            },
            &crate::LoadOptions::default(),
        );
        let Ok(loaded) = loaded else {
            panic!("spec does not load");
        };
        let text = loaded.program.ir().to_string();
        assert!(text.starts_with("in  x: Events[Int]\n"), "{text}");
        assert!(text.contains("= input x"), "{text}");
        assert!(text.contains("last(n"), "{text}");
        assert!(text.contains("out c: Events[Int] = n"), "{text}");
    }
}
