//! Transports: where the bytes come from and where the outputs go, each a
//! [`crate::step_loop::Source`] and a [`crate::step_loop::Sink`] plugged into the one step loop.
//!
//! Owns: stdin/stdout for Telegraf's `processors.execd` ([`stdio`]; also the fleet's, whose
//! shared state lives in [`crate::state`]) and the TeSSLa Telegraf Connector's UDP wiring
//! ([`udp`]), and which one a run uses ([`Transport`], [`run`]). A new transport is a file here,
//! a variant and an arm below, and its option in `cli/args.rs` and `cli/config.rs`.

pub mod stdio;
pub mod udp;

use crate::processor::Processor;
use crate::step_loop::{Ending, Setup};

/// Where records come from and outputs go.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Transport {
    /// stdin/stdout (instances spread over the run's threads).
    Stdio,
    /// The connector's UDP wiring: datagrams in on `listen`, out to `send`, at most
    /// `max_datagram` bytes each.
    Udp {
        listen: String,
        send: String,
        max_datagram: usize,
    },
}

/// Run `proc` on `transport` until its input ends, a signal, or a closed output.
pub async fn run(
    transport: &Transport,
    proc: &mut Processor,
    setup: Setup<'_>,
) -> std::io::Result<Ending> {
    match transport {
        Transport::Stdio => stdio::run(proc, setup).await,
        Transport::Udp {
            listen,
            send,
            max_datagram,
        } => udp::run(proc, listen, send, *max_datagram, setup).await,
    }
}
