//! The fleet level's state and its event-time rule (docs/fleet.md, "Event time").
//!
//! Owns: the map per fleet input (robot key → latest value), the changes waiting for the
//! watermark, each live robot's clock, and stepping the fleet monitor. The rule: the fleet steps
//! time T once T is before the watermark W = max(min over live robots' clocks, newest clock −
//! silence); a robot whose clock stays more than the silence behind W leaves every map at its
//! clock + silence; an evicted robot leaves at the fleet's next step; a change at or before the
//! fleet's last step (late) is stepped 1 ns after it. At the end of the input everything pending
//! is stepped. Also owns switching the fleet program to a committed fleet rollout's version
//! ([`Level::switch_to`]) at its first step at or after the version's start.

use super::actions::Actions;
use crate::log;
use crate::processor::fleet_tap::Drained;
use crate::telegraf::encode::{self, Prepared, StepEvent};
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::Arc;
use tessla_engine::collections;
use tessla_engine::snapshot::SValue;
use tessla_engine::{Monitor, OutputEvent, Program, Value};

/// One pending change of a fleet map.
#[derive(Debug, Clone)]
struct Pend {
    key: Arc<str>,
    /// `None`: the robot leaves every map.
    set: Option<(usize, Value)>,
}

/// One fleet output event, kept until its step is written.
struct Ev {
    output: usize,
    value: Value,
}

impl StepEvent for Ev {
    fn output(&self) -> usize {
        self.output
    }
    fn value(&self) -> &Value {
        &self.value
    }
}

/// Counters of the fleet level (the summary's `fleet` part).
#[derive(Debug, Default, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct FleetCounters {
    pub steps: u64,
    pub changes: u64,
    /// Changes that came at or before the fleet's last step (stepped 1 ns after it).
    pub late: u64,
    /// Robots that left the maps: silent past the bound, or evicted.
    pub left: u64,
    pub outputs: u64,
    /// Switches to a committed fleet rollout's version.
    pub switches: u64,
}

/// A fleet spec version waiting for its step.
struct Switch {
    /// The first step at or after this runs the version.
    at: i64,
    revision: u64,
    id: String,
    from: i64,
    program: Arc<Program>,
    /// Whether the level had stepped past `from` when the switch was decided here.
    late: bool,
}

pub struct Level {
    program: Arc<Program>,
    /// Started at the fleet's first step.
    monitor: Option<Monitor>,
    /// Per fleet input (by index into the names the taps use): its input number in the program
    /// (`None`: the program running now does not read it).
    inputs: Vec<Option<usize>>,
    /// The robot outputs the taps collect (the fleet spec at start-up's inputs).
    names: Vec<String>,
    /// `--instance-by` (for the actions of a new version).
    by: Vec<String>,
    /// `--version-tag`: the tag set to the running fleet spec's version.
    version_tag: Option<String>,
    /// Fleet spec versions to switch to, by start.
    switches: Vec<Switch>,
    maps: Vec<Value>,
    pending: BTreeMap<i64, Vec<Pend>>,
    clocks: HashMap<Arc<str>, i64>,
    order: BTreeSet<(i64, Arc<str>)>,
    /// The newest clock of any robot.
    front: i64,
    /// The fleet has stepped every time up to here.
    done: i64,
    silence: i64,
    /// The fleet across NATS partitions: the minimum of the live partitions' promises (no time
    /// at or after it is stepped yet; `i64::MAX` in one process, [`super::watermark`]).
    bound: i64,
    prepared: Prepared,
    scratch: encode::Scratch,
    actions: Actions,
    tags: Vec<(String, String)>,
    events: Vec<(i64, Ev)>,
    pub counters: FleetCounters,
}

/// Why a fleet level cannot be built from a checked fleet spec.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LevelError {
    /// A robot output the level reads has no input of that name.
    #[error("fleet spec: no input `{0}`")]
    NoInput(String),
    /// A `@FleetAction` lacks its arguments.
    #[error(transparent)]
    Action(#[from] super::actions::ActionError),
}

