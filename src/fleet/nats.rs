//! The fleet level over NATS partitions (`--fleet-spec` with `--state nats://...?lease=NAME`,
//! docs/fleet.md, "A fleet of NATS partitions").
//!
//! Owns both ends, in every partition process: sending what the partition's holder steps (its
//! robots' fleet changes, clocks and evictions, with its promise: a heartbeat when idle) as
//! entries `fleet.m.<partition>.g<generation>.<pid>x<n>` of the state bucket, keyed by the
//! partition lease's generation; and the fleet level itself, run by every process on the same
//! entries in the bucket's order (a hot standby), written out only by the holder of the `fleet`
//! lease, which records how far it wrote (`fleet.written`, the stream sequence) so that a
//! standby taking over writes from there on. A holder of a partition that ends while a standby
//! of it is live says so (the partition is handed over: the fleet holds it until the standby's
//! first entry). The holder of the fleet lease also decides drop-outs (a partition silent past
//! twice the lease TTL), the end of a partition handed over whose standbys are gone, and the
//! end of the fleet's input (a close: stopping, every
//! partition ended and no partition lease held, so no restart is under way) and puts them in
//! the stream, so every process applies them at the same point; a process stopping without
//! the fleet lease takes it to close when it was released, or when it is the last live
//! partition and the lease lapses (its holder killed). It also writes the fleet
//! checkpoint (the table and the level after an entry, every 5 s; its store is
//! [`super::checkpoint`]) and deletes the entries the checkpoint before covered, so the entries
//! stay bounded; a process that starts goes on from the checkpoint. The rules themselves are [`super::watermark`]. A
//! committed fleet rollout is a switch entry `fleet.m.switch.r<revision>` the fleet lease's
//! holder puts in the same stream; every process switches its level where it reads that entry
//! (docs/fleet.md, "Rollouts of the fleet spec").

use super::Level;
use super::checkpoint::{self, Taken};
use super::watermark::{self, Msg, Partitions};
use crate::nats::conn::{Conn, Failure, connect};
use crate::nats::kv_keys::kv_key_part_of;
use crate::nats::url::Url;
use crate::processor::fleet_tap::Drained;
use crate::state::lease::Lease;
use async_nats::jetstream::{self, kv};
use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The lease of the fleet level, beside the partitions' (`lease.vfleet`).
pub const LEASE: &str = "fleet";
/// How far the holder of the fleet lease has written (the stream sequence of the last message
/// whose outputs it wrote).
const WRITTEN_KEY: &str = "fleet.written";
/// A holder of a partition lease that sent nothing for this long sends a heartbeat.
const HEARTBEAT: Duration = Duration::from_millis(200);
/// At most this many messages' outputs kept by a standby (the holder's progress trims them).
const MAX_KEPT: usize = 100_000;
/// The holder of the fleet lease writes a checkpoint this often (while entries come), and
/// then deletes the entries the checkpoint before it covered.
const CHECKPOINT_EVERY: Duration = Duration::from_secs(5);
/// A process holding the fleet's entries behind a switch entry whose decision it has not read
/// says so after this long (the decision normally comes within a channel poll).
const WAITING_SAID_AFTER: Duration = Duration::from_secs(10);
/// A standby (a process of a partition whose lease another holds) renews its key
/// `fleet.standby.<partition>.<pid>` this often; one older than three times this is not live.
const STANDBY_EVERY: Duration = Duration::from_secs(1);
/// The holder of the fleet lease looks for the standbys of the partitions handing over at
/// most this often (only while one is).
const HANDING_LOOK_EVERY: Duration = Duration::from_millis(200);
/// A partition handing over whose standby still renews its key but has not taken it over
/// this long past the drop time (counted from the holder's first look) drops out, as a silent
/// one does: a takeover needs the old holder's stop (at most 2 s) and one lease poll.
const HANDING_AT_MOST_PAST_DROP: Duration = Duration::from_secs(10);
/// How long a process stopping waits to take a fleet lease it found released.
const TAKE_FREE_WAIT: Duration = Duration::from_secs(2);
/// A process stopping without the fleet lease, which hears no other live partition for this
/// long (three heartbeats), counts itself the last live partition.
const LAST_LIVE_AFTER: Duration = Duration::from_millis(600);
/// The margin past the lease TTL (for the fleet lease to lapse) and past the drop time (for a
/// killed partition to drop out) a last live partition stopping waits.
const LAPSE_MARGIN: Duration = Duration::from_secs(1);

enum Job {
    Put(String, bytes::Bytes),
    /// Put a fleet checkpoint (encoded here, off the step loop); once it is stored, delete the
    /// entries the checkpoint stored before it covered. The copy taken, and how long taking it
    /// held the step loop.
    Checkpoint(Box<Taken>, Duration),
    Flush(std::sync::mpsc::Sender<()>),
}

/// A look for the standbys of the partitions handing over: per partition and generation, the
/// key of a live standby of it, none, or why it is not known.
type Looked = Vec<(String, u64, Result<Option<String>, String>)>;

#[derive(Default)]
struct Inbox {
    msgs: VecDeque<(u64, bytes::Bytes)>,
    /// The holder's `fleet.written`, as last seen.
    written: u64,
}

