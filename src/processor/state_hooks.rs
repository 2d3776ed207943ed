//! What `--state` reads and writes of a processor: every instance's key, monitor and
//! [`Continuity`] to save ([`Processor::saved_instances`]), and instances restored from saved
//! state ([`Processor::restore_instance_at`]); a monitor whose clock is beyond `--max-ahead` of
//! the wall clock is neither saved nor restored.

use super::dedup::Recent;
use super::instance_table::Key;
use super::pool::describe;
use super::{Processor, clock};
use crate::log;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::time::Instant;
use tessla_engine::{Monitor, Program};

/// What an instance carries across a save besides its monitor, so that a restart changes
/// nothing: the version it ran (its id: a rollout committed while it was silent switches it at
/// its next record, as without the restart), the event time its version was settled for (its
/// horizon), its newest records (a message redelivered after the restart is still a repeat),
/// and the rollouts (version id and start) whose version its records did not fit. Each is
/// empty in state written before it was saved.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Continuity {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub version: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub horizon: Option<i64>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub recent: Vec<(i64, u64)>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unfit: Vec<(String, i64)>,
}

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

    /// [`Processor::monitors`] with each instance's [`Continuity`] (restored by
    /// [`Processor::restore_instance_at`]): what `--state` saves.
    pub fn saved_instances(&self) -> impl Iterator<Item = (&Key, &Monitor, Continuity)> {
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
                let c = Continuity {
                    version: Some(self.versions.get(i.version).id.clone()),
                    horizon: Some(horizon),
                    recent: i.recent.saved(),
                    unfit: i
                        .unfit
                        .iter()
                        .filter_map(|&r| self.versions.rule_id(r))
                        .collect(),
                };
                (k, &i.monitor, c)
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
        self.restore_instance_at(key, monitor, Continuity::default());
    }

    /// The rules (by index) `c` says the instance's records did not fit (those still held).
    fn unfit_rules(&self, c: &Continuity) -> Vec<usize> {
        c.unfit
            .iter()
            .filter_map(|id| self.versions.rule_of(id))
            .collect()
    }

    /// The program instance `key`, saved with `c` and a monitor whose clock is `clock`, runs
    /// when restored: the version it ran, when this process holds it; else the version the
    /// rules give at its horizon (its clock for state that did not record one), passing over
    /// the rollouts its records did not fit.
    pub fn program_for_saved(&self, key: &Key, c: &Continuity, clock: i64) -> &Arc<Program> {
        if let Some(v) = c.version.as_deref().and_then(|id| self.versions.find(id)) {
            return &self.versions.get(v).program;
        }
        let unfit = self.unfit_rules(c);
        let at = c.horizon.unwrap_or(clock);
        let v = self.versions.target_skipping(key, at, &unfit).0;
        &self.versions.get(v).program
    }

    /// [`Processor::restore_instance`] with what it was saved with ([`Continuity`]; its parts
    /// empty in state that did not record them): its version is the one the rules give at its
    /// horizon ([`Processor::program_for_saved`]), and it switches at its first step from the
    /// next start.
    pub fn restore_instance_at(&mut self, key: Key, monitor: Monitor, c: Continuity) {
        if let Some(ahead) = self.clock_ahead(&monitor) {
            log_warn!(
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
            let horizon = c.horizon.unwrap_or(ts);
            let unfit = self.unfit_rules(&c);
            let settled =
                (v == self.versions.target_skipping(&key, horizon, &unfit).0).then(|| {
                    let next = self.versions.next_start(&key, horizon, i64::MAX);
                    (self.versions.rules.len(), next.unwrap_or(i64::MAX))
                });
            let slot = self
                .pool
                .insert(key, monitor, (v, &id), now, self.lane.as_deref());
            if let Some(inst) = self.pool.table.get_mut(slot) {
                inst.horizon = horizon;
                inst.unfit = unfit;
                inst.recent = Recent::restored(&c.recent);
                if let Some(settled) = settled {
                    inst.settled = settled;
                }
            }
            self.schedule(slot, ts);
        }
    }
}