impl Level {
    /// A level running `program` (checked by [`super::check`]) whose inputs read the robot
    /// outputs `names`; `silence` in ns; `tags`: the static `--tag`s; `by`: `--instance-by`.
    pub fn new(
        program: Arc<Program>,
        names: &[String],
        silence: i64,
        tags: Vec<(String, String)>,
        by: Vec<String>,
    ) -> Result<Level, LevelError> {
        let inputs = names
            .iter()
            .map(|n| {
                program
                    .inputs
                    .iter()
                    .position(|i| &i.name == n)
                    .map(Some)
                    .ok_or_else(|| LevelError::NoInput(n.clone()))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let actions = Actions::new(&program, by.clone(), tags.clone())?;
        Ok(Level {
            prepared: Prepared::new(encode::encodings(&program), super::MEASUREMENT),
            monitor: None,
            maps: inputs.iter().map(|_| collections::empty_map()).collect(),
            inputs,
            names: names.to_vec(),
            by,
            version_tag: None,
            switches: Vec::new(),
            pending: BTreeMap::new(),
            clocks: HashMap::new(),
            order: BTreeSet::new(),
            front: i64::MIN,
            done: i64::MIN,
            silence: silence.max(0),
            bound: i64::MAX,
            scratch: encode::Scratch::default(),
            actions,
            tags,
            events: Vec::new(),
            counters: FleetCounters::default(),
            program,
        })
    }

    /// `--version-tag TAG`: a switch to a new fleet spec version sets TAG to its id.
    pub fn set_version_tag(&mut self, tag: Option<String>) {
        self.version_tag = tag;
    }

    /// A fleet rollout is pending or has switched the program (a checkpoint, which holds the
    /// start-up fleet spec's monitor, is not written then).
    pub fn has_switch(&self) -> bool {
        !self.switches.is_empty() || self.counters.switches > 0
    }

    /// The robot outputs the taps collect for this level (a new version may read only these).
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The fleet inputs the running version reads whose robot output committed robot rollout
    /// `c`'s version lacks: the robots it picks stop feeding them (each map keeps their last
    /// value until they leave; docs/fleet.md).
    pub fn unfed(&self, c: &crate::spec_feed::RobotCommit) -> Vec<String> {
        self.program
            .inputs
            .iter()
            .map(|i| &i.name)
            .filter(|n| self.names.contains(*n) && !c.outputs.contains(*n))
            .cloned()
            .collect()
    }

    /// The `tessla_fleet_status` line saying fleet input `input` is left without its robot
    /// output by robot rollout `c`, stamped `ts` (the wall clock), tagged as the fleet's lines.
    pub fn unfed_line(
        &self,
        c: &crate::spec_feed::RobotCommit,
        input: &str,
        ts: i64,
        out: &mut Vec<u8>,
    ) {
        let mut line = super::watermark::status_head(&self.tags, None);
        let quoted = |s: &str| s.replace('\\', "\\\\").replace('"', "\\\"");
        line.push_str(&format!(
            " event=\"input_unfed\",input=\"{}\",version=\"{}\",revision={}i",
            quoted(input),
            quoted(&c.id),
            c.revision
        ));
        if !c.select.is_empty() {
            line.push_str(&format!(",select=\"{}\"", quoted(&c.select)));
        }
        line.push_str(&format!(" {ts}\n"));
        out.extend_from_slice(line.as_bytes());
    }

    /// A committed fleet rollout: run its version from the first fleet step at or after
    /// max(its start, the step after the last one stepped): the one rule for a decision seen
    /// after the level has passed its start (it switches at its next step, and the switch's
    /// status line says `late=true`). Its inputs must be among [`Self::names`] (the check
    /// refuses others).
    pub fn switch_to(&mut self, c: &crate::spec_feed::FleetCommit) {
        let Some(version) = &c.version else {
            return;
        };
        let late = c.from <= self.done;
        let at = c.from.max(self.done.saturating_add(1));
        if late {
            log_warn!(
                "fleet: fleet rollout {} (version {}) starts at {}, but the fleet level had stepped up to {}: it switches at its next step",
                c.revision,
                c.id,
                c.from,
                self.done
            );
        }
        let pos = self.switches.partition_point(|s| s.at <= at);
        self.switches.insert(
            pos,
            Switch {
                at,
                revision: c.revision,
                id: c.id.clone(),
                from: c.from,
                program: Arc::clone(&version.program),
                late,
            },
        );
    }

    /// Switch to the versions due at step `t` (the last one wins); `true` when one did. The
    /// maps stay (robot data); the monitor starts afresh at `t`.
    fn switch_due(&mut self, t: i64, out: &mut Vec<u8>) -> bool {
        let n = self.switches.partition_point(|s| s.at <= t);
        if n == 0 {
            return false;
        }
        let due: Vec<Switch> = self.switches.drain(..n).collect();
        let mut switched = false;
        for sw in due {
            let inputs: Vec<Option<usize>> = self
                .names
                .iter()
                .map(|n| sw.program.inputs.iter().position(|i| &i.name == n))
                .collect();
            let tags = super::version_tags(&self.tags, self.version_tag.as_deref(), &sw.id);
            let mut actions = match Actions::new(&sw.program, self.by.clone(), tags.clone()) {
                Ok(a) => a,
                Err(e) => {
                    log::warn_limited("fleet switch", || {
                        format!(
                            "fleet: version {} cannot run here: {e}; the fleet level stays on the version it runs",
                            sw.id
                        )
                    });
                    continue;
                }
            };
            self.prepared = Prepared::new(encode::encodings(&sw.program), super::MEASUREMENT);
            actions.carry_seq(&self.actions);
            self.actions = actions;
            self.inputs = inputs;
            self.tags = tags;
            self.program = sw.program;
            self.monitor = None;
            self.counters.switches += 1;
            log_info!(
                "fleet: the fleet level runs version {} (fleet rollout {}) from its step at {t}",
                sw.id,
                sw.revision
            );
            // Where the switch took effect, in event time: the same line in every process.
            let mut line = super::watermark::status_head(&self.tags, None);
            line.push_str(&format!(
                " event=\"switched\",version=\"{}\",revision={}i,from={}i,late={} {t}\n",
                sw.id, sw.revision, sw.from, sw.late
            ));
            out.extend_from_slice(line.as_bytes());
            switched = true;
        }
        switched
    }

    /// Take in what the processors collected, then step every time the watermark has passed
    /// (`end`: the input ended, step everything pending); outputs appended to `out`.
    pub fn pump(&mut self, drained: Vec<Drained>, end: bool, out: &mut Vec<u8>) {
        for d in drained {
            self.absorb(d);
        }
        let w = self.watermark();
        self.expire(w);
        let upto = if end { i64::MAX } else { w };
        while let Some(entry) = self.pending.first_entry() {
            if *entry.key() >= upto {
                break;
            }
            let (t, pends) = entry.remove_entry();
            self.step(t, pends, out);
        }
        // The fleet's own delays fire up to the watermark (the running version's only up to
        // the next switch).
        let w = self.switches.first().map_or(w, |s| w.min(s.at));
        if !end
            && w > self.done.saturating_add(1)
            && let Some(monitor) = &mut self.monitor
        {
            let events = &mut self.events;
            monitor.advance_to(w, &mut |e: OutputEvent<'_>| {
                events.push((
                    e.ts,
                    Ev {
                        output: e.output,
                        value: e.value.clone(),
                    },
                ))
            });
            self.write(out);
            self.done = self.done.max(w - 1);
        }
    }

    /// Hold the watermark below `bound` (the partitions' promises; `i64::MAX`: no bound).
    pub fn set_bound(&mut self, bound: i64) {
        self.bound = bound;
    }

    /// The robots in the fleet now (live clocks).
    pub fn robots(&self) -> usize {
        self.clocks.len()
    }

    fn absorb(&mut self, d: Drained) {
        for c in d.changes {
            self.counters.changes += 1;
            let t = if c.ts <= self.done {
                self.counters.late += 1;
                self.done.saturating_add(1)
            } else {
                c.ts
            };
            self.pending.entry(t).or_default().push(Pend {
                key: c.key,
                set: Some((c.input, c.value)),
            });
        }
        for (key, clock) in d.clocks {
            self.front = self.front.max(clock);
            match self.clocks.get_mut(&key) {
                Some(c) if *c == clock => {}
                Some(c) => {
                    self.order.remove(&(*c, Arc::clone(&key)));
                    *c = clock;
                    self.order.insert((clock, key));
                }
                None => {
                    self.clocks.insert(Arc::clone(&key), clock);
                    self.order.insert((clock, key));
                }
            }
        }
        for key in d.left {
            if let Some(c) = self.clocks.remove(&key) {
                self.order.remove(&(c, Arc::clone(&key)));
                let t = c.saturating_add(1).max(self.done.saturating_add(1));
                self.pending
                    .entry(t)
                    .or_default()
                    .push(Pend { key, set: None });
            }
        }
    }

    /// Times before this are final: every live robot has passed them, or the robots that have
    /// not are silent (more than the silence behind the newest).
    fn watermark(&self) -> i64 {
        let Some((min, _)) = self.order.first() else {
            return self.front.min(self.bound);
        };
        (*min)
            .max(self.front.saturating_sub(self.silence))
            .min(self.bound)
    }

    /// Robots silent past the bound before `w` leave the maps at their clock + silence.
    fn expire(&mut self, w: i64) {
        while let Some((c, _)) = self.order.first() {
            let leave = c.saturating_add(self.silence);
            if leave >= w {
                break;
            }
            let Some((_, key)) = self.order.pop_first() else {
                break;
            };
            self.clocks.remove(&key);
            let t = leave.max(self.done.saturating_add(1));
            self.pending
                .entry(t)
                .or_default()
                .push(Pend { key, set: None });
        }
    }

    /// Apply the changes at `t` (leavings first, then values, each in key order) and step the
    /// fleet monitor with the maps that changed.
    fn step(&mut self, t: i64, mut pends: Vec<Pend>, out: &mut Vec<u8>) {
        pends.sort_by(|a, b| {
            (a.set.is_some(), &a.key, a.set.as_ref().map(|s| s.0)).cmp(&(
                b.set.is_some(),
                &b.key,
                b.set.as_ref().map(|s| s.0),
            ))
        });
        let mut changed = vec![false; self.maps.len()];
        for p in pends {
            let key = Value::Str(Arc::clone(&p.key));
            match p.set {
                None => {
                    let mut gone = false;
                    for (i, m) in self.maps.iter_mut().enumerate() {
                        if let Value::Bool(true) =
                            collections::map_contains(&[m.clone(), key.clone()])
                        {
                            *m = collections::map_remove(&[m.clone(), key.clone()]);
                            if let Some(c) = changed.get_mut(i) {
                                *c = true;
                            }
                            gone = true;
                        }
                    }
                    if gone {
                        self.counters.left += 1;
                    }
                }
                Some((i, v)) => {
                    let Some(m) = self.maps.get_mut(i) else {
                        continue;
                    };
                    let old = collections::map_get_or_else(&[m.clone(), key.clone(), Value::Unit]);
                    let had = matches!(
                        collections::map_contains(&[m.clone(), key.clone()]),
                        Value::Bool(true)
                    );
                    if had && old == v {
                        continue;
                    }
                    *m = collections::map_add(&[m.clone(), key, v]);
                    if let Some(c) = changed.get_mut(i) {
                        *c = true;
                    }
                }
            }
        }
        if self.switch_due(t, out) {
            // The new version's first input: every map it reads.
            for (c, i) in changed.iter_mut().zip(&self.inputs) {
                *c = *c || i.is_some();
            }
        }
        if !changed.iter().any(|&c| c) {
            self.done = self.done.max(t);
            return;
        }
        let events = &mut self.events;
        let mut sink = |e: OutputEvent<'_>| {
            events.push((
                e.ts,
                Ev {
                    output: e.output,
                    value: e.value.clone(),
                },
            ))
        };
        let program = &self.program;
        let monitor = self
            .monitor
            .get_or_insert_with(|| Monitor::starting_at(Arc::clone(program), t));
        for (i, c) in changed.iter().enumerate() {
            if !c {
                continue;
            }
            let (Some(&Some(input)), Some(m)) = (self.inputs.get(i), self.maps.get(i)) else {
                continue;
            };
            if let Err(e) = monitor.push(t, input, m.clone(), &mut sink) {
                log::warn_limited("fleet step", || {
                    format!("fleet level: the step at {t} refused a map: {e:?}")
                });
            }
        }
        monitor.flush(&mut sink);
        self.counters.steps += 1;
        self.done = self.done.max(t);
        self.write(out);
    }

