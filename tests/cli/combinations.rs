//! The combination test: seeded schedules of everything that happens to a fleet at once,
//! run in-process against a one-process oracle (Jepsen's checkers and FoundationDB's
//! simulation are the models).
//!
//! A schedule mixes, for three to five robots: records in order, at equal times, late (stepped
//! after the clock, or dropped: `--late drop`), ahead of the clock, with bad values and
//! over-long; silences past `--instance-idle` and past a watchdog `delay`; publishes
//! (fleet-wide, canary, renamed, added and removed outputs, an input of the record's own time
//! added and removed (`@TelegrafTime`), a spec that does not compile, one that reads the data
//! as the wrong type, one signed by a key nobody trusts, and a forged decision), rollbacks (a
//! publish of an earlier version), SIGHUP;
//! and, per schedule, one of two fleets:
//! - **threads**: one process with 1 to 3 threads (no `--state`: the only way threads run),
//!   `--allowed-lateness` on (watchdogs fire by the wall clock), maybe `--instance-idle`;
//! - **partitions**: one or two partitions, each an active process with `--state` and maybe a
//!   standby; restarts, takeovers (a clean stop), crashes (the standby restores the last save
//!   and replays the records since, as the NATS fleet's replay buffer does), saves, and
//!   `--max-instances` below the robot count with one partition.
//!
//! Every publish is decided as `spec publish` decides it (`spec_feed::decide`: the votes of
//! every live process, actives and standbys) and delivered with its decision to every process,
//! and to processes that start later with the channel's history.
//!
//! Checked, for every schedule:
//! - every output line of the fleet, per robot and in order (measurement, tags with the
//!   version tag, field names, values, time), equals the oracle's: one process with one
//!   thread, no failure, fed the same records, silences and decided rollouts (the lines a
//!   crashed process wrote after its last save are re-written by the replay: the allowed
//!   repeats, dropped from the comparison and counted);
//! - each line's field names are the outputs of the version its tag names, and its value
//!   field was computed by that version (each version writes `x * 10 + k` with its own `k`);
//! - every process that acted on a rollout acted as the decision says, none voted on a rollout
//!   decided before it started, and none found a committed version unrunnable.
//!
//! Not combined (what the docs say differs, so no oracle line exists): a restart with
//! wall-clock features (a restored instance's silence and idle time count from its restore),
//! a crash after a rollout was committed since the last save (the replay judges the records
//! since the save by the rollouts known at the replay: `late_instances`), and
//! `--max-instances` over threads or partitions (each thread and process keeps its own share).
//!
//! `COMBINATION_SEEDS=N` runs N schedules (default 300; `make combinations SEEDS=N`),
//! `COMBINATION_SEED=S` one: a failure prints its seed and its schedule.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tessla_telegraf::processor::clock::Wall;
use tessla_telegraf::processor::instance_table::shard_of;
use tessla_telegraf::processor::versions::Selector;
use tessla_telegraf::processor::{LateMode, Options, Processor};
use tessla_telegraf::spec_feed::bundle::{Bundle, BundleFile, Link};
use tessla_telegraf::spec_feed::decide::{self, Tally};
use tessla_telegraf::spec_feed::error::RolloutError;
use tessla_telegraf::spec_feed::reload::SpecSource;
use tessla_telegraf::spec_feed::sign::RecordError;
use tessla_telegraf::spec_feed::{
    Arrival, Channel, Decision, Event, Outcome, Phase, Rollout, Updates, Vote,
};
use tessla_telegraf::state::Context;
use tessla_telegraf::state::file as state_file;

/// The event time schedules start at (the wall clock follows it 50 ms behind).
const T0: i64 = 1_700_000_000_000_000_000;
const MS: i64 = 1_000_000;
/// Lines longer than this are refused by the splitter (one schedule op writes one).
const MAX_RECORD: usize = 64 * 1024;

/// A version of the pool: its output named `name` writes `x * 10 + k`; `quiet` is the
/// watchdog (`delay` 300 ms after each record), `d` an added output; `stamp` reads each
/// record's own time (`@TelegrafTime`) and writes `lag`, how far its step is after it (0, or
/// more for a late record stepped after its robot's clock).
struct Version {
    name: &'static str,
    k: i64,
    quiet: bool,
    extra: bool,
    stamp: bool,
}

