//! The workspace's house rules on imports, checked on the sources of every crate (the root
//! crate's `src/` and `crates/*/src`): no module loops (no two modules import each other,
//! directly or round a loop), and data flows one way: each crate's modules sit in layers, and a
//! module imports only from its own layer or the layers below.
//!
//! A module is a file: `a/b.rs` is `a::b`, `a/mod.rs` is the folder's own module `a`, `lib.rs`
//! the crate root `lib`, `main.rs` the binary `main`. An import is a `crate::` or `super::` path
//! in code (comments, strings and `#[cfg(test)] mod` blocks aside; in `main.rs`, a path through
//! the library crate), naming the deepest module it reaches; a name the crate root re-exports
//! counts as an import of the module defining it. A folder's `mod.rs` reaching its own children
//! by their bare names (`mod x; use x::f;`) is not counted. Paths into the other workspace crates
//! are read too (`::tessla_syntax`), for the rules that name a crate.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// A crate's layers, top to bottom: a module may import from its own layer and the ones below.
/// An entry stands for a module and everything under it (`front` is `front`, `front::lower`,
/// `front::lower::call`, ...); the longest entry covering a module decides its layer.
type Layers = &'static [&'static [&'static str]];

/// Imports the layers would allow but a crate forbids: (from, to, why), entries covering as in
/// [`Layers`]; `to` may be another crate (`::tessla_syntax`).
type Forbidden = &'static [(&'static str, &'static str, &'static str)];

/// The root crate, in the order a record travels (the book's Architecture chapter, "Layout").
const ROOT_LAYERS: Layers = &[
    // The command line and the crate's roots.
    &["main", "lib", "cli"],
    // The transports, and the tools that drive a processor or read what it wrote.
    &["transport", "simulate", "replay", "report"],
    // The one step loop every transport plugs into.
    &["step_loop"],
    // The fleet level: a spec over every robot's outputs, in event time.
    &["fleet"],
    // New spec versions while running: the fleet's spec channel, a watched file, bundles.
    &["spec_feed"],
    // Where monitor state is kept (a file, a NATS bucket and its lease).
    &["state"],
    // NATS as both the state store and the spec channel use it: the connection, the URL, its
    // secrets, the key layout in a bucket (neither of the two owns it).
    &["nats"],
    // The processor: instances, the live clock, duplicates, reloads, wiring diagnostics.
    &["processor"],
    // The Telegraf binding: records to input events, outputs to metrics.
    &["telegraf"],
    // Logging and the shared helpers.
    &["log", "watchdog", "bundled"],
    // The natives this program adds to the engine's builtins (lidar, the fleet's closest pair).
    &["natives"],
];

/// tessla-syntax: source text to the syntax tree.
const SYNTAX_LAYERS: Layers = &[
    &["lib", "include"],
    &["parser"],
    &["lexer"],
    &["ast", "diag"],
    &["source"],
];

/// tessla-engine: the front end's passes, the builtins table between them and the runtime, the
/// runtime, and the data both share. `front` and `ir` cover all their modules (`ir::schedule`
/// and `ir::fold` are IR-to-IR passes beside the IR).
const ENGINE_LAYERS: Layers = &[
    &["lib", "load"],
    &["front"],
    &["builtins"],
    &["runtime"],
    &["ir", "value"],
];
const ENGINE_FORBIDDEN: Forbidden = &[(
    "front",
    "runtime",
    "the front end reaches the runtime only through `builtins`",
)];
/// The IR and the runtime know nothing of the syntax tree (the IR has its own operators).
const ENGINE_NO_SYNTAX: Forbidden = &[
    (
        "ir",
        "::tessla_syntax",
        "the IR does not depend on the syntax tree",
    ),
    (
        "runtime",
        "::tessla_syntax",
        "the runtime does not depend on the syntax tree",
    ),
];

/// tessla-trace: the CTF reader on top of the text-trace driver (lib.rs: options, errors, the
/// printer), on top of the fast path for plain event lines, on top of the trace reader and writer.
const TRACE_LAYERS: Layers = &[&["ctf"], &["lib"], &["fast"], &["reader", "writer"]];