    /// Write the collected output events, one group per timestamp; coordinated actions as one
    /// `action` metric per addressed robot.
    fn write(&mut self, out: &mut Vec<u8>) {
        if self.events.is_empty() {
            return;
        }
        let events = std::mem::take(&mut self.events);
        let mut rest = &events[..];
        let mut plain: Vec<Ev> = Vec::new();
        while let Some((ts, _)) = rest.first() {
            let ts = *ts;
            let n = rest.iter().take_while(|e| e.0 == ts).count();
            let (step, tail) = rest.split_at(n);
            rest = tail;
            plain.clear();
            for (_, e) in step {
                self.counters.outputs += 1;
                if self.actions.is_action(e.output) {
                    self.actions.write(ts, e.output, &e.value, out);
                } else {
                    plain.push(Ev {
                        output: e.output,
                        value: e.value.clone(),
                    });
                }
            }
            if !plain.is_empty() {
                let dropped = encode::encode_prepared(
                    &mut self.scratch,
                    &self.prepared,
                    ts,
                    &plain,
                    &self.tags,
                    out,
                );
                for d in dropped {
                    log::warn_limited("fleet output value", || {
                        format!(
                            "fleet output `{}` at {ts}: {}; field dropped",
                            d.output, d.reason
                        )
                    });
                }
            }
        }
    }
}

