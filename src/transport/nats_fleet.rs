//! The step loop of `--state nats://...`: stdin -> processor -> stdout, as
//! [`crate::transport::stdio`], with a shared state backend and, with `?lease=NAME`, a
//! partition lease.
//!
//! Owns: restoring each instance from the backend before its first record is stepped; while
//! standing by (another process holds the lease), keeping the records read in a replay buffer
//! instead of stepping them; on taking the lease, replaying the buffer, skipping each record an
//! instance's restored state already covers (timestamp not after its last evaluated step); on
//! losing it, dropping every instance; the save points (`--state-interval`, every ending while
//! holding the lease, then releasing it). Signals and SIGHUP as in the stdio transport.

use crate::log::{self, Level};
use crate::processor::Processor;
use crate::processor::clock::Wall;
use crate::processor::instances::Key;
use crate::state::Backend;
use crate::state::lease::Lease;
use crate::transport::Ending;
use crate::watchdog::{Phase, Watch};
use lineproto::{Metric, Record, RecordSplitter, parse_record_into};
use std::collections::{HashMap, VecDeque};
use std::io::Write;
use std::time::{Duration, Instant};
use tokio::io::AsyncReadExt;

const BUF: usize = 64 * 1024;
/// Most bytes of records a standby keeps for replay; the oldest go first past it.
const MAX_BUFFER_BYTES: usize = 256 << 20;

/// What the loop needs besides the processor.
pub struct Fleet<'a> {
    pub backend: &'a mut dyn Backend,
    /// `None`: no lease, this process steps everything it reads.
    pub lease: Option<Lease>,
    pub instance_by: Vec<String>,
    /// `--state-interval`.
    pub interval: Option<Duration>,
    /// How long a standby keeps records for replay.
    pub window: Duration,
    /// A processor without instances (after losing the lease).
    pub fresh: &'a dyn Fn() -> Option<Processor>,
    /// SIGHUP.
    pub on_hangup: &'a mut dyn FnMut(&mut Processor, &mut Vec<u8>),
    /// Where the loop marks what it is doing, for the step watchdog (`--step-timeout`).
    pub watch: std::sync::Arc<Watch>,
}

struct Loop<'a, 'b> {
    f: &'b mut Fleet<'a>,
    active: bool,
    buffer: VecDeque<(Instant, Record)>,
    buffered_bytes: usize,
    scratch: Metric,
}

impl Loop<'_, '_> {
    /// The instance key and timestamp of a record, if it parses.
    fn key_of(&mut self, rec: &Record) -> Option<(Key, Option<i64>)> {
        if rec.oversized || !matches!(parse_record_into(&rec.bytes, &mut self.scratch), Ok(true)) {
            return None;
        }
        let key = self
            .f
            .instance_by
            .iter()
            .map(|t| self.scratch.tag(t).map(str::to_string))
            .collect();
        Some((key, self.scratch.timestamp))
    }

    /// The instance key of a record from its measurement and tags alone (the step loop parses
    /// the whole record afterwards; a lidar record's fields cost most of a parse). Falls back
    /// to [`Loop::key_of`] when the short form does not parse.
    fn key_only(&mut self, rec: &Record) -> Option<Key> {
        let bytes = &rec.bytes;
        let start = bytes
            .iter()
            .position(|b| !b.is_ascii_whitespace())
            .unwrap_or(bytes.len());
        let mut i = start;
        while i < bytes.len() && bytes[i] != b' ' && bytes[i] != b'\n' {
            i += if bytes[i] == b'\\' { 2 } else { 1 };
        }
        let series = bytes.get(start..i.min(bytes.len())).unwrap_or_default();
        if !rec.oversized && !series.is_empty() && series[0] != b'#' {
            let mut head = Vec::with_capacity(series.len() + 5);
            head.extend_from_slice(series);
            head.extend_from_slice(b" _=0i");
            if matches!(parse_record_into(&head, &mut self.scratch), Ok(true)) {
                return Some(
                    self.f
                        .instance_by
                        .iter()
                        .map(|t| self.scratch.tag(t).map(str::to_string))
                        .collect(),
                );
            }
        }
        self.key_of(rec).map(|(k, _)| k)
    }

