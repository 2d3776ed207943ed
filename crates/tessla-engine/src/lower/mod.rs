//! Lowering: from the checked syntax of a spec to a [`Program`] (the IR the monitor runs).
//!
//! Every expression becomes a [`Term`]: a constant, a stream node, runtime value code (a closure
//! over a frame of variables, used inside function bodies and lambdas), or a function. Functions
//! applied to stream arguments are expanded in place (TeSSLa's macros); operators and liftable
//! functions on streams become signal lifts; value-level functions are compiled once into
//! closures, so evaluation never walks the AST. Recursion is allowed only through the lazy
//! arguments of the builtins table (`last`, `delay`).
//!
//! Owns: the [`Compiler`] (scopes, definitions, `--set` overrides, annotations, the outputs)
//! here; the stream operators in `stream`; base time and time units in `time`. Names and
//! signatures of builtins are `crate::builtins`, operator semantics `crate::ops`, format strings
//! `crate::format`, evaluation order and cross-step slots `crate::schedule`.

use crate::builtins::{self, Builtin, Kind, StreamOp};
use crate::format::format_value;
use crate::schedule;
use time::unit_factor;

mod stream;
pub mod time;

use crate::collections;
use crate::ir::{
    Annotation, Func, InputInfo, LiftFunc, Node, NodeId, OutputInfo, Program, SArg, Scalar, Type,
};
use crate::natives;
use crate::ops::{self, scalar_op};
use crate::value::{Callable, RuntimeError, Value};
use std::cell::RefCell;
use std::collections::HashMap;
use std::rc::Rc;
use std::sync::{Arc, OnceLock};
use tessla_syntax::ast::{self, BinOp, Body, Def, Expr, ExprKind, Statement, StrPart, UnaryOp};
use tessla_syntax::diag::{Category, Diagnostic, nearest};
use tessla_syntax::source::{SourceMap, Span};

/// Frame code: runtime value code reading variables from a frame.
type Dyn = Arc<dyn Fn(&[Value]) -> Value + Send + Sync>;

#[derive(Clone)]
enum Term {
    Const(Value),
    Stream(NodeId),
    Dyn(Dyn),
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
    compiled_fns: HashMap<*const Def, Arc<OnceLock<Func>>>,
    unit_node: Option<NodeId>,
    /// Element types of stream nodes known from operators and declarations.
    node_types: HashMap<NodeId, Type>,
    /// The unit of the base time in femtoseconds (`µs` in `33333 µs`); `None`: `base_ns`.
    base_unit: Option<i128>,
    /// Time literals are allowed (a base time is set, or 1 ns is assumed).
    time_units: bool,
    /// Stable origin of the nodes created now (see [`crate::snapshot`]): a hash of the text of
    /// the def being compiled and of every def it looked up so far.
    origin: u64,
    /// The origin of each node (`Program::node_origins`).
    origins: Vec<u64>,
    /// Every scope cell and def state created: scopes and defs refer to each other through
    /// `Rc`s, so they are cleared when compiling ends ([`Compiler::break_cycles`]) or each
    /// compile leaked the whole name table (found by cargo fuzz's leak checker).
    scopes: Vec<Rc<RefCell<Option<Env>>>>,
    states: Vec<Rc<RefCell<DefState>>>,
}

/// The type of a parameterless def's constant value, if it is a literal constant.
fn const_type_of(d: &Def) -> Option<Type> {
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

/// The native of an `extern` no builtin provides: an error when evaluated.
fn unknown_extern(_: &[Value]) -> Value {
    Value::Error(RuntimeError::Other("call of an unknown extern".into()))
}

fn is_err(v: &Value) -> Option<Value> {
    match v {
        Value::Error(_) => Some(v.clone()),
        _ => None,
    }
}

/// Call a native strictly: the first error argument is the result.
fn call_native(f: natives::NativeFn, args: &[Value]) -> Value {
    if let Some(e) = args.iter().find_map(is_err) {
        return e;
    }
    f(args)
}

fn binop(op: BinOp, a: &Value, b: &Value) -> Value {
    ops::binary_value(op, a, b)
}

/// The closure of a binary operator, with the inline scalar path for its usual operand types
/// ([`ScalarOp::eval`], as the evaluator's `Bin` nodes use it) before the general one.
fn binop_fn(op: BinOp) -> Func {
    let two = || Value::Error(RuntimeError::Other("an operator needs two operands".into()));
    match scalar_op(op) {
        Some(sop) => Arc::new(move |v: &[Value]| match v {
            [a, b] => match (Scalar::of(a), Scalar::of(b)) {
                (Some(x), Some(y)) => match sop.eval(x, y) {
                    Some(r) => r.value(),
                    None => binop(op, a, b),
                },
                _ => binop(op, a, b),
            },
            _ => two(),
        }),
        None => Arc::new(move |v: &[Value]| match v {
            [a, b] => binop(op, a, b),
            _ => two(),
        }),
    }
}

fn unop(op: UnaryOp, a: &Value) -> Value {
    ops::unary_value(op, a)
}

/// A runtime function value (closure over a captured frame).
struct RtClosure {
    captured: Vec<Value>,
    body: Dyn,
}

impl std::fmt::Debug for RtClosure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("<function>")
    }
}

impl Callable for RtClosure {
    fn call(&self, args: &[Value]) -> Value {
        let mut frame = self.captured.clone();
        frame.extend_from_slice(args);
        (self.body)(&frame)
    }
}

/// A compiled named function called as a value.
struct FnValue(Func);

impl std::fmt::Debug for FnValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("<function>")
    }
}

impl Callable for FnValue {
    fn call(&self, args: &[Value]) -> Value {
        (self.0)(args)
    }
}

