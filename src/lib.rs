//! tessla-telegraf: a TeSSLa runtime-verification engine that runs as a Telegraf
//! `processors.execd` plugin.
//!
//! Data flows one way: bytes in (line protocol via the `lineproto` crate, or TeSSLa traces via
//! [`trace`]) -> input events bound to streams ([`telegraf`]) -> the evaluation engine (crate
//! `tessla-engine`, running a program checked from a spec parsed by `tessla-syntax`) -> output
//! events -> bytes out. [`transport`] moves the bytes (stdin/stdout, UDP); [`cli`] wires the
//! subcommands. `replay`, `report` and `simulate` are built with the `tools` feature (default on).

// First, so that its macros (`log_error!` .. `log_debug!`) are in scope in every module below.
#[macro_use]
pub mod log;

pub mod bundled;
pub mod cli;
pub mod fleet;
pub mod natives;
pub mod nats;
pub mod processor;
#[cfg(feature = "tools")]
pub mod replay;
#[cfg(feature = "tools")]
pub mod report;
#[cfg(feature = "tools")]
pub mod simulate;
pub mod spec_feed;
pub mod state;
pub mod step_loop;
pub mod telegraf;
/// TeSSLa's trace formats (crate `tessla-trace`), re-exported where the CLI and tests use them.
pub use tessla_trace as trace;
pub mod transport;
pub mod watchdog;