/// lineproto: records cut, parsed and written; the parsers' parts; the record types; a list
/// pattern's keys and the array its elements can be read into.
const LINEPROTO_LAYERS: Layers = &[
    &["lib"],
    &["split", "parse", "write"],
    &["fast", "telegraf_rules"],
    &["metric"],
    &["list"],
];

/// test-support (dev-only): the NATS stand-in on the cluster on the servers; the TeSSLa suite's
/// cases and the real Telegraf beside them; the workspace's folders and the benchmarks' records
/// under all.
const TEST_SUPPORT_LAYERS: Layers = &[
    &["lib"],
    &["nats_standin", "tessla_suite", "real_telegraf"],
    &["nats_cluster"],
    &["servers"],
    &["paths", "workload"],
];

struct Crate {
    /// The workspace member's folder (`.` for the root crate).
    dir: &'static str,
    layers: Layers,
    forbidden: Forbidden,
}

const ROOT: Crate = Crate {
    dir: ".",
    layers: ROOT_LAYERS,
    forbidden: &[],
};
const ENGINE: Crate = Crate {
    dir: "crates/tessla-engine",
    layers: ENGINE_LAYERS,
    forbidden: ENGINE_FORBIDDEN,
};
/// Every crate but the root, whose checks are all active.
const LIBRARIES: &[Crate] = &[
    Crate {
        dir: "crates/tessla-syntax",
        layers: SYNTAX_LAYERS,
        forbidden: &[],
    },
    ENGINE,
    Crate {
        dir: "crates/tessla-trace",
        layers: TRACE_LAYERS,
        forbidden: &[],
    },
    Crate {
        dir: "crates/lineproto",
        layers: LINEPROTO_LAYERS,
        forbidden: &[],
    },
    Crate {
        dir: "crates/test-support",
        layers: TEST_SUPPORT_LAYERS,
        forbidden: &[],
    },
];

/// The workspace's crates, as `::name` in a path.
const WORKSPACE_CRATES: &[&str] = &[
    "tessla_syntax",
    "tessla_engine",
    "tessla_trace",
    "lineproto",
];
/// The library crate, as `main.rs` names it.
const LIB_CRATE: &str = "tessla_telegraf";