/// The partition side and the fleet level of one process.
pub struct FleetNats {
    partition: String,
    silence: i64,
    conn: Conn,
    store: kv::Store,
    jobs: tokio::sync::mpsc::UnboundedSender<Job>,
    inbox: Arc<Mutex<Inbox>>,
    lease: Lease,
    level: Level,
    table: Partitions,
    tags: Vec<(String, String)>,
    /// Outputs per stream sequence, not written yet.
    outputs: VecDeque<(u64, Vec<u8>)>,
    /// The last stream sequence whose outputs were written (here or by the holder before).
    written: u64,
    holding: bool,
    /// The newest robot clock this process sent.
    front: i64,
    /// The partition lease's generation when this process last held it.
    generation: Option<u64>,
    /// Whether this process held its partition lease at the last pump.
    holds_partition: bool,
    last_sent: Instant,
    sent: u64,
    /// When each partition was last heard (for drop-outs, decided by the holder).
    heard: HashMap<String, Instant>,
    drops_sent: HashSet<(String, u64)>,
    drop_after: Duration,
    /// The stream sequence of the last entry taken in (or of the checkpoint started from).
    applied: u64,
    /// The sequence of the last checkpoint written or started from, and when.
    checkpointed: (u64, Instant),
    /// Fleet rollouts committed here whose switch entry was not read yet.
    commits: Vec<crate::spec_feed::FleetCommit>,
    /// Fleet rollouts whose switch entry was read (applied once, at its first entry).
    switched: HashSet<u64>,
    /// Fleet rollouts whose switch entry this process put.
    switch_put: HashSet<u64>,
    /// Entries from a switch entry on whose rollout this process has not seen committed yet.
    held: VecDeque<(u64, bytes::Bytes)>,
    /// Since when entries are held (the switch entry's stream sequence), and whether it was
    /// said (a `W!` and a `waiting` status line).
    waiting: Option<(u64, Instant, bool)>,
    /// As a standby: when this process last renewed its standby key (`None`: not a standby).
    standby_at: Option<Instant>,
    /// As the fleet level's holder: when it last looked for the standbys of the partitions
    /// handing over, and the answer, until it came.
    look: (Instant, Option<tokio::sync::oneshot::Receiver<Looked>>),
    /// The ends this process put for partitions handing over whose standbys were gone.
    ends_sent: HashSet<(String, u64)>,
    /// As the fleet level's holder: when it first found each partition handing over.
    handing_since: HashMap<(String, u64), Instant>,
}

/// A switch entry: the fleet level runs fleet rollout `fleet_switch`'s version from here on.
#[derive(serde::Serialize, serde::Deserialize)]
struct SwitchEntry {
    fleet_switch: u64,
}

fn now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

impl FleetNats {
    /// Connect to `url`'s bucket (made by the state backend already), start following the
    /// fleet's entries and the `fleet` lease. `partition`: this process's lease name.
    pub fn connect(
        url: &Url,
        partition: String,
        level: Level,
        silence: i64,
        tags: Vec<(String, String)>,
    ) -> Result<FleetNats, Failure> {
        if partition == LEASE {
            return Err(Failure::Config(format!(
                "--state ?lease={LEASE} is the fleet level's own lease; name the partition otherwise"
            )));
        }
        let conn = Conn::start()
            .map_err(|e| Failure::Io(format!("cannot start the fleet's NATS thread: {e}")))?;
        let u = url.clone();
        let (store, max_payload) = conn
            .call(async move {
                let (client, _) = connect(&u).await?;
                let max_payload = client.server_info().max_payload;
                jetstream::new(client)
                    .get_key_value(u.bucket.clone())
                    .await
                    .map(|s| (s, max_payload))
                    .map_err(|e| {
                        Failure::Io(format!("fleet: cannot open bucket {}: {e}", u.bucket))
                    })
            })
            .ok_or_else(|| Failure::Io("the fleet's NATS thread stopped".into()))??;
        let mut level = level;
        let mut table = Partitions::default();
        let mut written = 0;
        let mut applied = 0;
        let mut heard = HashMap::new();
        let st = store.clone();
        let saved = conn
            .call(async move { checkpoint::load(&st).await })
            .unwrap_or(Ok(None));
        if let Some(saved) = saved.transpose() {
            match saved {
                Ok(checkpoint::Loaded {
                    checkpoint: c,
                    bytes,
                    parts,
                    took,
                }) => {
                    log_info!(
                        "fleet: starting from the fleet checkpoint at stream sequence {} (the entries it covers may be deleted; {bytes} bytes in {parts} parts, read in {} ms)",
                        c.seq,
                        took.as_millis()
                    );
                    table = Partitions::from_state(c.table);
                    level.restore(c.level);
                    level.set_bound(table.bound());
                    written = c.written;
                    applied = c.seq;
                    for (p, _) in table.holding_back() {
                        heard.insert(p.to_string(), Instant::now());
                    }
                }
                Err(e) => log_warn!(
                    "fleet: the fleet checkpoint is not one ({e}); following the entries from the first"
                ),
            }
        }
        let inbox = Arc::new(Mutex::new(Inbox::default()));
        let (jobs, rx) = tokio::sync::mpsc::unbounded_channel();
        conn.handle.spawn(publisher(
            store.clone(),
            rx,
            checkpoint::part_size(max_payload),
        ));
        conn.handle
            .spawn(follow(store.clone(), Arc::clone(&inbox), applied));
        let lease = Lease::start(&conn, &store, LEASE.to_string(), url.ttl);
        Ok(FleetNats {
            partition,
            silence,
            conn,
            store,
            jobs,
            inbox,
            lease,
            level,
            table,
            tags,
            outputs: VecDeque::new(),
            written,
            holding: false,
            front: i64::MIN,
            generation: None,
            holds_partition: false,
            last_sent: Instant::now() - HEARTBEAT,
            sent: 0,
            heard,
            drops_sent: HashSet::new(),
            drop_after: url.ttl * 2,
            applied,
            checkpointed: (applied, Instant::now()),
            commits: Vec::new(),
            switched: HashSet::new(),
            switch_put: HashSet::new(),
            held: VecDeque::new(),
            waiting: None,
            standby_at: None,
            look: (Instant::now() - HANDING_LOOK_EVERY, None),
            ends_sent: HashSet::new(),
            handing_since: HashMap::new(),
        })
    }