/// A pending change in a checkpoint: (time, robot key, `None`: leaves, or (fleet input,
/// value)).
type PendState = (i64, String, Option<(usize, SValue)>);

/// The fleet level's state between two inputs (a fleet checkpoint across NATS partitions,
/// `super::nats`): its monitor, maps, pending changes, robot clocks and action counts.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct LevelState {
    monitor: Option<tessla_engine::snapshot::Snapshot>,
    maps: Vec<SValue>,
    pending: Vec<PendState>,
    clocks: Vec<(String, i64)>,
    front: i64,
    done: i64,
    actions: Vec<(String, i64)>,
    counters: FleetCounters,
}

/// A copy of the fleet level's state taken on the step loop ([`Level::copy`]): the maps and
/// the monitor's values are shared (`Arc`), so it costs a clone of the robot clocks and action
/// counts; turning it into a [`LevelState`] (the snapshot, the conversion of every value) runs
/// off the step loop.
#[derive(Clone)]
pub struct LevelCopy {
    monitor: Option<Monitor>,
    maps: Vec<Value>,
    pending: BTreeMap<i64, Vec<Pend>>,
    clocks: HashMap<Arc<str>, i64>,
    front: i64,
    done: i64,
    actions: HashMap<Arc<str>, i64>,
    counters: FleetCounters,
}

