//! The type checker: Hindley–Milner style inference over the resolved spec (`resolve.rs`: the
//! flattened statements, global definitions by id, imports), run before compilation,
//! so ill-typed specs are compile errors (file, line, column, caret, fix) and not runtime values.
//!
//! Owns: the type rules of TeSSLa 1.2 as far as the engine needs them. Types are unified *modulo
//! `Events`*: a stream `Events[T]` fits wherever a `T` is expected and the other way round. That
//! is TeSSLa's implicit signal lift of operators and liftable functions over streams, its
//! conversion of constants into events at t = 0, and macro expansion of functions with stream
//! parameters, all in one rule. Everything else must match exactly: `if` conditions are Bool,
//! both branches have one type, Int operators take Ints (Float has the dotted operators), builtins
//! get arguments of their signature, user functions get arguments of their declared parameter
//! types, a def's declared type matches its body, and an output is not a function.
//!
//! TeSSLa's own rules, checked here for every definition whether an output uses it or not:
//! names resolve (unknown names are reported here), types are applied to as many type arguments
//! as they take, parameters (of defs and lambdas) have types, a recursive definition has its
//! type written somewhere on its cycle (a function: its return type), a type argument no
//! parameter type determines is given at the call, named arguments follow TeSSLa's order rule,
//! and annotations are used as declared (kind, arity, argument types, constants; defined once,
//! at the top level). Only `liftable` functions apply to streams (a stream for a value parameter
//! of another user function is a type mismatch), `liftable` needs a function of value types,
//! and a builtin without a signature of its own is typed by its declaration in the bundled
//! prelude (`sum(x: Events[Int])`), type arguments counted too.
//!
//! Soundness rule: the checker never rejects a spec TeSSLa accepts. Whatever it does not model
//! (type aliases and extern types, named arguments of builtins, record fields of a value of still
//! unknown type) gets a fresh type variable, which fits everything. Definitions are generalised (let-polymorphism) when they are done, so generic
//! functions and constants may be used at several types.

use crate::builtins::{self, Sig};
use crate::ir::Type;
use crate::resolve::{Global, Resolved, at};
use std::cell::RefCell;
use std::collections::HashMap;
use std::rc::Rc;
use std::sync::OnceLock;
use tessla_syntax::ast::{self, BinOp, Body, Def, Expr, ExprKind, Statement, StrPart, UnaryOp};
use tessla_syntax::diag::{Category, Diagnostic};
use tessla_syntax::source::Span;

/// A type during inference.
#[derive(Clone, Debug, PartialEq)]
enum Ty {
    Var(u32),
    /// `Int`, `Float`, `Bool`, `String`, `Unit`, `Option[T]`, `List[T]`, `Set[T]`, `Map[K, V]`,
    /// `Events[T]`.
    Con(&'static str, Vec<Ty>),
    Fn(Vec<Ty>, Box<Ty>),
    /// Fields sorted by name.
    Record(Vec<(String, Ty)>),
}

fn con(n: &'static str) -> Ty {
    Ty::Con(n, Vec::new())
}
fn int() -> Ty {
    con("Int")
}
fn float() -> Ty {
    con("Float")
}
fn boolean() -> Ty {
    con("Bool")
}
fn string() -> Ty {
    con("String")
}
fn unit() -> Ty {
    con("Unit")
}
fn ev(t: Ty) -> Ty {
    Ty::Con("Events", vec![t])
}
fn opt(t: Ty) -> Ty {
    Ty::Con("Option", vec![t])
}
fn list(t: Ty) -> Ty {
    Ty::Con("List", vec![t])
}
fn set(t: Ty) -> Ty {
    Ty::Con("Set", vec![t])
}
fn map(k: Ty, v: Ty) -> Ty {
    Ty::Con("Map", vec![k, v])
}
/// A tuple is the record with fields `_1` to `_n` (TeSSLa: `(a, b)` is `{_1 = a, _2 = b}`).
fn tuple(ts: Vec<Ty>) -> Ty {
    let mut fs: Vec<(String, Ty)> = ts
        .into_iter()
        .enumerate()
        .map(|(i, t)| (format!("_{}", i + 1), t))
        .collect();
    fs.sort_by(|a, b| a.0.cmp(&b.0));
    Ty::Record(fs)
}

fn func(ps: Vec<Ty>, r: Ty) -> Ty {
    Ty::Fn(ps, Box::new(r))
}

/// A generalised type: `vars` are instantiated afresh at each use.
#[derive(Clone, Debug)]
struct Scheme {
    vars: Vec<u32>,
    ty: Ty,
}

enum State {
    Todo,
    /// Being inferred: uses (recursion through `last`/`delay`) see this monomorphic type.
    InProgress(Ty),
    Done(Scheme),
}

struct DefInfo<'a> {
    def: &'a Def,
    /// The scope the def's body sees.
    scope: Rc<Scope<'a>>,
    state: RefCell<State>,
}

enum Local<'a> {
    Mono(Ty),
    Def(Rc<DefInfo<'a>>),
}

/// Names in scope: local (parameters, block and `where` defs) over the module prefix's globals.
struct Scope<'a> {
    names: RefCell<HashMap<String, Local<'a>>>,
    parent: Option<Rc<Scope<'a>>>,
    /// Module prefix (`Foo.` inside `module Foo`), for global lookups.
    prefix: String,
}

impl<'a> Scope<'a> {
    fn root(prefix: String) -> Rc<Scope<'a>> {
        Rc::new(Scope {
            names: RefCell::new(HashMap::new()),
            parent: None,
            prefix,
        })
    }
    fn child(self: &Rc<Self>) -> Rc<Scope<'a>> {
        Rc::new(Scope {
            names: RefCell::new(HashMap::new()),
            parent: Some(self.clone()),
            prefix: self.prefix.clone(),
        })
    }
}

enum Found<'a> {
    Mono(Ty),
    Def(Rc<DefInfo<'a>>),
}

/// An expression of the resolved spec, by identity: its address in the syntax tree. The
/// checker and the lowering borrow the same parsed files, which stay put while a spec loads,
/// so an id the checker records is the id the lowering looks up (no AST field needed).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ExprId(usize);

impl ExprId {
    pub fn of(e: &Expr) -> Self {
        ExprId(std::ptr::from_ref(e) as usize)
    }
}

/// The typed program the checker hands the lowering: the element type of each input (by its
/// index in [`Resolved::inputs`]), of each output (by the id of its expression; an object
/// output's members are fields of it) and of each top-level parameterless def (by dotted
/// name, for `out *`). Types the checker leaves open are [`Type::Unknown`] inside. The
/// lowering takes its types from here only: it has no type rules of its own.
#[derive(Debug, Default)]
pub struct Types {
    pub inputs: Vec<Type>,
    pub outputs: HashMap<ExprId, Type>,
    pub defs: HashMap<String, Type>,
}

impl Types {
    /// The element type of an output expression ([`Type::Unknown`]: none, or open).
    pub fn output(&self, e: &Expr) -> Type {
        self.outputs
            .get(&ExprId::of(e))
            .cloned()
            .unwrap_or(Type::Unknown)
    }
}

/// Check the statements of all files (includes first); returns the type errors found.
pub fn check(files: &[ast::File]) -> Vec<Diagnostic> {
    check_typed(files).0
}

/// Check the statements of all files; returns the type errors found and the [`Types`] table.
pub fn check_typed(files: &[ast::File]) -> (Vec<Diagnostic>, Types) {
    let resolved = Resolved::new(files);
    check_resolved(&resolved)
}

