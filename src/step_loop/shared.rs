//! Stepping with a state store shared by a fleet (`--state nats://...`): each instance restored
//! from the backend before its first record here is stepped, and, with `?lease=NAME`, the
//! partition lease followed.
//!
//! Owns: while standing by (another process holds the lease), keeping the records read in a
//! replay buffer instead of stepping them; on taking the lease, replaying the buffer, skipping
//! each record an instance's restored state already covers (timestamp not after its last
//! evaluated step); on losing it, dropping every instance.

use crate::log;
use crate::processor::Processor;
use crate::processor::clock::Wall;
use crate::processor::instance_table::{self, Key};
use crate::state::Backend;
use crate::state::lease::Lease;
use crate::watchdog::Watch;
use lineproto::{Metric, Record, RecordRef, parse_record_into};
use std::collections::{HashMap, VecDeque};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Most bytes of records a standby keeps for replay; the oldest go first past it.
const MAX_BUFFER_BYTES: usize = 256 << 20;

/// The records of a shared store's run on their way to the processor.
pub(super) struct Shared {
    instance_by: Vec<String>,
    /// `None`: no lease, this process steps everything it reads.
    pub(super) lease: Option<Lease>,
    /// Stepping (holding the lease, or without one); standing by otherwise.
    pub(super) active: bool,
    /// How long a standby keeps records for replay.
    window: Duration,
    buffer: VecDeque<(Instant, Record)>,
    buffered_bytes: usize,
    scratch: Metric,
    watch: Arc<Watch>,
}

impl Shared {
    pub(super) fn new(
        instance_by: Vec<String>,
        lease: Option<Lease>,
        window: Duration,
        watch: Arc<Watch>,
    ) -> Shared {
        Shared {
            instance_by,
            active: lease.is_none(),
            lease,
            window,
            buffer: VecDeque::new(),
            buffered_bytes: 0,
            scratch: Metric::default(),
            watch,
        }
    }

    /// Records kept for replay, not stepped.
    pub(super) fn buffered(&self) -> usize {
        self.buffer.len()
    }

    /// Whether saving now is right: stepping, and (with a lease) still holding it.
    pub(super) fn may_save(&self) -> bool {
        self.active && self.lease.as_ref().is_none_or(|l| l.holding())
    }

    /// The instance key and timestamp of a record, if it parses (a buffered record before its
    /// replay: its timestamp decides whether the restored state covers it).
    fn key_and_time(&mut self, rec: RecordRef<'_>) -> Option<(Key, Option<i64>)> {
        if rec.oversized || !matches!(parse_record_into(rec.bytes, &mut self.scratch), Ok(true)) {
            return None;
        }
        Some((
            instance_table::key_of(&self.instance_by, &self.scratch),
            self.scratch.timestamp,
        ))
    }

    /// Step `rec`, or keep it for replay while standing by. A record's instance is restored
    /// from the backend before its first record here is stepped.
    pub(super) fn step(
        &mut self,
        proc: &mut Processor,
        backend: &mut dyn Backend,
        rec: RecordRef<'_>,
        out: &mut Vec<u8>,
    ) {
        if !self.active {
            self.keep(rec.to_record());
            return;
        }
        // The key from the record's series key alone, by the routine that picks a `--threads`
        // shard: the processor parses the record once, right after.
        if !rec.oversized
            && let Some(key) = instance_table::record_key(rec.bytes, &self.instance_by)
        {
            backend.arriving(&key, proc);
        }
        proc.record_ref(rec, out);
    }

    fn keep(&mut self, rec: Record) {
        let now = Instant::now();
        self.buffered_bytes += rec.bytes.len();
        self.buffer.push_back((now, rec));
        while let Some((at, r)) = self.buffer.front() {
            let old = now.saturating_duration_since(*at) > self.window;
            if !old && self.buffered_bytes <= MAX_BUFFER_BYTES {
                break;
            }
            if !old {
                log::warn_limited("replay buffer", || {
                    format!(
                        "standby: replay buffer over {} MB; dropping its oldest records",
                        MAX_BUFFER_BYTES >> 20
                    )
                });
            }
            self.buffered_bytes -= r.bytes.len();
            self.buffer.pop_front();
        }
    }

    /// Follow the lease: take over (restore, replay) or stand by (drop instances if lost).
    pub(super) fn follow_lease(
        &mut self,
        proc: &mut Processor,
        backend: &mut dyn Backend,
        out: &mut Vec<u8>,
    ) {
        let Some(lease) = &self.lease else {
            return;
        };
        let holding = lease.holding();
        let lost = lease.take_lost();
        if self.active && !holding {
            proc.end_of_read();
            self.active = false;
            log_warn!(
                "lease: not holding partition {} (renewal overdue or taken over); standing by",
                lease.name
            );
        }
        if lost {
            if let Ok(mut p) = proc.sibling() {
                p.watch_with(self.watch.lane());
                *proc = p;
            }
            backend.forget();
        }
        if holding && !self.active {
            self.active = true;
            let name = lease.name.clone();
            self.replay(proc, backend, out, &name);
        }
    }

    /// Step the buffered records the restored state does not cover yet.
    fn replay(
        &mut self,
        proc: &mut Processor,
        backend: &mut dyn Backend,
        out: &mut Vec<u8>,
        name: &str,
    ) {
        let buffer = std::mem::take(&mut self.buffer);
        self.buffered_bytes = 0;
        let mut keyed = Vec::with_capacity(buffer.len());
        for (at, rec) in buffer {
            let k = self.key_and_time(rec.view());
            if let Some((key, _)) = &k {
                backend.arriving(key, proc);
            }
            keyed.push((k, at, rec));
        }
        let covered: HashMap<Key, i64> = proc
            .monitors()
            .filter_map(|(k, m)| Some((k.clone(), m.last_evaluated()?)))
            .collect();
        let (mut stepped, mut skipped) = (0usize, 0usize);
        for (k, at, rec) in keyed {
            if let Some((key, Some(ts))) = &k
                && covered.get(key).is_some_and(|last| ts <= last)
            {
                skipped += 1;
                continue;
            }
            // Each record stepped as when it arrived: its instance's silent time counts from
            // then, as in a process that held the lease all along.
            proc.set_wall(Wall::at(at));
            proc.record(&rec, out);
            stepped += 1;
        }
        proc.end_of_read();
        log_info!(
            "lease: holding partition {name}; replayed {stepped} buffered records ({skipped} already covered by the saved state)"
        );
    }
}
