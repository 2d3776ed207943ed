//! Loading a spec: read files (through an include resolver), parse, resolve, check, lower to a
//! [`Program`].
//!
//! Owns: the single entry point every command uses (`check`, `trace`, `run`, the bundled robot
//! monitors), the options that affect compilation (base time, `--set` overrides, the
//! application's natives) and the error
//! type carrying rendered-ready diagnostics.

use crate::builtins::Natives;
use crate::front::lower;
use crate::runtime::exec::Program;
use std::path::Path;
use std::sync::Arc;
use tessla_syntax::diag::Category;
use tessla_syntax::diag::Diagnostic;
use tessla_syntax::include::{FsResolver, ResolveError, Resolver, load_spec};
use tessla_syntax::source::SourceMap;

/// Options that change how a spec compiles.
#[derive(Debug, Clone, Default)]
pub struct LoadOptions {
    /// TeSSLa's base-time form (`1 ns`, `1 ms`, `33333 µs`, `1ms`); `None` = 1 ns.
    pub base_time: Option<String>,
    /// `--set NAME=VALUE` overrides of top-level constants, in command-line order.
    pub overrides: Vec<(String, String)>,
    /// TeSSLa's rule when no base time is set: a time literal (`100ms`) is a compile error.
    /// When true and `base_time` is `None`, time literals are rejected (the conformance runner
    /// sets it for cases without a base time); when false, `None` means 1 ns.
    pub time_units_need_base: bool,
    /// Library files bundled with the program, by file name (`Telegraf.tessla`, the TeSSLa
    /// Telegraf Connector's annotations): an `include` of that name (`"./Telegraf.tessla"`,
    /// `"Telegraf.tessla"`, any case) with no such file beside the including spec reads the
    /// bundled text instead. A file that exists is read as written.
    pub bundled_includes: Vec<(String, String)>,
    /// Called once for each bundled include used: (the name as written, the including file).
    pub on_bundled_include: Option<fn(&str, &str)>,
    /// The application's natives, added to the builtins table for this load: a spec reaches
    /// each through `extern("name")` (see [`Natives`]).
    pub natives: Natives,
}

/// A checked, compiled spec.
#[derive(Debug)]
pub struct Loaded {
    pub program: Arc<Program>,
    /// Every file read, for rendering `warnings`.
    pub sources: SourceMap,
    pub warnings: Vec<Diagnostic>,
}

/// Why a spec could not be loaded; `diagnostics` point into `sources`.
#[derive(Debug)]
pub struct LoadError {
    pub sources: SourceMap,
    pub diagnostics: Vec<Diagnostic>,
}

impl LoadError {
    /// All diagnostics rendered with file, line, column and a caret (plain text, no colour).
    pub fn render(&self) -> String {
        tessla_syntax::diag::render(&self.diagnostics, &self.sources, false)
    }
}

impl std::fmt::Display for LoadError {
    /// Same text as [`LoadError::render`].
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.render())
    }
}

impl std::error::Error for LoadError {}

/// Load the spec at `path` from the file system (includes relative to the including file,
/// then [`LoadOptions::bundled_includes`]).
pub fn load_file(path: &Path, options: &LoadOptions) -> Result<Loaded, LoadError> {
    load_with(
        &path.display().to_string(),
        &file_resolver(options),
        options,
    )
}

/// The resolver [`load_file`] reads through: the file system, then `options`' bundled
/// includes. For callers that wrap it (a spec bundle records every file a load reads).
pub fn file_resolver(options: &LoadOptions) -> impl Resolver + '_ {
    FsOrBundled {
        bundled: &options.bundled_includes,
        on_use: options.on_bundled_include,
    }
}

/// The file system, with [`LoadOptions::bundled_includes`] for includes of missing files.
struct FsOrBundled<'a> {
    bundled: &'a [(String, String)],
    on_use: Option<fn(&str, &str)>,
}

impl Resolver for FsOrBundled<'_> {
    fn resolve(&self, from: Option<&str>, name: &str) -> Result<(String, String), ResolveError> {
        let Some(from) = from else {
            return FsResolver.resolve(None, name);
        };
        let beside = Path::new(from)
            .parent()
            .map_or_else(|| Path::new(name).to_path_buf(), |d| d.join(name));
        let file_name = name.strip_prefix("./").unwrap_or(name);
        let bundled = self
            .bundled
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(file_name));
        match bundled {
            Some((n, text)) if !beside.exists() => {
                if let Some(f) = self.on_use {
                    f(name, from);
                }
                Ok((format!("<bundled>/{n}"), text.clone()))
            }
            _ => FsResolver.resolve(Some(from), name),
        }
    }
}

/// Load the spec named `root` through `resolver` (the bundled specs use an in-memory resolver).
pub fn load_with(
    root: &str,
    resolver: &dyn Resolver,
    options: &LoadOptions,
) -> Result<Loaded, LoadError> {
    let mut sources = SourceMap::new();
    let (base, base_unit) = match options
        .base_time
        .as_deref()
        .map(lower::time::parse_base_parts)
    {
        None => (1_000_000, 1_000_000),
        Some(Ok((count, unit))) => (count * unit, unit),
        Some(Err(msg)) => {
            return Err(LoadError {
                sources,
                diagnostics: vec![Diagnostic::error(Category::Time, None, msg.0)],
            });
        }
    };
    let files = match load_spec(root, resolver, &mut sources) {
        Ok(f) => f,
        Err(diagnostics) => {
            return Err(LoadError {
                sources,
                diagnostics,
            });
        }
    };
    let mut asts: Vec<_> = files.into_iter().map(|(_, f)| f).collect();
    let mut library = None;
    // The bundled prelude's definitions the spec refers to (none for a spec of builtins only).
    if let Some(text) = crate::front::prelude::needed(&asts) {
        let id = sources.add("<prelude>", None, text.clone());
        library = Some(id);
        let (file, diagnostics) = tessla_syntax::parser::parse(&text, id);
        if !diagnostics.is_empty() {
            return Err(LoadError {
                sources,
                diagnostics,
            });
        }
        asts.push(file);
    }
    let resolved = crate::front::resolve::Resolved::with_library(&asts, library);
    let typed = match crate::front::typeck::check_with(&resolved, &options.natives) {
        Ok(typed) => typed,
        Err(diagnostics) => {
            return Err(LoadError {
                sources,
                diagnostics,
            });
        }
    };
    let result = lower::Compiler::new(&sources, &typed, base)
        .with_base_unit(base_unit)
        .with_time_units(!(options.time_units_need_base && options.base_time.is_none()))
        .program(&options.overrides);
    match result {
        Ok((program, warnings)) => Ok(Loaded {
            program: Arc::new(Program::new(program)),
            sources,
            warnings,
        }),
        Err(diagnostics) => Err(LoadError {
            sources,
            diagnostics,
        }),
    }
}
