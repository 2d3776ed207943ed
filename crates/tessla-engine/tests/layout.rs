//! The engine's house rules on imports, checked on its sources: no two modules import each other
//! (directly or round a loop), the front end reaches the runtime only through the builtins
//! table, and the runtime never imports the front end.
//!
//! A module is a file or folder under `src/` (`ir/` is one module), except that each module of
//! the folders `front/` and `runtime/` counts on its own (`front::lower`, `runtime::exec`). An import is any `crate::` path in code
//! (comments and `#[cfg(test)]` modules aside); a name the crate root re-exports counts as an
//! import of the module that defines it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The passes of the front end: they may use the runtime only through `builtins`.
const PASSES: &[&str] = &[
    "front::prelude",
    "front::resolve",
    "front::typeck",
    "front::lower",
    "front::schedule",
];
/// The folders whose modules count one by one.
const FOLDERS: &[&str] = &["front", "runtime"];
/// The data both sides share.
const SHARED: &[&str] = &["ir", "value"];

type Graph = BTreeMap<String, BTreeSet<String>>;

/// Source text without comments, string and char literals (kept as empty quotes), so braces
/// and `crate::` inside them do not count.
fn code_only(src: &str) -> String {
    let mut out = String::with_capacity(src.len());
    let mut chars = src.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '/' if chars.peek() == Some(&'/') => {
                for c in chars.by_ref() {
                    if c == '\n' {
                        out.push('\n');
                        break;
                    }
                }
            }
            '"' => {
                let mut escaped = false;
                for c in chars.by_ref() {
                    match c {
                        '\\' if !escaped => escaped = true,
                        '"' if !escaped => break,
                        _ => escaped = false,
                    }
                }
                out.push_str("\"\"");
            }
            // A char literal ('{', '\n'); a lifetime ('a) has no closing quote soon after.
            '\'' => {
                let rest: String = chars.clone().take(12).collect();
                let len = if rest.starts_with('\\') {
                    rest.get(2..).and_then(|r| r.find('\'')).map(|i| i + 3)
                } else if rest.chars().nth(1) == Some('\'') {
                    Some(2)
                } else {
                    None
                };
                match len {
                    Some(n) => {
                        for _ in 0..n {
                            chars.next();
                        }
                        out.push_str("' '");
                    }
                    None => out.push('\''),
                }
            }
            _ => out.push(c),
        }
    }
    out
}

/// `code` without its `#[cfg(test)] mod name { ... }` blocks.
fn without_tests(code: &str) -> String {
    let mut out = String::new();
    let mut rest = code;
    while let Some(at) = rest.find("#[cfg(test)]") {
        let after = &rest[at..];
        let Some(open) = after.find('{') else { break };
        if !after[..open].contains("mod ") {
            out.push_str(&rest[..at + open + 1]);
            rest = &rest[at + open + 1..];
            continue;
        }
        let mut depth = 0usize;
        let mut end = after.len();
        for (i, c) in after[open..].char_indices() {
            match c {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        end = open + i + 1;
                        break;
                    }
                }
                _ => {}
            }
        }
        out.push_str(&rest[..at]);
        rest = &after[end..];
    }
    out.push_str(rest);
    out
}

/// The leading identifier of `s` (after spaces).
fn ident(s: &str) -> &str {
    let s = s.trim_start();
    let end = s
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(s.len());
    &s[..end]
}

