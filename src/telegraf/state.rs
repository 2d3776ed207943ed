//! `--state FILE`: every monitor instance's state saved at shutdown and read back at start.
//!
//! Owns: the state file format (JSON: a header with magic, format version and the fingerprint
//! of what the state is valid for, then one engine snapshot per instance key), the atomic write
//! (temporary file in the same folder, fsync, rename, fsync of the folder) and reading it back:
//! a missing file starts fresh; a corrupt file, another format version or a file written for
//! another spec / `--set` / `--base-time` / `--instance-by` is renamed aside
//! (`FILE.rejected-<unix seconds>`) with a warning, and the run starts fresh. Never fatal.
//!
//! JSON rather than a binary format: it is readable when something goes wrong, floats are stored
//! as their bits (exact, NaN included), and the size is measured in `docs/state-and-reload.md`.
//!
//! Also owns what `--state` names ([`Target`]: a file, or `nats://HOST:PORT/BUCKET`, whose
//! backend lives in [`super::state_nats`]) and the format of one instance's entry
//! ([`encode_entry`], [`check_entry`]: the same magic, version and fingerprint, per instance)
//! and the warning both backends give for values that cannot be saved ([`warn_unsaved`]).

use crate::log::{self, Level};
use crate::telegraf::instances::Key;
use crate::telegraf::processor::Processor;
use serde::{Deserialize, Serialize};
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tessla_engine::Program;
use tessla_engine::runtime::snapshot::{self, Snapshot};

pub const MAGIC: &str = "tessla-telegraf-state";
/// Format version; bumped on any incompatible change of the layout below or of node keys
/// (2: structural node keys, see `tessla_engine::runtime::snapshot`).
pub const VERSION: u32 = 2;

/// Where `--state` keeps the state.
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// `--state FILE`: one file, this module.
    File(PathBuf),
    /// `--state nats://HOST:PORT[,HOST:PORT...]/BUCKET[?options]`: a JetStream key-value bucket.
    Nats(Box<super::state_nats::Url>),
}

/// Parse `--state`: `nats://...` is a bucket, anything else a file path. Anything that looks
/// like a URL (`SCHEME://`, or `nats:` without `//`) is parsed as one, so a mistyped bucket URL
/// is refused rather than taken as a file name.
pub fn parse_target(s: &str) -> Result<Target, String> {
    let lower = s.to_ascii_lowercase();
    if s.contains("://") || lower.starts_with("nats:") || lower.starts_with("tls:") {
        super::state_nats::Url::parse(s).map(|u| Target::Nats(Box::new(u)))
    } else if s.is_empty() {
        Err("empty path".into())
    } else {
        Ok(Target::File(PathBuf::from(s)))
    }
}

/// What, besides the program, decides whether saved state fits this run.
#[derive(Debug, Clone, Default)]
pub struct Context {
    /// `--set NAME=VALUE`, as given.
    pub set: Vec<String>,
    pub base_time: String,
    pub instance_by: Vec<String>,
}

