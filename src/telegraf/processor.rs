//! The step loop: records in, pass-through and verdict lines out.
//!
//! Owns: routing each metric to its monitor instance (one, or one per value of the
//! `--instance-by` tags, each with its own state, timestamps and late-record rule; evicted past
//! `--max-instances` or after `--instance-idle`); when a step is evaluated (a record with a later
//! timestamp arrives, or the transport says no more input is available right now: [`flush`]);
//! late records (`--late shift|drop`); records without a timestamp (wall clock, as Telegraf);
//! pass-through of each record's exact bytes before the outputs it causes; and the counters of
//! the summary line. Bad records are reported with their line number and skipped.
//!
//! [`flush`]: Processor::flush

use super::binding::{self, InputBinding};
use super::encode::{self, Encoding};
use super::instances::{Key, Table};
use crate::log;
use lineproto::{Metric, Record, RecordRef, parse_record_into};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tessla_engine::{InputError, Monitor, OutputEvent, Program, Value};

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Default)]
pub enum LateMode {
    /// Evaluate a late record at the last evaluated step + 1 ns.
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
}

/// Most monitor instances with a step open at once (see [`Processor::record`]); past it the
/// steps open longest are evaluated.
pub const MAX_OPEN_STEPS: usize = 1024;

pub const DEFAULT_MAX_INSTANCES: usize = 100_000;

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
    pub dropped_values: u64,
    /// Monitor instances created.
    pub instances: u64,
    /// Monitor instances evicted (LRU or idle).
    pub evicted: u64,
    /// Exact repeats of a recent record, dropped ([`super::dedup`]).
    pub duplicates: u64,
}

impl Counters {
    /// Add `other`'s counts (a `--threads` worker's, at the end of a run).
    pub fn add(&mut self, other: &Counters) {
        self.records += other.records;
        self.events += other.events;
        self.outputs += other.outputs;
        self.parse_errors += other.parse_errors;
        self.late += other.late;
        self.dropped_values += other.dropped_values;
        self.instances += other.instances;
        self.evicted += other.evicted;
    }
}

/// One monitor and the tags its output lines carry (static tags and instance tags).
struct Instance {
    monitor: Monitor,
    tags: Vec<(String, String)>,
    recent: super::dedup::Recent,
}

/// What writing a step's outputs needs, apart from the instance.
struct Emitter {
    encodings: Vec<Encoding>,
    measurement: String,
    events: Vec<(i64, usize, Value)>,
    /// Scratch: the encoder's buffers.
    encode: encode::Scratch,
}

pub struct Processor {
    program: Arc<Program>,
    bindings: Vec<InputBinding>,
    emitter: Emitter,
    opts: Options,
    /// Most instances kept here: `--max-instances`, or this thread's share of it.
    keep: usize,
    /// Most steps held open here: [`MAX_OPEN_STEPS`], or this thread's share of it.
    keep_open: usize,
    pub counters: Counters,
    instances: Table<Instance>,
    /// Stands in for "now" when no idle limit needs the clock.
    epoch: Instant,
    /// The slot of the only instance, when there is one that is never evicted.
    single: Option<usize>,
    /// Reused for every record's parse (keeps its strings' and vectors' capacity).
    scratch: Metric,
    /// Warns about inputs the first records never feed (see [`super::wiring`]).
    wiring: super::wiring::WiringCheck,
}

fn now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

fn describe(instance_by: &[String], key: &Key) -> String {
    instance_by
        .iter()
        .zip(key)
        .map(|(k, v)| format!("{k}={}", v.as_deref().unwrap_or("(absent)")))
        .collect::<Vec<_>>()
        .join(",")
}

impl Processor {
    /// A processor for `program`; fails when an input annotation is malformed.
    pub fn new(program: Arc<Program>, opts: Options) -> Result<Processor, String> {
        let bindings = binding::bindings(&program)?;
        let encodings = encode::encodings(&program);
        let wiring = super::wiring::WiringCheck::new(&bindings);
        Ok(Processor {
            program,
            bindings,
            emitter: Emitter {
                encodings,
                measurement: opts.measurement.clone(),
                events: Vec::new(),
                encode: encode::Scratch::default(),
            },
            keep: opts.max_instances.max(1),
            keep_open: MAX_OPEN_STEPS,
            opts,
            counters: Counters::default(),
            instances: Table::default(),
            epoch: Instant::now(),
            single: None,
            scratch: Metric::default(),
            wiring,
        })
    }

