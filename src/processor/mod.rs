//! The processor: one record in, its pass-through and verdict lines out.
//!
//! Owns: routing each metric to its monitor instance (one, or one per value of the
//! `--instance-by` tags, each with its own state, timestamps and late-record rule; evicted past
//! `--max-instances` or after `--instance-idle`); the time model of live input (README, "Time"):
//! every record is a step of its own, evaluated at once, so the outputs never depend on how the
//! input was split into reads; a record not after its instance's last step is stepped 1 ns after
//! it (`--late shift`) or dropped (`--late drop`, only when it is earlier); a record stamped
//! beyond `--max-ahead` of the wall clock is refused; and while an instance's input is silent,
//! its armed `delay`s fire by the wall clock ([`Processor::advance_wall`], with [`clock`]).
//! Also: records without a timestamp (wall clock, as Telegraf), pass-through of each record's
//! exact bytes before the outputs it causes, and the counters of the summary line. Bad records
//! are reported with their line number and skipped.
//!
//! Its rooms: the instances ([`instances`]: the table, and the pool that routes to it, creates
//! and evicts), writing a step's outputs (`emit`), the live clock ([`clock`]), what a monitor
//! continuing in another program keeps and resets ([`carry`]), exact duplicates ([`dedup`]),
//! spec versions and the switch between them ([`versions`], `switch`) and warnings about inputs
//! no metric feeds ([`wiring`]).

pub mod carry;
pub mod clock;
pub mod dedup;
mod emit;
pub mod instances;
mod pool;
mod switch;
pub mod versions;
pub mod wiring;

use self::instances::Key;
use self::versions::{Version, Versions};
use crate::log;
use crate::telegraf::encode;
use crate::watchdog::Lane;
use clock::{Anchor, Deadlines, Wall};
use emit::{Emitter, Fired};
use lineproto::{Metric, Record, RecordRef, parse_record_into};
use pool::{Instance, Pool, describe, instance_note};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tessla_engine::{InputError, Monitor, OutputEvent, Program};

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

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Counters {
    pub records: u64,
    pub events: u64,
    pub outputs: u64,
    pub parse_errors: u64,
    pub late: u64,
    /// Records refused for a timestamp beyond `--max-ahead` of the wall clock.
    pub ahead: u64,
    pub dropped_values: u64,
    /// Monitor instances created.
    pub instances: u64,
    /// Monitor instances evicted (LRU or idle).
    pub evicted: u64,
    /// Exact repeats of a recent record, dropped ([`self::dedup`]).
    pub duplicates: u64,
    /// Instances switched to another spec version ([`versions`]).
    pub switched: u64,
}

