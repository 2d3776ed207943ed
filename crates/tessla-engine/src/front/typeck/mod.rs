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
//! (type aliases and extern types, named arguments of builtins, record fields of a value of
//! still unknown type) gets a fresh type variable, which fits everything. Definitions are
//! generalised (let-polymorphism) when they are done, so generic functions and constants may
//! be used at several types.
//!
//! The result is the typed program the lowering consumes ([`Typed`]: the resolved spec with the
//! element types of inputs, outputs by [`ExprId`] and `out *` defs), a stage only [`check`]
//! makes; the lowering writes no type rule the checker owns.
//!
//! This file is the driver ([`check`]: inputs, definitions, annotations, outputs), the
//! `Checker` state and its scopes. Each rule lives in one file, by concern: `ty` (types,
//! unification), `infer` (expressions), `operators`, `calls` (application, named arguments,
//! type arguments), `defs` (definitions, recursion), `names` (lookup, written types),
//! `signatures` (builtins from the table, prelude declarations), `annotations`, `liftable`.

use crate::builtins::{self, Builtin, Natives, Sig, Variadic};
use crate::front::resolve::{Global, Resolved, at};
use crate::ir::Type;
use std::cell::RefCell;
use std::collections::HashMap;
use std::rc::Rc;
use std::sync::OnceLock;
use tessla_syntax::ast::{self, BinOp, Body, Def, Expr, ExprKind, StrPart, UnaryOp};
use tessla_syntax::diag::{Category, Diagnostic};
use tessla_syntax::source::Span;

mod annotations;
mod calls;
mod defs;
mod infer;
mod liftable;
mod names;
mod operators;
mod signatures;
mod ty;

pub use annotations::ANNOTATION_ARGS_CONSTANT;
pub use calls::order_named;
use names::*;
use signatures::*;
use ty::*;

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

/// The typed program, the stage between checking and lowering: the resolved spec that passed
/// the checker, with the element type of each input (by its index in [`Resolved::inputs`]), of
/// each output (by the id of its expression; an object output's members are fields of it) and
/// of each top-level parameterless def (by dotted name, for `out *`). Types the checker leaves
/// open are [`Type::Unknown`] inside. Only [`check`] makes one (its fields are private), so the
/// lowering, which requires one, runs on checked specs only and takes its types from here; the
/// few rules the checker leaves open (named arguments of builtins, constant arguments, ...) are
/// marked in `lower/` as their one place.
#[derive(Debug)]
pub struct Typed<'a> {
    resolved: &'a Resolved<'a>,
    /// The natives the application registered (`extern("name")` beyond the builtins table).
    natives: &'a Natives,
    inputs: Vec<Type>,
    outputs: HashMap<ExprId, Type>,
    defs: HashMap<String, Type>,
}

impl<'a> Typed<'a> {
    /// The resolved spec that was checked.
    pub fn resolved(&self) -> &'a Resolved<'a> {
        self.resolved
    }

    /// The natives the spec was checked with.
    pub fn natives(&self) -> &'a Natives {
        self.natives
    }

    /// The element type of input `i` (by its index in [`Resolved::inputs`]).
    pub fn input(&self, i: usize) -> Type {
        self.inputs.get(i).cloned().unwrap_or(Type::Unknown)
    }

    /// The element type of an output expression ([`Type::Unknown`]: none, or open).
    pub fn output(&self, e: &Expr) -> Type {
        self.outputs
            .get(&ExprId::of(e))
            .cloned()
            .unwrap_or(Type::Unknown)
    }

    /// The element type of the top-level parameterless def `name` (for `out *`).
    pub fn def(&self, name: &str) -> Type {
        self.defs.get(name).cloned().unwrap_or(Type::Unknown)
    }
}

/// Check a resolved spec with the builtins only: see [`check_with`] (the unit tests' way in).
#[cfg(test)]
pub fn check<'a>(resolved: &'a Resolved<'a>) -> Result<Typed<'a>, Vec<Diagnostic>> {
    static NONE: Natives = Natives::new();
    check_with(resolved, &NONE)
}

