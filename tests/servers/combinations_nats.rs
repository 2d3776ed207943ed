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

/// Fleet spec versions a schedule publishes (`spec publish ROBOT --fleet FILE`): the robot
/// spec each is checked against at publish, the file, and what the fleet does with it.
const FLEET_VERSIONS: &[(usize, &str, FleetFate)] = &[
    // Accepted: the counts shifted, the ys kept.
    (
        0,
        "in c: Events[Map[String, Int]]\nin y: Events[Map[String, Int]]\n\
liftable def sumOf(m: Map[String, Int]): Int = Map.fold(m, 0, (acc: Int, k: String, v: Int) => acc + v)\n\
out sumOf(c) + 1000 as counts\nout sumOf(y) as ys\n",
        FleetFate::Accepted,
    ),
    // Accepted: reads fewer inputs (`c` only).
    (
        0,
        "in c: Events[Map[String, Int]]\nout Map.size(c) as counts\n",
        FleetFate::Accepted,
    ),
    // Accepted: the start-up fleet spec again.
    (0, FLEET_SPEC, FleetFate::Accepted),
    // A type error: refused at publish.
    (
        0,
        "in c: Events[Map[String, Int]]\nout Map.size(c) + true as counts\n",
        FleetFate::RefusedAtPublish,
    ),
    // An input that is no robot output: refused at publish.
    (
        0,
        "in w: Events[Map[String, Int]]\nout Map.size(w) as ws\n",
        FleetFate::RefusedAtPublish,
    ),
    // `z` is version 2's output, so the publish checks; but the running fleet levels do not
    // collect it: every process votes to abort it.
    (
        2,
        "in z: Events[Map[String, Int]]\nout Map.size(z) as zs\n",
        FleetFate::Aborted,
    ),
];

#[derive(Clone, Copy, PartialEq, Debug)]
enum FleetFate {
    Accepted,
    RefusedAtPublish,
    Aborted,
}

/// What a fleet publish of the schedule is: which of [`FLEET_VERSIONS`], its start ahead of
/// the records or behind the fleet level (late), and what follows it at once.
#[derive(Clone, Copy, PartialEq, Debug)]
enum After {
    Nothing,
    /// A restart of the process holding the `fleet` lease: a takeover.
    Takeover,
    /// A restart of the other partition's process.
    Restart,
}

/// The fleet publishes of a schedule, taken in turn (each seed starts further on), so every
/// combination is run: accepted ahead and late, refused at publish and by the vote, each
/// followed by a takeover, a restart or nothing.
const FLEET_CASES: &[(usize, bool, After)] = &[
    (0, false, After::Takeover),
    (3, false, After::Takeover),
    (1, true, After::Restart),
    (5, false, After::Takeover),
    (2, true, After::Takeover),
    (4, false, After::Restart),
    (0, true, After::Nothing),
    (5, false, After::Restart),
    (1, false, After::Nothing),
];

/// One partition's process, and the sync robot whose answer says it has stepped all before.
struct Part {
    child: Option<LiveChild>,
    lease: &'static str,
    sync: &'static str,
    /// The clock of each of its robots in the last fleet entry waited for.
    clocks: BTreeMap<String, i64>,
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
        wait_entry(c, p.lease, p.sync, ts(k), from, &mut p.clocks);
        records.push(line);
    }
}

/// Wait until partition `lease`'s process has followed the fleet entry of `robot`'s record at
/// `t` (its `D!` line, after `from` stderr lines): the entry has its place in the stream
/// before the next record is written anywhere. The entry's clock for the robot is at or after
/// `t` and after the one waited for before (a record at or before the robot's last step is
/// stepped 1 ns after it): a replacement that has just started logs the entries before it too.
fn wait_entry(
    c: &mut LiveChild,
    lease: &str,
    robot: &str,
    t: i64,
    from: usize,
    clocks: &mut BTreeMap<String, i64>,
) {
    let part = format!(" from {lease} (generation");
    let clock = format!("(\"{robot}\", ");
    let after = clocks.get(robot).map_or(t, |c| t.max(c + 1));
    let of = |l: &str| -> Option<i64> {
        if !(l.contains("D! fleet: entry ") && l.contains(&part)) {
            return None;
        }
        l.split(&clock)
            .skip(1)
            .filter_map(|rest| rest.split(')').next()?.trim().parse::<i64>().ok())
            .max()
    };
    let line = c.wait_err("the record's fleet entry", from, |l| {
        of(l).is_some_and(|c| c >= after)
    });
    if let Some(c) = of(&line) {
        clocks.insert(robot.to_string(), c);
    }
}

