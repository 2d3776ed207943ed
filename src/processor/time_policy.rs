//! The time policy of live input: a record stamped beyond `--max-ahead` of the wall clock is
//! refused ([`Processor::refuse_ahead`]), and a record not after its instance's last step is
//! stepped 1 ns after it (`--late shift`) or dropped (`--late drop`, only when it is earlier):
//! [`late_step`].

use super::counters::Counters;
use super::pool::instance_note;
use super::{LateMode, Options, Processor, clock};
use crate::log;
use lineproto::{Metric, RecordRef};

impl Processor {
    /// Whether `ts` is beyond `--max-ahead` of the wall clock: then the record is refused
    /// (passed through, not evaluated), warned about and counted, and `true` is returned.
    #[inline]
    pub(super) fn refuse_ahead(&mut self, rec: &RecordRef<'_>, metric: &Metric, ts: i64) -> bool {
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
}

/// The step of a record stamped `ts` in an instance whose last step was at `last`, and whether
/// its events are dropped. A record not after its instance's last step (a record, or a delay
/// that fired) is a step of its own 1 ns after it: it never joins or collides with an evaluated
/// step. One earlier than it is late: counted, warned about, and with `--late drop` dropped.
#[inline]
pub(super) fn late_step(
    opts: &Options,
    counters: &mut Counters,
    rec: &RecordRef<'_>,
    metric: &Metric,
    ts: i64,
    last: Option<i64>,
) -> (i64, bool) {
    let Some(last) = last.filter(|&last| ts <= last) else {
        return (ts, false);
    };
    let at = last.saturating_add(1);
    let mut dropped = false;
    if ts < last {
        counters.late += 1;
        dropped = opts.late == LateMode::Drop;
        let by = &opts.instance_by;
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
    (at, dropped)
}
