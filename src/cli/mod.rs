//! Command line: argument definitions (clap), dispatch to one module per subcommand, and the one
//! error type every subcommand returns ([`CliError`]: the exit code and the message for stderr).
//!
//! Exit codes (documented in the README):
//! - 0: success (also: stdin EOF, SIGTERM/SIGINT after flushing, stdout closed by the reader)
//! - 1: a runtime error in `trace` mode (decreasing timestamps, multiple events, error values)
//! - 2: a spec error (parse, type, include ...) or a bad command line
//! - 3: an I/O error that stops the run (input file unreadable, UDP address not bindable)
//! - 4: `run`'s step watchdog: a step made no progress for `--step-timeout`

pub mod check;
pub mod run;
pub mod run_fleet;
pub mod trace;

use clap::{Args, Parser, Subcommand};

#[cfg(feature = "tools")]
pub mod replay;
#[cfg(feature = "tools")]
pub mod report;
#[cfg(feature = "tools")]
pub mod simulate;
use std::fmt;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// Why a subcommand failed, as its exit code says (README "Exit codes"); success is 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Code {
    /// 1: a runtime error in `trace` mode.
    Runtime = 1,
    /// 2: a spec error or a bad command line.
    Spec = 2,
    /// 3: an I/O error that stops the run.
    Io = 3,
}

/// A subcommand's failure: the exit code and what to tell the user (written to stderr by
/// [`main`], in the subcommand's style: `E! ` lines or plain text).
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

/// What every subcommand returns.
pub type CliResult = Result<(), CliError>;

/// How a subcommand writes its error to stderr.
#[derive(Clone, Copy)]
enum Style {
    /// Telegraf's `E! ` prefix on every line (`run` and the tools).
    Log,
    /// The text as it is (`check` and `trace`, read by people and TeSSLa's tools).
    Plain,
}

/// `--version`: the crate's version, the commit it was built from, the TeSSLa version implemented.
pub const VERSION: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    " (commit ",
    env!("TESSLA_TELEGRAF_COMMIT"),
    "; implements TeSSLa 1.2)"
);

/// The exit codes, as `--help` and the man page list them (README, "Exit codes").
pub const EXIT_CODES: &str = "Exit codes:
  0: success: input ended (EOF), SIGTERM/SIGINT after flushing, or stdout closed by the reader
  1: a runtime error in `trace` mode
  2: a spec error or a bad command line, reported before any input is read
  3: an I/O error that stops the run
  4: `run`'s step watchdog: one step made no progress for --step-timeout (an evaluation that does
     not end, or a stdout nobody reads); Telegraf restarts the child";

#[derive(Debug, Parser)]
#[command(
    name = "tessla-telegraf",
    version = VERSION,
    about = "Runtime verification of TeSSLa specifications as a Telegraf processors.execd plugin",
    args_conflicts_with_subcommands = true,
    after_help = EXIT_CODES
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    /// `run` is the default subcommand: its options may be given without the word `run`.
    #[command(flatten)]
    pub run: RunArgs,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Read line protocol (stdin, or UDP), check it against the spec, write verdicts (default).
    Run(Box<RunArgs>),
    /// Parse and check a spec; print its inputs and outputs with types and annotations.
    Check(CheckArgs),
    /// Run a spec over a TeSSLa input trace and print TeSSLa's output trace format.
    Trace(TraceArgs),
    /// Publish a recorded robot run to MQTT as the robot's JSON messages.
    #[cfg(feature = "tools")]
    Replay(replay::ReplayArgs),
    /// Render a run's line protocol (pass-through and verdicts) as an HTML report with SVG plots.
    #[cfg(feature = "tools")]
    Report(report::ReportArgs),
    /// Run a simulated TurtleBot3 in closed loop with the monitors (the digital twin's behaviour).
    #[cfg(feature = "tools")]
    Simulate(simulate::SimulateArgs),
    /// Print a shell completion script for this command line (`make install` installs them).
    Completions(CompletionsArgs),
    /// Print the man page (roff), made from this command line (`make install` installs it).
    Manpage,
}

#[derive(Debug, Args, Clone)]
pub struct CompletionsArgs {
    /// The shell to complete in.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

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
    /// NAME=VALUE assignments separated by spaces (`TESSLA_SET="delta=0.05 gain=1.0"`).
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub set: Vec<String>,
}

/// The environment variable [`SpecOptions::set_from_env`] reads.
pub const SET_ENV: &str = "TESSLA_SET";

/// The environment variable `run` takes its spec from without `--spec`.
pub const SPEC_ENV: &str = "TESSLA_SPEC";

impl RunArgs {
    /// Without `--spec`, the spec [`SPEC_ENV`] names (when set and not empty); without `--set`,
    /// the assignments of [`SET_ENV`].
    pub fn from_env(&mut self) {
        if self.spec.is_none()
            && let Some(path) = std::env::var_os(SPEC_ENV).filter(|p| !p.is_empty())
        {
            self.spec = Some(PathBuf::from(path));
        }
        self.spec_options.set_from_env();
    }
}

