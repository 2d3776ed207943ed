//! The record's way through the processor: parse it (into the reused scratch metric), route it
//! to its instance, step it and write its pass-through and outputs. Whether its time is accepted
//! is `time_policy`'s; the deadlines it arms are `wall`'s.

use super::Processor;
use super::emit::Fired;
use super::pool::instance_note;
use super::time_policy;
use crate::log;
use lineproto::{Metric, Record, RecordRef, parse_record_into};
use tessla_engine::{InputError, OutputEvent};

/// Metrics kept for checking a new version's bindings.
const SAMPLES: usize = 16;

/// List elements at this index or past it are not read apart (the record takes the full parser):
/// the array grows to the largest index seen.
const CAPTURE_LIMIT: usize = 16384;

impl Processor {
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
        // What `take` left there is a default metric, which owns no memory: put back without
        // the call that would drop it.
        std::mem::forget(std::mem::replace(&mut self.scratch, metric));
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

    pub(super) fn passthrough(&self, rec: &RecordRef<'_>, out: &mut Vec<u8>) {
        if self.opts.passthrough {
            out.extend_from_slice(rec.bytes);
            if rec.bytes.last() != Some(&b'\n') {
                out.push(b'\n');
            }
        }
    }

    /// Route one parsed record to its instance: delay firings before it, pass-through, then
    /// its own step, evaluated at once.
    fn record_metric(&mut self, rec: &RecordRef<'_>, metric: &Metric, out: &mut Vec<u8>) {
        if metric.overwritten > 0 {
            let by = &self.opts.instance_by;
            log::warn_limited("repeated field", || {
                format!(
                    "line {}{}: {} field value(s) overwritten by a later value of the same key; the last value is used, as Telegraf does",
                    rec.line,
                    instance_note(by, metric),
                    metric.overwritten
                )
            });
        }
        let ts = metric.timestamp.unwrap_or(self.wall.ns);
        let own = ts;
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
            self.settle(slot, ts, Some(metric), out);
        }
        let Some(inst) = self.pool.table.get_mut(slot) else {
            return;
        };
        if let Some(t) = metric.timestamp
            && inst
                .recent
                .is_duplicate(t, metric, rec.bytes, &mut self.list_keys)
        {
            self.counters.duplicates += 1;
            let by = &self.opts.instance_by;
            log::warn_limited("duplicate", || {
                format!(
                    "line {}{}: exact repeat of a recent record (a redelivered message); dropped",
                    rec.line,
                    instance_note(by, metric)
                )
            });
            return;
        }
        // A record not after its instance's last step is stepped after it, or dropped.
        let (ts, dropped) = time_policy::late_step(
            &self.opts,
            &mut self.counters,
            rec,
            metric,
            ts,
            inst.monitor.last_evaluated(),
        );
        let monitor = &mut inst.monitor;
        // The delay firings before `ts` first, so their outputs precede this record's
        // pass-through.
        let events = &mut self.emitter.events;
        monitor.advance_to(ts, &mut |e: OutputEvent<'_>| events.push(Fired::of(e)));
        let version = self.versions.get(inst.version);
        self.emitter.emit(
            &version.encodings,
            &inst.escaped_tags,
            (&inst.fleet_key, &version.program),
            &mut self.counters,
            out,
        );
        self.passthrough(rec, out);
        if !dropped {
            self.push_fields(metric, rec.line, (ts, own), slot, out);
        }
        self.tap_clock(slot);
        self.schedule(slot, ts);
        self.pool
            .evict(now, &mut self.counters, self.lane.as_deref());
    }

    /// Whether `bytes` holds a newline before its last byte.
    fn spans_lines(bytes: &[u8]) -> bool {
        bytes
            .split_last()
            .is_some_and(|(_, head)| head.contains(&b'\n'))
    }

    /// Feed the metric's bound fields to instance `slot` as events at `ts`, evaluate the step
    /// and write its outputs. `own` is the record's own time (`ts` unless it was late and
    /// shifted): the `@TelegrafTime` inputs get it when the record's fields made the step.
    fn push_fields(
        &mut self,
        metric: &Metric,
        line: u64,
        (ts, own): (i64, i64),
        slot: usize,
        out: &mut Vec<u8>,
    ) {
        self.wiring.observe(metric, &self.versions.base().bindings);
        let Some(inst) = self.pool.table.get_mut(slot) else {
            return;
        };
        let version = self.versions.get(inst.version);
        let by = &self.opts.instance_by;
        let events = &mut self.emitter.events;
        let mut sink = |e: OutputEvent<'_>| events.push(Fired::of(e));
        let before = self.counters.events;
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
                            "line {line}{}: input `{}`: {}; value skipped",
                            instance_note(by, metric),
                            e.input,
                            e.reason
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
                            format!(
                                "line {line}{}: input `{}`: {why}; value skipped",
                                instance_note(by, metric),
                                b.name
                            )
                        });
                    }
                },
            }
        }
        if self.counters.events != before {
            // Not counted as events (those are the record's field values). Cannot fail: an
            // `@TelegrafTime` input has no field binding, and the step is the fields' own.
            for t in &version.times {
                let _ = inst
                    .monitor
                    .push(ts, t.input, tessla_engine::Value::Int(own), &mut sink);
            }
        }
        inst.monitor.flush(&mut sink);
        self.emitter.emit(
            &version.encodings,
            &inst.escaped_tags,
            (&inst.fleet_key, &version.program),
            &mut self.counters,
            out,
        );
    }

    /// No more input right now (the end of a read): evict instances past `--max-instances`
    /// (idle ones go by their own silence: [`Processor::advance_wall`] and their next record).
    /// Every record has been evaluated already.
    pub fn end_of_read(&mut self) {
        let now = self.pool.now(self.wall.at);
        self.pool
            .evict(now, &mut self.counters, self.lane.as_deref());
    }
}