/// Check a resolved spec; returns the type errors found (the resolver's first) and the
/// [`Types`] table.
pub fn check_resolved(resolved: &Resolved<'_>) -> (Vec<Diagnostic>, Types) {
    let mut types = Types::default();
    let mut c = Checker {
        resolved: Some(resolved),
        ..Checker::default()
    };
    for d in &resolved.diagnostics {
        c.report(d.clone());
    }
    for (name, ty) in &resolved.inputs {
        let before = c.diags.len();
        let t = c.ast_type(ty, &HashMap::new());
        types.inputs.push(match c.resolve(&t) {
            Ty::Con("Events", _) => element_type(&c.resolve(&t)),
            // A type already reported (`Events[Int, Int]`) is not reported twice.
            _ if c.diags.len() > before => Type::Unknown,
            _ => {
                c.report(
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
        });
        c.inputs.push(t);
    }
    for g in &resolved.defs {
        let scope = c.module_scope(&g.prefix);
        c.globals.push(Rc::new(DefInfo {
            def: g.def,
            scope,
            state: RefCell::new(State::Todo),
        }));
    }
    for g in c.globals.clone() {
        c.def_scheme(&g);
    }
    for (_, s) in &resolved.statements {
        let (anns, global): (&[ast::Annotation], bool) = match s {
            Statement::In { annotations, .. } | Statement::OutAll { annotations, .. } => {
                (annotations, false)
            }
            Statement::Out(o) => (&o.annotations, false),
            Statement::GlobalAnnotation(a) => (std::slice::from_ref(a), true),
            _ => continue,
        };
        for a in anns {
            c.annotation(a, global);
        }
    }
    for o in &resolved.outputs {
        let scope = c.module_scope("");
        let t = c.infer(&o.expr, &scope);
        types
            .outputs
            .insert(ExprId::of(&o.expr), element_type(&c.resolve(&t)));
        // A parameterless function (`def foo() = 42`) is called.
        if let Ty::Fn(ps, _) = c.resolve(&t)
            && !ps.is_empty()
        {
            c.report(
                Diagnostic::error(
                    Category::Type,
                    Some(o.expr.span),
                    "a function cannot be an output",
                )
                .with_label("this is a function")
                .with_help("output a stream or a value, e.g. the function applied to a stream"),
            );
        }
    }
    // Def types only serve `out *`.
    for (id, d) in c.globals.iter().enumerate().filter(|_| resolved.out_all) {
        if d.def.params.is_none()
            && let State::Done(s) = &*d.state.borrow()
            && let Some(name) = resolved.name(id)
        {
            types.defs.insert(name, element_type(&c.resolve(&s.ty)));
        }
    }
    c.break_cycles();
    (std::mem::take(&mut c.diags), types)
}

/// The element type of a stream (`T` of `Events[T]`; a constant is its own) as an IR type.
fn element_type(t: &Ty) -> Type {
    match t {
        Ty::Con("Events", args) => args.first().map_or(Type::Unknown, ir_type_of),
        other => ir_type_of(other),
    }
}

/// A resolved checker type as an IR type; what the IR cannot name (`Set`, `Map`, functions,
/// open variables) is [`Type::Unknown`]. A stream inside a value type (`List[Events[Int]]`) is
/// an artifact of unifying modulo `Events` (values never hold streams): its element type.
fn ir_type_of(t: &Ty) -> Type {
    let inner = |args: &[Ty]| Box::new(args.first().map_or(Type::Unknown, element_type));
    match t {
        Ty::Con("Unit", _) => Type::Unit,
        Ty::Con("Bool", _) => Type::Bool,
        Ty::Con("Int", _) => Type::Int,
        Ty::Con("Float", _) => Type::Float,
        Ty::Con("String", _) => Type::String,
        Ty::Con("Option", args) => Type::Option(inner(args)),
        Ty::Con("List", args) => Type::List(inner(args)),
        Ty::Con("Events", args) => Type::Events(inner(args)),
        Ty::Record(fs)
            if !fs.is_empty()
                && fs
                    .iter()
                    .enumerate()
                    .all(|(i, (n, _))| n.strip_prefix('_') == Some(&(i + 1).to_string())) =>
        {
            Type::Tuple(fs.iter().map(|(_, t)| element_type(t)).collect())
        }
        Ty::Record(fs) if !fs.is_empty() => Type::Record(
            fs.iter()
                .map(|(n, t)| (n.clone(), element_type(t)))
                .collect(),
        ),
        _ => Type::Unknown,
    }
}

/// TeSSLa's rules for named arguments: every name is a parameter, and once a named argument
/// stands elsewhere than at its parameter's position, no positional argument follows. Returns
/// the parameter position of each argument. The one place of this rule: the checker applies
/// it to user functions and annotations, the lowering to the callees only it resolves
/// (builtins, natives, lambdas).
pub fn order_named(
    args: &[ast::Arg],
    params: &[&str],
    callee: &str,
) -> Result<Vec<usize>, Diagnostic> {
    let mut out = Vec::with_capacity(args.len());
    let mut positional_ok = true;
    for (i, a) in args.iter().enumerate() {
        match &a.name {
            Some(n) => {
                let Some(pos) = params.iter().position(|p| *p == n.name) else {
                    return Err(Diagnostic::error(
                        Category::Name,
                        Some(n.span),
                        format!("`{}` is no parameter of `{callee}`", n.name),
                    )
                    .with_label("no such parameter")
                    .with_help(format!("its parameters are ({})", params.join(", "))));
                };
                positional_ok &= pos == i;
                out.push(pos);
            }
            None if !positional_ok => {
                return Err(Diagnostic::error(
                    Category::Type,
                    Some(a.value.span),
                    "a positional argument after a named one",
                )
                .with_label("positional")
                .with_help("name this argument too, or put the positional arguments first"));
            }
            None => out.push(i),
        }
    }
    Ok(out)
}

/// Type names every spec may use.
const BUILTIN_TYPES: [&str; 10] = [
    "Int", "Float", "Bool", "String", "Unit", "Events", "Option", "List", "Set", "Map",
];

#[derive(Default)]
struct Checker<'a> {
    subst: Vec<Option<Ty>>,
    diags: Vec<Diagnostic>,
    /// The resolved spec: statements, global definitions, imports, inputs, declared types.
    resolved: Option<&'a Resolved<'a>>,
    /// The global definitions, by [`DefId`](crate::resolve::DefId).
    globals: Vec<Rc<DefInfo<'a>>>,
    /// The types of the inputs, by their index in [`Resolved::inputs`].
    inputs: Vec<Ty>,
    module_scopes: HashMap<String, Rc<Scope<'a>>>,
    /// Every local scope made: a scope names defs whose `scope` is that scope (or a child), so
    /// [`Checker::break_cycles`] empties them when checking ends, or each check leaks them.
    local_scopes: Vec<Rc<Scope<'a>>>,
    /// Type parameters of the defs being inferred, innermost last: a lambda or nested def may
    /// name its enclosing def's type parameters. Used only to decide whether a type name is
    /// known (the types themselves stay as before).
    enclosing_tparams: Vec<String>,
    /// The defs being inferred, innermost last, each with whether its type is written
    /// (`None`: a barrier, an unused local def checked for its own sake). See
    /// [`Checker::check_recursion`].
    inferring: Vec<Option<(usize, bool)>>,
    /// Defs found on a recursion without a written type, reported when they are inferred.
    untyped_recursive: Vec<usize>,
    /// Members of literals being inferred through [`Checker::literal_member`].
    literal_members: Vec<(usize, String)>,
}

impl<'a> Checker<'a> {
    /// Check one use of an annotation against its definition: declared with the same kind
    /// (`@` on an `in`/`out`, `@@` on its own), arity, argument types, constant arguments. An
    /// annotation declared nowhere is left to the compiler (a warning there).
    fn annotation(&mut self, a: &'a ast::Annotation, global: bool) {
        let Some(defs) = self.resolved.map(|r| &r.annotations) else {
            return;
        };
        let Some(params) = defs.get(&(a.name.name.clone(), global)).copied() else {
            if defs.contains_key(&(a.name.name.clone(), !global)) {
                let (msg, help) = if global {
                    (
                        format!(
                            "`@{0}` annotates an `in` or `out`; it cannot be used as a global `@@{0}` annotation",
                            a.name.name
                        ),
                        format!(
                            "write `@{0}(...)` before an `in` or `out`, or define `def @@{0}` for a global one",
                            a.name.name
                        ),
                    )
                } else {
                    (
                        format!(
                            "`@@{0}` is a global annotation; it cannot annotate an `in` or `out`",
                            a.name.name
                        ),
                        format!(
                            "write `@@{0}(...)` on a line of its own, or define `def @{0}` to annotate streams",
                            a.name.name
                        ),
                    )
                };
                self.report(
                    Diagnostic::error(Category::Name, Some(a.name.span), msg)
                        .with_label("the other kind of annotation")
                        .with_help(help),
                );
            }
            return;
        };
        let name = at(&a.name, global);
        let names: Vec<&str> = params.iter().map(|p| p.name.name.as_str()).collect();
        let Some(positions) = self.order_named(&a.args, &names, &name) else {
            return;
        };
        if a.args.len() != params.len() {
            self.report(
                Diagnostic::error(
                    Category::Type,
                    Some(a.span),
                    match params.len() {
                        0 => format!("`{name}` takes no arguments, {} given", a.args.len()),
                        1 => format!("`{name}` takes 1 argument, {} given", a.args.len()),
                        n => format!("`{name}` takes {n} arguments, {} given", a.args.len()),
                    },
                )
                .with_help(format!("its parameters are ({})", names.join(", "))),
            );
            return;
        }
        let root = self.module_scope("");
        for (arg, pos) in a.args.iter().zip(positions) {
            let Some(p) = params.get(pos) else { continue };
            let t = self.infer(&arg.value, &root);
            if self.is_stream(&t) {
                self.report(
                    Diagnostic::error(
                        Category::Type,
                        Some(arg.value.span),
                        "annotation arguments must be constants",
                    )
                    .with_label("this is a stream")
                    .with_help("write a literal or a constant definition"),
                );
                continue;
            }
            let want = match &p.ty {
                Some(ty) => self.ast_type(ty, &HashMap::new()),
                None => self.fresh(),
            };
            self.expect(
                &want,
                &t,
                arg.value.span,
                &format!("argument `{}` of `{name}`", p.name.name),
            );
        }
    }

    /// [`order_named`], reporting its error.
    fn order_named(
        &mut self,
        args: &[ast::Arg],
        params: &[&str],
        callee: &str,
    ) -> Option<Vec<usize>> {
        order_named(args, params, callee)
            .map_err(|d| self.report(d))
            .ok()
    }

    /// A new local scope under `parent`, registered for [`Checker::break_cycles`].
    fn child_of(&mut self, parent: &Rc<Scope<'a>>) -> Rc<Scope<'a>> {
        let s = parent.child();
        self.local_scopes.push(s.clone());
        s
    }

    /// Empty every scope, breaking the `Rc` cycles between scopes and the defs they name.
    fn break_cycles(&mut self) {
        let module_scopes = self.module_scopes.drain().map(|(_, s)| s);
        for s in self.local_scopes.drain(..).chain(module_scopes) {
            if let Ok(mut names) = s.names.try_borrow_mut() {
                names.clear();
            }
        }
        self.globals.clear();
    }

    fn module_scope(&mut self, prefix: &str) -> Rc<Scope<'a>> {
        self.module_scopes
            .entry(prefix.to_string())
            .or_insert_with(|| Scope::root(prefix.to_string()))
            .clone()
    }

    fn fresh(&mut self) -> Ty {
        self.subst.push(None);
        Ty::Var((self.subst.len() - 1) as u32)
    }

    fn report(&mut self, d: Diagnostic) {
        // One error per place, and not a flood.
        if self.diags.len() < 20 && !self.diags.iter().any(|x| x.span == d.span) {
            self.diags.push(d);
        }
    }

    /// Follow variable bindings at the top of `t`.
    fn shallow(&self, t: &Ty) -> Ty {
        let mut t = t.clone();
        while let Ty::Var(v) = t {
            match self.subst.get(v as usize).and_then(Clone::clone) {
                Some(b) => t = b,
                None => break,
            }
        }
        t
    }

    /// `t` with every bound variable replaced (bounded depth: types are small).
    fn resolve(&self, t: &Ty) -> Ty {
        self.resolve_depth(t, 0)
    }

    fn resolve_depth(&self, t: &Ty, depth: u32) -> Ty {
        let t = self.shallow(t);
        if depth > 64 {
            return t;
        }
        let r = |x: &Ty| self.resolve_depth(x, depth + 1);
        match t {
            Ty::Var(_) => t,
            Ty::Con(n, args) => Ty::Con(n, args.iter().map(r).collect()),
            Ty::Fn(ps, ret) => Ty::Fn(ps.iter().map(r).collect(), Box::new(r(&ret))),
            Ty::Record(fs) => Ty::Record(fs.iter().map(|(n, t)| (n.clone(), r(t))).collect()),
        }
    }

    fn occurs(&self, v: u32, t: &Ty) -> bool {
        match self.resolve(t) {
            Ty::Var(w) => v == w,
            Ty::Con(_, args) => args.iter().any(|a| self.occurs(v, a)),
            Ty::Fn(ps, r) => ps.iter().any(|a| self.occurs(v, a)) || self.occurs(v, &r),
            Ty::Record(fs) => fs.iter().any(|(_, a)| self.occurs(v, a)),
        }
    }

    /// Unify modulo `Events`: `Events[T]` and `T` fit each other (signal lift, constants as
    /// streams, macro expansion).
    fn unify(&mut self, a: &Ty, b: &Ty) -> Result<(), ()> {
        let (a, b) = (self.shallow(a), self.shallow(b));
        match (&a, &b) {
            (Ty::Var(x), Ty::Var(y)) if x == y => Ok(()),
            (Ty::Var(x), t) | (t, Ty::Var(x)) => {
                // A cyclic type only comes from recursion through `last`; let it pass.
                if !self.occurs(*x, t)
                    && let Some(slot) = self.subst.get_mut(*x as usize)
                {
                    *slot = Some(t.clone());
                }
                Ok(())
            }
            (Ty::Con("Events", x), Ty::Con("Events", y)) => match (x.first(), y.first()) {
                (Some(x), Some(y)) => self.unify(x, y),
                _ => Ok(()),
            },
            (Ty::Con("Events", x), t) | (t, Ty::Con("Events", x)) => match x.first() {
                Some(x) => {
                    let x = x.clone();
                    self.unify(&x, t)
                }
                None => Ok(()),
            },
            (Ty::Con(n, xs), Ty::Con(m, ys)) => {
                if n != m || xs.len() != ys.len() {
                    return Err(());
                }
                for (x, y) in xs.iter().zip(ys) {
                    self.unify(x, y)?;
                }
                Ok(())
            }
            (Ty::Record(xs), Ty::Record(ys)) if xs.len() == ys.len() => {
                for ((n, x), (m, y)) in xs.iter().zip(ys) {
                    if n != m {
                        return Err(());
                    }
                    self.unify(x, y)?;
                }
                Ok(())
            }
            (Ty::Fn(ps, r), Ty::Fn(qs, s)) if ps.len() == qs.len() => {
                for (x, y) in ps.iter().zip(qs) {
                    self.unify(x, y)?;
                }
                self.unify(r, s)
            }
            _ => Err(()),
        }
    }

    /// Unify `found` (of the expression at `span`) with `expected`; report a mismatch with a fix
    /// where one is known.
    fn expect(&mut self, expected: &Ty, found: &Ty, span: Span, what: &str) -> bool {
        if self.unify(expected, found).is_ok() {
            return true;
        }
        let (e, f) = (self.resolve(expected), self.resolve(found));
        let (es, fs) = (show(&e), show(&f));
        let mut d = Diagnostic::error(
            Category::Type,
            Some(span),
            format!("{what}: expected {es}, found {fs}"),
        )
        .with_label(format!("this is {fs}"));
        let base = |t: &Ty| match t {
            Ty::Con("Events", a) => a.first().cloned().unwrap_or(Ty::Var(0)),
            t => t.clone(),
        };
        match (base(&e), base(&f)) {
            (Ty::Con("Float", _), Ty::Con("Int", _)) => {
                d = d.with_help("write a Float literal (`1.0`) or convert with `intToFloat(...)`");
            }
            (Ty::Con("Int", _), Ty::Con("Float", _)) => {
                d = d
                    .with_help("convert with `floatToInt(...)`, or use the dotted Float operators");
            }
            (Ty::Fn(ps, _), Ty::Fn(qs, _)) if ps.len() != qs.len() => {
                d = d.with_help(format!(
                    "a function of {} arguments is expected; this one takes {} arguments",
                    ps.len(),
                    qs.len()
                ));
            }
            (Ty::Con("String", _), _) => {
                d = d.with_help("convert with `toString(...)`");
            }
            _ => {}
        }
        self.report(d);
        false
    }

    fn generalize(&self, t: &Ty) -> Scheme {
        let ty = self.resolve(t);
        let mut vars = Vec::new();
        collect_vars(&ty, &mut vars);
        Scheme { vars, ty }
    }

    fn instantiate(&mut self, s: &Scheme) -> Ty {
        if s.vars.is_empty() {
            return s.ty.clone();
        }
        let map: HashMap<u32, Ty> = s.vars.iter().map(|v| (*v, self.fresh())).collect();
        substitute(&s.ty, &map)
    }

    /// The (instantiated) type of a def, inferring it on first use.
    fn def_type(&mut self, d: &Rc<DefInfo<'a>>) -> Ty {
        let s = self.def_scheme(d);
        self.instantiate(&s)
    }

    fn def_scheme(&mut self, d: &Rc<DefInfo<'a>>) -> Scheme {
        let state = std::mem::replace(&mut *d.state.borrow_mut(), State::Todo);
        match state {
            State::Done(s) => {
                *d.state.borrow_mut() = State::Done(s.clone());
                s
            }
            State::InProgress(t) => {
                *d.state.borrow_mut() = State::InProgress(t.clone());
                self.check_recursion(d);
                Scheme {
                    vars: Vec::new(),
                    ty: t,
                }
            }
            State::Todo => {
                let me = self.fresh();
                *d.state.borrow_mut() = State::InProgress(me.clone());
                let typed =
                    d.def.result_type.is_some() || matches!(d.def.body, Body::Extern { .. });
                self.inferring.push(Some((Rc::as_ptr(d) as usize, typed)));
                let t = self.infer_def(d.def, &d.scope);
                self.inferring.pop();
                self.unify(&me, &t).ok();
                self.report_untyped_recursion(d, &t);
                let s = self.generalize(&t);
                *d.state.borrow_mut() = State::Done(s.clone());
                s
            }
        }
    }

    /// The type of a def: a function type when it has parameters.
    fn infer_def(&mut self, d: &'a Def, scope: &Rc<Scope<'a>>) -> Ty {
        let outer = self.enclosing_tparams.len();
        self.enclosing_tparams
            .extend(d.type_params.iter().map(|tp| tp.name.clone()));
        let t = self.infer_def_body(d, scope);
        self.enclosing_tparams.truncate(outer);
        t
    }

    fn infer_def_body(&mut self, d: &'a Def, scope: &Rc<Scope<'a>>) -> Ty {
        self.check_liftable(d);
        let mut tparams: HashMap<String, Ty> = HashMap::new();
        for tp in &d.type_params {
            let v = self.fresh();
            tparams.insert(tp.name.clone(), v);
        }
        let inner = self.child_of(scope);
        let mut ptys = Vec::new();
        if let Some(ps) = &d.params {
            for p in ps {
                let t = match &p.ty {
                    Some(t) => self.ast_type(t, &tparams),
                    None => self.missing_parameter_type(p, Some(&d.name.name)),
                };
                inner
                    .names
                    .borrow_mut()
                    .insert(p.name.name.clone(), Local::Mono(t.clone()));
                ptys.push(t);
            }
        }
        let declared = d.result_type.as_ref().map(|t| self.ast_type(t, &tparams));
        let body = match &d.body {
            Body::Extern { .. } => declared.clone().unwrap_or_else(|| self.fresh()),
            Body::Expr { expr, where_defs } => {
                let scope = if where_defs.is_empty() {
                    inner
                } else {
                    self.local_defs(where_defs, &inner)
                };
                let t = self.infer(expr, &scope);
                self.check_unused(where_defs, &scope);
                if let Some(dt) = &declared {
                    self.expect(
                        dt,
                        &t,
                        expr.span,
                        &format!(
                            "the body of `{}` does not have its declared type",
                            d.name.name
                        ),
                    );
                }
                t
            }
        };
        let ret = declared.unwrap_or(body);
        if d.params.is_some() {
            func(ptys, ret)
        } else {
            ret
        }
    }

    /// TeSSLa's rule: a parameter has a type, in a `def` as in a lambda. Reports and returns a
    /// fresh type so that checking goes on.
    fn missing_parameter_type(&mut self, p: &ast::Param, function: Option<&str>) -> Ty {
        let n = &p.name.name;
        let msg = match function {
            Some(f) => format!("parameter `{n}` of `{f}` has no type"),
            None => format!("the lambda's parameter `{n}` has no type"),
        };
        self.report(
            Diagnostic::error(Category::Type, Some(p.name.span), msg)
                .with_label("type missing")
                .with_help(format!(
                    "TeSSLa needs the type of every parameter: write `{n}: Int` (or `{n}: Events[Int]` for a stream)"
                )),
        );
        self.fresh()
    }

    /// A def met again while its own type is inferred: TeSSLa infers types in dependency
    /// order and needs a written type somewhere on every cycle. The cycle is the defs being
    /// inferred from `d` up; one with a type (return type for a function) breaks it, and so
    /// does a def checked although unused (a barrier: nothing on the cycle refers to it).
    fn check_recursion(&mut self, d: &Rc<DefInfo<'a>>) {
        let me = Rc::as_ptr(d) as usize;
        for entry in self.inferring.iter().rev() {
            match entry {
                // Checked although unused, or a def with a type: no cycle without types.
                None | Some((_, true)) => return,
                Some((ptr, false)) if *ptr == me => break,
                Some(_) => {}
            }
        }
        if !self.inferring.contains(&Some((me, false))) {
            return;
        }
        if !self.untyped_recursive.contains(&me) {
            self.untyped_recursive.push(me);
        }
    }

    /// Report a def found by [`Checker::check_recursion`], once its type is inferred, with
    /// that type in the fix.
    fn report_untyped_recursion(&mut self, d: &Rc<DefInfo<'a>>, t: &Ty) {
        let me = Rc::as_ptr(d) as usize;
        let Some(k) = self.untyped_recursive.iter().position(|p| *p == me) else {
            return;
        };
        self.untyped_recursive.swap_remove(k);
        let n = &d.def.name.name;
        let written = |t: &Ty| {
            let mut vars = Vec::new();
            collect_vars(t, &mut vars);
            if vars.is_empty() {
                show(t)
            } else {
                "T".to_string()
            }
        };
        let help = match (&d.def.params, self.resolve(t)) {
            (Some(_), Ty::Fn(_, r)) => format!(
                "TeSSLa needs a written type on every recursion: `def {n}(...): {} = ...`",
                written(&r)
            ),
            (Some(_), _) => {
                format!("TeSSLa needs a written type on every recursion: `def {n}(...): T = ...`")
            }
            (None, t) => format!(
                "TeSSLa needs a written type on every recursion: `def {n}: {} = ...`",
                written(&t)
            ),
        };
        self.report(
            Diagnostic::error(
                Category::Recursion,
                Some(d.def.name.span),
                format!("`{n}` is defined recursively and needs a type"),
            )
            .with_label("recursive definition without a type")
            .with_help(help),
        );
    }

    /// Type-check the local defs that nothing used (TeSSLa checks every definition).
    fn check_unused(&mut self, defs: &'a [Def], scope: &Rc<Scope<'a>>) {
        for d in defs {
            let info = match scope.names.borrow().get(&d.name.name) {
                Some(Local::Def(info)) if matches!(*info.state.borrow(), State::Todo) => {
                    info.clone()
                }
                _ => continue,
            };
            self.inferring.push(None);
            self.def_scheme(&info);
            self.inferring.pop();
        }
    }

    fn local_defs(&mut self, defs: &'a [Def], scope: &Rc<Scope<'a>>) -> Rc<Scope<'a>> {
        let s = self.child_of(scope);
        for d in defs {
            s.names.borrow_mut().insert(
                d.name.name.clone(),
                Local::Def(Rc::new(DefInfo {
                    def: d,
                    scope: s.clone(),
                    state: RefCell::new(State::Todo),
                })),
            );
        }
        s
    }

    fn find(&self, name: &str, scope: &Rc<Scope<'a>>) -> Option<Found<'a>> {
        let mut s = Some(scope.clone());
        while let Some(sc) = s {
            match sc.names.borrow().get(name) {
                Some(Local::Mono(t)) => return Some(Found::Mono(t.clone())),
                Some(Local::Def(d)) => return Some(Found::Def(d.clone())),
                None => {}
            }
            s = sc.parent.clone();
        }
        self.find_global(name, &scope.prefix)
    }

    /// A global by name as seen from module `prefix` ([`Resolved::global`]'s rule).
    fn find_global(&self, name: &str, prefix: &str) -> Option<Found<'a>> {
        match self.resolved?.global(name, prefix)? {
            Global::Def(id) => self.globals.get(id).map(|d| Found::Def(d.clone())),
            Global::Input(i) => self.inputs.get(i).map(|t| Found::Mono(t.clone())),
        }
    }

    fn lookup(&mut self, id: &ast::Ident, scope: &Rc<Scope<'a>>) -> Ty {
        let name = id.name.as_str();
        match self.find(name, scope) {
            Some(Found::Mono(t)) => t,
            Some(Found::Def(d)) => self.def_type(&d),
            None if !is_builtin_name(name) => {
                self.unknown_name(id, scope);
                self.fresh()
            }
            None => self.builtin(name).unwrap_or_else(|| self.fresh()),
        }
    }

    /// Report a name that is neither in scope, nor a builtin, nor in the prelude.
    fn unknown_name(&mut self, id: &ast::Ident, scope: &Rc<Scope<'a>>) {
        let mut known: Vec<String> = Vec::new();
        let mut s = Some(scope.clone());
        while let Some(sc) = s {
            known.extend(sc.names.borrow().keys().cloned());
            s = sc.parent.clone();
        }
        if let Some(r) = self.resolved {
            known.extend(r.visible_names(&scope.prefix).map(str::to_string));
        }
        known.extend(builtins::names().map(str::to_string));
        known.extend(crate::prelude::names());
        self.report(tessla_syntax::diag::unknown_name(
            &id.name,
            id.span,
            known.iter().map(String::as_str),
        ));
    }

    /// Report a type name that is neither built in, a type parameter in scope, nor declared
    /// with `type` (a typo such as `Events[Integer]`). Dotted names (`M.T`) are not checked.
    fn check_type_name(&mut self, id: &ast::Ident, tparams: &HashMap<String, Ty>) {
        let n = id.name.as_str();
        if n.contains('.')
            || BUILTIN_TYPES.contains(&n)
            || tparams.contains_key(n)
            || self.enclosing_tparams.iter().any(|tp| tp == n)
            || self.declared_type(n).is_some()
        {
            return;
        }
        let known: Vec<&str> = BUILTIN_TYPES
            .iter()
            .copied()
            .chain(
                self.resolved
                    .iter()
                    .flat_map(|r| r.declared_types.keys().map(String::as_str)),
            )
            .chain(tparams.keys().map(String::as_str))
            .collect();
        let mut near = tessla_syntax::diag::nearest(n, known.iter().copied());
        if near.is_empty() {
            // `Integer` for `Int`, `Boolean` for `Bool`: a known name that starts the unknown one.
            let lower = n.to_lowercase();
            near = known
                .iter()
                .copied()
                .filter(|k| k.len() >= 3 && lower.starts_with(&k.to_lowercase()))
                .take(3)
                .collect();
        }
        let help = if near.is_empty() {
            "declare it with `type` or use a built-in type (Int, Float, Bool, String, Unit, Option, List, Set, Map)".to_string()
        } else {
            format!(
                "did you mean {}?",
                near.iter()
                    .map(|k| format!("`{k}`"))
                    .collect::<Vec<_>>()
                    .join(" or ")
            )
        };
        let d = Diagnostic::error(Category::Type, Some(id.span), format!("unknown type `{n}`"))
            .with_label("not a known type")
            .with_help(help);
        self.report(d);
    }

    /// The number of type parameters of the type `n` declared with `type`.
    fn declared_type(&self, n: &str) -> Option<usize> {
        self.resolved?.declared_types.get(n).copied()
    }

    /// The number of type arguments the type named `n` takes (`None`: not known here, e.g. a
    /// dotted name or an unknown type, which [`Checker::check_type_name`] reports).
    fn type_arity(&self, n: &str, tparams: &HashMap<String, Ty>) -> Option<usize> {
        if tparams.contains_key(n) || self.enclosing_tparams.iter().any(|tp| tp == n) {
            return Some(0);
        }
        match n {
            "Int" | "Float" | "Bool" | "String" | "Unit" => Some(0),
            "Events" | "Option" | "List" | "Set" => Some(1),
            "Map" => Some(2),
            _ => self.declared_type(n),
        }
    }

    /// Report a type applied to the wrong number of type arguments (TeSSLa: `Map[String]`,
    /// `Int[Bool]`, `Events[Int, Int]`, a bare `Events`); true when it is reported.
    fn check_type_arity(
        &mut self,
        id: &ast::Ident,
        given: usize,
        tparams: &HashMap<String, Ty>,
    ) -> bool {
        let Some(want) = self.type_arity(&id.name, tparams) else {
            return false;
        };
        if want == given {
            return false;
        }
        let n = &id.name;
        let msg = match (want, given) {
            (0, _) => format!("`{n}` takes no type arguments, {given} given"),
            (1, 0) => format!("`{n}` takes a type argument: `{n}[T]`"),
            _ => format!(
                "`{n}` takes {want} type argument{}, {given} given",
                if want == 1 { "" } else { "s" }
            ),
        };
        let help = match n.as_str() {
            "Map" => "write `Map[K, V]`, the type of the keys and of the values".to_string(),
            _ if want == 0 => format!("write `{n}` alone"),
            _ => format!("write `{n}[{}]`", vec!["T"; want].join(", ")),
        };
        self.report(
            Diagnostic::error(Category::Type, Some(id.span), msg)
                .with_label("wrong number of type arguments")
                .with_help(help),
        );
        true
    }

    fn ast_type(&mut self, t: &ast::Type, tparams: &HashMap<String, Ty>) -> Ty {
        if let ast::Type::Name(id) = t
            && self.check_type_arity(id, 0, tparams)
        {
            return self.fresh();
        }
        match t {
            ast::Type::Name(id) => match id.name.as_str() {
                "Int" => int(),
                "Float" => float(),
                "Bool" => boolean(),
                "String" => string(),
                "Unit" => unit(),
                n => match tparams.get(n) {
                    Some(t) => t.clone(),
                    None => {
                        self.check_type_name(id, tparams);
                        self.fresh()
                    }
                },
            },
            ast::Type::App { name, args, .. } => {
                let mut a: Vec<Ty> = args.iter().map(|x| self.ast_type(x, tparams)).collect();
                if self.check_type_arity(name, a.len(), tparams) {
                    return self.fresh();
                }
                match (name.name.as_str(), a.len()) {
                    ("Events", 1) => ev(a.remove(0)),
                    ("Option", 1) => opt(a.remove(0)),
                    ("List", 1) => list(a.remove(0)),
                    ("Set", 1) => set(a.remove(0)),
                    ("Map", 2) => {
                        let k = a.remove(0);
                        map(k, a.remove(0))
                    }
                    _ => {
                        self.check_type_name(name, tparams);
                        self.fresh()
                    }
                }
            }
            ast::Type::Function { params, result, .. } => {
                let ps = params
                    .iter()
                    .map(|(_, p)| self.ast_type(p, tparams))
                    .collect();
                let r = self.ast_type(result, tparams);
                func(ps, r)
            }
            ast::Type::Record { fields, .. } if fields.is_empty() => unit(),
            ast::Type::Record { fields, .. } => {
                let mut fs: Vec<(String, Ty)> = fields
                    .iter()
                    .map(|(n, t)| (n.name.clone(), self.ast_type(t, tparams)))
                    .collect();
                fs.sort_by(|a, b| a.0.cmp(&b.0));
                Ty::Record(fs)
            }
            ast::Type::Tuple { elems, .. } if elems.is_empty() => unit(),
            ast::Type::Tuple { elems, .. } => {
                tuple(elems.iter().map(|x| self.ast_type(x, tparams)).collect())
            }
        }
    }

    /// Is `t` (resolved) a stream?
    fn is_stream(&self, t: &Ty) -> bool {
        matches!(self.shallow(t), Ty::Con("Events", _))
    }

    /// The result of an operator or lifted function: a stream if any argument is one.
    fn lifted(&self, args: &[Ty], r: Ty) -> Ty {
        if args.iter().any(|a| self.is_stream(a)) && !self.is_stream(&r) {
            ev(r)
        } else {
            r
        }
    }

    /// The type of an expression. Definitions are inferred where they are first used, so a
    /// long chain of definitions recurses deeply: the stack grows on the heap instead of
    /// overflowing.
    fn infer(&mut self, e: &'a Expr, scope: &Rc<Scope<'a>>) -> Ty {
        stacker::maybe_grow(128 * 1024, 4 * 1024 * 1024, || self.infer_here(e, scope))
    }

    fn infer_here(&mut self, e: &'a Expr, scope: &Rc<Scope<'a>>) -> Ty {
        match &e.kind {
            ExprKind::Var(id) => match id.name.as_str() {
                n @ ("true" | "false" | "None" | "unit" | "nil")
                    if self.find(n, scope).is_none() =>
                {
                    match n {
                        "None" => {
                            let a = self.fresh();
                            opt(a)
                        }
                        "unit" => ev(unit()),
                        "nil" => {
                            let a = self.fresh();
                            ev(a)
                        }
                        _ => boolean(),
                    }
                }
                _ => self.lookup(id, scope),
            },
            ExprKind::RootMember(id) => match self.find_global(&id.name, "") {
                Some(Found::Mono(t)) => t,
                Some(Found::Def(d)) => self.def_type(&d),
                None => self.fresh(),
            },
            ExprKind::Int { .. } => int(),
            ExprKind::Float(_) => float(),
            ExprKind::Str { parts, .. } => {
                let mut ts = Vec::new();
                for p in parts {
                    if let StrPart::Interp { expr, .. } = p {
                        ts.push(self.infer(expr, scope));
                    }
                }
                self.lifted(&ts, string())
            }
            ExprKind::Tuple(es) if es.is_empty() => unit(),
            ExprKind::Tuple(es) => {
                let ts: Vec<Ty> = es.iter().map(|x| self.infer(x, scope)).collect();
                let r = tuple(ts.iter().map(|t| self.strip(t)).collect());
                self.lifted(&ts, r)
            }
            ExprKind::Record(members) if members.is_empty() => unit(),
            ExprKind::Record(members) => {
                let mut fs: Vec<(String, Ty)> = Vec::new();
                let mut ts = Vec::new();
                for (n, x) in members {
                    let t = self.infer(x, scope);
                    fs.push((n.name.clone(), self.strip(&t)));
                    ts.push(t);
                }
                fs.sort_by(|a, b| a.0.cmp(&b.0));
                fs.dedup_by(|a, b| a.0 == b.0);
                self.lifted(&ts, Ty::Record(fs))
            }
            ExprKind::Block { defs, result } => {
                let s = self.local_defs(defs, scope);
                let t = self.infer(result, &s);
                self.check_unused(defs, &s);
                t
            }
            ExprKind::Member { object, field } => {
                if let Some(path) = object.dotted_path() {
                    let head = path.split('.').next().unwrap_or_default();
                    if self.find(head, scope).is_none() {
                        let q = format!("{path}.{}", field.name);
                        return match self.find(&q, scope) {
                            Some(Found::Mono(t)) => t,
                            Some(Found::Def(d)) => self.def_type(&d),
                            None if !is_builtin_name(&q)
                                && self
                                    .resolved
                                    .is_some_and(|r| r.is_module(head, &scope.prefix)) =>
                            {
                                let id = ast::Ident {
                                    name: q,
                                    span: e.span,
                                };
                                self.unknown_name(&id, scope);
                                self.fresh()
                            }
                            None => self.builtin(&q).unwrap_or_else(|| self.fresh()),
                        };
                    }
                }
                if let Some(t) = self.literal_member(object, field, scope) {
                    return t;
                }
                let o = self.infer(object, scope);
                let base = self.resolve(&self.strip(&o));
                let r = match &base {
                    Ty::Record(fs) => match fs.iter().find(|(n, _)| *n == field.name) {
                        Some((_, t)) => t.clone(),
                        None => {
                            let known: Vec<String> =
                                fs.iter().map(|(n, _)| format!("`{n}`")).collect();
                            self.report(
                                Diagnostic::error(
                                    Category::Type,
                                    Some(field.span),
                                    format!("{} has no field `{}`", show(&base), field.name),
                                )
                                .with_help(format!("its fields are {}", known.join(", "))),
                            );
                            self.fresh()
                        }
                    },
                    other @ (Ty::Con(..) | Ty::Fn(..)) => {
                        self.report(
                            Diagnostic::error(
                                Category::Type,
                                Some(field.span),
                                format!("{} has no field `{}`", show(other), field.name),
                            )
                            .with_label("no such field")
                            .with_help("only records and tuples have fields"),
                        );
                        self.fresh()
                    }
                    _ => self.fresh(),
                };
                self.lifted(&[o], r)
            }
            ExprKind::Unary { op, operand } => {
                let t = self.infer(operand, scope);
                let (want, what) = match op {
                    UnaryOp::Not => (boolean(), "`!` needs a Bool"),
                    UnaryOp::FNeg => (float(), "`-.` needs a Float"),
                    UnaryOp::Neg | UnaryOp::BitNot => (int(), "this operator needs an Int"),
                };
                if matches!(op, UnaryOp::Neg) && self.base_is(&t, "Float") {
                    self.report(
                        Diagnostic::error(
                            Category::Type,
                            Some(e.span),
                            "`-` is not defined for Float in TeSSLa 1.2",
                        )
                        .with_label("a Float operand")
                        .with_help("use `-.` for Float"),
                    );
                    return self.lifted(&[t], float());
                }
                self.expect(&want, &t, operand.span, what);
                self.lifted(&[t], want)
            }
            ExprKind::Binary { op, lhs, rhs } => self.binary(*op, lhs, rhs, e.span, scope),
            ExprKind::If {
                is_static,
                cond,
                then_branch,
                else_branch,
            } => {
                let c = self.infer(cond, scope);
                self.expect(
                    &boolean(),
                    &c,
                    cond.span,
                    "the condition of `if` must be a Bool",
                );
                let t = self.infer(then_branch, scope);
                let f = self.infer(else_branch, scope);
                if *is_static {
                    // Only one branch is compiled; the other may have another type.
                    return self.fresh();
                }
                if self.unify(&t, &f).is_err() {
                    let (ts, fs) = (show(&self.resolve(&t)), show(&self.resolve(&f)));
                    self.report(
                        Diagnostic::error(
                            Category::Type,
                            Some(else_branch.span),
                            format!("the branches of `if` have different types: {ts} and {fs}"),
                        )
                        .with_label(format!("this is {fs}"))
                        .with_note_at(then_branch.span, format!("this is {ts}"))
                        .with_help("both branches must have the same type"),
                    );
                    return self.fresh();
                }
                let r = if self.is_stream(&f) { f } else { t };
                self.lifted(&[c], r)
            }
            ExprKind::Lambda { params, body } => {
                let inner = self.child_of(scope);
                let mut ps = Vec::new();
                for p in params {
                    let t = match &p.ty {
                        Some(t) => self.ast_type(t, &HashMap::new()),
                        None => self.missing_parameter_type(p, None),
                    };
                    inner
                        .names
                        .borrow_mut()
                        .insert(p.name.name.clone(), Local::Mono(t.clone()));
                    ps.push(t);
                }
                let r = self.infer(body, &inner);
                func(ps, r)
            }
            ExprKind::Call {
                function,
                args,
                type_args,
            } => {
                for t in type_args {
                    self.ast_type(t, &HashMap::new());
                }
                if let ExprKind::Var(id) = &function.kind {
                    match self.find(&id.name, scope) {
                        Some(Found::Def(d)) => self.type_arguments(
                            d.def,
                            type_args,
                            args.is_some(),
                            function.span,
                            e.span,
                        ),
                        // A builtin takes the type arguments its library declaration names.
                        None if !type_args.is_empty() => {
                            let name = crate::prelude::builtin_alias(&id.name).unwrap_or(&id.name);
                            if let Some(d) = builtins::get(name)
                                .and_then(|b| crate::prelude::declaration(b.name))
                            {
                                self.type_arguments(d, type_args, false, function.span, e.span);
                            }
                        }
                        _ => {}
                    }
                }
                let f = self.infer(function, scope);
                let Some(args) = args else {
                    return f;
                };
                self.call(f, function, args, e.span, scope)
            }
        }
    }

    /// `x._1` or `x.a` inside the definition of `x` itself, where `x` is a tuple or record
    /// literal without a written type: as in TeSSLa, the access is the member's own expression
    /// (`def x = (v, x._1)` is not a recursion of `x`). `None`: not such an access.
    fn literal_member(
        &mut self,
        object: &'a Expr,
        field: &ast::Ident,
        scope: &Rc<Scope<'a>>,
    ) -> Option<Ty> {
        let ExprKind::Var(id) = &object.kind else {
            return None;
        };
        let Some(Found::Def(d)) = self.find(&id.name, scope) else {
            return None;
        };
        if d.def.params.is_some() || !matches!(*d.state.borrow(), State::InProgress(_)) {
            return None;
        }
        let Body::Expr { expr, where_defs } = &d.def.body else {
            return None;
        };
        if !where_defs.is_empty() {
            return None;
        }
        let member = match &expr.kind {
            ExprKind::Tuple(es) => field
                .name
                .strip_prefix('_')
                .and_then(|k| k.parse::<usize>().ok())
                .and_then(|k| es.get(k.checked_sub(1)?)),
            ExprKind::Record(ms) => ms
                .iter()
                .find(|(n, _)| n.name == field.name)
                .map(|(_, e)| e),
            _ => None,
        }?;
        let key = (Rc::as_ptr(&d) as usize, field.name.clone());
        if self.literal_members.contains(&key) {
            return None;
        }
        self.literal_members.push(key);
        let t = self.infer(member, &d.scope);
        self.literal_members.pop();
        Some(t)
    }

    /// TeSSLa's rules for the type arguments of a call of a user function: as many as it has
    /// type parameters when given, and when none are given, each type parameter must occur in
    /// a parameter type so that the arguments determine it.
    fn type_arguments(
        &mut self,
        d: &Def,
        given: &[ast::Type],
        called: bool,
        name_span: Span,
        span: Span,
    ) {
        let n = &d.name.name;
        let type_params = || {
            d.type_params
                .iter()
                .map(|t| t.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        };
        if !given.is_empty() && given.len() != d.type_params.len() {
            self.report(
                Diagnostic::error(
                    Category::Type,
                    Some(span),
                    format!(
                        "`{n}` takes {} type argument{}, {} given",
                        d.type_params.len(),
                        if d.type_params.len() == 1 { "" } else { "s" },
                        given.len()
                    ),
                )
                .with_help(format!("its type parameters are [{}]", type_params())),
            );
            return;
        }
        let Some(params) = &d.params else { return };
        if !given.is_empty() || !called {
            return;
        }
        for tp in &d.type_params {
            let inferable = params
                .iter()
                .any(|p| p.ty.as_ref().is_some_and(|t| mentions(t, &tp.name)));
            if !inferable {
                self.report(
                    Diagnostic::error(
                        Category::Type,
                        Some(name_span),
                        format!(
                            "the type argument `{}` of `{n}` cannot be inferred",
                            tp.name
                        ),
                    )
                    .with_label("type arguments needed")
                    .with_help(format!(
                        "`{}` occurs in no parameter type; give the type arguments: `{n}[{}](...)`",
                        tp.name,
                        type_params()
                    )),
                );
                return;
            }
        }
    }

    /// The element type of a stream type, else the type itself.
    fn strip(&self, t: &Ty) -> Ty {
        match self.shallow(t) {
            Ty::Con("Events", a) => a.first().cloned().unwrap_or_else(|| t.clone()),
            other => other,
        }
    }

    fn base_is(&self, t: &Ty, name: &str) -> bool {
        matches!(self.shallow(&self.strip(t)), Ty::Con(n, _) if n == name)
    }

    fn binary(
        &mut self,
        op: BinOp,
        lhs: &'a Expr,
        rhs: &'a Expr,
        span: Span,
        scope: &Rc<Scope<'a>>,
    ) -> Ty {
        use BinOp::*;
        let a = self.infer(lhs, scope);
        let b = self.infer(rhs, scope);
        let sym = op.symbol();
        let (operand, result) = match op {
            Add | Sub | Mul | Div | Mod | Shl | Shr | BitAnd | BitOr | BitXor => (int(), int()),
            Lt | Gt | Le | Ge => (int(), boolean()),
            FAdd | FSub | FMul | FDiv => (float(), float()),
            FLt | FGt | FLe | FGe => (float(), boolean()),
            And | Or => (boolean(), boolean()),
            Eq | Ne => {
                if self.unify(&a, &b).is_err() {
                    let (x, y) = (show(&self.resolve(&a)), show(&self.resolve(&b)));
                    self.report(
                        Diagnostic::error(
                            Category::Type,
                            Some(span),
                            format!("`{sym}` compares values of one type, found {x} and {y}"),
                        )
                        .with_label("different types"),
                    );
                }
                return self.lifted(&[a, b], boolean());
            }
        };
        let int_op = matches!(op, Add | Sub | Mul | Div | Mod | Lt | Gt | Le | Ge);
        if int_op && (self.base_is(&a, "Float") || self.base_is(&b, "Float")) {
            self.report(
                Diagnostic::error(
                    Category::Type,
                    Some(span),
                    format!("`{sym}` is not defined for Float in TeSSLa 1.2"),
                )
                .with_label("a Float operand")
                .with_help(format!("use `{sym}.` for Float")),
            );
            return self.lifted(&[a, b], result);
        }
        let what = format!("operand of `{sym}`");
        if self.expect(&operand, &a, lhs.span, &what) {
            self.expect(&operand, &b, rhs.span, &what);
        }
        self.lifted(&[a, b], result)
    }

    fn call(
        &mut self,
        f: Ty,
        function: &'a Expr,
        args: &'a [ast::Arg],
        span: Span,
        scope: &Rc<Scope<'a>>,
    ) -> Ty {
        let mut ts: Vec<Ty> = args.iter().map(|a| self.infer(&a.value, scope)).collect();
        // Variadic builtins get their signature from the number of arguments.
        if let ExprKind::Var(id) = &function.kind
            && self.find(&id.name, scope).is_none()
            && builtins::get(&id.name).is_some_and(|b| b.sig == Sig::Variadic)
            && let Some(sig) = self.variadic(&id.name, ts.len())
        {
            return self.apply(sig, &ts, args, span, &id.name);
        }
        if args.iter().any(|a| a.name.is_some()) {
            // Named arguments: put them in parameter order when the callee is a user def.
            let params = match &function.kind {
                ExprKind::Var(id) => match self.find(&id.name, scope) {
                    Some(Found::Def(d)) => d.def.params.clone(),
                    _ => None,
                },
                _ => None,
            };
            let Some(params) = params else {
                return self.fresh();
            };
            let names: Vec<&str> = params.iter().map(|p| p.name.name.as_str()).collect();
            let callee = function
                .dotted_path()
                .unwrap_or_else(|| "the function".into());
            let Some(positions) = self.order_named(args, &names, &callee) else {
                return self.fresh();
            };
            let mut ordered: Vec<Option<Ty>> = vec![None; params.len()];
            for (pos, t) in positions.into_iter().zip(ts.iter()) {
                match ordered.get_mut(pos) {
                    Some(slot) => *slot = Some(t.clone()),
                    None => return self.fresh(),
                }
            }
            match ordered.into_iter().collect::<Option<Vec<Ty>>>() {
                Some(o) => ts = o,
                // A parameter without an argument (a default value): not modelled.
                None => return self.fresh(),
            }
        }
        let name = match &function.kind {
            ExprKind::Var(id) => id.name.clone(),
            _ => "the function".into(),
        };
        // A user function's parameters of value types, before the call binds anything.
        let value_params = match (function.dotted_path(), self.shallow(&f)) {
            (Some(path), Ty::Fn(ps, _)) => match self.find(&path, scope) {
                // A def without parameters (`def g = f`) names a function whose liftability
                // is its value's, not modelled: let through.
                Some(Found::Def(d)) if !d.def.liftable && d.def.params.is_some() => {
                    Some((d, self.value_params(&ps)))
                }
                _ => None,
            },
            _ => None,
        };
        let before = self.diags.len();
        let r = self.apply(f, &ts, args, span, &name);
        if self.diags.len() == before
            && let Some((d, value_params)) = value_params
        {
            self.check_not_lifted(d.def, &value_params, &ts, args, span);
        }
        if self.diags.len() > before
            && self.find(&name, scope).is_none()
            && let Some(h) = library_hint(&name)
            && let Some(d) = self.diags.last_mut()
        {
            d.help = Some(h.to_string());
        }
        r
    }

    /// Apply a function type to arguments.
    fn apply(&mut self, f: Ty, ts: &[Ty], args: &[ast::Arg], span: Span, name: &str) -> Ty {
        match self.shallow(&f) {
            Ty::Fn(ps, r) => {
                if ps.len() != ts.len() {
                    self.report(Diagnostic::error(
                        Category::Type,
                        Some(span),
                        format!("`{name}` takes {} arguments, {} given", ps.len(), ts.len()),
                    ));
                    return self.fresh();
                }
                for (i, (p, t)) in ps.iter().zip(ts).enumerate() {
                    let sp = args.get(i).map_or(span, |a| a.value.span);
                    if !self.expect(p, t, sp, &format!("argument {} of `{name}`", i + 1)) {
                        return self.fresh();
                    }
                }
                self.lifted(ts, *r)
            }
            Ty::Var(_) => {
                let r = self.fresh();
                let _ = self.unify(&f, &func(ts.to_vec(), r.clone()));
                r
            }
            other => {
                self.report(Diagnostic::error(
                    Category::Type,
                    Some(span),
                    format!(
                        "`{name}` is {}, not a function",
                        show(&self.resolve(&other))
                    ),
                ));
                self.fresh()
            }
        }
    }

    /// Signatures of builtins whose arity varies (`lift`, `slift`, `merge`, `log`).
    fn variadic(&mut self, name: &str, n: usize) -> Option<Ty> {
        let arity = |base: &str| -> Option<usize> {
            let rest = name.strip_prefix(base)?;
            if rest.is_empty() {
                Some(n)
            } else {
                rest.parse().ok()
            }
        };
        if let Some(k) = arity("slift").or_else(|| arity("lift")) {
            let k = k.min(n.saturating_sub(1));
            let xs: Vec<Ty> = (0..k).map(|_| self.fresh()).collect();
            let r = self.fresh();
            let is_lift = name.starts_with("lift");
            let fty = if is_lift {
                func(xs.iter().cloned().map(opt).collect(), opt(r.clone()))
            } else {
                func(xs.clone(), r.clone())
            };
            let mut ps: Vec<Ty> = xs.into_iter().map(ev).collect();
            ps.push(fty);
            return Some(func(ps, ev(r)));
        }
        if let Some(k) = arity("merge") {
            let a = self.fresh();
            return Some(func(vec![ev(a.clone()); k], ev(a)));
        }
        if name == "log" {
            return Some(func(vec![float(); n.clamp(1, 2)], float()));
        }
        None
    }

    /// The type of a builtin name, from its signature in the builtins table (`None`: not a
    /// builtin or one without a fixed signature).
    fn builtin(&mut self, name: &str) -> Option<Ty> {
        // Two variables per use, `A`/`K` and `B`/`V`, whether the signature uses them or not.
        let vars = [self.fresh(), self.fresh()];
        let name = crate::prelude::builtin_alias(name).unwrap_or(name);
        let b = builtins::get(name)?;
        // A builtin without a signature of its own has the one its library function declares
        // (`sum(x: Events[Int]): Events[Int]`).
        if b.sig == Sig::Any
            && let Some(d) = crate::prelude::declaration(b.name)
        {
            return Some(self.declared_signature(d));
        }
        let template = template(b.name)?;
        Some(with_vars(template, &vars))
    }

    /// The type a library declaration gives (fresh variables for its type parameters). Its
    /// types are TeSSLa's own: a name this checker does not model becomes a fresh variable,
    /// and nothing is reported (the declaration's spans are not in the spec's files).
    fn declared_signature(&mut self, d: &Def) -> Ty {
        let quiet = self.diags.len();
        let tparams: HashMap<String, Ty> = d
            .type_params
            .iter()
            .map(|tp| (tp.name.clone(), self.fresh()))
            .collect();
        let r = match &d.result_type {
            Some(t) => self.ast_type(t, &tparams),
            None => self.fresh(),
        };
        let t = match &d.params {
            Some(ps) => {
                let ps = ps
                    .iter()
                    .map(|p| match &p.ty {
                        Some(t) => self.ast_type(t, &tparams),
                        None => self.fresh(),
                    })
                    .collect();
                func(ps, r)
            }
            None => r,
        };
        self.diags.truncate(quiet);
        t
    }

    /// TeSSLa's rules for `liftable`: only a macro (a def with parameters or type parameters)
    /// can be liftable (`LiftableOnNonMacro`), and only when its parameter and result types
    /// are value types, not streams (`UnliftableMacroType`; see [`is_value_type`]).
    fn check_liftable(&mut self, d: &Def) {
        if !d.liftable {
            return;
        }
        if d.params.is_none() && d.type_params.is_empty() {
            self.report(
                Diagnostic::error(
                    Category::Type,
                    Some(d.span),
                    format!(
                        "`{}` is not a function, so it cannot be `liftable`",
                        d.name.name
                    ),
                )
                .with_label("liftable without parameters")
                .with_help(format!(
                    "remove `liftable`: only functions with parameters are lifted to streams \
                     (TeSSLa: Non-macro \"{}\" can not be liftable)",
                    d.name.name
                )),
            );
            return;
        }
        let library = self.resolved.and_then(|r| r.library);
        if matches!(d.body, Body::Extern { .. }) || library == Some(d.span.file) {
            return;
        }
        let bad = d
            .params
            .iter()
            .flatten()
            .filter_map(|p| p.ty.as_ref())
            .chain(d.result_type.as_ref())
            .find(|t| !is_value_type(t));
        if let Some(t) = bad {
            self.report(
                Diagnostic::error(
                    Category::Type,
                    Some(d.span),
                    format!(
                        "`{}` is declared `liftable`, but its type does not allow being lifted",
                        d.name.name
                    ),
                )
                .with_note_at(t.span(), "a stream type")
                .with_help(
                    "a liftable function takes and returns plain values (Int, Float, records, \
                     ...), which TeSSLa lifts to streams; remove `liftable`, or the stream types",
                ),
            );
        }
    }

    /// Each parameter type that is a plain value type (`Int`, not a stream, not a type
    /// variable), as `Some(type)`.
    fn value_params(&self, ps: &[Ty]) -> Vec<Option<Ty>> {
        ps.iter()
            .map(|p| match self.shallow(p) {
                Ty::Var(_) | Ty::Con("Events", _) => None,
                t @ (Ty::Con(..) | Ty::Fn(..) | Ty::Record(_)) => Some(t),
            })
            .collect()
    }

    /// TeSSLa lifts only `liftable` functions to streams: a stream given for a parameter of
    /// a plain value type (`Int`) of another function is a type mismatch. `ps` are the
    /// callee's value parameter types ([`Checker::value_params`]), `ts` the arguments'.
    fn check_not_lifted(
        &mut self,
        d: &Def,
        ps: &[Option<Ty>],
        ts: &[Ty],
        args: &[ast::Arg],
        span: Span,
    ) {
        for (i, (p, t)) in ps.iter().zip(ts).enumerate() {
            if let Some(p) = p
                && self.is_stream(t)
            {
                let n = &d.name.name;
                let (ps, ts) = (show(&self.resolve(p)), show(&self.resolve(t)));
                let sp = args.get(i).map_or(span, |a| a.value.span);
                self.report(
                    Diagnostic::error(
                        Category::Type,
                        Some(sp),
                        format!("argument {} of `{n}`: expected {ps}, found {ts}", i + 1),
                    )
                    .with_label(format!("a stream, but `{n}` is not liftable"))
                    .with_help(format!(
                        "only `liftable` functions apply to streams event by event: declare \
                         `liftable def {n}(...)`, or give the parameter a stream type \
                         (`Events[...]`)"
                    )),
                );
                return;
            }
        }
    }
}

/// TeSSLa's value types (what a liftable function may take and return): not a stream, and no
/// record or tuple holding one. A type name (an alias) counts as a value. TeSSLa also excludes
/// function types, but its library declares its liftable functions taking functions
/// (`List.map`) as `extern`, which the bundled prelude (and the corpus run with it) writes as
/// definitions: a function type is let through here.
fn is_value_type(t: &ast::Type) -> bool {
    match t {
        ast::Type::Name(_) => true,
        ast::Type::App { name, args, .. } => {
            name.name != "Events" && args.iter().all(is_value_type)
        }
        ast::Type::Function { .. } => true,
        ast::Type::Record { fields, .. } => fields.iter().all(|(_, t)| is_value_type(t)),
        ast::Type::Tuple { elems, .. } => elems.iter().all(is_value_type),
    }
}

/// The help for a library function given an argument of the wrong type: how to write it for
/// the type at hand.
fn library_hint(name: &str) -> Option<&'static str> {
    Some(match name {
        "sum" => {
            "`sum` is TeSSLa's `def sum(x: Events[Int]): Events[Int]`; for a Float stream \
             write it with `fold`: `fold(x, 0.0, (acc: Float, v: Float) => acc +. v)`"
        }
        "maximum" | "minimum" => {
            "`maximum` and `minimum` are declared for Events[Int]; for a Float stream use \
             `reduce(x, (a: Float, b: Float) => if a >. b then a else b)` (`<.` for the minimum)"
        }
        "average" => {
            "`average` is declared for Events[Int]; for a Float stream divide a `fold` sum \
             by `count(x)`"
        }
        _ => return None,
    })
}

