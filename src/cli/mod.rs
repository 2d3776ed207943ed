//! Command line: the arguments as clap reads them ([`args`]), `run`'s converted once into what
//! the core takes ([`config`]), one module per subcommand, the spec options they share
//! ([`spec_options`]), and the one error type every subcommand returns ([`error`]). This module parses
//! and dispatches, then reports a failure in its subcommand's style.

pub mod args;
pub mod check;
pub mod config;
pub mod ending;
pub mod error;
pub mod log_level;
#[cfg(feature = "tools")]
pub mod replay;
#[cfg(feature = "tools")]
pub mod report;
pub mod run;
#[cfg(feature = "tools")]
pub mod simulate;
pub mod spec_cmd;
pub mod spec_options;
pub mod trace;

pub use args::{Cli, Command};
pub use error::{CliError, CliResult, Code};

use clap::Parser;
use std::io::Write;
use std::process::ExitCode;

/// How a subcommand writes its error to stderr.
#[derive(Clone, Copy)]
enum Style {
    /// Telegraf's `E! ` prefix on every line (`run` and the tools).
    Log,
    /// The text as it is (`check` and `trace`, read by people and TeSSLa's tools).
    Plain,
}

/// Parse the command line, run the subcommand, report its error (if any) and return the exit code.
pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            // clap quotes a rejected value; a URL in it may carry a password.
            let text = crate::log::mask(&e.to_string());
            let written = if e.use_stderr() {
                std::io::stderr().lock().write_all(text.as_bytes())
            } else {
                std::io::stdout().lock().write_all(text.as_bytes())
            };
            drop(written);
            return ExitCode::from(u8::try_from(e.exit_code()).unwrap_or(2));
        }
    };
    let (result, style) = match cli.command {
        None => (run::run(cli.run), Style::Log),
        Some(Command::Run(a)) => (run::run(*a), Style::Log),
        Some(Command::Check(a)) => (check::run(a), Style::Plain),
        Some(Command::Trace(a)) => (trace::run(a), Style::Plain),
        #[cfg(feature = "tools")]
        Some(Command::Replay(a)) => (replay::run(a), Style::Log),
        #[cfg(feature = "tools")]
        Some(Command::Report(a)) => (report::run(a), Style::Log),
        #[cfg(feature = "tools")]
        Some(Command::Simulate(a)) => (simulate::run(a), Style::Log),
        Some(Command::Spec(a)) => (spec_cmd::run(*a), Style::Plain),
        Some(Command::Completions(a)) => (completions(a.shell), Style::Plain),
        Some(Command::Manpage) => (manpage(), Style::Plain),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            match style {
                Style::Log => {
                    log_error!("{}", e.message);
                    // Under Telegraf the message must reach its log before `Cmd.Wait` closes
                    // the pipes (a broken spec's diagnostic, at every restart).
                    ending::wait_until_read(std::time::Duration::from_secs(1));
                }
                Style::Plain => {
                    let mut text = crate::log::mask(&e.message);
                    if !text.ends_with('\n') {
                        text.push('\n');
                    }
                    // A closed stderr is not worth a panic: the exit code still tells.
                    let _ = std::io::stderr().lock().write_all(text.as_bytes());
                }
            }
            ExitCode::from(e.code as u8)
        }
    }
}

/// `completions SHELL`: the script clap_complete makes from [`Cli`].
fn completions(shell: clap_complete::Shell) -> CliResult {
    let mut cmd = <Cli as clap::CommandFactory>::command();
    let mut out = Vec::new();
    clap_complete::generate(shell, &mut cmd, "tessla-telegraf", &mut out);
    write_stdout(&out)
}

/// `manpage`: the roff page clap_mangen makes from [`Cli`] (the subcommands listed in it).
fn manpage() -> CliResult {
    let cmd = <Cli as clap::CommandFactory>::command();
    let mut out = Vec::new();
    clap_mangen::Man::new(cmd)
        .render(&mut out)
        .map_err(|e| CliError::io(format!("manpage: {e}")))?;
    write_stdout(&out)
}

fn write_stdout(bytes: &[u8]) -> CliResult {
    let mut stdout = std::io::stdout().lock();
    stdout
        .write_all(bytes)
        .and_then(|()| stdout.flush())
        .map_err(|e| CliError::io(format!("cannot write to stdout: {e}")))
}
