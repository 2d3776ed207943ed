//! The bundled prelude (`crates/tessla-engine/prelude/*.tessla`) proved against the library
//! corpus before the engine can load it itself.
//!
//! Every case of `tests/fixtures/stdlib/` and `tests/fixtures/userspecs/` runs through the real
//! binary (`tessla-telegraf trace`) with a spec made of the case's own text followed by the
//! prelude, arranged so that today's engine accepts it:
//!
//! - each module `M` becomes `P_M` (today's engine resolves `List.size` to a user module named
//!   `List` once there is one), and every `M.name` the prelude defines is rewritten to
//!   `P_M.name`, in the case and in the prelude;
//! - a primitive (`def f(..): T = extern("X")`) becomes a call of a top-level shim `__prim_X` that
//!   calls today's builtin `X` (or the operator syntax behind it); a primitive today's engine
//!   lacks stays an `extern` and fails when it is evaluated (that is what the engine must add);
//!   `last` and `delay` are left out of the modules, since a shim would lose their laziness, and
//!   references fall through to the builtins;
//! - TeSSLa imports `StreamFunctions`, `Option`, `PrimitiveFunctions` and `Types` unqualified:
//!   each of their non-primitive definitions is also copied to the top level (a case's own
//!   top-level definition of the same name wins), so the case runs the prelude's definition,
//!   not today's builtin of that name.
//!
//! The generated specs are kept in `target/prelude-specs/` for reading. Prints `N of M pass` and
//! each failure, writes `target/prelude-summary.txt`, fails when a case of
//! `tests/prelude-pass.txt` stops passing; `UPDATE_STDLIB=1` (`make stdlib`) rewrites the list.

use crate::support::stdlib_cases;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use stdlib_cases::{fixtures, library_and_user_cases, names, report, root, run_all, run_case_as};

/// The modules TeSSLa's prelude imports unqualified.
const IMPORTED: &[&str] = &["StreamFunctions", "Option", "PrimitiveFunctions", "Types"];

/// Primitives today's engine has under the same name (a shim calls them).
const TODAY: &[&str] = &[
    "nil",
    "default",
    "defaultFrom",
    "time",
    "last",
    "delay",
    "merge",
    "lift1",
    "lift2",
    "lift3",
    "lift4",
    "lift5",
    "slift1",
    "slift2",
    "slift3",
    "slift4",
    "slift5",
    "toString",
    "pow",
    "log",
    "sin",
    "cos",
    "tan",
    "atan",
    "intToFloat",
    "floatToInt",
    "None",
    "Some",
    "isNone",
    "getSome",
    "List.empty",
    "List.append",
    "List.prepend",
    "List.get",
    "List.set",
    "List.size",
    "List.tail",
    "List.init",
    "List.fold",
    "Set.empty",
    "Set.add",
    "Set.contains",
    "Set.remove",
    "Set.size",
    "Set.fold",
    "Map.empty",
    "Map.add",
    "Map.contains",
    "Map.get",
    "Map.remove",
    "Map.size",
    "Map.keys",
    "Map.fold",
    "String.concat",
];

/// Primitives today's engine reaches only through syntax: `{0}`, `{1}`, ... are the arguments.
const SYNTAX: &[(&str, &str)] = &[
    ("true", "true"),
    ("false", "false"),
    ("not", "!{0}"),
    ("ite", "if {0} then {1} else {2}"),
    ("staticite", "static if {0} then {1} else {2}"),
    ("and", "{0} && {1}"),
    ("or", "{0} || {1}"),
    ("eq", "{0} == {1}"),
    ("neq", "{0} != {1}"),
    ("gt", "{0} > {1}"),
    ("lt", "{0} < {1}"),
    ("geq", "{0} >= {1}"),
    ("leq", "{0} <= {1}"),
    ("fgt", "{0} >. {1}"),
    ("flt", "{0} <. {1}"),
    ("fgeq", "{0} >=. {1}"),
    ("fleq", "{0} <=. {1}"),
    ("add", "{0} + {1}"),
    ("sub", "{0} - {1}"),
    ("mul", "{0} * {1}"),
    ("div", "{0} / {1}"),
    ("mod", "{0} % {1}"),
    ("negate", "-{0}"),
    ("bitand", "{0} & {1}"),
    ("bitor", "{0} | {1}"),
    ("bitxor", "{0} ^ {1}"),
    ("bitflip", "~{0}"),
    ("leftshift", "{0} << {1}"),
    ("rightshift", "{0} >> {1}"),
    ("fadd", "{0} +. {1}"),
    ("fsub", "{0} -. {1}"),
    ("fmul", "{0} *. {1}"),
    ("fdiv", "{0} /. {1}"),
    ("fnegate", "-.{0}"),
];