/// Is `name` a builtin a spec may name (directly or by its prelude alias)? `extern`-only
/// natives are not.
fn is_builtin_name(name: &str) -> bool {
    let name = crate::prelude::builtin_alias(name).unwrap_or(name);
    builtins::get(name).is_some_and(|b| !matches!(b.kind, builtins::Kind::Extern(_)))
}

/// Stand-ins for `A`/`K` and `B`/`V` in a parsed signature (never a checker variable: those
/// count up from 0).
const TEMPLATE_VARS: [u32; 2] = [u32::MAX, u32::MAX - 1];

/// The parsed signature of a builtin with a fixed one, parsed once per process on first use.
fn template(name: &'static str) -> Option<&'static Ty> {
    static TEMPLATES: OnceLock<HashMap<&'static str, OnceLock<Option<Ty>>>> = OnceLock::new();
    let cells = TEMPLATES.get_or_init(|| {
        builtins::BUILTINS
            .iter()
            .filter(|b| matches!(b.sig, Sig::Fixed(_)))
            .map(|b| (b.name, OnceLock::new()))
            .collect()
    });
    let Sig::Fixed(sig) = builtins::get(name)?.sig else {
        return None;
    };
    cells
        .get(name)?
        .get_or_init(|| signature(sig, &TEMPLATE_VARS.map(Ty::Var)))
        .as_ref()
}

/// `t` with the template variables replaced by `vars`.
fn with_vars(t: &Ty, vars: &[Ty; 2]) -> Ty {
    let w = |x: &Ty| with_vars(x, vars);
    match t {
        Ty::Var(v) if *v == TEMPLATE_VARS[0] => vars[0].clone(),
        Ty::Var(v) if *v == TEMPLATE_VARS[1] => vars[1].clone(),
        Ty::Var(_) => t.clone(),
        Ty::Con(n, args) => Ty::Con(n, args.iter().map(w).collect()),
        Ty::Fn(ps, r) => Ty::Fn(ps.iter().map(w).collect(), Box::new(w(r))),
        Ty::Record(fs) => Ty::Record(fs.iter().map(|(n, t)| (n.clone(), w(t))).collect()),
    }
}

/// A type in TeSSLa's notation (`(Events[A], (B, A) => B) => Events[B]`) with `A`/`K` and
/// `B`/`V` standing for `vars`; `None` when it does not parse (a test parses every signature
/// of the builtins table).
fn signature(sig: &'static str, vars: &[Ty; 2]) -> Option<Ty> {
    let mut p = SigParser { rest: sig, vars };
    let t = p.ty()?;
    p.rest.trim().is_empty().then_some(t)
}

struct SigParser<'v> {
    rest: &'static str,
    vars: &'v [Ty; 2],
}

