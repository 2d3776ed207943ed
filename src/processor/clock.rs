//! The live clock: how a monitor instance's time relates to the wall clock on live input.
//!
//! Owns: the wall-clock reading a transport takes once per read ([`Wall`]: records without a
//! timestamp get it, and a record stamped more than `--max-ahead` beyond it is refused); each
//! instance's anchor (its last record's step time and when that record arrived, [`Anchor`]),
//! from which the instance's time is estimated while its input is silent; and the queue of
//! wall-clock deadlines at which an instance's next `delay` firing falls due ([`Deadlines`]).
//!
//! The model (the book, "Time on live input"): an instance's time moves with its records; while no record
//! arrives it moves on with the wall clock from its last record, held back by
//! `--allowed-lateness`, so a `delay` (a watchdog, a timeout, `period`) fires while the robot is
//! quiet. Only instances with an armed `delay` are in the queue, and a record costs the queue
//! nothing unless its instance's deadline moves earlier (a later deadline is found when the
//! earlier entry falls due: the entry is pushed again then).

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::time::{Duration, Instant};

/// The wall clock at one moment: a monotonic instant (for deadlines) and Unix nanoseconds (for
/// timestamps).
#[derive(Debug, Clone, Copy)]
pub struct Wall {
    pub at: Instant,
    pub ns: i64,
}

impl Wall {
    pub fn now() -> Wall {
        Wall {
            at: Instant::now(),
            ns: unix_ns(),
        }
    }

    /// The wall clock `at` (an instant in the past), its Unix time derived from now's.
    pub fn at(at: Instant) -> Wall {
        let now = Wall::now();
        let back = now.at.saturating_duration_since(at);
        Wall {
            at,
            ns: now.ns.saturating_sub(ns_of(back)),
        }
    }
}

/// Unix time in nanoseconds (0 before 1970, `i64::MAX` past 2262).
pub fn unix_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, ns_of)
}

/// A duration in nanoseconds, saturating.
pub fn ns_of(d: Duration) -> i64 {
    i64::try_from(d.as_nanos()).unwrap_or(i64::MAX)
}

/// An instance's last record: the time of its step and when it arrived.
#[derive(Debug, Clone, Copy)]
pub struct Anchor {
    pub ts: i64,
    pub at: Instant,
}

impl Anchor {
    /// When (wall clock) the instance's time reaches `target`: the anchor's arrival plus the
    /// time from its step to `target`, plus `lateness`. `None` when that is beyond what an
    /// [`Instant`] holds (a delay of centuries never falls due).
    pub fn deadline(&self, target: i64, lateness: Duration) -> Option<Instant> {
        let ahead = u64::try_from(target.saturating_sub(self.ts)).unwrap_or(0);
        self.at
            .checked_add(Duration::from_nanos(ahead))?
            .checked_add(lateness)
    }

    /// The instance's time at `now`: the anchor's step time plus the wall time since it
    /// arrived, less `lateness` (never before the anchor).
    pub fn time_at(&self, now: Instant, lateness: Duration) -> i64 {
        let since = now.saturating_duration_since(self.at);
        self.ts
            .saturating_add(ns_of(since.saturating_sub(lateness)))
    }
}

/// Wall-clock deadlines of instances' next `delay` firings, earliest first. An entry names the
/// instance by its slot and its id (a slot is reused after an eviction; the id is not). Entries
/// go stale when their instance's deadline moves; the owner checks each popped entry against
/// the instance's own record of its queued deadline.
#[derive(Default)]
pub struct Deadlines {
    heap: BinaryHeap<Reverse<(Instant, u64, usize)>>,
}

impl Deadlines {
    pub fn push(&mut self, at: Instant, id: u64, slot: usize) {
        self.heap.push(Reverse((at, id, slot)));
    }

    /// The earliest deadline queued (possibly stale: waking for it early is harmless).
    pub fn next(&self) -> Option<Instant> {
        self.heap.peek().map(|Reverse((at, _, _))| *at)
    }

    /// The earliest entry if it is due at `now`, taken off the queue.
    pub fn pop_due(&mut self, now: Instant) -> Option<(Instant, u64, usize)> {
        if self.next()? > now {
            return None;
        }
        self.heap.pop().map(|Reverse(e)| e)
    }

    pub fn clear(&mut self) {
        self.heap.clear();
    }

    pub fn len(&self) -> usize {
        self.heap.len()
    }

    pub fn is_empty(&self) -> bool {
        self.heap.is_empty()
    }
}

/// Render a duration in nanoseconds for a message (`3.2s`, `1h 2m`).
pub fn human_ns(ns: i64) -> String {
    let d = Duration::from_nanos(ns.unsigned_abs());
    // Whole milliseconds read best; below a millisecond, the exact value.
    let d = if d >= Duration::from_millis(1) {
        Duration::from_millis(u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
    } else {
        d
    };
    humantime::format_duration(d).to_string()
}

/// An event time for messages: RFC 3339 with nanoseconds.
pub fn show_time(ns: i64) -> String {
    match u64::try_from(ns) {
        Ok(n) => humantime::format_rfc3339_nanos(
            std::time::UNIX_EPOCH + std::time::Duration::from_nanos(n),
        )
        .to_string(),
        Err(_) => format!("{ns} ns"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_anchor_maps_instance_time_to_the_wall_clock_and_back() {
        let at = Instant::now();
        let a = Anchor { ts: 1_000, at };
        let late = Duration::from_millis(250);
        let d = a.deadline(1_000 + 1_000_000_000, late).unwrap();
        assert_eq!(d - at, Duration::from_millis(1250));
        // At the deadline the instance's time is exactly the target.
        assert_eq!(a.time_at(d, late), 1_000 + 1_000_000_000);
        // Before the lateness has passed, time stands at the anchor.
        assert_eq!(a.time_at(at + Duration::from_millis(100), late), 1_000);
        // A target before the anchor is due after the lateness alone.
        assert_eq!(a.deadline(0, late).unwrap() - at, late);
        // A delay of centuries never falls due.
        assert!(a.deadline(i64::MAX, Duration::MAX).is_none());
    }

    #[test]
    fn deadlines_pop_in_order_and_only_when_due() {
        let t = Instant::now();
        let mut q = Deadlines::default();
        q.push(t + Duration::from_secs(2), 1, 0);
        q.push(t + Duration::from_secs(1), 2, 1);
        assert_eq!(q.next(), Some(t + Duration::from_secs(1)));
        assert_eq!(q.pop_due(t), None);
        assert_eq!(
            q.pop_due(t + Duration::from_secs(3)),
            Some((t + Duration::from_secs(1), 2, 1))
        );
        assert_eq!(q.len(), 1);
        assert_eq!(q.pop_due(t + Duration::from_secs(1)), None);
    }

    #[test]
    fn durations_read_as_people_write_them() {
        assert_eq!(human_ns(3_600_000_000_000), "1h");
        assert_eq!(human_ns(1_500_000_000), "1s 500ms");
        assert_eq!(human_ns(-2_000_000), "2ms");
        assert_eq!(human_ns(5), "5ns");
    }
}
