//! The rollouts a process has received and the fleet's decisions on them, in revision order.
//!
//! Owns two rules: a rollout is voted on only while it is undecided (a process that starts,
//! restarts or takes over after the decision follows it and never decides again), and
//! decisions are acted on in revision order, each once: the lowest revision not acted on yet
//! goes first as soon as it is decided, and everything after it waits for it. A rollout this
//! process could not verify (unsigned, signed by a key it does not trust, its bundle not
//! matching) that is still undecided when a later one is decided is passed over: nothing could
//! put it in force here.

use super::error::RolloutError;
use super::{Arrival, Decision};
use std::collections::BTreeMap;

/// What to do next with a decided rollout.
#[derive(Debug)]
pub enum Step {
    /// Committed: put it in force (if this process can run it).
    Commit(Arrival),
    /// Aborted (or its decision cannot be used): nothing changes; why.
    Abort(Arrival, String),
}

#[derive(Default)]
struct Entry {
    arrival: Option<Arrival>,
    decision: Option<Result<Decision, RolloutError>>,
}

/// The rollouts and decisions not acted on yet, and how far the process has acted.
#[derive(Default)]
pub struct Ledger {
    entries: BTreeMap<u64, Entry>,
    /// Every revision up to this one has been acted on (or passed over).
    done: u64,
    /// Each acted-on rollout's start (for its status line).
    froms: BTreeMap<u64, i64>,
}

impl Ledger {
    /// A decision arrived. The first one for a revision counts (the channel creates it once).
    pub fn decided(&mut self, revision: u64, decision: Result<Decision, RolloutError>) {
        // Acted on, or passed over: a decision cannot change it now.
        if revision <= self.done {
            return;
        }
        let e = self.entries.entry(revision).or_default();
        if e.decision.is_none() {
            e.decision = Some(decision);
        }
    }

    /// A rollout arrived: `Some` when this process is to vote on it (it is not decided yet),
    /// `None` when it is decided already or was acted on (it is then never voted on).
    pub fn proposed(&mut self, a: Arrival) -> Option<Arrival> {
        let revision = a.rollout.revision;
        if revision <= self.done {
            log_warn!(
                "spec: rollout {revision} arrived after this process acted on rollout {}: ignored (rollouts take effect in revision order)",
                self.done
            );
            return None;
        }
        let e = self.entries.entry(revision).or_default();
        if e.arrival.is_some() {
            return None;
        }
        e.arrival = Some(a.clone());
        e.decision.is_none().then_some(a)
    }

    /// The next decided rollout to act on, in revision order; `None` while the lowest one
    /// waiting is undecided (or there is none).
    pub fn next_step(&mut self) -> Option<Step> {
        loop {
            let (&revision, e) = self.entries.first_key_value()?;
            let Some(arrival) = &e.arrival else {
                // A decision whose rollout has not arrived yet.
                return None;
            };
            // An unverifiable rollout still undecided is passed over once a later one is
            // decided (until then its own decision may still come).
            let later_decided = || {
                self.entries
                    .range(revision + 1..)
                    .any(|(_, l)| l.decision.is_some() && l.arrival.is_some())
            };
            let step = match &e.decision {
                None if arrival.bundle.is_err() && later_decided() => None,
                None => return None,
                Some(Err(why)) => Some(Step::Abort(
                    arrival.clone(),
                    format!("its decision record cannot be used ({why}), so it counts as aborted"),
                )),
                Some(Ok(d)) => Some(Self::step(arrival, d)),
            };
            let from = arrival.rollout.from;
            self.entries.remove(&revision);
            self.done = self.done.max(revision);
            match step {
                Some(s) => {
                    self.froms.insert(revision, from);
                    return Some(s);
                }
                // Passed over: its refusal was reported when it arrived.
                None => continue,
            }
        }
    }

    fn step(a: &Arrival, d: &Decision) -> Step {
        let r = &a.rollout;
        if d.revision != r.revision || d.id != r.id || d.digest != r.digest {
            return Step::Abort(
                a.clone(),
                format!(
                    "its decision is for revision {} version {}, not this rollout (version {}), so it counts as aborted",
                    d.revision, d.id, r.id
                ),
            );
        }
        if d.commit {
            Step::Commit(a.clone())
        } else {
            Step::Abort(a.clone(), d.reason.clone())
        }
    }

    /// The start of a rollout acted on (0 when unknown).
    pub fn from_of(&self, revision: u64) -> i64 {
        self.froms.get(&revision).copied().unwrap_or(0)
    }

