//! The bundled prelude (`crates/tessla-engine/prelude/*.tessla`): TeSSLa's standard library
//! written in TeSSLa, brought into a spec for the library names the engine has no builtin for.
//!
//! Owns: the catalog of prelude definitions (parsed once per process), the references a spec
//! makes, and the text of the definitions a spec needs (transitively), which `load` parses as one
//! extra file `<prelude>`; with it, the declarations of the library annotations a spec uses
//! (`@InstFunctionCall`, `@VisBubbles`, ...) and the `CTF` type when the spec names it; and the
//! parameter names of builtins, for named arguments. Names the builtins table has keep their builtin; a spec that uses no
//! prelude name gets no extra file at all. The prelude's folder README is the contract.
//!
//! Rules: each prelude file holds one `module M { ... }`; `M.name` reaches its definitions, and
//! the modules of [`IMPORTED`] are also imported unqualified (a spec's own definitions win). A
//! prelude definition's reference to a sibling that is a builtin (`size` in `List`, an `extern`
//! the table has) is rewritten to the builtin's name, so the builtin runs.

use crate::builtins::{self, Kind};
use std::collections::{HashMap, HashSet};
use std::sync::OnceLock;
use tessla_syntax::ast::{self, Def, Expr, ExprKind, Statement, StrPart};
use tessla_syntax::source::{FileId, Span};

/// The prelude files, in the order their modules are emitted.
const FILES: &[&str] = &[
    include_str!("../../prelude/Types.tessla"),
    include_str!("../../prelude/PrimitiveFunctions.tessla"),
    include_str!("../../prelude/Operators.tessla"),
    include_str!("../../prelude/Option.tessla"),
    include_str!("../../prelude/StreamFunctions.tessla"),
    include_str!("../../prelude/OptionUtils.tessla"),
    include_str!("../../prelude/List.tessla"),
    include_str!("../../prelude/Set.tessla"),
    include_str!("../../prelude/Map.tessla"),
    include_str!("../../prelude/String.tessla"),
    include_str!("../../prelude/LTL.tessla"),
    include_str!("../../prelude/MITL.tessla"),
    include_str!("../../prelude/CTF.tessla"),
    include_str!("../../prelude/Tessla.tessla"),
];

/// The library's annotation declarations (top-level `def @Name(...)`, as in TeSSLa): emitted
/// into a spec that uses one and does not declare it itself.
const ANNOTATION_FILES: &[&str] = &[
    include_str!("../../prelude/InstrumentationAnnotations.tessla"),
    include_str!("../../prelude/VisualizationAnnotations.tessla"),
];

/// Each library annotation's name and declaration text.
fn annotation_decls() -> &'static HashMap<String, String> {
    static DECLS: OnceLock<HashMap<String, String>> = OnceLock::new();
    DECLS.get_or_init(|| {
        let mut out = HashMap::new();
        for text in ANNOTATION_FILES {
            let (file, _) = tessla_syntax::parser::parse(text, FileId(0));
            for s in file.statements {
                if let Statement::AnnotationDef { name, span, .. } = s {
                    let decl = text
                        .get(span.start as usize..span.end as usize)
                        .unwrap_or_default();
                    out.insert(name.name.clone(), decl.to_string());
                }
            }
        }
        out
    })
}

/// Annotation names `statements` use (on inputs, outputs and globally) and declare.
fn annotation_uses(
    statements: &[Statement],
    used: &mut Vec<String>,
    declared: &mut HashSet<String>,
) {
    for s in statements {
        let anns: &[ast::Annotation] = match s {
            Statement::In { annotations, .. } | Statement::OutAll { annotations, .. } => {
                annotations
            }
            Statement::Out(o) => &o.annotations,
            Statement::GlobalAnnotation(a) => std::slice::from_ref(a),
            Statement::AnnotationDef { name, .. } => {
                declared.insert(name.name.clone());
                &[]
            }
            Statement::Module { statements, .. } => {
                annotation_uses(statements, used, declared);
                &[]
            }
            _ => &[],
        };
        used.extend(anns.iter().map(|a| a.name.name.clone()));
    }
}