impl SpecOptions {
    /// Without `--set` on the command line, take the assignments from [`SET_ENV`] (`run` and
    /// `check`: Telegraf's child and the systemd drop-in's check read the same variable, so
    /// the overrides are written once, in /etc/default/tessla-telegraf).
    pub fn set_from_env(&mut self) {
        if self.set.is_empty()
            && let Ok(v) = std::env::var(SET_ENV)
        {
            self.set = v.split_whitespace().map(str::to_string).collect();
        }
    }
}

#[derive(Debug, Args, Clone, Default)]
pub struct CheckArgs {
    /// The `.tessla` file.
    pub spec: PathBuf,
    /// Also print the lowered program: its nodes in evaluation order, and the outputs' nodes.
    #[arg(long)]
    pub ir: bool,
    /// Check a library of definitions meant to be included by other specs: no outputs needed
    /// (without this flag a spec without outputs is an error, since it would check nothing).
    #[arg(long)]
    pub library: bool,
    /// Print only the names of the spec's input streams, one a line (TeSSLa's `compile-core
    /// --list-in-streams`); with --list-out-streams, the outputs' names follow.
    #[arg(long)]
    pub list_in_streams: bool,
    /// Print only the names of the spec's output streams, one a line (TeSSLa's `compile-core
    /// --list-out-streams`).
    #[arg(long)]
    pub list_out_streams: bool,
    #[command(flatten)]
    pub spec_options: SpecOptions,
}

#[derive(Debug, Args, Clone, Default)]
pub struct TraceArgs {
    /// The `.tessla` file.
    pub spec: PathBuf,
    /// The input trace (`TS: name = value` lines; with --ctf a CTF trace directory); stdin when
    /// absent (never with --ctf).
    pub trace: Option<PathBuf>,
    /// Stop when this output stream writes its first event (TeSSLa's `-S`).
    #[arg(short = 'S', long, value_name = "STREAM")]
    pub stop_on: Option<String>,
    /// Stop reading after N+1 input events of a text or CSV trace, N events of a CTF trace (as
    /// TeSSLa's interpreter counts each), then end the run as at the end of the trace.
    #[arg(short = 'a', long, value_name = "N")]
    pub abort_at: Option<u64>,
    /// An event on a stream the spec does not declare is an error (exit 1); by default it is
    /// ignored, but time still advances to its timestamp, as in TeSSLa's interpreter.
    #[arg(short = 'r', long)]
    pub reject_undeclared_inputs: bool,
    /// The trace is CSV: a header `time,stream1,stream2,...`, then `TS,value,value,...` lines
    /// (an empty column is no event; values are TeSSLa expressions).
    #[arg(long, conflicts_with = "ctf")]
    pub csv: bool,
    /// The trace is a CTF 1.8 (Common Trace Format) trace directory: each event is an event of the
    /// input named after it, of type `Events[CTF]` (read with `CTF.getInt`/`CTF.getString`).
    #[arg(long)]
    pub ctf: bool,
    #[command(flatten)]
    pub spec_options: SpecOptions,
}

