//! The format of saved state, the same in every backend: a header (magic, format version, the
//! fingerprint of the spec and options it was written for) checked in one place
//! ([`check_header`]), and one instance's entry as a key-value backend stores it
//! ([`encode_entry`], [`check_entry`]); the warning every backend gives for values that cannot
//! be saved ([`warn_unsaved`]).

use crate::log::{self, Level};
use crate::processor::instances::Key;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use tessla_engine::Program;
use tessla_engine::runtime::snapshot::{self, Snapshot};

pub const MAGIC: &str = "tessla-telegraf-state";
/// Format version; bumped on any incompatible change of the layout below or of node keys
/// (2: structural node keys, see `tessla_engine::runtime::snapshot`).
pub const VERSION: u32 = 2;

/// What every saved state starts with.
#[derive(Deserialize)]
struct Header {
    magic: String,
    version: u32,
    fingerprint: String,
}

pub(crate) fn unix_now() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// One instance's saved state, as a key-value backend stores it: the file's header, its key and
/// its monitor.
#[derive(Serialize, Deserialize)]
struct Entry {
    magic: String,
    version: u32,
    fingerprint: String,
    written: u64,
    key: Key,
    monitor: Snapshot,
}

/// The bytes of instance `key`'s entry (JSON, as the file); the second value counts stream
/// values that are functions and cannot be saved.
pub fn encode_entry(
    program: &Program,
    fingerprint: &str,
    key: &Key,
    monitor: &tessla_engine::Monitor,
) -> (Vec<u8>, usize) {
    let keys = snapshot::node_keys(program);
    let monitor = snapshot::snapshot_with_keys(monitor, &keys);
    let unsaved = monitor.unsaved;
    let entry = Entry {
        magic: MAGIC.into(),
        version: VERSION,
        fingerprint: fingerprint.to_string(),
        written: unix_now(),
        key: key.clone(),
        monitor,
    };
    // Serialising owned plain data to memory cannot fail; an empty entry would be rejected.
    (serde_json::to_vec(&entry).unwrap_or_default(), unsaved)
}

/// The warning of a save, in every backend, when `unsaved` stream values (functions) could not
/// be saved; nothing when there are none.
pub fn warn_unsaved(unsaved: usize) {
    if unsaved > 0 {
        log::log(
            Level::Warn,
            &format!(
                "state: {unsaved} stream values are functions and cannot be saved; those streams restart empty"
            ),
        );
    }
}

/// An instance key for a message: its tag values in `--instance-by` order, an absent tag as
/// `(absent)`.
fn show_key(key: &Key) -> String {
    let values: Vec<&str> = key
        .iter()
        .map(|v| v.as_deref().unwrap_or("(absent)"))
        .collect();
    format!("[{}]", values.join(", "))
}

/// Check the header of saved state (`what`: "file" or "entry", for the messages): its magic,
/// format version and fingerprint (`fingerprint`: this run's). `Err` says why it is not usable.
pub fn check_header(bytes: &[u8], what: &str, fingerprint: &str) -> Result<(), String> {
    let header: Header = serde_json::from_slice(bytes)
        .map_err(|e| format!("not a state {what} (corrupt or truncated: {e})"))?;
    if header.magic != MAGIC {
        return Err(format!(
            "not a state {what} (magic `{}`, expected `{MAGIC}`)",
            header.magic
        ));
    }
    if header.version != VERSION {
        return Err(format!(
            "written in state format version {}, this build reads version {VERSION}",
            header.version
        ));
    }
    if header.fingerprint != fingerprint {
        return Err(format!(
            "written for another spec or other options (fingerprint {}, this run {fingerprint}; the spec, --set, --base-time and --instance-by must match)",
            header.fingerprint
        ));
    }
    Ok(())
}

/// Check an entry's bytes (magic, version, fingerprint, that it is `key`'s) and restore its
/// monitor; `Err` says why it is not usable.
pub fn check_entry(
    bytes: &[u8],
    program: &Arc<Program>,
    fingerprint: &str,
    key: &Key,
) -> Result<tessla_engine::Monitor, String> {
    check_header(bytes, "entry", fingerprint)?;
    let entry: Entry =
        serde_json::from_slice(bytes).map_err(|e| format!("corrupt state entry: {e}"))?;
    if &entry.key != key {
        return Err(format!(
            "the entry holds instance {}, not {}",
            show_key(&entry.key),
            show_key(key)
        ));
    }
    let keys = snapshot::node_keys(program);
    Ok(snapshot::restore_with_keys(
        Arc::clone(program),
        &entry.monitor,
        &keys,
    ))
}
