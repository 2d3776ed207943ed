//! What the integration tests share (tests/integration.rs): the binary run as a child
//! ([`child`], [`live_child`]), the recorded run ([`recorded`]), real servers ([`servers`],
//! [`nats_cluster`], [`real_telegraf`]) and the clients and stand-ins that talk to them.
//!
//! `bench/fleet_nats.rs` and `bench/telegraf_delay.rs` include some of these files by path, and
//! crates/tessla-trace's conformance test includes `tessla_suite.rs`: a file here names its
//! siblings as `super::...`, which is the includer's root there.

pub mod child;
// Without the `tools` feature the tests of `replay`, `simulate` and most of the real Telegraf's
// are left out (tests/cli/mod.rs, tests/servers/mod.rs), and with them the only users of some
// helpers of these four.
#[cfg_attr(not(feature = "tools"), allow(dead_code))]
pub mod dashboards;
pub mod live_child;
#[cfg_attr(not(feature = "tools"), allow(dead_code))]
pub mod mqtt_client;
pub mod nats_cluster;
pub mod nats_standin;
#[cfg_attr(not(feature = "tools"), allow(dead_code))]
pub mod real_telegraf;
pub mod recorded;
#[cfg_attr(not(feature = "tools"), allow(dead_code))]
pub mod servers;
pub mod stdlib_cases;
pub mod tessla_suite;
pub mod udp_ends;

/// The binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_tessla-telegraf");
