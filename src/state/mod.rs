//! Where monitor state is kept between runs and across a fleet: `--state FILE` ([`file`](mod@file)) or a
//! shared NATS key-value bucket ([`nats`], with the partition [`lease`]), outside the Telegraf
//! binding. Both store the same entry format ([`entry`]: magic, format version, the
//! fingerprint of the options the state is valid for, and the keys of the program each instance
//! ran), and restore it the same way ([`restore`]: stream by stream into the running program).
//!
//! Owns what `--state` names ([`Target`]), the options that decide whether saved state fits a
//! run at all ([`Context`], [`fingerprint`]), and what the step loop calls at its save points
//! ([`Backend`]).

pub mod entry;
pub mod file;
pub mod lease;
pub mod nats;
pub mod restore;

use crate::nats::url::{Url, UrlError};
use crate::processor::Processor;
use crate::processor::instance_table::Key;
use std::io;
use std::path::PathBuf;
use tessla_engine::snapshot;

/// Where `--state` keeps the state.
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// `--state FILE`: one file, this module.
    File(PathBuf),
    /// `--state nats://HOST:PORT[,HOST:PORT...]/BUCKET[?options]`: a JetStream key-value bucket.
    Nats(Box<Url>),
}

/// Why `--state` names no store.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TargetError {
    /// A URL (it looks like one) that does not parse as a bucket's.
    #[error(transparent)]
    Url(#[from] UrlError),
    #[error("empty path")]
    EmptyPath,
}

/// Parse `--state`: `nats://...` is a bucket, anything else a file path. Anything that looks
/// like a URL (`SCHEME://`, or `nats:` without `//`) is parsed as one, so a mistyped bucket URL
/// is refused rather than taken as a file name.
impl Target {
    pub fn parse(s: &str) -> Result<Target, TargetError> {
        let lower = s.to_ascii_lowercase();
        if s.contains("://") || lower.starts_with("nats:") || lower.starts_with("tls:") {
            Ok(Target::Nats(Box::new(Url::parse(s)?)))
        } else if s.is_empty() {
            Err(TargetError::EmptyPath)
        } else {
            Ok(Target::File(PathBuf::from(s)))
        }
    }
}

/// What decides whether saved state fits this run at all: options that change the meaning of
/// every stream's state. (The program does not: each stream whose key is unchanged keeps its
/// state, [`restore`].)
#[derive(Debug, Clone, Default)]
pub struct Context {
    /// `--set NAME=VALUE`, as given. A set value can reach a stream through a function constant,
    /// which node keys do not see, so any change refuses the state.
    pub set: Vec<String>,
    pub base_time: String,
    pub instance_by: Vec<String>,
}

/// The fingerprint of the options `ctx`, as written in saved state (hex).
pub fn fingerprint(ctx: &Context) -> String {
    let mut h = snapshot::text_hash("tessla-telegraf-state options");
    for s in &ctx.set {
        h = snapshot::mix(h, snapshot::text_hash(&format!("--set {s}")));
    }
    h = snapshot::mix(
        h,
        snapshot::text_hash(&format!("--base-time {}", ctx.base_time)),
    );
    for t in &ctx.instance_by {
        h = snapshot::mix(h, snapshot::text_hash(&format!("--instance-by {t}")));
    }
    format!("{h:016x}")
}

/// Where the state of a run is kept: a file ([`file::FileBackend`]) or a shared bucket
/// ([`nats::NatsBackend`]). The step loop calls these at its save points.
pub trait Backend {
    /// What to name in messages (the file's path, the bucket's URL).
    fn describe(&self) -> String;
    /// At start, before the first record: restore what the backend restores up front.
    fn load(&mut self, proc: &mut Processor);
    /// Before the first record of instance `key` in this process is stepped (a shared backend
    /// restores that instance here).
    fn arriving(&mut self, _key: &Key, _proc: &mut Processor) {}
    /// Save every instance of `proc`; returns how many.
    fn save(&mut self, proc: &Processor) -> io::Result<usize>;
    /// The process dropped all its instances (its partition went to another process): look
    /// each one up again when it next arrives.
    fn forget(&mut self) {}
    /// Before [`Backend::save`]: `json` gives the fleet level of this process (`--fleet-spec`
    /// without NATS partitions) as JSON, to save beside the instances (`None`: none to save).
    /// A backend that keeps no fleet level does not call it (a partitioned fleet keeps its
    /// own, in the stream).
    fn keep_fleet(&mut self, _json: &dyn Fn() -> Option<Vec<u8>>) {}
    /// After [`Backend::load`]: the fleet level's JSON the state held, once (`None`: none, or
    /// state written before the fleet level was saved).
    fn take_fleet(&mut self) -> Option<String> {
        None
    }
}