    fn step(&mut self, proc: &mut Processor, rec: &Record, out: &mut Vec<u8>) {
        if let Some(key) = self.key_only(rec) {
            self.f.backend.arriving(&key, proc);
        }
        proc.record(rec, out);
    }

    fn keep(&mut self, rec: Record) {
        let now = Instant::now();
        self.buffered_bytes += rec.bytes.len();
        self.buffer.push_back((now, rec));
        while let Some((at, r)) = self.buffer.front() {
            let old = now.saturating_duration_since(*at) > self.f.window;
            if !old && self.buffered_bytes <= MAX_BUFFER_BYTES {
                break;
            }
            if !old {
                log::warn_limited("replay buffer", || {
                    format!(
                        "standby: replay buffer over {} MB; dropping its oldest records",
                        MAX_BUFFER_BYTES >> 20
                    )
                });
            }
            self.buffered_bytes -= r.bytes.len();
            self.buffer.pop_front();
        }
    }

    /// Follow the lease: take over (restore, replay) or stand by (drop instances if lost).
    fn follow_lease(&mut self, proc: &mut Processor, out: &mut Vec<u8>) {
        let Some(lease) = &self.f.lease else {
            return;
        };
        let holding = lease.holding();
        let lost = lease.take_lost();
        if self.active && !holding {
            proc.flush(out);
            self.active = false;
            log::log(
                Level::Warn,
                &format!(
                    "lease: not holding partition {} (renewal overdue or taken over); standing by",
                    lease.name
                ),
            );
        }
        if lost {
            if let Some(mut p) = (self.f.fresh)() {
                p.watch_with(self.f.watch.lane());
                *proc = p;
            }
            self.f.backend.forget();
        }
        if holding && !self.active {
            self.active = true;
            let name = lease.name.clone();
            self.replay(proc, out, &name);
        }
    }

    /// Step the buffered records the restored state does not cover yet.
    fn replay(&mut self, proc: &mut Processor, out: &mut Vec<u8>, name: &str) {
        let buffer = std::mem::take(&mut self.buffer);
        self.buffered_bytes = 0;
        let mut keyed = Vec::with_capacity(buffer.len());
        for (at, rec) in buffer {
            let k = self.key_of(&rec);
            if let Some((key, _)) = &k {
                self.f.backend.arriving(key, proc);
            }
            keyed.push((k, at, rec));
        }
        let covered: HashMap<Key, i64> = proc
            .monitors()
            .filter_map(|(k, m)| Some((k.clone(), m.last_evaluated()?)))
            .collect();
        let (mut stepped, mut skipped) = (0usize, 0usize);
        for (k, at, rec) in keyed {
            if let Some((key, Some(ts))) = &k
                && covered.get(key).is_some_and(|last| ts <= last)
            {
                skipped += 1;
                continue;
            }
            // Each record stepped as when it arrived: its instance's silent time counts from
            // then, as in a process that held the lease all along.
            proc.set_wall(Wall::at(at));
            proc.record(&rec, out);
            stepped += 1;
        }
        proc.flush(out);
        log::log(
            Level::Info,
            &format!(
                "lease: holding partition {name}; replayed {stepped} buffered records ({skipped} already covered by the saved state)"
            ),
        );
    }

    fn save(&mut self, proc: &Processor, level: Level) {
        if !self.active || self.f.lease.as_ref().is_some_and(|l| !l.holding()) {
            return;
        }
        let start = Instant::now();
        match self.f.backend.save(proc) {
            Ok(n) => log::log(
                level,
                &format!(
                    "state: saved {n} monitor instances to {} in {} ms",
                    self.f.backend.describe(),
                    start.elapsed().as_millis()
                ),
            ),
            Err(e) => log::log(
                Level::Error,
                &format!("state: cannot save to {}: {e}", self.f.backend.describe()),
            ),
        }
    }
}