    /// A fleet rollout committed (the spec channel): applied where its switch entry is read;
    /// as the fleet lease's holder, put that entry.
    pub fn committed(&mut self, c: crate::spec_feed::FleetCommit) {
        if !self.switched.contains(&c.revision) {
            self.commits.push(c);
        }
    }

    /// The fleet level this process follows, and whether it writes its lines (it holds the
    /// `fleet` lease).
    pub fn level_and_holding(&self) -> (&Level, bool) {
        (&self.level, self.holding)
    }

    /// A switch entry at `seq`: `true` when applied (or already applied), `false` when its
    /// rollout is not known committed here yet (the entries from here on wait for it).
    fn switch_entry(&mut self, seq: u64, e: &SwitchEntry) -> bool {
        let r = e.fleet_switch;
        if self.switched.contains(&r) {
            return true;
        }
        let Some(i) = self.commits.iter().position(|c| c.revision == r) else {
            return false;
        };
        let c = self.commits.remove(i);
        log_info!(
            "fleet: switch entry for fleet rollout {r} (version {}) at stream sequence {seq}",
            c.id
        );
        self.level.switch_to(&c);
        self.switched.insert(r);
        true
    }

    /// As the fleet lease's holder: put a switch entry for each committed fleet rollout not
    /// yet in the stream.
    fn put_switches(&mut self) {
        let due: Vec<u64> = self
            .commits
            .iter()
            .map(|c| c.revision)
            .filter(|r| !self.switch_put.contains(r))
            .collect();
        for r in due {
            if let Ok(bytes) = serde_json::to_vec(&SwitchEntry { fleet_switch: r }) {
                let _ = self
                    .jobs
                    .send(Job::Put(format!("fleet.m.switch.r{r}"), bytes.into()));
                self.switch_put.insert(r);
            }
        }
    }

    fn put(&mut self, part: &str, generation: u64, kind: &str, msg: &Msg) {
        let Ok(bytes) = serde_json::to_vec(msg) else {
            return;
        };
        self.sent += 1;
        let key = format!(
            "fleet.m.{}.g{generation}.{kind}{}x{}",
            kv_key_part_of(part),
            std::process::id(),
            self.sent
        );
        let _ = self.jobs.send(Job::Put(key, bytes.into()));
    }

    /// Send what this partition's processors collected (when holding the partition lease:
    /// `generation`), then follow the fleet level; outputs to `out` while holding its lease.
    pub fn pump(
        &mut self,
        drained: Vec<Drained>,
        end: bool,
        generation: Option<u64>,
        out: &mut Vec<u8>,
    ) {
        // Records are stepped only while holding the partition lease; a renewal that falls
        // overdue between the step and now must not lose their changes: they go with the
        // generation they were stepped in (a newer holder's entries make them stale).
        let fresh = generation.is_some();
        self.holds_partition = fresh;
        // A new generation (this process took the partition, at its start or over from
        // another): its first entry goes out now.
        let first = fresh && generation != self.generation;
        self.generation = generation.or(self.generation);
        if let Some(g) = self.generation {
            for d in &drained {
                for (_, c) in &d.clocks {
                    self.front = self.front.max(*c);
                }
            }
            let promise = self.front.max(now_ns().saturating_sub(self.silence));
            let mut msg = Msg::of(&self.partition, g, promise, end, drained);
            msg.handed = end && fresh && self.handed_over();
            if msg.is_data() || first || (fresh && self.last_sent.elapsed() >= HEARTBEAT) {
                let part = self.partition.clone();
                self.put(&part, g, "", &msg);
                self.last_sent = Instant::now();
            }
        }
        // Only after the entry (the queue puts in order): a standby taking the partition over
        // marks its key stale once its first entry is in the stream, so the fleet level's
        // holder, which ends a partition handing over when it sees no standby of it live,
        // puts that end after the takeover (where it is stale), never before it.
        self.stand_by(fresh);
        self.follow(out);
    }

    /// This process's partition ends here (its holder's input ended): whether a standby of
    /// it is live, so that the partition is handed over (it holds the fleet's bound until the
    /// standby's first entry) instead of ended. Not known: ended, as before.
    fn handed_over(&self) -> bool {
        // Never its own key (one left live by a renewal overdue for a moment).
        match self.live_standby(Some(&self.partition), Some(self.standby_key())) {
            Ok(Some(key)) => {
                log_info!(
                    "fleet: a standby of partition {} is live ({key}): the partition is handed over, and the fleet level holds it until the standby's first entry",
                    self.partition
                );
                true
            }
            Ok(None) => false,
            Err(e) => {
                log_warn!(
                    "fleet: cannot read the standby keys ({e}); partition {} ends without a hand-over",
                    self.partition
                );
                false
            }
        }
    }

