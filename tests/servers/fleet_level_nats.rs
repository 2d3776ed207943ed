//! The fleet level across NATS partitions (docs/fleet.md, "A fleet of NATS partitions"), the
//! "done when" of stage two: a real nats-server, two partitions of the real binary running the
//! fleet example (`specs/fleet/`) with `--state nats://...?lease=pN` and `--fleet-spec`, a
//! standby for partition p0, and a takeover in the middle: the holder of the fleet level (also
//! p0's holder) is stopped, the standbys take both leases over, and the fleet outputs written
//! by the first holder and then by the new one equal, line for line, one process's over the same
//! records. With SIGKILL (no save, no release) the new holder may write again the lines of the
//! old one's last progress interval, never others, and the new p0 holder's replay of records
//! the old one had already sent is not counted twice (no change is late at the fleet level).

use super::fleet_nats_specs::nats_server;
use crate::support::child;
use crate::support::fleet_partitions::{
    TwoPartitions, hand_over, two_partitions, wait_fleet_line_from,
};
use crate::support::kv;
use crate::support::live_child::{LiveChild, run_all};

const ROBOTS: usize = 4;
const STEPS: i64 = 120;

/// Event time of step `k`: ten minutes from now (every partition's promise is then its own
/// front, not the wall clock less the silence), 5 Hz.
pub(super) fn base() -> i64 {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as i64;
    now + 600_000_000_000
}

/// Robot `i`'s record at step `k`: lanes 0.4 m apart driving back and forth through zone A
/// (x 0..2, y 0..1) with different phases, so two are in it together at times; robot 3
/// violates P2 now and then.
fn record(base: i64, i: usize, k: i64) -> String {
    let phase = (k + 13 * i as i64) % 60;
    let x = -1.0 + 0.1 * (if phase < 30 { phase } else { 60 - phase }) as f64;
    let y = 0.2 + 0.4 * i as f64;
    let actual = if i == 3 && (k / 10) % 3 == 1 {
        0.5
    } else {
        0.1
    };
    format!(
        "mqtt_consumer,host=h,topic=tessla/r{i} expectedSpeed=0.1,actualSpeed={actual},x={x:.2},y={y:.2} {}\n",
        base + k * 200_000_000 + i as i64 * 1000
    )
}

/// The records of steps `ks` of the robots of partition `p` (robots 0 and 2 in p0, 1 and 3
/// in p1), or of every robot (`None`).
pub(super) fn records(base: i64, p: Option<usize>, ks: std::ops::Range<i64>) -> String {
    let mut s = String::new();
    for k in ks {
        for i in 0..ROBOTS {
            if p.is_none_or(|p| i % 2 == p) {
                s.push_str(&record(base, i, k));
            }
        }
    }
    s
}

pub(super) fn example_args() -> Vec<String> {
    let root = child::root();
    [
        "run",
        "--spec",
        root.join("specs/fleet/robot.tessla").to_str().unwrap(),
        "--instance-by",
        "topic",
        "--fleet-spec",
        root.join("specs/fleet/fleet.tessla").to_str().unwrap(),
        "--max-ahead",
        "off",
        "--allowed-lateness",
        "off",
        "--no-passthrough",
    ]
    .into_iter()
    .map(String::from)
    .collect()
}

/// The example run by one process over `input` (the oracle the partitions are held to): its
/// whole stdout and its fleet lines.
pub(super) fn one_process(input: &str) -> (String, Vec<String>) {
    let (one, err, code) = run_all(
        &example_args()
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
        input,
    );
    assert_eq!(code, 0, "{err}");
    let want = fleet_lines(&one);
    (one, want)
}

pub(super) fn spawn(state: &str, lease: &str) -> LiveChild {
    let mut a = example_args();
    a.extend([
        "--state".to_string(),
        format!("{state}?lease={lease}&ttl=1s"),
    ]);
    LiveChild::spawn(&a.iter().map(String::as_str).collect::<Vec<_>>())
}

