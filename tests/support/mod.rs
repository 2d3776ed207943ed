//! What the integration tests share (tests/integration.rs): the binary run as a child
//! ([`child`], [`live_child`]), the recorded run ([`recorded`]), the fleet example's run ([`fleet_example`]), two partitions of a NATS fleet ([`fleet_partitions`]), real servers ([`servers`],
//! [`nats_cluster`], [`real_telegraf`]) and the clients and stand-ins that talk to them.
//!
//! The helpers other crates and tools share too (servers, the NATS cluster and stand-in,
//! TeSSLa's suite) live in the dev-only crate `test-support` (crates/test-support) and are
//! re-exported here under their old names; [`real_telegraf`] adds the binary under test to
//! test-support's.

pub mod child;
// Without the `tools` feature the tests of `replay`, `simulate` and most of the real Telegraf's
// are left out (tests/cli/mod.rs, tests/servers/mod.rs), and with them the only users of some
// helpers of these three.
#[cfg_attr(not(feature = "tools"), allow(dead_code))]
pub mod dashboards;
pub mod fleet_example;
pub mod fleet_partitions;
pub mod kv;
pub mod live_child;
#[cfg_attr(not(feature = "tools"), allow(dead_code))]
pub mod mqtt_client;
#[cfg_attr(not(feature = "tools"), allow(dead_code))]
pub mod real_telegraf;
pub mod recorded;
pub mod stdlib_cases;
pub mod udp_ends;
pub use test_support::{nats_cluster, nats_standin, servers, tessla_suite};

/// The binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_tessla-telegraf");
