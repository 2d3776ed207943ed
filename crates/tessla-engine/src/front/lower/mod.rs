//! Lowering: from the checked syntax of a spec to a [`Program`] (the IR the monitor runs).
//!
//! Every expression becomes a `Term`: a constant, a stream node, value code over a frame of
//! variables ([`Code`], data: used inside function bodies and lambdas), or a function. Functions
//! applied to stream arguments are expanded in place (TeSSLa's macros); operators and liftable
//! functions on streams become signal lifts; value-level functions are lowered once into the
//! program's function table ([`Program::functions`]) and called by index. Nothing here builds a
//! closure: `crate::runtime::exec` compiles the code when a monitor is created; constants are
//! folded on the IR (`crate::ir::fold`). Recursion is allowed only through the lazy arguments of the builtins table
//! (`last`, `delay`).
//!
//! Owns: the [`Compiler`] and `program` (inputs, outputs, `out *` and their annotations) here.
//! It reads the resolved spec (`crate::front::resolve`): which definition, input or imported member a
//! global name means is decided there once, for the checker and the lowering; lowering keeps
//! only its local scopes (parameters, blocks and `where`, macro arguments). It lowers only a
//! checked spec (`crate::front::typeck::Typed`, which only the checker makes) and takes its
//! types from there (inputs, outputs, `out *` defs). The lowering keeps
//! only the rules the checker leaves open (each marked "the one place" where it is written); a
//! case the checker or name resolution rules out is `Compiler::unchecked`, an internal error.
//! By concern: `names`
//! (local scopes over the resolved globals, definitions on first use, externs),
//! `expr` (each expression form, operators), `call` (calls and arguments), `closure`
//! (value-level functions into the function table, function values, constant folding), `stream` (the stream operators), `time` (base time and time units), `overrides` (`--set`),
//! `traps` (warnings about specs that check but cannot do what they say: a `delay` armed once).
//! Names and signatures of
//! builtins are `crate::builtins`, operator semantics `crate::runtime::ops`, format strings
//! `crate::runtime::format`, evaluation order and cross-step slots `crate::ir::schedule`.

use crate::builtins::{self, Builtin, Kind, StreamOp};
use crate::front::resolve::Resolved;
use crate::front::typeck::Typed;
use crate::ir::fold::Folder;
use time::unit_factor;

mod call;
mod closure;
mod expr;
mod names;
mod objects;
mod overrides;
mod stream;
pub mod time;
mod traps;

use crate::ir::{
    Annotation, BinOp, Callee, Code, FnId, Function, InputInfo, LiftFn, Node, NodeId, OutputInfo,
    Prim, Program, SArg, Type, UnaryOp,
};
use crate::ir::{owner_key, scalar_op, schedule};
use crate::value::{NativeFn, RuntimeError, Value};
use std::cell::RefCell;
use std::collections::{HashMap, HashSet};
use std::rc::Rc;
use std::sync::Arc;
use tessla_syntax::ast::{self, Body, Def, Expr, ExprKind, Statement, StrPart};
use tessla_syntax::diag::{Category, Diagnostic};
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
    /// A native value function, with its name in the builtins table (`unknown extern` for an
    /// extern no builtin provides).
    Native {
        name: &'static str,
        f: NativeFn,
    },
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

/// Local names in scope (parameters, block and `where` definitions, macro arguments),
/// innermost last, over the globals of module `prefix` (found by [`Resolved::global`]).
/// `frame` = number of runtime variables of the current frame.
#[derive(Clone, Default)]
struct Env {
    names: Rc<HashMap<String, Binding>>,
    parent: Option<Rc<Env>>,
    frame: usize,
    /// The module prefix (`A.B.`, `""` at the top level) global names are looked up from.
    prefix: Rc<str>,
}

impl Env {
    /// The scope of a global definition's body: no local names, the globals of `prefix`.
    fn module(prefix: &str) -> Env {
        Env {
            prefix: prefix.into(),
            ..Env::default()
        }
    }

    /// A local name (`None`: not local; it may be a global, see [`Compiler::binding`]).
    fn local(&self, name: &str) -> Option<Binding> {
        self.names
            .get(name)
            .cloned()
            .or_else(|| self.parent.as_ref().and_then(|p| p.local(name)))
    }

    fn child(&self, names: HashMap<String, Binding>, frame: usize) -> Env {
        Env {
            names: Rc::new(names),
            parent: Some(Rc::new(self.clone())),
            frame,
            prefix: self.prefix.clone(),
        }
    }
}

struct Fail;
type R<T> = Result<T, Fail>;

