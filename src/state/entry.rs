//! The format of saved state, the same in every backend: a header (magic, format version, the
//! fingerprint of the options it was written for) checked in one place ([`check_header`]), what
//! is recorded of the program each instance ran ([`SavedProgram`], computed once per distinct
//! program by [`Programs`]), and one instance's entry as a key-value backend stores it
//! ([`encode_entry`], [`decode_entry`]); the warning every backend gives for values that cannot
//! be saved ([`warn_unsaved`]).

use crate::processor::instance_table::Key;
use crate::processor::{Continuity, carry};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use tessla_engine::snapshot::{self, Snapshot};
use tessla_engine::{Monitor, Program};

pub const MAGIC: &str = "tessla-telegraf-state";
/// Format version; bumped on any incompatible change of the layout below or of node keys
/// (2: structural node keys, see `tessla_engine::snapshot`; 3: the fingerprint covers
/// the options only, and the state records the keys of the program each instance ran, so an
/// edited spec keeps every stream whose key is unchanged).
pub const VERSION: u32 = 3;

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

/// What saved state records of the program an instance ran: enough to say, when it is restored
/// into another program, which streams start afresh.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SavedProgram {
    /// `snapshot::fingerprint` of the program, hex; informative (whether the program restoring
    /// the state is the same one), never a reason to refuse the state.
    pub fingerprint: String,
    /// The key of every evaluated stream, sorted ([`carry::stream_keys`]).
    pub keys: Vec<u64>,
}

impl SavedProgram {
    /// `program`'s record, from its node keys (`snapshot::node_keys`).
    pub fn of(program: &Program, node_keys: &[u64]) -> SavedProgram {
        SavedProgram {
            fingerprint: program_fingerprint(program),
            keys: carry::stream_keys(program, node_keys),
        }
    }
}

/// `snapshot::fingerprint(program)` as the state writes it (hex).
pub fn program_fingerprint(program: &Program) -> String {
    format!("{:016x}", snapshot::fingerprint(program))
}

/// One program of the monitors being saved.
pub struct Known {
    program: Arc<Program>,
    /// Its node keys, what a snapshot is keyed by.
    pub node_keys: Vec<u64>,
    pub saved: SavedProgram,
}

/// The distinct programs of the monitors being saved (instances may run different versions):
/// each program's keys are computed once, however many instances run it.
#[derive(Default)]
pub struct Programs {
    pub list: Vec<Known>,
}

impl Programs {
    /// The index in [`Programs::list`] of `program` (a monitor's own, `Monitor::program`),
    /// added when new. The programs are told apart by identity: a processor holds few.
    pub fn index(&mut self, program: &Arc<Program>) -> usize {
        if let Some(i) = self
            .list
            .iter()
            .position(|k| Arc::ptr_eq(&k.program, program))
        {
            return i;
        }
        let node_keys = snapshot::node_keys(program);
        self.list.push(Known {
            saved: SavedProgram::of(program, &node_keys),
            node_keys,
            program: Arc::clone(program),
        });
        self.list.len() - 1
    }

    /// The node keys of every program, by index (what encoding threads need).
    pub fn node_keys(&self) -> Vec<&[u64]> {
        self.list.iter().map(|k| k.node_keys.as_slice()).collect()
    }
}

/// One instance's saved state, as a key-value backend stores it: the file's header, the program
/// it ran, its key and its monitor.
#[derive(Serialize)]
struct EntryOut<'a> {
    magic: &'a str,
    version: u32,
    fingerprint: &'a str,
    written: u64,
    program: &'a SavedProgram,
    key: &'a Key,
    #[serde(skip_serializing_if = "Option::is_none")]
    spec_version: Option<&'a str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    horizon: Option<i64>,
    #[serde(skip_serializing_if = "<[_]>::is_empty")]
    recent: &'a [(i64, u64)],
    #[serde(skip_serializing_if = "<[_]>::is_empty")]
    unfit: &'a [(String, i64)],
    monitor: Snapshot,
}

/// An entry read back (its header checked by [`check_header`]).
#[derive(Deserialize)]
struct EntryIn {
    program: SavedProgram,
    key: Key,
    /// Absent in entries written before they were saved.
    #[serde(default)]
    spec_version: Option<String>,
    #[serde(default)]
    horizon: Option<i64>,
    #[serde(default)]
    recent: Vec<(i64, u64)>,
    #[serde(default)]
    unfit: Vec<(String, i64)>,
    monitor: Snapshot,
}

