//! Where new spec versions come from while a run goes on, and what each process says about
//! them: the fleet's spec channel (a NATS key-value bucket of signed rollouts, [`nats`]), the
//! watched spec file of one process ([`watch`]), and the bundle a version travels as
//! ([`bundle`]).
//!
//! Owns the rollout record every channel carries ([`Rollout`]: which version, from which event
//! time, for which instances), the outcome a process reports for each ([`Outcome`]), and the
//! [`Updates`] the step loop calls. Checking a version and switching instances to it is the
//! processor's (`processor::versions`).

pub mod bundle;
pub mod nats;
pub mod reload;
pub mod sign;
pub mod status;
pub mod watch;

use crate::log::{self, Level};
use crate::processor::Processor;
use crate::processor::versions::Selector;
use bundle::Bundle;
use reload::{Reloaded, SpecSource};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

/// One publish: version `id` (a [`bundle::Bundle::id`]) in force from event time `from` for the
/// instances `selector` picks. A channel's rollouts are append-only, in publish order
/// (`revision` increasing): a rollback is a rollout of the earlier version.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Rollout {
    /// The channel's sequence number of this rollout (increasing).
    pub revision: u64,
    /// The version: its bundle's short id.
    pub id: String,
    /// The bundle's full SHA-256 ([`bundle::Bundle::digest`]); a bundle that does not hash to
    /// it is refused.
    pub digest: String,
    /// The operator's label (`--label`), shown beside the id.
    #[serde(default)]
    pub label: String,
    /// Event time (ns since the Unix epoch) from which it is in force: every instance it picks
    /// switches at its first step at or after it.
    pub from: i64,
    /// The instances it is for (empty: every one).
    #[serde(default)]
    pub selector: Selector,
    /// When it was published (ns since the Unix epoch, the publisher's wall clock).
    #[serde(default)]
    pub published: i64,
}

/// What one process made of one version.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Outcome {
    /// The rollout's revision (0 for a local reload: SIGHUP or a watched file).
    pub revision: u64,
    pub id: String,
    pub label: String,
    pub accepted: bool,
    /// Why it was refused (the first lines of the diagnostic), or empty.
    #[serde(default)]
    pub reason: String,
    /// Outputs whose streams start afresh in the instances that switch.
    #[serde(default)]
    pub reset_outputs: Vec<String>,
    /// Instances it picks that had already stepped past its start when it arrived: they switch
    /// at their next step, so their records since the start were judged by the version before.
    #[serde(default)]
    pub late_instances: u64,
}

/// A rollout as a channel delivers it: verified with its bundle, or why it cannot be used (an
/// unsigned or foreign rollout, a bundle that does not match its digest).
#[derive(Debug, Clone)]
pub struct Arrival {
    pub rollout: Rollout,
    pub bundle: Result<Bundle, String>,
}

/// A fleet's spec channel, as the run sees it.
pub trait Channel {
    /// Rollouts that arrived since the last call, in revision order; never blocks.
    fn poll(&mut self) -> Vec<Arrival>;
    /// Record this process's outcomes where the operator's `spec status` reads them (best
    /// effort).
    fn report(&mut self, host: &str, partition: &str, outcomes: &[Outcome]);
}

/// The id a rollout gives for "the spec each process started with" (`spec rollback` to it).
pub const BASE: &str = "base";

/// New spec versions while the run goes on: SIGHUP and a watched spec file reload the spec the
/// process started with; a channel's rollouts put versions in force from an event time. Every
/// outcome is logged and written as a status metric ([`status`]).
pub struct Updates {
    pub source: SpecSource,
    watch: Option<watch::Watched>,
    channel: Option<Box<dyn Channel>>,
    /// Where the status metrics say they come from.
    host: String,
    partition: String,
    /// Every outcome so far (the channel's status key holds them all).
    outcomes: Vec<Outcome>,
    /// Versions compiled from rollouts, by id (a rollout of a version already held reuses it).
    compiled: HashMap<String, Arc<tessla_engine::Program>>,
    /// The rollouts the channel held at connect, not applied yet.
    first: Vec<Arrival>,
}

