//! The step watchdog (`run --step-timeout`): a monitor whose step does not finish exits, so that
//! Telegraf restarts it.
//!
//! Why: Telegraf's `processors.execd` restarts a child only when it exits. A child stuck in a
//! step (an evaluation that does not end) stays alive, Telegraf blocks writing to its full stdin
//! pipe, and the robot's input stalls at `mqtt_consumer`'s `max_undelivered_messages` for good. A
//! stuck step cannot notice itself, so a thread of its own watches it.
//!
//! A write that blocks is not a stuck step: its reader (Telegraf) is alive and busy elsewhere,
//! for example parsing a huge metric we passed through (its parse grows with the square of the
//! field count: 19 s for 110,000 fields). That is backpressure: ending the process then would lose
//! what is in the pipes and the state since the last save, and answer nothing sooner. So a write
//! stalled past the bound is only warned about ([`Phase::Writing`]), and the process waits.
//!
//! Owns: the shared marks the step loops and the processors leave ([`Watch`], [`Lane`]), and the
//! watching thread ([`spawn`]) that logs what was stuck (the phase, the record's line, the
//! instance, for how long) and exits with [`EXIT_CODE`], or warns about a blocked write.
//!
//! Cost on the record path: a processor with a lane does four relaxed atomic stores per record
//! (its progress count, the line, the instance slot cleared and then set) on cache lines only its
//! own thread writes (26 instructions of a P2 record's 10,221: BENCHMARKS.md);
//! no clock is read (the watching thread samples the marks every [`tick`] and times a stall by
//! its own clock). A new instance's name is written under a lock, once per instance.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU8, AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The exit code of a run stopped by the watchdog (the book, "Exit codes").
pub const EXIT_CODE: i32 = 4;

/// What the step loop is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Phase {
    /// Waiting for input, a signal or a deadline: nothing to watch.
    Idle = 0,
    /// Evaluating the records of a read and writing their outputs.
    Records = 1,
    /// Evaluating `delay`s that fell due while the input was silent, and writing their outputs.
    Delays = 2,
    /// Reloading the spec (SIGHUP).
    Reload = 3,
    /// Writing outputs to stdout (blocks while the reader does not read): watched, but a stall
    /// here is backpressure, warned about and waited for, never a reason to exit.
    Writing = 4,
}

impl Phase {
    fn from_u8(v: u8) -> Phase {
        match v {
            1 => Phase::Records,
            2 => Phase::Delays,
            3 => Phase::Reload,
            4 => Phase::Writing,
            _ => Phase::Idle,
        }
    }

    fn doing(self) -> &'static str {
        match self {
            Phase::Idle => "waiting",
            Phase::Records => "stepping records",
            Phase::Delays => "firing delays while the input was silent",
            Phase::Reload => "reloading the spec (SIGHUP)",
            Phase::Writing => "writing outputs to stdout (its reader is not reading)",
        }
    }
}

/// One processor's marks (each `--threads` worker has its own, so no two threads write one;
/// aligned to 128 bytes, so no two lanes share a cache line or an adjacent-line prefetch pair).
#[derive(Debug)]
#[repr(align(128))]
pub struct Lane {
    /// Bumped at every record: any change is progress.
    progress: AtomicU64,
    /// The line of the record last begun.
    line: AtomicU64,
    /// Its instance's slot, [`usize::MAX`] before the instance is known.
    slot: AtomicUsize,
    /// Instance names by slot (with `--instance-by`; written once per new instance).
    names: Mutex<HashMap<usize, String>>,
}

impl Default for Lane {
    fn default() -> Self {
        Lane {
            progress: AtomicU64::new(0),
            line: AtomicU64::new(0),
            slot: AtomicUsize::new(usize::MAX),
            names: Mutex::new(HashMap::new()),
        }
    }
}

impl Lane {
    /// A record at `line` begins (its instance is not known yet).
    #[inline]
    pub fn begin(&self, line: u64) {
        // One writer: a load and a store, not a locked read-modify-write.
        self.progress
            .store(self.progress.load(Relaxed).wrapping_add(1), Relaxed);
        self.line.store(line, Relaxed);
        self.slot.store(usize::MAX, Relaxed);
    }

    /// The record's instance is the one in `slot`.
    #[inline]
    pub fn instance(&self, slot: usize) {
        self.slot.store(slot, Relaxed);
    }

    /// The instance in `slot` is called `name` (`robot=a`).
    pub fn name(&self, slot: usize, name: String) {
        if let Ok(mut n) = self.names.lock() {
            n.insert(slot, name);
        }
    }

    /// The instance in `slot` is gone.
    pub fn forget(&self, slot: usize) {
        if let Ok(mut n) = self.names.lock() {
            n.remove(&slot);
        }
    }

    /// "line 42 (instance robot=a)", or "no record yet".
    fn describe(&self) -> String {
        let line = self.line.load(Relaxed);
        if line == 0 {
            return "no record yet".to_string();
        }
        let slot = self.slot.load(Relaxed);
        // `try_lock`: the watched thread may be the one holding it (then the name is left out).
        let name = self
            .names
            .try_lock()
            .ok()
            .and_then(|n| n.get(&slot).cloned());
        match name {
            Some(n) => format!("line {line} (instance {n})"),
            None => format!("line {line}"),
        }
    }
}

/// The marks of one step loop: its phase, and a [`Lane`] per processor.
#[derive(Debug, Default)]
pub struct Watch {
    phase: AtomicU8,
    /// Bumped at every phase change.
    phase_gen: AtomicU64,
    lanes: Mutex<Vec<Arc<Lane>>>,
}

