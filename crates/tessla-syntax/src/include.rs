//! `include "file"`: finding included files and loading a spec with all its includes.
//!
//! Owns: the [`Resolver`] trait (file system, or in memory for specs bundled in the binary),
//! include-loop and missing-file diagnostics, and the order in which files are read.

use crate::ast::File;
use crate::diag::{Category, Diagnostic};
use crate::source::{FileId, SourceMap};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Why a [`Resolver`] found no text for a name; its text goes into the "cannot load the spec"
/// and "cannot include" diagnostics.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ResolveError(pub String);

impl std::fmt::Display for ResolveError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ResolveError {}

impl From<String> for ResolveError {
    fn from(message: String) -> Self {
        ResolveError(message)
    }
}

/// Finds the text of a spec file by name.
pub trait Resolver {
    /// Resolve `name` as written in an `include` of the file `from` (`None` for the root spec).
    /// Returns a canonical name (used for loop detection and messages) and the text.
    fn resolve(&self, from: Option<&str>, name: &str) -> Result<(String, String), ResolveError>;
}

/// Resolves names relative to the including file's directory on the file system.
#[derive(Debug, Default, Clone, Copy)]
pub struct FsResolver;

impl Resolver for FsResolver {
    fn resolve(&self, from: Option<&str>, name: &str) -> Result<(String, String), ResolveError> {
        let path = normalize(&match from.and_then(|f| Path::new(f).parent()) {
            Some(dir) => dir.join(name),
            None => PathBuf::from(name),
        });
        let bytes =
            std::fs::read(&path).map_err(|e| format!("cannot read `{}`: {e}", path.display()))?;
        let text = String::from_utf8(bytes).map_err(|e| {
            let (line, column) = utf8_error_place(e.as_bytes(), e.utf8_error().valid_up_to());
            format!(
                "{}:{line}:{column}: invalid UTF-8; save the file as UTF-8",
                path.display()
            )
        })?;
        Ok((path.display().to_string(), text))
    }
}

/// 1-based line and column (in characters) of byte `at`, all bytes before it being valid UTF-8.
fn utf8_error_place(bytes: &[u8], at: usize) -> (usize, usize) {
    let before = String::from_utf8_lossy(bytes.get(..at).unwrap_or_default());
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let line = before.matches('\n').count() + 1;
    let column = before.get(line_start..).map_or(0, |l| l.chars().count()) + 1;
    (line, column)
}

/// `path` with `.` components removed and `dir/..` pairs folded (without touching the file
/// system), so one file reached by two spellings has one name and include loops are found.
fn normalize(path: &Path) -> PathBuf {
    use std::path::Component;
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                let last_is_normal =
                    matches!(out.components().next_back(), Some(Component::Normal(_)));
                if last_is_normal {
                    out.pop();
                } else {
                    out.push("..");
                }
            }
            other => out.push(other.as_os_str()),
        }
    }
    if out.as_os_str().is_empty() {
        out.push(".");
    }
    out
}

/// Resolves names from a fixed in-memory table (name -> text); used for the bundled specs.
#[derive(Debug, Default, Clone)]
pub struct MemResolver {
    /// The files by the name an `include` gives, with their text.
    pub files: HashMap<String, String>,
}

impl Resolver for MemResolver {
    fn resolve(&self, _from: Option<&str>, name: &str) -> Result<(String, String), ResolveError> {
        self.files
            .get(name)
            .map(|t| (name.to_string(), t.clone()))
            .ok_or_else(|| ResolveError(format!("no bundled spec named `{name}`")))
    }
}

/// Parse `root` and, recursively, every file it includes. Files come back in evaluation order:
/// an included file before the file that includes it, each file once.
pub fn load_spec(
    root: &str,
    resolver: &dyn Resolver,
    map: &mut SourceMap,
) -> Result<Vec<(FileId, File)>, Vec<Diagnostic>> {
    let mut state = LoadState {
        resolver,
        done: HashMap::new(),
        stack: Vec::new(),
        files: Vec::new(),
        diags: Vec::new(),
    };
    match resolver.resolve(None, root) {
        Ok((name, text)) => state.visit(map, name, text),
        Err(msg) => state.diags.push(
            Diagnostic::error(Category::Name, None, format!("cannot load the spec: {msg}"))
                .with_help("check the path given on the command line"),
        ),
    }
    if state.diags.iter().any(Diagnostic::is_error) {
        Err(state.diags)
    } else {
        Ok(state.files)
    }
}

struct LoadState<'r> {
    resolver: &'r dyn Resolver,
    /// Canonical name -> file, for files fully loaded.
    done: HashMap<String, FileId>,
    /// Canonical names of the files being loaded (the include chain), for loop detection.
    stack: Vec<String>,
    files: Vec<(FileId, File)>,
    diags: Vec<Diagnostic>,
}

/// A safety net against include loops the names cannot show (e.g. through symbolic links).
const MAX_INCLUDE_DEPTH: usize = 64;

impl LoadState<'_> {
    /// Resolve an include as TeSSLa does: the name as written, else with `.tessla` appended.
    fn resolve(&self, from: &str, name: &str) -> Result<(String, String), ResolveError> {
        self.resolver.resolve(Some(from), name).or_else(|err| {
            if name.ends_with(".tessla") {
                return Err(err);
            }
            self.resolver
                .resolve(Some(from), &format!("{name}.tessla"))
                .map_err(|_| err)
        })
    }

    fn visit(&mut self, map: &mut SourceMap, name: String, text: String) {
        let path = Path::new(&name).to_path_buf();
        let id = map.add(name.clone(), Some(&path), text);
        let (file, mut diags) = crate::parse(&map.get(id).text, id);
        self.diags.append(&mut diags);
        self.stack.push(name.clone());
        for inc in &file.includes {
            if self.stack.len() >= MAX_INCLUDE_DEPTH {
                self.diags.push(
                    Diagnostic::error(
                        Category::Recursion,
                        Some(inc.span),
                        format!("includes nested more than {MAX_INCLUDE_DEPTH} deep"),
                    )
                    .with_help("an include loop through links? check the include chain"),
                );
                break;
            }
            match self.resolve(&name, &inc.path) {
                Ok((inc_name, inc_text)) => {
                    if self.stack.contains(&inc_name) {
                        self.diags.push(
                            Diagnostic::error(
                                Category::Recursion,
                                Some(inc.span),
                                format!("include loop: `{inc_name}` includes itself through this include"),
                            )
                            .with_label("this include closes the loop")
                            .with_help("remove one of the includes in the loop"),
                        );
                    } else if !self.done.contains_key(&inc_name) {
                        self.visit(map, inc_name, inc_text);
                    }
                }
                Err(msg) => self.diags.push(
                    Diagnostic::error(
                        Category::Name,
                        Some(inc.span),
                        format!("cannot include `{}`: {msg}", inc.path),
                    )
                    .with_label("included here")
                    .with_help("include paths are relative to the including file"),
                ),
            }
        }
        self.stack.pop();
        self.done.insert(name, id);
        self.files.push((id, file));
    }
}
