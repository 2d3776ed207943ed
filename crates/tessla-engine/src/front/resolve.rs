//! Name resolution, the first pass after parsing: the statements of every file (includes first,
//! the prelude last) flattened into one program with module prefixes, its global definitions in
//! one arena with ids, imports, inputs, outputs, declared types and annotation definitions, and
//! the rule by which a global name is found from inside a module.
//!
//! Owns: [`Resolved`] (built once per spec by [`Resolved::new`]), [`DefId`], the global lookup
//! rule ([`Resolved::global`]) and the diagnostics of names at the statement level (annotation
//! definitions twice or inside a module, an annotation used as the other kind (`@` for `@@`),
//! and TeSSLa's multiple definitions rule: a name defined twice in one scope, be it a
//! definition, an input, a parameter or a record field). Both later passes look global names
//! up only here: the type checker (`typeck/`) and the lowering (`lower/`); local names
//! (parameters, blocks, `where`, macro arguments) are each pass's own, and the types of
//! definitions the checker's.

use std::collections::HashMap;
use tessla_syntax::ast::{self, Def, Ident, Out, Statement};
use tessla_syntax::diag::{Category, Diagnostic};

/// The index of a global definition in [`Resolved::defs`].
pub type DefId = usize;

/// A global definition: a top-level `def` or one inside a module.
#[derive(Debug)]
pub struct GlobalDef<'a> {
    pub def: &'a Def,
    /// The module prefix it is defined in (`""` at the top level, `A.B.` in `module B` inside
    /// `module A`); names in its body are looked up from there.
    pub prefix: String,
}

/// What a global name refers to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Global {
    Def(DefId),
    /// The index of an input in [`Resolved::inputs`].
    Input(usize),
}

/// A spec's statements, flattened and resolved at the statement level.
#[derive(Debug, Default)]
pub struct Resolved<'a> {
    /// Every statement with the module prefix it stands in, in the order TeSSLa reads them
    /// (each module's statements after the statements of the level around it).
    pub statements: Vec<(String, &'a Statement)>,
    /// Global definitions in that order; the first of two with one dotted name wins (the
    /// second is in `diagnostics`).
    pub defs: Vec<GlobalDef<'a>>,
    by_name: HashMap<String, DefId>,
    /// Every module by its full prefix (`A.`, `A.B.`).
    modules: std::collections::HashSet<String>,
    /// `in NAME: TYPE`, in order.
    pub inputs: Vec<(&'a Ident, &'a ast::Type)>,
    /// Input by name (a later input of the same name wins).
    input_by_name: HashMap<String, usize>,
    /// (importing module prefix, imported module prefix).
    pub imports: Vec<(String, String)>,
    /// `out EXPR`, in order.
    pub outputs: Vec<&'a Out>,
    /// Whether the spec has `out *`.
    pub out_all: bool,
    /// Names declared with `type` anywhere (modules included) with their number of type
    /// parameters.
    pub declared_types: HashMap<String, usize>,
    /// `def @Name(..)` (false) and `def @@Name(..)` (true) by (name, global): the parameters.
    pub annotations: HashMap<(String, bool), &'a [ast::Param]>,
    /// Annotation definitions twice or inside a module, names defined twice in one scope.
    pub diagnostics: Vec<Diagnostic>,
    /// The file of the bundled prelude, when the spec needs it: its definitions write in
    /// TeSSLa what TeSSLa's library declares `extern` (a liftable `List.map` taking a function).
    pub library: Option<tessla_syntax::source::FileId>,
}

