//! Every `.tessla` file of TeSSLa's own suite parses, except the cases that expect a syntax error.
//! The suite is read from `$TESSLA_SUITE` or `../shared/tessla-suite` (beside the repository).

use std::path::{Path, PathBuf};
use tessla_syntax::source::SourceMap;

fn suite_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("TESSLA_SUITE")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/tessla-suite")
        });
    dir.is_dir().then_some(dir)
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            walk(&p, out);
        } else if p.extension().is_some_and(|x| x == "tessla") {
            out.push(p);
        }
    }
}

/// True when the case's descriptor expects an error that is plausibly a syntax error.
fn expects_error(spec: &Path) -> bool {
    let dir = spec.parent().unwrap();
    std::fs::read_dir(dir).unwrap().flatten().any(|e| {
        let p = e.path();
        p.extension().is_some_and(|x| x == "json")
            && std::fs::read_to_string(&p).is_ok_and(|t| {
                t.contains(spec.file_name().unwrap().to_str().unwrap())
                    && t.contains("expectedErrors")
            })
    })
}

#[test]
fn suite_specs_parse() {
    let Some(dir) = suite_dir() else {
        assert!(
            std::env::var_os("REQUIRE_TESSLA_SUITE").is_none(),
            "TeSSLa suite missing"
        );
        eprintln!("skipped: TeSSLa suite not found (set TESSLA_SUITE)");
        return;
    };
    let mut files = Vec::new();
    walk(&dir, &mut files);
    files.sort();
    assert!(
        files.len() > 100,
        "suite looks incomplete: {} specs",
        files.len()
    );
    let mut failures = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let mut map = SourceMap::new();
        let id = map.add(f.display().to_string(), Some(f), text);
        let (_, diags) = tessla_syntax::parse(&map.get(id).text, id);
        if !diags.is_empty() && !expects_error(f) {
            failures.push(diags[0].one_line(&map));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} specs fail to parse:\n{}",
        failures.len(),
        files.len(),
        failures.join("\n")
    );
}