    /// Take in the fleet's messages, write the outputs while holding the fleet lease, and (as
    /// its holder) drop the partitions silent past the bound.
    pub fn follow(&mut self, out: &mut Vec<u8>) {
        let (msgs, progress) = match self.inbox.lock() {
            Ok(mut i) => (std::mem::take(&mut i.msgs), i.written),
            Err(_) => return,
        };
        let mut msgs: VecDeque<_> = std::mem::take(&mut self.held)
            .into_iter()
            .chain(msgs)
            .collect();
        while let Some((seq, bytes)) = msgs.pop_front() {
            if let Ok(e) = serde_json::from_slice::<SwitchEntry>(&bytes) {
                if !self.switch_entry(seq, &e) {
                    self.held.push_front((seq, bytes));
                    self.held.extend(msgs.drain(..));
                }
                continue;
            }
            let m: Msg = match serde_json::from_slice(&bytes) {
                Ok(m) => m,
                Err(e) => {
                    crate::log::warn_limited("fleet message", || {
                        format!(
                            "fleet: a message at stream sequence {seq} is not one: {e}; ignored"
                        )
                    });
                    continue;
                }
            };
            if !m.drop {
                self.heard.insert(m.p.clone(), Instant::now());
            }
            log_debug!(
                "fleet: entry {seq} from {} (generation {}): {} changes, clocks {:?}, left {:?}{}{}{}",
                m.p,
                m.g,
                m.changes.len(),
                m.clocks,
                m.left,
                if m.end { ", end" } else { "" },
                if m.drop { ", drop-out" } else { "" },
                if m.close { ", close" } else { "" },
            );
            let (drained, status) = self.table.apply(m);
            let mut o = Vec::new();
            for s in &status {
                watermark::status_line(s, &self.tags, now_ns(), &mut o);
                log_info!(
                    "fleet: partition {} (generation {}) {}",
                    s.partition,
                    s.generation,
                    s.event
                );
            }
            self.level.set_bound(self.table.bound());
            let end = self.table.closed();
            self.level.pump(drained.into_iter().collect(), end, &mut o);
            self.applied = seq;
            if !o.is_empty() {
                self.outputs.push_back((seq, o));
            }
        }
        self.say_waiting(out);
        let holding = self.lease.holding();
        if holding && !self.holding {
            let store = self.store.clone();
            let before = self
                .conn
                .call(async move { store.get(WRITTEN_KEY).await })
                .and_then(Result::ok)
                .flatten()
                .and_then(|b| std::str::from_utf8(&b).ok()?.trim().parse::<u64>().ok())
                .unwrap_or(0);
            self.written = self.written.max(before);
            log_info!(
                "fleet: holding the fleet level; the previous holder wrote up to stream sequence {before}, this process goes on from there"
            );
        } else if !holding && self.holding {
            log_warn!("fleet: not holding the fleet level any more; standing by");
        }
        self.holding = holding;
        self.written = self.written.max(if holding { 0 } else { progress });
        let written = self.written;
        if holding {
            let mut last = None;
            for (seq, o) in self.outputs.drain(..) {
                if seq > written {
                    out.extend_from_slice(&o);
                    last = Some(seq);
                }
            }
            if let Some(seq) = last {
                self.written = seq;
                let _ = self.jobs.send(Job::Put(
                    WRITTEN_KEY.to_string(),
                    seq.to_string().into_bytes().into(),
                ));
            }
            self.drop_silent();
            self.end_handed();
            self.checkpoint();
            self.put_switches();
        } else {
            while self.outputs.front().is_some_and(|(seq, _)| *seq <= written)
                || self.outputs.len() > MAX_KEPT
            {
                self.outputs.pop_front();
            }
        }
    }

    /// Entries held behind a switch entry whose decision this process has not read (it never
    /// switches on an entry alone): after [`WAITING_SAID_AFTER`], a `W!` and one
    /// `tessla_fleet_status` line `event="waiting"`, written by this process whether or not it
    /// holds the fleet lease (it is about this process: it follows no channel, or a channel
    /// that has not brought the decision); when the decision comes, an `I!`.
    fn say_waiting(&mut self, out: &mut Vec<u8>) {
        let Some((seq, bytes)) = self.held.front() else {
            if let Some((seq, since, true)) = self.waiting.take() {
                log_info!(
                    "fleet: the decision for the switch entry at stream sequence {seq} came after {}; the held entries go on",
                    humantime::format_duration(Duration::from_secs(since.elapsed().as_secs()))
                );
            }
            return;
        };
        let seq = *seq;
        let revision = serde_json::from_slice::<SwitchEntry>(bytes).map_or(0, |e| e.fleet_switch);
        let (at, since, said) = self
            .waiting
            .get_or_insert_with(|| (seq, Instant::now(), false));
        if *at != seq {
            (*at, *since, *said) = (seq, Instant::now(), false);
        }
        if *said || since.elapsed() < WAITING_SAID_AFTER {
            return;
        }
        *said = true;
        let held = self.held.len() - 1;
        log_warn!(
            "fleet: the switch entry for fleet rollout {revision} (stream sequence {seq}) came {} ago, but this process has not read the rollout's decision: the fleet level holds the {held} entries after it until it has (is `--spec-channel` given, and the same as the other processes'?)",
            humantime::format_duration(WAITING_SAID_AFTER)
        );
        let mut line = watermark::status_head(&self.tags, Some(&self.partition));
        line.push_str(&format!(
            " event=\"waiting\",revision={revision}i,sequence={seq}i,held={held}i {}\n",
            now_ns()
        ));
        out.extend_from_slice(line.as_bytes());
    }