impl<'a> Resolved<'a> {
    /// The annotations used in the spec, statement by statement: those of an `in`, `out` or
    /// `out *` (false), and each global `@@` annotation (true).
    pub fn annotation_uses(&self) -> impl Iterator<Item = (&'a [ast::Annotation], bool)> + '_ {
        self.statements.iter().filter_map(|&(_, s)| match s {
            Statement::In { annotations, .. } | Statement::OutAll { annotations, .. } => {
                Some((annotations.as_slice(), false))
            }
            Statement::Out(o) => Some((o.annotations.as_slice(), false)),
            Statement::GlobalAnnotation(a) => Some((std::slice::from_ref(a), true)),
            _ => None,
        })
    }

    /// Flatten and resolve the statements of `files` (the unit tests' way in).
    #[cfg(test)]
    pub fn new(files: &'a [ast::File]) -> Self {
        Self::with_library(files, None)
    }

    /// [`Resolved::new`] where `library` is the file of the bundled prelude (see
    /// [`Resolved::library`]): a spec's own definition of a name wins over the prelude's.
    pub fn with_library(
        files: &'a [ast::File],
        library: Option<tessla_syntax::source::FileId>,
    ) -> Self {
        let mut r = Resolved {
            library,
            ..Resolved::default()
        };
        for f in files {
            collect_type_names(&f.statements, &mut r.declared_types);
        }
        for f in files {
            r.statements
                .extend(f.statements.iter().map(|s| (String::new(), s)));
        }
        let mut first_annotation: HashMap<(String, bool), tessla_syntax::source::Span> =
            HashMap::new();
        // The first definition or input of each dotted name, for TeSSLa's multiple
        // definitions rule (an input is a top-level name like a definition).
        let mut first_name: HashMap<String, tessla_syntax::source::Span> = HashMap::new();
        let mut import_spans = Vec::new();
        let mut i = 0;
        while let Some((prefix, s)) = r.statements.get(i).cloned() {
            i += 1;
            match s {
                Statement::Def(d) => {
                    let name = format!("{prefix}{}", d.name.name);
                    r.define(&mut first_name, name.clone(), &d.name);
                    multiple_definitions_in_def(d, &mut r.diagnostics);
                    if let std::collections::hash_map::Entry::Vacant(slot) = r.by_name.entry(name) {
                        slot.insert(r.defs.len());
                        r.defs.push(GlobalDef { def: d, prefix });
                    }
                }
                Statement::Module {
                    name,
                    statements: inner,
                    ..
                } => {
                    let inner_prefix = format!("{prefix}{}.", name.name);
                    r.modules.insert(inner_prefix.clone());
                    r.statements
                        .extend(inner.iter().map(|st| (inner_prefix.clone(), st)));
                }
                Statement::Import { path, span } => {
                    let target: String = path.iter().map(|p| format!("{}.", p.name)).collect();
                    import_spans.push(*span);
                    r.imports.push((prefix, target));
                }
                Statement::In { span, .. } | Statement::OutAll { span, .. }
                    if !prefix.is_empty() =>
                {
                    r.diagnostics.push(in_out_in_module(*span));
                }
                Statement::Out(o) if !prefix.is_empty() => {
                    r.diagnostics.push(in_out_in_module(o.expr.span));
                }
                Statement::In { name, ty, .. } => {
                    r.define(&mut first_name, format!("{prefix}{}", name.name), name);
                    multiple_definitions_in_type(ty, &mut r.diagnostics);
                    r.input_by_name.insert(name.name.clone(), r.inputs.len());
                    r.inputs.push((name, ty));
                }
                Statement::Out(o) => {
                    multiple_definitions_in_expr(&o.expr, &mut r.diagnostics);
                    r.outputs.push(o);
                }
                Statement::OutAll { .. } => r.out_all = true,
                Statement::AnnotationDef {
                    name,
                    params,
                    global,
                    span,
                } => {
                    let key = (name.name.clone(), *global);
                    if !prefix.is_empty() {
                        r.diagnostics.push(
                            Diagnostic::error(
                                Category::Name,
                                Some(*span),
                                format!(
                                    "annotation `{}` is defined inside a module",
                                    at(name, *global)
                                ),
                            )
                            .with_label("inside a module")
                            .with_help("define annotations at the top level of the spec"),
                        );
                    } else if let Some(first) = first_annotation.get(&key) {
                        r.diagnostics.push(
                            Diagnostic::error(
                                Category::Name,
                                Some(name.span),
                                format!("annotation `{}` is defined twice", at(name, *global)),
                            )
                            .with_label("defined again here")
                            .with_note_at(*first, "first defined here")
                            .with_help("remove one of the definitions"),
                        );
                    } else {
                        first_annotation.insert(key.clone(), *span);
                        r.annotations.insert(key, params);
                    }
                }
                Statement::TypeDef { .. } | Statement::GlobalAnnotation(_) => {}
            }
        }
        r.ambiguous_imports(&import_spans);
        r.annotation_kinds();
        r
    }

    /// TeSSLa's two kinds of annotations: one defined by `def @A` annotates an `in` or `out`,
    /// one defined by `def @@A` stands on its own; a use of the other kind is reported.
    fn annotation_kinds(&mut self) {
        let mut found = Vec::new();
        for (anns, global) in self.annotation_uses() {
            for a in anns {
                let name = &a.name.name;
                if self.annotations.contains_key(&(name.clone(), global))
                    || !self.annotations.contains_key(&(name.clone(), !global))
                {
                    continue;
                }
                let (msg, help) = if global {
                    (
                        format!(
                            "`@{name}` annotates an `in` or `out`; it cannot be used as a global `@@{name}` annotation"
                        ),
                        format!(
                            "write `@{name}(...)` before an `in` or `out`, or define `def @@{name}` for a global one"
                        ),
                    )
                } else {
                    (
                        format!(
                            "`@@{name}` is a global annotation; it cannot annotate an `in` or `out`"
                        ),
                        format!(
                            "write `@@{name}(...)` on a line of its own, or define `def @{name}` to annotate streams"
                        ),
                    )
                };
                found.push(
                    Diagnostic::error(Category::Name, Some(a.name.span), msg)
                        .with_label("the other kind of annotation")
                        .with_help(help),
                );
            }
        }
        self.diagnostics.extend(found);
    }

    /// TeSSLa's rule: two imports into one module may not bring the same name (`import Bar`
    /// and `import Baz` both defining `foo`); the later import is reported.
    fn ambiguous_imports(&mut self, spans: &[tessla_syntax::source::Span]) {
        let mut seen: HashMap<(String, String), String> = HashMap::new();
        for (k, (at, target)) in self.imports.iter().enumerate() {
            let relative = format!("{at}{target}");
            let module = if self.modules.contains(&relative) {
                relative
            } else {
                target.clone()
            };
            let mut names: Vec<&str> = self
                .by_name
                .keys()
                .filter_map(|n| n.strip_prefix(module.as_str()))
                .filter(|n| !n.contains('.'))
                .collect();
            names.sort_unstable();
            for n in names {
                let key = (at.clone(), n.to_string());
                match seen.get(&key) {
                    Some(first) if *first != module => {
                        let shown = |m: &str| m.trim_end_matches('.').to_string();
                        self.diagnostics.push(
                            Diagnostic::error(
                                Category::Name,
                                spans.get(k).copied(),
                                format!(
                                    "cannot import `{n}` from `{}`: `{n}` is already imported \
                                     from `{}`",
                                    shown(&module),
                                    shown(first)
                                ),
                            )
                            .with_label("ambiguous import")
                            .with_help(format!(
                                "drop one of the imports and write `{}.{n}` where it is meant",
                                shown(&module)
                            )),
                        );
                        break;
                    }
                    Some(_) => {}
                    None => {
                        seen.insert(key, module.clone());
                    }
                }
            }
        }
    }

    /// Note the definition (or input) `ident` of the dotted name `name`: a second one of a
    /// name in one scope is TeSSLa's multiple definitions error.
    fn define(
        &mut self,
        first: &mut HashMap<String, tessla_syntax::source::Span>,
        name: String,
        ident: &Ident,
    ) {
        match first.get(&name) {
            // The prelude's definition of a name the spec defines itself is not used.
            Some(_) if self.library == Some(ident.span.file) => {}
            Some(at) => self.diagnostics.push(defined_twice(ident, *at)),
            None => {
                first.insert(name, ident.span);
            }
        }
    }

    /// The global definition with the dotted name `name` (`A.B.x`).
    pub fn def_id(&self, name: &str) -> Option<DefId> {
        self.by_name.get(name).copied()
    }

    /// The dotted name of a global definition.
    pub fn name(&self, id: DefId) -> Option<String> {
        self.defs
            .get(id)
            .map(|g| format!("{}{}", g.prefix, g.def.name.name))
    }

    /// A global by name as seen from module `prefix`, level by level from the module outwards
    /// (`A.B.`, `A.`, the top level): at each level its own definitions (a nested module's by
    /// their relative path, `Limits.maxSpeed` in `Robot`), at the top level then the inputs,
    /// then the members of the modules imported at that level, in import order. So a module's
    /// own definitions win over what it imports, and what it imports wins over the levels
    /// around it (TeSSLa's `misc/imports` case). An imported path is taken relative to the
    /// importing module when such a module exists, else from the top level.
    pub fn global(&self, name: &str, prefix: &str) -> Option<Global> {
        let mut p = prefix;
        let mut key = String::with_capacity(prefix.len() + name.len() + 32);
        loop {
            key.clear();
            key.push_str(p);
            key.push_str(name);
            if let Some(d) = self.by_name.get(&key) {
                return Some(Global::Def(*d));
            }
            if p.is_empty()
                && let Some(i) = self.input_by_name.get(name)
            {
                return Some(Global::Input(*i));
            }
            for (_, target) in self.imports.iter().filter(|(at, _)| at == p) {
                key.clear();
                key.push_str(p);
                key.push_str(target);
                if !self.modules.contains(&key) {
                    key.clear();
                    key.push_str(target);
                }
                key.push_str(name);
                if let Some(d) = self.by_name.get(&key) {
                    return Some(Global::Def(*d));
                }
            }
            if p.is_empty() {
                return None;
            }
            let trimmed = p.strip_suffix('.').unwrap_or(p);
            p = trimmed.rfind('.').map_or("", |k| &p[..=k]);
        }
    }

    /// Does `head` name a module as seen from module `prefix` (own and enclosing modules, the
    /// top level, imported modules)?
    #[cfg(test)]
    pub fn is_module(&self, head: &str, prefix: &str) -> bool {
        let mut p = prefix.to_string();
        loop {
            if self.modules.contains(&format!("{p}{head}.")) {
                return true;
            }
            if p.is_empty() {
                break;
            }
            let trimmed = p.trim_end_matches('.');
            p = trimmed
                .rfind('.')
                .map_or_else(String::new, |k| format!("{}.", &trimmed[..k]));
        }
        self.imports.iter().any(|(at, target)| {
            prefix.starts_with(at.as_str())
                && (self.modules.contains(&format!("{at}{target}{head}."))
                    || self.modules.contains(&format!("{target}{head}.")))
        })
    }

    /// Every global name visible from module `prefix` by its short name (for "did you mean").
    pub fn visible_names(&self, prefix: &str) -> impl Iterator<Item = &str> {
        self.by_name
            .keys()
            .filter_map(move |k| k.strip_prefix(prefix))
            .chain(self.input_by_name.keys().map(String::as_str))
    }
}

/// TeSSLa's rule: `in` and `out` only at the top level.
fn in_out_in_module(span: tessla_syntax::source::Span) -> Diagnostic {
    Diagnostic::error(
        Category::Name,
        Some(span),
        "inputs and outputs are not allowed inside a module",
    )
    .with_label("inside a module")
    .with_help("declare inputs and outputs at the top level of the spec, as `out Module.name`")
}

/// TeSSLa's `MultipleDefinitionsError`: `ident` is a second definition in the scope of the
/// one at `first` (a definition, input, parameter, record field).
fn defined_twice(ident: &Ident, first: tessla_syntax::source::Span) -> Diagnostic {
    Diagnostic::error(
        Category::Name,
        Some(ident.span),
        format!("`{}` is defined twice in the same scope", ident.name),
    )
    .with_label("defined again here")
    .with_note_at(first, "first defined here")
    .with_help("rename or remove one of them")
}

/// The second and later of the names in one scope, each against the first.
fn unique_names<'n>(names: impl IntoIterator<Item = &'n Ident>, out: &mut Vec<Diagnostic>) {
    let mut seen: HashMap<&str, tessla_syntax::source::Span> = HashMap::new();
    for n in names {
        match seen.get(n.name.as_str()) {
            Some(first) => out.push(defined_twice(n, *first)),
            None => {
                seen.insert(&n.name, n.span);
            }
        }
    }
}