/// Primitives whose laziness a shim would lose: left out of the modules.
const LAZY: &[&str] = &["last", "delay"];

/// Types today's engine knows: their `type X = extern("X")` lines are left out.
const TODAY_TYPES: &[&str] = &[
    "Bool", "Int", "Float", "String", "Unit", "Events", "Option", "List", "Set", "Map",
];

/// One `def` of a prelude module.
#[derive(Debug, Clone)]
struct Def {
    name: String,
    /// The whole block, as written (two spaces of indentation).
    text: String,
    /// For a primitive: the extern name and the header between the name and ` = extern(`.
    primitive: Option<(String, String)>,
    liftable: bool,
}

#[derive(Debug, Default)]
struct Prelude {
    /// Module name -> its definitions, in order.
    modules: BTreeMap<String, Vec<Def>>,
    /// Top-level `type` lines.
    types: Vec<String>,
}

fn prelude_dir() -> PathBuf {
    root().join("crates/tessla-engine/prelude")
}

fn ident_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

fn ident_at(s: &str) -> String {
    s.chars().take_while(|c| ident_char(*c)).collect()
}

/// Read every prelude file: `module M {` ... `}` at column 0, defs at two spaces.
fn load_prelude() -> Prelude {
    let mut p = Prelude::default();
    let mut files: Vec<PathBuf> = std::fs::read_dir(prelude_dir())
        .expect("crates/tessla-engine/prelude")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "tessla"))
        .collect();
    files.sort();
    for file in files {
        let text = std::fs::read_to_string(&file).expect("read a prelude file");
        let mut module: Option<String> = None;
        let mut defs: Vec<Def> = Vec::new();
        for line in text.lines() {
            if let Some(rest) = line.strip_prefix("module ") {
                module = Some(ident_at(rest));
                defs.clear();
                continue;
            }
            if module.is_some() && line.starts_with('}') {
                if let Some(m) = module.take() {
                    p.modules.insert(m, std::mem::take(&mut defs));
                }
                continue;
            }
            if module.is_none() {
                if line.starts_with("type ") {
                    p.types.push(line.to_string());
                }
                continue;
            }
            let (liftable, after) = match line
                .strip_prefix("  liftable def ")
                .map(|r| (true, r))
                .or_else(|| line.strip_prefix("  def ").map(|r| (false, r)))
            {
                Some(x) => x,
                None => {
                    if let Some(d) = defs.last_mut() {
                        d.text.push('\n');
                        d.text.push_str(line);
                    }
                    continue;
                }
            };
            let name = ident_at(after);
            let primitive = after.find(" = extern(\"").map(|at| {
                let header = after[name.len()..at].to_string();
                let ext = after[at + " = extern(\"".len()..]
                    .split('"')
                    .next()
                    .unwrap_or_default()
                    .to_string();
                (ext, header)
            });
            defs.push(Def {
                name,
                text: line.to_string(),
                primitive,
                liftable,
            });
        }
    }
    p
}

/// The balanced bracket group at the start of `s` (`open` first): (inside, rest).
fn group(s: &str, open: char, close: char) -> Option<(&str, &str)> {
    if !s.starts_with(open) {
        return None;
    }
    let mut depth = 0;
    for (i, c) in s.char_indices() {
        if c == open {
            depth += 1;
        } else if c == close {
            depth -= 1;
            if depth == 0 {
                return Some((&s[1..i], &s[i + 1..]));
            }
        }
    }
    None
}

/// Split at commas outside brackets.
fn split_top(s: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut depth = 0i32;
    let mut cur = String::new();
    for c in s.chars() {
        match c {
            '(' | '[' => depth += 1,
            ')' | ']' => depth -= 1,
            _ => {}
        }
        if c == ',' && depth == 0 {
            out.push(cur.trim().to_string());
            cur.clear();
        } else {
            cur.push(c);
        }
    }
    if !cur.trim().is_empty() {
        out.push(cur.trim().to_string());
    }
    out
}

