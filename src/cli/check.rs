//! `tessla-telegraf check SPEC`: parse and check a spec, print its inputs and outputs with types
//! and annotations, then its parameters (the top-level constants `--set` can change, with the
//! comment above each); exit 0, or 2 with diagnostics (also for a spec without outputs, unless
//! `--library`: a file of definitions other specs include). `--list-in-streams` and
//! `--list-out-streams` print only the streams' names, as TeSSLa's `compile-core` does.

use super::args::CheckArgs;
use super::error::{CliError, CliResult};
use super::spec_options::{load_options, require_outputs};
use std::io::Write;

pub fn run(mut args: CheckArgs) -> CliResult {
    args.spec_options.set_from_env();
    let options =
        load_options(&args.spec_options).map_err(|e| CliError::spec(format!("error: {e}")))?;
    let loaded =
        tessla_engine::load_file(&args.spec, &options).map_err(|e| CliError::spec(e.render()))?;
    if !loaded.warnings.is_empty() {
        // A closed stderr is not worth a panic.
        let _ = std::io::stderr().lock().write_all(
            tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, false).as_bytes(),
        );
    }
    // The Telegraf binding reads the annotations: check them as `run` does.
    crate::telegraf::binding::bindings(&loaded.program)
        .map_err(|e| CliError::spec(format!("error: {e}")))?;
    let p = &loaded.program;
    if args.list_in_streams || args.list_out_streams {
        return write_out(&list_streams(
            p,
            args.list_in_streams,
            args.list_out_streams,
        ));
    }
    if !args.library {
        require_outputs(&loaded.program, &args.spec.display().to_string())
            .map_err(|e| CliError::spec(format!("error: {e}")))?;
    }
    let ann = |a: &[tessla_engine::Annotation]| {
        a.iter()
            .map(|a| {
                let args: Vec<String> = a
                    .args
                    .iter()
                    .map(|(k, v)| match v {
                        tessla_engine::Value::Str(s) => format!("{k} = {s:?}"),
                        other => format!("{k} = {other}"),
                    })
                    .collect();
                format!(" @{}({})", a.name, args.join(", "))
            })
            .collect::<String>()
    };
    let mut out = String::new();
    for i in &p.inputs {
        out.push_str(&format!(
            "in  {}: Events[{}]{}\n",
            i.name,
            i.ty,
            ann(&i.annotations)
        ));
    }
    for o in &p.outputs {
        out.push_str(&format!(
            "out {}: Events[{}]{}\n",
            o.name,
            o.ty,
            ann(&o.annotations)
        ));
    }
    let params = parameters(&args.spec, &options.overrides);
    if !params.is_empty() {
        out.push_str("parameters (`--set`):\n");
        let width = params.iter().map(|p| p.0.len()).max().unwrap_or(0);
        for (name_value, comment) in &params {
            if comment.is_empty() {
                out.push_str(&format!("  {name_value}\n"));
            } else {
                out.push_str(&format!("  {name_value:width$}  -- {comment}\n"));
            }
        }
    }
    if args.library {
        let (defs, modules) = count_defs(&args.spec);
        out.push_str(&format!(
            "library: {defs} definitions in {modules} modules checked\n"
        ));
    }
    out.push_str(&format!(
        "{} inputs, {} outputs, {} stream nodes\n",
        p.inputs.len(),
        p.outputs.len(),
        p.nodes.len()
    ));
    if args.ir {
        out.push_str(&p.ir().to_string());
    }
    write_out(&out)
}

fn write_out(out: &str) -> CliResult {
    let mut stdout = std::io::stdout().lock();
    stdout
        .write_all(out.as_bytes())
        .and_then(|()| stdout.flush())
        .map_err(|e| CliError::io(format!("error: writing the result: {e}")))
}

/// The names of the inputs and/or outputs, one a line (inputs first), as TeSSLa's
/// `compile-core --list-in-streams` / `--list-out-streams` print them.
fn list_streams(p: &tessla_engine::Program, inputs: bool, outputs: bool) -> String {
    let ins = p.inputs.iter().map(|i| i.name.as_str()).filter(|_| inputs);
    let outs = p
        .outputs
        .iter()
        .map(|o| o.name.as_str())
        .filter(|_| outputs);
    ins.chain(outs).map(|n| format!("{n}\n")).collect()
}