/// The lowering of one checked spec. Its state, by concern: the spec it reads, the
/// definitions' lowering states (`Defs`), the stream graph being built (`Graph`), the
/// function table (`Functions`), the time settings (`TimeSettings`), how deep it is
/// (`Depth`) and the diagnostics.
pub struct Compiler<'a> {
    sources: &'a SourceMap,
    /// The resolve pass's result: what every global name means (`crate::front::resolve`).
    resolved: &'a Resolved<'a>,
    /// The checked spec: the types of inputs, outputs and top-level defs (see
    /// [`crate::front::typeck::Typed`]).
    typed: &'a Typed<'a>,
    pub diags: Vec<Diagnostic>,
    defs: Defs,
    graph: Graph,
    table: Functions,
    time: TimeSettings,
    depth: Depth,
}

/// The lowering state of definitions and their scopes (`names`).
struct Defs {
    /// The lowering state of each global definition, by [`DefId`](crate::front::resolve::DefId),
    /// made on first use (or by a `--set` override).
    globals: Vec<Option<Entry>>,
    /// Every scope cell and def state created: scopes and defs refer to each other through
    /// `Rc`s, so they are cleared when compiling ends ([`Compiler::break_cycles`]) or each
    /// compile leaked the whole name table (found by cargo fuzz's leak checker).
    scopes: Vec<Rc<RefCell<Option<Env>>>>,
    states: Vec<Rc<RefCell<DefState>>>,
}

/// The stream graph being built: nodes with their owners, the inputs.
struct Graph {
    nodes: Vec<Node>,
    /// The owner of each node (`Program::node_owners`).
    owners: Vec<u64>,
    /// The owner of the nodes created now (see [`crate::ir::owner_key`]): the name of
    /// the definition or output being lowered.
    owner: u64,
    /// The one `unit` node, once made.
    unit_node: Option<NodeId>,
    inputs: Vec<InputInfo>,
    input_nodes: Vec<NodeId>,
    /// Each `delay` call: its delay stream, its reset stream and its place (`traps`).
    delays_at: Vec<(NodeId, NodeId, Span)>,
}

/// The function table being built (`closure`) and constant folding over it.
struct Functions {
    /// The function table (`Program::functions`).
    functions: Vec<Function>,
    /// The function table entry of each named function lowered so far.
    compiled_fns: HashMap<*const Def, FnId>,
    /// Definitions (by their span: a local def is cloned afresh each time its scope is
    /// lowered) whose body failed to compile as a value function, so calls expand them at once
    /// instead of trying again (mutually recursive nested functions made that exponential).
    not_value_fns: HashSet<Span>,
    /// Constant folding with the functions finished so far (see `closure::fold`).
    folder: Folder,
}

/// Base time and time literals (`time`).
struct TimeSettings {
    /// The base time in femtoseconds.
    base_ns: i128,
    /// The unit of the base time in femtoseconds (`µs` in `33333 µs`); `None`: `base_ns`.
    base_unit: Option<i128>,
    /// Time literals are allowed (a base time is set, or 1 ns is assumed).
    time_units: bool,
}

/// How deep the lowering is.
struct Depth {
    /// Inside the lazy argument of `last`/`delay` (of the definition being lowered).
    lazy_depth: usize,
    /// Nested macro expansions (calls of functions on streams), bounded.
    inline_depth: usize,
}

/// The native of an `extern` no builtin provides: an error when evaluated.
fn unknown_extern(_: &[Value]) -> Value {
    Value::Error(RuntimeError::Other("call of an unknown extern".into()))
}

