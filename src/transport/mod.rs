//! Transports: moving bytes between the outside world and a [`crate::telegraf::processor::Processor`].
//!
//! Owns: stdin/stdout for Telegraf's `processors.execd` ([`stdio`]), the same with a shared NATS
//! state backend and partition lease for a fleet ([`nats_fleet`]) and the TeSSLa Telegraf
//! Connector's UDP wiring ([`udp`]), including signals, end of input and closed outputs.

use crate::telegraf::processor::Processor;

pub mod nats_fleet;
pub mod stdio;
pub mod udp;

/// A periodic task: how often, and what.
pub type Periodic<'a> = (std::time::Duration, &'a mut dyn FnMut(&Processor));

/// What the caller wants done between two reads.
pub struct Hooks<'a> {
    /// On SIGHUP (the spec reload); may append outputs to the buffer.
    pub on_hangup: &'a mut dyn FnMut(&mut Processor, &mut Vec<u8>),
    /// Every this long (`--state-interval`: save the state).
    pub periodic: Option<Periodic<'a>>,
}

/// A timer for [`Hooks::periodic`]: never fires without one. The first tick is one period
/// from now; ticks missed while busy are not made up.
pub(crate) fn timer(periodic: &Option<Periodic<'_>>) -> Option<tokio::time::Interval> {
    periodic.as_ref().map(|(d, _)| {
        let d = (*d).max(std::time::Duration::from_millis(1));
        let mut i = tokio::time::interval_at(tokio::time::Instant::now() + d, d);
        i.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        i
    })
}

/// Wait for the next tick of `timer` (forever without one).
pub(crate) async fn tick(timer: &mut Option<tokio::time::Interval>) {
    match timer {
        Some(t) => {
            t.tick().await;
        }
        None => std::future::pending().await,
    }
}

/// Sleep until `deadline` (forever without one): a processor's next `delay` by the wall clock.
pub(crate) async fn sleep_until(deadline: Option<std::time::Instant>) {
    match deadline {
        Some(d) => tokio::time::sleep_until(tokio::time::Instant::from_std(d)).await,
        None => std::future::pending().await,
    }
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
