//! The processor: one record in, its pass-through and verdict lines out.
//!
//! Owns: routing each metric to its monitor instance (one, or one per value of the
//! `--instance-by` tags, each with its own state, timestamps and late-record rule; evicted past
//! `--max-instances` or after `--instance-idle`); the time model of live input (the book, "Time on live input"):
//! every record is a step of its own, evaluated at once, so the outputs never depend on how the
//! input was split into reads; a record not after its instance's last step is stepped 1 ns after
//! it (`--late shift`) or dropped (`--late drop`, only when it is earlier); a record stamped
//! beyond `--max-ahead` of the wall clock is refused; and while an instance's input is silent,
//! its armed `delay`s fire by the wall clock ([`Processor::advance_wall`], with [`clock`]).
//! Also: records without a timestamp (wall clock, as Telegraf), pass-through of each record's
//! exact bytes before the outputs it causes, and the counters of the summary line. Bad records
//! are reported with their line number and skipped.
//!
//! Its rooms: this file holds the options, the processor's fields and its constructors; the
//! record's way (parse, route, step, write: `record`), the time policy (ahead
//! refused, late shifted or dropped: `time_policy`), `delay`s fired by the wall clock (`wall`,
//! on the deadline queue of [`clock`]), what `--state` saves and restores (`state_hooks`), the
//! counters and the summary line (`counters`); the instances ([`instance_table`]: the keyed table and
//! the instance key of a record; `pool`: the monitors in it, routed to, created and evicted), writing a
//! step's outputs (`emit`), what a monitor continuing in another program keeps and resets
//! ([`carry`]), exact duplicates ([`dedup`]), spec versions and the switch between them
//! ([`versions`], `switch`), warnings about inputs no metric feeds ([`wiring`]) and what the
//! fleet level reads from the instances ([`fleet_tap`]).

pub mod carry;
pub mod clock;
mod counters;
pub mod dedup;
mod emit;
pub mod fleet_tap;
pub mod instance_table;
mod pool;
mod record;
mod state_hooks;
mod switch;
mod time_policy;
pub mod versions;
mod wall;
pub mod wiring;

pub use counters::Counters;
pub use state_hooks::Continuity;
pub use switch::Refusal;

use self::instance_table::Key;
use self::versions::{Version, Versions};
use crate::telegraf::binding::BindingError;
use crate::telegraf::encode;
use crate::watchdog::Lane;
use clock::{Deadlines, Wall};
use emit::Emitter;
use lineproto::Metric;
use pool::Pool;
use std::sync::Arc;
use std::time::Duration;
use tessla_engine::Program;

/// A version accepted for some instances from an event time on ([`Processor::accept_version`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Accepted {
    /// Outputs whose streams start afresh in the instances it picks: those whose definition
    /// differs between the version such an instance ran just before its start and this one.
    pub reset_outputs: Vec<String>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LateMode {
    /// Evaluate a late record as a step of its own, 1 ns after its instance's last step.
    #[default]
    Shift,
    /// Drop a late record's events (it is still passed through).
    Drop,
}

#[derive(Debug, Clone)]
pub struct Options {
    pub passthrough: bool,
    pub late: LateMode,
    pub measurement: String,
    pub tags: Vec<(String, String)>,
    /// Tags whose values select the monitor instance (empty: one instance for everything).
    pub instance_by: Vec<String>,
    /// Most instances kept; past it the least recently used is evicted (at least 1).
    pub max_instances: usize,
    /// Evict an instance not used for this long (wall clock).
    pub instance_idle: Option<Duration>,
    /// Refuse a record stamped more than this ahead of the wall clock (`None`: `--max-ahead off`).
    pub max_ahead: Option<Duration>,
    /// How far an instance's time stays behind the wall clock while its input is silent, before
    /// its `delay`s fire (`--allowed-lateness`); `None` (`off`): time moves only with records.
    pub allowed_lateness: Option<Duration>,
    /// `--version-tag NAME`: every output line carries the id of the spec version that computed
    /// it in tag NAME (`None`: no such tag).
    pub version_tag: Option<String>,
}

pub const DEFAULT_MAX_INSTANCES: usize = 100_000;
/// `--max-ahead`: Telegraf stamps a metric when it parses the message, on a host kept by NTP
/// within milliseconds of ours; a robot's own clock (`json_time_key`) may be off by seconds. Ten
/// seconds allows both and bounds the harm of a clock that is wrong: until the wall clock
/// catches up, the instance's later records are late.
pub const DEFAULT_MAX_AHEAD: Duration = Duration::from_secs(10);
/// `--allowed-lateness`: the robot's messages cross Wi-Fi, the broker and Telegraf; their
/// delivery varies by tens of milliseconds, by more in a Wi-Fi retry. A quarter of a second
/// covers that at the robot's 5 Hz, and a watchdog still fires within a quarter second of its
/// time.
pub const DEFAULT_ALLOWED_LATENESS: Duration = Duration::from_millis(250);

impl Default for Options {
    fn default() -> Self {
        Options {
            passthrough: true,
            late: LateMode::Shift,
            measurement: "tessla".into(),
            tags: Vec::new(),
            instance_by: Vec::new(),
            max_instances: DEFAULT_MAX_INSTANCES,
            instance_idle: None,
            max_ahead: Some(DEFAULT_MAX_AHEAD),
            allowed_lateness: Some(DEFAULT_ALLOWED_LATENESS),
            version_tag: None,
        }
    }
}

