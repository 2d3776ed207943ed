//! The one step loop every transport plugs into: bytes from a [`Source`], split into records
//! and stepped on the processor, outputs to a [`Sink`], until the input ends, a signal comes or
//! the reader of the outputs goes away. Pending steps are always evaluated and written.
//!
//! Owns, for every transport alike: every record answered within the read that brought it
//! (before the next read's records are stepped; with worker threads, after a read that filled
//! the buffer the next one is taken while the slowest worker finishes, see
//! [`Source::read_ahead`]); the wall clock of each read; waking when an instance's `delay`
//! falls due while the input is silent ([`Processor::advance_wall`]); the signals (SIGTERM and
//! SIGINT end the run, SIGHUP reloads the spec); the save points of a state store
//! (`--state-interval`, and every ending) with its [`crate::state::Backend`]; the marks of the
//! step watchdog; feeding the fleet level (`--fleet-spec`) after every read and every wall-clock
//! advance. Stepping itself is on one thread or spread over several ([`shards`]), or with
//! a store shared by a fleet ([`shared`]: instances restored as they arrive, the partition lease
//! followed).
//!
//! Each loop iteration selects, `biased`, in this order: SIGTERM, SIGINT, SIGHUP (a signal is
//! never starved by input), the periodic save, the lease poll, the input, and last the
//! wall-clock deadline: a delay falls due by the wall clock only when no input is waiting, and
//! a record partly read (or being skipped past the size limit) is input arriving, not silence.

pub mod shards;
pub mod shared;

use crate::fleet::Feed;
use crate::log::Level as LogLevel;
use crate::processor::Processor;
use crate::processor::clock::Wall;
use crate::spec_feed::Updates;
use crate::state::Backend;
use crate::state::lease::Lease;
use crate::watchdog::{Phase, Watch};
use lineproto::{RecordRef, RecordSplitter};
use shards::Shards;
use shared::Shared;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Where the bytes come from (stdin, a UDP socket).
pub trait Source {
    /// Read the next bytes into `buf`: `None` at the end of the input.
    fn read(&mut self, buf: &mut [u8]) -> impl Future<Output = std::io::Result<Option<usize>>>;

    /// How much to read at a time when stepping on `threads` threads (a source may make room
    /// for it, such as a pipe enlarged). A read that fills it means more input is waiting.
    fn read_size(&mut self, _threads: usize) -> usize {
        64 * 1024
    }

    /// Whether each read is a whole message (a datagram): its last record ends with it.
    fn whole_reads(&self) -> bool {
        false
    }

    /// Read into `buf` only what is waiting now, without blocking: `Some(n)` with `n > 0`
    /// bytes, `None` when nothing is waiting, at the end of the input or on an error (the next
    /// [`Source::read`] meets them again), or when the source cannot tell. With worker threads
    /// the loop reads ahead while a worker still steps the read before.
    fn read_ahead(&mut self, _buf: &mut [u8]) -> Option<usize> {
        None
    }
}

/// Where the outputs go (stdout, UDP datagrams).
pub trait Sink {
    /// Write `out` and then each of `more` (the worker threads' outputs), in that order, and
    /// empty them all. An error means the reader went away.
    fn write(
        &mut self,
        out: &mut Vec<u8>,
        more: &mut [Vec<u8>],
    ) -> impl Future<Output = std::io::Result<()>>;
}

/// Where the state is kept, and when it is saved.
pub struct Store<'a> {
    pub backend: &'a mut dyn Backend,
    /// `--state-interval`: save this often as well as at every ending.
    pub interval: Option<Duration>,
    /// A store shared by a fleet (NATS): instances restored as they arrive.
    pub shared: Option<SharedStore>,
}

/// What a store shared by a fleet adds.
pub struct SharedStore {
    /// `?lease=NAME`: the partition lease; `None` steps everything read.
    pub lease: Option<Lease>,
    /// How long a standby keeps records for replay.
    pub window: Duration,
}

