//! Spec versions in a running processor: replacing the base version (a reload), checking and
//! accepting a rollout's version, and switching an instance to the version its rules give it
//! at each step ([`versions`](super::versions) owns the table and the rules).

use super::emit::Fired;
use super::versions::{Rule, Selector, Unfit, Version};
use super::{Accepted, Processor, pool};
use crate::telegraf::binding::BindingError;
use std::sync::Arc;
use tessla_engine::{Monitor, OutputEvent, Program};

impl Processor {
    /// Switch instance `slot` to the version its rules give it at `upto`, stepping through
    /// every version start from its horizon on the way: before each start its old version
    /// fires the `delay`s due before it, then the instance continues in the new version
    /// (streams whose key is unchanged keep their state). Its outputs go to `out`. The horizon
    /// (not the monitor's clock, which a late record moves past its stamp) is where it stands:
    /// the record's stamp decides its version, and a restart that restores the horizon decides
    /// alike.
    ///
    /// `metric`: the record that asks (none for a `delay` firing by the wall clock): a version
    /// it does not fit is passed over for this instance from now on, which stays on the last
    /// version it can run ([`super::versions::Versions::target_fitting`]).
    pub(super) fn settle(
        &mut self,
        slot: usize,
        upto: i64,
        metric: Option<&lineproto::Metric>,
        out: &mut Vec<u8>,
    ) {
        // Most steps: the rules have not changed since the instance last settled and no start
        // of one that picks it comes before `upto` (no key lookup, no copy per record).
        let rules = self.versions.rules.len();
        match self.pool.table.get_mut(slot) {
            Some(inst) if inst.settled.0 == rules && upto < inst.settled.1 => {
                inst.horizon = inst.horizon.max(upto);
                return;
            }
            Some(_) => {}
            None => return,
        }
        let Some(key) = self.pool.table.key(slot).cloned() else {
            return;
        };
        let Some(inst) = self.pool.table.get_mut(slot) else {
            return;
        };
        let mut cursor = inst.horizon;
        // First where the instance stands (a rule may have started at or before its clock),
        // then each start after it up to `upto`; `cursor` only grows.
        let mut next = if self.versions.target_skipping(&key, cursor, &inst.unfit).0 != inst.version
        {
            Some(cursor)
        } else {
            self.versions.next_start(&key, cursor, upto)
        };
        while let Some(at) = next {
            let mut target = self.versions.target_skipping(&key, at, &inst.unfit).0;
            if target != inst.version
                && let Some(m) = metric
            {
                let (by, counters) = (&self.opts.instance_by, &mut self.counters);
                target = self.versions.target_fitting(
                    &key,
                    at,
                    (m, inst.version),
                    &mut inst.unfit,
                    |rule, why| {
                        counters.unfit += 1;
                        pool::warn_unfit(by, &key, &self.versions, rule, &why);
                    },
                );
            }
            if target != inst.version {
                // The old version's firings before the start.
                let events = &mut self.emitter.events;
                inst.monitor
                    .advance_to(at, &mut |e: OutputEvent<'_>| events.push(Fired::of(e)));
                let old = self.versions.get(inst.version);
                self.emitter.emit(
                    &old.encodings,
                    &inst.escaped_tags,
                    (&inst.fleet_key, &old.program),
                    &mut self.counters,
                    out,
                );
                let new = self.versions.get(target);
                inst.monitor = new.carry(old, &inst.monitor);
                inst.version = target;
                if let Some(tag) = &self.opts.version_tag {
                    inst.set_tag(tag, &new.id);
                }
                self.counters.switched += 1;
            }
            cursor = at;
            next = self.versions.next_start(&key, cursor, upto);
        }
        let after = self.versions.next_start(&key, cursor, i64::MAX);
        inst.settled = (rules, after.unwrap_or(i64::MAX));
        inst.horizon = inst.horizon.max(upto);
    }

    /// Run `program` from now on in place of the base version (a spec reload): `carry` turns
    /// the monitor of each instance running the base into one of the new program (no step is
    /// open between records), and every instance's next `delay` firing is queued afresh.
    /// Instances running a version of a rollout keep it.
    /// Fails (nothing changed) when the new program's input annotations are malformed.
    pub fn replace_program(
        &mut self,
        program: Arc<Program>,
        id: &str,
        mut carry: impl FnMut(&Monitor) -> Monitor,
    ) -> Result<(), BindingError> {
        let label = self.versions.base().label.clone();
        let base = Version::new(id.to_string(), label, program, &self.opts.measurement)?;
        self.end_of_read();
        for inst in self.pool.table.values_mut() {
            if inst.version == 0 {
                inst.monitor = carry(&inst.monitor);
                if let Some(tag) = &self.opts.version_tag {
                    inst.set_tag(tag, &base.id);
                }
            }
        }
        self.wiring = super::wiring::WiringCheck::new(&base.bindings);
        if let Some(slot) = self.versions.list.first_mut() {
            *slot = base;
        }
        self.capture = self.versions.list_to_capture();
        self.requeue_all();
        Ok(())
    }

    /// Check a new version against this processor: its input annotations, that the selector
    /// names `--instance-by` tags, and its bindings against `samples`, the metrics the process
    /// has seen (every thread's [`Processor::samples`]: one answer for the process, never one
    /// thread's share; an input whose field is there but never converts to its type, or no
    /// input fed at all, refuses it). `Err` says why it is refused.
    pub fn check_version(
        &self,
        id: &str,
        program: &Arc<Program>,
        selector: &Selector,
        samples: &[lineproto::Metric],
    ) -> Result<(), Refusal> {
        let unknown = selector.unknown_tags(&self.opts.instance_by);
        if !unknown.is_empty() {
            return Err(Refusal::UnknownTags {
                selector: selector.clone(),
                tags: unknown.join(", "),
                by: if self.opts.instance_by.is_empty() {
                    "is not set".to_string()
                } else {
                    self.opts.instance_by.join(",")
                },
            });
        }
        if self.versions.find(id).is_none() {
            let m = &self.opts.measurement;
            let v = Version::new(id.to_string(), String::new(), Arc::clone(program), m)
                .map_err(Refusal::Annotations)?;
            super::versions::check_against(&v, samples)?;
        }
        Ok(())
    }

    /// How many instances `selector` picks have stepped past `from`, and by how much at most
    /// (ns): a rollout starting there arrived late for them.
    pub fn instances_past(&self, from: i64, selector: &Selector) -> (u64, i64) {
        let by = &self.opts.instance_by;
        self.pool
            .table
            .iter_lru()
            .filter(|(k, i)| {
                selector.matches(by, k) && i.monitor.last_evaluated().is_some_and(|t| t > from)
            })
            .fold((0, 0), |(n, max), (_, i)| {
                let behind = i.monitor.clock().saturating_sub(from);
                (n + 1, max.max(behind))
            })
    }

    /// Put a version ([`Processor::check_version`] passed) in force for the instances
    /// `selector` picks from event time `from` on: each switches at its first step at or after
    /// it. `Err`: its input annotations are malformed; nothing changed then.
    pub fn accept_version(
        &mut self,
        id: &str,
        label: &str,
        program: Arc<Program>,
        from: i64,
        selector: Selector,
    ) -> Result<Accepted, Refusal> {
        let version = match self.versions.find(id) {
            Some(v) => v,
            None => {
                let m = &self.opts.measurement;
                let v = Version::new(id.to_string(), label.to_string(), program, m)
                    .map_err(Refusal::Annotations)?;
                self.versions.list.push(v);
                self.capture = self.versions.list_to_capture();
                self.versions.list.len() - 1
            }
        };
        let reset_outputs = self.versions.reset_for(version, from, &selector);
        if !self.versions.has_rules() {
            // Without rules no step settled a version: each instance stands at its clock.
            for inst in self.pool.table.values_mut() {
                inst.horizon = inst.horizon.max(inst.monitor.clock());
            }
        }
        self.versions.rules.push(Rule {
            version,
            from,
            selector,
        });
        self.requeue_all();
        Ok(Accepted { reset_outputs })
    }
}

/// Why this processor refuses a new version ([`Processor::check_version`],
/// [`Processor::accept_version`]).
#[derive(Debug, Clone, thiserror::Error)]
pub enum Refusal {
    /// Its selector names tags that are not `--instance-by` tags here (`by`: their list, or
    /// "is not set").
    #[error(
        "its selector `{selector}` names tag(s) {tags} that do not choose instances here (--instance-by {by})"
    )]
    UnknownTags {
        selector: Selector,
        tags: String,
        by: String,
    },
    /// Its input annotations are malformed.
    #[error("its input annotations: {0}")]
    Annotations(BindingError),
    /// It does not fit the metrics seen.
    #[error(transparent)]
    Unfit(#[from] Unfit),
}
