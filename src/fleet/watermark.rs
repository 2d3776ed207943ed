//! The fleet level across NATS partitions, without NATS (docs/fleet.md, "A fleet of NATS
//! partitions"): what a partition sends ([`Msg`]), and the fleet level's table of partitions
//! ([`Partitions`]) that turns the messages, in the order the stream holds them, into what the
//! [`super::Level`] takes in and the bound on its watermark.
//!
//! Owns: each partition's generation (its lease's; messages of an older generation are
//! dropped, so a fenced-out holder counts nothing), its promise (no change it sends later is
//! at or before it), whether it is live, handing over (its holder ended while a standby of it
//! was live: the standby's first entry comes), ended or dropped out, and each robot's highest
//! clock reported by any generation: a change at or before it is a repeat (a new holder
//! replaying what its predecessor already sent) and is not counted twice. The bound is the
//! minimum promise over live and handing-over partitions; an ended or dropped-out partition
//! does not hold the fleet back. Every partition ended is the end of the fleet's input only once a close comes (a
//! restarted partition's replacement goes on). Status lines (`tessla_fleet_status`) name each partition's changes of state.

use crate::processor::fleet_tap::{Change, Drained};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use tessla_engine::snapshot::SValue;

/// The measurement of the fleet level's status lines.
pub const STATUS_MEASUREMENT: &str = "tessla_fleet_status";

/// One message to the fleet level, JSON in the stream.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Msg {
    /// The partition (its lease name).
    pub p: String,
    /// Its lease's generation.
    pub g: u64,
    /// `true`: the fleet level's holder says this partition (at generation `g`) dropped out.
    #[serde(default)]
    pub drop: bool,
    /// No change this partition sends later is at or before this time (ns).
    #[serde(default)]
    pub promise: i64,
    /// The partition's input ended (its holder stopped).
    #[serde(default)]
    pub end: bool,
    /// With `end`: a standby of the partition was live when its holder ended, so the
    /// partition is handed over and holds the fleet's bound at its promise until the
    /// standby's first entry (a newer generation) or an end without `handed` (the fleet
    /// level's holder's, once no standby of it is live).
    #[serde(default)]
    pub handed: bool,
    /// `true`: the fleet level's holder, stopping, found every partition ended and no
    /// partition lease held (no replacement coming): the fleet's input ended, step everything.
    #[serde(default)]
    pub close: bool,
    /// Robot output events: (time, robot key, fleet input, value).
    #[serde(default)]
    pub changes: Vec<(i64, String, usize, SValue)>,
    /// Robot clocks after their steps.
    #[serde(default)]
    pub clocks: Vec<(String, i64)>,
    /// Robots evicted.
    #[serde(default)]
    pub left: Vec<String>,
}

impl Msg {
    /// The message of partition `p` at generation `g` for what its processors collected.
    pub fn of(p: &str, g: u64, promise: i64, end: bool, drained: Vec<Drained>) -> Msg {
        let mut m = Msg {
            p: p.to_string(),
            g,
            drop: false,
            promise,
            end,
            handed: false,
            close: false,
            changes: Vec::new(),
            clocks: Vec::new(),
            left: Vec::new(),
        };
        for d in drained {
            m.changes.extend(d.changes.into_iter().filter_map(|c| {
                Some((
                    c.ts,
                    c.key.to_string(),
                    c.input,
                    SValue::from_value(&c.value)?,
                ))
            }));
            m.clocks
                .extend(d.clocks.into_iter().map(|(k, t)| (k.to_string(), t)));
            m.left.extend(d.left.into_iter().map(|k| k.to_string()));
        }
        m
    }

    /// Whether it carries anything but the promise.
    pub fn is_data(&self) -> bool {
        !self.changes.is_empty() || !self.clocks.is_empty() || !self.left.is_empty() || self.end
    }
}