impl Watch {
    /// A new lane for a processor.
    pub fn lane(&self) -> Arc<Lane> {
        let lane = Arc::new(Lane::default());
        if let Ok(mut l) = self.lanes.lock() {
            l.push(lane.clone());
        }
        lane
    }

    /// The loop is now doing `phase` (once per read, not per record).
    #[inline]
    pub fn set(&self, phase: Phase) {
        self.phase_gen
            .store(self.phase_gen.load(Relaxed).wrapping_add(1), Relaxed);
        self.phase.store(phase as u8, Relaxed);
    }

    /// Enter `phase` until the guard is dropped (then [`Phase::Idle`]).
    pub fn enter(&self, phase: Phase) -> Busy<'_> {
        self.set(phase);
        Busy(self)
    }

    /// The phase and a signature that changes with any progress.
    fn sample(&self) -> (Phase, u64) {
        let phase = Phase::from_u8(self.phase.load(Relaxed));
        let mut sig = self.phase_gen.load(Relaxed);
        if let Ok(lanes) = self.lanes.try_lock() {
            for l in lanes.iter() {
                sig = sig.wrapping_mul(31).wrapping_add(l.progress.load(Relaxed));
            }
        }
        (phase, sig)
    }

    fn describe(&self) -> String {
        let lanes: Vec<String> = match self.lanes.try_lock() {
            Ok(l) => l.iter().map(|l| l.describe()).collect(),
            Err(_) => Vec::new(),
        };
        match lanes.len() {
            0 => String::new(),
            1 => format!("; last record: {}", lanes.join("")),
            _ => format!(
                "; last record per thread: {}",
                lanes
                    .iter()
                    .enumerate()
                    .map(|(i, d)| format!("thread {}: {d}", i + 1))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
}

/// A phase entered with [`Watch::enter`]; dropping it returns to [`Phase::Idle`].
pub struct Busy<'a>(&'a Watch);

impl Drop for Busy<'_> {
    fn drop(&mut self) {
        self.0.set(Phase::Idle);
    }
}

/// How often the watching thread samples the marks: an eighth of the bound, between 10 ms
/// and 1 s (a stall is noticed between `bound` and `bound` + one tick after it began).
pub fn tick(bound: Duration) -> Duration {
    (bound / 8).clamp(Duration::from_millis(10), Duration::from_secs(1))
}

/// Start the watching thread: when the loop stays in one busy phase without progress for
/// `bound`, log an `E!` line and exit the process with [`EXIT_CODE`]; in [`Phase::Writing`], a
/// `W!` line instead (once per stall) and go on waiting. `None` (`--step-timeout 0`): no thread.
pub fn spawn(watch: Arc<Watch>, bound: Option<Duration>) -> std::io::Result<()> {
    let Some(bound) = bound.filter(|b| !b.is_zero()) else {
        return Ok(());
    };
    std::thread::Builder::new()
        .name("step-watchdog".into())
        .spawn(move || watch_loop(&watch, bound))
        .map(drop)
}

fn watch_loop(watch: &Watch, bound: Duration) {
    let tick = tick(bound);
    let mut last = watch.sample();
    let mut since = Instant::now();
    let mut warned = false;
    loop {
        std::thread::sleep(tick);
        let now = watch.sample();
        if now.0 == Phase::Idle || now != last {
            if warned {
                log_info!(
                    "stdout: our reader read again after {:.1} s; nothing was lost",
                    since.elapsed().as_secs_f64()
                );
            }
            warned = false;
            last = now;
            since = Instant::now();
            continue;
        }
        let stalled = since.elapsed();
        if stalled >= bound && now.0 == Phase::Writing {
            if !warned {
                warned = true;
                log_warn!(
                    "stdout: our reader has not read for {:.1} s (--step-timeout {}){}; \
                         waiting: a blocked write is backpressure, not a hung step (Telegraf \
                         may be parsing a large metric: the echo of a record with tens of \
                         thousands of fields takes it seconds; the book, \"With Telegraf\", \"A step that hangs\")",
                    stalled.as_secs_f64(),
                    humantime::format_duration(bound),
                    watch.describe()
                );
            }
            continue;
        }
        if stalled >= bound {
            log_error!(
                "step watchdog: no progress for {:.1} s (--step-timeout {}) while {}{}; \
                     exiting with code {EXIT_CODE} so that Telegraf restarts the monitor \
                     (with --state it continues from the last save)",
                stalled.as_secs_f64(),
                humantime::format_duration(bound),
                now.0.doing(),
                watch.describe()
            );
            // The stuck thread may hold stdout's lock: exit without waiting for it (the
            // standard library's exit only tries the lock).
            std::process::exit(EXIT_CODE);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn progress_and_phase_changes_change_the_sample() {
        let w = Watch::default();
        let lane = w.lane();
        let a = w.sample();
        assert_eq!(a.0, Phase::Idle);
        w.set(Phase::Records);
        let b = w.sample();
        assert_eq!(b.0, Phase::Records);
        assert_ne!(a, b);
        assert_eq!(w.sample(), b, "nothing happened: the same sample");
        lane.begin(7);
        let c = w.sample();
        assert_ne!(b, c);
        lane.instance(3);
        lane.name(3, "robot=a".into());
        assert_eq!(w.describe(), "; last record: line 7 (instance robot=a)");
        lane.forget(3);
        assert_eq!(w.describe(), "; last record: line 7");
    }

    #[test]
    fn the_tick_is_an_eighth_of_the_bound_within_limits() {
        assert_eq!(tick(Duration::from_secs(10)), Duration::from_millis(1000));
        assert_eq!(tick(Duration::from_secs(2)), Duration::from_millis(250));
        assert_eq!(tick(Duration::from_millis(1)), Duration::from_millis(10));
    }
}