/// Names defined twice inside a definition: its parameters, its `where` definitions, and
/// the scopes of its body.
fn multiple_definitions_in_def(d: &Def, out: &mut Vec<Diagnostic>) {
    if let Some(params) = &d.params {
        unique_names(params.iter().map(|p| &p.name), out);
        for p in params {
            if let Some(t) = &p.ty {
                multiple_definitions_in_type(t, out);
            }
        }
    }
    if let Some(t) = &d.result_type {
        multiple_definitions_in_type(t, out);
    }
    if let ast::Body::Expr { expr, where_defs } = &d.body {
        unique_names(where_defs.iter().map(|w| &w.name), out);
        for w in where_defs {
            multiple_definitions_in_def(w, out);
        }
        multiple_definitions_in_expr(expr, out);
    }
}

/// Fields named twice in a record type.
fn multiple_definitions_in_type(t: &ast::Type, out: &mut Vec<Diagnostic>) {
    match t {
        ast::Type::Name(_) => {}
        ast::Type::App { args, .. } => args
            .iter()
            .for_each(|a| multiple_definitions_in_type(a, out)),
        ast::Type::Function { params, result, .. } => {
            params
                .iter()
                .for_each(|(_, p)| multiple_definitions_in_type(p, out));
            multiple_definitions_in_type(result, out);
        }
        ast::Type::Record { fields, .. } => {
            unique_names(fields.iter().map(|(n, _)| n), out);
            fields
                .iter()
                .for_each(|(_, f)| multiple_definitions_in_type(f, out));
        }
        ast::Type::Tuple { elems, .. } => elems
            .iter()
            .for_each(|e| multiple_definitions_in_type(e, out)),
    }
}