const POOL: &[Version] = &[
    Version {
        name: "v",
        k: 0,
        quiet: true,
        extra: false,
        stamp: false,
    },
    Version {
        name: "v",
        k: 1,
        quiet: true,
        extra: false,
        stamp: false,
    },
    // Renamed.
    Version {
        name: "w",
        k: 2,
        quiet: true,
        extra: false,
        stamp: false,
    },
    // An output added.
    Version {
        name: "v",
        k: 3,
        quiet: true,
        extra: true,
        stamp: false,
    },
    // The watchdog removed, renamed.
    Version {
        name: "u",
        k: 4,
        quiet: false,
        extra: false,
        stamp: false,
    },
    // The record's own time added as an input (and dropped again by any other version).
    Version {
        name: "v",
        k: 5,
        quiet: true,
        extra: false,
        stamp: true,
    },
];

fn spec_text(v: &Version) -> String {
    let mut s = format!(
        "in x: Events[Int]\ndef c = count(x)\ndef {} = x * 10 + {}\nout c\nout {}\n",
        v.name, v.k, v.name
    );
    if v.quiet {
        s.push_str("def quiet = delay(const(300000000, x), x)\nout quiet\n");
    }
    if v.extra {
        s.push_str("def d = x + 1000\nout d\n");
    }
    if v.stamp {
        s.push_str(
            "def @TelegrafTime\n@TelegrafTime\nin mt: Events[Int]\ndef lag = on(x, time(x) - mt)\nout lag\n",
        );
    }
    s
}

/// Does not compile.
const BROKEN: &str = "in x: Events[Int]\nout x + true\n";
/// Reads the records' Int as a Bool.
const INCOMPATIBLE: &str = "in x: Events[Bool]\ndef c = count(x)\nout c\n";

fn bundle(text: &str) -> Bundle {
    Bundle {
        files: vec![BundleFile {
            name: "pool.tessla".into(),
            text: text.into(),
        }],
        links: vec![Link {
            from: None,
            written: "pool.tessla".into(),
            file: 0,
        }],
    }
}

#[derive(Debug, Clone, Copy)]
enum Kind {
    Normal,
    Equal,
    Late,
    Ahead,
    Bad,
    Long,
}

#[derive(Debug, Clone, Copy)]
enum What {
    Pool(usize),
    Broken,
    Incompatible,
}

#[derive(Debug, Clone, Copy)]
enum Trust {
    Signed,
    Untrusted,
    ForgedDecision,
}

#[derive(Debug, Clone)]
enum Op {
    Record {
        robot: usize,
        kind: Kind,
        x: i64,
    },
    Silence {
        ms: i64,
    },
    Publish {
        what: What,
        select: Option<Vec<usize>>,
        /// Its start from the current event time (ms; negative: in the past).
        from_ms: i64,
        trust: Trust,
    },
    Sighup,
    Save {
        partition: usize,
    },
    Restart {
        partition: usize,
    },
    Takeover {
        partition: usize,
    },
    Crash {
        partition: usize,
    },
}

#[derive(Debug, Clone)]
enum Fleet {
    Threads {
        threads: usize,
        idle: bool,
    },
    Partitions {
        partitions: usize,
        standby: bool,
        max_instances: Option<usize>,
    },
}

#[derive(Debug, Clone)]
struct Schedule {
    robots: usize,
    fleet: Fleet,
    ops: Vec<Op>,
    /// `--late drop` instead of the default `shift`.
    late_drop: bool,
}

