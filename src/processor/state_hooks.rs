//! What `--state` reads and writes of a processor: every instance's key, monitor and horizon
//! to save ([`Processor::saved_instances`]), and instances restored from saved state
//! ([`Processor::restore_instance_at`]); a monitor whose clock is beyond `--max-ahead` of the
//! wall clock is neither saved nor restored.

use super::instances::Key;
use super::pool::describe;
use super::{Processor, clock};
use crate::log;
use std::sync::Arc;
use std::time::Instant;
use tessla_engine::Monitor;

impl Processor {
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
}
