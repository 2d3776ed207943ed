//! The combination test's smaller set on real parts: seeded schedules run by real
//! `tessla-telegraf run` processes, two partitions of a fleet on a real nats-server (state in a
//! JetStream bucket with a lease per partition, `--spec-channel`), with real `spec publish`
//! (fleet-wide, canary, renamed and data-incompatible versions, one that does not compile) and
//! restarts of a partition's process in the middle. The oracle is one process started after
//! everything, fed every record in order: it reads the same rollouts and decisions at start.
//! Every publish starts at the next record's time, so a rollout known from the start judges
//! each record as one arriving in the middle does (the documented way to get one switch point
//! everywhere, `--from`). Every line, robot by robot, must equal the oracle's.
//!
//! The fleet level runs too (`--fleet-spec`, docs/fleet.md): a fleet spec over `c`, which every
//! version keeps, and `y`, which version 2 renames (the rule: robots on a version without `y`
//! stop feeding it, and the fleet's `y` map keeps their last value). Both partitions take part
//! in one fleet level (`?lease=`), and a restart that hits the holder of the `fleet` lease hands
//! it over; the fleet lines of every process together are each written once and equal, line
//! for line, the oracle's. The schedule's late records may be more than `--fleet-silence`
//! behind the newest robot, where the fleet's event-time rule depends on the order records
//! arrive in (docs/fleet.md, "Late and provisional values"), so both sides take them in the same
//! order: each record's fleet entry is in the stream (its process logged it) before the next
//! record is written, and the oracle reads one record at a time.

use super::fleet_nats_specs::{BASE_SPEC, Setup, channel_run, nats_server, published, ts};
use crate::support::child;
use crate::support::live_child::LiveChild;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;

/// Versions a schedule publishes: renamed (`z`), one that reads `x` as a Bool (refused by a
/// process that has seen an Int, so aborted), one that does not compile (refused at publish).
const VERSIONS: &[&str] = &[
    BASE_SPEC,
    "in x: Events[Int]\ndef c = count(x)\ndef y = x * 10\nout c\nout y\n",
    "in x: Events[Int]\ndef c = count(x)\ndef z = x + 500\nout c\nout z\n",
    "in x: Events[Bool]\ndef c = count(x)\nout c\n",
    "in x: Events[Int]\nout x + true\n",
];

/// The fleet spec: the sum of the robots' counts and of their `y`s.
const FLEET_SPEC: &str = "in c: Events[Map[String, Int]]\nin y: Events[Map[String, Int]]\n\
liftable def sumOf(m: Map[String, Int]): Int = Map.fold(m, 0, (acc: Int, k: String, v: Int) => acc + v)\n\
out sumOf(c) as counts\nout sumOf(y) as ys\n";

/// One partition's process, and the sync robot whose answer says it has stepped all before.
struct Part {
    child: Option<LiveChild>,
    lease: &'static str,
    sync: &'static str,
}

/// Each partition's sync robot steps `ts(k)`; wait until each has answered (it has stepped all
/// before) and its fleet entry is in the stream.
fn sync(parts: &mut [Part], k: i64, records: &mut Vec<String>) {
    for p in parts {
        let line = format!("m,robot={} x=1i {}\n", p.sync, ts(k));
        let c = p.child.as_mut().unwrap();
        let from = c.err.len();
        c.write(&line);
        let want = format!(" {}", ts(k));
        let sync = format!("robot={},", p.sync);
        c.wait_out("the sync record's answer", |l| {
            l.contains(&sync) && l.trim_end().ends_with(&want)
        });
        wait_entry(c, p.lease, p.sync, from);
        records.push(line);
    }
}

/// Wait until partition `lease`'s process has followed the fleet entry with `robot`'s clock
/// (its `D!` line, after `from` stderr lines): the entry has its place in the stream before
/// the next record is written anywhere.
fn wait_entry(c: &mut LiveChild, lease: &str, robot: &str, from: usize) {
    let part = format!(" from {lease} (generation");
    let clock = format!("(\"{robot}\", ");
    c.wait_err("the record's fleet entry", from, |l| {
        l.contains("D! fleet: entry ") && l.contains(&part) && l.contains(&clock)
    });
}

