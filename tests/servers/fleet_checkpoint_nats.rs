//! The fleet checkpoint of a large fleet (docs/fleet.md, "A fleet of NATS partitions", "The
//! fleet checkpoint: bounded entries"): 5,000 robots of the fleet example on two partitions of
//! the real binary, on a real nats-server whose `max_payload` is 256 KiB. The checkpoint's JSON
//! is over 1 MiB (one message could not hold it, even on a default server), so it is stored in
//! parts under the head `fleet.checkpoint`; the entries are still deleted (a bounded key count
//! after an idle run), and processes started later from that checkpoint (both partitions' next
//! processes) give, after the first holder's lines, the fleet lines of one process over the same
//! records, line for line.

use super::fleet_level_nats::{base, fleet_lines, one_process, spawn};
use super::fleet_nats_specs::nats_server;
use crate::support::fleet_partitions::{
    TwoPartitions, hand_over, two_partitions, wait_fleet_line_from,
};
use crate::support::kv;
use crate::support::live_child::LiveChild;

const ROBOTS: usize = 5000;
const ROUNDS: i64 = 8;

/// Every robot of partition `p` (robot `i` is in partition `i % 2`; `None`: all) at rounds
/// `ks`, one timestamp per round (5 Hz): lanes 0.5 m apart, 100 to a row, each driving 1 cm a
/// round; the first four of the first two rows are in zone A (x 0..2, y 0..1), so the slow-down
/// fires; one robot in 17 violates P2 at a time.
/// 5,000 robots' monitors and a checkpoint of 1.6 MB: a wait for a line may take longer than
/// the default on two cores running the other tests.
const PATIENT: std::time::Duration = std::time::Duration::from_secs(240);

fn records(base: i64, p: Option<usize>, ks: std::ops::Range<i64>) -> String {
    let mut s = String::new();
    for k in ks {
        let t = base + k * 200_000_000;
        for i in (0..ROBOTS).filter(|i| p.is_none_or(|p| i % 2 == p)) {
            let x = (i % 100) as f64 * 0.5 + 0.01 * k as f64;
            let y = (i / 100) as f64 * 0.5;
            let actual = if (i as i64 + k) % 17 == 0 { 0.5 } else { 0.1 };
            s.push_str(&format!(
                "mqtt_consumer,host=h,topic=tessla/r{i} expectedSpeed=0.1,actualSpeed={actual},x={x:.2},y={y:.2} {t}\n"
            ));
        }
    }
    s
}

/// Every key of `bucket` beginning `fleet.`, and the checkpoint's head.
fn fleet_keys(port: u16, bucket: &str) -> (Vec<String>, Option<serde_json::Value>) {
    kv::with_bucket(&format!("127.0.0.1:{port}"), bucket, async |kv| {
        let mut keys = kv::keys(&kv).await;
        keys.retain(|k| k.starts_with("fleet."));
        let head = kv
            .get("fleet.checkpoint")
            .await
            .unwrap()
            .and_then(|b| serde_json::from_slice(&b).ok());
        (keys, head)
    })
}

/// The parts of a line `fleet: starting from the fleet checkpoint ... B bytes in P parts, ...`.
fn parts_read(l: &str) -> Option<u64> {
    l.split_once(" parts, read in")?
        .0
        .rsplit(' ')
        .next()?
        .parse()
        .ok()
}