/// A partition's state at the fleet level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum State {
    Live,
    Ended,
    Dropped,
    /// Its holder ended while a standby of it was live: held at its promise until the
    /// standby's first entry (`takeover`), or until it ends (no standby live any more) or
    /// drops out.
    Handing,
}

impl State {
    fn word(self) -> &'static str {
        match self {
            State::Live => "live",
            State::Ended => "ended",
            State::Dropped => "dropped",
            State::Handing => "handing over",
        }
    }

    /// Whether a partition in this state holds the fleet's watermark back.
    fn holds(self) -> bool {
        matches!(self, State::Live | State::Handing)
    }
}

#[derive(Debug, Clone)]
struct Part {
    generation: u64,
    promise: i64,
    state: State,
}

/// A change of a partition's state, for the status output.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Status {
    pub partition: String,
    pub generation: u64,
    pub state: State,
    /// What happened: `joined`, `takeover`, `handing over`, `ended`, `dropped`, `rejoined`.
    pub event: &'static str,
}

/// Counters of the partitioned fleet level.
#[derive(Debug, Default, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counters {
    /// Messages of an older generation than the partition's newest, dropped.
    pub stale: u64,
    /// Changes a new generation sent again (at or before the robot's highest clock), dropped.
    pub repeats: u64,
}

/// The table's state in a fleet checkpoint.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PartsState {
    /// (partition, generation, promise, state).
    parts: Vec<(String, u64, i64, State)>,
    high: Vec<(String, i64)>,
    closed: bool,
    counters: Counters,
}

/// The fleet level's view of the partitions.
#[derive(Debug, Default, Clone)]
pub struct Partitions {
    parts: BTreeMap<String, Part>,
    /// Per robot: the highest clock any generation reported.
    high: HashMap<Arc<str>, i64>,
    /// A close came while every partition had ended (until one is live again).
    closed: bool,
    pub counters: Counters,
}

impl Partitions {
    /// Take in one message (in stream order): what the level takes in, if anything, and the
    /// status changes it makes.
    pub fn apply(&mut self, m: Msg) -> (Option<Drained>, Vec<Status>) {
        let mut status = Vec::new();
        if m.close {
            self.closed = self.all_done();
            return (None, status);
        }
        let known = self.parts.get(&m.p).cloned();
        if m.drop {
            if let Some(p) = self.parts.get_mut(&m.p)
                && p.generation == m.g
                && p.state.holds()
            {
                p.state = State::Dropped;
                status.push(Status {
                    partition: m.p,
                    generation: m.g,
                    state: State::Dropped,
                    event: "dropped",
                });
            }
            return (None, status);
        }
        // An end carrying nothing else (the fleet level's holder's for a partition handing
        // over, or a holder's last entry after a drop-out) brings no partition back.
        let bare_end = m.end && m.changes.is_empty() && m.clocks.is_empty() && m.left.is_empty();
        let event = match &known {
            Some(p) if m.g < p.generation => {
                self.counters.stale += 1;
                return (None, status);
            }
            None => Some("joined"),
            Some(p) if m.g > p.generation => Some("takeover"),
            Some(p) if p.state != State::Live && !bare_end => Some("rejoined"),
            Some(_) => None,
        };
        let state = match (m.end, m.handed) {
            (false, _) => State::Live,
            (true, true) => State::Handing,
            (true, false) => State::Ended,
        };
        // The state this generation had before (a repeated end says nothing again).
        let before = known
            .as_ref()
            .filter(|p| p.generation == m.g)
            .map(|p| p.state);
        let promise = known
            .as_ref()
            .filter(|p| p.generation == m.g)
            .map_or(m.promise, |p| p.promise.max(m.promise));
        self.parts.insert(
            m.p.clone(),
            Part {
                generation: m.g,
                promise,
                state,
            },
        );
        if let Some(event) = event {
            status.push(Status {
                partition: m.p.clone(),
                generation: m.g,
                state: State::Live,
                event,
            });
        }
        if state != State::Live && (event.is_some() || before != Some(state)) {
            status.push(Status {
                partition: m.p.clone(),
                generation: m.g,
                state,
                event: state.word(),
            });
        }
        let mut d = Drained::default();
        for (ts, key, input, value) in m.changes {
            let key: Arc<str> = Arc::from(key);
            if self.high.get(&key).is_some_and(|h| ts <= *h) {
                self.counters.repeats += 1;
                continue;
            }
            d.changes.push(Change {
                ts,
                key,
                input,
                value: value.to_value(),
            });
        }
        for (key, t) in m.clocks {
            let key: Arc<str> = Arc::from(key);
            let h = self.high.entry(Arc::clone(&key)).or_insert(t);
            *h = (*h).max(t);
            d.clocks.push((key, t));
        }
        d.left = m.left.into_iter().map(Arc::from).collect();
        (Some(d), status)
    }

