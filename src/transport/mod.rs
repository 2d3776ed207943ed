//! Transports: moving bytes between the outside world and a [`crate::telegraf::processor::Processor`].
//!
//! Owns: stdin/stdout for Telegraf's `processors.execd` ([`stdio`]) and the TeSSLa Telegraf
//! Connector's UDP wiring ([`udp`]), including signals, end of input and closed outputs.

use crate::telegraf::processor::Processor;

pub mod stdio;
pub mod udp;

/// Called on SIGHUP between two reads (the spec reload); may append outputs to the buffer.
pub type OnHangup<'a> = &'a mut dyn FnMut(&mut Processor, &mut Vec<u8>);

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