fn generate(seed: u64) -> Schedule {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let robots = rng.random_range(3..=5);
    let fleet = if rng.random_bool(0.5) {
        Fleet::Threads {
            threads: rng.random_range(1..=3),
            idle: rng.random_bool(0.5),
        }
    } else {
        let partitions = rng.random_range(1..=2);
        Fleet::Partitions {
            partitions,
            standby: rng.random_bool(0.6),
            max_instances: (partitions == 1 && rng.random_bool(0.3))
                .then(|| rng.random_range(2..robots)),
        }
    };
    let partitions = match fleet {
        Fleet::Threads { .. } => 0,
        Fleet::Partitions { partitions, .. } => partitions,
    };
    let mut ops = Vec::new();
    let n = rng.random_range(30..80);
    // The first record comes first: a publish before any data is checked against nothing.
    ops.push(Op::Record {
        robot: 0,
        kind: Kind::Normal,
        x: 1,
    });
    for _ in 0..n {
        let roll = rng.random_range(0..100);
        let op = match roll {
            0..55 => Op::Record {
                robot: rng.random_range(0..robots),
                kind: match rng.random_range(0..40) {
                    0..3 => Kind::Equal,
                    3..7 => Kind::Late,
                    7 => Kind::Ahead,
                    8..10 => Kind::Bad,
                    10 => Kind::Long,
                    _ => Kind::Normal,
                },
                x: rng.random_range(0..50),
            },
            55..63 => Op::Silence {
                ms: *[100, 400, 1300, 2600]
                    .get(rng.random_range(0..4))
                    .unwrap_or(&100),
            },
            63..78 => Op::Publish {
                what: match rng.random_range(0..12) {
                    0 => What::Broken,
                    1 => What::Incompatible,
                    _ => What::Pool(rng.random_range(0..POOL.len())),
                },
                select: rng.random_bool(0.4).then(|| {
                    let mut s: Vec<usize> = (0..robots).filter(|_| rng.random_bool(0.5)).collect();
                    if s.is_empty() {
                        s.push(0);
                    }
                    s
                }),
                from_ms: *[-500, 0, 1, 150, 700, 2000]
                    .get(rng.random_range(0..6))
                    .unwrap_or(&0),
                trust: match rng.random_range(0..14) {
                    0 => Trust::Untrusted,
                    1 => Trust::ForgedDecision,
                    _ => Trust::Signed,
                },
            },
            78..81 => Op::Sighup,
            _ if partitions == 0 => Op::Silence { ms: 100 },
            81..88 => Op::Save {
                partition: rng.random_range(0..partitions),
            },
            88..93 => Op::Restart {
                partition: rng.random_range(0..partitions),
            },
            93..97 => Op::Takeover {
                partition: rng.random_range(0..partitions),
            },
            _ => Op::Crash {
                partition: rng.random_range(0..partitions),
            },
        };
        ops.push(op);
    }
    let late_drop = rng.random_bool(0.25);
    Schedule {
        robots,
        fleet,
        ops,
        late_drop,
    }
}

/// A channel stand-in: what the bus delivered, and what the process reported.
#[derive(Clone, Default)]
struct Stand {
    events: Arc<Mutex<Vec<Event>>>,
    reports: Arc<Mutex<Vec<Outcome>>>,
}

impl Channel for Stand {
    fn poll(&mut self) -> Vec<Event> {
        std::mem::take(&mut *self.events.lock().unwrap())
    }
    fn report(&mut self, _: &str, _: &str, outcomes: &[Outcome]) {
        *self.reports.lock().unwrap() = outcomes.to_vec();
    }
}

/// What every process of a schedule shares.
struct World {
    spec_path: PathBuf,
    opts: Options,
    ctx: Context,
    t0: Instant,
}

impl World {
    fn wall(&self, w: i64) -> Wall {
        Wall {
            at: self.t0 + Duration::from_nanos(u64::try_from(w).unwrap_or(0)),
            ns: T0 + w - 50 * MS,
        }
    }
}

/// One process: its threads' processors, its view of the channel, its output.
struct Process {
    procs: Vec<Processor>,
    updates: Updates,
    stand: Stand,
    out: Vec<u8>,
    /// Revisions decided before it started (it must never vote on them).
    decided_before: Vec<u64>,
}

