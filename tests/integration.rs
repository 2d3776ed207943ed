//! The root crate's integration tests, in one test binary (one link, one copy of the support
//! code): `cargo test --test integration` runs them all, `cargo test --test integration execd::`
//! one group, `cargo test --test integration execd::hostile_input` one former test file.
//!
//! - [`cli`]: the engine and the command line, each run on files or in-process (no server);
//! - [`execd`]: the binary as Telegraf's `processors.execd` child (stdin/stdout, signals,
//!   `--state`, instances, the watchdog);
//! - [`servers`]: against real servers (Telegraf, Mosquitto, InfluxDB, NATS), each started on
//!   free loopback ports; a missing one skips (fails under `REQUIRE_SERVERS=1`).
//!
//! The tests of one binary run as threads of one process: none may change the process's
//! environment or folder (give a child its own with `Command::env` / `current_dir`), and a
//! server's port comes from [`support::servers::free_port`], never a fixed one.

mod cli;
mod execd;
mod servers;
mod support;
