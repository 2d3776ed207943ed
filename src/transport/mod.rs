//! Transports: where the bytes come from and where the outputs go, each a
//! [`crate::step_loop::Source`] and a [`crate::step_loop::Sink`] plugged into the one step loop.
//!
//! Owns: stdin/stdout for Telegraf's `processors.execd` ([`stdio`]; also the fleet's, whose
//! shared state lives in [`crate::state`]) and the TeSSLa Telegraf Connector's UDP wiring
//! ([`udp`]). A new transport is one file here.

pub mod stdio;
pub mod udp;