/// Names defined twice in the scopes inside an expression: a block's definitions, a lambda's
/// parameters, a record's fields.
fn multiple_definitions_in_expr(e: &ast::Expr, out: &mut Vec<Diagnostic>) {
    use ast::ExprKind as K;
    match &e.kind {
        K::Var(_) | K::RootMember(_) | K::Int { .. } | K::Float(_) => {}
        K::Str { parts, .. } => {
            for p in parts {
                if let ast::StrPart::Interp { expr, .. } = p {
                    multiple_definitions_in_expr(expr, out);
                }
            }
        }
        K::Tuple(items) => items
            .iter()
            .for_each(|i| multiple_definitions_in_expr(i, out)),
        K::Block { defs, result } => {
            unique_names(defs.iter().map(|d| &d.name), out);
            defs.iter()
                .for_each(|d| multiple_definitions_in_def(d, out));
            multiple_definitions_in_expr(result, out);
        }
        K::Record(fields) => {
            unique_names(fields.iter().map(|(n, _)| n), out);
            fields
                .iter()
                .for_each(|(_, v)| multiple_definitions_in_expr(v, out));
        }
        K::Call {
            function,
            type_args,
            args,
        } => {
            multiple_definitions_in_expr(function, out);
            type_args
                .iter()
                .for_each(|t| multiple_definitions_in_type(t, out));
            for a in args.iter().flatten() {
                multiple_definitions_in_expr(&a.value, out);
            }
        }
        K::Member { object, .. } => multiple_definitions_in_expr(object, out),
        K::Unary { operand, .. } => multiple_definitions_in_expr(operand, out),
        K::Binary { lhs, rhs, .. } => {
            multiple_definitions_in_expr(lhs, out);
            multiple_definitions_in_expr(rhs, out);
        }
        K::If {
            cond,
            then_branch,
            else_branch,
            ..
        } => {
            multiple_definitions_in_expr(cond, out);
            multiple_definitions_in_expr(then_branch, out);
            multiple_definitions_in_expr(else_branch, out);
        }
        K::Lambda { params, body } => {
            unique_names(params.iter().map(|p| &p.name), out);
            for p in params {
                if let Some(t) = &p.ty {
                    multiple_definitions_in_type(t, out);
                }
            }
            multiple_definitions_in_expr(body, out);
        }
    }
}

