//! Firing `delay`s by the wall clock while an instance's input is silent: each instance's next
//! firing queued as a wall-clock deadline ([`Processor::schedule`]), the earliest one a
//! transport sleeps until ([`Processor::next_deadline`]), and the firing itself
//! ([`Processor::advance_wall`]). The clock's data (anchors, the deadline queue) is
//! [`clock`](super::clock)'s.

use super::Processor;
use super::clock::{Anchor, Deadlines, Wall};
use super::emit::Fired;
use super::pool::Instance;
use std::time::{Duration, Instant};
use tessla_engine::OutputEvent;

impl Processor {
    /// Note instance `slot`'s last record at `ts` and queue its next `delay` firing by the wall
    /// clock. Without a `delay` in the program this is one comparison.
    #[inline]
    pub(super) fn schedule(&mut self, slot: usize, ts: i64) {
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
                    self.settle(slot, upto.saturating_sub(1), None, out);
                }
                let Some(inst) = self.pool.table.get_mut(slot) else {
                    continue;
                };
                let events = &mut self.emitter.events;
                inst.monitor
                    .advance_to(upto, &mut |e: OutputEvent<'_>| events.push(Fired::of(e)));
                let version = self.versions.get(inst.version);
                self.emitter.emit(
                    &version.encodings,
                    &inst.escaped_tags,
                    (&inst.fleet_key, &version.program),
                    &mut self.counters,
                    out,
                );
                self.tap_clock(slot);
            }
            if let Some(inst) = self.pool.table.get_mut(slot) {
                Self::queue(&mut self.deadlines, inst, slot, lateness);
            }
        }
        let now = self.pool.now(now);
        self.pool
            .evict_idle(now, &mut self.counters, self.lane.as_deref());
    }

    /// Queue every instance's next `delay` firing afresh (after its program changed).
    pub(super) fn requeue_all(&mut self) {
        self.has_delays = self.versions.has_delays() && self.opts.allowed_lateness.is_some();
        self.deadlines.clear();
        let (at, lateness) = (Wall::now().at, self.lateness());
        for (slot, inst) in self.pool.table.slots_mut() {
            inst.queued = None;
            if inst.anchor.is_none() {
                let ts = inst.monitor.clock();
                inst.anchor = Some(Anchor { ts, at });
            }
            if self.has_delays {
                Self::queue(&mut self.deadlines, inst, slot, lateness);
            }
        }
    }
}
