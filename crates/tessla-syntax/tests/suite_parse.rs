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

/// What TeSSLa's `.errors` file of the case for `spec` says, if that case expects errors: the
/// descriptor is `NAME.json` next to it (its file names may be written `_.ext`) or any
/// descriptor naming the spec.
fn expected_errors(spec: &Path) -> Option<String> {
    let dir = spec.parent()?;
    let file = spec.file_name()?.to_str()?;
    let stem = spec.file_stem()?.to_str()?;
    for e in std::fs::read_dir(dir).ok()?.flatten() {
        let p = e.path();
        if p.extension().is_none_or(|x| x != "json") {
            continue;
        }
        let Ok(t) = std::fs::read_to_string(&p) else {
            continue;
        };
        let Ok(desc) = serde_json::from_str::<serde_json::Value>(&t) else {
            continue;
        };
        let own = p.file_stem().and_then(|s| s.to_str()) == Some(stem);
        let names_spec = desc
            .get("spec")
            .and_then(|v| v.as_str())
            .is_some_and(|s| s == file || (own && s == "_.tessla"));
        if !names_spec {
            continue;
        }
        if let Some(errors) = desc.get("expectedErrors").and_then(|v| v.as_str()) {
            let errors = errors.replace("_.", &format!("{}.", p.file_stem()?.to_str()?));
            return std::fs::read_to_string(dir.join(errors)).ok();
        }
    }
    None
}

#[test]
fn suite_specs_parse() {
    let Some(dir) = suite_dir() else {
        assert!(
            std::env::var_os("REQUIRE_TESSLA_SUITE").is_none(),
            "TeSSLa suite missing"
        );
        let why = "TeSSLa suite not found at $TESSLA_SUITE or ../shared/tessla-suite";
        eprintln!("suite_parse: SKIPPED: {why}");
        // A note for `make test` to print loudly at the end (tools/test-skips.sh).
        let notes = Path::new(env!("CARGO_TARGET_TMPDIR")).join("skipped-suites");
        let _ = std::fs::create_dir_all(&notes);
        let _ = std::fs::write(notes.join("suite_parse"), format!("{why}\n"));
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
    let mut syntax_cases = 0;
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let mut map = SourceMap::new();
        let id = map.add(f.display().to_string(), Some(f), text);
        let (_, diags) = tessla_syntax::parse(&map.get(id).text, id);
        let wants_syntax_error = expected_errors(f).is_some_and(|e| e.contains("Invalid syntax"));
        if wants_syntax_error {
            syntax_cases += 1;
            if diags.is_empty() {
                failures.push(format!(
                    "{}: TeSSLa reports a syntax error, we do not",
                    f.display()
                ));
            }
        } else if let Some(d) = diags.first() {
            failures.push(d.one_line(&map));
        }
    }
    assert!(
        syntax_cases > 0,
        "no case expecting a syntax error was found"
    );
    assert!(
        failures.is_empty(),
        "{} of {} specs are parsed differently from TeSSLa:\n{}",
        failures.len(),
        files.len(),
        failures.join("\n")
    );
}
