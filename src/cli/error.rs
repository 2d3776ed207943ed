//! The one error type every subcommand returns ([`CliError`]: the exit code and the message
//! for stderr).
//!
//! Exit codes (documented in `--help` and the book, "With Telegraf", "Exit codes"):
//! - 0: success (also: stdin EOF, SIGTERM/SIGINT after flushing, stdout closed by the reader)
//! - 1: a runtime error in `trace` mode (decreasing timestamps, multiple events, error values)
//! - 2: a spec error (parse, type, include ...) or a bad command line
//! - 3: an I/O error that stops the run (input file unreadable, UDP address not bindable)
//! - 4: `run`'s step watchdog: a step made no progress for `--step-timeout`
//! - 5: `spec publish`, `spec rollback`, `spec decide`: the fleet aborted the rollout

use crate::nats::conn::Failure;
use std::fmt;

/// Why a subcommand failed, as its exit code says (the book, "Exit codes"); success is 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Code {
    /// 1: a runtime error in `trace` mode.
    Runtime = 1,
    /// 2: a spec error or a bad command line.
    Spec = 2,
    /// 3: an I/O error that stops the run.
    Io = 3,
    /// 5: the fleet aborted a rollout (`spec publish`, `rollback`, `decide`).
    Aborted = 5,
}

/// A subcommand's failure: the exit code and what to tell the user (written to stderr by
/// `cli::main`, in the subcommand's style: `E! ` lines or plain text).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CliError {
    pub code: Code,
    pub message: String,
}

impl CliError {
    pub fn new(code: Code, message: impl Into<String>) -> Self {
        CliError {
            code,
            message: message.into(),
        }
    }

    pub fn spec(message: impl Into<String>) -> Self {
        Self::new(Code::Spec, message)
    }

    pub fn io(message: impl Into<String>) -> Self {
        Self::new(Code::Io, message)
    }

    pub fn aborted(message: impl Into<String>) -> Self {
        Self::new(Code::Aborted, message)
    }

    pub fn runtime(message: impl Into<String>) -> Self {
        Self::new(Code::Runtime, message)
    }
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for CliError {}

/// The one conversion of a NATS failure (state store, spec channel): a configuration mistake is
/// exit 2, the connection exit 3; the message as the failure tells it (callers name the part
/// with [`CliError::within`]).
impl From<Failure> for CliError {
    fn from(f: Failure) -> Self {
        match f {
            Failure::Config(m) => CliError::spec(m),
            Failure::Io(m) => CliError::io(m),
        }
    }
}

impl CliError {
    /// The same error, its message led by `what: ` (`state`, `spec channel`, `spec`).
    pub fn within(mut self, what: &str) -> Self {
        self.message = format!("{what}: {}", self.message);
        self
    }
}

/// What every subcommand returns.
pub type CliResult = Result<(), CliError>;