/// The fleet's outputs in `out`, in order: its metrics and its actions, not its status lines.
pub(super) fn fleet_lines(out: &str) -> Vec<String> {
    out.lines()
        .filter(|l| {
            l.starts_with("tessla_fleet ")
                || l.starts_with("tessla_fleet,")
                || (l.starts_with("action,") && l.contains("source=fleet"))
        })
        .map(String::from)
        .collect()
}

/// The count in the fleet level's closing line `fleet: N changes ... not counted twice`.
fn repeats(err: &str) -> u64 {
    err.lines()
        .find_map(|l| {
            l.split_once("fleet: ")?
                .1
                .split_once(" changes sent again")?
                .0
                .parse()
                .ok()
        })
        .unwrap_or_else(|| panic!("no closing line of the fleet level: {err}"))
}

fn takeover(signal: &str) {
    let server = nats_server("");
    let state = format!("nats://127.0.0.1:{}/fleet_level", server.port);
    let base = base();
    let (half, all) = (STEPS / 2, 0..STEPS);

    // One process over every record: the fleet lines to match.
    let (one, want) = one_process(&records(base, None, all.clone()));
    assert!(
        want.iter().any(|l| l.starts_with("action,")),
        "the records bring two robots into zone A together: {one}"
    );

    // p0's primary first: it holds p0 and the fleet level; then p0's standby and p1, until
    // the fleet level knows both partitions (their heartbeats) before any record.
    let TwoPartitions {
        p0: mut a,
        standby,
        p1: mut b,
    } = two_partitions(&|lease| spawn(&state, lease), true);
    let mut a2 = standby.expect("p0's standby");

    a.write(&records(base, Some(0), 0..half));
    a2.write(&records(base, Some(0), 0..half));
    b.write(&records(base, Some(1), 0..half));
    // The first holder has written the fleet's lines up to shortly before the pause: stop it
    // there (after SIGKILL, p0's new holder then replays changes the fleet stepped already).
    let near_pause = base + (half - 5) * 200_000_000;
    wait_fleet_line_from(&mut a, "a fleet line near the pause", near_pause);
    let first_written = fleet_lines(&a.out.concat()).len();
    assert!(first_written > 0);
    let (a_out, a_err, a2_holds) = hand_over(a, signal, &mut a2, &mut b);

    a2.write(&records(base, Some(0), half..STEPS));
    b.write(&records(base, Some(1), half..STEPS));
    // The partition without the fleet level ends first, then the holder, which steps what is
    // pending once every partition has ended.
    let (holder, other) = if a2_holds { (a2, b) } else { (b, a2) };
    let (other_out, other_err, code) = other.finish();
    assert_eq!(code, 0, "{other_err}");
    let (holder_out, holder_err, code) = holder.finish();
    assert_eq!(code, 0, "{holder_err}");
    assert!(
        fleet_lines(&other_out).is_empty(),
        "only the fleet level's holder writes its lines: {other_out}"
    );
    assert!(
        holder_err.contains("fleet: holding the fleet level; the previous holder wrote up to"),
        "{holder_err}"
    );
    assert!(
        holder_out.contains("tessla_fleet_status,partition=p0") && holder_out.contains("takeover"),
        "the new p0 holder's generation is named: {holder_out}"
    );

    let before = fleet_lines(&a_out);
    let after = fleet_lines(&holder_out);
    assert!(!after.is_empty(), "the new holder goes on: {holder_out}");
    eprintln!(
        "fleet level takeover ({signal}): one process {} fleet lines; old holder {}, new holder {}; repeats not counted: {}",
        want.len(),
        before.len(),
        after.len(),
        repeats(&holder_err)
    );

    if signal == "TERM" {
        let got: Vec<String> = before.iter().chain(&after).cloned().collect();
        assert_eq!(
            got, want,
            "old holder:\n{a_out}\n{a_err}\nnew holder:\n{holder_out}\n{holder_err}"
        );
    } else {
        // SIGKILL: the old holder's lines are the first of one process's, the new holder's its
        // last; between them at most what the old one wrote after its last recorded progress.
        assert!(want.starts_with(&before), "{a_out}");
        assert!(want.ends_with(&after), "{holder_out}");
        assert!(
            before.len() + after.len() >= want.len(),
            "no line missing: {} + {} < {}",
            before.len(),
            after.len(),
            want.len()
        );
        let repeated = before.len() + after.len() - want.len();
        assert!(repeated <= before.len(), "{repeated}");
    }
    // After SIGKILL (no save) the new p0 holder replays every record from its buffer: what the
    // old one had sent is not counted twice (else the lines above would differ).
    // Counted again, they would be late changes (stepped after the fleet's last step; with
    // the repeats let through this run had 236).
    if signal == "KILL" {
        assert!(repeats(&holder_err) > 0, "{holder_err}");
    }
    assert_eq!(late(&holder_err), 0, "{holder_err}");
}

