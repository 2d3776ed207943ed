//! Takeovers at the fleet level across NATS partitions (docs/fleet.md, "A fleet of NATS
//! partitions") on a real nats-server with the real binary running the fleet example: a
//! process that starts while its partition lease is held by another (live, or just killed),
//! is fed records while it stands by and takes the lease over must send the fleet every change
//! of the records it replays (its fleet entries, and the fleet's lines, equal one process's);
//! and a fleet level whose holder was SIGKILLed while every other input ends at once is still
//! closed by the last process stopping, so the last steps' lines are written; and a partition
//! handed over to its standby (its holder stopped with SIGTERM) holds the fleet back until the
//! standby's first entry, while the other partition's records flow at once, but drops out
//! when its standby keeps its key live and never takes it over.

use super::fleet_level_nats::{base, example_args, fleet_lines, one_process, records};
use super::fleet_nats_specs::nats_server;
use crate::support::fleet_partitions::{
    TwoPartitions, two_partitions, wait_any_err, wait_fleet_line_from,
};
use crate::support::kv;
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

/// The holder of p0 and of the fleet level is stopped with SIGTERM while p0's standby is live,
/// and p1's next records (far past the silence) are written as soon as the fleet level has
/// taken in p0's end, before the standby's first entry. p0 is handed over, not ended: the
/// fleet holds it at its promise (`handing over`) until the standby's first entry
/// (`takeover`), so p1's records do not step the fleet on without p0 and none of p0's next
/// records is late: the first holder's fleet lines followed by the new holder's equal one
/// process's, line for line. (Before, p0 counted as ended in that window: the fleet stepped
/// on with p1's records, p0's robots left the maps, and their next changes came late.)
#[test]
fn a_partition_handed_over_holds_the_fleet_until_its_standby_takes_over() {
    let server = nats_server("");
    let state = format!("nats://127.0.0.1:{}/fleet_handing", server.port);
    let base = base();
    // p1's records after the stop go 4 s of event time past p0's last: twice the silence.
    let (half, end) = (20, 40);
    let (_, want) = one_process(&records(base, None, 0..end));
    assert!(!want.is_empty());

    let TwoPartitions {
        p0: mut a,
        standby,
        p1: mut b,
    } = two_partitions(&|lease| spawn(&state, lease), true);
    let mut a2 = standby.expect("p0's standby");
    a.write(&records(base, Some(0), 0..half));
    a2.write(&records(base, Some(0), 0..half));
    b.write(&records(base, Some(1), 0..half));
    // Both partitions' first half is in the fleet's lines.
    let near_pause = base + (half - 2) * 200_000_000;
    wait_fleet_line_from(&mut a, "a fleet line near the pause", near_pause);
    a.signal("TERM");
    // p0's end is in the fleet level (p1's process follows it too): p1's records flow at once,
    // while the stopping holder still holds p0's lease (it releases it after its fleet end,
    // so the standby's first entry comes later).
    let from = b.err.len();
    let ended = b.wait_err("p0's end at the fleet level", from, |l| {
        l.contains("fleet: partition p0 (generation")
            && (l.contains(") handing over") || l.contains(") ended"))
    });
    b.write(&records(base, Some(1), half..end));
    a2.write(&records(base, Some(0), half..end));
    let (a_out, a_err, code) = a.finish();
    assert_eq!(code, 0, "{a_err}");
    let new = wait_any_err(&mut [&mut a2, &mut b], "lease.vfleet taken by");
    a2.wait_err("p0 taken over", 0, |l| l.contains("holding partition p0"));
    let (holder, other) = if new == 0 { (a2, b) } else { (b, a2) };
    let (other_out, other_err, code) = other.finish();
    assert_eq!(code, 0, "{other_err}");
    assert!(fleet_lines(&other_out).is_empty(), "{other_out}");
    let (holder_out, holder_err, code) = holder.finish();
    assert_eq!(code, 0, "{holder_err}");
    assert!(
        holder_err.contains("the fleet's input ends"),
        "{holder_err}"
    );

    // The window was hit: p1's process took in p1's last record's entry before p0's
    // takeover (its log of the entries it follows, in the stream's order).
    let b_err = if new == 0 { &other_err } else { &holder_err };
    let last_p1 = base + (end - 1) * 200_000_000;
    let p1_done = b_err.lines().position(|l| {
        entry(l).is_some_and(|e| e.partition == "p1" && e.clocks.iter().any(|(_, t)| *t >= last_p1))
    });
    let p0_back = b_err
        .lines()
        .position(|l| l.contains("fleet: partition p0 (generation") && l.contains(") takeover"));
    assert!(
        p1_done.is_some() && p0_back.is_some() && p1_done < p0_back,
        "p1's records reached the fleet level before p0's takeover ({p1_done:?}, {p0_back:?}):\n{b_err}"
    );

    let mut got = fleet_lines(&a_out);
    let first = got.len();
    got.extend(fleet_lines(&holder_out));
    eprintln!(
        "handed over while p1 went on: one process {} fleet lines; the first holder {first}, the new holder {}",
        want.len(),
        got.len() - first
    );
    assert_eq!(
        got, want,
        "first holder:\n{a_err}\nnew holder:\n{holder_out}\n{holder_err}"
    );

    // The status output names p0 handing over, then its standby's takeover.
    let status: Vec<&str> = a_out
        .lines()
        .chain(holder_out.lines())
        .filter(|l| l.starts_with("tessla_fleet_status,partition=p0"))
        .collect();
    let handing = status
        .iter()
        .position(|l| l.contains("state=\"handing over\",event=\"handing over\""));
    let takeover = status.iter().position(|l| l.contains("event=\"takeover\""));
    assert!(
        handing.is_some() && handing < takeover,
        "p0's end at the fleet level: {ended}\n{status:#?}"
    );
    assert!(
        a_err.contains("a standby of partition p0 is live")
            && a_err.contains("the partition is handed over"),
        "{a_err}"
    );
}

