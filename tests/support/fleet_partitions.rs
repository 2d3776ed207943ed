//! Two partitions of a NATS fleet of the real binary, started as the fleet NATS tests need them
//! before their records flow (docs/fleet.md, "A fleet of NATS partitions"): p0's process holding
//! p0 and the fleet level, a standby for p0 if asked for, and p1's process, until the fleet
//! level names p1 `joined` ([`two_partitions`]); the hand-over when p0's holder, which holds the
//! fleet level too, is stopped ([`hand_over`]); and the waits around them ([`wait_any_err`],
//! [`wait_fleet_line_from`]).

use super::live_child::LiveChild;
use std::time::{Duration, Instant};

/// The processes [`two_partitions`] started.
pub struct TwoPartitions {
    /// p0's holder, which holds the fleet level too.
    pub p0: LiveChild,
    /// p0's standby, when asked for.
    pub standby: Option<LiveChild>,
    pub p1: LiveChild,
}

/// Start p0's process (`spawn("p0")`) and wait until it holds p0 and the fleet level; with
/// `standby`, a second p0 process, until it stands by; then p1's (`spawn("p1")`), until it
/// holds p1 and the fleet level knows it (its heartbeats: `joined`), so no record comes before
/// both partitions are in the fleet.
pub fn two_partitions(spawn: &dyn Fn(&str) -> LiveChild, standby: bool) -> TwoPartitions {
    let mut p0 = spawn("p0");
    p0.wait_err("p0 held", 0, |l| {
        l.contains("partition p0: held by this process")
    });
    p0.wait_err("fleet held", 0, |l| {
        l.contains("partition fleet: held by this process")
    });
    let standby = standby.then(|| {
        let mut s = spawn("p0");
        s.wait_err("p0 standby", 0, |l| {
            l.contains("partition p0: held by another")
        });
        s
    });
    let mut p1 = spawn("p1");
    p1.wait_err("p1 held", 0, |l| {
        l.contains("partition p1: held by this process")
    });
    p0.wait_out("p1 joined", |l| {
        l.starts_with("tessla_fleet_status,partition=p1") && l.contains("joined")
    });
    TwoPartitions { p0, standby, p1 }
}

/// Stop `holder` (p0's holder, holding the fleet level too) with `signal`, then wait until
/// `successor` or `other` takes the fleet level over (`lease.vfleet taken by`) and `successor`
/// (p0's standby, or p0's next process) holds p0. Returns the stopped process's stdout and
/// stderr, and whether the fleet level's new holder is `successor`.
///
/// After SIGTERM with `successor` standing by, p0 is handed over: the fleet level holds it at
/// its promise until `successor`'s first entry (docs/fleet.md, "Partitions that stop"), so
/// records may flow at once. After SIGKILL p0 holds the fleet back only until it drops out
/// (silent for twice the lease TTL), so this waits, as before, until the fleet level's new
/// holder has p0's new generation (`takeover`).
pub fn hand_over(
    holder: LiveChild,
    signal: &str,
    successor: &mut LiveChild,
    other: &mut LiveChild,
) -> (String, String, bool) {
    holder.signal(signal);
    let (out, err, _) = holder.finish();
    let new = wait_any_err(&mut [&mut *successor, &mut *other], "lease.vfleet taken by");
    successor.wait_err("p0 taken over", 0, |l| l.contains("holding partition p0"));
    if signal == "KILL" {
        let fleet_holder = if new == 0 {
            &mut *successor
        } else {
            &mut *other
        };
        fleet_holder.wait_err("p0's new generation at the fleet level", 0, |l| {
            l.contains("fleet: partition p0 (generation") && l.contains("takeover")
        });
    }
    (out, err, new == 0)
}

/// Wait until one of `children` logs `what` on stderr; its index.
pub fn wait_any_err(children: &mut [&mut LiveChild], what: &str) -> usize {
    let start = Instant::now();
    loop {
        for (n, c) in children.iter_mut().enumerate() {
            c.drain_err();
            if c.err.iter().any(|l| l.contains(what)) {
                return n;
            }
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "nobody logged {what}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Wait until `c` writes a fleet metric (`tessla_fleet`, tagged or not) stamped at or after `t`.
pub fn wait_fleet_line_from(c: &mut LiveChild, what: &str, t: i64) {
    c.wait_out(what, |l| {
        (l.starts_with("tessla_fleet ") || l.starts_with("tessla_fleet,"))
            && l.rsplit(' ')
                .next()
                .and_then(|s| s.trim().parse::<i64>().ok())
                .is_some_and(|s| s >= t)
    });
}