    /// A processor with this one's program and options and no instances (a `--threads` worker).
    pub fn sibling(&self) -> Result<Processor, String> {
        Processor::new(self.program.clone(), self.opts.clone())
    }

    /// `--max-instances`: the most instances kept over all threads.
    pub fn max_instances(&self) -> usize {
        self.opts.max_instances
    }

    /// Keep at most `n` instances here (at least 1): a `--threads` shard's share of the total.
    pub fn keep_instances(&mut self, n: usize) {
        self.keep = n.max(1);
    }

    /// Hold at most `n` steps open here (at least 1): a `--threads` shard's share of
    /// [`MAX_OPEN_STEPS`], so that the threads together hold as much as one.
    pub fn keep_open_steps(&mut self, n: usize) {
        self.keep_open = n.max(1);
    }

    /// The tags that select an instance (`--instance-by`).
    pub fn instance_by(&self) -> &[String] {
        &self.opts.instance_by
    }

    /// Monitor instances alive now.
    pub fn instance_count(&self) -> usize {
        self.instances.len()
    }

    fn now(&self) -> Instant {
        if self.opts.instance_idle.is_some() {
            Instant::now()
        } else {
            self.epoch
        }
    }

    fn key(&self, m: &Metric) -> Key {
        self.opts
            .instance_by
            .iter()
            .map(|t| m.tag(t).map(str::to_string))
            .collect()
    }

    /// The instance for `m`, created (starting at `ts`) when new.
    fn instance_for(&mut self, m: &Metric, ts: i64, now: Instant) -> usize {
        // One instance that is never evicted: skip the lookup.
        if self.opts.instance_by.is_empty()
            && self.opts.instance_idle.is_none()
            && let Some(i) = self.single
        {
            return i;
        }
        let key = self.key(m);
        if let Some(i) = self.instances.find(&key, now) {
            return i;
        }
        self.counters.instances += 1;
        let monitor = Monitor::starting_at(self.program.clone(), ts);
        self.insert_instance(key, monitor, now)
    }

    /// Add instance `key` (absent from the table) running `monitor`; returns its slot.
    fn insert_instance(&mut self, key: Key, monitor: Monitor, now: Instant) -> usize {
        let mut tags: Vec<(String, String)> = self
            .opts
            .tags
            .iter()
            .filter(|(k, _)| !self.opts.instance_by.contains(k))
            .cloned()
            .collect();
        for (k, v) in self.opts.instance_by.iter().zip(&key) {
            if let Some(v) = v {
                tags.push((k.clone(), v.clone()));
            }
        }
        if !self.opts.instance_by.is_empty() {
            tags.sort();
        }
        let i = self.instances.insert(
            key,
            Instance {
                monitor,
                tags,
                recent: Default::default(),
            },
            now,
        );
        if self.opts.instance_by.is_empty() && self.opts.instance_idle.is_none() {
            self.single = Some(i);
        }
        i
    }

    /// Evict instances past `--max-instances` or idle too long, writing their pending outputs.
    fn evict(&mut self, now: Instant, out: &mut Vec<u8>) {
        let max = self.keep;
        let total = self.opts.max_instances;
        while let Some(i) = self.instances.evictable(max, self.opts.instance_idle, now) {
            let full = self.instances.len() > max;
            let Some((key, mut inst)) = self.instances.remove(i) else {
                break;
            };
            self.emitter.flush(&mut inst, &mut self.counters, out);
            self.counters.evicted += 1;
            let by = &self.opts.instance_by;
            log::warn_limited("instance evicted", || {
                let why = if full {
                    format!("least recently used, --max-instances {total}")
                } else {
                    "idle longer than --instance-idle".to_string()
                };
                let share = if full && max != total {
                    format!(" (the threads share the total: this one keeps {max})")
                } else {
                    String::new()
                };
                format!(
                    "monitor instance {} evicted ({why}); its state starts afresh with its next record{share}",
                    describe(by, &key)
                )
            });
        }
    }

    /// Handle one record, appending pass-through and completed steps' outputs to `out`.
    pub fn record(&mut self, rec: &Record, out: &mut Vec<u8>) {
        self.record_ref(rec.view(), out);
    }