/// The oracle: one process, its own state bucket, following the channel from the start as the
/// partitions do (it votes, and reads each decision at the point the partitions do), fed one
/// record at a time (each answered before the next: one read each, as the partitions' entries
/// are taken one at a time).
struct Oracle {
    child: LiveChild,
    fed: usize,
}

impl Oracle {
    /// Feed the records it has not had yet, one at a time.
    fn catch_up(&mut self, records: &[String]) {
        for r in &records[self.fed..] {
            self.child.write(r);
            let start = std::time::Instant::now();
            loop {
                self.child.drain_out();
                if self
                    .child
                    .out
                    .iter()
                    .filter(|l| l.starts_with("tessla,"))
                    .count()
                    > self.fed
                {
                    break;
                }
                assert!(
                    start.elapsed() < std::time::Duration::from_secs(60),
                    "the oracle did not answer record {}: {r}",
                    self.fed
                );
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
            self.fed += 1;
        }
    }
}

/// The partition whose process holds the `fleet` lease now (its log's last word on it).
fn fleet_holder(parts: &mut [Part]) -> Option<usize> {
    parts.iter_mut().position(|p| {
        let c = p.child.as_mut().unwrap();
        c.drain_err();
        c.err
            .iter()
            .rev()
            .find_map(|l| {
                if l.contains("fleet: holding the fleet level") {
                    Some(true)
                } else if l.contains("fleet: not holding the fleet level") {
                    Some(false)
                } else {
                    None
                }
            })
            .unwrap_or(false)
    })
}

/// The `spec_version` tag of a line.
fn version_of(l: &str) -> Option<&str> {
    l.split(' ')
        .next()?
        .split(',')
        .find_map(|t| t.strip_prefix("spec_version="))
}

/// The fleet level's `switched` lines (stamped with the switch step's event time: the same in
/// every process), sorted.
fn switched_lines<'a>(lines: impl Iterator<Item = &'a str>) -> Vec<String> {
    let mut v: Vec<String> = lines
        .filter(|l| l.starts_with("tessla_fleet_status") && l.contains("event=\"switched\""))
        .map(String::from)
        .collect();
    v.sort();
    v
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
        "first difference at line {n} (time {at}):\n  partitions: {:#?}\n  one process: {:#?}\nrecords within 0.3 s, in input order:\n{}",
        &g[n.saturating_sub(2)..(n + 4).min(g.len())],
        &w[n.saturating_sub(2)..(n + 4).min(w.len())],
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

/// The `input_unfed` status lines without their wall-clock stamp, sorted.
fn unfed_lines<'a>(lines: impl Iterator<Item = &'a str>) -> Vec<String> {
    let mut v: Vec<String> = lines
        .filter(|l| l.starts_with("tessla_fleet_status") && l.contains("event=\"input_unfed\""))
        .map(|l| l.rsplit_once(' ').map_or(l, |(a, _)| a).to_string())
        .collect();
    v.sort();
    v
}

