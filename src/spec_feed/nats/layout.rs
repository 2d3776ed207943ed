//! The spec channel bucket's key layout (the list in [`super`]'s doc): what a process writes
//! to its status key ([`Status`]) and under which name, and the names of rollouts, decisions and
//! bundles with their revisions read back.

use crate::nats::kv_keys::kv_key_part_of;
use crate::spec_feed::Outcome;
use serde::{Deserialize, Serialize};

/// What a process writes to its status key: its outcomes so far, for `spec status`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    pub host: String,
    /// The partition (`--state`'s lease name), or empty.
    #[serde(default)]
    pub partition: String,
    pub pid: u32,
    /// When it was written (ns since the Unix epoch, the process's wall clock).
    pub time: i64,
    pub outcomes: Vec<Outcome>,
    /// Written by the process as it stopped (its key is no longer renewed): a publisher does
    /// not wait for its vote.
    #[serde(default)]
    pub stopped: bool,
}

/// The status key of a process: `status.<host>.<partition>.pid<N>`, or `status.<host>.pid<N>`
/// without a partition (host and partition written as the state bucket writes a tag value:
/// injective, only characters NATS allows). The pid keeps apart the processes of one host that
/// run one partition (its primary and its standbys); a restarted process writes a new key and
/// its old one, no longer renewed, reads as stopped or silent (`spec status`), and is no voter.
/// Keys written by earlier versions (`status.<host>.<partition>`) are still read: the status
/// names its own host, partition and pid.
pub fn status_key(host: &str, partition: &str, pid: u32) -> String {
    if partition.is_empty() {
        format!("status.{}.pid{pid}", kv_key_part_of(host))
    } else {
        format!(
            "status.{}.{}.pid{pid}",
            kv_key_part_of(host),
            kv_key_part_of(partition)
        )
    }
}

pub(super) fn rollout_key(revision: u64) -> String {
    format!("rollout.{revision}")
}

pub(super) fn decision_key(revision: u64) -> String {
    format!("decision.{revision}")
}

pub(super) fn bundle_key(id: &str) -> String {
    format!("bundle.{id}")
}

/// The revision of a `rollout.<revision>` key.
pub(super) fn revision_of(key: &str) -> Option<u64> {
    numbered(key, "rollout.")
}

/// The revision of a `decision.<revision>` key.
pub(super) fn decided_revision_of(key: &str) -> Option<u64> {
    numbered(key, "decision.")
}

pub(super) fn numbered(key: &str, prefix: &str) -> Option<u64> {
    let digits = key.strip_prefix(prefix)?;
    // Written as `rollout_key` writes it: no sign, no leading zero.
    digits
        .parse()
        .ok()
        .filter(|r: &u64| *r > 0 && r.to_string() == digits)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_name_revisions_and_processes() {
        assert_eq!(revision_of("rollout.12"), Some(12));
        assert_eq!(revision_of("rollout.0"), None);
        assert_eq!(revision_of("rollout.x"), None);
        assert_eq!(revision_of("rollout.012"), None);
        assert_eq!(revision_of("rollout.+1"), None);
        assert_eq!(revision_of("bundle.12"), None);
        assert_eq!(status_key("h.1", "p0", 7), "status.vh_2e1.vp0.pid7");
        assert_eq!(status_key("h", "", 7), "status.vh.pid7");
        // A primary and its standby on one host: two keys.
        assert_ne!(status_key("h", "p0", 7), status_key("h", "p0", 8));
    }
}