    /// [`Processor::record`] on a borrowed record (the stdio loop's records point into its read
    /// buffer; pass-through copies them from there).
    pub fn record_ref(&mut self, rec: RecordRef<'_>, out: &mut Vec<u8>) {
        self.counters.records += 1;
        if rec.oversized {
            self.counters.parse_errors += 1;
            log::warn_limited("parse error", || {
                format!("line {}: record longer than the limit; skipped", rec.line)
            });
            return;
        }
        // Parse into the scratch metric: plain records then allocate nothing.
        let mut metric = std::mem::take(&mut self.scratch);
        match parse_record_into(rec.bytes, &mut metric) {
            Ok(true) => {
                self.record_metric(&rec, &metric, out);
                self.scratch = metric;
            }
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

    /// Route one parsed record to its instance: pass-through, completed steps, its events.
    fn record_metric(&mut self, rec: &RecordRef<'_>, metric: &Metric, out: &mut Vec<u8>) {
        if metric.overwritten > 0 {
            log::warn_limited("repeated field", || {
                format!(
                    "line {}: {} field value(s) overwritten by a later value of the same key; the last value is used, as Telegraf does",
                    rec.line, metric.overwritten
                )
            });
        }
        let mut ts = metric.timestamp.unwrap_or_else(now_ns);
        let now = self.now();
        let slot = self.instance_for(metric, ts, now);
        let Some(inst) = self.instances.get_mut(slot) else {
            return;
        };
        if let Some(t) = metric.timestamp
            && inst.recent.is_duplicate(t, metric)
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
        let mut late = false;
        // The earliest timestamp still accepted: the open step, or just after the last evaluated one.
        let min = match (monitor.pending(), monitor.last_evaluated()) {
            (Some(p), _) => Some(p),
            (None, Some(l)) => Some(l.saturating_add(1)),
            (None, None) => None,
        };
        if let Some(min) = min
            && ts < min
        {
            late = true;
            self.counters.late += 1;
            let mode = self.opts.late;
            log::warn_limited("late record", || {
                format!(
                    "line {}: timestamp {ts} is not after the last evaluated step; {}",
                    rec.line,
                    if mode == LateMode::Shift {
                        format!("evaluated at {min}")
                    } else {
                        "its events are dropped".into()
                    }
                )
            });
            ts = min;
        }
        // Evaluate the open step and the delay firings before `ts` now, so their outputs
        // precede this record's pass-through whenever the previous read ended.
        if monitor.pending().is_none_or(|p| ts > p) {
            let events = &mut self.emitter.events;
            monitor.advance_to(ts, &mut |e: OutputEvent<'_>| {
                events.push((e.ts, e.output, e.value.clone()))
            });
            self.emitter.emit(&inst.tags, &mut self.counters, out);
        }
        if self.opts.passthrough {
            out.extend_from_slice(rec.bytes);
            if rec.bytes.last() != Some(&b'\n') {
                out.push(b'\n');
            }
        }
        if !(late && self.opts.late == LateMode::Drop) {
            self.push_fields(metric, rec.line, ts, slot, out);
        }
        self.instances.mark_open(slot);
        self.close_oldest_steps(out);
        self.evict(now, out);
    }

    /// Bound the steps held open: past [`MAX_OPEN_STEPS`] (a fleet piped in faster than it is
    /// read never pauses, so every robot would hold its last record's events, 360 beams each),
    /// evaluate the steps open longest. A later record of such an instance with the same
    /// timestamp is then late, as after a pause in the input.
    fn close_oldest_steps(&mut self, out: &mut Vec<u8>) {
        while self.instances.open_count() > self.keep_open {
            let Some(i) = self.instances.take_oldest_open() else {
                break;
            };
            if let Some(inst) = self.instances.get_mut(i) {
                self.emitter.flush(inst, &mut self.counters, out);
            }
        }
    }

    /// Whether `bytes` holds a newline before its last byte.
    fn spans_lines(bytes: &[u8]) -> bool {
        bytes
            .split_last()
            .is_some_and(|(_, head)| head.contains(&b'\n'))
    }

    /// Feed the metric's bound fields to instance `slot` as events at `ts`.
    fn push_fields(&mut self, metric: &Metric, line: u64, ts: i64, slot: usize, out: &mut Vec<u8>) {
        self.wiring.observe(metric, &self.bindings);
        let Some(inst) = self.instances.get_mut(slot) else {
            return;
        };
        for b in &self.bindings {
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
                Some(Ok(v)) => {
                    let events = &mut self.emitter.events;
                    let r = inst
                        .monitor
                        .push(ts, b.input, v, &mut |e: OutputEvent<'_>| {
                            events.push((e.ts, e.output, e.value.clone()))
                        });
                    match r {
                        Ok(()) => self.counters.events += 1,
                        Err(err) => {
                            self.counters.dropped_values += 1;
                            let why = match err {
                                InputError::Multiple { .. } => {
                                    "a second event on this input in the same step".to_string()
                                }
                                InputError::Decreasing { last, got } => format!(
                                    "timestamp {got} is before the last evaluated one ({last})"
                                ),
                                InputError::UnknownInput(i) => {
                                    format!("the spec has no input number {i}")
                                }
                            };
                            log::warn_limited("input event", || {
                                format!("line {line}: input `{}`: {why}; value skipped", b.name)
                            });
                        }
                    }
                }
            }
        }
        self.emitter.emit(&inst.tags, &mut self.counters, out);
    }

    /// No more input right now: evaluate every instance's pending step and append its outputs.
    pub fn flush(&mut self, out: &mut Vec<u8>) {
        for i in self.instances.take_open() {
            if let Some(inst) = self.instances.get_mut(i) {
                self.emitter.flush(inst, &mut self.counters, out);
            }
        }
        let now = self.now();
        self.evict(now, out);
    }

    /// The input ended: warn about inputs that what was seen never fed (once).
    pub fn finish_wiring(&mut self) {
        self.wiring.finish(&self.bindings);
    }

    /// The program every instance runs.
    pub fn program(&self) -> &Arc<Program> {
        &self.program
    }

    /// Every instance's key and monitor, least recently used first (`--state`).
    pub fn monitors(&self) -> impl Iterator<Item = (&Key, &Monitor)> {
        self.instances.iter_lru().map(|(k, i)| (k, &i.monitor))
    }

    /// Add an instance restored from saved state; ignored when `key` already has one.
    pub fn restore_instance(&mut self, key: Key, monitor: Monitor) {
        let now = self.now();
        if self.instances.find(&key, now).is_none() {
            self.insert_instance(key, monitor, now);
        }
    }

    /// Run `program` from now on (a spec reload). Every open step is evaluated first with the
    /// old program; then `carry` turns each instance's monitor into one of the new program.
    /// Fails (nothing changed) when the new program's input annotations are malformed.
    pub fn replace_program(
        &mut self,
        program: Arc<Program>,
        out: &mut Vec<u8>,
        mut carry: impl FnMut(&Monitor) -> Monitor,
    ) -> Result<(), String> {
        let bindings = binding::bindings(&program)?;
        self.flush(out);
        for inst in self.instances.values_mut() {
            inst.monitor = carry(&inst.monitor);
        }
        self.emitter.encodings = encode::encodings(&program);
        self.emitter.encode = encode::Scratch::default();
        self.wiring = super::wiring::WiringCheck::new(&bindings);
        self.bindings = bindings;
        self.program = program;
        Ok(())
    }

    /// The one-line summary printed at the end of a run.
    pub fn summary(&self) -> String {
        let c = &self.counters;
        let mut s = format!(
            "summary: {} records, {} events, {} outputs, {} parse errors, {} late records, {} dropped values, {} duplicates",
            c.records, c.events, c.outputs, c.parse_errors, c.late, c.dropped_values, c.duplicates
        );
        if !self.opts.instance_by.is_empty() {
            s.push_str(&format!(
                ", {} instances, {} evicted",
                c.instances, c.evicted
            ));
        }
        s
    }
}

