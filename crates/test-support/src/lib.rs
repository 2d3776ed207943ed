//! The workspace's test helpers that more than one crate or tool uses, as a dev-dependency
//! (never published): real servers started in a temporary folder ([`servers`]), a NATS cluster
//! ([`nats_cluster`]) and a stand-in fleet talking to it ([`nats_standin`]), the real Telegraf
//! with our binary as its processor ([`real_telegraf`]), TeSSLa's conformance cases
//! ([`tessla_suite`]), the benchmarks' records ([`workload`]); the workspace's folders they
//! need ([`paths`]).
//!
//! The root crate's tests (tests/support/ re-exports these beside its own helpers),
//! crates/tessla-trace's conformance test, the criterion benches of the root crate and of
//! crates/lineproto, and the benchmark tools bench/fleet_nats.rs and bench/telegraf_delay.rs
//! use it.

pub mod nats_cluster;
pub mod nats_standin;
pub mod paths;
pub mod real_telegraf;
pub mod servers;
pub mod tessla_suite;
pub mod workload;
