//! Lowering: from the checked syntax of a spec to a [`Program`] (the IR the monitor runs).
//!
//! Every expression becomes a [`Term`]: a constant, a stream node, value code over a frame of
//! variables ([`Code`], data: used inside function bodies and lambdas), or a function. Functions
//! applied to stream arguments are expanded in place (TeSSLa's macros); operators and liftable
//! functions on streams become signal lifts; value-level functions are lowered once into the
//! program's function table ([`Program::functions`]) and called by index. Nothing here builds a
//! closure: `crate::exec` compiles the code when a monitor is created (and, here, to fold
//! constants). Recursion is allowed only through the lazy arguments of the builtins table
//! (`last`, `delay`).
//!
//! Owns: the [`Compiler`] and `program` (statements, modules and imports, inputs, outputs and
//! their annotations) here. By concern: `names` (scopes, definitions on first use, externs),
//! `expr` (each expression form, operators), `call` (calls and arguments), `closure`
//! (value-level functions into the function table, function values, constant folding), `stream` (the stream operators), `types` (element types
//! of nodes), `time` (base time and time units), `overrides` (`--set`). Names and signatures of
//! builtins are `crate::builtins`, operator semantics `crate::ops`, format strings
//! `crate::format`, evaluation order and cross-step slots `crate::schedule`.

use crate::builtins::{self, Builtin, Kind, StreamOp};
use crate::schedule;
use time::unit_factor;
use types::{const_type_of, ir_type, value_type};

mod call;
mod closure;
mod expr;
mod names;
mod objects;
mod overrides;
mod stream;
pub mod time;
mod types;

use crate::exec::Exec;
use crate::ir::{
    Annotation, Callee, Code, FnId, Function, InputInfo, LiftFn, Node, NodeId, OutputInfo, Prim,
    Program, SArg, Type,
};
use crate::natives;
use crate::ops::scalar_op;
use crate::value::{RuntimeError, Value};
use std::cell::RefCell;
use std::collections::{HashMap, HashSet};
use std::rc::Rc;
use std::sync::Arc;
use tessla_syntax::ast::{self, BinOp, Body, Def, Expr, ExprKind, Statement, StrPart, UnaryOp};
use tessla_syntax::diag::{Category, Diagnostic, nearest};
use tessla_syntax::source::{SourceMap, Span};

#[derive(Clone)]
enum Term {
    Const(Value),
    Stream(NodeId),
    /// Value code reading the current frame (or closed code that cannot be folded yet).
    Code(Code),
    Func(Rc<FuncTerm>),
}

enum FuncTerm {
    /// A stream operator of the builtins table (`last`, `merge` ...).
    Builtin(&'static Builtin, StreamOp),
    Native(natives::NativeFn),
    User {
        def: Rc<Def>,
        env: Env,
    },
    Lambda {
        params: Vec<ast::Param>,
        body: Rc<Expr>,
        env: Env,
    },
}

#[derive(Clone)]
struct Entry {
    def: Rc<Def>,
    env_cell: Rc<RefCell<Option<Env>>>,
    state: Rc<RefCell<DefState>>,
}

enum DefState {
    Todo,
    InProgress {
        alias: Option<NodeId>,
        /// Where it was first used outside the lazy argument of `last`/`delay` while being
        /// compiled (checked for a strict cycle when it is done; see `lower/names.rs`).
        eager: Option<Span>,
    },
    Done(Term),
    /// Compiling it failed (already reported): uses fail silently.
    Failed,
}

#[derive(Clone)]
enum Binding {
    Term(Term),
    Def(Entry),
}

/// Names in scope, innermost last. `frame` = number of runtime variables of the current frame.
#[derive(Clone, Default)]
struct Env {
    names: Rc<HashMap<String, Binding>>,
    parent: Option<Rc<Env>>,
    frame: usize,
}

impl Env {
    fn lookup(&self, name: &str) -> Option<Binding> {
        self.names
            .get(name)
            .cloned()
            .or_else(|| self.parent.as_ref().and_then(|p| p.lookup(name)))
    }

    fn child(&self, names: HashMap<String, Binding>, frame: usize) -> Env {
        Env {
            names: Rc::new(names),
            parent: Some(Rc::new(self.clone())),
            frame,
        }
    }