#[test]
fn a_two_partition_fleet_with_a_takeover_gives_one_process_fleet_lines() {
    takeover("TERM");
}

#[test]
fn a_killed_fleet_level_holder_repeats_lines_never_loses_or_changes_them() {
    takeover("KILL");
}

/// The count in the fleet level's closing line `..., M changes late`.
fn late(err: &str) -> u64 {
    err.lines()
        .filter(|l| l.contains(" changes sent again "))
        .find_map(|l| {
            l.rsplit_once(", ")?
                .1
                .strip_suffix(" changes late")?
                .parse()
                .ok()
        })
        .unwrap_or_else(|| panic!("no closing line of the fleet level: {err}"))
}

/// A partition whose only process dies (no standby) drops out after twice its lease TTL: the
/// fleet level's holder names it in a status line, and the fleet no longer waits for it.
#[test]
fn a_partition_without_a_holder_drops_out_and_is_named() {
    let server = nats_server("");
    let state = format!("nats://127.0.0.1:{}/fleet_drop", server.port);
    let base = base();
    let TwoPartitions {
        p0: mut a, p1: b, ..
    } = two_partitions(&|lease| spawn(&state, lease), false);
    b.signal("KILL");
    let _ = b.finish();
    a.wait_out("p1 dropped", |l| {
        l.starts_with("tessla_fleet_status,partition=p1") && l.contains("state=\"dropped\"")
    });
    // p1 holds nothing back now: p0's records alone move the fleet on.
    a.write(&records(base, Some(0), 0..20));
    a.wait_out("a fleet line", |l| l.starts_with("tessla_fleet "));
    let (_, err, code) = a.finish();
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("fleet: partition p1 (generation")
            && err.contains("drops out of the fleet level"),
        "{err}"
    );
}

/// The keys `fleet.m.*` (the fleet's entries) in `bucket`, and whether `fleet.checkpoint` is
/// there.
fn fleet_keys(port: u16, bucket: &str) -> (Vec<String>, bool) {
    kv::with_bucket(&format!("127.0.0.1:{port}"), bucket, async |kv| {
        let keys = kv::keys(&kv).await;
        let checkpoint = keys.iter().any(|k| k == "fleet.checkpoint");
        let entries = keys
            .into_iter()
            .filter(|k| k.starts_with("fleet.m."))
            .collect();
        (entries, checkpoint)
    })
}