pub struct Processor {
    /// The spec versions held and which instance runs which ([`versions`]).
    versions: Versions,
    emitter: Emitter,
    opts: Options,
    pub counters: Counters,
    /// The monitor instances ([`pool`]).
    pool: Pool,
    /// Reused for every record's parse (keeps its strings' and vectors' capacity).
    scratch: Metric,
    /// The list pattern the parser reads apart once the wiring check is over
    /// ([`Versions::list_to_capture`]), and its keys' digests for [`dedup`].
    capture: Option<String>,
    list_keys: self::dedup::ListKeys,
    /// Warns about inputs the first records never feed (see [`self::wiring`]).
    wiring: self::wiring::WiringCheck,
    /// The wall clock of the current read ([`Processor::set_wall`]).
    wall: Wall,
    /// Instances' next `delay` firings by the wall clock.
    deadlines: Deadlines,
    /// Whether the program has a `delay` at all (without one, no deadline is ever computed).
    has_delays: bool,
    /// The step watchdog's marks for this processor (`run --step-timeout`; see
    /// [`crate::watchdog`]).
    lane: Option<Arc<Lane>>,
    /// A few metrics seen (the first, and each new instance's first, up to 16): a new
    /// spec version's bindings are checked against them before it is accepted.
    samples: Vec<Metric>,
}

impl Processor {
    /// A processor for `program`; fails when an input annotation is malformed.
    pub fn new(program: Arc<Program>, opts: Options) -> Result<Processor, BindingError> {
        let base = Version::new(String::new(), String::new(), program, &opts.measurement)?;
        Ok(Self::with_versions(
            Versions::new(base, opts.instance_by.clone()),
            opts,
        ))
    }

    fn with_versions(versions: Versions, opts: Options) -> Processor {
        let wiring = self::wiring::WiringCheck::new(&versions.base().bindings);
        Processor {
            has_delays: versions.has_delays() && opts.allowed_lateness.is_some(),
            capture: versions.list_to_capture(),
            versions,
            emitter: Emitter {
                events: Vec::new(),
                encode: encode::Scratch::default(),
                tap: None,
            },
            pool: Pool::new(&opts),
            opts,
            counters: Counters::default(),
            scratch: Metric::default(),
            list_keys: Default::default(),
            wiring,
            wall: Wall::now(),
            deadlines: Deadlines::default(),
            lane: None,
            samples: Vec::new(),
        }
    }

    /// A processor with this one's versions and options and no instances (a `--threads`
    /// worker).
    pub fn sibling(&self) -> Result<Processor, BindingError> {
        let mut p = Self::with_versions(self.versions.duplicate()?, self.opts.clone());
        if let Some(names) = self.fleet_outputs() {
            p.tap_fleet(names);
        }
        Ok(p)
    }

    /// Name the spec the process started with (its bundle's id and a label): the value of
    /// `--version-tag` and of the status lines.
    pub fn name_base(&mut self, id: &str, label: &str) {
        if let Some(v) = self.versions.list.first_mut() {
            v.id = id.to_string();
            v.label = label.to_string();
        }
    }

    /// The metrics kept for checking a new version's bindings (the first, and each new
    /// instance's first, up to 16): a process checks against every thread's together.
    pub fn samples(&self) -> &[Metric] {
        &self.samples
    }

    /// The versions held.
    pub fn versions(&self) -> &Versions {
        &self.versions
    }

    /// Leave the step watchdog's marks in `lane` (every record, every new instance).
    pub fn watch_with(&mut self, lane: Arc<Lane>) {
        self.pool.name_all(&lane);
        self.lane = Some(lane);
    }

    /// `--max-instances`: the most instances kept over all threads.
    pub fn max_instances(&self) -> usize {
        self.opts.max_instances
    }

    /// Keep at most `n` instances here (at least 1): a `--threads` shard's share of the total.
    pub fn keep_instances(&mut self, n: usize) {
        self.pool.keep = n.max(1);
    }

    /// The tags that select an instance (`--instance-by`).
    pub fn instance_by(&self) -> &[String] {
        &self.opts.instance_by
    }

    /// Monitor instances alive now.
    pub fn instance_count(&self) -> usize {
        self.pool.table.len()
    }

    /// The wall clock for the records that follow: a transport sets it once per read (the
    /// records of one read arrived together), a replay to when each record arrived.
    pub fn set_wall(&mut self, wall: Wall) {
        self.wall = wall;
    }

    /// The input ended: warn about inputs that what was seen never fed (once).
    pub fn finish_wiring(&mut self) {
        self.wiring.finish(&self.versions.base().bindings);
    }

    /// The program of the base version (every instance's, without rules).
    pub fn program(&self) -> &Arc<Program> {
        &self.versions.base().program
    }

    /// The program instance `key` runs at event time `t` (restoring saved state: at its
    /// horizon).
    pub fn program_for(&self, key: &Key, t: i64) -> &Arc<Program> {
        &self.versions.get(self.versions.target(key, t)).program
    }
}

#[cfg(test)]
pub(crate) mod tests;