impl Process {
    fn start(world: &World, threads: usize, history: &[Event], decided: Vec<u64>) -> Process {
        let source = SpecSource {
            path: Some(world.spec_path.clone()),
            options: Default::default(),
        };
        let (loaded, b) = source.load().unwrap();
        let mut first = Processor::new(loaded.program, world.opts.clone()).unwrap();
        first.name_base(&b.id(), "");
        let mut procs = vec![first];
        for _ in 1..threads {
            let s = procs[0].sibling().unwrap();
            procs.push(s);
        }
        let share = world.opts.max_instances / threads;
        if threads > 1 {
            for p in &mut procs {
                p.keep_instances(share);
            }
        }
        let stand = Stand::default();
        let mut updates = Updates::new(source, false, "");
        updates.with_channel(Box::new(stand.clone()), history.to_vec());
        let mut p = Process {
            procs,
            updates,
            stand,
            out: Vec::new(),
            decided_before: decided,
        };
        p.tick();
        p
    }

    fn tick(&mut self) {
        let mut refs: Vec<&mut Processor> = self.procs.iter_mut().collect();
        self.updates.tick(&mut refs, &mut self.out);
    }

    fn deliver(&mut self, e: Event) {
        self.stand.events.lock().unwrap().push(e);
        self.tick();
    }

    fn record(&mut self, world: &World, w: i64, line: &str) {
        let by = &world.opts.instance_by;
        let n = self.procs.len();
        let i = shard_of(line.as_bytes(), by, n);
        let p = &mut self.procs[i];
        p.set_wall(world.wall(w));
        let mut s = lineproto::RecordSplitter::new(MAX_RECORD);
        s.push(line.as_bytes());
        while let Some(r) = s.next_record() {
            p.record(&r, &mut self.out);
        }
        while let Some(r) = s.finish() {
            p.record(&r, &mut self.out);
        }
        p.end_of_read();
    }

    fn silence(&mut self, world: &World, w: i64) {
        let wall = world.wall(w);
        for p in &mut self.procs {
            p.set_wall(Wall {
                at: wall.at,
                ns: wall.ns,
            });
            p.advance_wall(wall.at, &mut self.out);
        }
    }

    fn hangup(&mut self) {
        let mut refs: Vec<&mut Processor> = self.procs.iter_mut().collect();
        self.updates.hangup(&mut refs, &mut self.out);
    }

    /// Its check outcome (vote) for `revision`, if it voted.
    fn vote(&self, revision: u64) -> Option<Outcome> {
        self.stand
            .reports
            .lock()
            .unwrap()
            .iter()
            .rev()
            .find(|o| o.revision == revision && o.phase == Phase::Check)
            .cloned()
    }
}

/// A partition: its state file, its active process, maybe a standby; the records it received
/// since its last save (the standby's replay buffer) and where the active's output stood then.
struct Partition {
    file: PathBuf,
    active: Process,
    standby: Option<Process>,
    since_save: Vec<(i64, String)>,
    out_at_save: usize,
    committed_since_save: bool,
    /// Output of processes that have stopped, in order.
    done: Vec<u8>,
}

struct Run {
    lines: Vec<u8>,
    repeats: usize,
    problems: Vec<String>,
    /// Per revision: the decision.
    decisions: Vec<(u64, Result<Decision, RolloutError>)>,
    outcomes: Vec<Vec<Outcome>>,
    /// Every version id the schedule published: its place in [`POOL`] (`None`: the
    /// incompatible one, whose only output is `c`).
    versions: BTreeMap<String, Option<usize>>,
}

fn line(robot: usize, kind: Kind, x: i64, ts: i64) -> String {
    match kind {
        Kind::Bad => format!("m,robot=r{robot} x=\"oops\" {ts}\n"),
        Kind::Long => format!(
            "m,robot=r{robot} x={x}i,blob=\"{}\" {ts}\n",
            "z".repeat(MAX_RECORD + 10)
        ),
        _ => format!("m,robot=r{robot} x={x}i {ts}\n"),
    }
}

fn options(s: &Schedule) -> Options {
    let mut o = Options {
        passthrough: false,
        instance_by: vec!["robot".into()],
        version_tag: Some("spec_version".into()),
        late: if s.late_drop {
            LateMode::Drop
        } else {
            LateMode::Shift
        },
        ..Options::default()
    };
    match s.fleet {
        Fleet::Threads { idle, .. } => {
            o.instance_idle = idle.then_some(Duration::from_millis(1000));
        }
        Fleet::Partitions { max_instances, .. } => {
            o.allowed_lateness = None;
            if let Some(m) = max_instances {
                o.max_instances = m;
            }
        }
    }
    o
}