    fn all_names(&self, out: &mut Vec<String>) {
        out.extend(self.names.keys().cloned());
        if let Some(p) = &self.parent {
            p.all_names(out);
        }
    }
}

struct Fail;
type R<T> = Result<T, Fail>;

pub struct Compiler<'a> {
    sources: &'a SourceMap,
    pub diags: Vec<Diagnostic>,
    nodes: Vec<Node>,
    /// Node ids whose definition is pending (reserved aliases), for error checks.
    lazy_depth: usize,
    inline_depth: usize,
    base_ns: i128,
    inputs: Vec<InputInfo>,
    input_nodes: Vec<NodeId>,
    annotation_params: HashMap<String, Vec<String>>,
    /// The function table entry of each named function lowered so far.
    compiled_fns: HashMap<*const Def, FnId>,
    /// Definitions (by their span: a local def is cloned afresh each time its scope is
    /// lowered) whose body failed to compile as a value function, so calls expand them at once
    /// instead of trying again (mutually recursive nested functions made that exponential).
    not_value_fns: HashSet<Span>,
    /// The function table (`Program::functions`).
    functions: Vec<Function>,
    /// Functions compiled for constant folding, and the context folding uses (rebuilt when a
    /// function is finished).
    fold_fns: Vec<Option<Exec>>,
    fold_ctx: Option<Arc<crate::exec::Ctx>>,
    unit_node: Option<NodeId>,
    /// Element types of stream nodes known from operators and declarations.
    node_types: HashMap<NodeId, Type>,
    /// The unit of the base time in femtoseconds (`µs` in `33333 µs`); `None`: `base_ns`.
    base_unit: Option<i128>,
    /// Time literals are allowed (a base time is set, or 1 ns is assumed).
    time_units: bool,
    /// The owner of the nodes created now (see [`crate::snapshot::owner_key`]): the name of
    /// the definition or output being lowered.
    owner: u64,
    /// The owner of each node (`Program::node_owners`).
    owners: Vec<u64>,
    /// Every scope cell and def state created: scopes and defs refer to each other through
    /// `Rc`s, so they are cleared when compiling ends ([`Compiler::break_cycles`]) or each
    /// compile leaked the whole name table (found by cargo fuzz's leak checker).
    scopes: Vec<Rc<RefCell<Option<Env>>>>,
    states: Vec<Rc<RefCell<DefState>>>,
    /// The checker's types of outputs and top-level defs (see [`crate::typeck::Types`]).
    types: crate::typeck::Types,
}

/// The native of an `extern` no builtin provides: an error when evaluated.
fn unknown_extern(_: &[Value]) -> Value {
    Value::Error(RuntimeError::Other("call of an unknown extern".into()))
}