impl LevelState {
    /// The robots in the fleet then (live clocks).
    pub fn robots(&self) -> usize {
        self.clocks.len()
    }
}

impl LevelCopy {
    /// The state to checkpoint; `None` when a value cannot be saved (a function value).
    pub fn state(&self) -> Option<LevelState> {
        let monitor = self.monitor.as_ref().map(tessla_engine::snapshot::snapshot);
        if monitor.as_ref().is_some_and(|m| m.unsaved > 0) {
            return None;
        }
        let maps = self
            .maps
            .iter()
            .map(SValue::from_value)
            .collect::<Option<Vec<_>>>()?;
        let mut pending = Vec::new();
        for (t, ps) in &self.pending {
            for p in ps {
                let set = match &p.set {
                    None => None,
                    Some((i, v)) => Some((*i, SValue::from_value(v)?)),
                };
                pending.push((*t, p.key.to_string(), set));
            }
        }
        let mut clocks: Vec<(String, i64)> = self
            .clocks
            .iter()
            .map(|(k, c)| (k.to_string(), *c))
            .collect();
        clocks.sort();
        let mut actions: Vec<(String, i64)> = self
            .actions
            .iter()
            .map(|(k, n)| (k.to_string(), *n))
            .collect();
        actions.sort();
        Some(LevelState {
            monitor,
            maps,
            pending,
            clocks,
            front: self.front,
            done: self.done,
            actions,
            counters: self.counters.clone(),
        })
    }
}