/// Bounded entries: the holder of the fleet level checkpoints it (`fleet.checkpoint`) every
/// 5 s and deletes the entries the checkpoint before covered, so over a long run (heartbeats
/// five a second per partition) the entries stay few; processes started after the trimming
/// (both partitions' next processes) start from the checkpoint, and the fleet lines, the first
/// holder's then the new one's, equal one process's over the same records.
#[test]
fn fleet_entries_stay_bounded_and_a_later_process_starts_from_the_checkpoint() {
    let server = nats_server("");
    let bucket = "fleet_checkpoint";
    let state = format!("nats://127.0.0.1:{}/{bucket}", server.port);
    let base = base();
    let (half, all) = (STEPS / 2, 0..STEPS);
    let (_, want) = one_process(&records(base, None, all.clone()));

    let TwoPartitions {
        p0: mut a,
        p1: mut b,
        ..
    } = two_partitions(&|lease| spawn(&state, lease), false);
    a.write(&records(base, Some(0), 0..half));
    b.write(&records(base, Some(1), 0..half));
    let near_pause = base + (half - 5) * 200_000_000;
    wait_fleet_line_from(&mut a, "a fleet line near the pause", near_pause);
    // The first half's entries are deleted once two checkpoints have passed.
    let (first, _) = fleet_keys(server.port, bucket);
    assert!(!first.is_empty());
    let start = std::time::Instant::now();
    let mut most = 0;
    let mut trimmed = false;
    // A long idle run: heartbeats only (two partitions, five a second: about 250 entries in
    // 25 s without trimming).
    while start.elapsed() < std::time::Duration::from_secs(25) {
        std::thread::sleep(std::time::Duration::from_millis(500));
        let (keys, checkpoint) = fleet_keys(server.port, bucket);
        if !trimmed && checkpoint && !keys.iter().any(|k| first.contains(k)) {
            trimmed = true;
        }
        if trimmed {
            most = most.max(keys.len());
        }
    }
    assert!(trimmed, "the first half's entries were never deleted");
    // Two checkpoint intervals of heartbeats (10 s, 100 entries) and the pause's data.
    assert!(most <= 160, "{most} fleet entries kept");
    eprintln!(
        "fleet checkpoint: {} entries before trimming, at most {most} kept after it",
        first.len()
    );

    // p1's next process and a standby for p0, both started after the trimming.
    let (b_out, b_err, code) = b.finish();
    assert_eq!(code, 0, "{b_err}");
    assert!(fleet_lines(&b_out).is_empty(), "{b_out}");
    let mut b2 = spawn(&state, "p1");
    let mut c = spawn(&state, "p0");
    for p in [&mut b2, &mut c] {
        p.wait_err("the checkpoint", 0, |l| {
            l.contains("fleet: starting from the fleet checkpoint at stream sequence")
        });
    }
    b2.wait_err("p1 held", 0, |l| {
        l.contains("partition p1: held by this process")
    });
    c.wait_err("p0 standby", 0, |l| {
        l.contains("partition p0: held by another")
    });
    let (a_out, a_err, c_holds) = hand_over(a, "TERM", &mut c, &mut b2);
    c.write(&records(base, Some(0), half..STEPS));
    b2.write(&records(base, Some(1), half..STEPS));
    let (holder, other) = if c_holds { (c, b2) } else { (b2, c) };
    let (other_out, other_err, code) = other.finish();
    assert_eq!(code, 0, "{other_err}");
    assert!(fleet_lines(&other_out).is_empty(), "{other_out}");
    let (holder_out, holder_err, code) = holder.finish();
    assert_eq!(code, 0, "{holder_err}");
    let got: Vec<String> = fleet_lines(&a_out)
        .into_iter()
        .chain(fleet_lines(&holder_out))
        .collect();
    assert_eq!(
        got, want,
        "first holder:\n{a_out}\n{a_err}\nnew holder:\n{holder_out}\n{holder_err}"
    );
}