/// Run until EOF, a signal or a closed stdout; saves (and releases the lease) at the end.
pub async fn run(proc: &mut Processor, mut fleet: Fleet<'_>) -> std::io::Result<Ending> {
    fleet.backend.load(proc);
    let mut l = Loop {
        active: fleet.lease.is_none(),
        f: &mut fleet,
        buffer: VecDeque::new(),
        buffered_bytes: 0,
        scratch: Metric::default(),
    };
    let mut stdin = tokio::io::stdin();
    let mut splitter = RecordSplitter::default();
    let mut buf = vec![0u8; BUF];
    let mut out = Vec::with_capacity(BUF);
    let mut signals = crate::transport::Signals::new()?;
    let period = l.f.interval.unwrap_or(Duration::from_secs(86_400 * 365));
    let mut saves = tokio::time::interval_at(tokio::time::Instant::now() + period, period);
    saves.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut lease_poll = tokio::time::interval(Duration::from_millis(20));
    lease_poll.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let watch = l.f.watch.clone();
    let ending = loop {
        // A standby holds no instances: only the process stepping a partition advances clocks.
        // A record partly read is input arriving, not silence.
        let deadline = proc
            .next_deadline()
            .filter(|_| l.active && !splitter.in_record());
        let n = tokio::select! {
            // Biased, in this order (see `Signals`): a signal is never starved by input, and a
            // delay falls due by the wall clock only when no input is waiting (input not read yet
            // is not silence).
            biased;
            _ = signals.term.recv() => break Ending::Signal,
            _ = signals.int.recv() => break Ending::Signal,
            _ = signals.hup.recv() => {
                (l.f.on_hangup)(proc, &mut out);
                let _busy = watch.enter(Phase::Reload);
                if write_out(&mut out).is_err() {
                    return Ok(finish(l, proc, Ending::OutputClosed));
                }
                continue;
            }
            _ = saves.tick(), if l.f.interval.is_some() => {
                l.save(proc, Level::Debug);
                continue;
            }
            _ = lease_poll.tick(), if l.f.lease.is_some() => {
                l.follow_lease(proc, &mut out);
                if write_out(&mut out).is_err() {
                    return Ok(finish(l, proc, Ending::OutputClosed));
                }
                continue;
            }
            r = stdin.read(&mut buf) => r?,
            _ = crate::transport::sleep_until(deadline) => {
                let _busy = watch.enter(Phase::Delays);
                crate::transport::advance_silent(proc, Wall::now(), &mut out);
                watch.set(Phase::Writing);
                if write_out(&mut out).is_err() {
                    return Ok(finish(l, proc, Ending::OutputClosed));
                }
                continue;
            }
        };
        if n == 0 {
            break Ending::Eof;
        }
        l.follow_lease(proc, &mut out);
        let _busy = watch.enter(Phase::Records);
        proc.set_wall(Wall::now());
        splitter.push(buf.get(..n).unwrap_or_default());
        while let Some(rec) = splitter.next_record() {
            if l.active {
                l.step(proc, &rec, &mut out);
            } else {
                l.keep(rec);
            }
        }
        if n < BUF && l.active {
            proc.flush(&mut out);
        }
        watch.set(Phase::Writing);
        if write_out(&mut out).is_err() {
            return Ok(finish(l, proc, Ending::OutputClosed));
        }
    };
    let busy = watch.enter(Phase::Records);
    while let Some(rec) = splitter.finish() {
        if l.active {
            l.step(proc, &rec, &mut out);
        }
    }
    if l.active {
        proc.flush(&mut out);
    }
    watch.set(Phase::Writing);
    let closed = write_out(&mut out).is_err();
    drop(busy);
    Ok(finish(
        l,
        proc,
        if closed { Ending::OutputClosed } else { ending },
    ))
}

/// The last save point: save while holding the lease, then hand it over.
fn finish(mut l: Loop<'_, '_>, proc: &Processor, ending: Ending) -> Ending {
    if l.active {
        l.save(proc, Level::Info);
    } else {
        log::log(
            Level::Info,
            &format!(
                "state: standing by at the end; nothing saved ({} records buffered, not stepped)",
                l.buffer.len()
            ),
        );
    }
    if let Some(lease) = &l.f.lease {
        lease.release();
    }
    ending
}

fn write_out(out: &mut Vec<u8>) -> std::io::Result<()> {
    if out.is_empty() {
        return Ok(());
    }
    let mut stdout = std::io::stdout().lock();
    let r = stdout.write_all(out).and_then(|()| stdout.flush());
    out.clear();
    r
}