impl Counters {
    /// Add `other`'s counts (a `--threads` worker's, at the end of a run). Every field: the
    /// summary must not depend on the thread count.
    pub fn add(&mut self, other: &Counters) {
        let Counters {
            records,
            events,
            outputs,
            parse_errors,
            late,
            ahead,
            dropped_values,
            instances,
            evicted,
            duplicates,
            switched,
        } = other;
        self.records += records;
        self.events += events;
        self.outputs += outputs;
        self.parse_errors += parse_errors;
        self.late += late;
        self.ahead += ahead;
        self.dropped_values += dropped_values;
        self.instances += instances;
        self.evicted += evicted;
        self.duplicates += duplicates;
        self.switched += switched;
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
    /// A few metrics seen (the first, and each new instance's first, up to [`SAMPLES`]): a new
    /// spec version's bindings are checked against them before it is accepted.
    samples: Vec<Metric>,
}

/// Metrics kept for checking a new version's bindings.
const SAMPLES: usize = 16;

/// List elements at this index or past it are not read apart (the record takes the full parser):
/// the array grows to the largest index seen.
const CAPTURE_LIMIT: usize = 16384;

impl Processor {
    /// A processor for `program`; fails when an input annotation is malformed.
    pub fn new(program: Arc<Program>, opts: Options) -> Result<Processor, String> {
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
    pub fn sibling(&self) -> Result<Processor, String> {
        Ok(Self::with_versions(
            self.versions.duplicate()?,
            self.opts.clone(),
        ))
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

    /// Handle one record, appending pass-through and completed steps' outputs to `out`.
    pub fn record(&mut self, rec: &Record, out: &mut Vec<u8>) {
        self.record_ref(rec.view(), out);
    }

    /// [`Processor::record`] on a borrowed record (the stdio loop's records point into its read
    /// buffer; pass-through copies them from there).
    pub fn record_ref(&mut self, rec: RecordRef<'_>, out: &mut Vec<u8>) {
        if let Some(l) = &self.lane {
            l.begin(rec.line);
        }
        self.counters.records += 1;
        if rec.oversized {
            self.counters.parse_errors += 1;
            log::warn_limited("parse error", || {
                format!("line {}: record longer than the limit; skipped", rec.line)
            });
            return;
        }
        // Parse into the scratch metric: plain records then allocate nothing. Once the wiring
        // check (which reads every field by name) is over, a list's elements are read apart.
        let mut metric = std::mem::take(&mut self.scratch);
        let capture = self.capture.as_deref().filter(|_| self.wiring.is_done());
        metric.list.set_prefix(capture, CAPTURE_LIMIT);
        let parsed = parse_record_into(rec.bytes, &mut metric);
        if let Ok(true) = parsed {
            self.record_metric(&rec, &metric, out);
        }
        self.scratch = metric;
        match parsed {
            Ok(true) => {}
            Ok(false) => self.counters.records -= 1,
            Err(_) if Self::spans_lines(rec.bytes) => {
                // A record spanning several physical lines that does not parse is most likely an
                // unbalanced quote that swallowed the lines after it: take each line alone, so
                // one bad line costs only itself.
                self.counters.records -= 1;
                for (line, part) in (rec.line..).zip(rec.bytes.split_inclusive(|&b| b == b'\n')) {
                    let sub = RecordRef {
                        bytes: part,
                        line,
                        oversized: false,
                    };
                    self.record_ref(sub, out);
                }
            }
            Err(e) => {
                self.counters.parse_errors += 1;
                log::warn_limited("parse error", || {
                    format!(
                        "line {}, column {}: {}: `{}`; line skipped",
                        rec.line, e.column, e.reason, e.excerpt
                    )
                });
            }
        }
    }

    fn passthrough(&self, rec: &RecordRef<'_>, out: &mut Vec<u8>) {
        if self.opts.passthrough {
            out.extend_from_slice(rec.bytes);
            if rec.bytes.last() != Some(&b'\n') {
                out.push(b'\n');
            }
        }
    }

    /// Whether `ts` is beyond `--max-ahead` of the wall clock: then the record is refused
    /// (passed through, not evaluated), warned about and counted, and `true` is returned.
    fn refuse_ahead(&mut self, rec: &RecordRef<'_>, metric: &Metric, ts: i64) -> bool {
        let Some(bound) = self.opts.max_ahead else {
            return false;
        };
        let wall = self.wall.ns;
        if ts <= wall.saturating_add(clock::ns_of(bound)) {
            return false;
        }
        self.counters.ahead += 1;
        let by = &self.opts.instance_by;
        log::warn_limited("ahead of the clock", || {
            let inst = instance_note(by, metric);
            format!(
                "line {}: timestamp {ts} is {} ahead of the wall clock{inst}; refused (not evaluated), so it cannot move the monitor's clock (--max-ahead {}; `--max-ahead off` for simulated data)",
                rec.line,
                clock::human_ns(ts.saturating_sub(wall)),
                humantime::format_duration(bound)
            )
        });
        true
    }

    /// Route one parsed record to its instance: delay firings before it, pass-through, then
    /// its own step, evaluated at once.
    fn record_metric(&mut self, rec: &RecordRef<'_>, metric: &Metric, out: &mut Vec<u8>) {
        if metric.overwritten > 0 {
            log::warn_limited("repeated field", || {
                format!(
                    "line {}: {} field value(s) overwritten by a later value of the same key; the last value is used, as Telegraf does",
                    rec.line, metric.overwritten
                )
            });
        }
        let mut ts = metric.timestamp.unwrap_or(self.wall.ns);
        if self.refuse_ahead(rec, metric, ts) {
            self.passthrough(rec, out);
            return;
        }
        let now = self.pool.now(self.wall.at);
        let created = self.counters.instances;
        let slot = self.pool.slot_for(
            metric,
            ts,
            now,
            &self.versions,
            &mut self.counters,
            self.lane.as_deref(),
        );
        if self.counters.instances != created && self.samples.len() < SAMPLES {
            self.samples.push(metric.with_list_as_fields());
        }
        if let Some(l) = &self.lane {
            l.instance(slot);
        }
        if self.versions.has_rules() {
            self.settle(slot, ts, out);
        }
        let Some(inst) = self.pool.table.get_mut(slot) else {
            return;
        };
        if let Some(t) = metric.timestamp
            && inst.recent.is_duplicate(t, metric, &mut self.list_keys)
        {
            self.counters.duplicates += 1;
            log::warn_limited("duplicate", || {
                format!(
                    "line {}: exact repeat of a recent record (a redelivered message); dropped",
                    rec.line
                )
            });
            return;
        }
        let monitor = &mut inst.monitor;
        let mut dropped = false;
        // A record not after its instance's last step (a record, or a delay that fired) is a
        // step of its own 1 ns after it: it never joins or collides with an evaluated step.
        if let Some(last) = monitor.last_evaluated()
            && ts <= last
        {
            let at = last.saturating_add(1);
            if ts < last {
                self.counters.late += 1;
                dropped = self.opts.late == LateMode::Drop;
                let by = &self.opts.instance_by;
                log::warn_limited("late record", || {
                    let inst_note = instance_note(by, metric);
                    format!(
                        "line {}: timestamp {ts} is {} before its instance's last step at {last}{inst_note}; {}",
                        rec.line,
                        clock::human_ns(last.saturating_sub(ts)),
                        if dropped {
                            "its events are dropped (--late drop)".to_string()
                        } else {
                            format!("evaluated as a step of its own at {at} (--late shift)")
                        }
                    )
                });
            }
            ts = at;
        }
        // The delay firings before `ts` first, so their outputs precede this record's
        // pass-through.
        let events = &mut self.emitter.events;
        monitor.advance_to(ts, &mut |e: OutputEvent<'_>| events.push(Fired::of(e)));
        let encodings = &self.versions.get(inst.version).encodings;
        self.emitter
            .emit(encodings, &inst.tags, &mut self.counters, out);
        self.passthrough(rec, out);
        if !dropped {
            self.push_fields(metric, rec.line, ts, slot, out);
        }
        self.schedule(slot, ts);
        self.pool
            .evict(now, &mut self.counters, self.lane.as_deref());
    }

    /// Note instance `slot`'s last record at `ts` and queue its next `delay` firing by the wall
    /// clock. Without a `delay` in the program this is one comparison.
    fn schedule(&mut self, slot: usize, ts: i64) {
        if !self.has_delays {
            return;
        }
        let (at, lateness) = (self.wall.at, self.lateness());
        if let Some(inst) = self.pool.table.get_mut(slot) {
            let anchor = Anchor { ts, at };
            inst.anchor = Some(anchor);
            Self::queue(&mut self.deadlines, inst, slot, lateness);
        }
    }

    /// Recompute `inst`'s deadline from its anchor and next firing; queue it unless an entry at
    /// or before it is queued already (that entry, when due, queues the later one).
    fn queue(deadlines: &mut Deadlines, inst: &mut Instance, slot: usize, lateness: Duration) {
        inst.deadline = match (inst.anchor, inst.monitor.next_firing()) {
            (Some(a), Some(t)) => a.deadline(t, lateness),
            _ => None,
        };
        if let Some(d) = inst.deadline
            && inst.queued.is_none_or(|q| q > d)
        {
            deadlines.push(d, inst.id, slot);
            inst.queued = Some(d);
        }
    }

    /// `--allowed-lateness` (only read where it is on: `has_delays` is false when it is off).
    fn lateness(&self) -> Duration {
        self.opts.allowed_lateness.unwrap_or(Duration::MAX)
    }

    /// The earliest wall-clock time at which an instance's `delay` may fall due, or (with
    /// `--instance-idle`) an instance falls idle past the limit: a transport sleeps until then
    /// when no input arrives, then calls [`Processor::advance_wall`].
    pub fn next_deadline(&self) -> Option<Instant> {
        match (self.deadlines.next(), self.pool.idle_due()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// The input is silent: move every instance whose `delay` has fallen due on to its time by
    /// the wall clock (its last record's time plus the wall time since, less
    /// `--allowed-lateness`), firing those delays; their outputs carry their TeSSLa time.
    /// Touches only the instances with a due deadline. An instance idle past `--instance-idle`
    /// when its `delay` falls due, or at `now`, is evicted (its `delay`s never fire).
    pub fn advance_wall(&mut self, now: Instant, out: &mut Vec<u8>) {
        let lateness = self.lateness();
        while let Some((due, id, slot)) = self.deadlines.pop_due(now) {
            let Some(inst) = self.pool.table.get_mut(slot) else {
                continue;
            };
            if inst.id != id || inst.queued != Some(due) {
                continue;
            }
            inst.queued = None;
            let (Some(anchor), Some(deadline)) = (inst.anchor, inst.deadline) else {
                continue;
            };
            if self.pool.idle_at(slot, deadline.min(now)) {
                // Idle past the limit before the firing: evicted, its delays go with it.
                self.pool
                    .evict_slot(slot, false, &mut self.counters, self.lane.as_deref());
                continue;
            }
            if deadline <= now {
                let upto = anchor.time_at(now, lateness).saturating_add(1);
                if self.versions.has_rules() {
                    // Firings from a version's start on are the new version's.
                    self.settle(slot, upto.saturating_sub(1), out);
                }
                let Some(inst) = self.pool.table.get_mut(slot) else {
                    continue;
                };
                let events = &mut self.emitter.events;
                inst.monitor
                    .advance_to(upto, &mut |e: OutputEvent<'_>| events.push(Fired::of(e)));
                let encodings = &self.versions.get(inst.version).encodings;
                self.emitter
                    .emit(encodings, &inst.tags, &mut self.counters, out);
            }
            if let Some(inst) = self.pool.table.get_mut(slot) {
                Self::queue(&mut self.deadlines, inst, slot, lateness);
            }
        }
        let now = self.pool.now(now);
        self.pool
            .evict_idle(now, &mut self.counters, self.lane.as_deref());
    }

    /// Whether `bytes` holds a newline before its last byte.
    fn spans_lines(bytes: &[u8]) -> bool {
        bytes
            .split_last()
            .is_some_and(|(_, head)| head.contains(&b'\n'))
    }

    /// Feed the metric's bound fields to instance `slot` as events at `ts`, evaluate the step
    /// and write its outputs.
    fn push_fields(&mut self, metric: &Metric, line: u64, ts: i64, slot: usize, out: &mut Vec<u8>) {
        self.wiring.observe(metric, &self.versions.base().bindings);
        let Some(inst) = self.pool.table.get_mut(slot) else {
            return;
        };
        let version = self.versions.get(inst.version);
        let events = &mut self.emitter.events;
        let mut sink = |e: OutputEvent<'_>| events.push(Fired::of(e));
        for b in &version.bindings {
            if !b.matches(metric) {
                continue;
            }
            match b.extract(metric) {
                None => {}
                Some(Err(e)) => {
                    self.counters.dropped_values += 1;
                    log::warn_limited("conversion", || {
                        format!(
                            "line {line}: input `{}`: {}; value skipped",
                            e.input, e.reason
                        )
                    });
                }
                Some(Ok(v)) => match inst.monitor.push(ts, b.input, v, &mut sink) {
                    Ok(()) => self.counters.events += 1,
                    Err(err) => {
                        self.counters.dropped_values += 1;
                        let why = match err {
                            InputError::Multiple { .. } => {
                                "a second event on this input in the same record".to_string()
                            }
                            InputError::Decreasing { last, got } => format!(
                                "timestamp {got} is not after the last evaluated one ({last})"
                            ),
                            InputError::UnknownInput(i) => {
                                format!("the spec has no input number {i}")
                            }
                        };
                        log::warn_limited("input event", || {
                            format!("line {line}: input `{}`: {why}; value skipped", b.name)
                        });
                    }
                },
            }
        }
        inst.monitor.flush(&mut sink);
        self.emitter
            .emit(&version.encodings, &inst.tags, &mut self.counters, out);
    }

    /// No more input right now (the end of a read): evict instances past `--max-instances`
    /// (idle ones go by their own silence: [`Processor::advance_wall`] and their next record).
    /// Every record has been evaluated already.
    pub fn end_of_read(&mut self) {
        let now = self.pool.now(self.wall.at);
        self.pool
            .evict(now, &mut self.counters, self.lane.as_deref());
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

    /// Whether `monitor`'s clock is beyond `--max-ahead` of the wall clock now.
    fn clock_ahead(&self, monitor: &Monitor) -> Option<i64> {
        let bound = self.opts.max_ahead?;
        let ahead = monitor.clock().saturating_sub(clock::unix_ns());
        (ahead > clock::ns_of(bound)).then_some(ahead)
    }

    /// Every instance's key and monitor, least recently used first (`--state`). An instance
    /// whose clock is beyond `--max-ahead` of the wall clock is left out: a wrong clock is
    /// never saved.
    pub fn monitors(&self) -> impl Iterator<Item = (&Key, &Monitor)> {
        self.saved_instances().map(|(k, m, _)| (k, m))
    }

    /// [`Processor::monitors`] with each instance's horizon, the event time whose version it
    /// runs (restored by [`Processor::restore_instance_at`]): what `--state` saves.
    pub fn saved_instances(&self) -> impl Iterator<Item = (&Key, &Monitor, i64)> {
        let rules = self.versions.has_rules();
        self.pool
            .table
            .iter_lru()
            .map(move |(k, i)| {
                // Without rules no step settled a version: it stands at its clock.
                let horizon = if rules {
                    i.horizon
                } else {
                    i.horizon.max(i.monitor.clock())
                };
                (k, &i.monitor, horizon)
            })
            .filter(|(k, m, _)| match self.clock_ahead(m) {
                None => true,
                Some(ahead) => {
                    log::warn_limited("state clock", || {
                        format!(
                            "monitor instance {} not saved: its clock is {} ahead of the wall clock (--max-ahead)",
                            describe(&self.opts.instance_by, k),
                            clock::human_ns(ahead)
                        )
                    });
                    false
                }
            })
    }

    /// Add an instance restored from saved state; ignored when `key` already has one, and
    /// refused (the instance starts fresh with its next record) when its clock is beyond
    /// `--max-ahead` of the wall clock. Its silent time counts from now.
    pub fn restore_instance(&mut self, key: Key, monitor: Monitor) {
        self.restore_instance_at(key, monitor, None);
    }

    /// [`Processor::restore_instance`] with the horizon it was saved with (`None`: state that
    /// did not record one, the monitor's clock): its version is the one the rules give there
    /// ([`Processor::program_for`]), and it switches at its first step from the next start.
    pub fn restore_instance_at(&mut self, key: Key, monitor: Monitor, horizon: Option<i64>) {
        if let Some(ahead) = self.clock_ahead(&monitor) {
            log::log(
                log::Level::Warn,
                &format!(
                    "state: monitor instance {} saved with a clock {} ahead of the wall clock (beyond --max-ahead {}); it starts fresh",
                    if self.opts.instance_by.is_empty() {
                        "(the only one)".to_string()
                    } else {
                        describe(&self.opts.instance_by, &key)
                    },
                    clock::human_ns(ahead),
                    self.opts
                        .max_ahead
                        .map(|d| humantime::format_duration(d).to_string())
                        .unwrap_or_default()
                ),
            );
            return;
        }
        let now = self.pool.now(Instant::now());
        if self.pool.table.find(&key, now).is_none() {
            let ts = monitor.clock();
            // The version whose program it was saved for (another: the base).
            let v = self
                .versions
                .list
                .iter()
                .position(|v| Arc::ptr_eq(&v.program, monitor.program()))
                .unwrap_or(0);
            let id = self.versions.get(v).id.clone();
            let horizon = horizon.unwrap_or(ts);
            let settled = (v == self.versions.target(&key, horizon)).then(|| {
                let next = self.versions.next_start(&key, horizon, i64::MAX);
                (self.versions.rules.len(), next.unwrap_or(i64::MAX))
            });
            let slot = self
                .pool
                .insert(key, monitor, (v, &id), now, self.lane.as_deref());
            if let Some(inst) = self.pool.table.get_mut(slot) {
                inst.horizon = horizon;
                if let Some(settled) = settled {
                    inst.settled = settled;
                }
            }
            self.schedule(slot, ts);
        }
    }

    /// The one-line summary printed at the end of a run.
    pub fn summary(&self) -> String {
        let c = &self.counters;
        let mut s = format!(
            "summary: {} records, {} events, {} outputs, {} parse errors, {} late records, {} ahead of the clock, {} dropped values, {} duplicates",
            c.records,
            c.events,
            c.outputs,
            c.parse_errors,
            c.late,
            c.ahead,
            c.dropped_values,
            c.duplicates
        );
        if !self.opts.instance_by.is_empty() {
            s.push_str(&format!(
                ", {} instances, {} evicted",
                c.instances, c.evicted
            ));
        }
        if c.switched > 0 {
            s.push_str(&format!(", {} switched spec version", c.switched));
        }
        s
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::processor::versions::Selector;
    use lineproto::{RecordSplitter, parse_record};
    use tessla_syntax::include::MemResolver;

    /// `c` counts `x`; `k` is a constant event at TeSSLa time 0.
    const SPEC: &str = "in x: Events[Int]\n\
                        def c = count(x)\n\
                        def k: Events[Int] = const(7, ())\n\
                        out c\nout k\nout x\n";

    fn processor(opts: Options) -> Processor {
        let resolver = MemResolver {
            files: [("t.tessla".to_string(), SPEC.to_string())].into(),
        };
        let loaded = tessla_engine::load_with("t.tessla", &resolver, &Default::default()).unwrap();
        Processor::new(loaded.program, opts).unwrap()
    }

    /// Feed `input` as one read (flushing at its end, as a transport does) and return the output.
    fn feed(p: &mut Processor, input: &str) -> String {
        let mut s = RecordSplitter::default();
        s.push(input.as_bytes());
        let mut out = Vec::new();
        while let Some(r) = s.next_record() {
            p.record(&r, &mut out);
        }
        while let Some(r) = s.finish() {
            p.record(&r, &mut out);
        }
        p.end_of_read();
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn an_unbalanced_quote_costs_only_its_own_line() {
        let mut p = processor(Options::default());
        let out = feed(&mut p, "m x=1 100\nm s=\"open 150\nm x=2 200\nm x=3 300\n");
        assert!(out.contains("m x=2 200\ntessla c=2i,x=2i 200\n"), "{out}");
        assert!(out.contains("m x=3 300\ntessla c=3i,x=3i 300\n"), "{out}");
        assert!(!out.contains("open"), "{out}");
        assert_eq!(p.counters.records, 4);
        assert_eq!(p.counters.parse_errors, 1);
        // A string field that really spans lines stays one record.
        let out = feed(&mut p, "m x=4,s=\"two\nlines\" 400\n");
        assert_eq!(out, "m x=4,s=\"two\nlines\" 400\ntessla c=4i,x=4i 400\n");
    }

    #[test]
    fn time_zero_events_carry_the_first_records_timestamp() {
        let mut p = processor(Options {
            passthrough: false,
            ..Options::default()
        });
        let out = feed(&mut p, "m x=5 1700000000000000000\n");
        assert_eq!(out, "tessla c=1i,k=7i,x=5i 1700000000000000000\n");
    }

    /// Every record is a step of its own, answered right after its pass-through; a record with
    /// the timestamp of its instance's last step is stepped 1 ns after it (not late).
    #[test]
    fn records_with_one_timestamp_are_stepped_each_apart() {
        let mut p = processor(Options::default());
        let out = feed(&mut p, "m x=5 100\nm y=1 100\nm x=6 200\n");
        assert_eq!(
            out,
            "m x=5 100\ntessla c=1i,k=7i,x=5i 100\nm y=1 100\nm x=6 200\ntessla c=2i,x=6i 200\n"
        );
        assert_eq!(p.counters.records, 3);
        assert_eq!(p.counters.events, 2);
        assert_eq!(p.counters.late, 0);
        // Two values of one input at one timestamp: both evaluated, the second 1 ns later.
        let mut p = processor(Options {
            passthrough: false,
            ..Options::default()
        });
        assert_eq!(
            feed(&mut p, "m x=1 100\nm x=2 100\n"),
            "tessla c=1i,k=7i,x=1i 100\ntessla c=2i,x=2i 101\n"
        );
        assert_eq!(p.counters.dropped_values, 0);
        assert_eq!(p.counters.late, 0);
    }

    #[test]
    fn late_records_shift_or_drop() {
        let mut p = processor(Options {
            passthrough: false,
            ..Options::default()
        });
        feed(&mut p, "m x=1 100\n");
        assert_eq!(feed(&mut p, "m x=2 50\n"), "tessla c=2i,x=2i 101\n");
        assert_eq!(p.counters.late, 1);
        // In one read: the late record is a step of its own after the last, never merged.
        let mut p = processor(Options {
            passthrough: false,
            ..Options::default()
        });
        assert_eq!(
            feed(&mut p, "m x=1 100\nm x=2 200\nm x=3 150\n"),
            "tessla c=1i,k=7i,x=1i 100\ntessla c=2i,x=2i 200\ntessla c=3i,x=3i 201\n"
        );
        let mut p = processor(Options {
            passthrough: false,
            late: LateMode::Drop,
            ..Options::default()
        });
        feed(&mut p, "m x=1 100\n");
        assert_eq!(feed(&mut p, "m x=2 50\n"), "");
        assert_eq!(feed(&mut p, "m x=3 300\n"), "tessla c=2i,x=3i 300\n");
        assert_eq!(p.counters.late, 1);
    }

    #[test]
    fn a_record_without_timestamp_gets_the_wall_clock() {
        let mut p = processor(Options {
            passthrough: false,
            ..Options::default()
        });
        let before = clock::unix_ns();
        p.set_wall(Wall::now());
        let out = feed(&mut p, "m x=1\n");
        let after = clock::unix_ns();
        let m = parse_record(out.as_bytes()).unwrap().unwrap();
        let ts = m.timestamp.unwrap();
        assert!(before <= ts && ts <= after, "{before} <= {ts} <= {after}");
    }

    /// A record stamped beyond --max-ahead is echoed, not evaluated, and cannot move the clock.
    #[test]
    fn a_record_far_ahead_of_the_wall_clock_is_refused() {
        let mut p = processor(Options::default());
        let now = clock::unix_ns();
        let out = feed(&mut p, &format!("m x=1 {now}\nm x=2 9223372036854775807\n"));
        assert!(out.contains("m x=2 9223372036854775807\n"), "{out}");
        assert!(!out.contains("x=2i"), "{out}");
        assert_eq!(p.counters.ahead, 1);
        let later = now + 1_000;
        let out = feed(&mut p, &format!("m x=3 {later}\n"));
        assert!(
            out.ends_with(&format!("tessla c=2i,x=3i {later}\n")),
            "{out}"
        );
        assert_eq!(p.counters.late, 0);
        assert!(
            p.summary().contains(", 1 ahead of the clock,"),
            "{}",
            p.summary()
        );
        // Off: simulated data far in the future is evaluated.
        let mut p = processor(Options {
            passthrough: false,
            max_ahead: None,
            ..Options::default()
        });
        let out = feed(&mut p, "m x=2 9000000000000000000\n");
        assert_eq!(out, "tessla c=1i,k=7i,x=2i 9000000000000000000\n");
    }

    /// A watchdog fires by the wall clock while the input is silent: at the instance's last
    /// record plus the delay, once the allowed lateness has passed; its output carries its TeSSLa
    /// time. Only the instance whose deadline is due is touched.
    #[test]
    fn delays_fire_by_the_wall_clock_while_the_input_is_silent() {
        let spec = "in x: Events[Int]\n\
                    def quiet = delay(const(1000, x), x)\n\
                    out quiet\nout x\n";
        let resolver = MemResolver {
            files: [("w.tessla".to_string(), spec.to_string())].into(),
        };
        let loaded = tessla_engine::load_with("w.tessla", &resolver, &Default::default()).unwrap();
        let lateness = Duration::from_micros(100);
        let mut p = Processor::new(
            loaded.program,
            Options {
                passthrough: false,
                instance_by: vec!["robot".into()],
                allowed_lateness: Some(lateness),
                ..Options::default()
            },
        )
        .unwrap();
        let t0 = Instant::now();
        p.set_wall(Wall { at: t0, ns: 0 });
        let out = feed(&mut p, "m,robot=a x=1i 5000\nm,robot=b x=1i 5000\n");
        assert_eq!(out.lines().count(), 2);
        // Due 1000 ns + lateness after the records arrived.
        assert_eq!(
            p.next_deadline(),
            Some(t0 + Duration::from_nanos(1000) + lateness)
        );
        // Robot b speaks again half-way; only a falls silent.
        p.set_wall(Wall {
            at: t0 + Duration::from_nanos(500),
            ns: 0,
        });
        feed(&mut p, "m,robot=b x=2i 5500\n");
        let mut out = Vec::new();
        p.advance_wall(t0 + Duration::from_nanos(900), &mut out);
        assert!(out.is_empty());
        p.advance_wall(t0 + Duration::from_nanos(1000) + lateness, &mut out);
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "tessla,robot=a quiet=true 6000\n"
        );
        let mut out = Vec::new();
        p.advance_wall(t0 + Duration::from_nanos(1500) + lateness, &mut out);
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "tessla,robot=b quiet=true 6500\n"
        );
        assert_eq!(p.next_deadline(), None);
        // A record after the firing but stamped before it is late: a step of its own after it.
        p.set_wall(Wall {
            at: t0 + Duration::from_millis(1),
            ns: 0,
        });
        let out = feed(&mut p, "m,robot=a x=3i 5900\n");
        assert_eq!(out, "tessla,robot=a x=3i 6001\n");
        assert_eq!(p.counters.late, 1);
    }

    #[test]
    fn instances_keep_separate_state_and_tag_their_outputs() {
        let mut p = processor(Options {
            passthrough: false,
            instance_by: vec!["robot".into()],
            tags: vec![("site".into(), "lab".into())],
            ..Options::default()
        });
        let out = feed(
            &mut p,
            "m,robot=a x=1 100\nm,robot=b x=1 100\nm,robot=a x=1 200\nm x=9 300\n",
        );
        let mut lines: Vec<&str> = out.lines().collect();
        lines.sort();
        assert_eq!(
            lines,
            [
                "tessla,robot=a,site=lab c=1i,k=7i,x=1i 100",
                "tessla,robot=a,site=lab c=2i,x=1i 200",
                "tessla,robot=b,site=lab c=1i,k=7i,x=1i 100",
                // A metric without the tag is an instance of its own, without the tag.
                "tessla,site=lab c=1i,k=7i,x=9i 300",
            ]
        );
        assert_eq!(p.instance_count(), 3);
        assert!(p.summary().ends_with("3 instances, 0 evicted"));
    }

    /// A program compiled from `spec` (the processor's tests and its neighbours' use it).
    pub(crate) fn program(spec: &str) -> Arc<Program> {
        let resolver = MemResolver {
            files: [("v.tessla".to_string(), spec.to_string())].into(),
        };
        tessla_engine::load_with("v.tessla", &resolver, &Default::default())
            .unwrap()
            .program
    }

    const OLD: &str = "in x: Events[Int]\ndef c = count(x)\ndef s = x + 1\nout c\nout s\n";
    const NEW: &str = "in x: Events[Int]\ndef c = count(x)\ndef s = x * 10\nout c\nout s\n";

    fn versioned() -> Processor {
        let mut p = Processor::new(
            program(OLD),
            Options {
                passthrough: false,
                instance_by: vec!["robot".into()],
                version_tag: Some("spec_version".into()),
                ..Options::default()
            },
        )
        .unwrap();
        p.name_base("old", "");
        p
    }

    /// A rollout for robot a from time 300: a's records before 300 are judged by the old
    /// version, from 300 by the new one, with `c` (unchanged) continuing; b stays on the old.
    #[test]
    fn a_rollout_switches_its_instances_at_their_first_step_from_its_start() {
        let mut p = versioned();
        let sel = Selector::parse("robot=a").unwrap();
        p.check_version("new", &program(NEW), &sel, p.samples())
            .unwrap();
        let acc = p
            .accept_version("new", "ten", program(NEW), 300, sel)
            .unwrap();
        assert_eq!(acc.reset_outputs, ["s"]);
        let out = feed(
            &mut p,
            "m,robot=a x=1i 100\nm,robot=b x=1i 100\nm,robot=a x=2i 299\nm,robot=a x=3i 300\nm,robot=b x=3i 300\nm,robot=a x=4i 400\n",
        );
        assert_eq!(
            out,
            "tessla,robot=a,spec_version=old c=1i,s=2i 100\n\
             tessla,robot=b,spec_version=old c=1i,s=2i 100\n\
             tessla,robot=a,spec_version=old c=2i,s=3i 299\n\
             tessla,robot=a,spec_version=new c=3i,s=30i 300\n\
             tessla,robot=b,spec_version=old c=2i,s=4i 300\n\
             tessla,robot=a,spec_version=new c=4i,s=40i 400\n"
        );
        assert_eq!(p.counters.switched, 1);
        // A robot first seen after the start begins in the new version, one that does not
        // match never.
        let out = feed(&mut p, "m,robot=c x=1i 500\n");
        assert_eq!(out, "tessla,robot=c,spec_version=old c=1i,s=2i 500\n");
        // A late record behind the start, after the switch: its instance's clock has passed
        // the start, so it is a step after its last one, in the version in force there.
        let out = feed(&mut p, "m,robot=a x=5i 250\n");
        assert_eq!(out, "tessla,robot=a,spec_version=new c=5i,s=50i 401\n");
    }

    /// A rollout back to the old version later: the instance switches back at its start.
    /// Rules are kept in publish order; the newest that applies wins.
    #[test]
    fn a_later_rollout_wins_and_a_rollback_switches_back() {
        let mut p = versioned();
        p.accept_version("new", "", program(NEW), 200, Selector::all())
            .unwrap();
        p.accept_version("old", "rollback", program(OLD), 400, Selector::all())
            .unwrap();
        let out = feed(
            &mut p,
            "m,robot=a x=1i 100\nm,robot=a x=1i 250\nm,robot=a x=1i 450\n",
        );
        assert_eq!(
            out,
            "tessla,robot=a,spec_version=old c=1i,s=2i 100\n\
             tessla,robot=a,spec_version=new c=2i,s=10i 250\n\
             tessla,robot=a,spec_version=old c=3i,s=2i 450\n"
        );
        // Both starts passed in one step: ends in the newest.
        let out = feed(&mut p, "m,robot=b x=1i 100\nm,robot=b x=1i 500\n");
        assert!(
            out.ends_with("tessla,robot=b,spec_version=old c=2i,s=2i 500\n"),
            "{out}"
        );
        assert_eq!(p.versions().list.len(), 2);
    }

    /// Checks before a version counts: a selector naming a tag that chooses no instance, and
    /// bindings that cannot read the metrics seen.
    #[test]
    fn a_version_that_does_not_fit_is_refused() {
        let mut p = versioned();
        let e = p
            .check_version(
                "new",
                &program(NEW),
                &Selector::parse("site=lab").unwrap(),
                &[],
            )
            .unwrap_err();
        assert!(e.contains("site"), "{e}");
        feed(&mut p, "m,robot=a x=1i 100\n");
        let strings = "in x: Events[Bool]\nout x\n";
        let e = p
            .check_version("b", &program(strings), &Selector::all(), p.samples())
            .unwrap_err();
        assert!(e.contains("input `x`"), "{e}");
        let other = "in y: Events[Int]\nout y\n";
        let e = p
            .check_version("o", &program(other), &Selector::all(), p.samples())
            .unwrap_err();
        assert!(e.contains("none of its inputs"), "{e}");
        p.check_version("new", &program(NEW), &Selector::all(), p.samples())
            .unwrap();
    }

    /// A rollout starting behind instances' clocks: they are counted (the status says how many
    /// switched late), and each switches at its next step.
    #[test]
    fn instances_already_past_a_start_are_counted_and_switch_next() {
        let mut p = versioned();
        feed(&mut p, "m,robot=a x=1i 100\nm,robot=b x=1i 500\n");
        let sel = Selector::parse("robot=a,b").unwrap();
        assert_eq!(p.instances_past(300, &sel), (1, 200));
        assert_eq!(p.instances_past(600, &sel), (0, 0));
        p.accept_version("new", "", program(NEW), 300, sel).unwrap();
        let out = feed(&mut p, "m,robot=b x=2i 600\n");
        assert_eq!(out, "tessla,robot=b,spec_version=new c=2i,s=20i 600\n");
    }

    const AB: &str = "in x: Events[Int]\ndef a = x * 2\ndef b = x + 100\nout a\nout b\n";
    const CD: &str = "in x: Events[Int]\ndef c = x * 3\ndef d = x + 1000\nout c\nout d\n";

    fn renamed() -> Processor {
        let mut p = Processor::new(
            program(AB),
            Options {
                passthrough: false,
                instance_by: vec!["robot".into()],
                ..Options::default()
            },
        )
        .unwrap();
        p.name_base("v1", "");
        p
    }

    /// A canary whose outputs have other names than the base's (as many of them): each
    /// instance's lines carry its own version's field names, whichever instance wrote last.
    #[test]
    fn a_canary_with_renamed_outputs_writes_its_own_field_names() {
        let mut p = renamed();
        p.accept_version(
            "v2",
            "",
            program(CD),
            300,
            Selector::parse("robot=r1").unwrap(),
        )
        .unwrap();
        let out = feed(
            &mut p,
            "m,robot=r1 x=5i 100\nm,robot=r2 x=5i 100\nm,robot=r1 x=5i 300\nm,robot=r2 x=5i 300\nm,robot=r1 x=6i 400\nm,robot=r2 x=6i 400\nm,robot=r1 x=7i 500\n",
        );
        assert_eq!(
            out,
            "tessla,robot=r1 a=10i,b=105i 100\n\
             tessla,robot=r2 a=10i,b=105i 100\n\
             tessla,robot=r1 c=15i,d=1005i 300\n\
             tessla,robot=r2 a=10i,b=105i 300\n\
             tessla,robot=r1 c=18i,d=1006i 400\n\
             tessla,robot=r2 a=12i,b=106i 400\n\
             tessla,robot=r1 c=21i,d=1007i 500\n"
        );
        // Without a rollout, the same bytes as ever.
        let mut q = renamed();
        let out = feed(&mut q, "m,robot=r1 x=5i 100\nm,robot=r2 x=6i 100\n");
        assert_eq!(
            out,
            "tessla,robot=r1 a=10i,b=105i 100\ntessla,robot=r2 a=12i,b=106i 100\n"
        );
    }

    /// One instance switching to a version with renamed outputs, back, and to it again: each
    /// line carries the names of the version that computed it.
    #[test]
    fn an_instance_switching_back_and_forth_writes_each_versions_names() {
        let mut p = renamed();
        let r1 = || Selector::parse("robot=r1").unwrap();
        p.accept_version("v2", "", program(CD), 200, r1()).unwrap();
        p.accept_version("v1", "", program(AB), 300, r1()).unwrap();
        p.accept_version("v2", "", program(CD), 400, r1()).unwrap();
        let out = feed(
            &mut p,
            "m,robot=r1 x=1i 100\nm,robot=r1 x=1i 200\nm,robot=r1 x=1i 300\nm,robot=r1 x=1i 400\n",
        );
        assert_eq!(
            out,
            "tessla,robot=r1 a=2i,b=101i 100\n\
             tessla,robot=r1 c=3i,d=1001i 200\n\
             tessla,robot=r1 a=2i,b=101i 300\n\
             tessla,robot=r1 c=3i,d=1001i 400\n"
        );
        assert_eq!(p.counters.switched, 3);
    }

    /// `reset_outputs` names what changes between the version each picked robot runs before the
    /// start and the new one: r1 ran v2 (from 100), which v3 changes in `t` only, although v3
    /// differs from the base in `s` too; a selector also picking r2 (on the base) adds `s`.
    #[test]
    fn reset_outputs_name_only_what_changes_from_the_version_the_robot_ran() {
        const V1: &str = "in x: Events[Int]\ndef s = x + 1\ndef t = x + 2\nout s\nout t\n";
        const V2: &str = "in x: Events[Int]\ndef s = x * 10\ndef t = x + 2\nout s\nout t\n";
        const V3: &str = "in x: Events[Int]\ndef s = x * 10\ndef t = x * 20\nout s\nout t\n";
        let base = || {
            let mut p = Processor::new(
                program(V1),
                Options {
                    passthrough: false,
                    instance_by: vec!["robot".into()],
                    ..Options::default()
                },
            )
            .unwrap();
            let r1 = Selector::parse("robot=r1").unwrap();
            let acc = p.accept_version("v2", "", program(V2), 100, r1).unwrap();
            assert_eq!(acc.reset_outputs, ["s"]);
            p
        };
        let mut p = base();
        let r1 = Selector::parse("robot=r1").unwrap();
        let acc = p.accept_version("v3", "", program(V3), 200, r1).unwrap();
        assert_eq!(acc.reset_outputs, ["t"]);
        let mut p = base();
        let both = Selector::parse("robot=r1,r2").unwrap();
        let acc = p.accept_version("v3", "", program(V3), 200, both).unwrap();
        assert_eq!(acc.reset_outputs, ["s", "t"]);
        // Every robot but r1 runs the base at 199: all of them start `s` and `t` afresh.
        let mut p = base();
        let acc = p
            .accept_version("v3", "", program(V3), 200, Selector::all())
            .unwrap();
        assert_eq!(acc.reset_outputs, ["s", "t"]);
        // A rule starting after the new one does not count; one for r1 back to the base does.
        let mut p = base();
        let r1 = || Selector::parse("robot=r1").unwrap();
        p.accept_version("v3", "", program(V3), 300, r1()).unwrap();
        let acc = p.accept_version("v2", "", program(V2), 250, r1()).unwrap();
        assert_eq!(acc.reset_outputs, Vec::<String>::new());
    }

    const COUNT: &str = "in x: Events[Int]\ndef n = count(x)\nout n\n";

    fn idle_processor(spec: &str, idle: Duration) -> Processor {
        Processor::new(
            program(spec),
            Options {
                passthrough: false,
                instance_by: vec!["robot".into()],
                instance_idle: Some(idle),
                max_ahead: None,
                ..Options::default()
            },
        )
        .unwrap()
    }

    /// Output lines sorted (instances on different processors interleave otherwise).
    fn sorted(out: &str) -> Vec<String> {
        let mut v: Vec<String> = out.lines().map(String::from).collect();
        v.sort();
        v
    }

    /// Whether an instance is evicted for idleness depends on its own silence only: robots r5
    /// and r2 each silent 2.5 s past a 1 s limit both start afresh, on one processor (one
    /// thread) as on two (two threads, one robot each).
    #[test]
    fn an_idle_instance_is_evicted_by_its_own_silence_alone() {
        let t0 = Instant::now();
        let first = "m,robot=r5 x=1i 1000\nm,robot=r2 x=1i 1000\n";
        let second = "m,robot=r5 x=1i 2000\nm,robot=r2 x=1i 2000\n";
        let run = |procs: &mut [Processor], text: &str, at: Instant| {
            let mut out = String::new();
            for line in text.lines() {
                let i = if procs.len() > 1 && line.contains("r2") {
                    1
                } else {
                    0
                };
                procs[i].set_wall(Wall { at, ns: 0 });
                out.push_str(&feed(&mut procs[i], &format!("{line}\n")));
            }
            out
        };
        let idle = Duration::from_secs(1);
        let mut one = [idle_processor(COUNT, idle)];
        let mut two = [idle_processor(COUNT, idle), idle_processor(COUNT, idle)];
        let later = t0 + Duration::from_millis(2500);
        let mut a = run(&mut one, first, t0);
        a.push_str(&run(&mut one, second, later));
        let mut b = run(&mut two, first, t0);
        b.push_str(&run(&mut two, second, later));
        assert_eq!(
            sorted(&a),
            [
                "tessla,robot=r2 n=1i 1000",
                "tessla,robot=r2 n=1i 2000",
                "tessla,robot=r5 n=1i 1000",
                "tessla,robot=r5 n=1i 2000",
            ]
        );
        assert_eq!(sorted(&a), sorted(&b));
        assert_eq!(one[0].counters.evicted, 2);
        assert_eq!(two[0].counters.evicted + two[1].counters.evicted, 2);
        // Within the limit, both keep their count.
        let mut p = idle_processor(COUNT, idle);
        p.set_wall(Wall { at: t0, ns: 0 });
        feed(&mut p, first);
        p.set_wall(Wall {
            at: t0 + Duration::from_millis(900),
            ns: 0,
        });
        assert_eq!(
            feed(&mut p, second),
            "tessla,robot=r5 n=2i 2000\ntessla,robot=r2 n=2i 2000\n"
        );
        assert_eq!(p.counters.evicted, 0);
    }

    /// A silent instance idle past the limit before its watchdog falls due is evicted, its
    /// `delay` never fires; the wall clock wakes the loop for the eviction itself.
    #[test]
    fn a_watchdog_due_after_the_idle_limit_does_not_fire() {
        let spec = "in x: Events[Int]\n\
                    def silent = delay(const(2000000000, x), x)\n\
                    out silent\n";
        let t0 = Instant::now();
        let mut p = idle_processor(spec, Duration::from_secs(1));
        p.set_wall(Wall { at: t0, ns: 0 });
        feed(&mut p, "m,robot=r1 x=1i 1000000000\n");
        // Evicting it is due at the idle limit, before the watchdog.
        let next = p.next_deadline().unwrap();
        assert!(next <= t0 + Duration::from_millis(1001), "{next:?}");
        let mut out = Vec::new();
        p.advance_wall(t0 + Duration::from_millis(2260), &mut out);
        assert_eq!(String::from_utf8(out).unwrap(), "");
        assert_eq!(p.counters.evicted, 1);
        assert_eq!(p.instance_count(), 0);
        assert_eq!(p.next_deadline(), None);
        // With a longer limit, it fires.
        let mut p = idle_processor(spec, Duration::from_secs(5));
        p.set_wall(Wall { at: t0, ns: 0 });
        feed(&mut p, "m,robot=r1 x=1i 1000000000\n");
        let mut out = Vec::new();
        p.advance_wall(t0 + Duration::from_millis(2260), &mut out);
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "tessla,robot=r1 silent=true 3000000000\n"
        );
        assert_eq!(p.counters.evicted, 0);
    }

    /// A spec over a list pattern and an exact field: the list's length, some elements and a
    /// fold over all of them, so any element read differently changes an output.
    const LIST_SPEC: &str = "@TelegrafIn(\"m\", \"\", \"lidar_*\")\n\
        in l: Events[List[Float]]\n\
        @TelegrafIn(\"m\", \"\", \"x\")\n\
        in x: Events[Float]\n\
        def n = List.size(l)\n\
        def a = List.get(l, 0)\n\
        def b = List.get(l, 3)\n\
        def s = List.fold(l, 0.0, (acc: Float, v: Float) => if v == v then acc +. v else acc +. 1000.0)\n\
        out n\nout a\nout b\nout s\nout x\n";

    /// Records with lists as Telegraf writes them and everything unusual a list's fields can
    /// be: missing, repeated and non-Float elements, other index forms, keys of the prefix that
    /// are no index, escapes, redelivered and late records.
    fn list_records(n: usize) -> String {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0x9e37_79b9);
        let mut next = move |m: u64| rand::RngCore::next_u64(&mut rng) % m;
        let mut text = String::new();
        let mut last = String::new();
        for r in 0..n {
            if r > 0 && next(40) == 0 {
                // A redelivered message (another field order would do: the digest is the same).
                text.push_str(&last);
                continue;
            }
            let beams = 4 + next(6) as usize;
            let mut fields: Vec<String> = Vec::new();
            for i in 0..beams {
                if next(15) == 0 {
                    continue;
                }
                let v = match next(12) {
                    0 => "0".to_string(),
                    1 => "2.4749999046325684".to_string(),
                    2 => format!("{}i", next(5)),
                    3 if next(4) == 0 => "\"x\"".to_string(),
                    4 => "1e3".to_string(),
                    5 => "-0.5".to_string(),
                    _ => format!("{}.{}", next(4), next(1000)),
                };
                fields.push(format!("lidar_{i}={v}"));
            }
            match next(30) {
                0 => fields.push("lidar_2=7.5".into()),
                1 => fields.push("lidar_02=7.5".into()),
                2 => fields.push("lidar_+1=7.5".into()),
                3 => fields.push("lidar_count=5i".into()),
                4 => fields.push("lidar_=1".into()),
                5 => fields.push("lidar_99999=1".into()),
                6 => fields.push("lidar\\ 1=2".into()),
                7 => fields.push("lidar_1x=2".into()),
                _ => {}
            }
            fields.push(format!("x={}", next(100)));
            for i in (1..fields.len()).rev() {
                fields.swap(i, next(i as u64 + 1) as usize);
            }
            let ts = if next(50) == 0 {
                r * 1000 - 1500
            } else {
                r * 1000 + 1000
            };
            last = format!("m,robot=r{} {} {ts}\n", next(2), fields.join(","));
            text.push_str(&last);
        }
        text
    }

    /// Reading a list's elements apart (after the wiring window) changes no output and no
    /// counter: the same records through a processor that never captures give the same bytes.
    #[test]
    fn a_list_read_apart_gives_what_the_fields_give() {
        let resolver = MemResolver {
            files: [("t.tessla".to_string(), LIST_SPEC.to_string())].into(),
        };
        let loaded = tessla_engine::load_with("t.tessla", &resolver, &Default::default()).unwrap();
        let opts = || Options {
            instance_by: vec!["robot".into()],
            ..Options::default()
        };
        let mut fast = Processor::new(loaded.program.clone(), opts()).unwrap();
        let mut plain = Processor::new(loaded.program, opts()).unwrap();
        assert_eq!(fast.capture.as_deref(), Some("lidar_"));
        plain.capture = None;
        let input = list_records(3000);
        let (mut a, mut b) = (String::new(), String::new());
        for chunk in input.split_inclusive('\n').collect::<Vec<_>>().chunks(100) {
            a.push_str(&feed(&mut fast, &chunk.concat()));
            b.push_str(&feed(&mut plain, &chunk.concat()));
        }
        assert!(
            fast.wiring.is_done(),
            "the window ended: records were captured"
        );
        assert_eq!(a, b);
        assert_eq!(
            format!("{:?}", fast.counters),
            format!("{:?}", plain.counters)
        );
        assert!(fast.counters.duplicates > 10, "{:?}", fast.counters);
        assert!(fast.counters.late > 10, "{:?}", fast.counters);
        assert!(fast.counters.dropped_values > 10, "{:?}", fast.counters);
    }
}