type Graph = BTreeMap<String, BTreeSet<String>>;

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// Source text without comments, string and char literals (kept as empty quotes), so braces
/// and paths inside them do not count.
fn code_only(src: &str) -> String {
    let s: Vec<char> = src.chars().collect();
    let mut out = String::with_capacity(src.len());
    let mut i = 0;
    while i < s.len() {
        let c = s[i];
        let next = s.get(i + 1).copied();
        let ident_before = i > 0 && is_ident(s[i - 1]);
        if c == '/' && next == Some('/') {
            while i < s.len() && s[i] != '\n' {
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < s.len() {
                if s[i] == '/' && s.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if s[i] == '*' && s.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
            out.push(' ');
        } else if c == 'r'
            && (!ident_before || ((i == 1 || !is_ident(s[i - 2])) && s[i - 1] == 'b'))
            && matches!(next, Some('"' | '#'))
        {
            // A raw string: r"..", r#".."#, br"..".
            let mut j = i + 1;
            let mut hashes = 0;
            while s.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if s.get(j) != Some(&'"') {
                out.push(c);
                i += 1;
                continue;
            }
            j += 1;
            while j < s.len() {
                if s[j] == '"' && (1..=hashes).all(|k| s.get(j + k) == Some(&'#')) {
                    j += hashes + 1;
                    break;
                }
                j += 1;
            }
            out.push_str("\"\"");
            i = j;
            continue;
        } else if c == '"' {
            i += 1;
            while i < s.len() && s[i] != '"' {
                i += if s[i] == '\\' { 2 } else { 1 };
            }
            out.push_str("\"\"");
        } else if c == '\'' {
            // A char literal ('{', '\n', '\u{7f}'); a lifetime ('a) has no closing quote soon after.
            let len = if next == Some('\\') {
                (i + 3..(i + 12).min(s.len()))
                    .find(|&j| s[j] == '\'')
                    .map(|j| j - i)
            } else if s.get(i + 2) == Some(&'\'') {
                Some(2)
            } else {
                None
            };
            match len {
                Some(n) => {
                    out.push_str("' '");
                    i += n;
                }
                None => out.push('\''),
            }
        } else {
            out.push(c);
        }
        i += 1;
    }
    out
}

/// The end of the `{ ... }` block whose `{` is at `open`.
fn block_end(code: &str, open: usize) -> usize {
    let mut depth = 0usize;
    for (i, c) in code[open..].char_indices() {
        match c {
            '{' => depth += 1,
            '}' => {
                depth -= 1;
                if depth == 0 {
                    return open + i + 1;
                }
            }
            _ => {}
        }
    }
    code.len()
}

/// `head` is an inline module's start (`pub(crate) mod name`): its name.
fn inline_module(head: &str) -> Option<&str> {
    let mut words = head.split_whitespace();
    let mut w = words.next()?;
    if w.starts_with("pub") {
        w = words.next()?;
    }
    let name = words.next()?;
    (w == "mod" && words.next().is_none()).then_some(name)
}

/// `code` without its `#[cfg(test)] mod name { ... }` blocks (whitespace of equal length in their
/// place, so offsets stay).
fn without_tests(code: &str) -> String {
    let mut out = code.to_string();
    let mut from = 0;
    while let Some(at) = code[from..].find("#[cfg(test)]").map(|a| from + a) {
        let after = at + "#[cfg(test)]".len();
        from = after;
        let Some(end) = code[after..].find(['{', ';']).map(|e| after + e) else {
            break;
        };
        // The item after the attribute (and any other attributes).
        let head = code[after..end].rsplit(']').next().unwrap_or_default();
        if code[end..].starts_with('{') && inline_module(head).is_some() {
            let close = block_end(code, end);
            let blank: String = code[at..close]
                .chars()
                .map(|c| match c {
                    '\n' => "\n".to_string(),
                    c => " ".repeat(c.len_utf8()),
                })
                .collect();
            out.replace_range(at..close, &blank);
            from = close;
        }
    }
    out
}

/// The names of the inline (non-test) modules enclosing offset `at` of `code`, outermost first.
fn inline_modules_at(code: &str, at: usize) -> Vec<String> {
    let mut names = Vec::new();
    let mut from = 0;
    while let Some(open) = code[from..at].find('{').map(|o| from + o) {
        let head_start = code[..open].rfind([';', '{', '}']).map_or(0, |p| p + 1);
        let head = code[head_start..open].trim();
        let head = head.rsplit(']').next().unwrap_or(head);
        match inline_module(head) {
            Some(name) if block_end(code, open) > at => {
                names.push(name.to_string());
                from = open + 1;
            }
            Some(_) => from = block_end(code, open),
            None => from = open + 1,
        }
    }
    names
}

/// The leading identifier of `s` (after spaces).
fn ident(s: &str) -> &str {
    let s = s.trim_start();
    &s[..s.find(|c: char| !is_ident(c)).unwrap_or(s.len())]
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

/// What a crate's paths can name: its modules and the names its root re-exports.
struct Names {
    modules: BTreeSet<Vec<String>>,
    /// Re-exported name -> the module defining it, or `::crate` for another crate's.
    reexports: BTreeMap<String, String>,
}

fn name_of(module: &[String]) -> String {
    if module.is_empty() {
        "lib".to_string()
    } else {
        module.join("::")
    }
}

impl Names {
    /// The deepest module of `module` (inline modules and items dropped).
    fn known(&self, module: &[String]) -> String {
        let n = (0..=module.len())
            .rev()
            .find(|&n| self.modules.contains(&module[..n]))
            .unwrap_or(0);
        name_of(&module[..n])
    }

    /// The modules `path` names, read from module `base` (`crate::` paths from the root).
    fn targets(&self, base: &[String], path: &str, out: &mut Vec<String>) {
        let mut m = base.to_vec();
        let mut rest = path.trim_start();
        loop {
            if rest.starts_with('{') {
                for item in group(rest) {
                    self.targets(&m, item, out);
                }
                return;
            }
            let seg = ident(rest);
            rest = rest.trim_start()[seg.len()..].trim_start();
            match seg {
                "super" => {
                    m.pop();
                }
                "self" | "" => return out.push(self.known(&m)),
                _ => {
                    let mut child = m.clone();
                    child.push(seg.to_string());
                    if self.modules.contains(&child) {
                        m = child;
                    } else if m.is_empty()
                        && let Some(target) = self.reexports.get(seg)
                    {
                        return out.push(target.clone());
                    } else {
                        return out.push(self.known(&m));
                    }
                }
            }
            match rest.strip_prefix("::") {
                Some(r) => rest = r,
                None => return out.push(self.known(&m)),
            }
        }
    }
}

/// The names a `use` tree brings in, with the path each stands for: `a::{b, c::d as e}` is
/// `b` (a::b) and `e` (a::c::d).
fn use_tree(prefix: &str, tree: &str, out: &mut Vec<(String, String)>) {
    let tree = tree.trim();
    if let Some(at) = tree.find('{').filter(|&a| !tree[..a].contains(" as ")) {
        let prefix = format!("{prefix}{}", &tree[..at]);
        for item in group(&tree[at..]) {
            use_tree(&prefix, item, out);
        }
        return;
    }
    let (path, alias) = match tree.split_once(" as ") {
        Some((p, a)) => (p.trim(), Some(a.trim())),
        None => (tree, None),
    };
    let name = alias.unwrap_or_else(|| path.rsplit("::").next().unwrap_or(path));
    if !name.is_empty() && name != "*" {
        out.push((name.to_string(), format!("{prefix}{path}")));
    }
}

/// The names the crate root (`lib.rs`, as code) re-exports and the modules defining them.
fn root_reexports(lib: &str, modules: &BTreeSet<Vec<String>>) -> BTreeMap<String, String> {
    let names = Names {
        modules: modules.clone(),
        reexports: BTreeMap::new(),
    };
    let mut reexports = BTreeMap::new();
    for (at, _) in lib.match_indices("pub use ") {
        if at > 0 && is_ident(lib[..at].chars().next_back().unwrap_or(' ')) {
            continue;
        }
        let body = &lib[at + "pub use ".len()..];
        let body = &body[..body.find(';').unwrap_or(body.len())];
        let mut leaves = Vec::new();
        use_tree("", body, &mut leaves);
        for (name, path) in leaves {
            let path = path.strip_prefix("crate::").unwrap_or(&path);
            let path = path.strip_prefix("self::").unwrap_or(path);
            let head = ident(path);
            let target = if modules.contains(&vec![head.to_string()]) {
                let mut t = Vec::new();
                names.targets(&[], path, &mut t);
                t.pop().unwrap_or_default()
            } else {
                format!("::{head}")
            };
            reexports.insert(name, target);
        }
    }
    reexports
}

/// A source file's module (`a/b.rs` is `a::b`, `a/mod.rs` is `a`, `lib.rs` the root).
fn module_of(rel: &Path) -> Vec<String> {
    let mut parts: Vec<String> = rel
        .with_extension("")
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    if parts.last().is_some_and(|l| l == "mod" || l == "lib") {
        parts.pop();
    }
    parts
}

fn files(dir: &Path, out: &mut Vec<PathBuf>) {
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

/// Where each path starting at `prefix` (`crate::`, `super::`, `tessla_syntax::`) begins in
/// `code`, when `prefix` starts a path there (not `x::super::`, not `my_crate::`).
fn path_starts<'a>(code: &'a str, prefix: &'a str) -> impl Iterator<Item = usize> + 'a {
    code.match_indices(prefix).filter_map(move |(at, _)| {
        let before = code[..at].chars().next_back();
        let free = !before.is_some_and(|c| is_ident(c) || c == ':');
        free.then_some(at)
    })
}

/// The import graph of the crate in `dir`: every module, the modules and crates it imports.
fn import_graph(dir: &str) -> Graph {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join(dir).join("src");
    let mut all = Vec::new();
    files(&src, &mut all);
    let code_of = |path: &Path| {
        let text = std::fs::read_to_string(path).expect("source file");
        without_tests(&code_only(&text))
    };
    let mut modules: BTreeSet<Vec<String>> = all
        .iter()
        .map(|p| module_of(p.strip_prefix(&src).expect("under src")))
        .filter(|m| m.first().is_none_or(|f| f != "main"))
        .collect();
    modules.insert(Vec::new());
    let lib = src.join("lib.rs");
    let reexports = if lib.exists() {
        root_reexports(&code_of(&lib), &modules)
    } else {
        BTreeMap::new()
    };
    let names = Names { modules, reexports };
    let mut graph = Graph::new();
    for path in &all {
        let module = module_of(path.strip_prefix(&src).expect("under src"));
        let mut code = code_of(path);
        let binary = module == ["main"];
        if binary {
            // The binary reaches the library crate by its name.
            code = code.replace(&format!("{LIB_CRATE}::"), "crate::");
        }
        let name = if binary {
            "main".to_string()
        } else {
            name_of(&module)
        };
        let mut found = Vec::new();
        for at in path_starts(&code, "crate::") {
            names.targets(&[], &code[at + "crate::".len()..], &mut found);
        }
        for at in path_starts(&code, "super::") {
            let mut here = module.clone();
            here.extend(inline_modules_at(&code, at));
            names.targets(&here, &code[at..], &mut found);
        }
        for krate in WORKSPACE_CRATES {
            if path_starts(&code, &format!("{krate}::")).next().is_some() {
                found.push(format!("::{krate}"));
            }
        }
        let deps = graph.entry(name.clone()).or_default();
        deps.extend(found.into_iter().filter(|d| *d != name));
    }
    graph
}

/// One group of modules that reach each other through their imports.
struct Loop {
    /// Its shortest loop through its first module: `a -> b -> a`.
    path: Vec<String>,
    /// Every module of the group.
    modules: Vec<String>,
}

/// Every import loop: one per group of modules that reach each other (its shortest loop through
/// the group's first module, then the whole group when the loop does not pass them all).
fn find_cycles(graph: &Graph) -> Vec<Loop> {
    // Tarjan's strongly connected components.
    struct Tarjan<'g> {
        graph: &'g Graph,
        index: BTreeMap<&'g str, usize>,
        low: BTreeMap<&'g str, usize>,
        stack: Vec<&'g str>,
        components: Vec<Vec<&'g str>>,
    }
    impl<'g> Tarjan<'g> {
        fn visit(&mut self, n: &'g str) {
            let i = self.index.len();
            self.index.insert(n, i);
            self.low.insert(n, i);
            self.stack.push(n);
            for d in self.graph.get(n).into_iter().flatten() {
                let d = d.as_str();
                if !self.index.contains_key(d) {
                    self.visit(d);
                    let low = self.low[n].min(self.low[d]);
                    self.low.insert(n, low);
                } else if self.stack.contains(&d) {
                    let low = self.low[n].min(self.index[d]);
                    self.low.insert(n, low);
                }
            }
            if self.low[n] == self.index[n] {
                let at = self.stack.iter().rposition(|&s| s == n).unwrap_or(0);
                self.components.push(self.stack.split_off(at));
            }
        }
    }
    let mut t = Tarjan {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        components: Vec::new(),
    };
    for n in graph.keys() {
        if !t.index.contains_key(n.as_str()) {
            t.visit(n);
        }
    }
    let mut cycles = Vec::new();
    for component in t.components.iter().filter(|c| c.len() > 1) {
        // The shortest way from the component's first module back to it, inside the component.
        let start = *component.iter().min().expect("not empty");
        let mut came_from: BTreeMap<&str, &str> = BTreeMap::new();
        let mut queue = std::collections::VecDeque::from([start]);
        'search: while let Some(n) = queue.pop_front() {
            for d in graph.get(n).into_iter().flatten() {
                let d = d.as_str();
                if d == start {
                    let mut cycle = vec![start.to_string(), n.to_string()];
                    let mut at = n;
                    while at != start {
                        at = came_from[at];
                        cycle.push(at.to_string());
                    }
                    cycle.reverse();
                    let mut modules: Vec<String> =
                        component.iter().map(|m| m.to_string()).collect();
                    modules.sort();
                    cycles.push(Loop {
                        path: cycle,
                        modules,
                    });
                    break 'search;
                }
                if component.contains(&d) && !came_from.contains_key(d) && d != start {
                    came_from.insert(d, n);
                    queue.push_back(d);
                }
            }
        }
    }
    cycles
}

fn listing(graph: &Graph) -> String {
    graph
        .iter()
        .map(|(m, ds)| {
            let ds: Vec<&str> = ds.iter().map(String::as_str).collect();
            format!("  {m} -> {}\n", ds.join(", "))
        })
        .collect()
}

/// Whether `entry` covers `module` (is it, or a module it is under).
fn covers(entry: &str, module: &str) -> bool {
    module == entry
        || module
            .strip_prefix(entry)
            .is_some_and(|r| r.starts_with("::"))
}

/// The layer of `module` (0 the top) and the entry placing it: the longest covering entry.
fn layer_of(layers: Layers, module: &str) -> Option<(usize, &'static str)> {
    layers
        .iter()
        .enumerate()
        .flat_map(|(i, l)| l.iter().map(move |e| (i, *e)))
        .filter(|(_, e)| covers(e, module))
        .max_by_key(|(_, e)| e.len())
}

/// Everything wrong with `graph` against `layers` and `forbidden`: modules in no layer,
/// entries covering no module, upward imports, forbidden imports.
fn layer_problems(graph: &Graph, layers: Layers, forbidden: Forbidden) -> Vec<String> {
    let mut problems = Vec::new();
    for entry in layers.iter().flat_map(|l| l.iter()) {
        if !graph.keys().any(|m| covers(entry, m)) {
            problems.push(format!("the layer entry `{entry}` covers no module"));
        }
    }
    for (m, deps) in graph {
        let Some((from, _)) = layer_of(layers, m) else {
            problems.push(format!("`{m}` is in no layer"));
            continue;
        };
        for d in deps {
            if let Some((to, entry)) = layer_of(layers, d)
                && to < from
            {
                problems.push(format!(
                    "`{m}` (layer {from}) imports `{d}` from the layer above (layer {to}: `{entry}`)"
                ));
            }
            for (f, t, why) in forbidden {
                if covers(f, m) && covers(t, d) {
                    problems.push(format!("`{m}` imports `{d}`: {why}"));
                }
            }
        }
    }
    problems
}

fn layers_text(layers: Layers) -> String {
    layers
        .iter()
        .enumerate()
        .map(|(i, l)| format!("  layer {i}: {}\n", l.join(", ")))
        .collect()
}

fn assert_no_cycles(krate: &Crate, graph: &Graph) {
    let cycles = find_cycles(graph);
    let shown: Vec<String> = cycles
        .iter()
        .map(|c| {
            let mut line = format!("  {}", c.path.join(" -> "));
            if c.modules.len() + 1 > c.path.len() {
                line.push_str(&format!(" (a loop among {})", c.modules.join(", ")));
            }
            line + "\n"
        })
        .collect();
    assert!(
        cycles.is_empty(),
        "import loops in {}:\n{}imports:\n{}",
        krate.dir,
        shown.concat(),
        listing(graph)
    );
}

fn assert_layered(krate: &Crate, graph: &Graph, forbidden: Forbidden) {
    let problems = layer_problems(graph, krate.layers, forbidden);
    assert!(
        problems.is_empty(),
        "in {}:\n  {}\nlayers:\n{}imports:\n{}",
        krate.dir,
        problems.join("\n  "),
        layers_text(krate.layers),
        listing(graph)
    );
}

/// A graph from `a -> b, c` lines.
fn graph_of(lines: &[&str]) -> Graph {
    let mut g = Graph::new();
    for line in lines {
        let (m, ds) = line.split_once("->").unwrap_or((line, ""));
        let deps = g.entry(m.trim().to_string()).or_default();
        deps.extend(
            ds.split(',')
                .map(str::trim)
                .filter(|d| !d.is_empty())
                .map(String::from),
        );
    }
    g
}

#[test]
fn every_workspace_crate_is_checked() {
    let manifest =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("Cargo.toml"))
            .expect("Cargo.toml");
    let members = manifest
        .lines()
        .find_map(|l| l.trim().strip_prefix("members = "))
        .expect("workspace members");
    let members: BTreeSet<&str> = members
        .trim_matches(['[', ']'])
        .split(',')
        .map(|m| m.trim().trim_matches('"'))
        .filter(|m| !m.is_empty())
        .collect();
    let checked: BTreeSet<&str> = LIBRARIES.iter().map(|c| c.dir).collect();
    assert_eq!(members, checked, "a workspace member without layers here");
}

#[test]
fn the_import_graphs_are_read() {
    // The reader finds what is known to be there (else the rules would pass vacuously).
    let has = |g: &Graph, a: &str, b: &str| g.get(a).is_some_and(|d| d.contains(b));
    let engine = import_graph(ENGINE.dir);
    for (a, b) in [
        ("builtins", "runtime::natives::core"),
        ("runtime::monitor", "runtime::exec"),
        ("runtime::snapshot", "ir::print"),
        ("front::lower", "builtins"),
        ("front::lower::call", "front::lower"),
        ("front::lower::call", "front::typeck"),
        ("front::typeck", "front::resolve"),
        ("load", "front::lower"),
        ("front::lower", "::tessla_syntax"),
    ] {
        assert!(has(&engine, a, b), "{a} -> {b}?\n{}", listing(&engine));
    }
    // `super::` in an inline module (`ops::natives`) is the file's module, not its parent.
    assert!(
        !has(&engine, "runtime::ops", "runtime"),
        "{}",
        listing(&engine)
    );
    let syntax = import_graph("crates/tessla-syntax");
    // `crate::parse`, re-exported by the root, is the parser's.
    assert!(has(&syntax, "include", "parser"), "{}", listing(&syntax));
    let trace = import_graph("crates/tessla-trace");
    assert!(has(&trace, "ctf", "lib"), "{}", listing(&trace));
    assert!(
        has(&trace, "ctf::decode", "ctf::tsdl"),
        "{}",
        listing(&trace)
    );
    let lineproto = import_graph("crates/lineproto");
    assert!(has(&lineproto, "parse", "fast"), "{}", listing(&lineproto));
    assert!(
        has(&lineproto, "write", "metric"),
        "{}",
        listing(&lineproto)
    );
    let root = import_graph(ROOT.dir);
    for (a, b) in [
        ("main", "cli"),
        ("cli::run", "processor"),
        ("step_loop", "state"),
        ("transport::stdio", "step_loop"),
        ("cli::check", "cli::error"),
        ("cli::trace", "::tessla_trace"),
        ("replay::read_csv", "replay"),
        ("report::html", "report::stats"),
    ] {
        assert!(has(&root, a, b), "{a} -> {b}?\n{}", listing(&root));
    }
}

#[test]
fn the_source_reader_leaves_out_comments_strings_and_tests() {
    let code = without_tests(&code_only(
        "// crate::a\n/* crate::b /* crate::c */ */ let s = \"crate::d\";\n\
         let r = r#\"crate::e \" crate::f\"#;\nlet c = '\"'; let l: &'static str = x;\n\
         #[cfg(test)]\nmod tests { use crate::g; fn f() { {} } }\n\
         #[cfg(test)]\nuse crate::h;\nuse crate::i;",
    ));
    for gone in [
        "crate::a", "crate::b", "crate::c", "crate::d", "crate::e", "crate::f",
    ] {
        assert!(!code.contains(gone), "{gone} in {code}");
    }
    assert!(!code.contains("crate::g"), "{code}");
    assert!(
        code.contains("crate::h") && code.contains("crate::i"),
        "{code}"
    );
    assert!(code.contains("&'static str"), "{code}");
    // Root re-exports count for the module defining them; another crate's stay that crate's.
    let modules: BTreeSet<Vec<String>> = [
        vec![],
        vec!["a".into()],
        vec!["b".into(), "c".into()],
        vec!["b".into()],
    ]
    .into_iter()
    .collect();
    let roots = root_reexports(
        "pub use a::{X, Y as Z};\npub use b::c::{self as d, W};\npub use other as o;",
        &modules,
    );
    assert_eq!(roots.get("X").map(String::as_str), Some("a"));
    assert_eq!(roots.get("Z").map(String::as_str), Some("a"));
    assert_eq!(roots.get("W").map(String::as_str), Some("b::c"));
    assert_eq!(roots.get("d").map(String::as_str), Some("b::c"));
    assert_eq!(roots.get("o").map(String::as_str), Some("::other"));
    let names = Names {
        modules,
        reexports: roots,
    };
    let mut found = Vec::new();
    names.targets(&[], "{a::f, b::{self, c::g}, W}", &mut found);
    names.targets(&["b".into(), "c".into()], "super::super::a", &mut found);
    assert_eq!(found, ["a", "b", "b::c", "b::c", "a"]);
    // A module's inline modules, for `super::` inside them.
    let code = "mod m { pub mod n { X } } mod k { }";
    assert_eq!(inline_modules_at(code, code.find('X').unwrap()), ["m", "n"]);
    assert!(inline_modules_at(code, code.len() - 2).contains(&"k".to_string()));
}

#[test]
fn the_loop_finder_finds_every_loop() {
    let g = graph_of(&["a -> b", "b -> c, d", "c -> a", "d", "e -> f", "f -> e, a"]);
    let cycles = find_cycles(&g);
    assert_eq!(cycles.len(), 2);
    let paths: Vec<String> = cycles.iter().map(|c| c.path.join(" -> ")).collect();
    assert!(paths.contains(&"a -> b -> c -> a".to_string()), "{paths:?}");
    assert!(paths.contains(&"e -> f -> e".to_string()), "{paths:?}");
    assert!(cycles.iter().any(|c| c.modules == ["a", "b", "c"]));
    assert!(find_cycles(&graph_of(&["a -> b, c", "b -> c", "c"])).is_empty());
}

#[test]
fn the_layer_check_finds_upward_and_forbidden_imports() {
    const LAYERS: Layers = &[&["top"], &["mid", "mid::x"], &["low"], &["gone"]];
    let g = graph_of(&[
        "top -> mid::y, low",
        "mid::y -> low",
        "mid::x -> top",
        "low",
        "stray",
    ]);
    let problems = layer_problems(&g, LAYERS, &[("top", "low", "no skipping")]);
    let text = problems.join("\n");
    assert_eq!(problems.len(), 4, "{text}");
    assert!(text.contains("`mid::x` (layer 1) imports `top`"), "{text}");
    assert!(text.contains("`top` imports `low`: no skipping"), "{text}");
    assert!(text.contains("`stray` is in no layer"), "{text}");
    assert!(text.contains("`gone` covers no module"), "{text}");
    assert_eq!(layer_of(LAYERS, "mid::x::z"), Some((1, "mid::x")));
}

#[test]
fn no_import_loops_in_the_library_crates() {
    for krate in LIBRARIES {
        assert_no_cycles(krate, &import_graph(krate.dir));
    }
}

#[test]
fn the_library_crates_import_only_downward() {
    // For the engine also: the front end reaches the runtime only through `builtins`, and the
    // runtime and the shared data (`ir`, `value`) never import the front end.
    for krate in LIBRARIES {
        assert_layered(krate, &import_graph(krate.dir), krate.forbidden);
    }
}

#[test]
fn the_ir_and_the_runtime_never_import_the_syntax_tree() {
    assert_layered(&ENGINE, &import_graph(ENGINE.dir), ENGINE_NO_SYNTAX);
}

#[test]
fn no_import_loops_in_the_root_crate() {
    assert_no_cycles(&ROOT, &import_graph(ROOT.dir));
}

#[test]
fn the_root_crate_imports_only_downward() {
    assert_layered(&ROOT, &import_graph(ROOT.dir), ROOT.forbidden);
}