    /// As the fleet level's holder, every [`CHECKPOINT_EVERY`]: put the fleet level's state
    /// after the last entry taken in (every output up to it is written) as the fleet
    /// checkpoint, then delete the entries the checkpoint before this one covered (one
    /// checkpoint behind, so a process that has just read that one still finds the entries
    /// after it).
    fn checkpoint(&mut self) {
        let (last, at) = self.checkpointed;
        if self.applied <= last || at.elapsed() < CHECKPOINT_EVERY || !self.outputs.is_empty() {
            return;
        }
        // After a fleet rollout (pending or switched), or while entries wait behind a switch
        // entry, no checkpoint: the entries stay and a later process replays them, meeting the
        // switch entry where the holder did (docs/fleet.md, "Rollouts of the fleet spec").
        if self.level.has_switch() || !self.held.is_empty() {
            return;
        }
        // On the step loop only a copy (the maps and monitor values are shared): converting,
        // encoding, deflating and hashing it run in the store task's blocking thread.
        let started = Instant::now();
        let Some(level) = self.level.copy() else {
            return;
        };
        let taken = Taken {
            seq: self.applied,
            written: self.written,
            table: self.table.clone(),
            level,
        };
        let _ = self
            .jobs
            .send(Job::Checkpoint(Box::new(taken), started.elapsed()));
        self.checkpointed = (self.applied, Instant::now());
    }

    /// As the fleet level's holder: put a drop-out in the stream for each live partition not
    /// heard for the bound (one handing over: [`Self::end_handed`]).
    fn drop_silent(&mut self) {
        let silent: Vec<(String, u64)> = self
            .table
            .live()
            .filter(|(p, _)| {
                self.heard
                    .get(*p)
                    .is_none_or(|at| at.elapsed() > self.drop_after)
            })
            .map(|(p, g)| (p.to_string(), g))
            .filter(|k| !self.drops_sent.contains(k))
            .collect();
        for (p, g) in silent {
            log_warn!(
                "fleet: partition {p} (generation {g}) sent nothing for {}; it drops out of the fleet level",
                humantime::format_duration(self.drop_after)
            );
            self.put_drop(p, g);
        }
    }

    /// Put a drop-out of partition `p` at generation `g` in the stream.
    fn put_drop(&mut self, p: String, g: u64) {
        let msg = Msg {
            drop: true,
            ..Msg::of(&p, g, 0, false, Vec::new())
        };
        self.put(&p, g, "drop", &msg);
        self.drops_sent.insert((p, g));
    }

    /// As the fleet level's holder, while a partition is handing over (its holder ended while
    /// a standby of it was live), at most every [`HANDING_LOOK_EVERY`]: look for its standbys
    /// (off the step loop; the answer is taken in at a later call). A standby live: the
    /// partition counts as heard (its next holder is coming). None live any more (stopped:
    /// its key deleted; or stale): put an end for the partition at that generation in the
    /// stream, so every process ends it at the same point (after the standby's first entry,
    /// where it is stale, if the standby took over: it marks its key stale only after that
    /// entry). The keys not readable: the drop-out rule (silent past the drop time). A standby
    /// live but not taking over for the drop time and [`HANDING_AT_MOST_PAST_DROP`]: the
    /// partition drops out.
    fn end_handed(&mut self) {
        if let Some(rx) = &mut self.look.1 {
            match rx.try_recv() {
                Ok(looked) => {
                    self.look.1 = None;
                    for (p, g, live) in looked {
                        self.looked(p, g, live);
                    }
                }
                Err(tokio::sync::oneshot::error::TryRecvError::Empty) => return,
                Err(tokio::sync::oneshot::error::TryRecvError::Closed) => self.look.1 = None,
            }
        }
        let handing: Vec<(String, u64)> = self
            .table
            .handing()
            // This process took the partition over at a newer generation: its entry comes.
            .filter(|(p, g)| {
                !(self.holds_partition
                    && *p == self.partition
                    && self.generation.is_some_and(|own| own > *g))
            })
            .map(|(p, g)| (p.to_string(), g))
            .filter(|k| !self.ends_sent.contains(k) && !self.drops_sent.contains(k))
            .collect();
        if handing.is_empty() || self.look.0.elapsed() < HANDING_LOOK_EVERY {
            return;
        }
        let (tx, rx) = tokio::sync::oneshot::channel();
        let store = self.store.clone();
        let except = self.own_key_unless_standing_by();
        self.conn.handle.spawn(async move {
            let mut looked = Vec::new();
            for (p, g) in handing {
                let live = live_standby(store.clone(), Some(&p), except.as_deref()).await;
                looked.push((p, g, live));
            }
            let _ = tx.send(looked);
        });
        self.look = (Instant::now(), Some(rx));
    }

    /// The answer of a look for partition `p`'s standbys ([`Self::end_handed`]).
    fn looked(&mut self, p: String, g: u64, live: Result<Option<String>, String>) {
        if !self.table.handing().any(|h| h == (p.as_str(), g)) {
            return;
        }
        let since = *self
            .handing_since
            .entry((p.clone(), g))
            .or_insert_with(Instant::now);
        match live {
            Ok(Some(key)) if since.elapsed() > self.drop_after + HANDING_AT_MOST_PAST_DROP => {
                if !self.drops_sent.contains(&(p.clone(), g)) {
                    log_warn!(
                        "fleet: partition {p} (generation {g}) was handed over {} ago and its standby ({key}) has not taken it over; it drops out of the fleet level",
                        humantime::format_duration(Duration::from_secs(since.elapsed().as_secs()))
                    );
                    self.put_drop(p, g);
                }
            }
            Ok(Some(_)) => {
                self.heard.insert(p, Instant::now());
            }
            Ok(None) => {
                if self.ends_sent.contains(&(p.clone(), g)) {
                    return;
                }
                log_info!(
                    "fleet: partition {p} (generation {g}) was handed over, but no standby of it is live any more: it ends"
                );
                let msg = Msg::of(&p, g, 0, true, Vec::new());
                self.put(&p, g, "end", &msg);
                self.ends_sent.insert((p, g));
            }
            Err(e) => {
                crate::log::warn_limited("fleet standby keys", || {
                    format!(
                        "fleet: cannot read the standby keys of partition {p}, which is handed over ({e}); it drops out if nothing comes from it for {}",
                        humantime::format_duration(self.drop_after)
                    )
                });
                let silent = self
                    .heard
                    .get(&p)
                    .is_none_or(|at| at.elapsed() > self.drop_after);
                if silent && !self.drops_sent.contains(&(p.clone(), g)) {
                    log_warn!(
                        "fleet: partition {p} (generation {g}) sent nothing for {} while handed over; it drops out of the fleet level",
                        humantime::format_duration(self.drop_after)
                    );
                    self.put_drop(p, g);
                }
            }
        }
    }

