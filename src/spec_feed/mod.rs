//! Where new spec versions come from while a run goes on, and what each process says about
//! them: the fleet's spec channel (a NATS key-value bucket of signed rollouts and the fleet's
//! signed decisions on them, [`nats`]), the watched spec file of one process ([`watch`]), and
//! the bundle a version travels as ([`bundle`]).
//!
//! Owns the rollout record every channel carries ([`Rollout`]: which version, from which event
//! time, for which instances), the fleet's decision on it ([`Decision`]: committed or aborted,
//! with every process's vote), the outcome a process reports for each ([`Outcome`]: its vote,
//! then what the decision did here), and the [`Updates`] the step loop calls. A rollout is a
//! proposal: a process checks it and votes, and acts only on the decision, in revision order
//! ([`ledger`]). Checking a version and switching instances to it is the processor's
//! (`processor::versions`).

pub mod bundle;
pub mod decide;
pub mod error;
pub mod ledger;
pub mod nats;
pub mod reload;
pub mod sign;
pub mod status;
pub mod watch;

use crate::processor::Processor;
use crate::processor::versions::Selector;
use bundle::Bundle;
use error::RolloutError;
use ledger::{Ledger, Step};
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
    /// A version of the fleet spec (`spec publish --fleet`, docs/fleet.md, "Rollouts of the
    /// fleet spec"): checked against the robot spec and put in force in the fleet level, not in
    /// the robots' instances. Not written when false, so the records (and signatures) of robot
    /// rollouts are as before.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub fleet: bool,
}

/// A fleet spec version as a process checked it ([`FleetCheck`]): its program and, per fleet
/// input in the program's order, the robot output it reads.
#[derive(Debug, Clone)]
pub struct FleetVersion {
    pub program: Arc<tessla_engine::Program>,
    pub names: Vec<String>,
}

/// A committed fleet rollout, for the fleet level to put in force from `from` (the step loop
/// hands it over: [`Updates::take_fleet`]).
#[derive(Debug, Clone)]
pub struct FleetCommit {
    pub revision: u64,
    pub id: String,
    pub from: i64,
    /// `None`: this process cannot run it (its check failed here); the fleet level stays on
    /// the version it runs, and a partitioned one goes on past the switch entry.
    pub version: Option<FleetVersion>,
}

/// A committed robot rollout, as the fleet level sees it: the outputs its version has (a fleet
/// input reading an output it lacks is no longer fed by the robots it picks: docs/fleet.md).
/// Only rollouts committed while this process runs ([`Updates::take_robot_commits`]), not
/// those in the channel's history at start.
#[derive(Debug, Clone)]
pub struct RobotCommit {
    pub revision: u64,
    pub id: String,
    /// The robots it picks (`Selector`'s text; empty: every one).
    pub select: String,
    pub outputs: Vec<String>,
}

/// How this process checks a fleet spec version (the fleet level's own check against the
/// robot spec, given by the command that runs it; the fleet level sits above this module).
pub type FleetCheck = Box<dyn Fn(&Bundle) -> Result<FleetVersion, RolloutError>>;

/// What a process's outcome for a version is: its check of a proposal (its vote), or what the
/// fleet's decision did here.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// A reload checked (and, accepted, put in force), or a rollout checked: `accepted` is the
    /// process's vote.
    #[default]
    Check,
    /// The fleet committed the rollout: `accepted`, it is in force here from its start;
    /// refused, this process cannot run it (its robots stay on the versions they run).
    Committed,
    /// The fleet aborted the rollout: nothing changed.
    Aborted,
}

/// What one process made of one version.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Outcome {
    /// The rollout's revision (0 for a local reload: SIGHUP or a watched file).
    pub revision: u64,
    pub id: String,
    pub label: String,
    /// [`Phase::Check`]: passed the checks here (a rollout: the vote to commit it);
    /// [`Phase::Committed`]: in force here.
    pub accepted: bool,
    /// Why it was refused (the first lines of the diagnostic), or empty.
    #[serde(default)]
    pub reason: String,
    /// Outputs whose streams start afresh in the instances that switch.
    #[serde(default)]
    pub reset_outputs: Vec<String>,
    /// Instances it picks that had already stepped past its start when it was committed: they
    /// switch at their next step, so their records since the start were judged by the version
    /// before.
    #[serde(default)]
    pub late_instances: u64,
    /// A check (a vote), or what the fleet's decision did.
    #[serde(default)]
    pub phase: Phase,
}