/// A restart of partition `i`'s process: it saves, releases its lease (and the `fleet` lease
/// when it holds it); the next one takes the partition lease at start and restores each robot
/// at its first record (a restart, not the end of the partition's input: the fleet level goes
/// on with it). `wait_holder`: wait until a process holds the fleet level again (a later step
/// picks the holder); not needed before the seed's end, where a process stopping takes a
/// released `fleet` lease itself (docs/fleet.md, "Partitions that stop").
fn restart(
    parts: &mut [Part],
    i: usize,
    spawn: &dyn Fn(&str) -> LiveChild,
    fleet_out: &mut Vec<String>,
    logs: &mut String,
    wait_holder: bool,
) {
    let p = &mut parts[i];
    let (out, err, code) = p.child.take().unwrap().finish();
    assert_eq!(code, 0, "{err}");
    fleet_out.extend(out.lines().map(String::from));
    logs.push_str(&err);
    let mut c = spawn(p.lease);
    let held = format!("holding partition {};", p.lease);
    c.wait_err("the replacement's lease", 0, |l| l.contains(&held));
    p.child = Some(c);
    if !wait_holder {
        return;
    }
    // A process holds the fleet level again before the next step, which may pick its holder
    // (a restart of its holder hands the `fleet` lease over).
    let start = std::time::Instant::now();
    while fleet_holder(parts).is_none() {
        assert!(
            start.elapsed() < std::time::Duration::from_secs(60),
            "no process took the fleet level over"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// The seeds run.
const SEEDS: [u64; 4] = [0, 1, 2, 3];
/// The schedule's steps per seed.
const STEPS: usize = 24;

/// What the schedule did, over every seed.
#[derive(Default, Debug)]
struct Counts {
    restarts: usize,
    /// Fleet publishes: accepted with a start ahead, accepted late, refused at publish,
    /// aborted by the vote.
    fleet_ahead: usize,
    fleet_late: usize,
    fleet_refused: usize,
    fleet_aborted: usize,
    /// Takeovers of the fleet lease and restarts of the other partition right after an
    /// accepted and right after a refused (at publish or by the vote) fleet publish.
    takeover_after_accepted: usize,
    takeover_after_refused: usize,
    restart_after_accepted: usize,
    restart_after_refused: usize,
    /// Seeds whose end stopped the fleet level's holder first, and of those, the ones where
    /// the other process, stopping, took the released `fleet` lease itself (else its lease
    /// task had taken it before its input ended).
    holder_stopped_first: usize,
    free_lease_taken: usize,
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
    let fleet_specs: Vec<_> = FLEET_VERSIONS
        .iter()
        .enumerate()
        .map(|(i, (_, v, _))| child::write(s.dir.path(), &format!("fleet{i}.tessla"), v))
        .collect();
    // The bucket first (the first publish makes it): a rollout for no robot.
    published(&s.publish(&url, &specs[0], &["--select", "robot=none"]), 1);
    let mut revision = 1;
    let mut total = 0;
    let (mut fleet_total, mut fleet_holders, mut switches, mut unfed) = (0, 0, 0, 0);
    let mut n = Counts::default();
    let mut case = 0;
    // Every fleet spec version accepted so far (the channel keeps them for the next seeds).
    let mut ever_accepted: Vec<String> = Vec::new();
    for seed in SEEDS {
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
        // The oracle: one process, its own state bucket, following the channel from the start.
        let oracle_state = format!("{url}/oracle_{seed}");
        let mut a = channel_run(&url, &s, &base);
        a.extend(["--state", oracle_state.as_str(), "--fleet-spec", fleet]);
        let mut oracle = Oracle {
            child: LiveChild::spawn(&a),
            fed: 0,
        };
        let mut parts = [
            Part {
                child: Some(spawn("p0")),
                lease: "p0",
                sync: "s0",
                clocks: BTreeMap::new(),
            },
            Part {
                child: Some(spawn("p1")),
                lease: "p1",
                sync: "s1",
                clocks: BTreeMap::new(),
            },
        ];
        let mut fleet_out: Vec<String> = Vec::new();
        let mut records: Vec<String> = Vec::new();
        let mut k = 10 * seed as i64 * 100;
        let mut last: BTreeMap<usize, i64> = BTreeMap::new();
        let mut logs = String::new();
        // The fleet spec versions the fleet committed in this seed: revision, version.
        let mut accepted: Vec<(u64, String)> = Vec::new();
        // Both partitions known to the fleet level before the first robot: their sync robots
        // hold its watermark until each partition's changes are in.
        k += 1;
        sync(&mut parts, k, &mut records);
        for step in 0..STEPS {
            match rng.random_range(0..12) {
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
                        // Never an exact repeat (a redelivery, dropped: no fleet entry).
                        let mut x = rng.random_range(0..50);
                        let mut line = format!("m,robot=r{robot} x={x}i {t}\n");
                        while records.contains(&line) {
                            x += 1;
                            line = format!("m,robot=r{robot} x={x}i {t}\n");
                        }
                        let p = &mut parts[robot % 2];
                        let c = p.child.as_mut().unwrap();
                        let from = c.err.len();
                        c.write(&line);
                        wait_entry(c, p.lease, &format!("r{robot}"), t, from, &mut p.clocks);
                        records.push(line);
                    }
                    k += 1;
                    sync(&mut parts, k, &mut records);
                }
                6..8 => {
                    // The oracle has every record before it reads the decision.
                    oracle.catch_up(&records);
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
                    if v != 4 {
                        decided(&mut parts, &mut oracle, revision);
                    }
                }
                8..10 => {
                    // A fleet spec version (docs/fleet.md, "Rollouts of the fleet spec").
                    oracle.catch_up(&records);
                    let (f, late, after) = FLEET_CASES[(case + seed as usize) % FLEET_CASES.len()];
                    case += 1;
                    let (robot_spec, _, fate) = FLEET_VERSIONS[f];
                    // Ahead of the records, or behind the fleet level's last step: it switches
                    // at its next step, where the switch entry is in every process, and where
                    // the oracle reads the decision.
                    let from = if late {
                        ts(k - rng.random_range(2..8))
                    } else {
                        ts(k + 1)
                    }
                    .to_string();
                    let out = s.publish(
                        &url,
                        &specs[robot_spec],
                        &["--fleet", fleet_specs[f].to_str().unwrap(), "--from", &from],
                    );
                    let text = format!(
                        "seed {seed}: fleet publish {f}: exit {:?}\n{}{}",
                        out.status.code(),
                        child::text(&out.stdout),
                        child::text(&out.stderr)
                    );
                    let refused = match (fate, out.status.code()) {
                        (FleetFate::Accepted, Some(0)) => {
                            revision += 1;
                            accepted.push((revision, published(&out, revision)));
                            if late {
                                n.fleet_late += 1;
                            } else {
                                n.fleet_ahead += 1;
                            }
                            false
                        }
                        (FleetFate::RefusedAtPublish, Some(2)) => {
                            assert!(text.contains("was not published"), "{text}");
                            n.fleet_refused += 1;
                            true
                        }
                        (FleetFate::Aborted, Some(5)) => {
                            revision += 1;
                            n.fleet_aborted += 1;
                            true
                        }
                        _ => panic!("{text}"),
                    };
                    if fate != FleetFate::RefusedAtPublish {
                        decided(&mut parts, &mut oracle, revision);
                    }
                    // Right after it: a takeover of the fleet level, or a restart of the
                    // other partition's process.
                    let holder = fleet_holder(&mut parts);
                    let hit = match (after, holder) {
                        (After::Takeover, Some(h)) => Some(h),
                        (After::Restart, Some(h)) => Some(1 - h),
                        _ => None,
                    };
                    if let Some(i) = hit {
                        restart(&mut parts, i, &spawn, &mut fleet_out, &mut logs, true);
                        n.restarts += 1;
                        match (after, refused) {
                            (After::Takeover, false) => n.takeover_after_accepted += 1,
                            (After::Takeover, true) => n.takeover_after_refused += 1,
                            (_, false) => n.restart_after_accepted += 1,
                            (_, true) => n.restart_after_refused += 1,
                        }
                    }
                    // Every process has the switch entry before the next record (a
                    // replacement replays it from the stream).
                    if fate == FleetFate::Accepted {
                        let entry = format!("switch entry for fleet rollout {revision} (");
                        for p in &mut parts {
                            p.child
                                .as_mut()
                                .unwrap()
                                .wait_err("the switch entry", 0, |l| l.contains(&entry));
                        }
                    }
                }
                _ => {
                    let i = rng.random_range(0..2usize);
                    let last = step + 1 == STEPS;
                    restart(&mut parts, i, &spawn, &mut fleet_out, &mut logs, !last);
                    n.restarts += 1;
                }
            }
        }
        // The seed's end, seeded: both inputs end together, so the fleet level's holder sees
        // every partition end and steps everything pending, as the oracle does at its end; or
        // the holder stops first (the other partition is live: it hands over, no close) and
        // the other's input ends at once: that process, stopping, takes the released `fleet`
        // lease (unless its lease task took it first) and closes (docs/fleet.md, "Partitions
        // that stop").
        let first = if rng.random_bool(0.5) {
            fleet_holder(&mut parts)
        } else {
            None
        };
        if let Some(h) = first {
            let (out, err, code) = parts[h].child.take().unwrap().finish();
            assert_eq!(code, 0, "{err}");
            assert!(
                !err.contains("the fleet's input ends"),
                "seed {seed}: the holder closed while another partition was live\n{err}"
            );
            fleet_out.extend(out.lines().map(String::from));
            logs.push_str(&err);
            n.holder_stopped_first += 1;
        }
        for p in parts.iter_mut().filter(|p| p.child.is_some()) {
            p.child.as_mut().unwrap().close_stdin();
        }
        for p in parts.iter_mut().filter(|p| p.child.is_some()) {
            let (out, err, code) = p.child.take().unwrap().finish();
            assert_eq!(code, 0, "{err}");
            if first.is_some() {
                assert!(
                    err.contains("the fleet's input ends"),
                    "seed {seed}: the last process did not close the fleet's input\n{err}"
                );
                n.free_lease_taken +=
                    usize::from(err.contains("took the fleet level its holder released"));
            }
            fleet_out.extend(out.lines().map(String::from));
            logs.push_str(&err);
        }
        let holders = logs.matches("fleet: holding the fleet level").count();
        assert!(
            holders >= 1,
            "seed {seed}: no process held the fleet level\n{logs}"
        );
        fleet_holders += holders;
        oracle.catch_up(&records);
        let (out, _, code) = oracle.child.finish();
        assert_eq!(code, 0, "the oracle");
        // The robots' lines, robot by robot, the oracle's.
        let (got, want) = (
            by_robot(fleet_out.iter().cloned()),
            by_robot(out.lines().map(String::from)),
        );
        assert_eq!(
            got, want,
            "seed {seed}: the fleet's lines (left) against one process's (right)"
        );
        total += want.values().map(Vec::len).sum::<usize>();
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
                .filter(|l| !l.starts_with("D! ") || l.contains("D! fleet: entry"))
                .collect::<Vec<_>>()
                .join("\n")
        );
        // The fleet switched at the same steps, once each.
        let mut switches_this = 0;
        let (got_sw, want_sw) = (
            switched_lines(fleet_out.iter().map(String::as_str)),
            switched_lines(out.lines()),
        );
        assert_eq!(got_sw, want_sw, "seed {seed}: the switches");
        // One switch per version accepted in this seed, unless the records end before its
        // start (the earlier seeds' are in the channel too: every fleet level starts with
        // them, as a process started later does).
        for (r, v) in &accepted {
            let v = format!("version=\"{v}\",revision={r}i,");
            assert!(
                want_sw.iter().filter(|l| l.contains(&v)).count() <= 1,
                "seed {seed}: {v}: {want_sw:#?}"
            );
            switches_this += usize::from(want_sw.iter().any(|l| l.contains(&v)));
        }
        ever_accepted.extend(accepted.iter().map(|(_, v)| v.clone()));
        switches += switches_this;
        // A robot rollout that leaves a fleet input without its robot output (version 2 has no
        // `y`) says so once, in the holder's lines as in one process's (stamped with the wall
        // clock: compared without it).
        let (got_unfed, want_unfed) = (
            unfed_lines(fleet_out.iter().map(String::as_str)),
            unfed_lines(out.lines()),
        );
        assert_eq!(got_unfed, want_unfed, "seed {seed}: the input_unfed lines");
        unfed += want_unfed.len();
        // A refused version never changes a line: every fleet line is the start-up fleet
        // spec's (the earliest line's version) or an accepted one's.
        let first = want
            .iter()
            .min_by_key(|l| time_of(l))
            .and_then(|l| version_of(l))
            .map(String::from);
        for l in &want {
            let v = version_of(l).map(String::from);
            assert!(
                v == first || v.as_ref().is_some_and(|v| ever_accepted.contains(v)),
                "seed {seed}: a fleet line of a version not accepted: {l}"
            );
        }
        fleet_total += got.len();
    }
    eprintln!(
        "combinations on real processes: {total} lines equal to one process's; {} rollouts, {} restarts; {fleet_total} fleet lines written once, equal to one process's, the fleet level held {fleet_holders} times, {switches} fleet switches at the oracle's steps, {unfed} fleet inputs left unfed said once, in seeds {SEEDS:?}; {n:?}",
        revision - 1,
        n.restarts
    );
    // At least one restart hit the fleet level's holder and another process took over.
    assert!(fleet_holders > 3, "the fleet level never changed hands");
    assert!(
        total > 100 && n.restarts > 0 && revision > 3,
        "{total} lines compared"
    );
    assert!(unfed > 0, "no rollout left a fleet input unfed");
    assert!(switches > 3, "{switches} fleet switches");
    // Every fleet combination ran.
    assert!(
        n.fleet_ahead > 0
            && n.fleet_late > 0
            && n.fleet_refused > 0
            && n.fleet_aborted > 0
            && n.takeover_after_accepted > 0
            && n.takeover_after_refused > 0
            && n.restart_after_accepted > 0
            && n.restart_after_refused > 0
            && n.holder_stopped_first > 0,
        "{n:?}"
    );
}

/// Wait until every partition's process and the oracle have acted on rollout `revision`'s
/// decision (its `tessla_spec` line), before the next record.
fn decided(parts: &mut [Part], oracle: &mut Oracle, revision: u64) {
    let r = format!("revision={revision}i");
    let pred = |l: &str| {
        l.starts_with("tessla_spec,")
            && l.contains(&r)
            && (l.contains(",outcome=committed,") || l.contains(",outcome=aborted,"))
    };
    for p in parts {
        p.child.as_mut().unwrap().wait_out("the decision", pred);
    }
    oracle.child.wait_out("the decision", pred);
}