/// What the loop runs with besides its processor, source and sink.
pub struct Setup<'a> {
    /// Threads to spread `--instance-by` instances over (1: the calling thread only), as
    /// `cli/config.rs` decided (one with a store: it holds one processor's instances, and a
    /// shared one restores each as it arrives on the calling thread).
    pub threads: usize,
    /// New spec versions: SIGHUP, a watched spec file, a fleet's spec channel.
    pub updates: &'a mut Updates,
    pub store: Option<Store<'a>>,
    /// Where the loop marks what it is doing, for the step watchdog (`--step-timeout`).
    pub watch: Arc<Watch>,
    /// `--fleet-spec`: the fleet level (or, partitioned, the way to it), fed from every
    /// thread's instances after each read.
    pub fleet: Option<&'a mut Feed>,
}

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending {
    /// End of input.
    Eof,
    /// SIGTERM or SIGINT.
    Signal,
    /// The reader of our output went away.
    OutputClosed,
}

/// Run `proc` on `source` and `sink` until the input ends, a signal or a closed output. A store
/// is loaded first and saved at the end, whatever the ending.
pub async fn run<S: Source, K: Sink>(
    proc: &mut Processor,
    source: &mut S,
    sink: &mut K,
    setup: Setup<'_>,
) -> std::io::Result<Ending> {
    let Setup {
        threads,
        updates,
        mut store,
        watch,
        fleet,
    } = setup;
    let mut shared = store.as_mut().and_then(|s| {
        let sh = s.shared.take()?;
        Some(Shared::new(
            proc.instance_by().to_vec(),
            sh.lease,
            sh.window,
            watch.clone(),
        ))
    });
    // The versions a channel already holds are in force before anything is restored (an
    // instance continues in the version its rules give it) and before the first record; the
    // `--threads` workers made below copy them.
    let mut out = Vec::with_capacity(64 * 1024);
    updates.tick(&mut [&mut *proc], &mut out);
    let mut fleet = fleet;
    if let Some(f) = fleet.as_deref_mut() {
        for c in updates.take_fleet() {
            f.switch(c);
        }
        for c in updates.take_robot_commits() {
            f.robot_rollout(&c, &mut out);
        }
    }
    if let Some(s) = store.as_mut() {
        s.backend.load(proc);
        // `--state FILE` with the fleet level in this process: it goes on from the saved one.
        if let (Some(json), Some(f)) = (s.backend.take_fleet(), fleet.as_deref_mut()) {
            f.restore_saved(&json, &s.backend.describe());
        }
    }
    let interval = store.as_ref().and_then(|s| s.interval);
    let mut shards = Shards::new(proc, threads, &watch).map_err(std::io::Error::other)?;
    let mut l = Loop {
        proc,
        shards: &mut shards,
        shared: shared.as_mut(),
        backend: store.as_mut().map(|s| &mut *s.backend),
        out,
        watch: &watch,
        fleet,
    };
    let r = l.run(source, sink, updates, interval).await;
    // Every ending (EOF, signal, closed output, I/O error) has evaluated what it could: save.
    l.save(LogLevel::Info);
    if let Some(f) = l.fleet.as_deref_mut() {
        f.release();
    }
    if let Some(s) = &l.shared {
        if !s.active {
            log_info!(
                "state: standing by at the end; nothing saved ({} records buffered, not stepped)",
                s.buffered()
            );
        }
        if let Some(lease) = &s.lease {
            lease.release();
        }
    }
    shards.finish(proc);
    r
}

/// One run's moving parts.
struct Loop<'p, 'b> {
    proc: &'p mut Processor,
    shards: &'p mut Shards,
    shared: Option<&'p mut Shared>,
    backend: Option<&'p mut (dyn Backend + 'b)>,
    out: Vec<u8>,
    watch: &'p Watch,
    fleet: Option<&'p mut Feed>,
}