/// A partition handed over whose standby key is renewed but which nobody takes over (here the
/// test renews a standby key of p0 with no process behind it) holds the fleet back only until
/// the drop time and 10 s more have passed since the fleet level's holder found it handing
/// over: then it drops out (`dropped`), and p1's records step the fleet on. Once the key is
/// gone, p1's process, stopping, closes the fleet's input.
#[test]
fn a_hand_over_nobody_takes_drops_out() {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

    let server = nats_server("");
    let bucket = "fleet_no_taker";
    let state = format!("nats://127.0.0.1:{}/{bucket}", server.port);
    let base = base();
    // p1's records after the stop go 4 s of event time past p0's last: twice the silence, so
    // p0's robots, silent, do not hold the fleet back once p0 dropped out.
    let (half, end) = (10, 30);
    let TwoPartitions {
        p0: mut a,
        p1: mut b,
        ..
    } = two_partitions(&|lease| spawn(&state, lease), false);
    a.write(&records(base, Some(0), 0..half));
    b.write(&records(base, Some(1), 0..half));
    wait_fleet_line_from(
        &mut a,
        "a fleet line near the pause",
        base + (half - 2) * 200_000_000,
    );

    // A standby key of p0, renewed every 500 ms until `stop`, then deleted.
    let stop = Arc::new(AtomicBool::new(false));
    let addr = format!("127.0.0.1:{}", server.port);
    let renewer = {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || {
            kv::with_bucket(&addr, bucket, async |kv| {
                let key = "fleet.standby.vp0.pid999999";
                while !stop.load(Ordering::SeqCst) {
                    let now = SystemTime::now()
                        .duration_since(UNIX_EPOCH)
                        .unwrap()
                        .as_nanos();
                    kv.put(key, now.to_string().into()).await.unwrap();
                    tokio::time::sleep(Duration::from_millis(500)).await;
                }
                kv.delete(key).await.unwrap();
            })
        })
    };
    // The key is there before p0's holder ends.
    let start = Instant::now();
    while !kv::with_bucket(&format!("127.0.0.1:{}", server.port), bucket, async |kv| {
        kv::keys(&kv)
            .await
            .iter()
            .any(|k| k == "fleet.standby.vp0.pid999999")
    }) {
        assert!(start.elapsed() < Duration::from_secs(30), "no standby key");
        std::thread::sleep(Duration::from_millis(50));
    }

    a.signal("TERM");
    let (_, a_err, code) = a.finish();
    assert_eq!(code, 0, "{a_err}");
    assert!(a_err.contains("the partition is handed over"), "{a_err}");
    let stopped = Instant::now();
    b.write(&records(base, Some(1), half..end));
    let dropped = b.wait_err("p0 dropped out", 0, |l| {
        l.contains("fleet: partition p0 (generation") && l.contains("has not taken it over")
    });
    // The drop time (twice the 2 s TTL) and 10 s, counted from p1's process's first look.
    assert!(
        stopped.elapsed() >= Duration::from_secs(14),
        "dropped after {:?}: {dropped}",
        stopped.elapsed()
    );
    // p1's records step the fleet on: a fleet line past p0's last record.
    wait_fleet_line_from(
        &mut b,
        "a fleet line of p1's records after the drop-out",
        base + (half + 2) * 200_000_000,
    );
    stop.store(true, Ordering::SeqCst);
    renewer.join().unwrap();
    b.close_stdin();
    let (b_out, b_err, code) = b.finish();
    assert_eq!(code, 0, "{b_err}");
    assert!(
        b_out
            .lines()
            .any(|l| l.starts_with("tessla_fleet_status,partition=p0")
                && l.contains("event=\"dropped\"")),
        "{b_out}"
    );
    assert!(b_err.contains("the fleet's input ends"), "{b_err}");
}