#[derive(Debug, Args, Clone, Default)]
pub struct RunArgs {
    /// The `.tessla` file; without it the bundled robot monitors run. Without --spec, the
    /// environment variable TESSLA_SPEC names it when set and not empty (Telegraf's child
    /// inherits it from the systemd drop-in's EnvironmentFile, /etc/default/tessla-telegraf,
    /// which the drop-in's check reads too: the path is written in one place).
    #[arg(long)]
    pub spec: Option<PathBuf>,
    #[command(flatten)]
    pub spec_options: SpecOptions,
    /// Do not echo input records (by default each is written back unchanged before its outputs;
    /// never in UDP mode).
    #[arg(long)]
    pub no_passthrough: bool,
    /// What to do with a record stamped before its instance's last step (README, "Time"): a
    /// step of its own 1 ns after it, or dropped. A record with the same timestamp as the last
    /// step is always stepped 1 ns after it.
    #[arg(long, value_enum, default_value_t)]
    pub late: crate::processor::LateMode,
    /// Refuse a record stamped more than this ahead of the wall clock (warned, counted, passed
    /// through, not evaluated), so one wrong timestamp cannot move a monitor's clock; `off` for
    /// simulated data stamped in the future.
    #[arg(long, value_name = "DURATION|off", default_value = "10s", value_parser = parse_bound)]
    pub max_ahead: Bound,
    /// While an instance's input is silent, its time follows the wall clock this far behind, so
    /// that `delay`s (watchdogs, timeouts, `period`) fire while the robot is quiet; a record
    /// delivered later than this after its time is late. `off`: time moves only with the
    /// records (as in TeSSLa's offline traces; for replaying files slower than they were recorded).
    #[arg(long, value_name = "DURATION|off", default_value = "250ms", value_parser = parse_bound)]
    pub allowed_lateness: Bound,
    /// Measurement of the metric that groups outputs without a Telegraf annotation.
    #[arg(long, default_value = "tessla")]
    pub measurement: String,
    /// Add a static tag to every output metric: `--tag site=lab` (repeatable).
    #[arg(long = "tag", value_name = "KEY=VALUE")]
    pub tags: Vec<String>,
    /// UDP mode (the TeSSLa Telegraf Connector's wiring): receive line protocol on this address.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:1653")]
    pub udp_listen: Option<String>,
    /// UDP mode: send outputs to this address.
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:1654")]
    pub udp_send: String,
    /// UDP mode: largest datagram to send, in bytes (lines are never split).
    #[arg(long, value_name = "BYTES", default_value_t = 8192)]
    pub udp_max_datagram: usize,
    /// Least severe messages written to stderr.
    #[arg(long, value_enum, default_value_t)]
    pub log_level: crate::log::Level,
    /// One monitor instance per distinct value of these tags (`--instance-by topic` or
    /// `--instance-by robot,site`); every output line carries them. Default: one instance.
    #[arg(long, value_name = "TAG[,TAG]", value_delimiter = ',')]
    pub instance_by: Vec<String>,
    /// Most monitor instances kept; past it the least recently used is evicted (counted, warned).
    #[arg(long, value_name = "N", default_value_t = crate::processor::DEFAULT_MAX_INSTANCES,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    pub max_instances: usize,
    /// With --instance-by, on stdin: spread the instances over this many threads (default: the
    /// machine's cores; always 1 with --state, whose file holds one processor's instances, and in
    /// UDP mode, which answers datagram by datagram). Each instance's outputs keep their order and
    /// the output set is the same as with one thread; lines of different instances read together
    /// may come in another order (pass-through included). --max-instances stays the total, split
    /// evenly among the threads.
    #[arg(long, value_name = "N",
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=1024))]
    pub threads: Option<usize>,
    /// Evict a monitor instance that received no record for this long (wall clock): `30s`, `5m`, `1h`.
    #[arg(long, value_name = "DURATION", value_parser = humantime::parse_duration)]
    pub instance_idle: Option<std::time::Duration>,
    /// Save every monitor instance's state to FILE on shutdown (EOF, SIGTERM, SIGINT) and
    /// continue from it at start, so a Telegraf restart or reload keeps the monitors' state.
    /// `nats://HOST:PORT[,...]/BUCKET[?lease=NAME&ttl=3s&replicas=3]`: a JetStream key-value
    /// bucket shared by a fleet's processes (docs/state-and-reload.md).
    #[arg(long, value_name = "FILE|nats://HOST:PORT/BUCKET", value_parser = crate::state::parse_target)]
    pub state: Option<crate::state::Target>,
    /// Also save the state this often while running (`30s`, `5m`), so a crash or SIGKILL
    /// loses at most this much. Needs --state.
    #[arg(long, value_name = "DURATION", value_parser = humantime::parse_duration, requires = "state")]
    pub state_interval: Option<std::time::Duration>,
    /// Exit with code 4 when one step (evaluating a record or a fallen-due delay, and writing its
    /// outputs) makes no progress for this long, so that Telegraf restarts the monitor: Telegraf
    /// never restarts a child that is alive, and blocks on its full stdin pipe. `0` disables.
    #[arg(long, value_name = "DURATION", default_value = "10s", value_parser = humantime::parse_duration)]
    pub step_timeout: std::time::Duration,
}

/// A duration, or `off`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Bound(pub Option<std::time::Duration>);

fn parse_bound(s: &str) -> Result<Bound, String> {
    if s.eq_ignore_ascii_case("off") {
        return Ok(Bound(None));
    }
    humantime::parse_duration(s)
        .map(|d| Bound(Some(d)))
        .map_err(|e| format!("{e} (a duration such as `10s`, `5m`, or `off`)"))
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
        Some(Command::Completions(a)) => (completions(a.shell), Style::Plain),
        Some(Command::Manpage) => (manpage(), Style::Plain),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            match style {
                Style::Log => {
                    crate::log::log(crate::log::Level::Error, &e.message);
                    // Under Telegraf the message must reach its log before `Cmd.Wait` closes
                    // the pipes (a broken spec's diagnostic, at every restart).
                    run::wait_until_read(std::time::Duration::from_secs(1));
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

impl SpecOptions {
    /// `--base-time`, or `1 ns` (Telegraf's unit) when not given.
    pub fn base_time_or_default(&self) -> String {
        self.base_time.clone().unwrap_or_else(|| "1 ns".to_string())
    }
}

/// The engine's load options from the command line (`--base-time`, `--set NAME=VALUE`).
pub fn load_options(o: &SpecOptions) -> Result<tessla_engine::LoadOptions, String> {
    let overrides = o
        .set
        .iter()
        .map(|s| {
            s.split_once('=')
                .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
                .ok_or_else(|| format!("--set {s}: expected NAME=VALUE"))
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
    })
}