/// Check a resolved spec, `natives` added to the builtins: the typed program, or the errors
/// found (the resolver's first).
pub fn check_with<'a>(
    resolved: &'a Resolved<'a>,
    natives: &'a Natives,
) -> Result<Typed<'a>, Vec<Diagnostic>> {
    let mut types = Typed {
        resolved,
        natives,
        inputs: Vec::new(),
        outputs: HashMap::new(),
        defs: HashMap::new(),
    };
    let mut c = Checker {
        resolved: Some(resolved),
        natives: Some(natives),
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
    for (anns, global) in resolved.annotation_uses() {
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
    if c.diags.is_empty() {
        Ok(types)
    } else {
        Err(std::mem::take(&mut c.diags))
    }
}

#[derive(Default)]
struct Checker<'a> {
    subst: Vec<Option<Ty>>,
    diags: Vec<Diagnostic>,
    /// The resolved spec: statements, global definitions, imports, inputs, declared types.
    resolved: Option<&'a Resolved<'a>>,
    /// The natives the application registered: an `extern` of one is checked against its
    /// registered signature.
    natives: Option<&'a Natives>,
    /// The global definitions, by [`DefId`](crate::front::resolve::DefId).
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
    /// A new local scope under `parent`, registered for [`Checker::break_cycles`].
    pub(super) fn child_of(&mut self, parent: &Rc<Scope<'a>>) -> Rc<Scope<'a>> {
        let s = parent.child();
        self.local_scopes.push(s.clone());
        s
    }

    /// Empty every scope, breaking the `Rc` cycles between scopes and the defs they name.
    pub(super) fn break_cycles(&mut self) {
        let module_scopes = self.module_scopes.drain().map(|(_, s)| s);
        for s in self.local_scopes.drain(..).chain(module_scopes) {
            if let Ok(mut names) = s.names.try_borrow_mut() {
                names.clear();
            }
        }
        self.globals.clear();
    }

    pub(super) fn module_scope(&mut self, prefix: &str) -> Rc<Scope<'a>> {
        self.module_scopes
            .entry(prefix.to_string())
            .or_insert_with(|| Scope::root(prefix.to_string()))
            .clone()
    }

    pub(super) fn report(&mut self, d: Diagnostic) {
        // One error per place, and not a flood.
        if self.diags.len() < 20 && !self.diags.iter().any(|x| x.span == d.span) {
            self.diags.push(d);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The diagnostics of loading `spec` (empty when it loads), each as "category: message".
    fn load_messages(spec: &str) -> Vec<String> {
        let resolver = tessla_syntax::include::MemResolver {
            files: [("spec.tessla".to_string(), spec.to_string())].into(),
        };
        match crate::load_with("spec.tessla", &resolver, &crate::LoadOptions::default()) {
            Ok(_) => Vec::new(),
            Err(e) => e
                .diagnostics
                .iter()
                .map(|d| format!("{:?}: {}", d.category, d.message))
                .collect(),
        }
    }

    #[test]
    fn unknown_dotted_names_are_the_checkers_and_library_literals_load() {
        for (name, spec_name) in [
            ("Foo.bar", "Foo.bar"),
            ("Math.zzz", "Math.zzz"),
            ("Operators.zzz", "Operators.zzz(x)"),
            ("Operators.add.zzz", "Operators.add.zzz"),
        ] {
            let spec = format!("in x: Events[Int]\nout {spec_name} as y\n");
            assert_eq!(
                load_messages(&spec),
                [format!("Name: unknown name `{name}`")],
                "{spec}"
            );
        }
        let spec = "in x: Events[Int]\nout const(Types.true, x) as a\n\
                    out const(Option.None[Int], x) as b\n";
        assert_eq!(load_messages(spec), Vec::<String>::new());
    }

    #[test]
    fn the_rules_the_checker_leaves_open_are_reported_by_the_lowering_not_as_internal_errors() {
        for (spec, want) in [
            (
                "def f(a: Int, b: Int) = a + b\nout f(a = 1, a = 2) as y",
                "Type: an argument is given twice or there are too many arguments",
            ),
            (
                "def f(a: Int, b: Int) = a + b\ndef y = f(b = 1)\nout y",
                "Type: missing arguments",
            ),
            (
                "def g = 5\nout g(a = 1) as y",
                "Type: named arguments need a function",
            ),
            (
                "out default(x, x) as y",
                "Type: argument 2 must be a constant",
            ),
            (
                "out reduce(x, nil) as y",
                "Type: argument 2 must be a function",
            ),
            (
                "out count(Operators.add) as y",
                "Type: a function is used where a stream is needed",
            ),
            (
                "def f = extern(\"foo\")\nout f as y",
                "Type: extern definition `f` needs a type annotation",
            ),
        ] {
            let spec = format!("in x: Events[Int]\n{spec}\n");
            assert_eq!(load_messages(&spec), [want.to_string()], "{spec}");
        }
    }

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
    fn variadic_builtins_are_typed_from_their_shape_in_the_table() {
        let mut c = Checker::default();
        let mut typed = |name: &str, n: usize| match builtins::get(name).map(|b| b.sig) {
            Some(Sig::Variadic(shape)) => c.variadic(&shape, n).map(|t| show(&t)),
            other => Some(format!("{name} is not variadic: {other:?}")),
        };
        let lift2 = typed("lift2", 3);
        assert_eq!(
            lift2.as_deref(),
            Some("(Events[?], Events[?], (Option[?], Option[?]) => Option[?]) => Events[?]")
        );
        let slift = typed("slift", 2);
        assert_eq!(slift.as_deref(), Some("(Events[?], (?) => ?) => Events[?]"));
        let merge3 = typed("merge3", 5);
        assert_eq!(
            merge3.as_deref(),
            Some("(Events[?], Events[?], Events[?]) => Events[?]")
        );
        assert_eq!(typed("log", 5).as_deref(), Some("(Float, Float) => Float"));
        assert_eq!(typed("log", 0).as_deref(), Some("(Float) => Float"));
    }

    #[test]
    fn an_input_that_is_no_stream_is_a_type_error() {
        let spec = "in x: Int\nout x";
        let (file, _) = tessla_syntax::parse(spec, tessla_syntax::source::FileId::default());
        let resolved = Resolved::new(std::slice::from_ref(&file));
        let Err(errors) = check(&resolved) else {
            panic!("an input of type Int was accepted");
        };
        assert_eq!(errors.len(), 1);
        assert_eq!(errors[0].message, "input `x` must have a type Events[T]");
    }

    #[test]
    fn the_type_table_has_inputs_outputs_and_defs() {
        let spec = "in x: Events[Int]\nliftable def f(a: Int) = (a, true)\ndef g = f(x)\nout g\nout f(x) as h\nout *";
        let (file, diags) = tessla_syntax::parse(spec, tessla_syntax::source::FileId::default());
        assert!(diags.is_empty());
        let resolved = Resolved::new(std::slice::from_ref(&file));
        let Ok(types) = check(&resolved) else {
            panic!("a well-typed spec was rejected");
        };
        let pair = Type::Tuple(vec![Type::Int, Type::Bool]);
        assert_eq!(types.defs.get("g"), Some(&pair));
        assert_eq!(types.inputs, vec![Type::Int]);
        assert_eq!(types.outputs.len(), 2);
        assert!(types.outputs.values().all(|t| *t == pair));
    }
}