/// The fingerprint of `program` run with `ctx`, as written in the file (hex).
pub fn fingerprint(program: &Program, ctx: &Context) -> String {
    let mut h = snapshot::fingerprint(program);
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

#[derive(Deserialize)]
struct Header {
    magic: String,
    version: u32,
    fingerprint: String,
}

#[derive(Serialize, Deserialize)]
struct SavedInstance {
    /// The values of the `--instance-by` tags (`null`: tag absent).
    key: Key,
    monitor: Snapshot,
}

#[derive(Serialize, Deserialize)]
struct StateFile {
    magic: String,
    version: u32,
    fingerprint: String,
    /// Unix seconds when written (informational).
    written: u64,
    instances: Vec<SavedInstance>,
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

/// Check an entry's bytes (magic, version, fingerprint, that it is `key`'s) and restore its
/// monitor; `Err` says why it is not usable.
pub fn check_entry(
    bytes: &[u8],
    program: &Arc<Program>,
    fingerprint: &str,
    key: &Key,
) -> Result<tessla_engine::Monitor, String> {
    let header: Header = serde_json::from_slice(bytes)
        .map_err(|e| format!("not a state entry (corrupt or truncated: {e})"))?;
    if header.magic != MAGIC {
        return Err(format!(
            "not a state entry (magic `{}`, expected `{MAGIC}`)",
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

/// One instance as the file holds it, borrowed for writing (the same JSON as [`SavedInstance`]).
#[derive(Serialize)]
struct SavedRef<'a> {
    key: &'a Key,
    monitor: Snapshot,
}

/// The file's fields before `instances`, in [`StateFile`]'s order.
#[derive(Serialize)]
struct HeaderOut<'a> {
    magic: &'a str,
    version: u32,
    fingerprint: &'a str,
    written: u64,
}

/// Instances per encoding thread below which one thread does it all.
const PER_THREAD: usize = 512;

/// The JSON of `instances`, comma-separated, and the count of stream values that could not be
/// saved.
fn encode_instances(
    instances: &[(&Key, &tessla_engine::Monitor)],
    keys: &[u64],
) -> io::Result<(Vec<u8>, usize)> {
    let mut out = Vec::with_capacity(instances.len() * 2048);
    let mut unsaved = 0;
    for (i, (key, m)) in instances.iter().enumerate() {
        let monitor = snapshot::snapshot_with_keys(m, keys);
        unsaved += monitor.unsaved;
        if i > 0 {
            out.push(b',');
        }
        serde_json::to_writer(&mut out, &SavedRef { key, monitor }).map_err(io::Error::other)?;
    }
    Ok((out, unsaved))
}

/// Save every instance of `proc` to `path` atomically. Returns the number of instances saved.
///
/// The instances are snapshotted and encoded on up to as many threads as the machine has cores
/// (each a contiguous run of them, so the file lists them in the same order, least recently used
/// first), then written in one pass: the bytes are those of [`StateFile`] serialised whole.
pub fn save(path: &Path, proc: &Processor, ctx: &Context) -> io::Result<usize> {
    let program = proc.program();
    let keys = snapshot::node_keys(program);
    let monitors: Vec<(&Key, &tessla_engine::Monitor)> = proc.monitors().collect();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads = cores.min(monitors.len() / PER_THREAD).max(1);
    let chunk = monitors.len().div_ceil(threads).max(1);
    let parts: Vec<(Vec<u8>, usize)> = if threads == 1 {
        vec![encode_instances(&monitors, &keys)?]
    } else {
        std::thread::scope(|s| {
            let handles: Vec<_> = monitors
                .chunks(chunk)
                .map(|c| s.spawn(|| encode_instances(c, &keys)))
                .collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join()
                        .map_err(|_| io::Error::other("a state encoding thread failed"))?
                })
                .collect::<io::Result<Vec<_>>>()
        })?
    };
    let unsaved: usize = parts.iter().map(|(_, u)| u).sum();
    warn_unsaved(unsaved);
    let fingerprint = fingerprint(program, ctx);
    let header = serde_json::to_vec(&HeaderOut {
        magic: MAGIC,
        version: VERSION,
        fingerprint: &fingerprint,
        written: unix_now(),
    })
    .map_err(io::Error::other)?;
    // `{...}` without its closing brace, then the instances.
    let open = header.strip_suffix(b"}").unwrap_or(&header);
    write_atomic(path, |w| {
        w.write_all(open)?;
        w.write_all(b",\"instances\":[")?;
        let mut first = true;
        for (bytes, _) in &parts {
            if bytes.is_empty() {
                continue;
            }
            if !first {
                w.write_all(b",")?;
            }
            first = false;
            w.write_all(bytes)?;
        }
        w.write_all(b"]}\n")
    })?;
    Ok(monitors.len())
}

/// Write `path` through a temporary file in the same folder: fsync, rename over `path`, fsync
/// the folder, so a crash leaves either the old or the new file, never a torn one.
/// Hand-written (a few lines): `tempfile`'s `persist` does not sync the folder.
fn write_atomic(
    path: &Path,
    body: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "state".into());
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    let result = (|| {
        let f = OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .open(&tmp)?;
        let mut w = BufWriter::new(f);
        body(&mut w)?;
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        fs::rename(&tmp, path)?;
        File::open(&dir)?.sync_all()
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// How reading the state file went.
#[derive(Debug, PartialEq)]
pub enum Outcome {
    /// No file: start fresh.
    Missing,
    /// This many instances restored.
    Restored(usize),
    /// Not usable (why); renamed to the path given, if that worked.
    Rejected(String, Option<PathBuf>),
    /// The file could not be read at all (permissions ...); left in place.
    Unreadable(String),
}

/// Read `path` and restore its instances into `proc` (which has none yet). Logs what happened.
pub fn load(path: &Path, proc: &mut Processor, ctx: &Context) -> Outcome {
    let outcome = load_quiet(path, proc, ctx);
    let shown = path.display();
    match &outcome {
        Outcome::Missing => log::log(
            Level::Info,
            &format!("state: {shown} does not exist yet; starting fresh"),
        ),
        Outcome::Restored(n) => log::log(
            Level::Info,
            &format!("state: restored {n} monitor instances from {shown}"),
        ),
        Outcome::Rejected(why, aside) => log::log(
            Level::Warn,
            &format!(
                "state: {shown} not used: {why}; {}; starting fresh",
                match aside {
                    Some(p) => format!("renamed to {}", p.display()),
                    None => "could not rename it aside".into(),
                }
            ),
        ),
        Outcome::Unreadable(e) => log::log(
            Level::Warn,
            &format!("state: cannot read {shown}: {e}; starting fresh"),
        ),
    }
    outcome
}

fn load_quiet(path: &Path, proc: &mut Processor, ctx: &Context) -> Outcome {
    let text = match fs::read(path) {
        Ok(t) => t,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Outcome::Missing,
        Err(e) => return Outcome::Unreadable(e.to_string()),
    };
    match check(&text, proc.program(), ctx) {
        Ok(file) => {
            let program = Arc::clone(proc.program());
            let keys = snapshot::node_keys(&program);
            let n = file.instances.len();
            for s in file.instances {
                let m = snapshot::restore_with_keys(Arc::clone(&program), &s.monitor, &keys);
                proc.restore_instance(s.key, m);
            }
            Outcome::Restored(n)
        }
        Err(why) => {
            let moved =
                aside_name(path).and_then(|aside| fs::rename(path, &aside).ok().map(|()| aside));
            Outcome::Rejected(why, moved)
        }
    }
}

/// `FILE.rejected-<unix seconds>`, with `-2`, `-3` ... appended when that exists already.
fn aside_name(path: &Path) -> Option<PathBuf> {
    let base = format!("{}.rejected-{}", path.display(), unix_now());
    (1..1000)
        .map(|n| match n {
            1 => PathBuf::from(&base),
            n => PathBuf::from(format!("{base}-{n}")),
        })
        .find(|p| !p.exists())
}

/// Parse and validate the file's bytes.
fn check(text: &[u8], program: &Program, ctx: &Context) -> Result<StateFile, String> {
    let header: Header = serde_json::from_slice(text)
        .map_err(|e| format!("not a state file (corrupt or truncated: {e})"))?;
    if header.magic != MAGIC {
        return Err(format!(
            "not a state file (magic `{}`, expected `{MAGIC}`)",
            header.magic
        ));
    }
    if header.version != VERSION {
        return Err(format!(
            "written in state format version {}, this build reads version {VERSION}",
            header.version
        ));
    }
    let expected = fingerprint(program, ctx);
    if header.fingerprint != expected {
        return Err(format!(
            "written for another spec or other options (fingerprint {}, this run {expected}; the spec, --set, --base-time and --instance-by must match)",
            header.fingerprint
        ));
    }
    serde_json::from_slice(text).map_err(|e| format!("corrupt state file: {e}"))
}

/// Where the state of a run is kept: a file ([`FileBackend`]) or a shared bucket
/// ([`super::state_nats::NatsBackend`]). The step loop calls these at its save points.
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
}

/// `--state FILE`: [`load`] at start, [`save`] at the save points.
pub struct FileBackend {
    pub path: PathBuf,
    pub ctx: Context,
}

impl Backend for FileBackend {
    fn describe(&self) -> String {
        self.path.display().to_string()
    }

    fn load(&mut self, proc: &mut Processor) {
        load(&self.path, proc, &self.ctx);
    }

    fn save(&mut self, proc: &Processor) -> io::Result<usize> {
        save(&self.path, proc, &self.ctx)
    }
}