/// Why a rollout or decision signed with a key not trusted is refused.
fn foreign() -> RolloutError {
    RecordError::Untrusted {
        signer: "OFOREIGN".into(),
    }
    .into()
}

/// Run `s` on the fleet it names (`oracle`: one process, one thread, no failure, taking the
/// decisions in `given`).
fn run(s: &Schedule, dir: &Path, oracle: Option<&[(u64, Result<Decision, RolloutError>)]>) -> Run {
    let spec_path = dir.join("base.tessla");
    std::fs::write(&spec_path, spec_text(&POOL[0])).unwrap();
    let world = World {
        spec_path,
        opts: options(s),
        ctx: Context {
            instance_by: vec!["robot".into()],
            ..Context::default()
        },
        t0: Instant::now(),
    };
    let mut versions = BTreeMap::new();
    let base_id = SpecSource {
        path: Some(world.spec_path.clone()),
        options: Default::default(),
    }
    .load()
    .unwrap()
    .1
    .id();
    versions.insert(base_id, Some(0));
    let (threads, n_part, standby) = match (&s.fleet, oracle) {
        (_, Some(_)) => (1, 1, false),
        (Fleet::Threads { threads, .. }, None) => (*threads, 1, false),
        (
            Fleet::Partitions {
                partitions,
                standby,
                ..
            },
            None,
        ) => (1, *partitions, *standby),
    };
    let stateful = oracle.is_none() && matches!(s.fleet, Fleet::Partitions { .. });
    let mut history: Vec<Event> = Vec::new();
    let mut decided: Vec<u64> = Vec::new();
    let mut parts: Vec<Partition> = (0..n_part)
        .map(|k| Partition {
            file: dir.join(format!("p{k}.state")),
            active: Process::start(&world, threads, &[], Vec::new()),
            standby: standby.then(|| Process::start(&world, 1, &[], Vec::new())),
            since_save: Vec::new(),
            out_at_save: 0,
            committed_since_save: false,
            done: Vec::new(),
        })
        .collect();
    let mut problems = Vec::new();
    let mut repeats = 0;
    let mut decisions = Vec::new();
    let mut revision = 0u64;
    // Event time (ns after T0) and wall time (ns after t0), and each robot's last stamp.
    let (mut e, mut w) = (0i64, 0i64);
    let mut last: Vec<i64> = vec![0; s.robots];
    for op in &s.ops {
        match op {
            Op::Record { robot, kind, x } => {
                e += 100 * MS;
                w += 100 * MS;
                let ts = match kind {
                    Kind::Equal if last[*robot] > 0 => last[*robot],
                    Kind::Late if last[*robot] > 0 => last[*robot] - 40 * MS,
                    Kind::Ahead => w + 60_000 * MS,
                    _ => e,
                };
                if !matches!(kind, Kind::Ahead) {
                    last[*robot] = last[*robot].max(ts);
                }
                let text = line(*robot, *kind, *x, T0 + ts);
                let k = if n_part == 1 { 0 } else { robot % n_part };
                let part = &mut parts[k];
                part.active.record(&world, w, &text);
                part.since_save.push((w, text));
            }
            Op::Silence { ms } => {
                e += ms * MS;
                w += ms * MS;
                for part in &mut parts {
                    part.active.silence(&world, w);
                }
            }
            Op::Publish {
                what,
                select,
                from_ms,
                trust,
            } => {
                revision += 1;
                let text = match what {
                    What::Pool(i) => spec_text(&POOL[*i]),
                    What::Broken => BROKEN.into(),
                    What::Incompatible => INCOMPATIBLE.into(),
                };
                let b = bundle(&text);
                match what {
                    What::Pool(i) => {
                        versions.insert(b.id(), Some(*i));
                    }
                    What::Incompatible => {
                        versions.insert(b.id(), None);
                    }
                    What::Broken => {}
                }
                let selector = match select {
                    None => Selector::all(),
                    Some(rs) => Selector::parse(&format!(
                        "robot={}",
                        rs.iter()
                            .map(|r| format!("r{r}"))
                            .collect::<Vec<_>>()
                            .join(",")
                    ))
                    .unwrap(),
                };
                let rollout = Rollout {
                    revision,
                    id: b.id(),
                    digest: b.digest(),
                    label: format!("{what:?}"),
                    from: T0 + e + from_ms * MS,
                    selector,
                    published: 0,
                    fleet: false,
                };
                let arrival = Arrival {
                    rollout: rollout.clone(),
                    bundle: match trust {
                        Trust::Untrusted => Err(foreign()),
                        _ => Ok(b),
                    },
                };
                let proposal = Event::Proposal(arrival);
                let decision = match oracle {
                    Some(given) => given
                        .iter()
                        .find(|(r, _)| *r == revision)
                        .map(|(_, d)| d.clone())
                        .unwrap_or_else(|| Err(RecordError::NoBody { what: "decision" }.into())),
                    None => {
                        // Every live process votes; the rule decides.
                        let mut votes = Vec::new();
                        for (k, part) in parts.iter_mut().enumerate() {
                            let live = std::iter::once((format!("p{k}/active"), &mut part.active))
                                .chain(part.standby.as_mut().map(|p| (format!("p{k}/standby"), p)));
                            for (name, p) in live {
                                p.deliver(proposal.clone());
                                let v = p.vote(revision);
                                votes.push(Vote {
                                    process: name,
                                    accepted: v.as_ref().map(|o| o.accepted),
                                    reason: v.map(|o| o.reason).unwrap_or_default(),
                                });
                            }
                        }
                        let d = decide::decide(&rollout, &Tally { votes }, 0);
                        match trust {
                            Trust::ForgedDecision => Err(foreign()),
                            _ => Ok(d),
                        }
                    }
                };
                if oracle.is_some() {
                    for part in &mut parts {
                        part.active.deliver(proposal.clone());
                    }
                }
                let event = Event::Decision {
                    revision,
                    decision: decision.clone(),
                };
                let committed = matches!(&decision, Ok(d) if d.commit);
                decisions.push((revision, decision));
                for part in &mut parts {
                    part.active.deliver(event.clone());

                    if let Some(sb) = part.standby.as_mut() {
                        sb.deliver(event.clone());
                    }
                    part.committed_since_save |= committed;
                }
                history.push(proposal);
                history.push(event);
                decided.push(revision);
            }
            Op::Sighup if oracle.is_none() => {
                for part in &mut parts {
                    part.active.hangup();
                }
            }
            Op::Save { partition } if stateful => {
                let part = &mut parts[*partition];
                state_file::save(&part.file, &part.active.procs[0], &world.ctx).unwrap();
                part.since_save.clear();
                part.out_at_save = part.active.out.len();
                part.committed_since_save = false;
            }
            Op::Restart { partition } | Op::Takeover { partition } if stateful => {
                let part = &mut parts[*partition];
                state_file::save(&part.file, &part.active.procs[0], &world.ctx).unwrap();
                let next = match (op, part.standby.take()) {
                    (Op::Takeover { .. }, Some(sb)) => {
                        part.standby = Some(Process::start(&world, 1, &history, decided.clone()));
                        sb
                    }
                    (_, sb) => {
                        part.standby = sb;
                        Process::start(&world, 1, &history, decided.clone())
                    }
                };
                let old = std::mem::replace(&mut part.active, next);
                part.done.extend_from_slice(&old.out);
                outcomes_check(&old, &decisions, &mut problems);
                state_file::load(&part.file, &mut part.active.procs[0], &world.ctx);
                part.since_save.clear();
                part.out_at_save = 0;
                part.committed_since_save = false;
            }
            Op::Crash { partition } if stateful => {
                let part = &mut parts[*partition];
                if part.committed_since_save {
                    continue;
                }
                let next = match part.standby.take() {
                    Some(sb) => {
                        part.standby = Some(Process::start(&world, 1, &history, decided.clone()));
                        sb
                    }
                    None => Process::start(&world, 1, &history, decided.clone()),
                };
                let mut old = std::mem::replace(&mut part.active, next);
                // What it wrote since its last save is written again by the replay.
                let kept: Vec<u8> = old.out.drain(..part.out_at_save).collect();
                repeats += lines_of(&old.out).len();
                part.done.extend_from_slice(&kept);
                outcomes_check(&old, &decisions, &mut problems);
                if part.file.exists() {
                    state_file::load(&part.file, &mut part.active.procs[0], &world.ctx);
                }
                for (at, text) in part.since_save.clone() {
                    part.active.record(&world, at, &text);
                }
                part.out_at_save = 0;
            }
            Op::Sighup
            | Op::Save { .. }
            | Op::Restart { .. }
            | Op::Takeover { .. }
            | Op::Crash { .. } => {}
        }
    }
    let mut lines = Vec::new();
    let mut outcomes = Vec::new();
    for part in &mut parts {
        lines.extend_from_slice(&part.done);
        lines.extend_from_slice(&part.active.out);
        outcomes_check(&part.active, &decisions, &mut problems);
        outcomes.push(part.active.stand.reports.lock().unwrap().clone());
    }
    Run {
        lines,
        repeats,
        problems,
        decisions,
        outcomes,
        versions,
    }
}