/// An annotation's name as written at its use: `@Name` or `@@Name`.
pub fn at(name: &Ident, global: bool) -> String {
    format!("{}{}", if global { "@@" } else { "@" }, name.name)
}

/// The names of every `type` declaration in `statements` and the modules inside them, with
/// their number of type parameters.
fn collect_type_names(statements: &[Statement], out: &mut HashMap<String, usize>) {
    for s in statements {
        match s {
            Statement::TypeDef {
                name, type_params, ..
            } => {
                out.insert(name.name.clone(), type_params.len());
            }
            Statement::Module { statements, .. } => collect_type_names(statements, out),
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(spec: &str) -> ast::File {
        let (file, diags) = tessla_syntax::parse(spec, tessla_syntax::source::FileId::default());
        assert!(diags.is_empty(), "{diags:?}");
        file
    }

    #[test]
    fn modules_imports_and_inputs_resolve_from_where_they_are_used() {
        let files = [parse(
            "in x: Events[Int]\n\
             module A {\n  def a = 1\n  module B {\n    def b = a\n  }\n}\n\
             module C {\n  import A.B\n  def c = b\n}\n\
             def a = 2\ntype T[U] = Option[U]\nout x\nout *\n",
        )];
        let r = Resolved::new(&files);
        let id = |n: &str| r.def_id(n).map(Global::Def);
        // Own module first, then enclosing modules, then the top level.
        assert_eq!(r.global("a", "A.B."), id("A.a"));
        assert_eq!(r.global("a", ""), id("a"));
        // Imports count inside the importing module only.
        assert_eq!(r.global("b", "C."), id("A.B.b"));
        assert_eq!(r.global("B.b", ""), None);
        assert_eq!(r.global("B.b", "A."), id("A.B.b"));
        assert_eq!(r.global("b", ""), None);
        assert_eq!(r.global("x", "C."), Some(Global::Input(0)));
        assert_eq!(r.defs.len(), 4);
        assert_eq!(r.name(0).as_deref(), Some("a"));
        assert_eq!(r.outputs.len(), 1);
        assert!(r.out_all);
        assert_eq!(r.declared_types.get("T"), Some(&1));
        assert!(r.is_module("A", "") && r.is_module("B", "A.") && r.is_module("A", "C."));
        assert!(!r.is_module("B", "") && !r.is_module("a", ""));
    }

    #[test]
    fn a_modules_imports_come_before_the_levels_around_it() {
        let files = [parse(
            "module X {\n  def v = 1\n}\ndef v = 2\n\
             module Y {\n  import X\n  def w = v\n}\n\
             module Q {\n  import X\n  def v = 3\n}\n\
             module Z {\n  def u = v\n}\n",
        )];
        let r = Resolved::new(&files);
        let id = |n: &str| r.def_id(n).map(Global::Def);
        assert_eq!(r.global("v", "Y."), id("X.v"));
        assert_eq!(r.global("v", "Q."), id("Q.v"));
        assert_eq!(r.global("v", "Z."), id("v"));
        assert_eq!(r.global("v", ""), id("v"));
    }

    #[test]
    fn a_name_defined_twice_in_one_scope_is_an_error_of_name_resolution() {
        let files = [parse(
            "in x: Events[Int]\nin x: Events[Int]\ndef x = 1\n\
             def f(a: Int, a: Int): Int = { def b = 1\n def b = 2\n b }\n\
             def g = (c: Int, c: Int) => c\n\
             def r: {p: Int, p: Int} = {q = 1, q = 2}\n\
             module M {\n  def x = 1\n  def y = 1\n  def y = 2\n}\nout x\n",
        )];
        let r = Resolved::new(&files);
        let names: Vec<&str> = r
            .diagnostics
            .iter()
            .map(|d| d.message.split('`').nth(1).unwrap_or(""))
            .collect();
        // Inputs and definitions share the top level; `M.x` is in another scope.
        assert_eq!(names, ["x", "x", "a", "b", "c", "p", "q", "y"]);
        assert!(
            r.diagnostics
                .iter()
                .all(|d| d.message.ends_with("is defined twice in the same scope"))
        );
    }

    #[test]
    fn annotation_definitions_are_single_and_at_the_top_level() {
        let files = [parse(
            "def @A(x: Int)\ndef @@A\ndef @A(y: Int)\nmodule M {\n  def @B\n}\nin x: Events[Int]\nout x\n",
        )];
        let r = Resolved::new(&files);
        assert_eq!(r.annotations.len(), 2);
        let msgs: Vec<&str> = r.diagnostics.iter().map(|d| d.message.as_str()).collect();
        assert_eq!(
            msgs,
            [
                "annotation `@A` is defined twice",
                "annotation `@B` is defined inside a module"
            ]
        );
    }

    #[test]
    fn an_annotation_used_as_the_other_kind_is_an_error_of_name_resolution() {
        let files = [parse(
            "def @S\ndef @@G\n@@S\n@G\nin x: Events[Int]\n@S\nout x\n@@G\n@@U\n",
        )];
        let r = Resolved::new(&files);
        let msgs: Vec<&str> = r.diagnostics.iter().map(|d| d.message.as_str()).collect();
        assert_eq!(
            msgs,
            [
                "`@S` annotates an `in` or `out`; it cannot be used as a global `@@S` annotation",
                "`@@G` is a global annotation; it cannot annotate an `in` or `out`"
            ]
        );
    }
}
