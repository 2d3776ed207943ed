//! The step loop: records in, pass-through and verdict lines out.
//!
//! Owns: one monitor instance fed from metrics; when a step is evaluated (a record with a later
//! timestamp arrives, or the transport says no more input is available right now: [`flush`]);
//! late records (`--late shift|drop`); records without a timestamp (wall clock, as Telegraf);
//! pass-through of each record's exact bytes before the outputs it causes; and the counters of
//! the summary line. Bad records are reported with their line number and skipped.
//!
//! [`flush`]: Processor::flush

use super::binding::{self, InputBinding};
use super::encode::{self, Encoding};
use crate::log;
use lineproto::{Record, parse_record};
use std::sync::Arc;
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
}

impl Default for Options {
    fn default() -> Self {
        Options {
            passthrough: true,
            late: LateMode::Shift,
            measurement: "tessla".into(),
            tags: Vec::new(),
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
}

pub struct Processor {
    program: Arc<Program>,
    monitor: Option<Monitor>,
    bindings: Vec<InputBinding>,
    encodings: Vec<Encoding>,
    opts: Options,
    pub counters: Counters,
    events: Vec<(i64, usize, Value)>,
}

fn now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

impl Processor {
    /// A processor for `program`; fails when an input annotation is malformed.
    pub fn new(program: Arc<Program>, opts: Options) -> Result<Processor, String> {
        let bindings = binding::bindings(&program)?;
        let encodings = encode::encodings(&program);
        Ok(Processor {
            program,
            monitor: None,
            bindings,
            encodings,
            opts,
            counters: Counters::default(),
            events: Vec::new(),
        })
    }

    /// Handle one record, appending pass-through and completed steps' outputs to `out`.
    pub fn record(&mut self, rec: &Record, out: &mut Vec<u8>) {
        self.counters.records += 1;
        if rec.oversized {
            self.counters.parse_errors += 1;
            log::warn_limited("parse error", || {
                format!("line {}: record longer than the limit; skipped", rec.line)
            });
            return;
        }
        let metric = match parse_record(&rec.bytes) {
            Ok(Some(m)) => m,
            Ok(None) => {
                self.counters.records -= 1;
                return;
            }
            Err(e) => {
                self.counters.parse_errors += 1;
                log::warn_limited("parse error", || {
                    format!(
                        "line {}, column {}: {}: `{}`; line skipped",
                        rec.line, e.column, e.reason, e.excerpt
                    )
                });
                return;
            }
        };
        let mut ts = metric.timestamp.unwrap_or_else(now_ns);
        let monitor = self
            .monitor
            .get_or_insert_with(|| Monitor::starting_at(self.program.clone(), ts));
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
        if monitor.pending().is_some_and(|p| ts > p) {
            let events = &mut self.events;
            monitor.advance_to(ts, &mut |e: OutputEvent<'_>| {
                events.push((e.ts, e.output, e.value.clone()))
            });
            self.emit(out);
        }
        if self.opts.passthrough {
            out.extend_from_slice(&rec.bytes);
            if rec.bytes.last() != Some(&b'\n') {
                out.push(b'\n');
            }
        }
        if late && self.opts.late == LateMode::Drop {
            return;
        }
        let Some(monitor) = self.monitor.as_mut() else {
            return;
        };
        for b in &self.bindings {
            if !b.matches(&metric) {
                continue;
            }
            match b.extract(&metric) {
                None => {}
                Some(Err(e)) => {
                    self.counters.dropped_values += 1;
                    log::warn_limited("conversion", || {
                        format!(
                            "line {}: input `{}`: {}; value skipped",
                            rec.line, e.input, e.reason
                        )
                    });
                }
                Some(Ok(v)) => {
                    let events = &mut self.events;
                    let r = monitor.push(ts, b.input, v, &mut |e: OutputEvent<'_>| {
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
                                other => format!("{other:?}"),
                            };
                            log::warn_limited("input event", || {
                                format!(
                                    "line {}: input `{}`: {why}; value skipped",
                                    rec.line, b.name
                                )
                            });
                        }
                    }
                }
            }
        }
        self.emit(out);
    }

    /// No more input right now: evaluate the pending step and append its outputs.
    pub fn flush(&mut self, out: &mut Vec<u8>) {
        if let Some(m) = self.monitor.as_mut() {
            let events = &mut self.events;
            m.flush(&mut |e: OutputEvent<'_>| events.push((e.ts, e.output, e.value.clone())));
        }
        self.emit(out);
    }

    fn emit(&mut self, out: &mut Vec<u8>) {
        let events = std::mem::take(&mut self.events);
        let mut i = 0;
        while i < events.len() {
            let ts = events[i].0;
            let mut step = Vec::new();
            while i < events.len() && events[i].0 == ts {
                step.push((events[i].1, events[i].2.clone()));
                i += 1;
            }
            self.counters.outputs += step.len() as u64;
            let dropped = encode::encode_step(
                ts,
                &step,
                &self.encodings,
                &self.opts.measurement,
                &self.opts.tags,
                out,
            );
            for d in dropped {
                self.counters.dropped_values += 1;
                log::warn_limited("output value", || {
                    format!("output `{}` at {ts}: {}; field dropped", d.output, d.reason)
                });
            }
        }
    }

    /// The one-line summary printed at the end of a run.
    pub fn summary(&self) -> String {
        let c = &self.counters;
        format!(
            "summary: {} records, {} events, {} outputs, {} parse errors, {} late records, {} dropped values",
            c.records, c.events, c.outputs, c.parse_errors, c.late, c.dropped_values
        )
    }
}