/// A process's outcomes against the decisions: acted as decided, never voted on a rollout
/// decided before it started, never found a committed version unrunnable.
fn outcomes_check(
    p: &Process,
    decisions: &[(u64, Result<Decision, RolloutError>)],
    problems: &mut Vec<String>,
) {
    for o in p.stand.reports.lock().unwrap().iter() {
        if o.phase == Phase::Check && p.decided_before.contains(&o.revision) && o.revision != 0 {
            problems.push(format!(
                "a process voted on rollout {} decided before it started",
                o.revision
            ));
        }
        if o.phase == Phase::Check {
            continue;
        }
        let commit = decisions
            .iter()
            .find(|(r, _)| *r == o.revision)
            .is_some_and(|(_, d)| matches!(d, Ok(d) if d.commit));
        match (o.phase, o.accepted, commit) {
            (Phase::Committed, true, true) | (Phase::Aborted, _, false) => {}
            (Phase::Committed, false, true) => problems.push(format!(
                "rollout {} committed but unrunnable: {}",
                o.revision, o.reason
            )),
            _ => problems.push(format!(
                "rollout {}: outcome {} against the decision (commit: {commit})",
                o.revision,
                o.word()
            )),
        }
    }
}

fn lines_of(bytes: &[u8]) -> Vec<String> {
    String::from_utf8_lossy(bytes)
        .lines()
        .filter(|l| !l.starts_with("tessla_spec,"))
        .map(String::from)
        .collect()
}