    /// The bound on the fleet's watermark: the least promise of the live partitions and of
    /// those handing over.
    pub fn bound(&self) -> i64 {
        self.parts
            .values()
            .filter(|p| p.state.holds())
            .map(|p| p.promise)
            .min()
            .unwrap_or(i64::MAX)
    }

    /// Every partition known has ended or dropped out (and there is one; one handing over
    /// has not). Not yet the end of the fleet's input: a partition's process that stops may
    /// be restarted (its replacement takes the lease over and goes on), so the fleet waits
    /// for [`Self::closed`].
    pub fn all_done(&self) -> bool {
        !self.parts.is_empty() && self.parts.values().all(|p| !p.state.holds())
    }

    /// The fleet's input ended: a close came while every partition had ended, and none is
    /// live again since. The fleet steps everything pending, as one process does at the end
    /// of its input.
    pub fn closed(&self) -> bool {
        self.closed && self.all_done()
    }

    /// Every partition known, by name.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.parts.keys().map(String::as_str)
    }

    /// The table's state, for a fleet checkpoint.
    pub fn state(&self) -> PartsState {
        let mut high: Vec<(String, i64)> =
            self.high.iter().map(|(k, t)| (k.to_string(), *t)).collect();
        high.sort();
        PartsState {
            parts: self
                .parts
                .iter()
                .map(|(n, p)| (n.clone(), p.generation, p.promise, p.state))
                .collect(),
            high,
            closed: self.closed,
            counters: self.counters.clone(),
        }
    }

    /// The table of a fleet checkpoint.
    pub fn from_state(s: PartsState) -> Partitions {
        Partitions {
            parts: s
                .parts
                .into_iter()
                .map(|(n, generation, promise, state)| {
                    (
                        n,
                        Part {
                            generation,
                            promise,
                            state,
                        },
                    )
                })
                .collect(),
            high: s.high.into_iter().map(|(k, t)| (Arc::from(k), t)).collect(),
            closed: s.closed,
            counters: s.counters,
        }
    }

    /// Whether partition `p` dropped out (silent past the bound; its next holder's first
    /// entry brings it back).
    pub fn dropped(&self, p: &str) -> bool {
        self.parts.get(p).is_some_and(|p| p.state == State::Dropped)
    }

    /// The live partitions and their generations.
    pub fn live(&self) -> impl Iterator<Item = (&str, u64)> {
        self.parts
            .iter()
            .filter(|(_, p)| p.state == State::Live)
            .map(|(n, p)| (n.as_str(), p.generation))
    }

    /// The partitions holding the fleet back (live or handing over) and their generations:
    /// the ones that drop out when silent.
    pub fn holding_back(&self) -> impl Iterator<Item = (&str, u64)> {
        self.parts
            .iter()
            .filter(|(_, p)| p.state.holds())
            .map(|(n, p)| (n.as_str(), p.generation))
    }

    /// The partitions handing over and their generations.
    pub fn handing(&self) -> impl Iterator<Item = (&str, u64)> {
        self.parts
            .iter()
            .filter(|(_, p)| p.state == State::Handing)
            .map(|(n, p)| (n.as_str(), p.generation))
    }
}