impl Outcome {
    /// What this process made of rollout `r`, in `phase`: `accepted` or why not (`reason`).
    fn of(r: &Rollout, phase: Phase, accepted: bool, reason: String) -> Outcome {
        Outcome {
            revision: r.revision,
            id: r.id.clone(),
            label: r.label.clone(),
            accepted,
            reason,
            phase,
            ..Outcome::default()
        }
    }

    /// The status metric's `outcome` tag and `spec status`'s word: `accepted`/`refused` (a
    /// reload, or a vote), `committed`, `unrunnable` (committed, but it cannot run here),
    /// `aborted`.
    pub fn word(&self) -> &'static str {
        match (self.phase, self.accepted) {
            (Phase::Check, true) => "accepted",
            (Phase::Check, false) => "refused",
            (Phase::Committed, true) => "committed",
            (Phase::Committed, false) => "unrunnable",
            (Phase::Aborted, _) => "aborted",
        }
    }
}

/// One process's vote on a rollout, as the decision records it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Vote {
    /// The process's status key (`status.<host>.<partition>.pid<N>`, or `status.<host>.pid<N>`).
    pub process: String,
    /// `Some(true)`: it accepted; `Some(false)`: it refused (`reason`); `None`: it did not
    /// answer before the deadline (counted as a refusal).
    pub accepted: Option<bool>,
    #[serde(default)]
    pub reason: String,
}

/// The fleet's decision on a rollout: stored once (`decision.<revision>`, created with the KV
/// `create`), signed with the operator's key like the rollout. Processes act on nothing else.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Decision {
    pub revision: u64,
    /// The rollout's version id and digest: a decision is for that rollout only.
    pub id: String,
    pub digest: String,
    /// Committed (every process that voted accepted it) or aborted.
    pub commit: bool,
    /// Why (the refusals, the processes that did not answer; or that every vote accepted).
    #[serde(default)]
    pub reason: String,
    /// The votes it was decided on.
    #[serde(default)]
    pub votes: Vec<Vote>,
    /// When it was decided (ns since the Unix epoch, the deciding command's wall clock).
    pub decided: i64,
}

/// A rollout as a channel delivers it: verified with its bundle, or why it cannot be used (an
/// unsigned or foreign rollout, a bundle that does not match its digest).
#[derive(Debug, Clone)]
pub struct Arrival {
    pub rollout: Rollout,
    pub bundle: Result<Bundle, RolloutError>,
}

/// What a channel delivers: a rollout (a proposal), or the fleet's decision on one (`Err`: a
/// decision record that is unsigned, signed by a key not trusted, or cannot be read).
#[derive(Debug, Clone)]
pub enum Event {
    Proposal(Arrival),
    Decision {
        revision: u64,
        decision: Result<Decision, RolloutError>,
    },
}

impl Event {
    pub fn revision(&self) -> u64 {
        match self {
            Event::Proposal(a) => a.rollout.revision,
            Event::Decision { revision, .. } => *revision,
        }
    }
}

/// A fleet's spec channel, as the run sees it.
pub trait Channel {
    /// Rollouts and decisions that arrived since the last call; never blocks.
    fn poll(&mut self) -> Vec<Event>;
    /// Record this process's outcomes where the operator's `spec status` and `spec publish`
    /// read them (best effort; also rewritten every few seconds, which tells the publisher
    /// that the process is alive).
    fn report(&mut self, host: &str, partition: &str, outcomes: &[Outcome]);
}

/// The id a rollout gives for "the spec each process started with" (`spec rollback` to it).
pub const BASE: &str = "base";