/// The top-level items of a `{a, b::{c, d}, e}` group at the start of `s`.
fn group(s: &str) -> Vec<&str> {
    let mut items = Vec::new();
    let mut depth = 0usize;
    let mut start = 1;
    for (i, c) in s.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => {
                depth -= 1;
                if depth == 0 {
                    items.push(&s[start..i]);
                    break;
                }
            }
            ',' if depth == 1 => {
                items.push(&s[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    items
}

/// The modules a path after `crate::` names (`runtime::{exec, ops}` names two).
fn targets(path: &str, root_names: &BTreeMap<String, String>) -> Vec<String> {
    let path = path.trim_start();
    if path.starts_with('{') {
        return group(path)
            .into_iter()
            .flat_map(|p| targets(p, root_names))
            .collect();
    }
    let head = ident(path);
    if FOLDERS.contains(&head) {
        let rest = path.trim_start()[head.len()..].trim_start();
        if let Some(rest) = rest.strip_prefix("::") {
            let rest = rest.trim_start();
            if rest.starts_with('{') {
                return group(rest)
                    .into_iter()
                    .map(ident)
                    .filter(|s| !s.is_empty() && *s != "self")
                    .map(|s| format!("{head}::{s}"))
                    .collect();
            }
            return vec![format!("{head}::{}", ident(rest))];
        }
    }
    match root_names.get(head) {
        Some(m) => vec![m.clone()],
        None if head.is_empty() => vec![],
        None => vec![head.to_string()],
    }
}

fn module_of(rel: &Path) -> Option<String> {
    let parts: Vec<String> = rel
        .with_extension("")
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    match parts.as_slice() {
        [lib] if lib == "lib" => None,
        [folder, m, ..] if FOLDERS.contains(&folder.as_str()) && m != "mod" => {
            Some(format!("{folder}::{m}"))
        }
        [first, ..] => Some(first.clone()),
        [] => None,
    }
}

fn files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .expect("source folder")
        .map(|e| e.expect("entry").path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// Names the crate root re-exports (`pub use runtime::monitor::{Monitor, ...}`), by module.
fn root_names(lib: &str) -> BTreeMap<String, String> {
    let mut names = BTreeMap::new();
    for line in lib.lines() {
        let Some(rest) = line.trim().strip_prefix("pub use ") else {
            continue;
        };
        let rest = rest.trim_end_matches(';');
        let Some(split) = rest.find("::{").or_else(|| rest.rfind("::")) else {
            continue;
        };
        let module: Vec<&str> = rest[..split].split("::").collect();
        let module = match module.as_slice() {
            [folder, m, ..] if FOLDERS.contains(folder) => format!("{folder}::{m}"),
            [m, ..] => m.to_string(),
            [] => continue,
        };
        let items = rest[split + 2..].trim_matches(|c| c == '{' || c == '}');
        for item in items.split(',') {
            names.insert(item.trim().to_string(), module.clone());
        }
    }
    names
}

fn import_graph() -> Graph {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let lib = std::fs::read_to_string(src.join("lib.rs")).expect("lib.rs");
    let roots = root_names(&lib);
    let mut all = Vec::new();
    files(&src, &mut all);
    let mut graph = Graph::new();
    for path in all {
        let rel = path.strip_prefix(&src).expect("under src");
        let Some(module) = module_of(rel) else {
            continue;
        };
        let text = std::fs::read_to_string(&path).expect("source file");
        let code = without_tests(&code_only(&text));
        let deps = graph.entry(module.clone()).or_default();
        for (at, _) in code.match_indices("crate::") {
            for t in targets(&code[at + "crate::".len()..], &roots) {
                if t != module {
                    deps.insert(t);
                }
            }
        }
    }
    graph
}

/// A loop of imports, if there is one.
fn find_cycle(graph: &Graph) -> Option<Vec<String>> {
    fn visit(
        n: &str,
        graph: &Graph,
        state: &mut BTreeMap<String, u8>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(n.to_string(), 1);
        stack.push(n.to_string());
        for d in graph.get(n).into_iter().flatten() {
            match state.get(d.as_str()) {
                Some(1) => {
                    let from = stack.iter().position(|s| s == d).unwrap_or(0);
                    let mut cycle = stack[from..].to_vec();
                    cycle.push(d.clone());
                    return Some(cycle);
                }
                Some(_) => {}
                None => {
                    if let Some(c) = visit(d, graph, state, stack) {
                        return Some(c);
                    }
                }
            }
        }
        stack.pop();
        state.insert(n.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for n in graph.keys() {
        if !state.contains_key(n.as_str())
            && let Some(c) = visit(n, graph, &mut state, &mut Vec::new())
        {
            return Some(c);
        }
    }
    None
}

fn listing(graph: &Graph) -> String {
    graph
        .iter()
        .map(|(m, ds)| {
            format!(
                "{m} -> {}\n",
                ds.iter().cloned().collect::<Vec<_>>().join(", ")
            )
        })
        .collect()
}

#[test]
fn the_import_graph_is_read() {
    // The reader finds what is known to be there (else the rules below would pass vacuously).
    let g = import_graph();
    let has = |a: &str, b: &str| g.get(a).is_some_and(|d| d.contains(b));
    assert!(has("builtins", "runtime::natives"), "{}", listing(&g));
    assert!(has("runtime::monitor", "runtime::exec"), "{}", listing(&g));
    assert!(
        has("runtime::snapshot", "runtime::monitor"),
        "{}",
        listing(&g)
    );
    assert!(has("front::lower", "builtins"), "{}", listing(&g));
    assert!(has("front::typeck", "front::resolve"), "{}", listing(&g));
    assert!(has("load", "front::lower"), "{}", listing(&g));
    // A name re-exported by the crate root counts for the module defining it.
    let roots = root_names("pub use runtime::monitor::{InputError, Monitor};\npub use a::B;");
    assert_eq!(
        roots.get("Monitor").map(String::as_str),
        Some("runtime::monitor")
    );
    assert_eq!(roots.get("B").map(String::as_str), Some("a"));
    // Comments, strings and test modules are not imports.
    let code = without_tests(&code_only(
        "// crate::x\nlet s = \"crate::y\";\n#[cfg(test)]\nmod tests { use crate::z; }\nuse crate::w;",
    ));
    assert!(
        !code.contains("crate::x") && !code.contains("crate::y"),
        "{code}"
    );
    assert!(
        !code.contains("crate::z") && code.contains("crate::w"),
        "{code}"
    );
}

#[test]
fn no_two_modules_import_each_other() {
    let g = import_graph();
    if let Some(cycle) = find_cycle(&g) {
        panic!("import loop {}\n{}", cycle.join(" -> "), listing(&g));
    }
    // The check itself finds a loop.
    let mut looped = Graph::new();
    looped.entry("a".into()).or_default().insert("b".into());
    looped.entry("b".into()).or_default().insert("a".into());
    assert!(find_cycle(&looped).is_some());
}

#[test]
fn the_front_end_reaches_the_runtime_only_through_the_builtins_table() {
    let g = import_graph();
    for pass in PASSES {
        assert!(g.contains_key(*pass), "no module `{pass}`\n{}", listing(&g));
        let into_runtime: Vec<_> = g
            .get(*pass)
            .into_iter()
            .flatten()
            .filter(|d| d.starts_with("runtime"))
            .collect();
        assert!(
            into_runtime.is_empty(),
            "`{pass}` imports {into_runtime:?}\n{}",
            listing(&g)
        );
    }
}

#[test]
fn the_runtime_and_the_shared_data_never_import_the_front_end() {
    let g = import_graph();
    for (m, deps) in &g {
        let runtime = m.starts_with("runtime");
        if !runtime && !SHARED.contains(&m.as_str()) {
            continue;
        }
        for d in deps {
            let allowed = SHARED.contains(&d.as_str()) || (runtime && d.starts_with("runtime::"));
            assert!(allowed, "`{m}` imports `{d}`\n{}", listing(&g));
        }
    }
}
