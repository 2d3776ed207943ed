//! The command line as clap reads it: the subcommands and their arguments, with `run`'s in
//! groups (spec, time, instances, transport, state, output). Nothing here is used by the core:
//! `run`'s arguments are converted once by [`super::config`].

use super::log_level::LogLevel;
use super::spec_options::SpecOptions;
use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;

/// `--version`: the crate's version, the commit it was built from, the TeSSLa version implemented.
pub const VERSION: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    " (commit ",
    env!("TESSLA_TELEGRAF_COMMIT"),
    "; implements TeSSLa 1.2)"
);

/// The exit codes, as `--help` and the man page list them (the book, "Exit codes").
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
    Replay(super::replay::ReplayArgs),
    /// Render a run's line protocol (pass-through and verdicts) as an HTML report with SVG plots.
    #[cfg(feature = "tools")]
    Report(super::report::ReportArgs),
    /// Run a simulated TurtleBot3 in closed loop with the monitors (the digital twin's behaviour).
    #[cfg(feature = "tools")]
    Simulate(super::simulate::SimulateArgs),
    /// The fleet's spec channel: publish a spec version (signed), list the rollouts, show what
    /// every process made of them, roll back, make the signing key.
    Spec(Box<super::spec_cmd::SpecArgs>),
    /// Print a shell completion script for this command line (`make install` installs them).
    Completions(CompletionsArgs),
    /// Print the man page (roff), made from this command line (`make install` installs it).
    Manpage,
    /// Print the book's command-line chapter (Markdown), made from this command line like the
    /// man page (`make cli-md` writes docs/book/src/cli.md).
    #[command(hide = true)]
    CliMarkdown,
}