/// The prelude's modules (a dotted name with another head is never a prelude name).
const MODULES: &[&str] = &[
    "Types",
    "PrimitiveFunctions",
    "Operators",
    "Option",
    "StreamFunctions",
    "OptionUtils",
    "List",
    "Set",
    "Map",
    "String",
    "LTL",
    "MITL",
    "CTF",
    "Tessla",
];

/// Whether `name` may be a prelude name the builtins table lacks; answers without building the
/// catalog, so a spec of builtins only never parses the prelude.
fn candidate(name: &str) -> bool {
    if usable_builtin(name) {
        return false;
    }
    match name.split_once('.') {
        Some((head, _)) => MODULES.contains(&head),
        None => true,
    }
}

/// The modules TeSSLa imports unqualified.
pub const IMPORTED: &[&str] = &["StreamFunctions", "Option", "PrimitiveFunctions", "Types"];

/// Names the engine resolves before its builtins table.
const SPECIAL: &[&str] = &["true", "false", "None"];

/// One prelude definition.
struct Entry {
    module: String,
    name: String,
    /// The text to emit inside `module M { }`; `None`: a builtin serves every use.
    text: Option<String>,
    /// Other entries its text refers to.
    deps: Vec<usize>,
    /// The builtin serving every use, when there is one (`List.size`, `merge` for `merge2`).
    alias: Option<String>,
    /// Its parameter names (for named arguments to the builtin).
    params: Vec<String>,
    /// Its declaration as parsed (the types of a builtin it stands for).
    decl: Def,
}

struct Catalog {
    entries: Vec<Entry>,
    /// `M.name` -> entry.
    by_key: HashMap<String, usize>,
}

/// A builtin a spec can use by name (not an `extern`-only native, not a placeholder).
fn usable_builtin(name: &str) -> bool {
    SPECIAL.contains(&name)
        || builtins::get(name).is_some_and(|b| {
            !matches!(
                b.kind,
                Kind::Extern(_) | Kind::Stream(builtins::StreamOp::Unsupported)
            )
        })
}

/// The builtin a library name stands for when the name itself is not in the builtins table
/// (`Option.None` -> `None`, `StreamFunctions.fold` -> `fold`, `merge2` -> `merge`).
pub fn builtin_alias(name: &str) -> Option<&'static str> {
    if !candidate(name) {
        return None;
    }
    let c = catalog();
    let i = if name.contains('.') {
        *c.by_key.get(name)?
    } else {
        IMPORTED
            .iter()
            .find_map(|m| c.by_key.get(&format!("{m}.{name}")).copied())?
    };
    c.entries[i].alias.as_deref().filter(|a| *a != name)
}

/// The parameter names TeSSLa gives the library function a builtin serves (`resetCount` ->
/// `events`, `reset`), for named arguments; `None` when the prelude declares no such function.
pub fn param_names(builtin: &str) -> Option<Vec<String>> {
    let c = catalog();
    let e = c
        .entries
        .iter()
        .find(|e| e.alias.as_deref() == Some(builtin))?;
    Some(e.params.clone()).filter(|p| !p.is_empty())
}

/// The declaration of the library function a builtin serves (`sum` -> `def sum(x: Events[Int]):
/// Events[Int]`), whose types are the builtin's signature; `None` when the prelude declares no
/// such function.
pub fn declaration(builtin: &str) -> Option<&'static Def> {
    catalog()
        .entries
        .iter()
        .find(|e| e.alias.as_deref() == Some(builtin))
        .map(|e| &e.decl)
}

/// The parameter names of the value function the builtins table lists as `name`
/// (`String.format` -> `formatString`, `value`): looked up by the table's key, never by the
/// native's address (the linker may merge two natives of the same body). `None` for a name the
/// table has no value function or operator under, or the prelude declares no parameters for.
pub fn native_param_names(name: &str) -> Option<Vec<String>> {
    let b = builtins::get(name)?;
    match b.kind {
        Kind::Value(_) | Kind::Operator(_) => param_names(b.name),
        _ => None,
    }
}

fn catalog() -> &'static Catalog {
    static CATALOG: OnceLock<Catalog> = OnceLock::new();
    CATALOG.get_or_init(build)
}

