//! Takeovers at the fleet level across NATS partitions (docs/fleet.md, "A fleet of NATS
//! partitions") on a real nats-server with the real binary running the fleet example: a
//! process that starts while its partition lease is held by another (live, or just killed),
//! is fed records while it stands by and takes the lease over must send the fleet every change
//! of the records it replays (its fleet entries, and the fleet's lines, equal one process's);
//! and a fleet level whose holder was SIGKILLed while every other input ends at once is still
//! closed by the last process stopping, so the last steps' lines are written.

use super::fleet_level_nats::{base, example_args, fleet_lines, one_process, records};
use super::fleet_nats_specs::nats_server;
use crate::support::live_child::LiveChild;

/// The lease TTL of every process here (a takeover of a killed holder's lease takes this long).
const TTL: &str = "2s";

/// A partition process of the fleet example on `state`, logging the fleet entries it follows
/// (`D! fleet: entry N from p0 (generation G): C changes, clocks [...]`).
fn spawn(state: &str, lease: &str) -> LiveChild {
    let mut a = example_args();
    a.extend([
        "--state".to_string(),
        format!("{state}?lease={lease}&ttl={TTL}"),
        "--log-level".to_string(),
        "debug".to_string(),
    ]);
    LiveChild::spawn(&a.iter().map(String::as_str).collect::<Vec<_>>())
}

/// A fleet entry as a process logs it: partition, generation, changes, clocks.
struct Entry {
    partition: String,
    generation: u64,
    changes: usize,
    clocks: Vec<(String, i64)>,
}

fn entry(l: &str) -> Option<Entry> {
    let rest = l.split_once("D! fleet: entry ")?.1;
    let rest = rest.split_once(" from ")?.1;
    let (partition, rest) = rest.split_once(" (generation ")?;
    let (generation, rest) = rest.split_once("): ")?;
    let (changes, rest) = rest.split_once(" changes, clocks [")?;
    let clocks = rest.split_once(']')?.0;
    let clocks = clocks
        .split("), ")
        .filter_map(|c| {
            let (k, t) = c
                .trim_start_matches('(')
                .trim_end_matches(')')
                .split_once(", ")?;
            Some((k.trim_matches('"').to_string(), t.parse().ok()?))
        })
        .collect();
    Some(Entry {
        partition: partition.to_string(),
        generation: generation.parse().ok()?,
        changes: changes.parse().ok()?,
        clocks,
    })
}

/// The changes the fleet example's robot spec gives per record: `p2_violated` and `position`.
const CHANGES_PER_RECORD: usize = 2;

/// A process starts while partition p0's lease is held by another (`kill`: SIGKILLed just
/// after; else live, stopped cleanly once the records are fed), is fed p0's first records
/// while it stands by, and takes p0 over. Its fleet entries carry every replayed record's
/// changes (as many as one process's robots give), the entry with the last buffered step's
/// clocks comes without another record, and the fleet lines equal one process's.
fn buffered_records_reach_the_fleet(kill: bool) {
    let server = nats_server("");
    let state = format!(
        "nats://127.0.0.1:{}/fleet_takeover_{}",
        server.port,
        if kill { "kill" } else { "live" }
    );
    let base = base();
    let (buffered, end) = (5, 30);
    let (_, want) = one_process(&records(base, None, 0..end));
    assert!(!want.is_empty());

    // p1 first: it holds p1 and the fleet level; then p0's first holder.
    let mut b = spawn(&state, "p1");
    b.wait_err("fleet held", 0, |l| {
        l.contains("partition fleet: held by this process")
    });
    let mut x = spawn(&state, "p0");
    x.wait_err("p0 held", 0, |l| {
        l.contains("partition p0: held by this process")
    });
    b.wait_out("p0 joined", |l| {
        l.starts_with("tessla_fleet_status,partition=p0") && l.contains("joined")
    });
    // The process that takes p0 over, fed p0's first steps while it stands by.
    let mut a = spawn(&state, "p0");
    a.wait_err("p0 standby", 0, |l| {
        l.contains("partition p0: held by another")
    });
    if kill {
        x.signal("KILL");
    }
    a.write(&records(base, Some(0), 0..buffered));
    let x_err = if kill {
        x.finish().1
    } else {
        // Records come while the holder still holds the lease; then it stops cleanly.
        std::thread::sleep(std::time::Duration::from_millis(300));
        let (_, err, code) = x.finish();
        assert_eq!(code, 0, "{err}");
        err
    };
    let held = a.wait_err("p0 taken over", 0, |l| l.contains("holding partition p0;"));
    assert!(
        held.contains(&format!("replayed {} buffered records", buffered * 2)),
        "{held}"
    );
    // The replayed records' entry comes with no further record: the last buffered step's
    // clocks of both robots, in an entry of the new generation.
    let last = |i: usize| base + (buffered - 1) * 200_000_000 + i as i64 * 1000;
    let line = a.wait_err("the replayed records' entry", 0, |l| {
        entry(l).is_some_and(|e| {
            e.partition == "p0"
                && [0, 2].iter().all(|i| {
                    e.clocks
                        .iter()
                        .any(|(k, t)| *k == format!("tessla/r{i}") && *t >= last(*i))
                })
        })
    });
    let generation = entry(&line).unwrap().generation;
    // Every change of the replayed records is in the new generation's entries so far.
    a.drain_err();
    let sent: usize = a
        .err
        .iter()
        .filter_map(|l| entry(l))
        .filter(|e| e.partition == "p0" && e.generation == generation)
        .map(|e| e.changes)
        .sum();
    assert_eq!(
        sent,
        buffered as usize * 2 * CHANGES_PER_RECORD,
        "the replayed records' changes, in generation {generation}:\n{}",
        a.err.concat()
    );

    a.write(&records(base, Some(0), buffered..end));
    b.write(&records(base, Some(1), 0..end));
    let (a_out, a_err, code) = a.finish();
    assert_eq!(code, 0, "{a_err}");
    assert!(fleet_lines(&a_out).is_empty(), "{a_out}");
    let (b_out, b_err, code) = b.finish();
    assert_eq!(code, 0, "{b_err}");
    assert!(b_err.contains("the fleet's input ends"), "{b_err}");
    assert_eq!(
        fleet_lines(&b_out),
        want,
        "fleet holder:\n{b_err}\nthe process that took p0 over:\n{a_err}\nthe first p0 holder:\n{x_err}"
    );
}