#[test]
fn a_fleet_checkpoint_over_the_max_payload_is_stored_in_parts_trims_and_restarts_line_for_line() {
    let server = nats_server("max_payload: 262144");
    let bucket = "fleet_big";
    let state = format!("nats://127.0.0.1:{}/{bucket}", server.port);
    let base = base();
    let half = ROUNDS / 2;
    let (_, want) = one_process(&records(base, None, 0..ROUNDS));
    assert!(
        want.iter().any(|l| l.starts_with("action,")),
        "zone A holds robots together: {}",
        want.len()
    );

    let TwoPartitions {
        p0: mut a,
        p1: mut b,
        ..
    } = two_partitions(&|lease| spawn(&state, lease).patient(PATIENT), false);
    write(&mut a, &records(base, Some(0), 0..half));
    write(&mut b, &records(base, Some(1), 0..half));
    let near_pause = base + (half - 2) * 200_000_000;
    wait_fleet_line_from(&mut a, "a fleet line near the pause", near_pause);
    let (first, _) = fleet_keys(server.port, bucket);
    let first: Vec<String> = first
        .into_iter()
        .filter(|k| k.starts_with("fleet.m."))
        .collect();
    assert!(!first.is_empty());
    // Idle (heartbeats only) until the first half's entries are gone: two checkpoints later.
    let start = std::time::Instant::now();
    let mut keys = Vec::new();
    let mut head = None;
    while start.elapsed() < std::time::Duration::from_secs(60) {
        std::thread::sleep(std::time::Duration::from_millis(500));
        (keys, head) = fleet_keys(server.port, bucket);
        if head.is_some() && !keys.iter().any(|k| first.contains(k)) {
            break;
        }
    }
    assert!(
        !keys.iter().any(|k| first.contains(k)),
        "the first half's entries were never deleted: {} keys",
        keys.len()
    );
    let head = head.expect("a checkpoint head");
    // The checkpoint after every first-half record: its JSON over 1 MiB, in parts.
    let parts = head["parts"].as_u64().expect("a head with parts");
    let json = head["json"].as_u64().expect("a head with the JSON's size");
    assert!(parts >= 2, "{head}");
    assert!(json > 1024 * 1024, "{head}");
    // Bounded: the head, its parts (and a newer one's while it is stored), the holder's
    // progress, a few intervals of heartbeats; never the first half's entries again.
    let (keys, _) = fleet_keys(server.port, bucket);
    let entries = keys.iter().filter(|k| k.starts_with("fleet.m.")).count();
    let cp_parts = keys.iter().filter(|k| k.starts_with("fleet.cp.")).count();
    assert!(entries <= 160, "{entries} fleet entries kept");
    assert!(
        cp_parts as u64 <= 2 * parts,
        "{cp_parts} parts kept: {keys:?}"
    );
    eprintln!(
        "fleet checkpoint: {json} bytes of JSON in {parts} parts; {} entries before trimming, {entries} after, {cp_parts} parts",
        first.len()
    );

    // Both partitions' next processes, started from the checkpoint.
    let (b_out, b_err, code) = b.finish();
    assert_eq!(code, 0, "{b_err}");
    assert!(fleet_lines(&b_out).is_empty());
    let mut b2 = spawn(&state, "p1").patient(PATIENT);
    let mut c = spawn(&state, "p0").patient(PATIENT);
    for p in [&mut b2, &mut c] {
        let l = p.wait_err("the checkpoint", 0, |l| {
            l.contains("fleet: starting from the fleet checkpoint at stream sequence")
        });
        assert!(parts_read(&l).is_some_and(|n| n >= 2), "{l}");
    }
    b2.wait_err("p1 held", 0, |l| {
        l.contains("partition p1: held by this process")
    });
    c.wait_err("p0 standby", 0, |l| {
        l.contains("partition p0: held by another")
    });
    let (a_out, a_err, c_holds) = hand_over(a, "TERM", &mut c, &mut b2);
    write(&mut c, &records(base, Some(0), half..ROUNDS));
    write(&mut b2, &records(base, Some(1), half..ROUNDS));
    let (holder, other) = if c_holds { (c, b2) } else { (b2, c) };
    let (other_out, other_err, code) = other.finish();
    assert_eq!(code, 0, "{other_err}");
    assert!(fleet_lines(&other_out).is_empty());
    let (holder_out, holder_err, code) = holder.finish();
    assert_eq!(code, 0, "{holder_err}");
    let got: Vec<String> = fleet_lines(&a_out)
        .into_iter()
        .chain(fleet_lines(&holder_out))
        .collect();
    if got != want {
        let at = got.iter().zip(&want).position(|(g, w)| g != w);
        panic!(
            "{} fleet lines, {} wanted; first difference at {at:?}: {:?} / {:?}\nfirst holder:\n{}\nnew holder:\n{}",
            got.len(),
            want.len(),
            at.map(|i| &got[i]),
            at.map(|i| &want[i]),
            tail(&a_err),
            tail(&holder_err)
        );
    }
}

/// Write `text` to `c`'s stdin; if it exited, its log's end.
fn write(c: &mut LiveChild, text: &str) {
    if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| c.write(text))).is_err() {
        std::thread::sleep(std::time::Duration::from_millis(500));
        c.drain_err();
        panic!("the process exited: {}", tail(&c.err.concat()));
    }
}

/// The last lines of a log (the full one is long at this size).
fn tail(s: &str) -> String {
    let lines: Vec<&str> = s.lines().collect();
    lines[lines.len().saturating_sub(30)..].join("\n")
}