impl SigParser<'_> {
    fn eat(&mut self, tok: &str) -> bool {
        let r = self.rest.trim_start();
        match r.strip_prefix(tok) {
            Some(after) => {
                self.rest = after;
                true
            }
            None => {
                self.rest = r;
                false
            }
        }
    }

    /// Types separated by commas up to `close`.
    fn list(&mut self, close: &str) -> Option<Vec<Ty>> {
        let mut out = Vec::new();
        if self.eat(close) {
            return Some(out);
        }
        loop {
            out.push(self.ty()?);
            if self.eat(close) {
                return Some(out);
            }
            if !self.eat(",") {
                return None;
            }
        }
    }

    fn ty(&mut self) -> Option<Ty> {
        if self.eat("(") {
            let params = self.list(")")?;
            if !self.eat("=>") {
                return None;
            }
            return Some(func(params, self.ty()?));
        }
        let r = self.rest.trim_start();
        let end = r
            .find(|c: char| !c.is_ascii_alphanumeric())
            .unwrap_or(r.len());
        let (name, after) = r.split_at(end);
        self.rest = after;
        let args = if self.eat("[") {
            self.list("]")?
        } else {
            Vec::new()
        };
        let mut args = args.into_iter();
        let mut arg = || args.next();
        Some(match name {
            "A" | "K" => self.vars[0].clone(),
            "B" | "V" => self.vars[1].clone(),
            "Int" => int(),
            "Float" => float(),
            "Bool" => boolean(),
            "String" => string(),
            "Unit" => unit(),
            "Events" => ev(arg()?),
            "Option" => opt(arg()?),
            "List" => list(arg()?),
            "Set" => set(arg()?),
            "Map" => map(arg()?, arg()?),
            _ => return None,
        })
    }
}