impl Loop<'_, '_> {
    async fn run<S: Source, K: Sink>(
        &mut self,
        source: &mut S,
        sink: &mut K,
        updates: &mut Updates,
        interval: Option<Duration>,
    ) -> std::io::Result<Ending> {
        let watch = self.watch;
        let mut signals = Signals::new()?;
        let mut saves = every(interval);
        let lease_poll = self
            .shared
            .as_ref()
            .and_then(|s| s.lease.as_ref())
            .is_some();
        let mut lease_ticks = every(lease_poll.then_some(Duration::from_millis(20)));
        let mut update_ticks = every(updates.interval());
        let size = source.read_size(self.shards.threads());
        let mut buf = vec![0u8; size];
        // With worker threads: the next read, taken while a worker still steps the one before
        // when that one filled `buf` (so more input was waiting); `pending` bytes of it.
        let mut ahead = Vec::new();
        let mut pending = None;
        let mut splitter = RecordSplitter::default();
        let ending = loop {
            // A standby holds no instances: only the process stepping a partition advances
            // clocks. A record partly read is input arriving, not silence.
            let deadline = self
                .shards
                .next_deadline(self.proc)
                .filter(|_| self.active() && !splitter.in_record());
            let n = tokio::select! {
                biased;
                _ = signals.term.recv() => break Ending::Signal,
                _ = signals.int.recv() => break Ending::Signal,
                _ = signals.hup.recv() => {
                    let _busy = watch.enter(Phase::Reload);
                    self.updates(updates, true);
                    if self.write(sink).await.is_err() {
                        return Ok(Ending::OutputClosed);
                    }
                    continue;
                }
                _ = tick(&mut saves) => {
                    self.save(LogLevel::Debug);
                    continue;
                }
                _ = tick(&mut update_ticks) => {
                    let _busy = watch.enter(Phase::Reload);
                    self.updates(updates, false);
                    if self.write(sink).await.is_err() {
                        return Ok(Ending::OutputClosed);
                    }
                    continue;
                }
                _ = tick(&mut lease_ticks) => {
                    self.follow_lease();
                    self.fleet_tick();
                    if self.write(sink).await.is_err() {
                        return Ok(Ending::OutputClosed);
                    }
                    continue;
                }
                r = async {
                    match pending.take() {
                        Some(n) => Ok(Some(n)),
                        None => source.read(&mut buf).await,
                    }
                } => r?,
                _ = sleep_until(deadline) => {
                    // Silent input: the instances whose delays fell due move on by the wall clock.
                    let _busy = watch.enter(Phase::Delays);
                    let wall = Wall::now();
                    advance_silent(self.proc, wall, &mut self.out);
                    let out = &mut self.out;
                    self.shards.each(|p| advance_silent(p, wall, out));
                    self.fleet(false);
                    watch.set(Phase::Writing);
                    if self.write(sink).await.is_err() {
                        return Ok(Ending::OutputClosed);
                    }
                    continue;
                }
            };
            let Some(n) = n else {
                break Ending::Eof;
            };
            self.follow_lease();
            let _busy = watch.enter(Phase::Records);
            let bytes = buf.get(..n).unwrap_or_default();
            let whole = source.whole_reads();
            let end_read = whole || n < size;
            let mut read_ahead = || {
                if !end_read {
                    ahead.resize(size, 0);
                    pending = source.read_ahead(&mut ahead);
                }
            };
            self.records(&mut splitter, bytes, end_read, whole, &mut read_ahead)?;
            self.fleet(false);
            if pending.is_some() {
                std::mem::swap(&mut buf, &mut ahead);
            }
            if whole {
                // Each message on its own: its lines are numbered from 1.
                splitter = RecordSplitter::default();
            }
            watch.set(Phase::Writing);
            if self.write(sink).await.is_err() {
                return Ok(Ending::OutputClosed);
            }
        };
        let _busy = watch.enter(Phase::Records);
        // A read taken ahead is stepped and answered before the ending.
        if let Some(n) = pending.take() {
            let bytes = buf.get(..n).unwrap_or_default();
            self.records(&mut splitter, bytes, true, false, &mut || {})?;
        }
        self.records(&mut splitter, &[], true, true, &mut || {})?;
        self.fleet(true);
        if let Some(f) = self.fleet.as_deref_mut() {
            // The fleet's end waits for the entries' store, the other partitions and the fleet
            // lease, each wait bounded by time (docs/fleet.md, "Partitions that stop"): no step
            // to watch. (Watched, a loaded machine made those waits pass the step timeout and
            // the watchdog ended a process whose records were all stepped, losing its last lines.)
            watch.set(Phase::Idle);
            f.finish(&mut self.out);
        }
        watch.set(Phase::Writing);
        if self.write(sink).await.is_err() {
            return Ok(Ending::OutputClosed);
        }
        Ok(ending)
    }

