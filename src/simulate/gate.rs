//! What the simulated robot does with an action before executing it (the book, "What a robot must
//! do with an action"): refuse one that is stale or repeated, accept a restarted monitor's.
//!
//! Owns: the rule and its counts. An action carries `seq` (its number in its monitor instance:
//! 1, 2, 3 ...) and `valid_until` (ns: its timestamp plus the spec's `action_validity`):
//! - **stale**: the robot's clock is past `valid_until` (a broker that was down, a retried
//!   publish): refused;
//! - **repeated**: `seq` not above the last accepted one, and a timestamp not newer than the
//!   last accepted one's (a redelivery of an action already seen, or an older one overtaking):
//!   refused;
//! - **a restarted monitor**: `seq` not above the last accepted one, but a newer timestamp (the
//!   monitor restarted without `--state` and counts from 1 again): accepted, and counted.
//!
//! An action without these fields (a spec that does not send them) is accepted as it is.
//! The [`Action`] type, as a twin returns it, is defined here with the rule that reads it.

/// What the twin answered to one message.
#[derive(Debug, Clone, PartialEq)]
pub struct Action {
    /// m/s: the speed to execute.
    pub speed: f64,
    /// The monitor changed the robot's own command.
    pub augmented: bool,
    /// The spec's running MSE, when the action carried it.
    pub speed_mse: Option<f64>,
    /// Its number in its monitor instance (`seq`), when it carried one.
    pub seq: Option<i64>,
    /// ns: until when it may be applied (`valid_until`), when it carried it.
    pub valid_until: Option<i64>,
    /// ns: its timestamp, when the twin knows it.
    pub time_ns: Option<i64>,
}

/// How the robot judged one action.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    Accepted,
    /// Accepted: a lower or equal `seq` with a newer timestamp.
    Restarted,
    RefusedStale,
    RefusedRepeated,
}

impl Verdict {
    pub fn accepted(self) -> bool {
        matches!(self, Verdict::Accepted | Verdict::Restarted)
    }
}

/// The robot's memory of the last accepted action, and the counts.
#[derive(Debug, Default, Clone)]
pub struct Gate {
    /// (seq, timestamp in ns) of the last accepted action.
    last: Option<(i64, i64)>,
    pub refused_stale: usize,
    pub refused_repeated: usize,
    pub monitor_restarts: usize,
}

impl Gate {
    /// Judge `action` arriving when the robot's clock reads `now_ns`.
    pub fn judge(&mut self, action: &Action, now_ns: i64) -> Verdict {
        if action.valid_until.is_some_and(|until| now_ns > until) {
            self.refused_stale += 1;
            return Verdict::RefusedStale;
        }
        let Some(seq) = action.seq else {
            return Verdict::Accepted;
        };
        // Its timestamp; `valid_until` orders actions alike when the timestamp did not come
        // with it (both grow by the same validity).
        let ts = action.time_ns.or(action.valid_until).unwrap_or(i64::MIN);
        let verdict = match self.last {
            None => Verdict::Accepted,
            Some((last_seq, _)) if seq > last_seq => Verdict::Accepted,
            Some((_, last_ts)) if ts > last_ts => Verdict::Restarted,
            Some(_) => Verdict::RefusedRepeated,
        };
        match verdict {
            Verdict::RefusedRepeated => self.refused_repeated += 1,
            Verdict::Restarted => {
                self.monitor_restarts += 1;
                self.last = Some((seq, ts));
            }
            _ => self.last = Some((seq, ts)),
        }
        verdict
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn action(seq: i64, ts: i64) -> Action {
        Action {
            speed: 0.1,
            augmented: false,
            speed_mse: None,
            seq: Some(seq),
            valid_until: Some(ts + 400),
            time_ns: Some(ts),
        }
    }

    #[test]
    fn stale_and_repeated_actions_are_refused_and_a_restart_accepted() {
        let mut g = Gate::default();
        assert_eq!(g.judge(&action(1, 1000), 1100), Verdict::Accepted);
        assert_eq!(g.judge(&action(2, 1200), 1300), Verdict::Accepted);
        // The same action again (a QoS 1 redelivery), and an older one overtaking.
        assert_eq!(g.judge(&action(2, 1200), 1350), Verdict::RefusedRepeated);
        assert_eq!(g.judge(&action(1, 1000), 1360), Verdict::RefusedRepeated);
        // Past its validity (1400 + 400).
        assert_eq!(g.judge(&action(3, 1400), 1801), Verdict::RefusedStale);
        // The monitor restarted: seq 1 again, but newer.
        assert_eq!(g.judge(&action(1, 1800), 1900), Verdict::Restarted);
        assert_eq!(g.judge(&action(2, 2000), 2100), Verdict::Accepted);
        assert_eq!(
            (g.refused_stale, g.refused_repeated, g.monitor_restarts),
            (1, 2, 1)
        );
        // Without the fields: accepted as it is.
        let plain = Action {
            seq: None,
            valid_until: None,
            time_ns: None,
            ..action(0, 0)
        };
        assert_eq!(g.judge(&plain, i64::MAX), Verdict::Accepted);
    }
}