fn value_type(v: &Value) -> Type {
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
            unit_node: None,
            base_unit: None,
            time_units: true,
            node_types: HashMap::new(),
            origin: 0,
            origins: Vec::new(),
            scopes: Vec::new(),
            states: Vec::new(),
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
        self.origins.push(self.origin);
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
        for (name, value) in overrides {
            // Parameters: top-level defs whose value is a constant literal.
            let known: Vec<String> = names
                .iter()
                .filter_map(|(n, b)| match b {
                    Binding::Def(e)
                        if e.def.params.is_none()
                            && !n.contains('.')
                            && const_type_of(&e.def).is_some() =>
                    {
                        Some(n.clone())
                    }
                    _ => None,
                })
                .collect();
            let Some(Binding::Def(entry)) = names.get(name).cloned() else {
                let mut k = known.clone();
                k.sort();
                self.diags.push(
                    Diagnostic::error(
                        Category::Name,
                        None,
                        format!("--set {name}: the spec has no top-level constant `{name}`"),
                    )
                    .with_help(format!("known constants: {}", k.join(", "))),
                );
                continue;
            };
            let mut map = SourceMap::new();
            let fid = map.add("--set", None, format!("def {name} = {value}\n"));
            let (file, diags) = tessla_syntax::parse(&map.get(fid).text, fid);
            let new_def = match (diags.is_empty(), file.statements.first()) {
                (true, Some(Statement::Def(d))) => {
                    let mut d = d.clone();
                    // `--set delta=-0.5` means the Float -0.5 (in a spec it is written `-.0.5`).
                    if let Body::Expr { expr, .. } = &mut d.body
                        && let ExprKind::Unary { op, operand } = &mut expr.kind
                        && *op == UnaryOp::Neg
                        && matches!(operand.kind, ExprKind::Float(_))
                    {
                        *op = UnaryOp::FNeg;
                    }
                    d
                }
                _ => {
                    self.diags.push(Diagnostic::error(
                        Category::Syntax,
                        None,
                        format!("--set {name}={value}: not an expression"),
                    ));
                    continue;
                }
            };
            // Type check: the new value must be a constant of the old value's type.
            let old_ty = const_type_of(&entry.def);
            let new_ty = const_type_of(&new_def);
            if old_ty != new_ty || new_ty.is_none() {
                self.diags.push(Diagnostic::error(
                    Category::Type,
                    Some(entry.def.name.span),
                    format!("--set {name}={value}: expected a constant of type {old_ty:?}, found {new_ty:?}"),
                ));
                continue;
            }
            let mut d = (*entry.def).clone();
            d.body = new_def.body;
            names.insert(
                name.clone(),
                Binding::Def(Entry {
                    def: Rc::new(d),
                    env_cell: entry.env_cell.clone(),
                    state: self.new_state(),
                }),
            );
        }
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
            self.origin = crate::snapshot::text_hash(&o.source_text);
            if let Ok(t) = self.expr(&o.expr, &env) {
                let ty = match &t {
                    Term::Const(v) => value_type(v),
                    Term::Stream(n) => self.stream_type(*n),
                    _ => Type::Unknown,
                };
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
                    outputs.push(OutputInfo {
                        name: name.clone(),
                        ty: self.stream_type(n),
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
            Err(d) => {
                self.diags.push(d);
                return Err(self.diags);
            }
        };
        let (last_slot, n_last_slots) = schedule::last_slots(&self.nodes, &order);
        Ok((
            Program {
                last_slot,
                n_last_slots,
                inputs: self.inputs,
                outputs,
                global_annotations: Vec::new(),
                delays: order
                    .iter()
                    .copied()
                    .filter(|i| matches!(self.nodes.get(*i), Some(Node::Delay { .. })))
                    .collect(),
                nodes: self.nodes,
                node_origins: self.origins,
                order,
                output_nodes,
            },
            self.diags,
        ))
    }

    /// Replace the signal lift just made for `t` by a node the evaluator runs inline (a typed
    /// fast path: no closure call, no argument copies).
    fn inline_op(&mut self, t: &Term, make: impl FnOnce(&[SArg], &Func) -> Option<Node>) {
        if let Term::Stream(n) = t
            && let Some(Node::SLift { args, f }) = self.nodes.get(*n)
            && let Some(node) = make(args, f)
            && let Some(slot) = self.nodes.get_mut(*n)
        {
            *slot = node;
        }
    }

    fn slift_node(&mut self, args: Vec<SArg>, f: Func) -> NodeId {
        self.node(Node::SLift { args, f })
    }

    /// Record the element type of a stream term (when known and not recorded yet).
    fn typed(&mut self, t: Term, ty: Type) -> Term {
        if let Term::Stream(n) = t
            && ty != Type::Unknown
        {
            self.node_types.entry(n).or_insert(ty);
        }
        t
    }

    fn stream_type(&self, n: NodeId) -> Type {
        self.stream_type_within(n, &mut 64)
    }

    /// The element type of a node, visiting at most `budget` nodes (streams may be recursive
    /// through `last`, and merges branch).
    fn stream_type_within(&self, n: NodeId, budget: &mut u32) -> Type {
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
            Term::Dyn(_) => self.error(
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

    fn def_term(&mut self, e: &Entry, span: Span) -> R<Term> {
        if e.def.params.is_some() {
            let env = e.env_cell.borrow().clone().unwrap_or_default();
            return Ok(Term::Func(Rc::new(FuncTerm::User {
                def: e.def.clone(),
                env,
            })));
        }
        let st = std::mem::replace(&mut *e.state.borrow_mut(), DefState::Todo);
        match st {
            DefState::Done(t) => {
                *e.state.borrow_mut() = DefState::Done(t.clone());
                Ok(t)
            }
            DefState::Failed => {
                *e.state.borrow_mut() = DefState::Failed;
                Err(Fail)
            }
            DefState::InProgress { alias } => {
                if self.lazy_depth == 0 {
                    *e.state.borrow_mut() = DefState::InProgress { alias };
                    self.diags.push(
                        Diagnostic::error(Category::Recursion, Some(span), format!("`{}` is defined in terms of itself", e.def.name.name))
                            .with_help("recursion is allowed only through the first argument of `last` or `delay`"),
                    );
                    return Err(Fail);
                }
                let a = match alias {
                    Some(a) => a,
                    None => self.node(Node::Alias(usize::MAX)),
                };
                *e.state.borrow_mut() = DefState::InProgress { alias: Some(a) };
                Ok(Term::Stream(a))
            }
            DefState::Todo => {
                *e.state.borrow_mut() = DefState::InProgress { alias: None };
                let env = e.env_cell.borrow().clone().unwrap_or_default();
                let saved = self.lazy_depth;
                self.lazy_depth = 0;
                let saved_origin = self.origin;
                self.origin = crate::snapshot::text_hash(self.sources.text(e.def.span));
                let r = self.body(&e.def, &env);
                self.origin = saved_origin;
                let r = match (r, &e.def.result_type) {
                    (Ok(t), Some(declared)) => {
                        let ty = match ir_type(declared) {
                            Type::Events(t) => *t,
                            t => t,
                        };
                        Ok(self.typed(t, ty))
                    }
                    (r, _) => r,
                };
                self.lazy_depth = saved;
                let alias = match &*e.state.borrow() {
                    DefState::InProgress { alias } => *alias,
                    _ => None,
                };
                match r {
                    Ok(t) => {
                        if let Some(a) = alias {
                            match &t {
                                Term::Stream(n) => self.nodes[a] = Node::Alias(*n),
                                Term::Const(v) => self.nodes[a] = Node::Const(v.clone()),
                                _ => {
                                    *e.state.borrow_mut() = DefState::Todo;
                                    return self.error(
                                        Category::Recursion,
                                        span,
                                        "only streams may be defined recursively",
                                    );
                                }
                            }
                        }
                        *e.state.borrow_mut() = DefState::Done(t.clone());
                        Ok(t)
                    }
                    Err(Fail) => {
                        if let Some(a) = alias {
                            self.nodes[a] = Node::Nil;
                        }
                        *e.state.borrow_mut() = DefState::Failed;
                        Err(Fail)
                    }
                }
            }
        }
    }

    fn body(&mut self, d: &Def, env: &Env) -> R<Term> {
        match &d.body {
            Body::Extern { span, .. } if d.result_type.is_none() => self.error(
                Category::Type,
                *span,
                format!(
                    "extern definition `{}` needs a type annotation",
                    d.name.name
                ),
            ),
            Body::Extern { name, .. } => match builtins::extern_native(name) {
                Some(f) => Ok(Term::Func(Rc::new(FuncTerm::Native(f)))),
                // As in TeSSLa, an unknown extern is an error when it is evaluated.
                None if d.params.is_some() => {
                    let f: natives::NativeFn = unknown_extern;
                    Ok(Term::Func(Rc::new(FuncTerm::Native(f))))
                }
                None => {
                    let msg: Arc<str> = format!("unknown extern `{name}`").into();
                    Ok(Term::Const(Value::Error(RuntimeError::Other(msg))))
                }
            },
            Body::Expr { expr, where_defs } => {
                if where_defs.is_empty() {
                    self.expr(expr, env)
                } else {
                    let env = self.local_defs(where_defs, env);
                    self.expr(expr, &env)
                }
            }
        }
    }

    fn local_defs(&mut self, defs: &[Def], env: &Env) -> Env {
        let cell: Rc<RefCell<Option<Env>>> = self.new_scope();
        let mut names = HashMap::new();
        for d in defs {
            names.insert(
                d.name.name.clone(),
                Binding::Def(Entry {
                    def: Rc::new(d.clone()),
                    env_cell: cell.clone(),
                    state: self.new_state(),
                }),
            );
        }
        let child = env.child(names, env.frame);
        *cell.borrow_mut() = Some(child.clone());
        child
    }

    fn lookup(&mut self, name: &str, span: Span, env: &Env) -> R<Term> {
        match env.lookup(name) {
            Some(Binding::Term(t)) => Ok(t),
            Some(Binding::Def(e)) => {
                let text = crate::snapshot::text_hash(self.sources.text(e.def.span));
                self.origin = crate::snapshot::mix(self.origin, text);
                self.def_term(&e, span)
            }
            None => {
                if name == "true" {
                    return Ok(Term::Const(Value::Bool(true)));
                }
                if name == "false" {
                    return Ok(Term::Const(Value::Bool(false)));
                }
                if name == "None" {
                    return Ok(Term::Const(Value::None));
                }
                if let Some(b) = builtins::get(name) {
                    return Ok(match b.kind {
                        Kind::Stream(StreamOp::Nil) => Term::Stream(self.node(Node::Nil)),
                        Kind::Stream(StreamOp::Unit) => Term::Stream(self.unit()),
                        Kind::Stream(op) => Term::Func(Rc::new(FuncTerm::Builtin(b, op))),
                        Kind::Constant(v) => Term::Const(v()),
                        Kind::Value(f) | Kind::Operator(f) => {
                            Term::Func(Rc::new(FuncTerm::Native(f)))
                        }
                        // Only through `extern("name")`.
                        Kind::Extern(_) => return self.unknown_name(name, span, env),
                    });
                }
                self.unknown_name(name, span, env)
            }
        }
    }

    fn unknown_name<T>(&mut self, name: &str, span: Span, env: &Env) -> R<T> {
        {
            {
                let mut known = Vec::new();
                env.all_names(&mut known);
                known.extend(builtins::names().map(str::to_string));
                let near = nearest(name, known.iter().map(String::as_str));
                let mut d =
                    Diagnostic::error(Category::Name, Some(span), format!("unknown name `{name}`"));
                if !near.is_empty() {
                    d = d.with_help(format!(
                        "did you mean {}?",
                        near.iter()
                            .map(|n| format!("`{n}`"))
                            .collect::<Vec<_>>()
                            .join(" or ")
                    ));
                }
                self.diags.push(d);
                Err(Fail)
            }
        }
    }

    fn expr(&mut self, e: &Expr, env: &Env) -> R<Term> {
        match &e.kind {
            ExprKind::Var(id) => self.lookup(&id.name, id.span, env),
            ExprKind::RootMember(id) => self.lookup(&id.name, id.span, env),
            ExprKind::Int { value, unit } => {
                let v = match unit {
                    None => *value,
                    Some(u) if !self.time_units => {
                        self.diags.push(
                            Diagnostic::error(
                                Category::Time,
                                Some(u.span),
                                format!("time unit `{}` used, but no base time is set", u.name),
                            )
                            .with_help("set the base time of the trace (`--base-time 1ms`)"),
                        );
                        return Err(Fail);
                    }
                    Some(u) => {
                        let f = unit_factor(&u.name).unwrap_or(1);
                        let fs = value.checked_mul(f).unwrap_or(i128::MAX);
                        // As TeSSLa does: the literal must be a whole number of the base
                        // time's unit; then it is divided by the base's count, truncating
                        // (100ms at 33333 µs is 3), but it must not become 0.
                        let unit_fs = self.base_unit.unwrap_or(self.base_ns);
                        if fs % unit_fs != 0 {
                            return self.error(
                                Category::Time,
                                e.span,
                                format!(
                                    "cannot convert {value} {} to the base time's unit",
                                    u.name
                                ),
                            );
                        }
                        let r = fs / unit_fs / (self.base_ns / unit_fs).max(1);
                        if r == 0 && *value != 0 {
                            return self.error(
                                Category::Time,
                                e.span,
                                format!(
                                    "cannot represent {value} {} in terms of the base time",
                                    u.name
                                ),
                            );
                        }
                        r
                    }
                };
                match i64::try_from(v) {
                    Ok(i) => Ok(Term::Const(Value::Int(i))),
                    Err(_) => self.error(
                        Category::Type,
                        e.span,
                        "integer literal does not fit in 64 bits",
                    ),
                }
            }
            ExprKind::Float(f) => Ok(Term::Const(Value::Float(*f))),
            ExprKind::Str { parts, .. } => {
                let mut terms = Vec::new();
                for p in parts {
                    match p {
                        StrPart::Text(t) => terms.push(Term::Const(Value::Str(t.as_str().into()))),
                        StrPart::Interp { expr, format } => {
                            let t = self.expr(expr, env)?;
                            let fmt = format.clone();
                            let f: Func = Arc::new(move |a: &[Value]| match (&fmt, a.first()) {
                                (Some(spec), Some(v)) => Value::Str(format_value(spec, v).into()),
                                (None, Some(v)) => Value::Str(v.to_string().into()),
                                _ => Value::Unit,
                            });
                            terms.push(self.apply_value_fn(f, vec![t], e.span)?);
                        }
                    }
                }
                if terms.len() == 1 {
                    return Ok(terms.remove(0));
                }
                let concat: Func = Arc::new(|a: &[Value]| {
                    if let Some(err) = a.iter().find_map(is_err) {
                        return err;
                    }
                    let mut s = String::new();
                    for v in a {
                        s.push_str(&v.to_string());
                    }
                    Value::Str(s.into())
                });
                self.apply_value_fn(concat, terms, e.span)
            }
            ExprKind::Tuple(es) if es.is_empty() => Ok(Term::Const(Value::Unit)),
            ExprKind::Tuple(es) => {
                let terms = es
                    .iter()
                    .map(|x| self.expr(x, env))
                    .collect::<R<Vec<_>>>()?;
                let f: Func = Arc::new(|a: &[Value]| Value::Tuple(a.to_vec().into()));
                self.apply_value_fn(f, terms, e.span)
            }
            ExprKind::Record(members) => {
                let mut sorted: Vec<_> = members.iter().collect();
                sorted.sort_by(|a, b| a.0.name.cmp(&b.0.name));
                let names: Vec<Arc<str>> = sorted
                    .iter()
                    .map(|(n, _)| Arc::from(n.name.as_str()))
                    .collect();
                let terms = sorted
                    .iter()
                    .map(|(_, x)| self.expr(x, env))
                    .collect::<R<Vec<_>>>()?;
                let f: Func = Arc::new(move |a: &[Value]| {
                    Value::Record(
                        names
                            .iter()
                            .cloned()
                            .zip(a.iter().cloned())
                            .collect::<Vec<_>>()
                            .into(),
                    )
                });
                self.apply_value_fn(f, terms, e.span)
            }
            ExprKind::Block { defs, result } => {
                let env = self.local_defs(defs, env);
                self.expr(result, &env)
            }
            ExprKind::Member { object, field } => {
                // `Foo.Bar.x` where `Foo` is not a value in scope: a module member.
                if let Some(path) = dotted_path(object)
                    && env
                        .lookup(path.split('.').next().unwrap_or_default())
                        .is_none()
                {
                    let q = format!("{path}.{}", field.name);
                    return self.lookup(&q, e.span, env);
                }
                let obj = self.expr(object, env)?;
                let fname: Arc<str> = field.name.as_str().into();
                let f: Func = Arc::new(move |a: &[Value]| match a.first() {
                    Some(Value::Record(r)) => r
                        .iter()
                        .find(|(k, _)| *k == fname)
                        .map(|(_, v)| v.clone())
                        .unwrap_or_else(|| {
                            Value::Error(RuntimeError::Other(format!("no field {fname}").into()))
                        }),
                    Some(Value::Tuple(t)) => fname
                        .strip_prefix('_')
                        .and_then(|i| i.parse::<usize>().ok())
                        .and_then(|i| t.get(i.wrapping_sub(1)))
                        .cloned()
                        .unwrap_or_else(|| {
                            Value::Error(RuntimeError::Other(format!("no member {fname}").into()))
                        }),
                    Some(err @ Value::Error(_)) => err.clone(),
                    other => Value::Error(RuntimeError::Other(
                        format!("no member {fname} in {other:?}").into(),
                    )),
                });
                self.apply_value_fn(f, vec![obj], e.span)
            }
            ExprKind::Unary { op, operand } => {
                let t = self.expr(operand, env)?;
                let op = *op;
                let ty = match op {
                    UnaryOp::Not => Type::Bool,
                    UnaryOp::FNeg => Type::Float,
                    UnaryOp::Neg | UnaryOp::BitNot => Type::Int,
                };
                let f: Func = Arc::new(move |a: &[Value]| unop(op, &a[0]));
                let r = self.apply_value_fn(f, vec![t], e.span)?;
                Ok(self.typed(r, ty))
            }
            ExprKind::Binary { op, lhs, rhs } => {
                let a = self.expr(lhs, env)?;
                let b = self.expr(rhs, env)?;
                let op = *op;
                let int_op = matches!(
                    op,
                    BinOp::Add
                        | BinOp::Sub
                        | BinOp::Mul
                        | BinOp::Div
                        | BinOp::Mod
                        | BinOp::Lt
                        | BinOp::Gt
                        | BinOp::Le
                        | BinOp::Ge
                );
                let is_float = |c: &Compiler<'_>, t: &Term| match t {
                    Term::Const(Value::Float(_)) => true,
                    Term::Stream(n) => c.stream_type(*n) == Type::Float,
                    _ => false,
                };
                if int_op && (is_float(self, &a) || is_float(self, &b)) {
                    self.diags.push(
                        Diagnostic::error(
                            Category::Type,
                            Some(e.span),
                            format!("`{}` is not defined for Float in TeSSLa 1.2", op.symbol()),
                        )
                        .with_label("a Float operand")
                        .with_help(format!("use `{}.` for Float", op.symbol())),
                    );
                    return Err(Fail);
                }
                if matches!(op, BinOp::And | BinOp::Or) {
                    // Lazy: the right side is not evaluated when the left decides.
                    if let Term::Dyn(_) | Term::Const(_) = a
                        && let Term::Dyn(_) | Term::Const(_) = b
                        && !matches!((&a, &b), (Term::Const(_), Term::Const(_)))
                    {
                        let (fa, fb) = (self.as_dyn(a), self.as_dyn(b));
                        let is_and = op == BinOp::And;
                        return Ok(Term::Dyn(Arc::new(move |fr: &[Value]| match fa(fr) {
                            Value::Bool(x) if x != is_and => Value::Bool(x),
                            Value::Bool(_) => fb(fr),
                            other => other,
                        })));
                    }
                }
                let ty = match op {
                    BinOp::FAdd | BinOp::FSub | BinOp::FMul | BinOp::FDiv => Type::Float,
                    BinOp::Add => match (&a, &b) {
                        (Term::Stream(n), _) | (_, Term::Stream(n)) => self.stream_type(*n),
                        _ => Type::Unknown,
                    },
                    BinOp::Sub
                    | BinOp::Mul
                    | BinOp::Div
                    | BinOp::Mod
                    | BinOp::Shl
                    | BinOp::Shr
                    | BinOp::BitAnd
                    | BinOp::BitOr
                    | BinOp::BitXor => Type::Int,
                    _ => Type::Bool,
                };
                let r = self.apply_value_fn(binop_fn(op), vec![a, b], e.span)?;
                if let Some(sop) = scalar_op(op) {
                    self.inline_op(&r, |args, f| match args {
                        [a, b] => Some(Node::Bin {
                            op: sop,
                            a: a.clone(),
                            b: b.clone(),
                            f: f.clone(),
                        }),
                        _ => None,
                    });
                }
                Ok(self.typed(r, ty))
            }
            ExprKind::If {
                cond,
                then_branch,
                else_branch,
                ..
            } => {
                let c = self.expr(cond, env)?;
                if let Term::Const(v) = &c {
                    return match v {
                        Value::Bool(true) => self.expr(then_branch, env),
                        Value::Bool(false) => self.expr(else_branch, env),
                        _ => self.error(
                            Category::Type,
                            cond.span,
                            "the condition of `if` must be a Bool",
                        ),
                    };
                }
                let t = self.expr(then_branch, env)?;
                let f = self.expr(else_branch, env)?;
                if let Term::Dyn(_) = c
                    && !matches!(t, Term::Stream(_) | Term::Func(_))
                    && !matches!(f, Term::Stream(_) | Term::Func(_))
                {
                    let (fc, ft, ff) = (self.as_dyn(c), self.as_dyn(t), self.as_dyn(f));
                    return Ok(Term::Dyn(Arc::new(move |fr: &[Value]| match fc(fr) {
                        Value::Bool(true) => ft(fr),
                        Value::Bool(false) => ff(fr),
                        other => other,
                    })));
                }
                let ite: Func = Arc::new(|v: &[Value]| match &v[0] {
                    Value::Bool(true) => v[1].clone(),
                    Value::Bool(false) => v[2].clone(),
                    other => other.clone(),
                });
                let ty = match (&t, &f) {
                    (Term::Stream(n), _) | (_, Term::Stream(n)) => self.stream_type(*n),
                    (Term::Const(v), _) => value_type(v),
                    _ => Type::Unknown,
                };
                let r = self.apply_value_fn(ite, vec![c, t, f], e.span)?;
                self.inline_op(&r, |args, _| match args {
                    [c, t, f] => Some(Node::Ite {
                        cond: c.clone(),
                        then: t.clone(),
                        other: f.clone(),
                    }),
                    _ => None,
                });
                Ok(self.typed(r, ty))
            }
            ExprKind::Lambda { params, body } => Ok(Term::Func(Rc::new(FuncTerm::Lambda {
                params: params.clone(),
                body: Rc::new((**body).clone()),
                env: env.clone(),
            }))),
            ExprKind::Call { function, args, .. } => {
                let f = self.expr(function, env)?;
                let Some(args) = args else {
                    return Ok(f);
                };
                // `last` and `delay`: the first argument is lazy (may refer back recursively).
                let lazy_first = matches!(&f, Term::Func(ft) if matches!(&**ft, FuncTerm::Builtin(b, _) if b.lazy == [0]));
                let mut terms = Vec::with_capacity(args.len());
                for (i, a) in args.iter().enumerate() {
                    if lazy_first && i == 0 {
                        self.lazy_depth += 1;
                        let r = self.expr(&a.value, env);
                        self.lazy_depth -= 1;
                        terms.push(r?);
                    } else {
                        terms.push(self.expr(&a.value, env)?);
                    }
                }
                let terms = self.order_named_args(&f, args, terms, e.span)?;
                self.call(f, terms, e.span, env)
            }
        }
    }

    /// Put named arguments (`f(b = 1, a = x)`) in the order of the function's parameters.
    fn order_named_args(
        &mut self,
        f: &Term,
        args: &[ast::Arg],
        terms: Vec<Term>,
        span: Span,
    ) -> R<Vec<Term>> {
        if args.iter().all(|a| a.name.is_none()) {
            return Ok(terms);
        }
        let params: Vec<String> = match f {
            Term::Func(ft) => match &**ft {
                FuncTerm::User { def, .. } => def
                    .params
                    .iter()
                    .flatten()
                    .map(|p| p.name.name.clone())
                    .collect(),
                FuncTerm::Lambda { params, .. } => {
                    params.iter().map(|p| p.name.name.clone()).collect()
                }
                _ => {
                    return self.error(
                        Category::Unsupported,
                        span,
                        "named arguments need a function with named parameters",
                    );
                }
            },
            _ => return self.error(Category::Type, span, "named arguments need a function"),
        };
        let mut slots: Vec<Option<Term>> = vec![None; params.len()];
        let mut next = 0;
        for (a, t) in args.iter().zip(terms) {
            let idx = match &a.name {
                Some(n) => match params.iter().position(|p| *p == n.name) {
                    Some(i) => i,
                    None => {
                        let near = nearest(&n.name, params.iter().map(String::as_str)).join(", ");
                        self.diags.push(
                            Diagnostic::error(
                                Category::Name,
                                Some(n.span),
                                format!("no parameter named `{}`", n.name),
                            )
                            .with_help(format!(
                                "parameters: {}",
                                if near.is_empty() {
                                    params.join(", ")
                                } else {
                                    near
                                }
                            )),
                        );
                        return Err(Fail);
                    }
                },
                None => {
                    while next < slots.len() && slots[next].is_some() {
                        next += 1;
                    }
                    next
                }
            };
            match slots.get_mut(idx) {
                Some(slot @ None) => *slot = Some(t),
                _ => {
                    return self.error(
                        Category::Type,
                        span,
                        "an argument is given twice or there are too many arguments",
                    );
                }
            }
        }
        slots
            .into_iter()
            .map(|s| s.ok_or(Fail))
            .collect::<R<Vec<_>>>()
            .or_else(|_| self.error(Category::Type, span, "missing arguments"))
    }

    /// Turn a constant or frame code into frame code.
    fn as_dyn(&self, t: Term) -> Dyn {
        match t {
            Term::Dyn(d) => d,
            Term::Const(v) => Arc::new(move |_: &[Value]| v.clone()),
            _ => Arc::new(|_: &[Value]| Value::Error(RuntimeError::Other("not a value".into()))),
        }
    }

    /// Apply a strict value function to terms: fold constants, lift over streams, or build frame
    /// code inside function bodies.
    fn apply_value_fn(&mut self, f: Func, args: Vec<Term>, span: Span) -> R<Term> {
        if args.iter().all(|a| matches!(a, Term::Const(_))) {
            let vals: Vec<Value> = args
                .into_iter()
                .map(|a| match a {
                    Term::Const(v) => v,
                    _ => Value::Unit,
                })
                .collect();
            return Ok(Term::Const(f(&vals)));
        }
        let has_stream = args.iter().any(|a| matches!(a, Term::Stream(_)));
        let has_dyn = args.iter().any(|a| matches!(a, Term::Dyn(_)));
        if args.iter().any(|a| matches!(a, Term::Func(_))) {
            // Functions as arguments of value functions become closures.
            let mut conv = Vec::new();
            for a in args {
                conv.push(match a {
                    Term::Func(ft) => self.func_value(&ft, span)?,
                    other => other,
                });
            }
            return self.apply_value_fn(f, conv, span);
        }
        if has_stream && !has_dyn {
            let sargs = args
                .into_iter()
                .map(|a| match a {
                    Term::Stream(n) => SArg::Stream(n),
                    Term::Const(v) => SArg::Const(v),
                    _ => SArg::Const(Value::Unit),
                })
                .collect();
            return Ok(Term::Stream(self.slift_node(sargs, f)));
        }
        if has_stream {
            return self.error(
                Category::Unsupported,
                span,
                "mixing streams and function parameters in one expression is not supported",
            );
        }
        let ds: Vec<Dyn> = args.into_iter().map(|a| self.as_dyn(a)).collect();
        Ok(Term::Dyn(Arc::new(move |fr: &[Value]| {
            let vals: Vec<Value> = ds.iter().map(|d| d(fr)).collect();
            f(&vals)
        })))
    }

    /// A function term as a runtime value (`Value::Closure`), constant or frame code.
    fn func_value(&mut self, ft: &Rc<FuncTerm>, span: Span) -> R<Term> {
        match &**ft {
            FuncTerm::Native(n) => {
                let n = *n;
                let f: Func = Arc::new(move |a: &[Value]| call_native(n, a));
                Ok(Term::Const(Value::Closure(Arc::new(FnValue(f)))))
            }
            FuncTerm::User { def, env } => {
                let (f, _) = self.compile_fn(def, env, span)?;
                let outer = env.frame;
                if outer == 0 {
                    return Ok(Term::Const(Value::Closure(Arc::new(FnValue(f)))));
                }
                // Defined inside a function body: the closure captures the enclosing frame.
                Ok(Term::Dyn(Arc::new(move |fr: &[Value]| {
                    Value::Closure(Arc::new(RtClosure {
                        captured: fr[..outer.min(fr.len())].to_vec(),
                        body: f.clone(),
                    }))
                })))
            }
            FuncTerm::Lambda { params, body, env } => {
                let (names, frame) = self.param_frame(params, env.frame);
                let inner = env.child(names, frame);
                let code = self.expr(body, &inner)?;
                let code = self.as_dyn(code);
                let outer = env.frame;
                if outer == 0 {
                    Ok(Term::Const(Value::Closure(Arc::new(RtClosure {
                        captured: Vec::new(),
                        body: code,
                    }))))
                } else {
                    Ok(Term::Dyn(Arc::new(move |fr: &[Value]| {
                        Value::Closure(Arc::new(RtClosure {
                            captured: fr[..outer.min(fr.len())].to_vec(),
                            body: code.clone(),
                        }))
                    })))
                }
            }
            FuncTerm::Builtin(b, _) => self.error(
                Category::Unsupported,
                span,
                format!("the stream function `{}` cannot be used as a value", b.name),
            ),
        }
    }

    fn param_frame(&self, params: &[ast::Param], base: usize) -> (HashMap<String, Binding>, usize) {
        let mut names = HashMap::new();
        for (i, p) in params.iter().enumerate() {
            let slot = base + i;
            let d: Dyn = Arc::new(move |fr: &[Value]| fr.get(slot).cloned().unwrap_or(Value::Unit));
            names.insert(p.name.name.clone(), Binding::Term(Term::Dyn(d)));
        }
        (names, base + params.len())
    }

    /// Compile a named value function once into a closure (recursion through a cell). The
    /// closure takes the enclosing function's frame (`env.frame` values, none at top level)
    /// followed by the arguments. The flag is false while the function is still being compiled
    /// (a recursive call), so such calls must not be folded at compile time.
    fn compile_fn(&mut self, def: &Rc<Def>, env: &Env, span: Span) -> R<(Func, bool)> {
        let key = Rc::as_ptr(def);
        if let Some(cell) = self.compiled_fns.get(&key) {
            if let Some(f) = cell.get() {
                return Ok((f.clone(), true));
            }
            let cell = cell.clone();
            return Ok((
                Arc::new(move |a: &[Value]| match cell.get() {
                    Some(f) => f(a),
                    None => Value::Error(RuntimeError::Other("function not compiled".into())),
                }),
                false,
            ));
        }
        let cell: Arc<OnceLock<Func>> = Arc::new(OnceLock::new());
        self.compiled_fns.insert(key, cell.clone());
        let params = def.params.clone().unwrap_or_default();
        let (names, frame) = self.param_frame(&params, env.frame);
        let inner = Env {
            names: Rc::new(names),
            parent: Some(Rc::new(env.clone())),
            frame,
        };
        let Ok(body) = self.body(def, &inner) else {
            self.compiled_fns.remove(&key);
            return Err(Fail);
        };
        let f: Func = match body {
            Term::Dyn(d) => Arc::new(move |a: &[Value]| d(a)),
            Term::Const(v) => Arc::new(move |_: &[Value]| v.clone()),
            Term::Func(ft) => match &*ft {
                FuncTerm::Native(n) if matches!(def.body, Body::Extern { .. }) => {
                    let n = *n;
                    Arc::new(move |a: &[Value]| call_native(n, a))
                }
                // A function returning a function: the result is a closure value.
                _ => match self.func_value(&ft, span)? {
                    Term::Const(v) => Arc::new(move |_: &[Value]| v.clone()),
                    Term::Dyn(d) => Arc::new(move |a: &[Value]| d(a)),
                    _ => {
                        return self.error(
                            Category::Unsupported,
                            span,
                            "this function value is not supported",
                        );
                    }
                },
            },
            Term::Stream(_) => {
                return self.error(
                    Category::Type,
                    span,
                    format!(
                        "`{}` makes a stream and cannot be called on values",
                        def.name.name
                    ),
                );
            }
        };
        let _ = cell.set(f.clone());
        Ok((f, true))
    }

    fn call(&mut self, f: Term, args: Vec<Term>, span: Span, env: &Env) -> R<Term> {
        let Term::Func(ft) = f else {
            // Calling a closure value at runtime.
            if let Term::Dyn(_) | Term::Const(Value::Closure(_)) = f {
                let mut all = vec![f];
                all.extend(args);
                let call: Func = Arc::new(|a: &[Value]| match &a[0] {
                    Value::Closure(c) => c.call(&a[1..]),
                    other => Value::Error(RuntimeError::Other(
                        format!("{other:?} is not a function").into(),
                    )),
                });
                return self.apply_value_fn(call, all, span);
            }
            return self.error(Category::Type, span, "this is not a function");
        };
        match &*ft {
            FuncTerm::Builtin(b, op) => self.stream_builtin(b.name, *op, args, span),
            FuncTerm::Native(n) => {
                let n = *n;
                self.apply_value_fn(Arc::new(move |a: &[Value]| call_native(n, a)), args, span)
            }
            FuncTerm::User { def, env: denv } => {
                let params = def.params.clone().unwrap_or_default();
                if let Body::Extern { .. } = def.body {
                    let r = match self.body(def, denv)? {
                        Term::Func(inner) => self.call(Term::Func(inner), args, span, env)?,
                        other => other,
                    };
                    return Ok(self.typed_as_declared(r, def));
                }
                if params.len() != args.len() {
                    return self.error(
                        Category::Type,
                        span,
                        format!(
                            "`{}` takes {} arguments, {} given",
                            def.name.name,
                            params.len(),
                            args.len()
                        ),
                    );
                }
                let has_func = args.iter().any(|a| matches!(a, Term::Func(_)));
                let has_stream = args.iter().any(|a| matches!(a, Term::Stream(_)));
                let stream_params = def.params.as_ref().is_some_and(|ps| ps.iter().any(|p| matches!(&p.ty, Some(ast::Type::App { name, .. }) if name.name == "Events")));
                // `liftable` functions on streams are signal-lifted, not expanded.
                let lift = def.liftable && has_stream && !has_func && !stream_params;
                let mut expand = !lift && (has_func || has_stream || stream_params);
                if !expand {
                    let saved = self.diags.len();
                    match self.call_compiled(def, denv, args.clone(), span) {
                        Ok(t) => return Ok(t),
                        // A body that makes streams from its parameters (`static if`, `const`
                        // ...) cannot be a value function: expand it like a macro instead.
                        Err(Fail) if !lift => {
                            self.diags.truncate(saved);
                            expand = true;
                        }
                        Err(Fail) => return Err(Fail),
                    }
                }
                if expand {
                    self.inline_depth += 1;
                    if self.inline_depth > 200 {
                        self.inline_depth -= 1;
                        return self.error(
                            Category::Recursion,
                            span,
                            format!("`{}` expands without end (recursive macro)", def.name.name),
                        );
                    }
                    let names: HashMap<String, Binding> = params
                        .iter()
                        .zip(args)
                        .map(|(p, a)| (p.name.name.clone(), Binding::Term(a)))
                        .collect();
                    // The expansion runs in the caller's runtime frame (its arguments read it):
                    // lambdas made inside capture that frame and put parameters after it.
                    let inner = denv.child(names, env.frame.max(denv.frame));
                    let r = self.body(def, &inner);
                    self.inline_depth -= 1;
                    r
                } else {
                    self.call_compiled(def, denv, args, span)
                }
            }
            FuncTerm::Lambda {
                params,
                body,
                env: lenv,
            } => {
                if params.len() != args.len() {
                    return self.error(
                        Category::Type,
                        span,
                        format!(
                            "the function takes {} arguments, {} given",
                            params.len(),
                            args.len()
                        ),
                    );
                }
                let names: HashMap<String, Binding> = params
                    .iter()
                    .zip(args)
                    .map(|(p, a)| (p.name.name.clone(), Binding::Term(a)))
                    .collect();
                // Inlined in the caller's runtime frame (see the expansion of user functions).
                let inner = lenv.child(names, env.frame.max(lenv.frame));
                self.expr(body, &inner)
            }
        }
    }

    /// Call a user function compiled to a value function (lifted over stream arguments).
    fn call_compiled(&mut self, def: &Rc<Def>, denv: &Env, args: Vec<Term>, span: Span) -> R<Term> {
        let (f, ready) = self.compile_fn(def, denv, span)?;
        // A function defined inside a function body also gets the enclosing frame.
        let mut all: Vec<Term> = (0..denv.frame)
            .map(|slot| {
                let d: Dyn =
                    Arc::new(move |fr: &[Value]| fr.get(slot).cloned().unwrap_or(Value::Unit));
                Term::Dyn(d)
            })
            .collect();
        all.extend(args);
        if !ready && all.iter().all(|a| matches!(a, Term::Const(_))) {
            // A recursive call with constant arguments: evaluated at run time.
            let vals: Vec<Value> = all
                .into_iter()
                .filter_map(|a| match a {
                    Term::Const(v) => Some(v),
                    _ => None,
                })
                .collect();
            return Ok(Term::Dyn(Arc::new(move |_: &[Value]| f(&vals))));
        }
        let r = self.apply_value_fn(f, all, span)?;
        Ok(self.typed_as_declared(r, def))
    }

    /// Record a function's declared result type on the stream its call made.
    fn typed_as_declared(&mut self, t: Term, def: &Def) -> Term {
        match def.result_type.as_ref().map(ir_type) {
            Some(Type::Events(ty)) => self.typed(t, *ty),
            Some(ty) => self.typed(t, ty),
            None => t,
        }
    }

    fn stream_arg(&mut self, args: &[Term], i: usize, span: Span) -> R<NodeId> {
        match args.get(i) {
            Some(t) => self.stream_of(t.clone(), span),
            None => self.error(Category::Type, span, format!("missing argument {}", i + 1)),
        }
    }

    fn value_fn_arg(&mut self, args: &[Term], i: usize, span: Span) -> R<Func> {
        match args.get(i) {
            Some(Term::Func(ft)) => match self.func_value(ft, span)? {
                Term::Const(Value::Closure(c)) => Ok(Arc::new(move |a: &[Value]| c.call(a))),
                _ => self.error(
                    Category::Unsupported,
                    span,
                    "this function cannot be compiled to a value",
                ),
            },
            Some(Term::Const(Value::Closure(c))) => {
                let c = c.clone();
                Ok(Arc::new(move |a: &[Value]| c.call(a)))
            }
            _ => self.error(
                Category::Type,
                span,
                format!("argument {} must be a function", i + 1),
            ),
        }
    }

    fn const_arg(&mut self, args: &[Term], i: usize, span: Span) -> R<Value> {
        match args.get(i) {
            Some(Term::Const(v)) => Ok(v.clone()),
            _ => self.error(
                Category::Type,
                span,
                format!("argument {} must be a constant", i + 1),
            ),
        }
    }
}

/// `a.b.c` as the string "a.b.c" when the expression is only names and member accesses.
fn dotted_path(e: &Expr) -> Option<String> {
    match &e.kind {
        ExprKind::Var(id) => Some(id.name.clone()),
        ExprKind::Member { object, field } => {
            dotted_path(object).map(|p| format!("{p}.{}", field.name))
        }
        _ => None,
    }
}