    /// New spec versions into every processor of the run: a reload on SIGHUP (`hangup`),
    /// else whatever the watched file or the channel brought. Status lines go to the output.
    fn updates(&mut self, updates: &mut Updates, hangup: bool) {
        let mut procs = self.shards.all(self.proc);
        if hangup {
            updates.hangup(&mut procs, &mut self.out);
        } else {
            updates.tick(&mut procs, &mut self.out);
        }
        // Committed fleet rollouts go to the fleet level.
        let commits = updates.take_fleet();
        let robots = updates.take_robot_commits();
        if let Some(f) = self.fleet.as_deref_mut() {
            for c in commits {
                f.switch(c);
            }
            // A robot rollout that leaves a fleet input without its robot output says so.
            for c in &robots {
                f.robot_rollout(c, &mut self.out);
            }
        }
    }

    /// Feed the fleet level what every thread's instances produced and step it as far as its
    /// watermark allows (`end`: the input ended, everything pending).
    fn fleet(&mut self, end: bool) {
        let Some(feed) = self.fleet.as_deref_mut() else {
            return;
        };
        let drained = self
            .shards
            .all(self.proc)
            .into_iter()
            .map(|p| p.fleet_drain())
            .collect();
        let lease = self.shared.as_ref().and_then(|s| s.lease.as_ref());
        feed.pump(drained, end, lease, &mut self.out);
    }

    /// Between reads (the lease poll): a partitioned fleet's heartbeat and its fleet level's
    /// progress, with what the instances gave since the last read: a takeover's replay
    /// ([`Self::follow_lease`], just before) steps the buffered records here, and their changes
    /// go to the fleet now. (Before, the tick sent a heartbeat alone and the replayed records'
    /// changes waited in the taps for the next read, which a partition whose input waits for
    /// the fleet's answer never gets: docs/fleet.md, "A fleet of NATS partitions".)
    fn fleet_tick(&mut self) {
        if matches!(self.fleet.as_deref(), Some(Feed::Nats(_))) {
            self.fleet(false);
        }
    }

    /// Stepping now: without a lease, or holding it.
    fn active(&self) -> bool {
        self.shared.as_ref().is_none_or(|s| s.active)
    }

