//! Transports: moving bytes between the outside world and a [`crate::processor::Processor`].
//!
//! Owns: stdin/stdout for Telegraf's `processors.execd` ([`stdio`]), the same with a shared NATS
//! state backend and partition lease for a fleet ([`nats_fleet`]) and the TeSSLa Telegraf
//! Connector's UDP wiring ([`udp`]), including signals, end of input and closed outputs.
//! What their step loops share lives here: the signals (`Signals`, with the order every loop
//! selects in), the periodic task with its timer (`Ticker`), the wall-clock deadline and the
//! silent-input step (`advance_silent`).

use crate::processor::Processor;
use crate::processor::clock::Wall;

pub mod nats_fleet;
pub mod stdio;
pub mod udp;

/// A periodic task: how often, and what.
pub type Periodic<'a> = (std::time::Duration, &'a mut dyn FnMut(&Processor));

/// On SIGHUP (the spec reload); may append outputs to the buffer.
pub type OnHangup<'a> = &'a mut dyn FnMut(&mut Processor, &mut Vec<u8>);

/// What the caller wants done between two reads.
pub struct Hooks<'a> {
    /// On SIGHUP (see [`OnHangup`]).
    pub on_hangup: OnHangup<'a>,
    /// Every this long (`--state-interval`: save the state).
    pub periodic: Option<Periodic<'a>>,
    /// Where the loop marks what it is doing, for the step watchdog (`--step-timeout`).
    pub watch: std::sync::Arc<crate::watchdog::Watch>,
}

impl<'a> Hooks<'a> {
    /// The SIGHUP hook, the periodic task with its timer (the timer starts now), and the
    /// watchdog's marks.
    pub(crate) fn split(
        self,
    ) -> (
        OnHangup<'a>,
        Ticker<'a>,
        std::sync::Arc<crate::watchdog::Watch>,
    ) {
        let ticker = Ticker(self.periodic.map(|periodic| {
            let d = periodic.0.max(std::time::Duration::from_millis(1));
            let mut i = tokio::time::interval_at(tokio::time::Instant::now() + d, d);
            i.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            (i, periodic)
        }));
        (self.on_hangup, ticker, self.watch)
    }
}

/// [`Hooks::periodic`] with its timer: the periodic branch of every step loop,
/// `_ = ticker.tick() => { ticker.run(proc); continue; }`. Never fires without a task. The
/// first tick is one period after [`Hooks::split`]; ticks missed while busy are not made up.
pub(crate) struct Ticker<'a>(Option<(tokio::time::Interval, Periodic<'a>)>);

impl Ticker<'_> {
    /// Wait for the next tick (forever without a periodic task).
    pub(crate) async fn tick(&mut self) {
        match &mut self.0 {
            Some((timer, _)) => {
                timer.tick().await;
            }
            None => std::future::pending().await,
        }
    }

    /// Run the periodic task (on a tick).
    pub(crate) fn run(&mut self, proc: &Processor) {
        if let Some((_, (_, task))) = &mut self.0 {
            task(proc);
        }
    }
}

/// Sleep until `deadline` (forever without one): a processor's next `delay` by the wall clock.
pub(crate) async fn sleep_until(deadline: Option<std::time::Instant>) {
    match deadline {
        Some(d) => tokio::time::sleep_until(tokio::time::Instant::from_std(d)).await,
        None => std::future::pending().await,
    }
}

/// The signals every step loop answers: SIGTERM and SIGINT end the run, SIGHUP reloads the spec.
///
/// Each loop selects on them first (`biased`: SIGTERM, SIGINT, SIGHUP), then its periodic
/// ticks, then its input, then the wall-clock deadline ([`sleep_until`], [`advance_silent`]).
/// Signals first so input never starves them; the deadline last so a delay falls due by the
/// wall clock only when no input is waiting (input not read yet is not silence).
pub(crate) struct Signals {
    pub term: tokio::signal::unix::Signal,
    pub int: tokio::signal::unix::Signal,
    pub hup: tokio::signal::unix::Signal,
}

impl Signals {
    /// Install the handlers (before the first read, so no signal is missed).
    pub(crate) fn new() -> std::io::Result<Self> {
        use tokio::signal::unix::{SignalKind, signal};
        Ok(Self {
            term: signal(SignalKind::terminate())?,
            int: signal(SignalKind::interrupt())?,
            hup: signal(SignalKind::hangup())?,
        })
    }
}

/// The silent input: the deadline of [`sleep_until`] passed with no input waiting, so `proc`
/// moves on to `wall` (read once per wake-up, the same for every processor of the loop) and the
/// delays that fell due are evaluated, outputs appended to `out`.
pub(crate) fn advance_silent(proc: &mut Processor, wall: Wall, out: &mut Vec<u8>) {
    proc.set_wall(wall);
    proc.advance_wall(wall.at, out);
}

/// How a transport's run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ending {
    /// End of input.
    Eof,
    /// SIGTERM or SIGINT.
    Signal,
    /// The reader of our output went away.
    OutputClosed,
}