/// A definition as parsed: module, the def, and the file text its spans point into.
struct Raw<'a> {
    module: String,
    def: Def,
    text: &'a str,
}

fn build() -> Catalog {
    let mut raws: Vec<Raw<'static>> = Vec::new();
    for text in FILES {
        let (file, _) = tessla_syntax::parser::parse(text, FileId(0));
        for s in file.statements {
            if let Statement::Module {
                name, statements, ..
            } = s
            {
                for st in statements {
                    if let Statement::Def(def) = st {
                        raws.push(Raw {
                            module: name.name.clone(),
                            def,
                            text,
                        });
                    }
                }
            }
        }
    }
    let by_key: HashMap<String, usize> = raws
        .iter()
        .enumerate()
        .map(|(i, r)| (format!("{}.{}", r.module, r.def.name.name), i))
        .collect();
    // The builtin serving each entry, if any.
    let alias: Vec<Option<String>> = raws
        .iter()
        .map(|r| {
            let n = &r.def.name.name;
            let q = format!("{}.{n}", r.module);
            if let ast::Body::Extern { name: x, .. } = &r.def.body {
                return usable_builtin(x).then(|| x.clone());
            }
            if usable_builtin(&q) {
                Some(q)
            } else if IMPORTED.contains(&r.module.as_str()) && usable_builtin(n) {
                Some(n.clone())
            } else {
                None
            }
        })
        .collect();
    let mut entries = Vec::with_capacity(raws.len());
    for (i, r) in raws.iter().enumerate() {
        let mut refs = Vec::new();
        def_refs(&r.def, &mut Vec::new(), &mut refs);
        let mut deps = Vec::new();
        let text = match &alias[i] {
            None => {
                // Rewrite references to builtin siblings; collect the entries used.
                let mut edits: Vec<(Span, &str)> = Vec::new();
                for (name, span) in &refs {
                    let sib = (!name.contains('.'))
                        .then(|| by_key.get(&format!("{}.{name}", r.module)))
                        .flatten();
                    match sib {
                        Some(&j) => match &alias[j] {
                            Some(a) if a != name => edits.push((*span, a.as_str())),
                            Some(_) => {}
                            None => deps.push(j),
                        },
                        None => deps.extend(resolve_in(&by_key, name)),
                    }
                }
                edits.sort_by_key(|(s, _)| s.start);
                let mut out = String::new();
                let mut at = r.def.span.start as usize;
                for (s, a) in edits {
                    if (s.start as usize) < at {
                        continue;
                    }
                    out.push_str(&r.text[at..s.start as usize]);
                    out.push_str(a);
                    at = s.end as usize;
                }
                out.push_str(&r.text[at..r.def.span.end as usize]);
                Some(out)
            }
            Some(_) => None,
        };
        entries.push(Entry {
            module: r.module.clone(),
            name: r.def.name.name.clone(),
            text,
            deps,
            alias: alias[i].clone(),
            params: r
                .def
                .params
                .iter()
                .flatten()
                .map(|p| p.name.name.clone())
                .collect(),
            decl: r.def.clone(),
        });
    }
    Catalog { entries, by_key }
}

/// Every library name, qualified (`List.find`) and, for the imported modules, short (`sample`),
/// for "did you mean" listings.
pub fn names() -> Vec<String> {
    let c = catalog();
    let mut out: Vec<String> = c.by_key.keys().cloned().collect();
    for e in &c.entries {
        if IMPORTED.contains(&e.module.as_str()) {
            out.push(e.name.clone());
        }
    }
    out
}

/// The entry a reference from outside its module means (`M.name`, or an imported `name`).
fn resolve_in(by_key: &HashMap<String, usize>, name: &str) -> Option<usize> {
    if usable_builtin(name) {
        return None;
    }
    if name.contains('.') {
        return by_key.get(name).copied();
    }
    IMPORTED
        .iter()
        .find_map(|m| by_key.get(&format!("{m}.{name}")).copied())
}