impl Emitter {
    /// Evaluate the instance's pending step (or its first step) and write the outputs.
    fn flush(&mut self, inst: &mut Instance, counters: &mut Counters, out: &mut Vec<u8>) {
        let events = &mut self.events;
        inst.monitor
            .flush(&mut |e: OutputEvent<'_>| events.push((e.ts, e.output, e.value.clone())));
        self.emit(&inst.tags, counters, out);
    }

    /// Write the collected events as metrics, one group per timestamp.
    fn emit(&mut self, tags: &[(String, String)], counters: &mut Counters, out: &mut Vec<u8>) {
        if self.events.is_empty() {
            return;
        }
        let mut rest = &self.events[..];
        while let Some(&(ts, _, _)) = rest.first() {
            // One timestamp's events, encoded in place.
            let n = rest.iter().take_while(|e| e.0 == ts).count();
            let (step, tail) = rest.split_at(n);
            rest = tail;
            counters.outputs += step.len() as u64;
            let dropped = encode::encode_step_with(
                &mut self.encode,
                ts,
                step,
                &self.encodings,
                &self.measurement,
                tags,
                out,
            );
            for d in dropped {
                counters.dropped_values += 1;
                log::warn_limited("output value", || {
                    format!("output `{}` at {ts}: {}; field dropped", d.output, d.reason)
                });
            }
        }
        // Keep the buffer's capacity for the next step.
        self.events.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
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
        p.flush(&mut out);
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

    /// A fleet that never pauses holds at most MAX_OPEN_STEPS steps open: the oldest are
    /// evaluated while records keep coming, with the outputs they would get at a pause.
    #[test]
    fn open_steps_are_bounded_without_changing_outputs() {
        let robots = MAX_OPEN_STEPS + 100;
        let mut p = processor(Options {
            passthrough: false,
            instance_by: vec!["robot".into()],
            ..Options::default()
        });
        let mut out = Vec::new();
        for r in 0..robots {
            let rec = Record {
                bytes: format!("m,robot=r{r} x={r}i 100\n").into_bytes(),
                line: r as u64 + 1,
                oversized: false,
            };
            p.record(&rec, &mut out);
        }
        let before_flush = String::from_utf8(out.clone()).unwrap();
        // The first 100 robots' steps were closed without a pause in the input.
        assert_eq!(before_flush.lines().count(), 100, "{before_flush}");
        assert!(before_flush.starts_with("tessla,robot=r0 c=1i,k=7i,x=0i 100\n"));
        assert_eq!(p.instances.open_count(), MAX_OPEN_STEPS);
        p.flush(&mut out);
        let all = String::from_utf8(out).unwrap();
        assert_eq!(all.lines().count(), robots);
        for r in 0..robots {
            let line = format!("tessla,robot=r{r} c=1i,k=7i,x={r}i 100\n");
            assert!(all.contains(&line), "missing {line}");
        }
        assert_eq!(p.counters.late, 0);
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

    #[test]
    fn records_with_one_timestamp_join_one_step_after_their_pass_through() {
        let mut p = processor(Options::default());
        let out = feed(&mut p, "m x=5 100\nm y=1 100\nm x=6 200\n");
        // The step at 100 is evaluated when the record at 200 arrives, before it is echoed.
        assert_eq!(
            out,
            "m x=5 100\nm y=1 100\ntessla c=1i,k=7i,x=5i 100\nm x=6 200\ntessla c=2i,x=6i 200\n"
        );
        assert_eq!(p.counters.records, 3);
        assert_eq!(p.counters.events, 2);
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
        let mut p = processor(Options {
            passthrough: false,
            late: LateMode::Drop,
            ..Options::default()
        });
        feed(&mut p, "m x=1 100\n");
        assert_eq!(feed(&mut p, "m x=2 100\n"), "");
        assert_eq!(feed(&mut p, "m x=3 300\n"), "tessla c=2i,x=3i 300\n");
        assert_eq!(p.counters.late, 1);
    }

    #[test]
    fn a_record_without_timestamp_gets_the_wall_clock() {
        let mut p = processor(Options {
            passthrough: false,
            ..Options::default()
        });
        let before = now_ns();
        let out = feed(&mut p, "m x=1\n");
        let after = now_ns();
        let m = parse_record(out.as_bytes()).unwrap().unwrap();
        let ts = m.timestamp.unwrap();
        assert!(before <= ts && ts <= after, "{before} <= {ts} <= {after}");
    }

    #[test]
    fn a_second_event_in_one_step_is_counted_and_skipped() {
        let mut p = processor(Options {
            passthrough: false,
            ..Options::default()
        });
        assert_eq!(
            feed(&mut p, "m x=1 100\nm x=2 100\n"),
            "tessla c=1i,k=7i,x=1i 100\n"
        );
        assert_eq!(p.counters.dropped_values, 1);
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
}