#[derive(Debug, Args, Clone)]
pub struct CompletionsArgs {
    /// The shell to complete in.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
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

/// `run`'s command line, in groups: the spec, time, instances, transport, state, output, spec
/// channel. Each group is converted once into what the core takes
/// ([`super::config::RunConfig`]).
#[derive(Debug, Args, Clone, Default)]
pub struct RunArgs {
    /// The `.tessla` file; without it the bundled robot monitors run. Without --spec, the
    /// environment variable TESSLA_SPEC names it when set and not empty (Telegraf's child
    /// inherits it from the systemd drop-in's EnvironmentFile, /etc/default/tessla-telegraf,
    /// which the drop-in's check reads too: the path is written in one place).
    #[arg(long)]
    pub spec: Option<PathBuf>,
    /// Watch the spec file and the files it includes (checked every second) and reload it when
    /// one changes, as SIGHUP does: a spec that does not check is refused and the running one
    /// stays; streams whose definition did not change keep their state.
    #[arg(long, requires = "spec")]
    pub watch_spec: bool,
    #[command(flatten)]
    pub spec_options: SpecOptions,
    /// Exit with code 4 when one step (evaluating a record or a fallen-due delay, and writing its
    /// outputs) makes no progress for this long, so that Telegraf restarts the monitor: Telegraf
    /// never restarts a child that is alive, and blocks on its full stdin pipe. `0` disables.
    #[arg(long, value_name = "DURATION", default_value = "10s", value_parser = humantime::parse_duration)]
    pub step_timeout: std::time::Duration,
    #[command(flatten)]
    pub time: TimeArgs,
    #[command(flatten)]
    pub instances: InstanceArgs,
    #[command(flatten)]
    pub transport: TransportArgs,
    #[command(flatten)]
    pub state: StateArgs,
    #[command(flatten)]
    pub output: OutputArgs,
    #[command(flatten)]
    pub spec_channel: SpecChannelArgs,
}

/// Time: late records, clocks ahead, and how far an instance's time follows the wall clock.
#[derive(Debug, Args, Clone, Default)]
#[command(next_help_heading = "Time")]
pub struct TimeArgs {
    /// What to do with a record stamped before its instance's last step (the book, "Time"): a
    /// step of its own 1 ns after it, or dropped. A record with the same timestamp as the last
    /// step is always stepped 1 ns after it.
    #[arg(long, value_enum, default_value_t)]
    pub late: Late,
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
}

/// Instances: one monitor per robot, how many, for how long, on how many threads.
#[derive(Debug, Args, Clone, Default)]
#[command(next_help_heading = "Instances")]
pub struct InstanceArgs {
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
    /// A fleet spec (docs/fleet.md): a TeSSLa file whose inputs are robot-spec outputs seen as
    /// maps from robot key (the --instance-by values) to latest value, `Events[Map[String, T]]`;
    /// its outputs are written to measurement `tessla_fleet` (or as annotated).
    #[arg(long, value_name = "FILE", requires = "instance_by")]
    pub fleet_spec: Option<PathBuf>,
    /// With --fleet-spec: a robot whose time stays this far behind the newest robot's no longer
    /// holds the fleet level back, and leaves the fleet's maps this long after its last step.
    #[arg(long, value_name = "DURATION", default_value = "2s", value_parser = humantime::parse_duration, requires = "fleet_spec")]
    pub fleet_silence: std::time::Duration,
}

/// Transport: stdin/stdout (Telegraf's execd) unless UDP mode is asked for.
#[derive(Debug, Args, Clone, Default)]
#[command(next_help_heading = "Transport (UDP)")]
pub struct TransportArgs {
    /// UDP mode (the TeSSLa Telegraf Connector's wiring): receive line protocol on this address.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:1653")]
    pub udp_listen: Option<String>,
    /// UDP mode: send outputs to this address.
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:1654")]
    pub udp_send: String,
    /// UDP mode: largest datagram to send, in bytes (lines are never split).
    #[arg(long, value_name = "BYTES", default_value_t = 8192)]
    pub udp_max_datagram: usize,
}

/// State: where the monitors' state is kept between runs, and how often it is saved.
#[derive(Debug, Args, Clone, Default)]
#[command(next_help_heading = "State")]
pub struct StateArgs {
    /// Save every monitor instance's state to FILE on shutdown (EOF, SIGTERM, SIGINT) and
    /// continue from it at start, so a Telegraf restart or reload keeps the monitors' state.
    /// `nats://HOST:PORT[,...]/BUCKET[?lease=NAME&ttl=3s&replicas=3]`: a JetStream key-value
    /// bucket shared by a fleet's processes (docs/book/src/state-and-reload.md).
    #[arg(long, value_name = "FILE|nats://HOST:PORT/BUCKET", value_parser = parse_state)]
    pub state: Option<crate::state::Target>,
    /// Also save the state this often while running (`30s`, `5m`), so a crash or SIGKILL
    /// loses at most this much. Needs --state.
    #[arg(long, value_name = "DURATION", value_parser = humantime::parse_duration, requires = "state")]
    pub state_interval: Option<std::time::Duration>,
}

/// Output: what is written besides the verdicts, and how they are named.
#[derive(Debug, Args, Clone, Default)]
#[command(next_help_heading = "Output")]
pub struct OutputArgs {
    /// Do not echo input records (by default each is written back unchanged before its outputs;
    /// never in UDP mode).
    #[arg(long)]
    pub no_passthrough: bool,
    /// Measurement of the metric that groups outputs without a Telegraf annotation.
    #[arg(long, default_value = "tessla")]
    pub measurement: String,
    /// Add a static tag to every output metric: `--tag site=lab` (repeatable).
    #[arg(long = "tag", value_name = "KEY=VALUE")]
    pub tags: Vec<String>,
    /// Tag every output metric with the id of the spec version that computed it (the first 12
    /// hex digits of the SHA-256 of the spec and its includes): `--version-tag spec_version`.
    /// A dashboard can then split a verdict series where the spec changed.
    #[arg(long, value_name = "TAG")]
    pub version_tag: Option<String>,
    /// Least severe messages written to stderr.
    #[arg(long, value_enum, default_value_t)]
    pub log_level: LogLevel,
}

/// Spec channel: new spec versions for a fleet, published by the operator with `tessla-telegraf
/// spec publish` (docs/book/src/state-and-reload.md, "Spec versions across a fleet").
#[derive(Debug, Args, Clone, Default)]
#[command(next_help_heading = "Spec channel")]
pub struct SpecChannelArgs {
    /// Follow the fleet's spec channel: `nats://HOST:PORT[,...][/BUCKET][?options]` (bucket
    /// `tessla_specs` when none is named; the login and TLS options of --state). Each rollout
    /// signed with a trusted key is checked here and put in force from its event time; one
    /// that fails is refused and the running versions stay. Every outcome is a `tessla_spec`
    /// metric and is written to the channel for `tessla-telegraf spec status`.
    #[arg(long, value_name = "nats://HOST:PORT[/BUCKET]", value_parser = crate::spec_feed::nats::parse_url)]
    pub spec_channel: Option<crate::nats::url::Url>,
    /// The operator's public key(s) (`tessla-telegraf spec keygen` prints one): a rollout not
    /// signed with one of them is refused. Needed with --spec-channel (or --spec-trust-file).
    #[arg(
        long,
        value_name = "PUBKEY[,PUBKEY]",
        value_delimiter = ',',
        requires = "spec_channel"
    )]
    pub spec_trust: Vec<String>,
    /// A file of trusted public keys, one a line (`#` starts a comment).
    #[arg(long, value_name = "FILE", requires = "spec_channel")]
    pub spec_trust_file: Option<PathBuf>,
}

/// `--late`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Default)]
pub enum Late {
    /// Evaluate a late record as a step of its own, 1 ns after its instance's last step.
    #[default]
    Shift,
    /// Drop a late record's events (it is still passed through).
    Drop,
}

/// A duration, or `off`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Bound(pub Option<std::time::Duration>);

/// A bound that is neither a duration nor `off`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0} (a duration such as `10s`, `5m`, or `off`)")]
pub struct BoundError(humantime::DurationError);

fn parse_bound(s: &str) -> Result<Bound, BoundError> {
    if s.eq_ignore_ascii_case("off") {
        return Ok(Bound(None));
    }
    humantime::parse_duration(s)
        .map(|d| Bound(Some(d)))
        .map_err(BoundError)
}

/// `--state`, read as the store's own parser reads it.
fn parse_state(s: &str) -> Result<crate::state::Target, crate::state::TargetError> {
    crate::state::Target::parse(s)
}

/// The environment variable `run` takes its spec from without `--spec`.
pub const SPEC_ENV: &str = "TESSLA_SPEC";
