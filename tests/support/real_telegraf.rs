//! The real Telegraf as this crate's tests run it: `test_support::real_telegraf` (the pinned
//! builds, the rewritten shipped confs, what turns Telegraf's deliveries back into records)
//! with the binary under test ([`super::BIN`]) as the `processors.execd` child and the offline
//! run.

pub use test_support::real_telegraf::*;

/// An offline `run` of the binary under test: see [`test_support::real_telegraf::offline`].
pub fn offline(args: &[String], input: &str) -> String {
    test_support::real_telegraf::offline(super::BIN, args, input)
}