impl Level {
    /// The state to checkpoint; `None` when a value cannot be saved (a function value).
    pub fn state(&self) -> Option<LevelState> {
        self.copy()?.state()
    }

    /// What [`LevelCopy::state`] turns into the state to checkpoint, taken cheaply (values are
    /// shared, not converted); `None` when the level is not checkpointed now (a fleet rollout
    /// pending or switched, or outputs of a step not written yet).
    pub fn copy(&self) -> Option<LevelCopy> {
        // A checkpoint holds the start-up fleet spec's monitor: once a fleet rollout is
        // pending or has switched the program, the level is not checkpointed (its entries
        // stay, a later process replays them and meets the switch entry where the holder did).
        if !self.events.is_empty() || self.has_switch() {
            return None;
        }
        Some(LevelCopy {
            monitor: self.monitor.clone(),
            maps: self.maps.clone(),
            pending: self.pending.clone(),
            clocks: self.clocks.clone(),
            front: self.front,
            done: self.done,
            actions: self.actions.seq().clone(),
            counters: self.counters.clone(),
        })
    }

    /// Continue from `state` (a level made by [`Level::new`] for the same fleet spec).
    pub fn restore(&mut self, state: LevelState) {
        self.monitor = state
            .monitor
            .map(|snap| tessla_engine::snapshot::restore(Arc::clone(&self.program), &snap));
        if state.maps.len() == self.maps.len() {
            self.maps = state.maps.iter().map(SValue::to_value).collect();
        }
        self.pending.clear();
        for (t, key, set) in state.pending {
            self.pending.entry(t).or_default().push(Pend {
                key: Arc::from(key),
                set: set.map(|(i, v)| (i, v.to_value())),
            });
        }
        self.clocks.clear();
        self.order.clear();
        for (key, c) in state.clocks {
            let key: Arc<str> = Arc::from(key);
            self.clocks.insert(Arc::clone(&key), c);
            self.order.insert((c, key));
        }
        self.front = state.front;
        self.done = state.done;
        self.actions.set_counts(state.actions);
        self.counters = state.counters;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::processor::fleet_tap::Change;
    use crate::spec_feed::{FleetCommit, FleetVersion};

    fn program(text: &str) -> Arc<Program> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fleet.tessla");
        std::fs::write(&path, text).unwrap();
        tessla_engine::load_file(&path, &Default::default())
            .unwrap()
            .program
    }

    /// Robot `key`'s output `c` = `v` at `ts`, its clock there.
    fn change(key: &str, ts: i64, v: i64) -> Drained {
        let key: Arc<str> = Arc::from(key);
        Drained {
            changes: vec![Change {
                ts,
                key: Arc::clone(&key),
                input: 0,
                value: Value::Int(v),
            }],
            clocks: vec![(key, ts)],
            left: Vec::new(),
        }
    }

    fn commit(revision: u64, from: i64, p: &Arc<Program>) -> FleetCommit {
        FleetCommit {
            revision,
            id: format!("new{revision}"),
            from,
            version: Some(FleetVersion {
                program: Arc::clone(p),
                names: vec!["c".into()],
            }),
        }
    }

