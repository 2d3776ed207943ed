//! The fleet's decision on a rollout, from the votes of its processes: who votes, when the
//! count is complete, and the rule (`docs/book/src/state-and-reload.md`, "One decision per rollout").
//!
//! Voters are the processes alive when the rollout was proposed: those whose status key the
//! server stored within [`LIVE`] before it (every process rewrites its key every
//! [`super::nats::HEARTBEAT`]) and did not mark it stopped, and any that report a vote for it
//! later. A vote is the process's
//! check outcome for the rollout's revision. The rollout is committed when every voter accepted
//! it (with no voter at all too: the processes that start later follow the record); a refusal,
//! or a voter that has not answered by the deadline, aborts it.

use super::nats::{LIVE, Reported};
use super::{Decision, Phase, Rollout, Vote};

/// The votes so far: one per voter, `accepted: None` for one that has not answered yet.
#[derive(Debug, Clone, PartialEq)]
pub struct Tally {
    pub votes: Vec<Vote>,
}

impl Tally {
    /// Every voter has answered.
    pub fn complete(&self) -> bool {
        self.votes.iter().all(|v| v.accepted.is_some())
    }

    /// A voter refused (no need to wait for the others).
    pub fn refused(&self) -> bool {
        self.votes.iter().any(|v| v.accepted == Some(false))
    }

    /// The voters that have not answered.
    pub fn silent(&self) -> Vec<&str> {
        self.votes
            .iter()
            .filter(|v| v.accepted.is_none())
            .map(|v| v.process.as_str())
            .collect()
    }
}

/// The votes on rollout `revision` among `statuses`, with `proposed` the server's time of the
/// rollout (ns): a process is a voter when its key was written at most [`LIVE`] before it, or
/// when it has voted.
pub fn tally(revision: u64, statuses: &[Reported], proposed: i64) -> Tally {
    let live_since = proposed.saturating_sub(i64::try_from(LIVE.as_nanos()).unwrap_or(i64::MAX));
    let mut votes = Vec::new();
    for r in statuses {
        let Ok(s) = &r.status else { continue };
        let vote = s
            .outcomes
            .iter()
            .rev()
            .find(|o| o.revision == revision && o.phase == Phase::Check);
        match vote {
            Some(o) => votes.push(Vote {
                process: r.key.clone(),
                accepted: Some(o.accepted),
                reason: o.reason.clone(),
            }),
            None if r.written >= live_since && !s.stopped => votes.push(Vote {
                process: r.key.clone(),
                accepted: None,
                reason: String::new(),
            }),
            None => {}
        }
    }
    Tally { votes }
}

/// The decision on `r` from `tally` (complete, or the deadline passed), made at `now` (ns).
pub fn decide(r: &Rollout, tally: &Tally, now: i64) -> Decision {
    let refusals: Vec<String> = tally
        .votes
        .iter()
        .filter(|v| v.accepted == Some(false))
        .map(|v| format!("{} refused it: {}", v.process, v.reason))
        .collect();
    // Decided on a refusal, the voters not heard yet did not matter.
    let silent = if refusals.is_empty() {
        tally.silent()
    } else {
        Vec::new()
    };
    let commit = refusals.is_empty() && silent.is_empty();
    let reason = if commit {
        match tally.votes.len() {
            0 => "no process was following the channel; those that start follow this record"
                .to_string(),
            n => format!("all {n} processes accepted it"),
        }
    } else {
        let mut parts = refusals;
        if !silent.is_empty() {
            parts.push(format!(
                "no answer before the deadline from {} (counted as a refusal)",
                silent.join(", ")
            ));
        }
        parts.join("; ")
    };
    Decision {
        revision: r.revision,
        id: r.id.clone(),
        digest: r.digest.clone(),
        commit,
        reason,
        votes: tally.votes.clone(),
        decided: now,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::processor::versions::Selector;
    use crate::spec_feed::Outcome;
    use crate::spec_feed::nats::Status;

    const S: i64 = 1_000_000_000;

    fn status(key: &str, written: i64, outcomes: Vec<Outcome>) -> Reported {
        Reported {
            key: key.into(),
            status: Ok(Status {
                host: "h".into(),
                partition: String::new(),
                pid: 1,
                time: written,
                outcomes,
                stopped: false,
            }),
            written,
        }
    }

    fn vote(revision: u64, accepted: bool, phase: Phase) -> Outcome {
        Outcome {
            revision,
            accepted,
            reason: if accepted { "" } else { "input `x`" }.into(),
            phase,
            ..Outcome::default()
        }
    }

    fn rollout() -> Rollout {
        Rollout {
            revision: 2,
            id: "v".into(),
            digest: "d".into(),
            label: String::new(),
            from: 0,
            selector: Selector::all(),
            published: 0,
            fleet: false,
        }
    }

    /// Live processes are waited for; a stale key is not; a refusal or a silent voter aborts;
    /// no voter at all commits.
    #[test]
    fn a_rollout_commits_only_when_every_live_process_accepted_it() {
        let at = 100 * S;
        let statuses = vec![
            status("status.a", at - S, vec![vote(2, true, Phase::Check)]),
            status("status.b", at - 2 * S, vec![vote(1, true, Phase::Check)]),
            status("status.gone", at - 60 * S, vec![]),
            // Started after the proposal and voted: counted.
            status("status.late", at + S, vec![vote(2, true, Phase::Check)]),
        ];
        let t = tally(2, &statuses, at);
        assert_eq!(t.votes.len(), 3, "{t:?}");
        assert!(!t.complete());
        assert_eq!(t.silent(), ["status.b"]);
        let d = decide(&rollout(), &t, at);
        assert!(!d.commit);
        assert!(d.reason.contains("no answer") && d.reason.contains("status.b"));
        // b answers: committed.
        let mut statuses = statuses;
        statuses[1] = status("status.b", at, vec![vote(2, true, Phase::Check)]);
        let t = tally(2, &statuses, at);
        assert!(t.complete() && !t.refused());
        let d = decide(&rollout(), &t, at);
        assert!(d.commit, "{d:?}");
        assert_eq!(d.reason, "all 3 processes accepted it");
        // One refusal aborts, saying who and why.
        statuses[0] = status("status.a", at, vec![vote(2, false, Phase::Check)]);
        let t = tally(2, &statuses, at);
        assert!(t.refused());
        let d = decide(&rollout(), &t, at);
        assert!(!d.commit && d.reason.contains("status.a refused it: input `x`"));
        // Nobody following: committed.
        let d = decide(&rollout(), &tally(2, &[], at), at);
        assert!(d.commit && d.reason.contains("no process"));
    }
}