/// One instance's state as read back from any backend: the program it ran, its horizon (the
/// event time whose version it ran, `Processor::saved_instances`; `None`: not recorded) and its
/// monitor.
pub struct Saved {
    pub program: SavedProgram,
    pub continuity: Continuity,
    pub monitor: Snapshot,
}

/// The bytes of instance `key`'s entry (JSON, as the file), its monitor snapshotted with the
/// keys of its own program (looked up in `programs`) and its `horizon`; the second value counts
/// stream values that are functions and cannot be saved.
pub fn encode_entry(
    programs: &mut Programs,
    fingerprint: &str,
    key: &Key,
    monitor: &Monitor,
    c: &Continuity,
) -> (Vec<u8>, usize) {
    let i = programs.index(monitor.program());
    let Some(known) = programs.list.get(i) else {
        return (Vec::new(), 0);
    };
    let snap = snapshot::snapshot_with_keys(monitor, &known.node_keys);
    let unsaved = snap.unsaved;
    let entry = EntryOut {
        magic: MAGIC,
        version: VERSION,
        fingerprint,
        written: unix_now(),
        program: &known.saved,
        key,
        spec_version: c.version.as_deref(),
        horizon: c.horizon,
        recent: &c.recent,
        unfit: &c.unfit,
        monitor: snap,
    };
    // Serialising owned plain data to memory cannot fail; an empty entry would be rejected.
    (serde_json::to_vec(&entry).unwrap_or_default(), unsaved)
}

/// The warning of a save, in every backend, when `unsaved` stream values (functions) could not
/// be saved; nothing when there are none.
pub fn warn_unsaved(unsaved: usize) {
    if unsaved > 0 {
        log_warn!(
            "state: {unsaved} stream values are functions and cannot be saved; those streams restart empty"
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

/// Why saved state (a file, or an entry of a bucket) is not used; `what` is `file` or `entry`.
#[derive(Debug, thiserror::Error)]
pub enum StateError {
    #[error("not a state {what} (corrupt or truncated: {source})")]
    NotState {
        what: String,
        source: serde_json::Error,
    },
    #[error("not a state {what} (magic `{magic}`, expected `{MAGIC}`)")]
    Magic { what: String, magic: String },
    #[error("written in state format version {0}, this build reads version {VERSION}")]
    Version(u32),
    #[error(
        "written for other options (fingerprint {theirs}, this run {ours}; --set, --base-time and --instance-by must match)"
    )]
    Fingerprint { theirs: String, ours: String },
    #[error("corrupt state {what}: {source}")]
    Corrupt {
        what: String,
        source: serde_json::Error,
    },
    /// An entry stored under another instance's name (shown as `[v1, v2]`).
    #[error("the entry holds instance {held}, not {wanted}")]
    OtherInstance { held: String, wanted: String },
    /// A file's instance naming a program the file does not list.
    #[error("corrupt state file: an instance names program {program}, the file lists {listed}")]
    NoSuchProgram { program: usize, listed: usize },
}

/// Check the header of saved state (`what`: "file" or "entry", for the messages): its magic,
/// format version and fingerprint (`fingerprint`: this run's options, [`super::fingerprint`]).
/// `Err` says why it is not usable.
pub fn check_header(bytes: &[u8], what: &str, fingerprint: &str) -> Result<(), StateError> {
    let header: Header = serde_json::from_slice(bytes).map_err(|source| StateError::NotState {
        what: what.to_string(),
        source,
    })?;
    if header.magic != MAGIC {
        return Err(StateError::Magic {
            what: what.to_string(),
            magic: header.magic,
        });
    }
    if header.version != VERSION {
        return Err(StateError::Version(header.version));
    }
    if header.fingerprint != fingerprint {
        return Err(StateError::Fingerprint {
            theirs: header.fingerprint,
            ours: fingerprint.to_string(),
        });
    }
    Ok(())
}

/// Check an entry's bytes (magic, version, fingerprint, that it is `key`'s) and read what it
/// saved; `Err` says why it is not usable.
pub fn decode_entry(bytes: &[u8], fingerprint: &str, key: &Key) -> Result<Saved, StateError> {
    check_header(bytes, "entry", fingerprint)?;
    let entry: EntryIn = serde_json::from_slice(bytes).map_err(|source| StateError::Corrupt {
        what: "entry".into(),
        source,
    })?;
    if &entry.key != key {
        return Err(StateError::OtherInstance {
            held: show_key(&entry.key),
            wanted: show_key(key),
        });
    }
    Ok(Saved {
        program: entry.program,
        continuity: Continuity {
            version: entry.spec_version,
            horizon: entry.horizon,
            recent: entry.recent,
            unfit: entry.unfit,
        },
        monitor: entry.monitor,
    })
}
