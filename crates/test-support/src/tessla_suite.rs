//! TeSSLa's conformance cases as the tests read them: where the suite is (`$TESSLA_SUITE` or
//! `../shared/tessla-suite` beside the workspace, and whether its absence skips or fails:
//! `REQUIRE_TESSLA_SUITE=1` fails), every case descriptor with a spec, and the load options a
//! descriptor asks for.
//!
//! The root crate's tests and crates/tessla-trace/tests/conformance.rs use it.

use std::path::{Path, PathBuf};
use tessla_engine::LoadOptions;

pub use crate::paths::workspace_root;

/// The suite's folder; `None` (with a note on stderr) when it is missing and may be skipped.
/// Panics when it is missing and `REQUIRE_TESSLA_SUITE` is set.
pub fn suite_or_skip(test: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("TESSLA_SUITE")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("../shared/tessla-suite"));
    if dir.is_dir() {
        return Some(dir);
    }
    assert!(
        std::env::var_os("REQUIRE_TESSLA_SUITE").is_none(),
        "REQUIRE_TESSLA_SUITE is set but the TeSSLa suite was not found at {} (set TESSLA_SUITE or put it at ../shared/tessla-suite)",
        dir.display()
    );
    let why = format!(
        "TeSSLa suite not found at {} (set TESSLA_SUITE)",
        dir.display()
    );
    eprintln!("{test}: SKIPPED: {why}");
    note_skip(test, &why);
    None
}

/// Leave a note that `test` was skipped, and why, for `make test` to print loudly at the end
/// (`tools/test-skips.sh` reads `target/tmp/skipped-suites/`).
pub fn note_skip(test: &str, why: &str) {
    let dir = crate::paths::skip_dir();
    // Best effort: the note only adds to the skip message above.
    let _ = std::fs::create_dir_all(&dir);
    let _ = std::fs::write(dir.join(test), format!("{why}\n"));
}

/// One case: its name (`folder/case`), the folder of its files, its descriptor.
pub struct Case {
    pub name: String,
    pub dir: PathBuf,
    pub desc: serde_json::Value,
}

/// Every `*.json` descriptor with a `spec` under `root`, sorted by name. `_.ext` in a
/// descriptor means "the file named like the descriptor" and is resolved here.
pub fn cases(root: &Path) -> Vec<Case> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "json")
                && let Ok(t) = std::fs::read_to_string(&p)
                && let Ok(mut desc) = serde_json::from_str::<serde_json::Value>(&t)
                && desc.get("spec").is_some()
            {
                let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or("");
                if let Some(obj) = desc.as_object_mut() {
                    for val in obj.values_mut() {
                        if let Some(ext) = val.as_str().and_then(|s| s.strip_prefix("_.")) {
                            *val = serde_json::Value::String(format!("{stem}.{ext}"));
                        }
                    }
                }
                let rel = p.strip_prefix(root).unwrap_or(&p).with_extension("");
                out.push(Case {
                    name: rel.display().to_string(),
                    dir: d.clone(),
                    desc,
                });
            }
        }
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    out
}

/// The descriptor's file for `key` (`spec`, `input`, `expectedOutput`, ...), in the case's folder.
pub fn file(dir: &Path, desc: &serde_json::Value, key: &str) -> Option<PathBuf> {
    desc.get(key).and_then(|v| v.as_str()).map(|f| dir.join(f))
}

/// Load options as TeSSLa runs the case: its `baseTime`, and time literals without a base time
/// are a compile error.
pub fn load_options(desc: &serde_json::Value) -> LoadOptions {
    LoadOptions {
        base_time: desc
            .get("baseTime")
            .and_then(|v| v.as_str())
            .map(str::to_string),
        overrides: Vec::new(),
        time_units_need_base: true,
        ..Default::default()
    }
}
