//! `--state FILE`: every monitor instance's state saved at shutdown and read back at start.
//!
//! Owns: the state file (JSON: the header of [`super::entry`], then one engine snapshot per
//! instance key), the atomic write (temporary file in the same folder, fsync, rename, fsync of
//! the folder) and reading it back: a missing file starts fresh; a corrupt file, another format
//! version or a file written for another spec / `--set` / `--base-time` / `--instance-by` is
//! renamed aside (`FILE.rejected-<unix seconds>`) with a warning, and the run starts fresh.
//! Never fatal.
//!
//! JSON rather than a binary format: it is readable when something goes wrong, floats are stored
//! as their bits (exact, NaN included), and the size is measured in `docs/state-and-reload.md`.

use super::entry::{self, MAGIC, VERSION, unix_now, warn_unsaved};
use super::{Backend, Context, fingerprint};
use crate::log::{self, Level};
use crate::processor::Processor;
use crate::processor::instances::Key;
use serde::{Deserialize, Serialize};
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tessla_engine::Program;
use tessla_engine::runtime::snapshot::{self, Snapshot};

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
/// first), then written in one pass: the bytes are those of `StateFile` serialised whole.
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
    entry::check_header(text, "file", &fingerprint(program, ctx))?;
    serde_json::from_slice(text).map_err(|e| format!("corrupt state file: {e}"))
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