    /// At the end of this process: send what is queued; as the fleet level's holder, wait a
    /// little for the other partitions to end and release their leases. When every partition
    /// has ended and no other process holds a partition lease (no replacement is coming: a
    /// restarted partition's new process takes its lease at start), put a close in the stream,
    /// so that every process steps everything pending at the same point, as one process does
    /// at the end of its input; then write what the level gave. A partition still held (a
    /// restart in progress) leaves the pending changes to the next holder. Not holding the
    /// fleet lease, it takes a released one (`take_free_fleet_lease`) or, as the last
    /// live partition, one whose holder fell silent (`take_lapsed_fleet_lease`: then it
    /// waits up to the drop time and a margin for the killed holder's partition to drop out).
    pub fn finish(&mut self, out: &mut Vec<u8>) {
        // A standby stopping is no replacement for anyone any more.
        if self.standby_at.take().is_some() {
            let store = self.store.clone();
            let key = self.standby_key();
            let _ = self.conn.call(async move { store.delete(key).await });
        }
        self.flush();
        let start = Instant::now();
        let mut wait = self.drop_after.min(Duration::from_secs(2));
        if !self.lease.holding() && !self.take_free_fleet_lease() {
            if !self.take_lapsed_fleet_lease(out) {
                return;
            }
            // The holder was killed: its partition, silent, drops out after the drop time
            // (counted from its last entry, before this stop), and then the close is put.
            wait = self.drop_after + LAPSE_MARGIN;
        }
        let mut closing = false;
        let mut standby_said = false;
        loop {
            self.follow(out);
            if self.table.closed() || start.elapsed() > wait {
                break;
            }
            if !closing
                && self.table.all_done()
                && !self.partitions_held()
                && !self.standby_live(&mut standby_said)
            {
                let part = self.partition.clone();
                let msg = Msg {
                    close: true,
                    ..Msg::of(&part, 0, 0, false, Vec::new())
                };
                self.put(&part, 0, "close", &msg);
                self.flush();
                closing = true;
                log_info!("fleet: every partition ended and none is held; the fleet's input ends");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Stopping while nobody holds the fleet lease (its holder stopped first and released it),
    /// this process takes it, so that the fleet's input is closed and its pending lines written
    /// when every partition has ended (else nobody would write them): its lease task takes a
    /// released lease at its next poll. With several stopping at once, one takes it; the others
    /// return after [`TAKE_FREE_WAIT`].
    fn take_free_fleet_lease(&self) -> bool {
        if !self.lease.free() {
            return false;
        }
        let start = Instant::now();
        while start.elapsed() < TAKE_FREE_WAIT {
            if self.lease.holding() {
                log_info!(
                    "fleet: stopping, took the fleet level its holder released, to end its input"
                );
                return true;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        false
    }

    /// Stopping while the fleet lease is held by a process that may be dead (SIGKILL: its
    /// lease stays until it lapses), this process takes it when it is the **last live
    /// partition**: no entry from another live partition for [`LAST_LIVE_AFTER`] (a live
    /// holder sends a heartbeat every 200 ms). It then waits, at most the lease TTL and
    /// [`LAPSE_MARGIN`], for its lease task to take the lapsed lease; a renewal seen meanwhile
    /// means the holder lives (it closes the fleet's input itself when it stops), and it
    /// returns at once. Without it, nobody closed the fleet's input and the last steps' lines
    /// were lost (docs/fleet.md, "Partitions that stop").
    fn take_lapsed_fleet_lease(&mut self, out: &mut Vec<u8>) -> bool {
        let Some((first, _)) = self.lease.current() else {
            return false;
        };
        let start = Instant::now();
        // Entries taken in within the first heartbeat may have been put before this stop.
        let fresh = start + HEARTBEAT / 2;
        let limit = self.lease.ttl() + LAPSE_MARGIN;
        let mut said = false;
        while start.elapsed() < LAST_LIVE_AFTER + limit {
            self.follow(out);
            // Another partition's holder is live (its own partition counts when another
            // process holds it): it stops later and does this.
            let own = self.holds_partition.then_some(self.partition.as_str());
            let heard = self
                .table
                .live()
                .filter(|(p, _)| Some(*p) != own)
                .any(|(p, _)| self.heard.get(p).is_some_and(|at| *at > fresh));
            if heard {
                return false;
            }
            if start.elapsed() >= LAST_LIVE_AFTER {
                if self.lease.holding() {
                    log_info!(
                        "fleet: stopping, took the fleet level whose holder fell silent, to end its input"
                    );
                    return true;
                }
                if !said {
                    said = true;
                    log_info!(
                        "fleet: stopping as the last live partition while another process holds the fleet level; waiting up to {} for its lease to lapse",
                        humantime::format_duration(limit)
                    );
                }
            }
            if let Some((r, mine)) = self.lease.current()
                && r != first
                && !mine
            {
                if said {
                    log_info!(
                        "fleet: the fleet level's holder renewed its lease; it ends the fleet's input itself"
                    );
                }
                return false;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        log_warn!(
            "fleet: the fleet level's lease did not lapse within {}; the fleet's last steps wait for its next holder",
            humantime::format_duration(limit)
        );
        false
    }

    /// This process's standby key.
    fn standby_key(&self) -> String {
        format!(
            "fleet.standby.{}.pid{}",
            kv_key_part_of(&self.partition),
            std::process::id()
        )
    }

    /// Not holding its partition's lease (`holding` false), this process is a standby: it
    /// renews its standby key every [`STANDBY_EVERY`] so that a fleet holder stopping hands the
    /// fleet level over instead of closing its input; taking the partition over, it marks the
    /// key stale.
    fn stand_by(&mut self, holding: bool) {
        let due = match (holding, self.standby_at) {
            (false, None) => true,
            (false, Some(at)) => at.elapsed() >= STANDBY_EVERY,
            (true, Some(_)) => {
                self.standby_at = None;
                let _ = self
                    .jobs
                    .send(Job::Put(self.standby_key(), b"0".to_vec().into()));
                return;
            }
            (true, None) => false,
        };
        if due {
            self.standby_at = Some(Instant::now());
            let _ = self.jobs.send(Job::Put(
                self.standby_key(),
                now_ns().to_string().into_bytes().into(),
            ));
        }
    }

    /// Whether another process is a live standby (its standby key renewed within three
    /// [`STANDBY_EVERY`]): it will take a partition over, so the fleet's input has not ended.
    /// Logged once (`said`). Not known (the keys cannot be listed): not live, as before.
    fn standby_live(&self, said: &mut bool) -> bool {
        let live = self
            .live_standby(None, self.own_key_unless_standing_by())
            .ok()
            .flatten();
        if let Some(key) = &live
            && !*said
        {
            *said = true;
            log_info!(
                "fleet: a standby is live ({key}): the fleet level is handed over, its input not closed"
            );
        }
        live.is_some()
    }

    /// This process's standby key unless it stands by now (a key it left behind, deleted or
    /// marked stale, is not a standby).
    fn own_key_unless_standing_by(&self) -> Option<String> {
        self.standby_at.is_none().then(|| self.standby_key())
    }

    /// [`live_standby`] of partition `of` (`None`: any) other than key `except`, waited for.
    fn live_standby(
        &self,
        of: Option<&str>,
        except: Option<String>,
    ) -> Result<Option<String>, String> {
        let store = self.store.clone();
        let of = of.map(str::to_string);
        self.conn
            .call(async move { live_standby(store, of.as_deref(), except.as_deref()).await })
            .unwrap_or_else(|| Err("the fleet's NATS thread stopped".into()))
    }

    /// Whether a process (other than this one, for the partition it holds) holds the lease of
    /// a partition the fleet level knows: its lease key is present (deleted at a clean stop).
    fn partitions_held(&self) -> bool {
        let keys: Vec<String> = self
            .table
            .names()
            .filter(|p| !(self.holds_partition && *p == self.partition))
            // A dropped partition's holder died (its key stays until taken over); a process
            // taking it over sends at once, and the partition is live again.
            .filter(|p| !self.table.dropped(p))
            .map(|p| format!("lease.{}", kv_key_part_of(p)))
            .collect();
        let store = self.store.clone();
        self.conn
            .call(async move {
                for key in keys {
                    match store.entry(key).await {
                        Ok(Some(e)) if e.operation == kv::Operation::Put => return true,
                        Ok(_) => {}
                        // Not known: as held (the pending changes wait for the next holder).
                        Err(_) => return true,
                    }
                }
                false
            })
            .unwrap_or(true)
    }

    /// After the last write: record how far this process wrote, and give the fleet lease up.
    pub fn release(&mut self) {
        let c = &self.table.counters;
        log_info!(
            "fleet: {} changes sent again by a partition's new holder not counted twice, {} messages of a replaced generation dropped; the fleet level stepped {} times, {} changes late",
            c.repeats,
            c.stale,
            self.level.counters.steps,
            self.level.counters.late
        );
        if self.holding {
            let store = self.store.clone();
            let seq = self.written;
            let _ = self.conn.call(async move {
                store
                    .put(WRITTEN_KEY, seq.to_string().into_bytes().into())
                    .await
            });
        }
        self.flush();
        self.lease.release();
    }

    /// Wait until every queued put was sent.
    fn flush(&self) {
        let (tx, rx) = std::sync::mpsc::channel();
        if self.jobs.send(Job::Flush(tx)).is_ok() {
            let _ = rx.recv_timeout(Duration::from_secs(5));
        }
    }
}

/// The key of a live standby (its key renewed within three [`STANDBY_EVERY`]) of partition
/// `of` (`None`: of any partition), other than `except`; `Err` when the keys cannot be read.
/// Only the standby keys are read: the subjects of the bucket's stream under
/// `fleet.standby.<partition>.`, not every key of the bucket (which holds every robot's
/// instance).
async fn live_standby(
    store: kv::Store,
    of: Option<&str>,
    except: Option<&str>,
) -> Result<Option<String>, String> {
    use futures_util::TryStreamExt;
    let filter = match of {
        Some(p) => format!("{}fleet.standby.{}.>", store.prefix, kv_key_part_of(p)),
        None => format!("{}fleet.standby.>", store.prefix),
    };
    let subjects: Vec<(String, usize)> = store
        .stream
        .info_with_subjects(filter)
        .await
        .map_err(|e| e.to_string())?
        .try_collect()
        .await
        .map_err(|e| e.to_string())?;
    let stale = i64::try_from((STANDBY_EVERY * 3).as_nanos()).unwrap_or(i64::MAX);
    let now = now_ns();
    for (subject, _) in subjects {
        let Some(key) = subject.strip_prefix(store.prefix.as_str()) else {
            continue;
        };
        if except == Some(key) {
            continue;
        }
        let Some(v) = store.get(key).await.map_err(|e| e.to_string())? else {
            continue;
        };
        let at = std::str::from_utf8(&v)
            .ok()
            .and_then(|t| t.trim().parse::<i64>().ok())
            .unwrap_or(0);
        if now.saturating_sub(at) < stale {
            return Ok(Some(key.to_string()));
        }
    }
    Ok(None)
}

/// Put the queued entries in order, one at a time.
async fn publisher(
    store: kv::Store,
    mut rx: tokio::sync::mpsc::UnboundedReceiver<Job>,
    part: usize,
) {
    // The sequence the last checkpoint this process stored covers: the next one stored
    // deletes the entries up to it (never entries no stored checkpoint covers).
    let mut stored = 0;
    while let Some(job) = rx.recv().await {
        match job {
            Job::Put(key, bytes) => {
                if let Err(e) = store.put(&key, bytes).await {
                    crate::log::warn_limited("fleet put", || {
                        format!("fleet: cannot put {key}: {e}")
                    });
                }
            }
            Job::Checkpoint(taken, held) => {
                let seq = taken.seq;
                let started = Instant::now();
                let json = match tokio::task::spawn_blocking(move || taken.encode()).await {
                    Ok(Ok(Some(json))) => json,
                    Ok(Ok(None)) => {
                        crate::log::warn_limited("fleet checkpoint", || {
                            "fleet: the fleet level holds a value a checkpoint cannot keep; its entries are kept".into()
                        });
                        continue;
                    }
                    Ok(Err(e)) => {
                        crate::log::warn_limited("fleet checkpoint put", || {
                            format!(
                                "fleet: cannot store the fleet checkpoint: {e}; the entries are kept"
                            )
                        });
                        continue;
                    }
                    Err(e) => {
                        crate::log::warn_limited("fleet checkpoint put", || {
                            format!(
                                "fleet: cannot store the fleet checkpoint: cannot encode it: {e}; the entries are kept"
                            )
                        });
                        continue;
                    }
                };
                let encode = started.elapsed();
                let s = match checkpoint::store(&store, seq, json.into(), part).await {
                    Ok(s) => s,
                    Err(e) => {
                        crate::log::warn_limited("fleet checkpoint put", || {
                            format!(
                                "fleet: cannot store the fleet checkpoint: {e}; the entries are kept"
                            )
                        });
                        continue;
                    }
                };
                // The first at info, then every 5 s at debug.
                let line = format!(
                    "fleet: checkpoint at stream sequence {seq}: {} bytes of JSON, {} bytes stored in {} parts (held the step loop {} ms, encoded in {} ms, compressed in {} ms, put in {} ms)",
                    s.json,
                    s.bytes,
                    s.parts,
                    held.as_millis(),
                    encode.as_millis(),
                    s.compress.as_millis(),
                    s.put.as_millis()
                );
                if stored == 0 {
                    log_info!("{line}");
                } else {
                    log_debug!("{line}");
                }
                let upto = std::mem::replace(&mut stored, seq);
                checkpoint::trim(&store, upto, s.first).await;
            }
            Job::Flush(done) => {
                let _ = done.send(());
            }
        }
    }
}

/// Follow every fleet entry of the bucket after stream sequence `after` (a checkpoint's; 0:
/// from the first), in the stream's order, and the holder's progress.
async fn follow(store: kv::Store, inbox: Arc<Mutex<Inbox>>, after: u64) {
    use futures_util::StreamExt;
    let progress = {
        let (store, inbox) = (store.clone(), Arc::clone(&inbox));
        async move {
            let Ok(mut w) = store.watch_with_history(WRITTEN_KEY).await else {
                return;
            };
            while let Some(Ok(e)) = w.next().await {
                if let Some(n) = std::str::from_utf8(&e.value)
                    .ok()
                    .and_then(|s| s.trim().parse::<u64>().ok())
                    && let Ok(mut i) = inbox.lock()
                {
                    i.written = i.written.max(n);
                }
            }
        }
    };
    tokio::spawn(progress);
    // A watch made again (after an error) starts from the first entry: each is taken once.
    let mut last = after;
    loop {
        match store.watch_with_history("fleet.m.>").await {
            Ok(mut w) => {
                while let Some(e) = w.next().await {
                    match e {
                        Ok(e) if e.operation == kv::Operation::Put && e.revision > last => {
                            last = e.revision;
                            if let Ok(mut i) = inbox.lock() {
                                i.msgs.push_back((e.revision, e.value));
                            }
                        }
                        Ok(_) => {}
                        Err(err) => {
                            log_warn!("fleet: following the fleet's entries: {err}");
                        }
                    }
                }
            }
            Err(e) => log_warn!("fleet: cannot follow the fleet's entries: {e}; retrying"),
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
}
