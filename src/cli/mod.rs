//! Command line: argument definitions (clap) and dispatch to one module per subcommand.
//!
//! Exit codes (documented in the README):
//! - 0: success (also: stdin EOF, SIGTERM/SIGINT after flushing, stdout closed by the reader)
//! - 1: a runtime error in `trace` mode (decreasing timestamps, multiple events, error values)
//! - 2: a spec error (parse, type, include ...) or a bad command line
//! - 3: an I/O error that stops the run (input file unreadable, UDP address not bindable)

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
use std::path::PathBuf;

pub const EXIT_OK: i32 = 0;
pub const EXIT_RUNTIME: i32 = 1;
pub const EXIT_SPEC: i32 = 2;
pub const EXIT_IO: i32 = 3;

#[derive(Debug, Parser)]
#[command(
    name = "tessla-telegraf",
    version,
    about = "Runtime verification of TeSSLa specifications as a Telegraf processors.execd plugin",
    args_conflicts_with_subcommands = true
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
    Run(RunArgs),
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
}

/// Options shared by every subcommand that loads a spec.
#[derive(Debug, Args, Clone, Default)]
pub struct SpecOptions {
    /// Base time unit of time literals, in TeSSLa's form (`1 ns`, `1 ms`, `33333 µs`).
    #[arg(long, value_name = "UNIT", default_value = "1 ns")]
    pub base_time: String,
    /// Override a top-level constant of the spec: `--set delta=0.05` (repeatable).
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub set: Vec<String>,
}

#[derive(Debug, Args, Clone, Default)]
pub struct CheckArgs {
    /// The `.tessla` file.
    pub spec: PathBuf,
    /// Also print the lowered program: its nodes in evaluation order, and the outputs' nodes.
    #[arg(long)]
    pub ir: bool,
    #[command(flatten)]
    pub spec_options: SpecOptions,
}

#[derive(Debug, Args, Clone, Default)]
pub struct TraceArgs {
    /// The `.tessla` file.
    pub spec: PathBuf,
    /// The input trace (`TS: name = value` lines); stdin when absent.
    pub trace: Option<PathBuf>,
    #[command(flatten)]
    pub spec_options: SpecOptions,
}

#[derive(Debug, Args, Clone, Default)]
pub struct RunArgs {
    /// The `.tessla` file; without it the bundled robot monitors run.
    #[arg(long)]
    pub spec: Option<PathBuf>,
    #[command(flatten)]
    pub spec_options: SpecOptions,
    /// Do not echo input records (by default each is written back unchanged before its outputs;
    /// never in UDP mode).
    #[arg(long)]
    pub no_passthrough: bool,
    /// What to do with a record whose timestamp is not after the last evaluated step.
    #[arg(long, value_enum, default_value_t)]
    pub late: crate::telegraf::processor::LateMode,
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
    #[arg(long, value_name = "N", default_value_t = crate::telegraf::processor::DEFAULT_MAX_INSTANCES,
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
    #[arg(long, value_name = "FILE|nats://HOST:PORT/BUCKET", value_parser = crate::telegraf::state::parse_target)]
    pub state: Option<crate::telegraf::state::Target>,
    /// Also save the state this often while running (`30s`, `5m`), so a crash or SIGKILL
    /// loses at most this much. Needs --state.
    #[arg(long, value_name = "DURATION", value_parser = humantime::parse_duration, requires = "state")]
    pub state_interval: Option<std::time::Duration>,
}

pub fn main() -> i32 {
    let cli = Cli::parse();
    match cli.command {
        None => run(cli.run),
        Some(Command::Run(a)) => run(a),
        Some(Command::Check(a)) => check(a),
        Some(Command::Trace(a)) => trace(a),
        #[cfg(feature = "tools")]
        Some(Command::Replay(a)) => replay::run(a),
        #[cfg(feature = "tools")]
        Some(Command::Report(a)) => report::run(a),
        #[cfg(feature = "tools")]
        Some(Command::Simulate(a)) => simulate::run(a),
    }
}

fn run(args: RunArgs) -> i32 {
    run::run(args)
}

fn check(args: CheckArgs) -> i32 {
    check::run(args)
}

fn trace(args: TraceArgs) -> i32 {
    trace::run(args)
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
        base_time: Some(o.base_time.clone()),
        overrides,
        time_units_need_base: false,
    })
}