/// Lines by robot, each robot's in order.
fn by_robot(bytes: &[u8]) -> BTreeMap<String, Vec<String>> {
    let mut m: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for l in lines_of(bytes) {
        let robot = l
            .split(' ')
            .next()
            .unwrap_or("")
            .split(',')
            .find_map(|t| t.strip_prefix("robot="))
            .unwrap_or("")
            .to_string();
        m.entry(robot).or_default().push(l);
    }
    m
}

/// Each line's fields are the outputs of the version its tag names, and its value field
/// carries that version's `k`.
fn labels(run: &Run) -> Vec<String> {
    let mut problems = Vec::new();
    for l in lines_of(&run.lines) {
        let mut parts = l.split(' ');
        let head = parts.next().unwrap_or("");
        let fields = parts.next().unwrap_or("");
        let Some(id) = head
            .split(',')
            .find_map(|t| t.strip_prefix("spec_version="))
        else {
            problems.push(format!("no version tag: {l}"));
            continue;
        };
        let v = match run.versions.get(id) {
            Some(Some(i)) => &POOL[*i],
            Some(None) => {
                if fields.split(',').any(|f| !f.starts_with("c=")) {
                    problems.push(format!("fields the incompatible version lacks: {l}"));
                }
                continue;
            }
            None => {
                problems.push(format!("version {id} is none the schedule published: {l}"));
                continue;
            }
        };
        for f in fields.split(',') {
            let (k, val) = f.split_once('=').unwrap_or((f, ""));
            let ok = match k {
                "c" => true,
                "quiet" => v.quiet,
                "d" => v.extra,
                // A step is never before the record's own time; a late record's is after it.
                "lag" => {
                    v.stamp
                        && val
                            .trim_end_matches('i')
                            .parse::<i64>()
                            .is_ok_and(|n| n >= 0)
                }
                _ if k == v.name => val
                    .trim_end_matches('i')
                    .parse::<i64>()
                    .is_ok_and(|n| n.rem_euclid(10) == v.k),
                _ => false,
            };
            if !ok {
                problems.push(format!(
                    "field `{f}` is not what version {id} (`{}` = x * 10 + {}) writes: {l}",
                    v.name, v.k
                ));
            }
        }
    }
    problems
}