/// The prelude text a spec needs (modules holding the definitions it refers to, transitively,
/// and the imports of the unqualified modules), or `None` when it needs none.
pub fn needed(files: &[ast::File]) -> Option<String> {
    let mut refs = Vec::new();
    let mut own = HashSet::new();
    for f in files {
        statement_refs(&f.statements, "", &mut refs, &mut own);
    }
    refs.retain(|(n, _)| !own.contains(n) && candidate(n));
    // TeSSLa's built-in type `CTF` (declared next to its module, as in TeSSLa): emitted when the
    // spec names it and declares no type of that name itself.
    let mut types = HashSet::new();
    for f in files {
        statement_types(&f.statements, &mut types);
    }
    let own_ctf = files.iter().any(|f| declares_type(&f.statements, CTF_TYPE));
    let mut ctf_type = !own_ctf && types.contains(CTF_TYPE);
    // Library annotations the spec uses without declaring them.
    let (mut used, mut declared) = (Vec::new(), HashSet::new());
    for f in files {
        annotation_uses(&f.statements, &mut used, &mut declared);
    }
    used.retain(|a| !declared.contains(a));
    used.sort();
    used.dedup();
    let decls: Vec<&str> = if used.is_empty() {
        Vec::new()
    } else {
        let all = annotation_decls();
        used.iter()
            .filter_map(|a| all.get(a).map(String::as_str))
            .collect()
    };
    if refs.is_empty() && !ctf_type && decls.is_empty() {
        return None;
    }
    let c = catalog();
    let mut todo: Vec<usize> = refs
        .iter()
        .filter_map(|(n, _)| resolve_in(&c.by_key, n))
        .collect();
    let mut seen = vec![false; c.entries.len()];
    while let Some(i) = todo.pop() {
        if std::mem::replace(&mut seen[i], true) || c.entries[i].text.is_none() {
            continue;
        }
        todo.extend(c.entries[i].deps.iter().copied());
    }
    let mut modules: Vec<(&str, Vec<&str>)> = Vec::new();
    for (i, e) in c.entries.iter().enumerate() {
        let Some(t) = e.text.as_deref().filter(|_| seen[i]) else {
            continue;
        };
        match modules.iter_mut().find(|(m, _)| *m == e.module) {
            Some((_, v)) => v.push(t),
            None => modules.push((&e.module, vec![t])),
        }
    }
    ctf_type |= !own_ctf && modules.iter().any(|(m, _)| *m == "CTF");
    if modules.is_empty() && !ctf_type && decls.is_empty() {
        return None;
    }
    let mut out = String::new();
    for d in decls {
        out.push_str(d);
        out.push('\n');
    }
    if ctf_type {
        out.push_str("type CTF = extern(\"CTF\")\n");
    }
    for (m, defs) in &modules {
        out.push_str(&format!("module {m} {{\n"));
        for d in defs {
            out.push_str("  ");
            out.push_str(d);
            out.push('\n');
        }
        out.push_str("}\n");
        if IMPORTED.contains(m) {
            out.push_str(&format!("import {m}\n"));
        }
    }
    Some(out)
}

/// The name of TeSSLa's opaque Common Trace Format event type.
const CTF_TYPE: &str = "CTF";

/// Whether `statements` (or a module in them) declare a type `name`.
fn declares_type(statements: &[Statement], name: &str) -> bool {
    statements.iter().any(|s| match s {
        Statement::TypeDef { name: n, .. } => n.name == name,
        Statement::Module { statements, .. } => declares_type(statements, name),
        _ => false,
    })
}

/// Type names used by the inputs and by the signatures of the definitions in `statements`.
fn statement_types(statements: &[Statement], out: &mut HashSet<String>) {
    for s in statements {
        match s {
            Statement::In { ty, .. } => type_names(ty, out),
            Statement::Def(d) => def_types(d, out),
            Statement::Module { statements, .. } => statement_types(statements, out),
            _ => {}
        }
    }
}

fn def_types(d: &Def, out: &mut HashSet<String>) {
    for p in d.params.iter().flatten() {
        if let Some(t) = &p.ty {
            type_names(t, out);
        }
    }
    if let Some(t) = &d.result_type {
        type_names(t, out);
    }
    if let ast::Body::Expr { where_defs, .. } = &d.body {
        where_defs.iter().for_each(|w| def_types(w, out));
    }
}