    /// A robot version without an output the running fleet spec reads leaves that input unfed:
    /// named (with the robot version and the robots it picks) in one status line each.
    #[test]
    fn a_robot_version_without_a_fleet_input_s_output_leaves_it_unfed() {
        let v1 = program(
            "in c: Events[Map[String, Int]]\nin y: Events[Map[String, Int]]\nout Map.size(c) + Map.size(y) as n\n",
        );
        let level = Level::new(
            v1,
            &["c".to_string(), "y".to_string()],
            1_000_000_000,
            vec![("v".into(), "f1".into())],
            vec!["robot".into()],
        )
        .unwrap();
        let robot = |outputs: &[&str], select: &str| crate::spec_feed::RobotCommit {
            revision: 4,
            id: "abc".into(),
            select: select.into(),
            outputs: outputs.iter().map(|o| o.to_string()).collect(),
        };
        assert!(level.unfed(&robot(&["c", "y", "z"], "")).is_empty());
        let c = robot(&["c", "z"], "robot=r1,r2");
        assert_eq!(level.unfed(&c), ["y"]);
        let mut out = Vec::new();
        level.unfed_line(&c, "y", 7, &mut out);
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "tessla_fleet_status,v=f1 event=\"input_unfed\",input=\"y\",version=\"abc\",revision=4i,select=\"robot=r1,r2\" 7\n"
        );
        assert_eq!(level.unfed(&robot(&[], "")), ["c", "y"]);
    }

    /// A switch known before its start runs at the first step at or after it; one decided
    /// after the level passed its start runs at the next step, `late=true`; the maps stay.
    #[test]
    fn a_fleet_version_switches_at_its_first_step_at_or_after_its_start() {
        let v1 = program("in c: Events[Map[String, Int]]\nout Map.size(c) as n\n");
        let v2 = program("in c: Events[Map[String, Int]]\nout Map.size(c) + 100 as n\n");
        let mut level = Level::new(
            v1,
            &["c".to_string()],
            1_000_000_000,
            vec![("v".into(), "old".into())],
            vec!["robot".into()],
        )
        .unwrap();
        level.set_version_tag(Some("v".into()));
        let mut out = Vec::new();
        level.pump(vec![change("r1", 10, 1)], false, &mut out);
        let mut second = change("r2", 20, 1);
        second.clocks.push((Arc::from("r1"), 20));
        level.pump(vec![second], false, &mut out);
        assert_eq!(
            String::from_utf8_lossy(&out),
            "tessla_fleet,v=old n=1i 10\n"
        );
        // Stepped 10, and the level's delays up to 19 (r2's clock passed them): switches
        // decided now with an earlier start are late, and run at the next step (20), in
        // revision order (the last wins); one starting at 25 runs at the first step after it.
        level.switch_to(&commit(1, 15, &v2));
        level.switch_to(&commit(2, 5, &v2));
        level.switch_to(&commit(3, 25, &v2));
        level.pump(vec![change("r1", 30, 2)], true, &mut out);
        let text = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines,
            [
                "tessla_fleet,v=old n=1i 10",
                "tessla_fleet_status,v=new1 event=\"switched\",version=\"new1\",revision=1i,from=15i,late=true 20",
                "tessla_fleet_status,v=new2 event=\"switched\",version=\"new2\",revision=2i,from=5i,late=true 20",
                "tessla_fleet,v=new2 n=102i 20",
                "tessla_fleet_status,v=new3 event=\"switched\",version=\"new3\",revision=3i,from=25i,late=false 30",
                // The maps stayed: r1 and r2 both in.
                "tessla_fleet,v=new3 n=102i 30",
            ],
            "{text}"
        );
    }

    /// The copy a checkpoint takes on the step loop is the level at that moment: the level
    /// stepping on afterwards (new robots, new map values) changes nothing in the state made
    /// from it off the step loop, which equals the state the level had when it was taken.
    #[test]
    fn a_copy_taken_for_a_checkpoint_keeps_the_level_as_it_was() {
        let p = program("in c: Events[Map[String, Int]]\nout Map.size(c) as n\n");
        let mut level = Level::new(
            p,
            &["c".to_string()],
            1_000_000_000,
            Vec::new(),
            vec!["robot".into()],
        )
        .unwrap();
        let mut out = Vec::new();
        level.pump(vec![change("r1", 10, 1)], false, &mut out);
        let mut second = change("r2", 20, 1);
        second.clocks.push((Arc::from("r1"), 20));
        level.pump(vec![second], false, &mut out);
        let then = serde_json::to_string(&level.state().unwrap()).unwrap();
        let copy = level.copy().unwrap();
        let mut third = change("r3", 30, 7);
        third
            .clocks
            .extend([(Arc::from("r1"), 30), (Arc::from("r2"), 30)]);
        level.pump(vec![third, change("r1", 40, 5)], false, &mut out);
        let now = serde_json::to_string(&level.state().unwrap()).unwrap();
        assert_ne!(now, then, "the level stepped on");
        assert_eq!(serde_json::to_string(&copy.state().unwrap()).unwrap(), then);
    }
}
