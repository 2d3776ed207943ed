//! Where new spec versions come from while a run goes on, and what each process says about
//! them: the fleet's spec channel (a NATS key-value bucket of signed rollouts, [`nats`]), the
//! watched spec file of one process ([`watch`]), and the bundle a version travels as
//! ([`bundle`]).
//!
//! Owns the rollout record every channel carries ([`Rollout`]: which version, from which event
//! time, for which instances), the outcome a process reports for each ([`Outcome`]), and the
//! [`Feed`] the step loop polls. Checking a version and switching instances to it is the
//! processor's (`processor::versions`).

pub mod bundle;

use crate::processor::versions::Selector;
use serde::{Deserialize, Serialize};

/// One publish: version `id` (a [`bundle::Bundle::id`]) in force from event time `from` for the
/// instances `selector` picks. A channel's rollouts are append-only, in publish order
/// (`revision` increasing): a rollback is a rollout of the earlier version.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Rollout {
    /// The channel's sequence number of this rollout (increasing).
    pub revision: u64,
    /// The version: its bundle's short id.
    pub id: String,
    /// The bundle's full SHA-256 ([`bundle::Bundle::digest`]); a bundle that does not hash to
    /// it is refused.
    pub digest: String,
    /// The operator's label (`--label`), shown beside the id.
    #[serde(default)]
    pub label: String,
    /// Event time (ns since the Unix epoch) from which it is in force: every instance it picks
    /// switches at its first step at or after it.
    pub from: i64,
    /// The instances it is for (empty: every one).
    #[serde(default)]
    pub selector: Selector,
    /// When it was published (ns since the Unix epoch, the publisher's wall clock).
    #[serde(default)]
    pub published: i64,
}

/// What one process made of one version.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Outcome {
    /// The rollout's revision (0 for a local reload: SIGHUP or a watched file).
    pub revision: u64,
    pub id: String,
    pub label: String,
    pub accepted: bool,
    /// Why it was refused (the first lines of the diagnostic), or empty.
    #[serde(default)]
    pub reason: String,
    /// Outputs whose streams start afresh in the instances that switch.
    #[serde(default)]
    pub reset_outputs: Vec<String>,
}