impl<'a> Compiler<'a> {
    /// The lowering of a checked spec; `base_ns_fs` is the base time in femtoseconds.
    pub fn new(sources: &'a SourceMap, typed: &'a Typed<'a>, base_ns_fs: i128) -> Compiler<'a> {
        let resolved = typed.resolved();
        Compiler {
            sources,
            resolved,
            typed,
            diags: Vec::new(),
            defs: Defs {
                globals: vec![None; resolved.defs.len()],
                scopes: Vec::new(),
                states: Vec::new(),
            },
            graph: Graph {
                nodes: Vec::new(),
                owners: Vec::new(),
                owner: 0,
                unit_node: None,
                inputs: Vec::new(),
                input_nodes: Vec::new(),
                delays_at: Vec::new(),
            },
            table: Functions {
                functions: Vec::new(),
                compiled_fns: HashMap::new(),
                not_value_fns: HashSet::new(),
                folder: Folder::new(builtins::prim),
            },
            time: TimeSettings {
                base_ns: base_ns_fs,
                base_unit: None,
                time_units: true,
            },
            depth: Depth {
                lazy_depth: 0,
                inline_depth: 0,
            },
        }
    }

    /// A new def state, registered for [`Compiler::break_cycles`].
    fn new_state(&mut self) -> Rc<RefCell<DefState>> {
        let s = Rc::new(RefCell::new(DefState::Todo));
        self.defs.states.push(s.clone());
        s
    }

    /// A new scope cell, registered for [`Compiler::break_cycles`].
    fn new_scope(&mut self) -> Rc<RefCell<Option<Env>>> {
        let c = Rc::new(RefCell::new(None));
        self.defs.scopes.push(c.clone());
        c
    }

    /// Empty every scope cell and def state, breaking the reference cycles between them.
    fn break_cycles(&mut self) {
        for c in self.defs.scopes.drain(..) {
            if let Ok(mut c) = c.try_borrow_mut() {
                *c = None;
            }
        }
        for st in self.defs.states.drain(..) {
            if let Ok(mut st) = st.try_borrow_mut() {
                *st = DefState::Failed;
            }
        }
    }

    /// Allow or forbid time literals (forbidden when the spec runs without a base time).
    pub fn with_time_units(mut self, allowed: bool) -> Self {
        self.time.time_units = allowed;
        self
    }

    /// Set the unit of the base time (see `parse_base_parts`) for time literal conversion.
    pub fn with_base_unit(mut self, unit_fs: i128) -> Self {
        self.time.base_unit = Some(unit_fs);
        self
    }

    fn error<T>(&mut self, cat: Category, span: Span, msg: impl Into<String>) -> R<T> {
        self.diags.push(Diagnostic::error(cat, Some(span), msg));
        Err(Fail)
    }

    /// The one path for a case the checker (`crate::front::typeck`) or name resolution rules
    /// out before lowering starts: `what` names what got through. No rule is written here
    /// again; reaching this is a bug of the checker, reported as such.
    fn unchecked<T>(&mut self, span: Span, what: &str) -> R<T> {
        self.diags.push(Diagnostic::error(
            Category::Other,
            Some(span),
            format!("internal error: the checker let through {what}; please report this spec"),
        ));
        Err(Fail)
    }

    fn node(&mut self, n: Node) -> NodeId {
        self.graph.nodes.push(n);
        self.graph.owners.push(self.graph.owner);
        self.graph.nodes.len() - 1
    }

    /// Lower the resolved spec (inputs, outputs, `out *`, the definitions they use) into a
    /// program.
    pub fn program(
        mut self,
        overrides: &[(String, String)],
    ) -> Result<(Program, Vec<Diagnostic>), Vec<Diagnostic>> {
        let resolved = self.resolved;
        for (name, _) in &resolved.inputs {
            let idx = self.graph.inputs.len();
            let n = self.node(Node::Input(idx));
            self.graph.input_nodes.push(n);
            self.graph.inputs.push(InputInfo {
                name: name.name.clone(),
                ty: self.typed.input(idx),
                annotations: Vec::new(),
            });
        }
        // --set overrides replace the body of a top-level constant.
        self.apply_overrides(overrides);
        let env = Env::default();

        // Annotations of inputs.
        let mut input_i = 0;
        for (_, s) in &resolved.statements {
            if let Statement::In { annotations, .. } = s {
                let anns = self.annotations(annotations, &env);
                if let Some(info) = self.graph.inputs.get_mut(input_i) {
                    info.annotations = anns;
                }
                input_i += 1;
            }
        }
        let mut outputs = Vec::new();
        let mut output_nodes = Vec::new();
        for o in &resolved.outputs {
            let annotations = self.annotations(&o.annotations, &env);
            let raw = annotations.iter().any(|a| a.name == "raw");
            let name = o
                .alias
                .as_ref()
                .map_or_else(|| o.source_text.clone(), |a| a.name.clone());
            self.graph.owner = owner_key(&name);
            // An object (a record with stream members): one output per member, as TeSSLa.
            match self.object_output(&o.expr, &env) {
                Some(Ok(members)) => {
                    for (path, t) in members {
                        let ty = member_type(self.typed.output(&o.expr), &path);
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
                let ty = self.typed.output(&o.expr);
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
        if resolved.out_all {
            for (i, info) in self.graph.inputs.clone().iter().enumerate() {
                outputs.push(OutputInfo {
                    name: info.name.clone(),
                    ty: info.ty.clone(),
                    annotations: Vec::new(),
                    raw: false,
                });
                output_nodes.push(self.graph.input_nodes[i]);
            }
            for (id, g) in resolved.defs.iter().enumerate() {
                if g.def.params.is_none()
                    && let Some(e) = self.global_entry(id)
                    && let Ok(t) = self.def_term(&e, g.def.name.span)
                    && let Term::Stream(n) = t
                    && let Some(name) = resolved.name(id)
                {
                    let ty = self.typed.def(&name);
                    outputs.push(OutputInfo {
                        name,
                        ty,
                        annotations: Vec::new(),
                        raw: false,
                    });
                    output_nodes.push(n);
                }
            }
        }
        drop(env);
        self.warn_delay_traps();
        self.break_cycles();
        if self.diags.iter().any(|d| d.is_error()) {
            return Err(self.diags);
        }
        let order = match schedule::order(&self.graph.nodes, &output_nodes) {
            Ok(o) => o,
            Err(cycle) => {
                // No node of the cycle has a place in the source.
                let d = Diagnostic::error(Category::Recursion, None, cycle.to_string()).with_help(
                    "recursion is allowed only through the first argument of `last` or `delay`",
                );
                self.diags.push(d);
                return Err(self.diags);
            }
        };
        let (last_slot, n_last_slots) = schedule::last_slots(&self.graph.nodes, &order);
        Ok((
            Program {
                functions: std::mem::take(&mut self.table.functions),
                last_slot,
                n_last_slots,
                inputs: self.graph.inputs,
                outputs,
                delays: order
                    .iter()
                    .copied()
                    .filter(|i| matches!(self.graph.nodes.get(*i), Some(Node::Delay { .. })))
                    .collect(),
                nodes: self.graph.nodes,
                node_owners: self.graph.owners,
                order,
                output_nodes,
            },
            self.diags,
        ))
    }

    fn annotations(&mut self, anns: &[ast::Annotation], env: &Env) -> Vec<Annotation> {
        let mut out = Vec::new();
        for a in anns {
            let params: Option<Vec<String>> = [false, true]
                .into_iter()
                .find_map(|global| {
                    self.resolved
                        .annotations
                        .get(&(a.name.name.clone(), global))
                })
                .map(|ps| ps.iter().map(|p| p.name.name.clone()).collect());
            if params.is_none() && a.name.name != "raw" {
                self.diags.push(
                    Diagnostic::warning(
                        Category::Name,
                        Some(a.name.span),
                        format!("annotation `@{}` is not declared", a.name.name),
                    )
                    .with_help(if a.name.name.starts_with("Telegraf") {
                        // The connector's annotations come with the connector (and with us).
                        "add this line at the top of the spec: include \"telegraf.tessla\" \
                         (the Telegraf annotations, bundled when no such file is beside the \
                         spec)"
                            .to_string()
                    } else {
                        format!("declare it: `def @{}(...)`", a.name.name)
                    }),
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
                    // For an annotation declared nowhere, the one place of this rule (the
                    // checker checks the arguments of declared annotations, with the same text).
                    Ok(_) => self.diags.push(Diagnostic::error(
                        Category::Type,
                        Some(arg.value.span),
                        crate::front::typeck::ANNOTATION_ARGS_CONSTANT,
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
        if let Some(u) = self.graph.unit_node {
            return u;
        }
        let u = self.node(Node::Const(Value::Unit));
        self.graph.unit_node = Some(u);
        u
    }

    fn stream_of(&mut self, t: Term, span: Span) -> R<NodeId> {
        match t {
            Term::Stream(n) => Ok(n),
            Term::Const(v) => Ok(self.node(Node::Const(v))),
            // Not a type rule: the lowering's signal that a function body cannot be compiled
            // to a value function (`call` then expands it as a macro).
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
                // The one place of this rule: the checker lets a function value stand for a
                // constant stream (`last(f, x)`, `count(Operators.add)`).
                self.error(
                    Category::Type,
                    span,
                    "a function is used where a stream is needed",
                )
            }
        }
    }
}

/// The element type of the member at `path` (`a.b`, `_1`) of an object output of type `whole`.
fn member_type(whole: Type, path: &str) -> Type {
    path.split('.').fold(whole, |t, field| match t {
        Type::Record(fs) => fs
            .into_iter()
            .find(|(n, _)| n == field)
            .map_or(Type::Unknown, |(_, t)| t),
        Type::Tuple(ts) => field
            .strip_prefix('_')
            .and_then(|k| k.parse::<usize>().ok())
            .and_then(|k| ts.into_iter().nth(k.checked_sub(1)?))
            .unwrap_or(Type::Unknown),
        _ => Type::Unknown,
    })
}