impl Updates {
    /// `watch`: look at the spec file every second. `partition`: the lease name (empty: none).
    pub fn new(source: SpecSource, watch: bool, partition: &str) -> Updates {
        let watch = if watch {
            source.path.as_deref().map(watch::Watched::new)
        } else {
            None
        };
        Updates {
            source,
            watch,
            channel: None,
            host: crate::state::nats_conn::hostname(),
            partition: partition.to_string(),
            outcomes: Vec::new(),
            compiled: HashMap::new(),
            first: Vec::new(),
        }
    }

    /// Follow `channel` too; `first`: the rollouts it already held, applied by the first
    /// [`Updates::tick`] (the step loop's, before anything is restored or read).
    pub fn with_channel(&mut self, channel: Box<dyn Channel>, first: Vec<Arrival>) {
        self.channel = Some(channel);
        self.first = first;
    }

    /// How often the step loop calls [`Updates::tick`] (`None`: never).
    pub fn interval(&self) -> Option<Duration> {
        match (&self.channel, &self.watch) {
            (Some(_), _) => Some(Duration::from_millis(100)),
            (None, Some(_)) => Some(watch::INTERVAL),
            (None, None) => None,
        }
    }

    /// SIGHUP: reload the spec file into every processor of the run.
    pub fn hangup(&mut self, procs: &mut [&mut Processor], out: &mut Vec<u8>) {
        if let Some(w) = self.watch.as_mut() {
            // What is read now is what the next look compares with.
            w.changed();
        }
        self.reload("SIGHUP", procs, out);
    }

    /// Look for changes: the watched file, the channel's new rollouts.
    pub fn tick(&mut self, procs: &mut [&mut Processor], out: &mut Vec<u8>) {
        if self.watch.as_mut().is_some_and(watch::Watched::changed) {
            self.reload("spec file changed", procs, out);
        }
        let mut arrivals = std::mem::take(&mut self.first);
        match self.channel.as_mut() {
            Some(c) => arrivals.extend(c.poll()),
            None => return,
        }
        if arrivals.is_empty() {
            return;
        }
        for a in arrivals {
            let outcome = self.apply(&a, procs);
            self.outcome(outcome, a.rollout.from, out);
        }
        if let Some(c) = self.channel.as_mut() {
            c.report(&self.host, &self.partition, &self.outcomes);
        }
    }

    fn reload(&mut self, why: &str, procs: &mut [&mut Processor], out: &mut Vec<u8>) {
        let (id, label) = procs
            .first()
            .map(|p| {
                (
                    p.versions().base().id.clone(),
                    p.versions().base().label.clone(),
                )
            })
            .unwrap_or_default();
        let outcome = match reload::reload(&self.source, why, procs) {
            Reloaded::Refused(reason) => Outcome {
                revision: 0,
                id,
                label,
                accepted: false,
                reason: first_lines(&reason),
                ..Outcome::default()
            },
            Reloaded::Replaced {
                id, reset_outputs, ..
            } => Outcome {
                revision: 0,
                id,
                label,
                accepted: true,
                reset_outputs,
                ..Outcome::default()
            },
        };
        self.outcome(outcome, status::now_ns(), out);
    }