/// The start of every fleet status line: `tessla_fleet_status` and its tags, sorted (the
/// fleet's `--tag`s and version tag, with `partition` when the line is about one).
pub fn status_head(tags: &[(String, String)], partition: Option<&str>) -> String {
    let mut line = String::from(STATUS_MEASUREMENT);
    let mut all: Vec<(&str, &str)> = tags.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
    all.extend(partition.map(|p| ("partition", p)));
    all.sort();
    for (k, v) in all {
        line.push(',');
        lineproto::write::write_tag_key(&mut line, k);
        line.push('=');
        lineproto::write::write_tag_value(&mut line, v);
    }
    line
}

/// A status line: `tessla_fleet_status,partition=P[,--tag...] state="live",event="joined",generation=Gi TS`.
pub fn status_line(s: &Status, tags: &[(String, String)], ts: i64, out: &mut Vec<u8>) {
    let mut line = status_head(tags, Some(&s.partition));
    line.push_str(&format!(
        " state=\"{}\",event=\"{}\",generation={}i {ts}\n",
        s.state.word(),
        s.event,
        s.generation
    ));
    out.extend_from_slice(line.as_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;
    use tessla_engine::Value;

    fn msg(p: &str, g: u64, promise: i64, changes: &[(i64, &str)], clocks: &[(&str, i64)]) -> Msg {
        Msg {
            p: p.into(),
            g,
            drop: false,
            promise,
            end: false,
            handed: false,
            close: false,
            changes: changes
                .iter()
                .map(|(t, k)| {
                    (
                        *t,
                        k.to_string(),
                        0,
                        SValue::from_value(&Value::Int(*t)).unwrap(),
                    )
                })
                .collect(),
            clocks: clocks.iter().map(|(k, t)| (k.to_string(), *t)).collect(),
            left: Vec::new(),
        }
    }

    #[test]
    fn the_bound_is_the_least_live_promise() {
        let mut ps = Partitions::default();
        assert_eq!(ps.bound(), i64::MAX);
        ps.apply(msg("p0", 1, 10, &[], &[]));
        ps.apply(msg("p1", 1, 7, &[], &[]));
        assert_eq!(ps.bound(), 7);
        let mut end = msg("p1", 1, 9, &[], &[]);
        end.end = true;
        let (_, st) = ps.apply(end);
        assert_eq!(st.last().map(|s| s.event), Some("ended"));
        assert_eq!(ps.bound(), 10);
        let drop = Msg {
            drop: true,
            ..msg("p0", 1, 0, &[], &[])
        };
        let (_, st) = ps.apply(drop);
        assert_eq!(st.first().map(|s| s.event), Some("dropped"));
        assert!(ps.all_done());
        assert_eq!(ps.bound(), i64::MAX);
    }

    #[test]
    fn the_table_goes_on_from_its_state() {
        let mut ps = Partitions::default();
        ps.apply(msg("p0", 3, 10, &[(5, "r1")], &[("r1", 6)]));
        ps.apply(msg("p1", 4, 7, &[], &[]));
        let json = serde_json::to_string(&ps.state()).unwrap();
        let mut back = Partitions::from_state(serde_json::from_str(&json).unwrap());
        assert_eq!(back.bound(), 7);
        // The robot's highest clock came along: its replayed change is a repeat.
        let (d, _) = back.apply(msg("p0", 5, 10, &[(6, "r1"), (7, "r1")], &[("r1", 7)]));
        assert_eq!(d.map(|d| d.changes.len()), Some(1));
        assert_eq!(back.counters.repeats, 1);
    }

    #[test]
    fn every_partition_ended_is_not_the_end_until_a_close() {
        let mut ps = Partitions::default();
        ps.apply(msg("p0", 1, 10, &[], &[]));
        let end = |p: &str, g| Msg {
            end: true,
            ..msg(p, g, 10, &[], &[])
        };
        let close = Msg {
            close: true,
            ..msg("p0", 0, 0, &[], &[])
        };
        ps.apply(end("p0", 1));
        assert!(ps.all_done() && !ps.closed(), "a restart may follow");
        // A close while a partition is live does nothing.
        ps.apply(msg("p0", 2, 10, &[], &[]));
        ps.apply(close.clone());
        assert!(!ps.closed());
        ps.apply(end("p0", 2));
        ps.apply(close);
        assert!(ps.closed());
        // A partition back (a new generation) opens the fleet again.
        ps.apply(msg("p0", 3, 10, &[], &[]));
        assert!(!ps.closed());
    }

    #[test]
    fn a_new_generation_does_not_count_twice_and_an_old_one_counts_nothing() {
        let mut ps = Partitions::default();
        let (d, _) = ps.apply(msg("p0", 3, 0, &[(5, "r1"), (6, "r1")], &[("r1", 6)]));
        assert_eq!(d.map(|d| d.changes.len()), Some(2));
        // The new holder replays from its last save: 5 and 6 again, then 7.
        let (d, st) = ps.apply(msg(
            "p0",
            8,
            0,
            &[(5, "r1"), (6, "r1"), (7, "r1")],
            &[("r1", 7)],
        ));
        assert_eq!(st.first().map(|s| s.event), Some("takeover"));
        let got: Vec<i64> = d
            .map(|d| d.changes.iter().map(|c| c.ts).collect())
            .unwrap_or_default();
        assert_eq!(got, vec![7]);
        assert_eq!(ps.counters.repeats, 2);
        // The fenced-out holder's late message.
        let (d, _) = ps.apply(msg("p0", 3, 0, &[(9, "r1")], &[("r1", 9)]));
        assert!(d.is_none());
        assert_eq!(ps.counters.stale, 1);
    }

    fn end(p: &str, g: u64, promise: i64, handed: bool) -> Msg {
        Msg {
            end: true,
            handed,
            ..msg(p, g, promise, &[], &[])
        }
    }

    #[test]
    fn a_handed_end_holds_the_bound_until_the_standby_takes_over() {
        let mut ps = Partitions::default();
        ps.apply(msg("p0", 1, 10, &[], &[]));
        ps.apply(msg("p1", 1, 7, &[], &[]));
        let (_, st) = ps.apply(end("p1", 1, 9, true));
        assert_eq!(
            st,
            vec![Status {
                partition: "p1".into(),
                generation: 1,
                state: State::Handing,
                event: "handing over",
            }]
        );
        // Held at its promise: p0's records do not step the fleet past it.
        assert_eq!(ps.bound(), 9);
        assert_eq!(ps.handing().collect::<Vec<_>>(), vec![("p1", 1)]);
        assert_eq!(ps.holding_back().count(), 2);
        assert_eq!(ps.live().collect::<Vec<_>>(), vec![("p0", 1)]);
        // Every other partition ended: not done while one hands over.
        ps.apply(end("p0", 1, 10, false));
        assert!(!ps.all_done());
        assert_eq!(ps.bound(), 9);
        // The standby's first entry: live again, at its own promise.
        let (d, st) = ps.apply(msg("p1", 2, 12, &[(11, "r1")], &[("r1", 11)]));
        assert_eq!(
            st.first().map(|s| (s.event, s.state)),
            Some(("takeover", State::Live))
        );
        assert_eq!(st.len(), 1);
        assert_eq!(d.map(|d| d.changes.len()), Some(1));
        assert_eq!(ps.bound(), 12);
        assert_eq!(ps.handing().count(), 0);
    }

    #[test]
    fn the_holders_end_ends_a_partition_handing_over_and_a_stale_one_is_ignored() {
        let mut ps = Partitions::default();
        ps.apply(msg("p0", 1, 10, &[], &[]));
        ps.apply(msg("p1", 1, 7, &[], &[]));
        ps.apply(end("p1", 1, 9, true));
        // No standby of p1 live any more: the fleet level's holder ends it.
        let (d, st) = ps.apply(end("p1", 1, 0, false));
        assert_eq!(
            st.iter().map(|s| (s.event, s.state)).collect::<Vec<_>>(),
            vec![("ended", State::Ended)],
            "no `rejoined` for the holder's bare end"
        );
        assert!(d.is_some_and(|d| d.changes.is_empty() && d.clocks.is_empty()));
        assert_eq!(ps.bound(), 10);
        // Said once: the same end again changes nothing.
        let (_, st) = ps.apply(end("p1", 1, 0, false));
        assert!(st.is_empty(), "{st:?}");
        ps.apply(end("p0", 1, 10, false));
        assert!(ps.all_done());

        // The takeover came before the holder's end (the standby marked its key stale after
        // its first entry): the end, of the older generation, is stale.
        let mut ps = Partitions::default();
        ps.apply(msg("p0", 1, 10, &[], &[]));
        ps.apply(end("p0", 1, 10, true));
        ps.apply(msg("p0", 2, 11, &[], &[]));
        let (d, st) = ps.apply(end("p0", 1, 0, false));
        assert!(d.is_none() && st.is_empty());
        assert_eq!(ps.counters.stale, 1);
        assert_eq!(ps.live().collect::<Vec<_>>(), vec![("p0", 2)]);
        assert_eq!(ps.bound(), 11);
    }

    #[test]
    fn a_partition_handing_over_still_drops_out_when_silent() {
        let mut ps = Partitions::default();
        ps.apply(msg("p0", 1, 10, &[], &[]));
        ps.apply(msg("p1", 1, 7, &[], &[]));
        ps.apply(end("p1", 1, 9, true));
        let (_, st) = ps.apply(Msg {
            drop: true,
            ..msg("p1", 1, 0, &[], &[])
        });
        assert_eq!(st.first().map(|s| s.event), Some("dropped"));
        assert_eq!(ps.bound(), 10);
        assert!(ps.dropped("p1"));
    }

    #[test]
    fn a_table_of_an_earlier_version_loads_and_handing_over_goes_through_a_checkpoint() {
        // `PartsState` as versions without `Handing` wrote it.
        let old = r#"{"parts":[["p0",3,10,"Live"],["p1",4,7,"Ended"],["p2",5,8,"Dropped"]],"high":[["r1",6]],"closed":false,"counters":{"stale":1,"repeats":2}}"#;
        let ps = Partitions::from_state(serde_json::from_str(old).unwrap());
        assert_eq!(ps.bound(), 10);
        assert_eq!(ps.counters.repeats, 2);
        assert!(ps.dropped("p2"));
        // An entry of an earlier version (no `handed`) reads as a plain end.
        let m: Msg = serde_json::from_str(r#"{"p":"p0","g":3,"promise":11,"end":true}"#).unwrap();
        assert!(m.end && !m.handed);

        let mut ps = Partitions::default();
        ps.apply(msg("p0", 1, 10, &[], &[]));
        ps.apply(end("p1", 2, 7, true));
        let json = serde_json::to_string(&ps.state()).unwrap();
        let back = Partitions::from_state(serde_json::from_str(&json).unwrap());
        assert_eq!(back.handing().collect::<Vec<_>>(), vec![("p1", 2)]);
        assert_eq!(back.bound(), 7);
    }

    #[test]
    fn a_status_line_is_line_protocol() {
        let mut out = Vec::new();
        let s = Status {
            partition: "p 0".into(),
            generation: 4,
            state: State::Dropped,
            event: "dropped",
        };
        status_line(&s, &[("site".into(), "a".into())], 12, &mut out);
        assert_eq!(
            String::from_utf8_lossy(&out),
            "tessla_fleet_status,partition=p\\ 0,site=a state=\"dropped\",event=\"dropped\",generation=4i 12\n"
        );
    }
}
