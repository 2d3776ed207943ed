//! The Telegraf binding: line-protocol metrics in, monitor steps, verdict metrics out.
//!
//! Owns: how a spec's inputs bind to metrics ([`binding`]: `@TelegrafIn`, indexed `_*` fields,
//! value conversion), how outputs become metrics ([`encode`]: `@TelegrafOut`, `@TelegrafField`,
//! the default grouped metric), and the step loop with pass-through, late records, exact
//! duplicates ([`dedup`]) and counters ([`processor`]), `--state` persistence ([`state`]; a shared
//! NATS bucket and partition lease: [`state_nats`]), SIGHUP spec reloads ([`reload`]) and warnings
//! about inputs no metric feeds ([`wiring`]). Transports (stdin/stdout, UDP, and the partition-lease
//! loop of a fleet on NATS: [`crate::transport`]) feed bytes to a [`processor::Processor`].

pub mod binding;
pub mod clock;
pub mod dedup;
pub mod encode;
pub mod instances;
pub mod processor;
pub mod reload;
pub mod state;
pub mod state_nats;
pub mod wiring;