    /// Step the records of one read (`bytes`) as the splitter finds them; `end_read`: no more
    /// input is waiting; `last`: the input or the message ended, so a last line without its
    /// newline is a record too. With worker threads, `read_ahead` runs once the calling
    /// thread has stepped its records, while a worker may still step its own.
    fn records(
        &mut self,
        splitter: &mut RecordSplitter,
        bytes: &[u8],
        end_read: bool,
        last: bool,
        read_ahead: &mut dyn FnMut(),
    ) -> std::io::Result<()> {
        let wall = Wall::now();
        if self.shards.threads() > 1 {
            splitter.push_with(bytes, |rec| self.shards.route(rec));
            if last {
                while let Some(rec) = splitter.finish() {
                    self.shards.route(rec.view());
                }
            }
            return self
                .shards
                .process(self.proc, end_read, wall, &mut self.out, read_ahead);
        }
        let Loop {
            proc,
            shared,
            backend,
            out,
            ..
        } = self;
        proc.set_wall(wall);
        let mut step = |rec: RecordRef<'_>| match (shared.as_deref_mut(), backend.as_deref_mut()) {
            (Some(s), Some(b)) => s.step(proc, b, rec, out),
            _ => proc.record_ref(rec, out),
        };
        // Each record straight from the read buffer (no copy per record).
        splitter.push_with(bytes, &mut step);
        if last {
            while let Some(rec) = splitter.finish() {
                step(rec.view());
            }
        }
        if end_read && self.active() {
            self.proc.end_of_read();
        }
        Ok(())
    }

    /// Follow the partition lease, if any: take over (restore, replay) or stand by.
    fn follow_lease(&mut self) {
        if let (Some(s), Some(b)) = (&mut self.shared, &mut self.backend) {
            s.follow_lease(self.proc, &mut **b, &mut self.out);
        }
    }

    /// Save to the store, if any and if this process steps; success logged at `level`, failure
    /// as an error (never fatal).
    fn save(&mut self, level: LogLevel) {
        if self.shared.as_ref().is_some_and(|s| !s.may_save()) {
            return;
        }
        let Some(backend) = self.backend.as_mut() else {
            return;
        };
        let start = Instant::now();
        if let Some(f) = self.fleet.as_deref() {
            backend.keep_fleet(&|| f.saved());
        }
        match backend.save(self.proc) {
            Ok(n) => log_at!(
                level,
                "state: saved {n} monitor instances to {} in {} ms",
                backend.describe(),
                start.elapsed().as_millis()
            ),
            Err(e) => log_error!("state: cannot save to {}: {e}", backend.describe()),
        }
    }

    async fn write<K: Sink>(&mut self, sink: &mut K) -> std::io::Result<()> {
        sink.write(&mut self.out, self.shards.outs_mut()).await
    }
}

/// A timer firing every `period` (the first one period from now; ticks missed while busy are
/// not made up), or never.
fn every(period: Option<Duration>) -> Option<tokio::time::Interval> {
    period.map(|d| {
        let d = d.max(Duration::from_millis(1));
        let mut i = tokio::time::interval_at(tokio::time::Instant::now() + d, d);
        i.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        i
    })
}

/// The next tick of [`every`]'s timer (forever without one).
async fn tick(timer: &mut Option<tokio::time::Interval>) {
    match timer {
        Some(t) => {
            t.tick().await;
        }
        None => std::future::pending().await,
    }
}

/// Sleep until `deadline` (forever without one): a processor's next `delay` by the wall clock.
async fn sleep_until(deadline: Option<Instant>) {
    match deadline {
        Some(d) => tokio::time::sleep_until(tokio::time::Instant::from_std(d)).await,
        None => std::future::pending().await,
    }
}

/// The signals the loop answers: SIGTERM and SIGINT end the run, SIGHUP reloads the spec.
struct Signals {
    term: tokio::signal::unix::Signal,
    int: tokio::signal::unix::Signal,
    hup: tokio::signal::unix::Signal,
}

impl Signals {
    /// Install the handlers (before the first read, so no signal is missed).
    fn new() -> std::io::Result<Self> {
        use tokio::signal::unix::{SignalKind, signal};
        Ok(Self {
            term: signal(SignalKind::terminate())?,
            int: signal(SignalKind::interrupt())?,
            hup: signal(SignalKind::hangup())?,
        })
    }
}