    /// Rollouts received and not acted on yet (waiting for a decision).
    pub fn waiting(&self) -> usize {
        self.entries
            .values()
            .filter(|e| e.arrival.is_some())
            .count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::processor::versions::Selector;
    use crate::spec_feed::Rollout;
    use crate::spec_feed::bundle::Bundle;
    use crate::spec_feed::sign::RecordError;

    fn unsigned() -> RolloutError {
        RecordError::Unsigned { what: "rollout" }.into()
    }

    fn arrival(revision: u64, ok: bool) -> Arrival {
        Arrival {
            rollout: Rollout {
                revision,
                id: format!("v{revision}"),
                digest: format!("d{revision}"),
                label: String::new(),
                from: 100 * revision as i64,
                selector: Selector::all(),
                published: 0,
                fleet: false,
            },
            bundle: if ok {
                Ok(Bundle {
                    files: Vec::new(),
                    links: Vec::new(),
                })
            } else {
                Err(unsigned())
            },
        }
    }

    fn decision(revision: u64, commit: bool) -> Result<Decision, RolloutError> {
        Ok(Decision {
            revision,
            id: format!("v{revision}"),
            digest: format!("d{revision}"),
            commit,
            reason: if commit { "" } else { "refused by p0" }.into(),
            votes: Vec::new(),
            decided: 0,
        })
    }

    fn names(l: &mut Ledger) -> Vec<String> {
        std::iter::from_fn(|| l.next_step())
            .map(|s| match s {
                Step::Commit(a) => format!("commit {}", a.rollout.revision),
                Step::Abort(a, why) => format!("abort {} ({why})", a.rollout.revision),
            })
            .collect()
    }

    /// A rollout is voted on while undecided; decisions are acted on in revision order, and a
    /// later decision waits for an earlier undecided rollout.
    #[test]
    fn decisions_are_acted_on_in_revision_order_and_an_undecided_rollout_holds_the_rest() {
        let mut l = Ledger::default();
        assert!(l.proposed(arrival(1, true)).is_some());
        assert!(l.proposed(arrival(2, true)).is_some());
        l.decided(2, decision(2, true));
        assert!(names(&mut l).is_empty(), "2 waits for 1");
        l.decided(1, decision(1, false));
        assert_eq!(
            names(&mut l),
            [
                "abort 1 (refused by p0)".to_string(),
                "commit 2".to_string()
            ]
        );
        assert_eq!(l.from_of(2), 200);
        // Acted on: a repeat of either changes nothing.
        assert!(l.proposed(arrival(2, true)).is_none());
        l.decided(1, decision(1, true));
        assert!(names(&mut l).is_empty());
    }

    /// A process that starts after the decision never votes: the decision is taken in first.
    #[test]
    fn a_rollout_decided_before_it_arrives_is_not_voted_on() {
        let mut l = Ledger::default();
        l.decided(1, decision(1, true));
        assert!(names(&mut l).is_empty(), "no rollout yet");
        assert!(l.proposed(arrival(1, true)).is_none());
        assert_eq!(names(&mut l), ["commit 1"]);
    }

    /// Found by the combination test: an unverifiable rollout was passed over as soon as it
    /// arrived, so its own abort, arriving next, sat in the ledger without a rollout and held
    /// every later rollout for ever. It is acted on now, and the next ones after it.
    #[test]
    fn an_unverifiable_rollouts_own_decision_is_acted_on_and_holds_nothing() {
        let mut l = Ledger::default();
        assert!(l.proposed(arrival(1, false)).is_some(), "voted on: refused");
        assert!(names(&mut l).is_empty());
        l.decided(1, decision(1, false));
        assert_eq!(names(&mut l), ["abort 1 (refused by p0)"]);
        l.proposed(arrival(2, true));
        l.decided(2, decision(2, true));
        assert_eq!(names(&mut l), ["commit 2"]);
    }

    /// An unverifiable undecided rollout does not hold the ones after it; a decision that does
    /// not match its rollout, or cannot be read, counts as an abort.
    #[test]
    fn unverifiable_rollouts_and_bad_decisions_never_put_anything_in_force() {
        let mut l = Ledger::default();
        // Undecided, with a later one decided: passed over.
        assert!(l.proposed(arrival(4, false)).is_some());
        l.proposed(arrival(5, true));
        l.decided(5, decision(5, true));
        assert_eq!(names(&mut l), ["commit 5"]);
        l.decided(4, decision(4, true));
        assert!(names(&mut l).is_empty(), "passed over for good");
        let mut l = Ledger::default();
        l.proposed(arrival(2, true));
        l.decided(2, decision(3, true));
        l.proposed(arrival(3, true));
        l.decided(3, Err(unsigned()));
        let steps = names(&mut l);
        assert_eq!(steps.len(), 2, "{steps:?}");
        assert!(
            steps[0].starts_with("abort 2") && steps[0].contains("not this rollout"),
            "{steps:?}"
        );
        assert!(
            steps[1].starts_with("abort 3") && steps[1].contains("unsigned"),
            "{steps:?}"
        );
        assert_eq!(l.waiting(), 0);
    }
}