fn type_names(t: &ast::Type, out: &mut HashSet<String>) {
    match t {
        ast::Type::Name(id) => {
            out.insert(id.name.clone());
        }
        ast::Type::App { name, args, .. } => {
            out.insert(name.name.clone());
            args.iter().for_each(|a| type_names(a, out));
        }
        ast::Type::Function { params, result, .. } => {
            params.iter().for_each(|(_, p)| type_names(p, out));
            type_names(result, out);
        }
        ast::Type::Record { fields, .. } => fields.iter().for_each(|(_, f)| type_names(f, out)),
        ast::Type::Tuple { elems, .. } => elems.iter().for_each(|e| type_names(e, out)),
    }
}

/// References of a spec's statements; `own` collects the (dotted) names it defines.
fn statement_refs(
    statements: &[Statement],
    prefix: &str,
    refs: &mut Vec<(String, Span)>,
    own: &mut HashSet<String>,
) {
    for s in statements {
        match s {
            Statement::Def(d) => {
                own.insert(format!("{prefix}{}", d.name.name));
                def_refs(d, &mut Vec::new(), refs);
            }
            Statement::Module {
                name, statements, ..
            } => statement_refs(statements, &format!("{prefix}{}.", name.name), refs, own),
            Statement::In {
                annotations, name, ..
            } => {
                own.insert(name.name.clone());
                annotation_refs(annotations, refs);
            }
            Statement::Out(o) => {
                annotation_refs(&o.annotations, refs);
                expr_refs(&o.expr, &mut Vec::new(), refs);
            }
            Statement::OutAll { annotations, .. } => annotation_refs(annotations, refs),
            Statement::GlobalAnnotation(a) => annotation_refs(std::slice::from_ref(a), refs),
            _ => {}
        }
    }
}

fn annotation_refs(annotations: &[ast::Annotation], refs: &mut Vec<(String, Span)>) {
    for a in annotations {
        for arg in &a.args {
            expr_refs(&arg.value, &mut Vec::new(), refs);
        }
    }
}

fn def_refs(d: &Def, bound: &mut Vec<String>, refs: &mut Vec<(String, Span)>) {
    let n = bound.len();
    for p in d.params.iter().flatten() {
        bound.push(p.name.name.clone());
    }
    if let ast::Body::Expr { expr, where_defs } = &d.body {
        bound.extend(where_defs.iter().map(|w| w.name.name.clone()));
        for w in where_defs {
            def_refs(w, bound, refs);
        }
        expr_refs(expr, bound, refs);
    }
    bound.truncate(n);
}