/// The silent input: the deadline passed with no input waiting, so `proc` moves on to `wall`
/// (read once per wake-up, the same for every processor of the loop) and the delays that fell
/// due are evaluated, outputs appended to `out`.
fn advance_silent(proc: &mut Processor, wall: Wall, out: &mut Vec<u8>) {
    proc.set_wall(wall);
    proc.advance_wall(wall.at, out);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::processor::Options;
    use crate::spec_feed::reload::SpecSource;
    use tessla_syntax::include::MemResolver;

    /// Two reads: the first fills the buffer, the second is taken ahead while the workers step
    /// the first, and SIGTERM arrives before the loop comes back for it. `read` is never
    /// called a third time when the signal was seen first.
    struct Ahead {
        first: Option<Vec<u8>>,
        ahead: Option<Vec<u8>>,
        size: usize,
        read_after_ahead: bool,
    }

    impl Source for Ahead {
        async fn read(&mut self, buf: &mut [u8]) -> std::io::Result<Option<usize>> {
            let Some(first) = self.first.take() else {
                self.read_after_ahead = true;
                return std::future::pending().await;
            };
            buf.get_mut(..first.len())
                .ok_or_else(|| std::io::Error::other("short buffer"))?
                .copy_from_slice(&first);
            Ok(Some(first.len()))
        }

        fn read_size(&mut self, _threads: usize) -> usize {
            self.size
        }

        fn read_ahead(&mut self, buf: &mut [u8]) -> Option<usize> {
            let ahead = self.ahead.take()?;
            // SIGTERM to this thread: the runtime's handler has run when `raise` returns, and
            // the sink's yield lets the runtime take it in before the loop selects again.
            // SAFETY: `raise` has no memory effects; the runtime's handler is installed (the
            // loop's `Signals` came before its first read), so the process is not ended.
            assert_eq!(unsafe { libc::raise(libc::SIGTERM) }, 0, "raise(SIGTERM)");
            buf.get_mut(..ahead.len())?.copy_from_slice(&ahead);
            Some(ahead.len())
        }
    }

    struct Collect(Vec<u8>);

    impl Sink for Collect {
        async fn write(&mut self, out: &mut Vec<u8>, more: &mut [Vec<u8>]) -> std::io::Result<()> {
            self.0.append(out);
            for m in more {
                self.0.append(m);
            }
            // Let the runtime's driver take in the signal before the loop selects again.
            tokio::task::yield_now().await;
            Ok(())
        }
    }

    fn records(from: i64, to: i64) -> Vec<u8> {
        (from..to)
            .map(|i| format!("m,robot=r{} x={i}i {}\n", i % 7, 1_000 + i))
            .collect::<String>()
            .into_bytes()
    }

    /// A read taken ahead is stepped and answered even when a signal ends the run before the
    /// loop comes back for it: nothing already read is lost.
    #[test]
    fn a_read_taken_ahead_is_answered_when_a_signal_ends_the_run() {
        let resolver = MemResolver {
            files: [(
                "t.tessla".to_string(),
                "in x: Events[Int]\nout x\n".to_string(),
            )]
            .into(),
        };
        let loaded = tessla_engine::load_with("t.tessla", &resolver, &Default::default())
            .unwrap_or_else(|e| panic!("{e:?}"));
        let opts = Options {
            instance_by: vec!["robot".to_string()],
            passthrough: false,
            ..Options::default()
        };
        let mut proc = Processor::new(loaded.program, opts).unwrap_or_else(|e| panic!("{e}"));
        let (first, ahead) = (records(0, 40), records(40, 70));
        assert!(ahead.len() <= first.len());
        let mut source = Ahead {
            size: first.len(),
            first: Some(first),
            ahead: Some(ahead),
            read_after_ahead: false,
        };
        let mut sink = Collect(Vec::new());
        let mut updates = Updates::new(
            SpecSource {
                path: None,
                options: Default::default(),
            },
            false,
            "",
        );
        let setup = Setup {
            threads: 2,
            updates: &mut updates,
            store: None,
            watch: Arc::new(Watch::default()),
            fleet: None,
        };
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap_or_else(|e| panic!("{e}"));
        let ending = rt
            .block_on(run(&mut proc, &mut source, &mut sink, setup))
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(ending, Ending::Signal);
        assert!(
            !source.read_after_ahead,
            "the signal was seen after the read ahead was stepped"
        );
        let out = String::from_utf8_lossy(&sink.0);
        let mut xs: Vec<i64> = out
            .lines()
            .filter_map(|l| l.split_once(" x=")?.1.split_once("i ")?.0.parse().ok())
            .collect();
        xs.sort_unstable();
        assert_eq!(xs, (0..70).collect::<Vec<i64>>(), "{out}");
    }
}