/// The holder of the fleet level stops (stdin closed: a clean stop) after every other
/// partition has ended, while a standby of its own partition is live: its partition is handed
/// over (the fleet level holds it until the standby's first entry) and it hands the fleet
/// level over without closing the fleet's input (a close would step everything pending, and
/// the standby's records after the takeover would come late). The standby takes both leases over
/// and goes on; the fleet lines of both holders equal one process's over the same records.
#[test]
fn a_stopping_fleet_holder_with_a_live_standby_hands_over_without_a_close() {
    let server = nats_server("");
    let state = format!("nats://127.0.0.1:{}/fleet_standby", server.port);
    let base = base();
    let (p1_end, takeover, end) = (25, 22, 40);
    // One process: p1's robots up to step 25, p0's up to 40, in time order.
    let mut input = String::new();
    for k in 0..end {
        for i in (0..ROBOTS).filter(|i| i % 2 == 0 || k < p1_end) {
            input.push_str(&record(base, i, k));
        }
    }
    let (_, want) = one_process(&input);

    let TwoPartitions {
        p0: mut a,
        standby,
        p1: mut b,
    } = two_partitions(&|lease| spawn(&state, lease), true);
    let mut a2 = standby.expect("p0's standby");
    a.write(&records(base, Some(0), 0..takeover));
    a2.write(&records(base, Some(0), 0..takeover));
    b.write(&records(base, Some(1), 0..p1_end));
    let (b_out, b_err, code) = b.finish();
    assert_eq!(code, 0, "{b_err}");
    assert!(fleet_lines(&b_out).is_empty(), "{b_out}");
    a.wait_out("p1 ended", |l| {
        l.starts_with("tessla_fleet_status,partition=p1") && l.contains("event=\"ended\"")
    });
    // Every other partition has ended; p0's standby is live: p0 is handed over, no close.
    let (a_out, a_err, code) = a.finish();
    assert_eq!(code, 0, "{a_err}");
    assert!(
        a_err.contains("a standby of partition p0 is live")
            && a_err.contains("fleet: partition p0 (generation")
            && a_err.contains(") handing over")
            && !a_err.contains("the fleet's input ends"),
        "{a_err}"
    );
    a2.wait_err("p0 taken over", 0, |l| l.contains("holding partition p0"));
    a2.write(&records(base, Some(0), takeover..end));
    let (a2_out, a2_err, code) = a2.finish();
    assert_eq!(code, 0, "{a2_err}");
    // The new holder closes the fleet's input at its own end (no standby left).
    assert!(a2_err.contains("the fleet's input ends"), "{a2_err}");
    let mut got = fleet_lines(&a_out);
    got.extend(fleet_lines(&a2_out));
    assert_eq!(
        got, want,
        "first holder:\n{a_out}\n{a_err}\nnew holder:\n{a2_err}"
    );
}

/// The holder of the fleet level stops first (a restart) while p1's process still reads; p1's
/// input then ends at once, before its lease task has taken the released fleet lease. The
/// process stopping takes the free lease itself, closes the fleet's input and writes the
/// pending lines: both processes' fleet lines equal one process's (before, nobody closed and
/// the last steps' lines were lost).
#[test]
fn a_process_stopping_after_the_fleet_holder_takes_the_free_level_and_closes() {
    let server = nats_server("");
    let state = format!("nats://127.0.0.1:{}/fleet_last", server.port);
    let base = base();
    let end = 20;
    let mut input = String::new();
    for k in 0..end {
        for i in 0..ROBOTS {
            input.push_str(&record(base, i, k));
        }
    }
    let (_, want) = one_process(&input);
    assert!(!want.is_empty());

    let TwoPartitions {
        p0: mut a,
        p1: mut b,
        ..
    } = two_partitions(&|lease| spawn(&state, lease), false);
    a.write(&records(base, Some(0), 0..end));
    b.write(&records(base, Some(1), 0..end));
    // Both partitions are past the step before last (the holder wrote its line).
    let near_end = base + (end - 2) * 200_000_000;
    wait_fleet_line_from(&mut a, "a fleet line near the end", near_end);
    let (a_out, a_err, code) = a.finish();
    assert_eq!(code, 0, "{a_err}");
    assert!(!a_err.contains("the fleet's input ends"), "{a_err}");
    let (b_out, b_err, code) = b.finish();
    assert_eq!(code, 0, "{b_err}");
    assert!(b_err.contains("the fleet's input ends"), "{b_err}");
    let mut got = fleet_lines(&a_out);
    got.extend(fleet_lines(&b_out));
    assert_eq!(got, want, "first holder:\n{a_err}\nlast process:\n{b_err}");
}
