//! Element types of stream nodes as far as lowering knows them (declarations, literals,
//! operators): what remains of type guessing in lowering, and why it remains.
//!
//! The type checker's table ([`crate::typeck::Types`]) holds one type per output expression and
//! per top-level parameterless definition (for `out *`); outputs and `out *` take the table's
//! type first (`known_or` in `lower/mod.rs`). Lowering still needs a type per *node* in two
//! places the table cannot answer: the table is keyed by source span, and one span lowers to
//! many nodes of different types (a function body is expanded once per call, at each call's
//! types), and it is [`Type::Unknown`] wherever the checker leaves a type open (open variables
//! of the builtins it does not check — `sum`, `maximum`, `minimum`, `average`, `runtime`,
//! `Operators.*` — extern types, and `Set`, `Map` and function types, which the IR cannot
//! name). The two uses:
//! - the Int-operator-on-Float error (`lower/expr.rs`) for operands whose type only the lowered
//!   node shows (the checker's rule covers the rest, and runs first);
//! - an output's element type when the table's is open (`check`'s listing and the bindings'
//!   conversions read it; `Events[?]` when neither knows).
//!
//! Making these go needs a per-node type from the checker (types of expressions per
//! instantiation), which the table does not carry.
//!
//! Owns: `Compiler::typed`, `stream_type`, [`ir_type`] (a syntax type as an IR type),
//! `value_type`, `const_type_of`.

use super::*;

impl Compiler<'_> {
    /// Record the element type of a stream term (when known and not recorded yet).
    pub(super) fn typed(&mut self, t: Term, ty: Type) -> Term {
        if let Term::Stream(n) = t
            && ty != Type::Unknown
        {
            self.node_types.entry(n).or_insert(ty);
        }
        t
    }

    pub(super) fn stream_type(&self, n: NodeId) -> Type {
        self.stream_type_within(n, &mut 64)
    }

    /// The element type of a node, visiting at most `budget` nodes (streams may be recursive
    /// through `last`, and merges branch).
    pub(super) fn stream_type_within(&self, n: NodeId, budget: &mut u32) -> Type {
        if *budget == 0 {
            return Type::Unknown;
        }
        *budget -= 1;
        if let Some(t) = self.node_types.get(&n) {
            return t.clone();
        }
        match self.nodes.get(n) {
            Some(Node::Input(i)) => self.inputs.get(*i).map_or(Type::Unknown, |i| i.ty.clone()),
            Some(Node::Const(v)) => value_type(v),
            Some(Node::Alias(m)) => self.stream_type_within(*m, budget),
            Some(Node::Time(_)) => Type::Int,
            Some(
                Node::Default { stream, .. }
                | Node::DefaultFrom { stream, .. }
                | Node::Filter { stream, .. },
            ) => self.stream_type_within(*stream, budget),
            Some(Node::Last { value, .. }) => self.stream_type_within(*value, budget),
            Some(Node::Delay { .. }) => Type::Unit,
            Some(Node::Fold { init, .. }) => value_type(init),
            Some(Node::Reduce { stream, .. }) => self.stream_type_within(*stream, budget),
            Some(Node::Merge(args)) => args
                .iter()
                .map(|a| self.stream_type_within(*a, budget))
                .find(|t| *t != Type::Unknown)
                .unwrap_or(Type::Unknown),
            _ => Type::Unknown,
        }
    }
}

/// The type of a parameterless def's constant value, if it is a literal constant.
pub(super) fn const_type_of(d: &Def) -> Option<Type> {
    match &d.body {
        Body::Expr { expr, .. } => match &expr.kind {
            ExprKind::Int { .. } => Some(Type::Int),
            ExprKind::Float(_) => Some(Type::Float),
            ExprKind::Str { .. } => Some(Type::String),
            ExprKind::Var(v) if v.name == "true" || v.name == "false" => Some(Type::Bool),
            ExprKind::Unary { operand, .. } => match &operand.kind {
                ExprKind::Int { .. } => Some(Type::Int),
                ExprKind::Float(_) => Some(Type::Float),
                _ => None,
            },
            _ => None,
        },
        Body::Extern { .. } => None,
    }
}

pub(super) fn value_type(v: &Value) -> Type {
    match v {
        Value::Unit => Type::Unit,
        Value::Bool(_) => Type::Bool,
        Value::Int(_) => Type::Int,
        Value::Float(_) => Type::Float,
        Value::Str(_) => Type::String,
        _ => Type::Unknown,
    }
}

/// The IR type of a declared AST type (`Events[T]` -> `T` for inputs).
pub fn ir_type(t: &ast::Type) -> Type {
    match t {
        ast::Type::Name(n) => match n.name.as_str() {
            "Int" => Type::Int,
            "Float" => Type::Float,
            "Bool" => Type::Bool,
            "String" => Type::String,
            "Unit" => Type::Unit,
            _ => Type::Unknown,
        },
        ast::Type::App { name, args, .. } => {
            let a = args.first().map(ir_type).unwrap_or(Type::Unknown);
            match name.name.as_str() {
                "Events" => Type::Events(Box::new(a)),
                "Option" => Type::Option(Box::new(a)),
                "List" => Type::List(Box::new(a)),
                _ => Type::Unknown,
            }
        }
        ast::Type::Tuple { elems, .. } if elems.is_empty() => Type::Unit,
        ast::Type::Tuple { elems, .. } => Type::Tuple(elems.iter().map(ir_type).collect()),
        ast::Type::Record { fields, .. } => Type::Record(
            fields
                .iter()
                .map(|(n, t)| (n.name.clone(), ir_type(t)))
                .collect(),
        ),
        ast::Type::Function { .. } => Type::Unknown,
    }
}