#[test]
fn a_process_taking_a_killed_holders_partition_sends_its_buffered_records_changes() {
    buffered_records_reach_the_fleet(true);
}

#[test]
fn a_process_taking_a_live_holders_partition_sends_its_buffered_records_changes() {
    buffered_records_reach_the_fleet(false);
}

/// The holder of p0 and of the fleet level is SIGKILLed once both partitions are near the
/// end, and p1's input ends at once: nobody else is left to close the fleet's input. p1's
/// process, stopping as the last live partition, waits for the fleet lease to lapse, takes
/// it, lets p0 drop out and closes: the killed holder's fleet lines followed by p1's (the
/// lines of the killed holder's last progress interval written again, identical) equal one
/// process's, line for line, the close's last steps included.
#[test]
fn a_killed_fleet_holder_is_replaced_by_the_last_partition_stopping_which_closes() {
    let server = nats_server("");
    let state = format!("nats://127.0.0.1:{}/fleet_killed_last", server.port);
    let base = base();
    let end = 20;
    let (_, want) = one_process(&records(base, None, 0..end));
    assert!(!want.is_empty());

    let mut a = spawn(&state, "p0");
    a.wait_err("fleet held", 0, |l| {
        l.contains("partition fleet: held by this process")
    });
    let mut b = spawn(&state, "p1");
    a.wait_out("p1 joined", |l| {
        l.starts_with("tessla_fleet_status,partition=p1") && l.contains("joined")
    });
    a.write(&records(base, Some(0), 0..end));
    b.write(&records(base, Some(1), 0..end));
    // Both partitions are past the step before last (the holder wrote its line).
    let near_end = base + (end - 2) * 200_000_000;
    a.wait_out("a fleet line near the end", |l| {
        l.starts_with("tessla_fleet ")
            && l.rsplit(' ')
                .next()
                .and_then(|t| t.trim().parse::<i64>().ok())
                .is_some_and(|t| t >= near_end)
    });
    a.signal("KILL");
    let started = std::time::Instant::now();
    let (b_out, b_err, code) = b.finish();
    let stop = started.elapsed();
    assert_eq!(code, 0, "{b_err}");
    let (a_out, _, _) = a.finish();
    assert!(
        b_err.contains("took the fleet level whose holder fell silent")
            && b_err.contains("the fleet's input ends"),
        "{b_err}"
    );
    // The stop is bounded: the drop time (twice the TTL) and its margin, and the wait for
    // the last live partition, with room for a busy machine.
    assert!(stop < std::time::Duration::from_secs(20), "{stop:?}");
    let before = fleet_lines(&a_out);
    let after = fleet_lines(&b_out);
    // After SIGKILL the new holder writes again the lines the old one wrote after its last
    // recorded progress (docs/fleet.md): identical, so the overlap is dropped once.
    let overlap = (0..=before.len().min(after.len()))
        .rev()
        .find(|n| before[before.len() - n..] == after[..*n])
        .unwrap_or(0);
    let mut got = before.clone();
    got.extend(after[overlap..].iter().cloned());
    eprintln!(
        "killed fleet holder, last partition closing: one process {} fleet lines; the killed holder {}, the last partition {} ({overlap} written again); stop took {stop:?}",
        want.len(),
        before.len(),
        after.len()
    );
    assert_eq!(got, want, "the last partition:\n{b_err}");
}