/// New spec versions while the run goes on: SIGHUP and a watched spec file reload the spec the
/// process started with; a channel's rollouts are checked (the process's vote) and put in
/// force from their event time once the fleet commits them. Every outcome is logged and
/// written as a status metric ([`status`]).
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
    /// What the channel held at connect, not taken in yet.
    first: Vec<Event>,
    /// The rollouts and decisions, in revision order.
    ledger: Ledger,
    /// The fleet level's check of a fleet spec version (`None`: this process runs no fleet
    /// level, and votes for any fleet version: `spec publish --fleet` checked it already).
    fleet_check: Option<FleetCheck>,
    /// Fleet rollouts committed and not yet handed to the fleet level.
    fleet_commits: Vec<FleetCommit>,
    /// Robot rollouts committed since the first tick, not yet handed to the fleet level.
    robot_commits: Vec<RobotCommit>,
    /// The first tick (the channel's history at connect) is done.
    ticked: bool,
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
            host: crate::nats::conn::hostname(),
            partition: partition.to_string(),
            outcomes: Vec::new(),
            compiled: HashMap::new(),
            first: Vec::new(),
            ledger: Ledger::default(),
            fleet_check: None,
            fleet_commits: Vec::new(),
            robot_commits: Vec::new(),
            ticked: false,
        }
    }

    /// This process runs a fleet level: fleet rollouts are checked with `check`.
    pub fn with_fleet(&mut self, check: FleetCheck) {
        self.fleet_check = Some(check);
    }

    /// The fleet rollouts committed since the last call, in revision order.
    pub fn take_fleet(&mut self) -> Vec<FleetCommit> {
        std::mem::take(&mut self.fleet_commits)
    }

    /// The robot rollouts committed since the last call (none from the channel's history at
    /// start), in revision order.
    pub fn take_robot_commits(&mut self) -> Vec<RobotCommit> {
        std::mem::take(&mut self.robot_commits)
    }

    /// Follow `channel` too; `first`: what it already held, taken in by the first
    /// [`Updates::tick`] (the step loop's, before anything is restored or read). Reports this
    /// process to the channel at once (with no outcome yet), so a publisher counts its vote.
    pub fn with_channel(&mut self, mut channel: Box<dyn Channel>, first: Vec<Event>) {
        channel.report(&self.host, &self.partition, &self.outcomes);
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

    /// Look for changes: the watched file, the channel's new rollouts and decisions.
    pub fn tick(&mut self, procs: &mut [&mut Processor], out: &mut Vec<u8>) {
        if self.watch.as_mut().is_some_and(watch::Watched::changed) {
            self.reload("spec file changed", procs, out);
        }
        let mut events = std::mem::take(&mut self.first);
        match self.channel.as_mut() {
            Some(c) => events.extend(c.poll()),
            None => return,
        }
        let history = !self.ticked;
        self.ticked = true;
        if events.is_empty() {
            return;
        }
        // Decisions first: a rollout already decided when it arrives is never voted on.
        let (decisions, proposals): (Vec<Event>, Vec<Event>) = events
            .into_iter()
            .partition(|e| matches!(e, Event::Decision { .. }));
        for e in decisions.into_iter().chain(proposals) {
            match e {
                Event::Decision { revision, decision } => self.ledger.decided(revision, decision),
                Event::Proposal(a) => {
                    if let Some(a) = self.ledger.proposed(a) {
                        let vote = if a.rollout.fleet {
                            self.vote_fleet(&a)
                        } else {
                            self.vote(&a, procs)
                        };
                        self.outcome(vote, a.rollout.from, out);
                    }
                }
            }
        }
        while let Some(step) = self.ledger.next_step() {
            let outcome = match step {
                Step::Commit(a) if a.rollout.fleet => self.commit_fleet(&a),
                Step::Commit(a) => self.commit(&a, procs),
                Step::Abort(a, why) => {
                    log_info!(
                        "spec: rollout {} (version {}{}) aborted by the fleet: {why}; nothing changes",
                        a.rollout.revision,
                        a.rollout.id,
                        label_note(&a.rollout.label)
                    );
                    Outcome::of(&a.rollout, Phase::Aborted, false, why)
                }
            };
            let from = self.ledger.from_of(outcome.revision);
            self.outcome(outcome, from, out);
        }
        // What the channel held at start was in force before this process: no news for the
        // fleet level.
        if history {
            self.robot_commits.clear();
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
        let samples = samples_of(procs);
        let outcome = match reload::reload(&self.source, why, procs, &samples) {
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

    /// The version a rollout names here: the base's id for [`BASE`].
    fn version_id(r: &Rollout, procs: &[&mut Processor]) -> String {
        match procs.first() {
            Some(p) if r.id == BASE => p.versions().base().id.clone(),
            _ => r.id.clone(),
        }
    }

    /// Check a rollout here, once for the whole process (its threads' processors together,
    /// against every metric any of them has seen): this process's vote. Nothing changes.
    fn vote(&mut self, a: &Arrival, procs: &[&mut Processor]) -> Outcome {
        let r = &a.rollout;
        let checked = self.check(a, procs, true);
        let (accepted, reason) = match &checked {
            Ok(_) => (true, String::new()),
            Err(e) => (false, e.to_string()),
        };
        if accepted {
            log_info!(
                "spec: rollout {} (version {}{}) checks here: voted to commit it; it is put in force when the fleet commits it",
                r.revision,
                r.id,
                label_note(&r.label)
            );
        } else {
            log_error!(
                "spec: rollout {} (version {}{}) refused here: {reason}; voted to abort it",
                r.revision,
                r.id,
                label_note(&r.label)
            );
        }
        Outcome::of(r, Phase::Check, accepted, reason)
    }

    /// Every check a rollout passes before it may run here: its record and bundle, compiling
    /// with this process's options, and the processors' checks (selector, annotations; with
    /// `data`, the bindings against every thread's samples at once: the vote. Once committed,
    /// whether the data fits is decided robot by robot, from each robot's own records, the same
    /// in every process: `Versions::target_fitting`).
    fn check(
        &mut self,
        a: &Arrival,
        procs: &[&mut Processor],
        data: bool,
    ) -> Result<Arc<tessla_engine::Program>, RolloutError> {
        let program = self.program_of(a, procs)?;
        let id = Self::version_id(&a.rollout, procs);
        let samples = if data { samples_of(procs) } else { Vec::new() };
        if let Some(p) = procs.first() {
            p.check_version(&id, &program, &a.rollout.selector, &samples)?;
        }
        Ok(program)
    }

    /// The fleet committed a rollout: put it in force in every processor from its start. A
    /// version this process cannot run (it does not compile with its options, its annotations
    /// or selector do not fit here) is a loud error: its robots stay on the versions they run.
    /// A robot whose records do not fit it stays on the last version it can run (decided per
    /// robot, at its records).
    fn commit(&mut self, a: &Arrival, procs: &mut [&mut Processor]) -> Outcome {
        let r = &a.rollout;
        let cannot = |reason: String| {
            log_error!(
                "spec: rollout {} (version {}{}) was committed by the fleet, but this process cannot run it: {reason}; the instances it picks stay on the versions they run (spec status shows it as unrunnable here)",
                r.revision,
                r.id,
                label_note(&r.label)
            );
            Outcome::of(r, Phase::Committed, false, reason)
        };
        let program = match self.check(a, procs, false) {
            Ok(p) => p,
            Err(e) => return cannot(e.to_string()),
        };
        let id = Self::version_id(r, procs);
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
                Err(e) => return cannot(e.to_string()),
            }
        }
        if late > 0 {
            log_warn!(
                "spec: rollout {} starts at {}, but {late} instances it picks had already stepped past it (by up to {}) when it was committed: they switch at their next step, and their records since its start were judged by the version before. For one switch point in every process, publish with a start a moment ahead (`spec publish --from +5s`)",
                r.revision,
                status::show_time(r.from),
                crate::processor::clock::human_ns(behind)
            );
        }
        let reset_note = if reset.is_empty() {
            "no output starts afresh".to_string()
        } else {
            format!("outputs starting afresh: {}", reset.join(", "))
        };
        self.robot_commits.push(RobotCommit {
            revision: r.revision,
            id: id.clone(),
            select: if r.selector.is_all() {
                String::new()
            } else {
                r.selector.to_string()
            },
            outputs: program.outputs.iter().map(|o| o.name.clone()).collect(),
        });
        log_info!(
            "spec: rollout {} (version {}{}) committed by the fleet; in force from {} for {}; {reset_note}",
            r.revision,
            r.id,
            label_note(&r.label),
            status::show_time(r.from),
            if r.selector.is_all() {
                "every instance".to_string()
            } else {
                r.selector.to_string()
            }
        );
        Outcome {
            reset_outputs: reset,
            late_instances: late,
            ..Outcome::of(r, Phase::Committed, true, String::new())
        }
    }

    /// Check a fleet rollout here: its bundle and the fleet level's check (the messages of
    /// `--fleet-spec` at start-up). `Ok(None)`: this process runs no fleet level.
    fn check_fleet(&self, a: &Arrival) -> Result<Option<FleetVersion>, RolloutError> {
        let bundle = a.bundle.as_ref().map_err(Clone::clone)?;
        if a.rollout.id == BASE {
            return Err(RolloutError::FleetBase);
        }
        if bundle.id() != a.rollout.id {
            return Err(RolloutError::OtherVersion {
                bundle: bundle.id().to_string(),
                said: a.rollout.id.clone(),
            });
        }
        match &self.fleet_check {
            Some(check) => check(bundle).map(Some),
            None => Ok(None),
        }
    }

    /// This process's vote on a fleet rollout.
    fn vote_fleet(&mut self, a: &Arrival) -> Outcome {
        let r = &a.rollout;
        match self.check_fleet(a) {
            Ok(_) => {
                log_info!(
                    "spec: fleet rollout {} (fleet spec version {}{}) checks here: voted to commit it",
                    r.revision,
                    r.id,
                    label_note(&r.label)
                );
                Outcome::of(r, Phase::Check, true, String::new())
            }
            Err(reason) => {
                log_error!(
                    "spec: fleet rollout {} (fleet spec version {}{}) refused here: {reason}; voted to abort it",
                    r.revision,
                    r.id,
                    label_note(&r.label)
                );
                Outcome::of(r, Phase::Check, false, first_lines(&reason.to_string()))
            }
        }
    }

    /// The fleet committed a fleet rollout: hand it to the fleet level, which switches at its
    /// first step at or after its start (docs/fleet.md, "Rollouts of the fleet spec").
    fn commit_fleet(&mut self, a: &Arrival) -> Outcome {
        let r = &a.rollout;
        match self.check_fleet(a) {
            Ok(Some(version)) => {
                log_info!(
                    "spec: fleet rollout {} (fleet spec version {}{}) committed by the fleet; the fleet level runs it from its first step at or after {}",
                    r.revision,
                    r.id,
                    label_note(&r.label),
                    status::show_time(r.from)
                );
                self.fleet_commits.push(FleetCommit {
                    revision: r.revision,
                    id: r.id.clone(),
                    from: r.from,
                    version: Some(version),
                });
                Outcome::of(r, Phase::Committed, true, String::new())
            }
            Ok(None) => Outcome::of(r, Phase::Committed, true, String::new()),
            Err(reason) => {
                log_error!(
                    "spec: fleet rollout {} (fleet spec version {}{}) was committed by the fleet, but this process cannot run it: {reason}; its fleet level stays on the fleet spec it runs",
                    r.revision,
                    r.id,
                    label_note(&r.label)
                );
                self.fleet_commits.push(FleetCommit {
                    revision: r.revision,
                    id: r.id.clone(),
                    from: r.from,
                    version: None,
                });
                Outcome::of(r, Phase::Committed, false, first_lines(&reason.to_string()))
            }
        }
    }

    /// The program of a rollout's version: the base's for [`BASE`], one compiled before, or its
    /// bundle compiled with this process's options.
    fn program_of(
        &mut self,
        a: &Arrival,
        procs: &[&mut Processor],
    ) -> Result<Arc<tessla_engine::Program>, RolloutError> {
        let r = &a.rollout;
        // A rollout the channel refused (unsigned, signed by a key not trusted, its bundle not
        // matching its digest) is refused whatever version it names: the base, or one held.
        let bundle = a.bundle.as_ref().map_err(Clone::clone)?;
        if r.id == BASE {
            return procs
                .first()
                .map(|p| Arc::clone(&p.versions().base().program))
                .ok_or(RolloutError::NoProcessor);
        }
        if let Some(p) = self.compiled.get(&r.id) {
            return Ok(Arc::clone(p));
        }
        if bundle.id() != r.id {
            return Err(RolloutError::OtherVersion {
                bundle: bundle.id(),
                said: r.id.clone(),
            });
        }
        let loaded = bundle
            .load(&self.source.options)
            .map_err(|e| RolloutError::DoesNotCheck(first_lines(&e.render())))?;
        if loaded.program.outputs.is_empty() {
            return Err(RolloutError::NoOutputs);
        }
        self.compiled
            .insert(r.id.clone(), Arc::clone(&loaded.program));
        Ok(loaded.program)
    }

    /// Log a local reload's outcome, write its status metric, keep it for the channel's status
    /// key (a rollout's vote and decision are logged where they are made).
    fn outcome(&mut self, o: Outcome, from: i64, out: &mut Vec<u8>) {
        status::write_line(out, &self.host, &self.partition, &o, from);
        self.outcomes.push(o);
    }
}

/// Every thread's samples together: what the process has seen.
fn samples_of(procs: &[&mut Processor]) -> Vec<lineproto::Metric> {
    procs
        .iter()
        .flat_map(|p| p.samples().iter().cloned())
        .collect()
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::processor::Options;
    use bundle::BundleFile;
    use lineproto::RecordSplitter;
    use std::sync::Mutex;

    /// A channel that hands out what the test puts in and keeps what the process reports.
    #[derive(Clone, Default)]
    struct Stand {
        events: Arc<Mutex<Vec<Event>>>,
        reports: Arc<Mutex<Vec<Vec<Outcome>>>>,
    }

    impl Channel for Stand {
        fn poll(&mut self) -> Vec<Event> {
            std::mem::take(&mut *self.events.lock().unwrap())
        }
        fn report(&mut self, _: &str, _: &str, outcomes: &[Outcome]) {
            self.reports.lock().unwrap().push(outcomes.to_vec());
        }
    }

    const BASE_SPEC: &str = "in y: Events[Float]\ndef n = count(y)\nout n\n";
    const BOOL_SPEC: &str = "in y: Events[Bool]\ndef n = count(y)\ndef b = y\nout n\nout b\n";

    fn bundle(text: &str) -> Bundle {
        Bundle {
            files: vec![BundleFile {
                name: "s.tessla".into(),
                text: text.into(),
            }],
            links: vec![bundle::Link {
                from: None,
                written: "s.tessla".into(),
                file: 0,
            }],
        }
    }

    fn proposal(revision: u64, text: &str, from: i64) -> Event {
        let b = bundle(text);
        Event::Proposal(Arrival {
            rollout: Rollout {
                revision,
                id: b.id(),
                digest: b.digest(),
                label: String::new(),
                from,
                selector: Selector::all(),
                published: 0,
                fleet: false,
            },
            bundle: Ok(b),
        })
    }

    fn decision(revision: u64, text: &str, commit: bool) -> Event {
        let b = bundle(text);
        Event::Decision {
            revision,
            decision: Ok(Decision {
                revision,
                id: b.id(),
                digest: b.digest(),
                commit,
                reason: String::new(),
                votes: Vec::new(),
                decided: 0,
            }),
        }
    }

    fn processor() -> Processor {
        let b = bundle(BASE_SPEC);
        let loaded = b.load(&Default::default()).unwrap();
        let mut p = Processor::new(
            loaded.program,
            Options {
                passthrough: false,
                instance_by: vec!["robot".into()],
                version_tag: Some("v".into()),
                ..Options::default()
            },
        )
        .unwrap();
        p.name_base(&b.id(), "");
        p
    }

    fn updates(stand: &Stand, first: Vec<Event>) -> Updates {
        let mut u = Updates::new(
            SpecSource {
                path: None,
                options: Default::default(),
            },
            false,
            "",
        );
        u.with_channel(Box::new(stand.clone()), first);
        u
    }

    fn feed(p: &mut Processor, input: &str) -> String {
        let mut s = RecordSplitter::default();
        s.push(input.as_bytes());
        let mut out = Vec::new();
        while let Some(r) = s.next_record() {
            p.record(&r, &mut out);
        }
        while let Some(r) = s.finish() {
            p.record(&r, &mut out);
        }
        String::from_utf8(out).unwrap()
    }

    /// The outcomes of the last report, as words.
    fn words(stand: &Stand) -> Vec<String> {
        let reports = stand.reports.lock().unwrap();
        reports
            .last()
            .map(|o| {
                o.iter()
                    .map(|o| format!("{} {}", o.revision, o.word()))
                    .collect()
            })
            .unwrap_or_default()
    }

    /// Defect 5 of the issue: robot r5 sends `y=1.5` and r2 `y=true`; a rollout reads `y` as
    /// Bool. The process votes once, on everything it has seen: the same vote whether the two
    /// robots landed on one thread's processor or on two.
    #[test]
    fn the_thread_count_does_not_change_a_vote() {
        let records = ["m,robot=r5 y=1.5 100\n", "m,robot=r2 y=true 100\n"];
        let vote = |procs: &mut [&mut Processor]| {
            let stand = Stand::default();
            let mut u = updates(&stand, vec![proposal(1, BOOL_SPEC, 1000)]);
            let mut out = Vec::new();
            u.tick(procs, &mut out);
            words(&stand)
        };
        let mut one = processor();
        feed(&mut one, &records.concat());
        let (mut a, mut b) = (processor(), processor());
        feed(&mut a, records[0]);
        feed(&mut b, records[1]);
        assert_eq!(vote(&mut [&mut one]), ["1 accepted"]);
        assert_eq!(vote(&mut [&mut a, &mut b]), ["1 accepted"]);
        // One thread's share alone would have refused it.
        let mut only_r5 = processor();
        feed(&mut only_r5, records[0]);
        assert_eq!(vote(&mut [&mut only_r5]), ["1 refused"]);
    }

    /// Defect 2 of the issue: a rollout refused by the running processes is aborted for the
    /// fleet; a process that starts afterwards (no metric seen, so it would have accepted it)
    /// follows the record and never runs it. A rollout committed before a process starts is in
    /// force there from its start. Nothing is put in force before the decision.
    #[test]
    fn a_process_follows_the_decision_and_never_decides_again() {
        // The running process: votes to refuse (its records carry a Float, not a Bool).
        let stand = Stand::default();
        let mut running = processor();
        feed(&mut running, "m,robot=r1 y=1.5 100\n");
        let mut u = updates(&stand, vec![proposal(1, BOOL_SPEC, 1000)]);
        let mut out = Vec::new();
        u.tick(&mut [&mut running], &mut out);
        assert_eq!(words(&stand), ["1 refused"]);
        stand
            .events
            .lock()
            .unwrap()
            .push(decision(1, BOOL_SPEC, false));
        u.tick(&mut [&mut running], &mut out);
        assert_eq!(words(&stand), ["1 refused", "1 aborted"]);
        // Restarted after the abort: no vote, the base stays.
        let stand2 = Stand::default();
        let mut restarted = processor();
        let mut u2 = updates(
            &stand2,
            vec![proposal(1, BOOL_SPEC, 1000), decision(1, BOOL_SPEC, false)],
        );
        u2.tick(&mut [&mut restarted], &mut out);
        assert_eq!(words(&stand2), ["1 aborted"]);
        let base = bundle(BASE_SPEC).id();
        let a = feed(&mut running, "m,robot=r1 y=2.5 2000\n");
        let b = feed(&mut restarted, "m,robot=r1 y=2.5 2000\n");
        assert!(a.contains(&format!("v={base}")), "{a}");
        assert!(b.contains(&format!("v={base}")), "{b}");
        // A proposal alone puts nothing in force; its commit does, from its start.
        let stand3 = Stand::default();
        let mut p = processor();
        let mut u3 = updates(&stand3, vec![proposal(1, BOOL_SPEC, 1000)]);
        u3.tick(&mut [&mut p], &mut out);
        let before = feed(&mut p, "m,robot=r9 y=true 1500\n");
        assert!(before.contains(&format!("v={base}")), "{before}");
        stand3
            .events
            .lock()
            .unwrap()
            .push(decision(1, BOOL_SPEC, true));
        u3.tick(&mut [&mut p], &mut out);
        assert_eq!(words(&stand3), ["1 accepted", "1 committed"]);
        let after = feed(&mut p, "m,robot=r9 y=true 1600\n");
        let new = bundle(BOOL_SPEC).id();
        assert!(
            after.contains(&format!("v={new}")) && after.contains("b=true"),
            "{after}"
        );
    }

    /// A committed version a robot's records do not fit: that robot stays on the last version
    /// it can run (loud and counted: no output silently lost), decided from its own records,
    /// while a robot whose records fit switches; the same in every process and thread.
    #[test]
    fn a_robot_whose_records_do_not_fit_a_committed_version_stays_on_its_own() {
        let stand = Stand::default();
        let mut p = processor();
        feed(&mut p, "m,robot=r1 y=1.5 100\n");
        let mut u = updates(
            &stand,
            vec![proposal(1, BOOL_SPEC, 1000), decision(1, BOOL_SPEC, true)],
        );
        let mut out = Vec::new();
        u.tick(&mut [&mut p], &mut out);
        assert_eq!(words(&stand), ["1 committed"]);
        let base = bundle(BASE_SPEC).id();
        let new = bundle(BOOL_SPEC).id();
        let after = feed(&mut p, "m,robot=r1 y=2.5 2000\nm,robot=r2 y=true 2000\n");
        assert!(
            after.contains(&format!("tessla,robot=r1,v={base} n=2i 2000")),
            "{after}"
        );
        assert!(
            after.contains(&format!("tessla,robot=r2,v={new} n=1i,b=true 2000")),
            "{after}"
        );
        assert_eq!(p.counters.unfit, 1);
        assert!(p.summary().contains("1 kept a version"), "{}", p.summary());
        // Sticky: r1's next records stay on its version without another error.
        let again = feed(&mut p, "m,robot=r1 y=3.5 3000\n");
        assert!(again.contains(&format!("v={base} n=3i")), "{again}");
        assert_eq!(p.counters.unfit, 1);
    }

    /// Defect 5's other half: a SIGHUP reload is checked as a rollout is, bindings included,
    /// against every thread's metrics: a spec that cannot read what arrives is refused and the
    /// running one stays.
    #[test]
    fn a_sighup_reload_checks_its_bindings_against_every_threads_metrics() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("spec.tessla");
        std::fs::write(&path, BOOL_SPEC).unwrap();
        let reload = |procs: &mut [&mut Processor]| {
            let mut u = Updates::new(
                SpecSource {
                    path: Some(path.clone()),
                    options: Default::default(),
                },
                false,
                "",
            );
            let mut out = Vec::new();
            u.hangup(procs, &mut out);
            let text = String::from_utf8(out).unwrap();
            text.contains("outcome=accepted")
        };
        // One thread saw a Float `y`, the other a Bool: the Bool spec reads one of them.
        let (mut a, mut b) = (processor(), processor());
        feed(&mut a, "m,robot=r5 y=1.5 100\n");
        feed(&mut b, "m,robot=r2 y=true 100\n");
        assert!(reload(&mut [&mut a, &mut b]));
        // Only Floats seen: refused, the running spec stays.
        let mut c = processor();
        feed(&mut c, "m,robot=r5 y=1.5 100\n");
        assert!(!reload(&mut [&mut c]));
        let after = feed(&mut c, "m,robot=r5 y=2.5 200\n");
        assert!(after.contains("n=2i"), "{after}");
    }

    /// Found by the combination test: a record with a value no version reads (a bad value)
    /// says nothing against a new version; the robot switches as its next good record would
    /// have, and the bad value is dropped as before.
    #[test]
    fn a_bad_value_does_not_keep_a_robot_off_a_new_version() {
        let stand = Stand::default();
        let mut p = processor();
        feed(&mut p, "m,robot=r1 y=1.5 100\n");
        const INT_SPEC: &str = "in y: Events[Int]\ndef n = count(y)\nout n\n";
        let mut u = updates(
            &stand,
            vec![proposal(1, INT_SPEC, 1000), decision(1, INT_SPEC, true)],
        );
        let mut out = Vec::new();
        u.tick(&mut [&mut p], &mut out);
        // `"oops"` is neither Float (the base) nor Int (the new version).
        feed(&mut p, "m,robot=r1 y=\"oops\" 1100\n");
        let after = feed(&mut p, "m,robot=r1 y=2i 1200\n");
        let new = bundle(INT_SPEC).id();
        assert!(after.contains(&format!("v={new}")), "{after}");
        assert_eq!(p.counters.unfit, 0);
    }

    /// A committed version this process cannot run (here: its selector names a tag that does
    /// not choose instances in this process) is reported as unrunnable, loudly, and changes
    /// nothing.
    #[test]
    fn a_committed_version_that_cannot_run_here_is_unrunnable_and_changes_nothing() {
        let stand = Stand::default();
        let mut p = processor();
        feed(&mut p, "m,robot=r1 y=1.5 100\n");
        let Event::Proposal(mut a) = proposal(1, BASE_SPEC.replace("n", "k").as_str(), 1000) else {
            unreachable!()
        };
        a.rollout.selector = Selector::parse("site=lab").unwrap();
        let Event::Decision { decision, .. } =
            decision(1, BASE_SPEC.replace("n", "k").as_str(), true)
        else {
            unreachable!()
        };
        let mut u = updates(
            &stand,
            vec![
                Event::Proposal(a),
                Event::Decision {
                    revision: 1,
                    decision,
                },
            ],
        );
        let mut out = Vec::new();
        u.tick(&mut [&mut p], &mut out);
        assert_eq!(words(&stand), ["1 unrunnable"]);
        let status = String::from_utf8(out).unwrap();
        assert!(status.contains("outcome=unrunnable"), "{status}");
        let after = feed(&mut p, "m,robot=r1 y=2.5 2000\n");
        assert!(after.contains("n=2i"), "{after}");
    }
}
