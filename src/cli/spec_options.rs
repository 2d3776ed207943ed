//! The spec every subcommand loads: the options that shape it (`--base-time`, `--set`, and
//! `TESSLA_SET` without `--set`: [`SpecOptions`]), the engine's load options made from them
//! ([`load_options`]), and the rule that a spec without outputs checks nothing
//! ([`require_outputs`]). Not the `spec` subcommand (the fleet's spec channel): that is
//! `spec_cmd.rs`.

use clap::Args;

/// Options shared by every subcommand that loads a spec.
#[derive(Debug, Args, Clone, Default)]
pub struct SpecOptions {
    /// Base time unit of time literals, in TeSSLa's form (`1 ns`, `1 ms`, `33333 µs`); `run`
    /// and `check` default to `1 ns` (Telegraf's unit); `trace` without it rejects time literals,
    /// as TeSSLa's interpreter does.
    #[arg(short = 't', long, value_name = "UNIT")]
    pub base_time: Option<String>,
    /// Override a top-level constant of the spec: `--set delta=0.05` (repeatable). `run` and
    /// `check` without any --set read the environment variable TESSLA_SET instead:
    /// NAME=VALUE assignments separated by spaces (`TESSLA_SET="delta=0.05 gain=1.0"`; a
    /// string value in double quotes may hold spaces: `greeting="hello world"`).
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub set: Vec<String>,
}

/// The environment variable [`SpecOptions::set_from_env`] reads.
pub const SET_ENV: &str = "TESSLA_SET";

impl SpecOptions {
    /// Without `--set` on the command line, take the assignments from [`SET_ENV`] (`run` and
    /// `check`: Telegraf's child and the systemd drop-in's check read the same variable, so
    /// the overrides are written once, in /etc/default/tessla-telegraf).
    pub fn set_from_env(&mut self) {
        if self.set.is_empty()
            && let Ok(v) = std::env::var(SET_ENV)
        {
            self.set = assignments(&v);
        }
    }
}

/// The assignments of a [`SET_ENV`] value: split at whitespace outside TeSSLa string literals,
/// so that `greeting="hello world" delta=0.1` is two (a literal's `\"` does not end it).
/// Hand-written: shell-style splitters (`shlex`) would strip the quotes the literal needs.
fn assignments(v: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let (mut quoted, mut escaped) = (false, false);
    for c in v.chars() {
        if quoted {
            quoted = escaped || c != '"';
            escaped = !escaped && c == '\\';
        } else if c.is_whitespace() {
            if !cur.is_empty() {
                out.push(std::mem::take(&mut cur));
            }
            continue;
        } else {
            quoted = c == '"';
        }
        cur.push(c);
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

impl SpecOptions {
    /// `--base-time`, or `1 ns` (Telegraf's unit) when not given.
    pub fn base_time_or_default(&self) -> String {
        self.base_time.clone().unwrap_or_else(|| "1 ns".to_string())
    }
}

/// Why the spec options or the spec they load cannot be used (a spec error, exit 2).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpecOptionError {
    /// A `--set` without `=`.
    #[error("--set {0}: expected NAME=VALUE")]
    BadSet(String),
    /// The spec (named as given) has no `out`.
    #[error(
        "{0}: the spec has no outputs, so it would check nothing and write nothing; \
         add `out NAME` for each stream to report (or `out *`); for a library of \
         definitions that other specs include, use `check --library`"
    )]
    NoOutputs(String),
    /// This program's natives could not be registered (a defect of the build, not of the spec).
    #[error("{0}")]
    Natives(#[from] tessla_engine::builtins::RegisterError),
}

impl From<SpecOptionError> for crate::cli::error::CliError {
    fn from(e: SpecOptionError) -> Self {
        crate::cli::error::CliError::spec(e.to_string())
    }
}

/// The engine's load options from the command line (`--base-time`, `--set NAME=VALUE`), with
/// this program's natives (`crate::natives`): every command that compiles a spec starts here.
pub fn load_options(o: &SpecOptions) -> Result<tessla_engine::LoadOptions, SpecOptionError> {
    let overrides = o
        .set
        .iter()
        .map(|s| {
            s.split_once('=')
                .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
                .ok_or_else(|| SpecOptionError::BadSet(s.clone()))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(tessla_engine::LoadOptions {
        base_time: Some(o.base_time_or_default()),
        overrides,
        time_units_need_base: false,
        bundled_includes: crate::bundled::LIBRARIES
            .iter()
            .map(|(n, t)| (n.to_string(), t.to_string()))
            .collect(),
        on_bundled_include: Some(crate::bundled::say_bundled_include),
        natives: crate::natives::natives()?,
    })
}

/// A spec without outputs checks nothing and writes nothing: a spec error for `check`, `run`
/// and `trace`.
pub fn require_outputs(
    program: &tessla_engine::Program,
    spec: &str,
) -> Result<(), SpecOptionError> {
    if program.outputs.is_empty() {
        Err(SpecOptionError::NoOutputs(spec.to_string()))
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::assignments;

    #[test]
    fn assignments_split_at_spaces_outside_string_literals() {
        assert_eq!(
            assignments("  delta=0.05\tgain=1.0 \n"),
            ["delta=0.05", "gain=1.0"]
        );
        assert_eq!(
            assignments(r#"greeting="hello world" delta=0.1"#),
            [r#"greeting="hello world""#, "delta=0.1"]
        );
        // An escaped quote does not end the literal; an escaped backslash before the quote
        // does not keep it open.
        assert_eq!(
            assignments(r#"a="say \"hi there\"" b="c:\\" d=1"#),
            [r#"a="say \"hi there\"""#, r#"b="c:\\""#, "d=1"]
        );
        assert!(assignments("   ").is_empty());
        // An unclosed literal keeps the rest: the spec's check then names the bad value.
        assert_eq!(assignments(r#"a="x y"#), [r#"a="x y"#]);
    }
}