impl<'a> Compiler<'a> {
    pub fn new(sources: &'a SourceMap, base_ns_fs: i128) -> Compiler<'a> {
        Compiler {
            sources,
            diags: Vec::new(),
            nodes: Vec::new(),
            lazy_depth: 0,
            inline_depth: 0,
            base_ns: base_ns_fs,
            inputs: Vec::new(),
            input_nodes: Vec::new(),
            annotation_params: HashMap::new(),
            compiled_fns: HashMap::new(),
            not_value_fns: HashSet::new(),
            functions: Vec::new(),
            fold_fns: Vec::new(),
            fold_ctx: None,
            unit_node: None,
            base_unit: None,
            time_units: true,
            node_types: HashMap::new(),
            owner: 0,
            owners: Vec::new(),
            scopes: Vec::new(),
            states: Vec::new(),
            types: crate::typeck::Types::default(),
        }
    }

    /// A new def state, registered for [`Compiler::break_cycles`].
    fn new_state(&mut self) -> Rc<RefCell<DefState>> {
        let s = Rc::new(RefCell::new(DefState::Todo));
        self.states.push(s.clone());
        s
    }

    /// A new scope cell, registered for [`Compiler::break_cycles`].
    fn new_scope(&mut self) -> Rc<RefCell<Option<Env>>> {
        let c = Rc::new(RefCell::new(None));
        self.scopes.push(c.clone());
        c
    }

    /// Empty every scope cell and def state, breaking the reference cycles between them.
    fn break_cycles(&mut self) {
        for c in self.scopes.drain(..) {
            if let Ok(mut c) = c.try_borrow_mut() {
                *c = None;
            }
        }
        for st in self.states.drain(..) {
            if let Ok(mut st) = st.try_borrow_mut() {
                *st = DefState::Failed;
            }
        }
    }

    /// Allow or forbid time literals (forbidden when the spec runs without a base time).
    pub fn with_time_units(mut self, allowed: bool) -> Self {
        self.time_units = allowed;
        self
    }

    /// Use the checker's types for outputs whose element type lowering does not know.
    pub fn with_types(mut self, types: crate::typeck::Types) -> Self {
        self.types = types;
        self
    }

    /// Set the unit of the base time (see [`parse_base_parts`]) for time literal conversion.
    pub fn with_base_unit(mut self, unit_fs: i128) -> Self {
        self.base_unit = Some(unit_fs);
        self
    }

    fn error<T>(&mut self, cat: Category, span: Span, msg: impl Into<String>) -> R<T> {
        self.diags.push(Diagnostic::error(cat, Some(span), msg));
        Err(Fail)
    }

    fn node(&mut self, n: Node) -> NodeId {
        self.nodes.push(n);
        self.owners.push(self.owner);
        self.nodes.len() - 1
    }

    /// Compile the statements of all files (includes first) into a program.
    pub fn program(
        mut self,
        files: &[ast::File],
        overrides: &[(String, String)],
    ) -> Result<(Program, Vec<Diagnostic>), Vec<Diagnostic>> {
        let mut names: HashMap<String, Binding> = HashMap::new();
        let mut outs: Vec<&ast::Out> = Vec::new();
        let mut out_all = false;
        let mut defs_in_order: Vec<String> = Vec::new();
        let env_cell: Rc<RefCell<Option<Env>>> = self.new_scope();
        let mut statements: Vec<(String, &Statement)> = Vec::new();
        for f in files {
            for s in &f.statements {
                statements.push((String::new(), s));
            }
        }
        // Module prefix (`Foo.Bar.`) -> (its scope cell, its members by short name).
        type ModuleScope = (Rc<RefCell<Option<Env>>>, HashMap<String, Binding>);
        let mut modules: HashMap<String, ModuleScope> = HashMap::new();
        // (importing module prefix, imported module prefix).
        let mut imports: Vec<(String, String)> = Vec::new();
        let mut i = 0;
        while i < statements.len() {
            let (prefix, s) = statements[i].clone();
            i += 1;
            match s {
                Statement::Def(d) => {
                    let name = format!("{prefix}{}", d.name.name);
                    if let Some(Binding::Def(prev)) = names.get(&name)
                        && prefix.is_empty()
                    {
                        let sp = prev.def.name.span;
                        self.diags.push(
                            Diagnostic::error(
                                Category::Other,
                                Some(d.name.span),
                                format!("`{name}` is defined twice"),
                            )
                            .with_note_at(sp, "first defined here"),
                        );
                        continue;
                    }
                    defs_in_order.push(name.clone());
                    // A def in a module sees the module's other members by their short names.
                    let cell = if prefix.is_empty() {
                        env_cell.clone()
                    } else if let Some(m) = modules.get(&prefix) {
                        m.0.clone()
                    } else {
                        let c = self.new_scope();
                        modules.insert(prefix.clone(), (c.clone(), HashMap::new()));
                        c
                    };
                    let entry = Entry {
                        def: Rc::new(d.clone()),
                        env_cell: cell,
                        state: self.new_state(),
                    };
                    if let Some(m) = modules.get_mut(&prefix) {
                        m.1.insert(d.name.name.clone(), Binding::Def(entry.clone()));
                    }
                    // Enclosing modules see it by its relative path (`Limits.maxSpeed` in
                    // `Robot`), so `import Robot` brings `Limits.maxSpeed` too, as in TeSSLa.
                    let mut outer = prefix.trim_end_matches('.');
                    while let Some(k) = outer.rfind('.') {
                        let p = format!("{}.", &outer[..k]);
                        let rel = format!("{}{}", &prefix[p.len()..], d.name.name);
                        if !modules.contains_key(&p) {
                            let c = self.new_scope();
                            modules.insert(p.clone(), (c, HashMap::new()));
                        }
                        if let Some(m) = modules.get_mut(&p) {
                            m.1.entry(rel)
                                .or_insert_with(|| Binding::Def(entry.clone()));
                        }
                        outer = &outer[..k];
                    }
                    names.insert(name, Binding::Def(entry));
                }
                Statement::Import { path, .. } => {
                    let target: String = path.iter().map(|p| format!("{}.", p.name)).collect();
                    imports.push((prefix.clone(), target));
                }
                Statement::Module {
                    name,
                    statements: inner,
                    ..
                } => {
                    for st in inner {
                        statements.push((format!("{prefix}{}.", name.name), st));
                    }
                }
                Statement::AnnotationDef { name, params, .. } => {
                    self.annotation_params.insert(
                        name.name.clone(),
                        params.iter().map(|p| p.name.name.clone()).collect(),
                    );
                }
                Statement::In { name, ty, .. } => {
                    let elem = match ir_type(ty) {
                        Type::Events(t) => *t,
                        _ => {
                            self.diags.push(
                                Diagnostic::error(
                                    Category::Type,
                                    Some(ty.span()),
                                    format!("input `{}` must have a type Events[T]", name.name),
                                )
                                .with_help(format!(
                                    "write `in {}: Events[Float]` (or another element type)",
                                    name.name
                                )),
                            );
                            Type::Unknown
                        }
                    };
                    let idx = self.inputs.len();
                    let n = self.node(Node::Input(idx));
                    self.input_nodes.push(n);
                    self.inputs.push(InputInfo {
                        name: name.name.clone(),
                        ty: elem,
                        annotations: Vec::new(),
                    });
                    names.insert(name.name.clone(), Binding::Term(Term::Stream(n)));
                }
                Statement::Out(o) => outs.push(o),
                Statement::OutAll { .. } => out_all = true,
                Statement::TypeDef { .. } | Statement::GlobalAnnotation(_) => {}
            }
        }
        // --set overrides replace the body of a top-level constant.
        self.apply_overrides(&mut names, overrides);
        // `import M`: M's members become visible by short name (own members win). `M` is
        // looked up relative to the importing module first, then from the top.
        for (at, target) in &imports {
            let full = [format!("{at}{target}"), target.clone()]
                .into_iter()
                .find(|t| modules.contains_key(t));
            let Some(members) = full.and_then(|t| modules.get(&t)).map(|m| m.1.clone()) else {
                continue;
            };
            let scope = if at.is_empty() {
                &mut names
            } else {
                match modules.get_mut(at) {
                    Some(m) => &mut m.1,
                    None => continue,
                }
            };
            for (k, b) in members {
                scope.entry(k).or_insert(b);
            }
        }
        let env = Env {
            names: Rc::new(names),
            parent: None,
            frame: 0,
        };
        *env_cell.borrow_mut() = Some(env.clone());
        // Module scopes nest: `Foo.Bar.` sees `Foo.`'s members, which see the top level.
        let mut prefixes: Vec<&String> = modules.keys().collect();
        prefixes.sort_by_key(|p| p.len());
        let mut module_envs: HashMap<String, Env> = HashMap::new();
        for p in prefixes {
            let trimmed = p.trim_end_matches('.');
            let parent = trimmed
                .rfind('.')
                .map(|k| format!("{}.", &trimmed[..k]))
                .and_then(|pp| module_envs.get(&pp).cloned())
                .unwrap_or_else(|| env.clone());
            if let Some((cell, members)) = modules.get(p) {
                let menv = parent.child(members.clone(), 0);
                *cell.borrow_mut() = Some(menv.clone());
                module_envs.insert(p.clone(), menv);
            }
        }

        // Annotations of inputs.
        let mut input_i = 0;
        for (_, s) in &statements {
            if let Statement::In { annotations, .. } = s {
                let anns = self.annotations(annotations, &env);
                if let Some(info) = self.inputs.get_mut(input_i) {
                    info.annotations = anns;
                }
                input_i += 1;
            }
        }
        let mut outputs = Vec::new();
        let mut output_nodes = Vec::new();
        for o in outs {
            let annotations = self.annotations(&o.annotations, &env);
            let raw = annotations.iter().any(|a| a.name == "raw");
            let name = o
                .alias
                .as_ref()
                .map_or_else(|| o.source_text.clone(), |a| a.name.clone());
            self.owner = crate::snapshot::owner_key(&name);
            // An object (a record with stream members): one output per member, as TeSSLa.
            match self.object_output(&o.expr, &env) {
                Some(Ok(members)) => {
                    for (path, t) in members {
                        let ty = match &t {
                            Term::Const(v) => value_type(v),
                            Term::Stream(n) => self.stream_type(*n),
                            _ => Type::Unknown,
                        };
                        if let Ok(n) = self.stream_of(t, o.expr.span) {
                            outputs.push(OutputInfo {
                                name: format!("{name}.{path}"),
                                ty,
                                annotations: annotations.clone(),
                                raw,
                            });
                            output_nodes.push(n);
                        }
                    }
                    continue;
                }
                Some(Err(Fail)) => continue,
                None => {}
            }
            if let Ok(t) = self.expr(&o.expr, &env) {
                let ty = match &t {
                    Term::Const(v) => value_type(v),
                    Term::Stream(n) => self.stream_type(*n),
                    _ => Type::Unknown,
                };
                let ty = known_or(ty, self.types.outputs.get(&o.expr.span));
                if let Ok(n) = self.stream_of(t, o.expr.span) {
                    outputs.push(OutputInfo {
                        name,
                        ty,
                        annotations,
                        raw,
                    });
                    output_nodes.push(n);
                }
            }
        }
        if out_all {
            for (i, info) in self.inputs.clone().iter().enumerate() {
                outputs.push(OutputInfo {
                    name: info.name.clone(),
                    ty: info.ty.clone(),
                    annotations: Vec::new(),
                    raw: false,
                });
                output_nodes.push(self.input_nodes[i]);
            }
            for name in &defs_in_order {
                if let Some(Binding::Def(e)) = env.lookup(name)
                    && e.def.params.is_none()
                    && let Ok(t) = self.def_term(&e, e.def.name.span)
                    && let Term::Stream(n) = t
                {
                    let ty = known_or(self.stream_type(n), self.types.defs.get(name));
                    outputs.push(OutputInfo {
                        name: name.clone(),
                        ty,
                        annotations: Vec::new(),
                        raw: false,
                    });
                    output_nodes.push(n);
                }
            }
        }
        drop(env);
        drop(module_envs);
        self.break_cycles();
        if self.diags.iter().any(|d| d.is_error()) {
            return Err(self.diags);
        }
        let order = match schedule::order(&self.nodes, &output_nodes) {
            Ok(o) => o,
            Err(cycle) => {
                let d = cycle.diagnostic();
                self.diags.push(d);
                return Err(self.diags);
            }
        };
        let (last_slot, n_last_slots) = schedule::last_slots(&self.nodes, &order);
        Ok((
            Program {
                functions: std::mem::take(&mut self.functions),
                exec: std::sync::OnceLock::new(),
                last_slot,
                n_last_slots,
                inputs: self.inputs,
                outputs,
                delays: order
                    .iter()
                    .copied()
                    .filter(|i| matches!(self.nodes.get(*i), Some(Node::Delay { .. })))
                    .collect(),
                nodes: self.nodes,
                node_owners: self.owners,
                order,
                output_nodes,
            },
            self.diags,
        ))
    }

    fn annotations(&mut self, anns: &[ast::Annotation], env: &Env) -> Vec<Annotation> {
        let mut out = Vec::new();
        for a in anns {
            let params = self.annotation_params.get(&a.name.name).cloned();
            if params.is_none() && a.name.name != "raw" {
                self.diags.push(
                    Diagnostic::warning(
                        Category::Name,
                        Some(a.name.span),
                        format!("annotation `@{}` is not declared", a.name.name),
                    )
                    .with_help(format!("declare it: `def @{}(...)`", a.name.name)),
                );
            }
            let mut args = Vec::new();
            for (i, arg) in a.args.iter().enumerate() {
                let name = arg
                    .name
                    .as_ref()
                    .map(|n| n.name.clone())
                    .or_else(|| params.as_ref().and_then(|p| p.get(i).cloned()))
                    .unwrap_or_else(|| format!("_{i}"));
                match self.expr(&arg.value, env) {
                    Ok(Term::Const(v)) => args.push((name, v)),
                    Ok(_) => self.diags.push(Diagnostic::error(
                        Category::Type,
                        Some(arg.value.span),
                        "annotation arguments must be constants",
                    )),
                    Err(Fail) => {}
                }
            }
            out.push(Annotation {
                name: a.name.name.clone(),
                args,
            });
        }
        out
    }

    fn unit(&mut self) -> NodeId {
        if let Some(u) = self.unit_node {
            return u;
        }
        let u = self.node(Node::Const(Value::Unit));
        self.unit_node = Some(u);
        u
    }

    fn stream_of(&mut self, t: Term, span: Span) -> R<NodeId> {
        match t {
            Term::Stream(n) => Ok(n),
            Term::Const(v) => Ok(self.node(Node::Const(v))),
            Term::Code(_) => self.error(
                Category::Type,
                span,
                "a value depending on a function parameter is used where a stream is needed",
            ),
            Term::Func(ft) => {
                // A parameterless function (`def foo() = 42`) used as a stream is called.
                if let FuncTerm::User { def, .. } = &*ft
                    && def.params.as_ref().is_some_and(|p| p.is_empty())
                {
                    let t = self.call(Term::Func(ft.clone()), Vec::new(), span, &Env::default())?;
                    return self.stream_of(t, span);
                }
                self.error(
                    Category::Type,
                    span,
                    "a function is used where a stream is needed",
                )
            }
        }
    }
}

/// The checker's type when it is fully known (the type table is where types come from), else
/// what lowering found for the node (`lower/types.rs`).
fn known_or(lowered: Type, checked: Option<&Type>) -> Type {
    match checked {
        Some(c) if c.is_known() => c.clone(),
        _ => lowered,
    }
}
