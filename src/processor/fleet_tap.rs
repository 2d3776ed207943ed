//! What the fleet level (`--fleet-spec`, `crate::fleet`) takes from this processor's
//! instances: the events of the robot outputs the fleet spec names (by name, so every spec
//! version maps its own output indices), each instance's clock after each step (the fleet's
//! watermark is the minimum over live robots), and the instances evicted (they leave the fleet's
//! maps). Collected while records are stepped, drained by the step loop after every read and
//! every wall-clock advance, on the thread that owns the fleet level.

use std::sync::Arc;
use tessla_engine::{Program, Value};

/// One event of a robot output the fleet reads.
#[derive(Debug, Clone)]
pub struct Change {
    pub ts: i64,
    /// The robot's key (its `--instance-by` tag values, joined by `,`).
    pub key: Arc<str>,
    /// The fleet input it feeds (an index into the names the tap was made with).
    pub input: usize,
    pub value: Value,
}

/// What a processor collected since the last drain.
#[derive(Debug, Default)]
pub struct Drained {
    pub changes: Vec<Change>,
    /// Each robot's clock after a step (later entries for the same robot are later clocks).
    pub clocks: Vec<(Arc<str>, i64)>,
    /// Robots whose instance was evicted (`--instance-idle`, `--max-instances`).
    pub left: Vec<Arc<str>>,
}

/// The collector one processor keeps.
#[derive(Debug)]
pub struct Tap {
    pub(super) names: Arc<[String]>,
    /// Per spec version's program: each output's fleet input, built when first needed.
    by_program: Vec<(Arc<Program>, Vec<Option<usize>>)>,
    pub(super) got: Drained,
}

impl Tap {
    pub fn new(names: Arc<[String]>) -> Tap {
        Tap {
            names,
            by_program: Vec::new(),
            got: Drained::default(),
        }
    }

    /// Keep the events (time, output index, value) that feed the fleet, from robot `key`
    /// running `program`.
    pub(super) fn take<'v>(
        &mut self,
        events: impl Iterator<Item = (i64, usize, &'v Value)>,
        key: &Arc<str>,
        program: &Arc<Program>,
    ) {
        let i = match self
            .by_program
            .iter()
            .position(|(p, _)| Arc::ptr_eq(p, program))
        {
            Some(i) => i,
            None => {
                let map = program
                    .outputs
                    .iter()
                    .map(|o| self.names.iter().position(|n| *n == o.name))
                    .collect();
                self.by_program.push((Arc::clone(program), map));
                self.by_program.len() - 1
            }
        };
        let Some((_, map)) = self.by_program.get(i) else {
            return;
        };
        for (ts, output, value) in events {
            if let Some(Some(input)) = map.get(output) {
                self.got.changes.push(Change {
                    ts,
                    key: Arc::clone(key),
                    input: *input,
                    value: value.clone(),
                });
            }
        }
    }

    /// Robot `key` has reached `clock`.
    pub(super) fn clock(&mut self, key: &Arc<str>, clock: i64) {
        self.got.clocks.push((Arc::clone(key), clock));
    }
}

impl super::Processor {
    /// Collect what the fleet level reads: the events of the robot outputs named `outputs`,
    /// each instance's clock and its eviction. Set before the `--threads` workers are made
    /// ([`super::Processor::sibling`] copies it).
    pub fn tap_fleet(&mut self, outputs: Arc<[String]>) {
        self.emitter.tap = Some(Tap::new(outputs));
        self.pool.left = Some(Vec::new());
    }

    /// The fleet outputs' names this processor collects for, if any.
    pub fn fleet_outputs(&self) -> Option<Arc<[String]>> {
        self.emitter.tap.as_ref().map(|t| Arc::clone(&t.names))
    }

    /// What was collected since the last call (empty without [`Self::tap_fleet`]).
    pub fn fleet_drain(&mut self) -> Drained {
        let mut got = match &mut self.emitter.tap {
            Some(t) => std::mem::take(&mut t.got),
            None => return Drained::default(),
        };
        if let Some(left) = &mut self.pool.left {
            got.left.append(left);
        }
        got
    }

    /// Record instance `slot`'s clock for the fleet level (after a step).
    pub(super) fn tap_clock(&mut self, slot: usize) {
        if let (Some(t), Some(inst)) = (&mut self.emitter.tap, self.pool.table.get_mut(slot)) {
            t.clock(&inst.fleet_key, inst.monitor.clock());
        }
    }
}