/// A primitive's header `[T](a: X, b: Y): R` -> (type parameter names, parameter names or None
/// for a constant).
fn header_names(header: &str) -> (Vec<String>, Option<Vec<String>>) {
    let mut rest = header;
    let mut tparams = Vec::new();
    if let Some((inside, r)) = group(rest, '[', ']') {
        tparams = split_top(inside);
        rest = r;
    }
    let params = group(rest, '(', ')').map(|(inside, _)| {
        split_top(inside)
            .iter()
            .map(|p| p.split(':').next().unwrap_or_default().trim().to_string())
            .collect()
    });
    (tparams, params)
}

fn shim_name(ext: &str) -> String {
    format!("__prim_{}", ext.replace('.', "_"))
}

/// How a primitive's body calls its shim: `(a, b)`, `[T]` or nothing.
fn call_suffix(tparams: &[String], params: &Option<Vec<String>>) -> String {
    match params {
        Some(ps) => format!("({})", ps.join(", ")),
        None if !tparams.is_empty() => format!("[{}]", tparams.join(", ")),
        None => String::new(),
    }
}

/// The shim's body for extern `ext`, if today's engine can express it.
fn shim_body(ext: &str, tparams: &[String], params: &Option<Vec<String>>) -> Option<String> {
    if let Some((_, template)) = SYNTAX.iter().find(|(n, _)| *n == ext) {
        let mut body = template.to_string();
        for (i, p) in params.iter().flatten().enumerate() {
            body = body.replace(&format!("{{{i}}}"), p);
        }
        return Some(body);
    }
    TODAY
        .contains(&ext)
        .then(|| format!("{ext}{}", call_suffix(tparams, params)))
}

/// Rewrite `M.name` to `P_M.name` wherever module `M` of the prelude defines `name`.
fn qualify(text: &str, defined: &BTreeMap<String, BTreeSet<String>>) -> String {
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    let bytes = text.as_bytes();
    while i < text.len() {
        let boundary = i == 0 || {
            let prev = bytes[i - 1] as char;
            !ident_char(prev) && prev != '.'
        };
        if boundary {
            let word = ident_at(&text[i..]);
            if !word.is_empty() {
                let after = &text[i + word.len()..];
                if let (Some(names), Some(member)) = (defined.get(&word), after.strip_prefix('.'))
                    && names.contains(&ident_at(member))
                {
                    out.push_str("P_");
                }
                out.push_str(&word);
                i += word.len();
                continue;
            }
        }
        let c = text[i..].chars().next().unwrap_or(' ');
        out.push(c);
        i += c.len_utf8();
    }
    out
}

/// Names a case defines at the top level (`def NAME` at column 0).
fn top_level_defs(case: &str) -> BTreeSet<String> {
    case.lines()
        .filter_map(|l| {
            l.strip_prefix("def ")
                .or_else(|| l.strip_prefix("liftable def "))
        })
        .map(|r| ident_at(r.trim_start()))
        .collect()
}

/// The prelude text to append to a case, arranged for today's engine.
fn prelude_for(p: &Prelude, case: &str) -> (String, BTreeMap<String, BTreeSet<String>>) {
    let mut defined: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (m, defs) in &p.modules {
        let kept = defs
            .iter()
            .filter(|d| {
                !d.primitive
                    .as_ref()
                    .is_some_and(|(ext, _)| LAZY.contains(&ext.as_str()))
            })
            .map(|d| d.name.clone())
            .collect();
        defined.insert(m.clone(), kept);
    }
    let mut shims: BTreeMap<String, String> = BTreeMap::new();
    let mut out = String::from("\n-- ---- the prelude, arranged for today's engine ----\n");
    for line in &p.types {
        let name = ident_at(line.trim_start_matches("type "));
        if !TODAY_TYPES.contains(&name.as_str()) {
            out.push_str(line);
            out.push('\n');
        }
    }
    for (m, defs) in &p.modules {
        out.push_str(&format!("module P_{m} {{\n"));
        for d in defs {
            match &d.primitive {
                Some((ext, _)) if LAZY.contains(&ext.as_str()) => {}
                Some((ext, header)) => {
                    let (tparams, params) = header_names(header);
                    match shim_body(ext, &tparams, &params) {
                        Some(body) => {
                            let shim = shim_name(ext);
                            shims
                                .entry(shim.clone())
                                .or_insert_with(|| format!("def {shim}{header} = {body}\n"));
                            let kw = if d.liftable { "liftable def" } else { "def" };
                            out.push_str(&format!(
                                "  {kw} {}{header} = {shim}{}\n",
                                d.name,
                                call_suffix(&tparams, &params)
                            ));
                        }
                        None => {
                            out.push_str(&d.text);
                            out.push('\n');
                        }
                    }
                }
                None => {
                    out.push_str(&qualify(&d.text, &defined));
                    out.push('\n');
                }
            }
        }
        out.push_str("}\n");
    }
    let own = top_level_defs(case);
    out.push_str("-- the unqualified imports\n");
    for m in IMPORTED {
        for d in p.modules.get(*m).into_iter().flatten() {
            if d.primitive.is_none() && !own.contains(&d.name) {
                let text: Vec<&str> = d
                    .text
                    .lines()
                    .map(|l| l.strip_prefix("  ").unwrap_or(l))
                    .collect();
                out.push_str(&qualify(&text.join("\n"), &defined));
                out.push('\n');
            }
        }
    }
    out.push_str("-- shims: the primitives as today's engine provides them\n");
    for s in shims.values() {
        out.push_str(s);
    }
    (out, defined)
}

