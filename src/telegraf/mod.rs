//! The Telegraf binding: line-protocol metrics in, monitor steps, verdict metrics out.
//!
//! Owns: how a spec's inputs bind to metrics ([`binding`]: `@TelegrafIn`, indexed `_*` fields,
//! value conversion), how outputs become metrics ([`encode`]: `@TelegrafOut`, `@TelegrafField`,
//! the default grouped metric), and the step loop with pass-through, late records and counters
//! ([`processor`]), `--state` persistence ([`state`]; a shared NATS bucket: [`state_nats`]), the
//! partition-lease step loop of a fleet on NATS ([`fleet`]) and SIGHUP spec reloads ([`reload`]).
//! Transports (stdin/stdout, UDP) feed bytes to a [`processor::Processor`].

pub mod binding;
pub mod encode;
pub mod fleet;
pub mod instances;
pub mod processor;
pub mod reload;
pub mod state;
pub mod state_nats;