/// Lines of `bytes` whose `lag` is above 0: a late record's step, after its own time.
fn late_lags(bytes: &[u8]) -> usize {
    lines_of(bytes)
        .iter()
        .filter(|l| {
            l.split(' ').nth(1).is_some_and(|fields| {
                fields.split(',').any(|f| {
                    f.strip_prefix("lag=")
                        .and_then(|v| v.trim_end_matches('i').parse::<i64>().ok())
                        .is_some_and(|n| n > 0)
                })
            })
        })
        .count()
}

fn check(seed: u64) -> Result<(usize, usize, usize), String> {
    let s = generate(seed);
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let fleet = run(&s, dir.path(), None);
    let odir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let oracle = run(&s, odir.path(), Some(&fleet.decisions));
    let mut problems = fleet.problems.clone();
    problems.extend(labels(&fleet));
    problems.extend(labels(&oracle));
    let (got, want) = (by_robot(&fleet.lines), by_robot(&oracle.lines));
    if got != want {
        for robot in want.keys().chain(got.keys()) {
            let (g, w) = (got.get(robot), want.get(robot));
            if g != w {
                let g = g.cloned().unwrap_or_default();
                let w = w.cloned().unwrap_or_default();
                let at = g
                    .iter()
                    .zip(&w)
                    .position(|(a, b)| a != b)
                    .unwrap_or(g.len().min(w.len()));
                problems.push(format!(
                    "robot {robot}: line {at} differs from the one-process oracle:\n  fleet:  {:?}\n  oracle: {:?}\n  fleet's lines:  {g:#?}\n  oracle's lines: {w:#?}",
                    g.get(at),
                    w.get(at)
                ));
                break;
            }
        }
    }
    if problems.is_empty() {
        Ok((
            lines_of(&fleet.lines).len(),
            fleet.repeats,
            late_lags(&fleet.lines),
        ))
    } else {
        Err(format!(
            "seed {seed} (replay: COMBINATION_SEED={seed} cargo test --test integration cli::combinations -- --nocapture):\n{}\nschedule: {s:#?}\noutcomes: {:?}\noracle outcomes: {:?}",
            problems.join("\n"),
            fleet.outcomes,
            oracle.outcomes
        ))
    }
}

#[test]
fn every_schedule_gives_the_one_process_oracles_lines() {
    let seeds: Vec<u64> = match std::env::var("COMBINATION_SEED") {
        Ok(s) => vec![s.parse().expect("COMBINATION_SEED is a number")],
        Err(_) => {
            let n: u64 = std::env::var("COMBINATION_SEEDS")
                .ok()
                .and_then(|s| s.parse().ok())
                .unwrap_or(300);
            (0..n).collect()
        }
    };
    let (mut lines, mut repeats, mut lags) = (0, 0, 0);
    for seed in &seeds {
        match check(*seed) {
            Ok((l, r, g)) => {
                lines += l;
                repeats += r;
                lags += g;
            }
            Err(e) => panic!("{e}"),
        }
    }
    eprintln!(
        "combinations: {} schedules, {lines} lines equal to the oracle's, {repeats} repeated after crashes, {lags} late records' steps carrying their own time",
        seeds.len()
    );
    assert!(
        lines > seeds.len() * 10,
        "schedules that write nothing prove nothing"
    );
    assert!(
        seeds.len() < 50 || lags > 0,
        "no late record was stepped under a version that reads its own time"
    );
}