/// Write the case's spec with the prelude around it; the case's own text stays first, so its
/// line numbers are unchanged.
fn build_spec(p: &Prelude, id: &str, case: &Path) -> Result<PathBuf, String> {
    let text =
        std::fs::read_to_string(case).map_err(|e| format!("read {}: {e}", case.display()))?;
    let (prelude, defined) = prelude_for(p, &text);
    let spec = format!("{}\n{prelude}", qualify(&text, &defined));
    let path = root()
        .join("target/prelude-specs")
        .join(format!("{}.tessla", id.replace('/', "__")));
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    }
    std::fs::write(&path, spec).map_err(|e| e.to_string())?;
    Ok(path)
}

#[test]
fn prelude_defines_every_library_name() {
    let p = load_prelude();
    let modules: BTreeSet<String> = names().into_iter().map(|(m, _)| m).collect();
    let strays: Vec<&String> = p.modules.keys().filter(|m| !modules.contains(*m)).collect();
    assert!(
        strays.is_empty(),
        "prelude modules NAMES.txt does not know: {strays:?}"
    );
    // Every public value name of NAMES.txt is defined by the prelude (types and annotations are
    // the engine's own).
    let text = std::fs::read_to_string(fixtures().join("stdlib/NAMES.txt")).unwrap_or_default();
    let mut missing = Vec::new();
    for l in text
        .lines()
        .filter(|l| !l.starts_with('#') && l.contains('|'))
    {
        let cols: Vec<&str> = l.split('|').map(str::trim).collect();
        if cols.len() < 3 || matches!(cols[2], "type" | "annotation") {
            continue;
        }
        let defined = p
            .modules
            .get(cols[0])
            .is_some_and(|defs| defs.iter().any(|d| d.name == cols[1]));
        if !defined {
            missing.push(format!("{}.{}", cols[0], cols[1]));
        }
    }
    assert!(
        missing.is_empty(),
        "library names the prelude lacks: {missing:?}"
    );
}

#[test]
fn library_cases_with_the_prelude() {
    let p = load_prelude();
    let _ = std::fs::remove_dir_all(root().join("target/prelude-specs"));
    let cases = library_and_user_cases();
    // Build every spec first (the workers only run them).
    let mut built = BTreeMap::new();
    for (id, case) in &cases {
        built.insert(case.clone(), build_spec(&p, id, case));
    }
    let _ = SPECS.set(built);
    let results = run_all(cases, run_with_prelude);
    // What the prelude adds over today's engine alone (its pass list: tests/stdlib-pass.txt).
    let today: BTreeSet<String> = std::fs::read_to_string(root().join("tests/stdlib-pass.txt"))
        .unwrap_or_default()
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|l| l.trim().to_string())
        .collect();
    let failing_today: Vec<&String> = results.keys().filter(|id| !today.contains(*id)).collect();
    let fixed = failing_today
        .iter()
        .filter(|id| results.get(**id).is_some_and(Result::is_ok))
        .count();
    eprintln!(
        "of the {} cases today's engine alone fails, {fixed} pass with the prelude",
        failing_today.len()
    );
    report(
        "library and user specs with the prelude",
        &results,
        "tests/prelude-pass.txt",
        "prelude-summary.txt",
    );
}

/// Case spec -> the spec built for it (`run_all` takes a plain function).
static SPECS: OnceLock<BTreeMap<PathBuf, Result<PathBuf, String>>> = OnceLock::new();

fn run_with_prelude(case: &Path) -> Result<(), String> {
    let spec = SPECS
        .get()
        .and_then(|m| m.get(case).cloned())
        .unwrap_or_else(|| Err("no spec built".into()))?;
    run_case_as(case, &spec)
}