    /// Check one rollout and put it in force in every processor (all or none).
    fn apply(&mut self, a: &Arrival, procs: &mut [&mut Processor]) -> Outcome {
        let r = &a.rollout;
        let refused = |reason: String| Outcome {
            revision: r.revision,
            id: r.id.clone(),
            label: r.label.clone(),
            accepted: false,
            reason,
            ..Outcome::default()
        };
        let program = match self.program_of(a, procs) {
            Ok(p) => p,
            Err(e) => return refused(e),
        };
        // "The spec each process started with" is the base version (index 0), whatever its id.
        let id = match procs.first() {
            Some(p) if r.id == BASE => p.versions().base().id.clone(),
            _ => r.id.clone(),
        };
        // Every thread's processor checks first (each has seen other metrics): all accept or
        // none does.
        for p in procs.iter() {
            if let Err(e) = p.check_version(&id, &program, &r.selector) {
                return refused(e);
            }
        }
        let mut reset = Vec::new();
        let (mut late, mut behind) = (0u64, 0i64);
        for p in procs.iter() {
            let (n, by) = p.instances_past(r.from, &r.selector);
            late += n;
            behind = behind.max(by);
        }
        for (i, p) in procs.iter_mut().enumerate() {
            match p.accept_version(
                &id,
                &r.label,
                Arc::clone(&program),
                r.from,
                r.selector.clone(),
            ) {
                Ok(acc) => {
                    if i == 0 {
                        reset = acc.reset_outputs;
                    }
                }
                // Annotations are the same for every processor: the first refuses before any
                // accepted.
                Err(e) => return refused(e),
            }
        }
        if late > 0 {
            log::log(
                Level::Warn,
                &format!(
                    "spec: rollout {} starts at {}, but {late} instances it picks had already stepped past it (by up to {}): they switch at their next step, and their records since its start were judged by the version before. For one switch point in every process, publish with a start a moment ahead (`spec publish --from +2s`)",
                    r.revision,
                    status::show_time(r.from),
                    crate::processor::clock::human_ns(behind)
                ),
            );
        }
        Outcome {
            revision: r.revision,
            id: r.id.clone(),
            label: r.label.clone(),
            accepted: true,
            reset_outputs: reset,
            late_instances: late,
            ..Outcome::default()
        }
    }

    /// The program of a rollout's version: the base's for [`BASE`], one compiled before, or its
    /// bundle compiled with this process's options.
    fn program_of(
        &mut self,
        a: &Arrival,
        procs: &[&mut Processor],
    ) -> Result<Arc<tessla_engine::Program>, String> {
        let r = &a.rollout;
        // A rollout the channel refused (unsigned, signed by a key not trusted, its bundle not
        // matching its digest) is refused whatever version it names: the base, or one held.
        let bundle = a.bundle.as_ref().map_err(Clone::clone)?;
        if r.id == BASE {
            return procs
                .first()
                .map(|p| Arc::clone(&p.versions().base().program))
                .ok_or_else(|| "no processor".to_string());
        }
        if let Some(p) = self.compiled.get(&r.id) {
            return Ok(Arc::clone(p));
        }
        if bundle.id() != r.id {
            return Err(format!(
                "its bundle is version {}, not {} as the rollout says",
                bundle.id(),
                r.id
            ));
        }
        let loaded = bundle
            .load(&self.source.options)
            .map_err(|e| format!("it does not check here: {}", first_lines(&e.render())))?;
        if loaded.program.outputs.is_empty() {
            return Err("it has no outputs, so it would check nothing and write nothing".into());
        }
        self.compiled
            .insert(r.id.clone(), Arc::clone(&loaded.program));
        Ok(loaded.program)
    }

    /// Log an outcome, write its status metric, keep it for the channel's status key.
    fn outcome(&mut self, o: Outcome, from: i64, out: &mut Vec<u8>) {
        let what = if o.revision == 0 {
            format!("spec version {}", o.id)
        } else {
            format!(
                "rollout {} (version {}{})",
                o.revision,
                o.id,
                label_note(&o.label)
            )
        };
        if o.accepted {
            let reset = if o.reset_outputs.is_empty() {
                "no output starts afresh".to_string()
            } else {
                format!("outputs starting afresh: {}", o.reset_outputs.join(", "))
            };
            if o.revision != 0 {
                log::log(
                    Level::Info,
                    &format!(
                        "spec: {what} accepted; in force from {} for {}; {reset}",
                        status::show_time(from),
                        "the instances its selector picks"
                    ),
                );
            }
        } else if o.revision != 0 {
            log::log(
                Level::Error,
                &format!(
                    "spec: {what} refused: {}; the running versions stay in use",
                    o.reason
                ),
            );
        }
        status::write_line(out, &self.host, &self.partition, &o, from);
        self.outcomes.push(o);
    }
}

fn label_note(label: &str) -> String {
    if label.is_empty() {
        String::new()
    } else {
        format!(", `{label}`")
    }
}

/// The first lines of a diagnostic: enough for a status metric and a table cell.
fn first_lines(text: &str) -> String {
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .take(3)
        .collect();
    lines.join(" | ")
}