fn collect_vars(t: &Ty, out: &mut Vec<u32>) {
    match t {
        Ty::Var(v) => {
            if !out.contains(v) {
                out.push(*v);
            }
        }
        Ty::Con(_, args) => args.iter().for_each(|a| collect_vars(a, out)),
        Ty::Fn(ps, r) => {
            ps.iter().for_each(|a| collect_vars(a, out));
            collect_vars(r, out);
        }
        Ty::Record(fs) => fs.iter().for_each(|(_, a)| collect_vars(a, out)),
    }
}

fn substitute(t: &Ty, map: &HashMap<u32, Ty>) -> Ty {
    let s = |x: &Ty| substitute(x, map);
    match t {
        Ty::Var(v) => map.get(v).cloned().unwrap_or_else(|| t.clone()),
        Ty::Con(n, args) => Ty::Con(n, args.iter().map(s).collect()),
        Ty::Fn(ps, r) => Ty::Fn(ps.iter().map(s).collect(), Box::new(s(r))),
        Ty::Record(fs) => Ty::Record(fs.iter().map(|(n, t)| (n.clone(), s(t))).collect()),
    }
}

/// TeSSLa's notation of a type; unknown parts print as `?`.
fn show(t: &Ty) -> String {
    match t {
        Ty::Var(_) => "?".into(),
        Ty::Con(n, args) if args.is_empty() => (*n).into(),
        Ty::Con(n, args) => format!(
            "{n}[{}]",
            args.iter().map(show).collect::<Vec<_>>().join(", ")
        ),
        Ty::Fn(ps, r) => format!(
            "({}) => {}",
            ps.iter().map(show).collect::<Vec<_>>().join(", "),
            show(r)
        ),
        Ty::Record(fs)
            if fs
                .iter()
                .enumerate()
                .all(|(i, (n, _))| n.strip_prefix('_') == Some(&(i + 1).to_string())) =>
        {
            format!(
                "({})",
                fs.iter()
                    .map(|(_, t)| show(t))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        }
        Ty::Record(fs) => format!(
            "{{{}}}",
            fs.iter()
                .map(|(n, t)| format!("{n}: {}", show(t)))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// Does the syntax type `t` name the type `name` anywhere?
fn mentions(t: &ast::Type, name: &str) -> bool {
    match t {
        ast::Type::Name(id) => id.name == name,
        ast::Type::App { name: n, args, .. } => {
            n.name == name || args.iter().any(|a| mentions(a, name))
        }
        ast::Type::Function { params, result, .. } => {
            params.iter().any(|(_, p)| mentions(p, name)) || mentions(result, name)
        }
        ast::Type::Record { fields, .. } => fields.iter().any(|(_, f)| mentions(f, name)),
        ast::Type::Tuple { elems, .. } => elems.iter().any(|e| mentions(e, name)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_signature_parses() {
        let vars = [Ty::Var(0), Ty::Var(1)];
        for b in builtins::BUILTINS {
            if let Sig::Fixed(sig) = b.sig {
                assert!(signature(sig, &vars).is_some(), "{}: {sig}", b.name);
            }
        }
        assert_eq!(
            signature("(Events[A], B, (B, A) => B) => Events[B]", &vars),
            Some(func(
                vec![
                    ev(Ty::Var(0)),
                    Ty::Var(1),
                    func(vec![Ty::Var(1), Ty::Var(0)], Ty::Var(1))
                ],
                ev(Ty::Var(1))
            ))
        );
        assert_eq!(
            signature("Map[K, V]", &vars),
            Some(map(Ty::Var(0), Ty::Var(1)))
        );
        assert_eq!(signature("(Int) =>", &vars), None);
        for b in builtins::BUILTINS {
            if let Sig::Fixed(sig) = b.sig {
                let direct = signature(sig, &vars);
                let cached = template(b.name).map(|t| with_vars(t, &vars));
                assert_eq!(direct, cached, "{}", b.name);
            }
        }
    }

    #[test]
    fn an_input_that_is_no_stream_is_a_type_error() {
        let spec = "in x: Int\nout x";
        let (file, _) = tessla_syntax::parse(spec, tessla_syntax::source::FileId::default());
        let (errors, types) = check_typed(&[file]);
        assert_eq!(types.inputs, vec![Type::Unknown]);
        assert_eq!(errors.len(), 1);
        assert_eq!(errors[0].message, "input `x` must have a type Events[T]");
    }

    #[test]
    fn the_type_table_has_inputs_outputs_and_defs() {
        let spec = "in x: Events[Int]\nliftable def f(a: Int) = (a, true)\ndef g = f(x)\nout g\nout f(x) as h\nout *";
        let (file, diags) = tessla_syntax::parse(spec, tessla_syntax::source::FileId::default());
        assert!(diags.is_empty());
        let (errors, types) = check_typed(&[file]);
        assert!(errors.is_empty());
        let pair = Type::Tuple(vec![Type::Int, Type::Bool]);
        assert_eq!(types.defs.get("g"), Some(&pair));
        assert_eq!(types.inputs, vec![Type::Int]);
        assert_eq!(types.outputs.len(), 2);
        assert!(types.outputs.values().all(|t| *t == pair));
    }
}