/// Free names of `e` (not in `bound`), with `M.x` paths as one dotted name.
fn expr_refs(e: &Expr, bound: &mut Vec<String>, refs: &mut Vec<(String, Span)>) {
    match &e.kind {
        ExprKind::Var(id) => {
            if !bound.contains(&id.name) {
                refs.push((id.name.clone(), id.span));
            }
        }
        ExprKind::RootMember(id) => refs.push((id.name.clone(), id.span)),
        ExprKind::Int { .. } | ExprKind::Float(_) => {}
        ExprKind::Str { parts, .. } => {
            for p in parts {
                if let StrPart::Interp { expr, .. } = p {
                    expr_refs(expr, bound, refs);
                }
            }
        }
        ExprKind::Tuple(es) => es.iter().for_each(|x| expr_refs(x, bound, refs)),
        ExprKind::Block { defs, result } => {
            let n = bound.len();
            bound.extend(defs.iter().map(|d| d.name.name.clone()));
            for d in defs {
                def_refs(d, bound, refs);
            }
            expr_refs(result, bound, refs);
            bound.truncate(n);
        }
        ExprKind::Record(fs) => fs.iter().for_each(|(_, x)| expr_refs(x, bound, refs)),
        ExprKind::Call { function, args, .. } => {
            expr_refs(function, bound, refs);
            for a in args.iter().flatten() {
                expr_refs(&a.value, bound, refs);
            }
        }
        ExprKind::Member { object, field } => {
            if let Some(path) = object.dotted_path()
                && !bound.contains(&path.split('.').next().unwrap_or_default().to_string())
            {
                refs.push((format!("{path}.{}", field.name), e.span));
            }
            expr_refs(object, bound, refs);
        }
        ExprKind::Unary { operand, .. } => expr_refs(operand, bound, refs),
        ExprKind::Binary { lhs, rhs, .. } => {
            expr_refs(lhs, bound, refs);
            expr_refs(rhs, bound, refs);
        }
        ExprKind::If {
            cond,
            then_branch,
            else_branch,
            ..
        } => {
            expr_refs(cond, bound, refs);
            expr_refs(then_branch, bound, refs);
            expr_refs(else_branch, bound, refs);
        }
        ExprKind::Lambda { params, body } => {
            let n = bound.len();
            bound.extend(params.iter().map(|p| p.name.name.clone()));
            expr_refs(body, bound, refs);
            bound.truncate(n);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn needs(spec: &str) -> Option<String> {
        let (f, d) = tessla_syntax::parser::parse(spec, FileId(0));
        assert!(d.is_empty(), "{d:?}");
        needed(&[f])
    }

    #[test]
    fn builtins_need_no_prelude() {
        assert_eq!(
            needs("in x: Events[Int]\nout count(x)\nout List.size(List.empty[Int])"),
            None
        );
    }

    #[test]
    fn every_prelude_file_parses() {
        for text in FILES.iter().chain(ANNOTATION_FILES) {
            let (_, d) = tessla_syntax::parser::parse(text, FileId(0));
            assert!(
                d.is_empty(),
                "{d:?}\n{}",
                text.lines().next().unwrap_or_default()
            );
        }
    }

    #[test]
    fn library_annotations_and_the_ctf_type_are_declared_on_use() {
        let t = needs("@InstFunctionCall(\"main\")\nin c: Events[Unit]\n@VisBubbles\nout c")
            .unwrap_or_default();
        assert!(t.contains("def @InstFunctionCall(name: String)"), "{t}");
        assert!(t.contains("def @VisBubbles"), "{t}");
        assert!(!t.contains("@VisPlot"), "{t}");
        // A spec's own declaration wins.
        assert_eq!(
            needs("def @VisBubbles\nin c: Events[Unit]\n@VisBubbles\nout c"),
            None
        );
        let t = needs("in e: Events[CTF]\nin x: Events[Int]\nout x").unwrap_or_default();
        assert!(t.contains("type CTF = extern(\"CTF\")"), "{t}");
        assert_eq!(needs("type CTF = Int\nin e: Events[CTF]\nout e"), None);
    }

    #[test]
    fn unknown_names_bring_their_definitions() {
        let t = needs("in b: Events[Bool]\nout boolFilter(b)\nout List.find(List.empty[Int], 1)")
            .unwrap_or_default();
        assert!(t.contains("def boolFilter"), "{t}");
        assert!(t.contains("import StreamFunctions"), "{t}");
        assert!(t.contains("module List"), "{t}");
        // `size` in `List` is the builtin `List.size`.
        assert!(!t.contains("extern(\"List.size\")"), "{t}");
    }

    #[test]
    fn library_names_of_builtins_resolve_to_the_builtin() {
        assert_eq!(builtin_alias("Option.None"), Some("None"));
        assert_eq!(builtin_alias("StreamFunctions.fold"), Some("fold"));
        assert_eq!(builtin_alias("StreamFunctions.merge2"), Some("merge"));
        assert_eq!(builtin_alias("List.size"), None);
        assert_eq!(builtin_alias("count"), None);
        assert_eq!(builtin_alias("boolFilter"), None);
        assert!(names().iter().any(|n| n == "MITL.since0"));
        assert!(names().iter().any(|n| n == "sample"));
    }

    #[test]
    fn own_definitions_win() {
        assert_eq!(
            needs("in b: Events[Bool]\ndef boolFilter(x: Events[Bool]) = x\nout boolFilter(b)"),
            None
        );
    }

    #[test]
    fn natives_take_their_parameter_names_by_their_name_in_the_table() {
        // Two names of one native each take their own entry's names; a stream operator or an
        // unknown name has none here.
        assert_eq!(
            native_param_names("String.format"),
            param_names("String.format")
        );
        assert!(native_param_names("String.format").is_some());
        assert_eq!(native_param_names("last"), None);
        assert_eq!(native_param_names("no such native"), None);
    }
}