/// The oracle: one process, its own state bucket, fed one record at a time (each answered
/// before the next: one read each, as the partitions' entries are taken one at a time).
fn oracle(args: &[&str], records: &[String]) -> (String, String) {
    let mut o = LiveChild::spawn(args);
    for (i, r) in records.iter().enumerate() {
        o.write(r);
        let start = std::time::Instant::now();
        loop {
            o.drain_out();
            if o.out.iter().filter(|l| l.starts_with("tessla,")).count() > i {
                break;
            }
            assert!(
                start.elapsed() < std::time::Duration::from_secs(60),
                "the oracle did not answer record {i}: {r}"
            );
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
    }
    let (out, err, code) = o.finish();
    assert_eq!(code, 0, "{err}");
    (out, err)
}

/// The time of a line protocol line.
fn time_of(l: &str) -> i64 {
    l.rsplit(' ')
        .next()
        .and_then(|t| t.trim().parse().ok())
        .unwrap_or(i64::MIN)
}

/// Where `got` and `want` (fleet lines) first differ in time order, with the records around
/// that time.
fn first_difference(got: &[String], want: &[String], records: &[String]) -> String {
    let order = |v: &[String]| {
        let mut v = v.to_vec();
        v.sort_by_key(|l| time_of(l));
        v
    };
    let (g, w) = (order(got), order(want));
    let n = g.iter().zip(&w).take_while(|(a, b)| a == b).count();
    let at = g.get(n).or(w.get(n)).map_or(i64::MAX, |l| time_of(l));
    let around: Vec<&str> = records
        .iter()
        .map(String::as_str)
        .filter(|r| (time_of(r) - at).abs() <= 300_000_000)
        .collect();
    format!(
        "first difference at line {n} (time {at}):\n  partitions: {:?}\n  one process: {:?}\nrecords within 0.3 s, in input order:\n{}",
        g.get(n),
        w.get(n),
        around.concat()
    )
}

/// The fleet level's lines (not its status, stamped with the wall clock), sorted; tagged with
/// the fleet spec's version (`--version-tag`) or not.
fn fleet_lines<'a>(lines: impl Iterator<Item = &'a str>) -> Vec<String> {
    let mut v: Vec<String> = lines
        .filter(|l| l.starts_with("tessla_fleet ") || l.starts_with("tessla_fleet,"))
        .map(String::from)
        .collect();
    v.sort();
    v
}

fn by_robot(lines: impl Iterator<Item = String>) -> BTreeMap<String, Vec<String>> {
    let mut m: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for l in lines.filter(|l| l.starts_with("tessla,")) {
        let robot = l
            .split(' ')
            .next()
            .and_then(|h| h.split(',').find_map(|t| t.strip_prefix("robot=")))
            .unwrap_or("")
            .to_string();
        m.entry(robot).or_default().push(l);
    }
    m
}