/// How many definitions and modules the spec's files (includes too) hold, nested ones counted.
fn count_defs(spec: &std::path::Path) -> (usize, usize) {
    use tessla_syntax::ast::Statement;
    fn walk(statements: &[Statement], n: &mut (usize, usize)) {
        for st in statements {
            match st {
                Statement::Def(_) => n.0 += 1,
                Statement::Module { statements, .. } => {
                    n.1 += 1;
                    walk(statements, n);
                }
                _ => {}
            }
        }
    }
    let mut sources = tessla_syntax::source::SourceMap::new();
    let mut n = (0, 0);
    if let Ok(files) = tessla_syntax::include::load_spec(
        &spec.display().to_string(),
        &tessla_syntax::include::FsResolver,
        &mut sources,
    ) {
        for (_, file) in &files {
            walk(&file.statements, &mut n);
        }
    }
    n
}

/// The file system, then the bundled libraries (`include "Telegraf.tessla"` without the file),
/// as the spec was loaded: so a spec that includes them still has its parameters listed.
struct FsOrLibraries;

impl tessla_syntax::include::Resolver for FsOrLibraries {
    fn resolve(
        &self,
        from: Option<&str>,
        name: &str,
    ) -> Result<(String, String), tessla_syntax::include::ResolveError> {
        let fs = tessla_syntax::include::FsResolver.resolve(from, name);
        let file_name = name.strip_prefix("./").unwrap_or(name);
        match crate::bundled::LIBRARIES
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(file_name))
        {
            Some((n, text)) if fs.is_err() => Ok((format!("<bundled>/{n}"), text.to_string())),
            _ => fs,
        }
    }
}

/// The spec's parameters: top-level definitions without parameters whose body is a literal
/// (a number, possibly negated, a string, `true`/`false`), as `name = value` (the `--set` value
/// when given) with the comment lines right above each, in file order (includes first).
fn parameters(spec: &std::path::Path, overrides: &[(String, String)]) -> Vec<(String, String)> {
    use tessla_syntax::ast::{Body, ExprKind, Statement};
    let mut sources = tessla_syntax::source::SourceMap::new();
    let Ok(files) = tessla_syntax::include::load_spec(
        &spec.display().to_string(),
        &FsOrLibraries,
        &mut sources,
    ) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for (id, file) in &files {
        let text = &sources.get(*id).text;
        for st in &file.statements {
            let Statement::Def(d) = st else { continue };
            let Body::Expr { expr, .. } = &d.body else {
                continue;
            };
            let literal = match &expr.kind {
                ExprKind::Int { .. } | ExprKind::Float(_) | ExprKind::Str { .. } => true,
                ExprKind::Var(v) => v.name == "true" || v.name == "false",
                ExprKind::Unary { operand, .. } => {
                    matches!(operand.kind, ExprKind::Int { .. } | ExprKind::Float(_))
                }
                _ => false,
            };
            if d.params.is_some() || !literal {
                continue;
            }
            let name = &d.name.name;
            let spec_value = text
                .get(expr.span.start as usize..expr.span.end as usize)
                .unwrap_or("?")
                .trim();
            let shown = match overrides.iter().rev().find(|(n, _)| n == name) {
                Some((_, v)) => format!("{name} = {v} (--set; spec {spec_value})"),
                None => format!("{name} = {spec_value}"),
            };
            out.push((shown, comment_above(text, d.span.start as usize)));
        }
    }
    out
}

/// The `--` comment lines directly above byte `at` (the start of a definition), joined.
fn comment_above(text: &str, at: usize) -> String {
    let before = text.get(..at).unwrap_or("");
    let mut lines: Vec<&str> = Vec::new();
    for line in before
        .lines()
        .rev()
        .skip(usize::from(!before.ends_with('\n')))
    {
        match line.trim().strip_prefix("--") {
            Some(c) => lines.push(c.trim()),
            None => break,
        }
    }
    lines.reverse();
    // The first sentence: the unit and what the parameter is; the spec has the rest.
    let all = lines.join(" ");
    match all.find(". ") {
        Some(i) => all[..=i].to_string(),
        None => all,
    }
}