#[test]
fn seeded_schedules_on_real_processes_give_the_one_process_lines() {
    let server = nats_server("");
    let url = format!("nats://127.0.0.1:{}", server.port);
    let s = Setup::new();
    let base = child::write(s.dir.path(), "base.tessla", BASE_SPEC);
    let fleet = child::write(s.dir.path(), "fleet.tessla", FLEET_SPEC);
    let fleet = fleet.to_str().unwrap();
    let specs: Vec<_> = VERSIONS
        .iter()
        .enumerate()
        .map(|(i, v)| child::write(s.dir.path(), &format!("v{i}.tessla"), v))
        .collect();
    // The bucket first (the first publish makes it): a rollout for no robot.
    published(&s.publish(&url, &specs[0], &["--select", "robot=none"]), 1);
    let mut revision = 1;
    let (mut total, mut restarts) = (0, 0);
    let (mut fleet_total, mut fleet_holders) = (0, 0);
    for seed in 0..3u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let state = format!("{url}/state_{seed}");
        let args = |lease: &str| {
            let mut a: Vec<String> = channel_run(&url, &s, &base)
                .into_iter()
                .map(String::from)
                .collect();
            a.extend([
                "--state".into(),
                format!("{state}?lease={lease}"),
                "--fleet-spec".into(),
                fleet.into(),
                // The fleet entries each process follows (`D! fleet: entry ...`): the test
                // writes a record once the one before has its place in the stream.
                "--log-level".into(),
                "debug".into(),
            ]);
            a
        };
        let spawn = |lease: &str| {
            let a = args(lease);
            LiveChild::spawn(&a.iter().map(String::as_str).collect::<Vec<_>>())
        };
        let mut parts = [
            Part {
                child: Some(spawn("p0")),
                lease: "p0",
                sync: "s0",
            },
            Part {
                child: Some(spawn("p1")),
                lease: "p1",
                sync: "s1",
            },
        ];
        let mut fleet_out: Vec<String> = Vec::new();
        let mut records: Vec<String> = Vec::new();
        let mut k = 10 * seed as i64 * 100;
        let mut last: BTreeMap<usize, i64> = BTreeMap::new();
        let mut logs = String::new();
        // Both partitions known to the fleet level before the first robot: their sync robots
        // hold its watermark until each partition's changes are in.
        k += 1;
        sync(&mut parts, k, &mut records);
        for _ in 0..24 {
            match rng.random_range(0..10) {
                0..6 => {
                    // A batch of records, then each partition's sync robot.
                    for _ in 0..rng.random_range(1..5) {
                        let robot = rng.random_range(0..4usize);
                        k += 1;
                        let t = match rng.random_range(0..8) {
                            0 => last.get(&robot).map_or(ts(k), |l| l - 20_000_000),
                            1 => *last.get(&robot).unwrap_or(&ts(k)),
                            _ => ts(k),
                        };
                        let l = last.entry(robot).or_insert(t);
                        *l = (*l).max(t);
                        let line = format!("m,robot=r{robot} x={}i {t}\n", rng.random_range(0..50));
                        let p = &mut parts[robot % 2];
                        let c = p.child.as_mut().unwrap();
                        let from = c.err.len();
                        c.write(&line);
                        wait_entry(c, p.lease, &format!("r{robot}"), from);
                        records.push(line);
                    }
                    k += 1;
                    sync(&mut parts, k, &mut records);
                }
                6..8 => {
                    let v = rng.random_range(0..VERSIONS.len());
                    let from = (ts(k + 1)).to_string();
                    let mut a = vec!["--from", from.as_str()];
                    if rng.random_bool(0.4) {
                        a.extend(["--select", "robot=r1,r2,s0"]);
                    }
                    let out = s.publish(&url, &specs[v], &a);
                    match (v, out.status.code()) {
                        (4, Some(2)) => {}
                        (3, Some(5)) | (_, Some(0)) => revision += 1,
                        (_, code) => panic!(
                            "seed {seed}: publish of version {v}: exit {code:?}\n{}{}",
                            child::text(&out.stdout),
                            child::text(&out.stderr)
                        ),
                    }
                    // Every process has acted on the decision before the next record.
                    for p in &mut parts {
                        let r = format!("revision={revision}i");
                        if v != 4 {
                            p.child.as_mut().unwrap().wait_out("the decision", |l| {
                                l.starts_with("tessla_spec,")
                                    && l.contains(&r)
                                    && (l.contains(",outcome=committed,")
                                        || l.contains(",outcome=aborted,"))
                            });
                        }
                    }
                }
                _ => {
                    // A restart of one partition's process: it saves, releases its lease; the
                    // next one takes it and restores each robot at its first record.
                    let p = &mut parts[rng.random_range(0..2usize)];
                    let (out, err, code) = p.child.take().unwrap().finish();
                    assert_eq!(code, 0, "{err}");
                    fleet_out.extend(out.lines().map(String::from));
                    logs.push_str(&err);
                    // The replacement takes the lease at start (a restart, not the end of the
                    // partition's input: the fleet level goes on with it).
                    let mut c = spawn(p.lease);
                    let held = format!("partition {}: held by this process", p.lease);
                    c.wait_err("the replacement's lease", 0, |l| l.contains(&held));
                    p.child = Some(c);
                    restarts += 1;
                }
            }
        }
        // Both inputs end together, so the fleet level's holder sees every partition end and
        // steps everything pending, as the oracle does at its end.
        for p in &mut parts {
            p.child.as_mut().unwrap().close_stdin();
        }
        for p in &mut parts {
            let (out, err, code) = p.child.take().unwrap().finish();
            assert_eq!(code, 0, "{err}");
            fleet_out.extend(out.lines().map(String::from));
            logs.push_str(&err);
        }
        let holders = logs.matches("fleet: holding the fleet level").count();
        assert!(
            holders >= 1,
            "seed {seed}: no process held the fleet level\n{logs}"
        );
        fleet_holders += holders;
        // The oracle: one process, its own state bucket, every record in order.
        let oracle_state = format!("{url}/oracle_{seed}");
        let mut a = channel_run(&url, &s, &base);
        a.extend(["--state", oracle_state.as_str(), "--fleet-spec", fleet]);
        let (out, _) = oracle(&a, &records);
        let (got, want) = (
            fleet_lines(fleet_out.iter().map(String::as_str)),
            fleet_lines(out.lines()),
        );
        assert!(
            !want.is_empty(),
            "seed {seed}: the oracle wrote no fleet line\n{out}"
        );
        // Each line written once, whichever process held the fleet level.
        let mut once = got.clone();
        once.dedup();
        assert_eq!(once, got, "seed {seed}: a fleet line written twice");
        // Line for line the oracle's.
        assert!(
            got == want,
            "seed {seed}: the partitions' fleet lines against one process's: {}\n{}",
            first_difference(&got, &want, &records),
            logs.lines()
                .filter(|l| !l.starts_with("D! "))
                .collect::<Vec<_>>()
                .join("\n")
        );
        fleet_total += got.len();
        let (got, want) = (
            by_robot(fleet_out.into_iter()),
            by_robot(out.lines().map(String::from)),
        );
        assert_eq!(
            got, want,
            "seed {seed}: the fleet's lines (left) against one process's (right)"
        );
        total += want.values().map(Vec::len).sum::<usize>();
    }
    eprintln!(
        "combinations on real processes: {total} lines equal to one process's; {} rollouts, {restarts} restarts; {fleet_total} fleet lines written once, equal to one process's, the fleet level held {fleet_holders} times in 3 seeds",
        revision - 1
    );
    // At least one restart hit the fleet level's holder and another process took over.
    assert!(fleet_holders > 3, "the fleet level never changed hands");
    assert!(
        total > 100 && restarts > 0 && revision > 3,
        "{total} lines compared"
    );
}
