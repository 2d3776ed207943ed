//! `--state FILE`: every monitor instance's state saved at shutdown and read back at start.
//!
//! Owns: the state file (JSON: the header of [`super::entry`], then one engine snapshot per
//! instance key), the atomic write (temporary file in the same folder, fsync, rename, fsync of
//! the folder) and reading it back: a missing file starts fresh; a corrupt file, another format
//! version or a file written for other `--set` / `--base-time` / `--instance-by` options is
//! renamed aside (`FILE.rejected-<unix seconds>`) with a warning, and the run starts fresh.
//! A file saved by another program (an edited spec) is restored stream by stream
//! ([`super::restore`]). Never fatal. With `--fleet-spec` (one process) the file also holds
//! the fleet level (`"fleet"`, JSON the step loop hands over and gets back as it is); a file
//! without it (earlier versions) still loads.
//!
//! JSON rather than a binary format: it is readable when something goes wrong, floats are stored
//! as their bits (exact, NaN included), and the size is measured in `docs/book/src/state-and-reload.md`.

use super::entry::{
    self, MAGIC, Programs, SavedProgram, StateError, VERSION, unix_now, warn_unsaved,
};
use super::restore::Restorer;
use super::{Backend, Context, fingerprint};
use crate::processor::Continuity;
use crate::processor::Processor;
use crate::processor::instance_table::Key;
use serde::{Deserialize, Serialize};
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use tessla_engine::snapshot::{self, Snapshot};

#[derive(Serialize, Deserialize)]
struct SavedInstance {
    /// The values of the `--instance-by` tags (`null`: tag absent).
    key: Key,
    /// The program it ran: an index into [`StateFile::programs`].
    program: usize,
    /// The id of the spec version it ran (`processor::Continuity`); absent in older files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    spec_version: Option<String>,
    /// The event time whose version it ran (`Processor::saved_instances`); absent in files
    /// written before it was saved (then its clock).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    horizon: Option<i64>,
    /// Its newest records (time, digest) and the rollouts its records did not fit
    /// (`processor::Continuity`); absent in older files.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    recent: Vec<(i64, u64)>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    unfit: Vec<(String, i64)>,
    monitor: Snapshot,
}

#[derive(Serialize, Deserialize)]
struct StateFile {
    magic: String,
    version: u32,
    fingerprint: String,
    /// Unix seconds when written (informational).
    written: u64,
    /// The programs the instances ran (one, unless a rollout had some run another version).
    programs: Vec<SavedProgram>,
    instances: Vec<SavedInstance>,
    /// The fleet level of a one-process `--fleet-spec` run, as the step loop gave it; absent
    /// in files without one (and in earlier versions).
    #[serde(default)]
    fleet: Option<Box<serde_json::value::RawValue>>,
}

/// One instance as the file holds it, borrowed for writing (the same JSON as [`SavedInstance`]).
#[derive(Serialize)]
struct SavedRef<'a> {
    key: &'a Key,
    program: usize,
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

/// The file's fields before `instances`, in [`StateFile`]'s order.
#[derive(Serialize)]
struct HeaderOut<'a> {
    magic: &'a str,
    version: u32,
    fingerprint: &'a str,
    written: u64,
    programs: Vec<&'a SavedProgram>,
}

/// Instances per encoding thread below which one thread does it all.
const PER_THREAD: usize = 512;

/// One instance to save: its key, its monitor, the index of its program in [`Programs`] and
/// what it carries besides.
type Instance<'a> = (&'a Key, &'a tessla_engine::Monitor, usize, Continuity);

/// The JSON of `instances`, comma-separated, and the count of stream values that could not be
/// saved. `keys`: the node keys of each program, by index.
fn encode_instances(instances: &[Instance<'_>], keys: &[&[u64]]) -> io::Result<(Vec<u8>, usize)> {
    let mut out = Vec::with_capacity(instances.len() * 2048);
    let mut unsaved = 0;
    for (i, (key, m, program, c)) in instances.iter().enumerate() {
        let (key, m, program) = (*key, *m, *program);
        let monitor = snapshot::snapshot_with_keys(m, keys.get(program).copied().unwrap_or(&[]));
        unsaved += monitor.unsaved;
        if i > 0 {
            out.push(b',');
        }
        serde_json::to_writer(
            &mut out,
            &SavedRef {
                key,
                program,
                spec_version: c.version.as_deref(),
                horizon: c.horizon,
                recent: &c.recent,
                unfit: &c.unfit,
                monitor,
            },
        )
        .map_err(io::Error::other)?;
    }
    Ok((out, unsaved))
}

/// Save every instance of `proc` to `path` atomically. Returns the number of instances saved.
///
/// Each instance is snapshotted with the keys of its own program (computed once per program).
/// The instances are snapshotted and encoded on up to as many threads as the machine has cores
/// (each a contiguous run of them, so the file lists them in the same order, least recently used
/// first), then written in one pass: the bytes are those of `StateFile` serialised whole.
pub fn save(path: &Path, proc: &Processor, ctx: &Context) -> io::Result<usize> {
    save_with_fleet(path, proc, ctx, None)
}

/// [`save`], with the fleet level's JSON (`fleet`, written as it is after the instances).
pub fn save_with_fleet(
    path: &Path,
    proc: &Processor,
    ctx: &Context,
    fleet: Option<&[u8]>,
) -> io::Result<usize> {
    let mut programs = Programs::default();
    let monitors: Vec<Instance<'_>> = proc
        .saved_instances()
        .map(|(k, m, h)| (k, m, programs.index(m.program()), h))
        .collect();
    let keys = programs.node_keys();
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
    let fingerprint = fingerprint(ctx);
    let header = serde_json::to_vec(&HeaderOut {
        magic: MAGIC,
        version: VERSION,
        fingerprint: &fingerprint,
        written: unix_now(),
        programs: programs.list.iter().map(|k| &k.saved).collect(),
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
        w.write_all(b"]")?;
        if let Some(fleet) = fleet {
            w.write_all(b",\"fleet\":")?;
            w.write_all(fleet)?;
        }
        w.write_all(b"}\n")
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
    load_with_fleet(path, proc, ctx).0
}

/// [`load`], and the fleet level's JSON the file holds, if any.
pub fn load_with_fleet(
    path: &Path,
    proc: &mut Processor,
    ctx: &Context,
) -> (Outcome, Option<String>) {
    let (outcome, notes, fleet) = load_quiet(path, proc, ctx);
    let shown = path.display();
    match &outcome {
        Outcome::Missing => log_info!("state: {shown} does not exist yet; starting fresh"),
        Outcome::Restored(n) => log_info!("state: restored {n} monitor instances from {shown}"),
        Outcome::Rejected(why, aside) => log_warn!(
            "state: {shown} not used: {why}; {}; starting fresh",
            match aside {
                Some(p) => format!("renamed to {}", p.display()),
                None => "could not rename it aside".into(),
            }
        ),
        Outcome::Unreadable(e) => log_warn!("state: cannot read {shown}: {e}; starting fresh"),
    }
    for note in notes {
        log_info!("{}", note);
    }
    (outcome, fleet)
}

/// [`load`] without its messages; the second value holds what a restore from another program
/// reset (to log after the outcome), the third the fleet level's JSON.
fn load_quiet(
    path: &Path,
    proc: &mut Processor,
    ctx: &Context,
) -> (Outcome, Vec<String>, Option<String>) {
    let text = match fs::read(path) {
        Ok(t) => t,
        Err(e) if e.kind() == io::ErrorKind::NotFound => {
            return (Outcome::Missing, Vec::new(), None);
        }
        Err(e) => return (Outcome::Unreadable(e.to_string()), Vec::new(), None),
    };
    match check(&text, ctx) {
        Ok(file) => {
            let mut restorer = Restorer::new(path.display().to_string());
            let mut notes = Vec::new();
            let n = file.instances.len();
            for s in file.instances {
                // `check` made sure every index is in range.
                let Some(saved) = file.programs.get(s.program) else {
                    continue;
                };
                let c = Continuity {
                    version: s.spec_version,
                    horizon: s.horizon,
                    recent: s.recent,
                    unfit: s.unfit,
                };
                let (m, note) = restorer.restore(proc, &s.key, saved, &s.monitor, &c);
                notes.extend(note);
                proc.restore_instance_at(s.key, m, c);
            }
            let fleet = file.fleet.map(|f| f.get().to_string());
            (Outcome::Restored(n), notes, fleet)
        }
        Err(why) => {
            let moved =
                aside_name(path).and_then(|aside| fs::rename(path, &aside).ok().map(|()| aside));
            (Outcome::Rejected(why.to_string(), moved), Vec::new(), None)
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
fn check(text: &[u8], ctx: &Context) -> Result<StateFile, StateError> {
    entry::check_header(text, "file", &fingerprint(ctx))?;
    let file: StateFile = serde_json::from_slice(text).map_err(|source| StateError::Corrupt {
        what: "file".into(),
        source,
    })?;
    if let Some(s) = file
        .instances
        .iter()
        .find(|s| s.program >= file.programs.len())
    {
        return Err(StateError::NoSuchProgram {
            program: s.program,
            listed: file.programs.len(),
        });
    }
    Ok(file)
}

/// Whether `--state FILE` can be saved: its folder exists and a file can be made in it, and the
/// path is not a folder. Checked at start, so a mistake is found before a run's state is lost
/// at its end; the message says what to do.
pub fn check_writable(path: &Path) -> Result<(), WritableError> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let shown = path.display().to_string();
    let folder = dir.display().to_string();
    match fs::metadata(&dir) {
        Ok(m) if m.is_dir() => {}
        Ok(_) => return Err(WritableError::NotAFolder { shown, folder }),
        Err(e) if e.kind() == io::ErrorKind::NotFound => {
            return Err(WritableError::NoFolder { shown, folder });
        }
        Err(source) => {
            return Err(WritableError::FolderUnreadable {
                shown,
                folder,
                source,
            });
        }
    }
    if path.is_dir() {
        return Err(WritableError::IsAFolder {
            shown,
            example: path.join("monitor.state").display().to_string(),
        });
    }
    // A file made and removed in the folder, as the save's temporary file will be.
    let probe = dir.join(format!(".tessla-telegraf-probe-{}", std::process::id()));
    match OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(_) => {
            let _ = fs::remove_file(&probe);
            Ok(())
        }
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => Ok(()),
        Err(source) => Err(WritableError::NotWritable {
            shown,
            folder,
            source,
        }),
    }
}

/// Why `--state FILE` cannot be saved ([`check_writable`]): what is wrong and what to do.
#[derive(Debug, thiserror::Error)]
pub enum WritableError {
    #[error("--state {shown}: {folder} is not a folder: give --state a file in a folder")]
    NotAFolder { shown: String, folder: String },
    #[error(
        "--state {shown}: the folder {folder} does not exist: create it \
         (`mkdir -p {folder}`, writable for the user Telegraf runs as; the systemd \
         drop-in's StateDirectory= makes /var/lib/tessla-telegraf) or give --state a \
         file in a folder that exists"
    )]
    NoFolder { shown: String, folder: String },
    #[error("--state {shown}: cannot read the folder {folder}: {source}")]
    FolderUnreadable {
        shown: String,
        folder: String,
        source: io::Error,
    },
    #[error("--state {shown} is a folder: give --state a file name, e.g. {example}")]
    IsAFolder { shown: String, example: String },
    #[error(
        "--state {shown}: cannot write in {folder} ({source}): make it writable for the user \
         Telegraf runs as (e.g. `sudo chown telegraf {folder}`) or give --state a file in \
         a folder you can write"
    )]
    NotWritable {
        shown: String,
        folder: String,
        source: io::Error,
    },
}

/// `--state FILE`: [`load`] at start, [`save`] at the save points, the fleet level with them.
pub struct FileBackend {
    pub path: PathBuf,
    pub ctx: Context,
    /// The fleet level to save next, and the one the file held at load.
    fleet_out: Option<Vec<u8>>,
    fleet_in: Option<String>,
}

impl FileBackend {
    pub fn new(path: PathBuf, ctx: Context) -> FileBackend {
        FileBackend {
            path,
            ctx,
            fleet_out: None,
            fleet_in: None,
        }
    }
}

impl Backend for FileBackend {
    fn describe(&self) -> String {
        self.path.display().to_string()
    }

    fn load(&mut self, proc: &mut Processor) {
        self.fleet_in = load_with_fleet(&self.path, proc, &self.ctx).1;
    }

    fn save(&mut self, proc: &Processor) -> io::Result<usize> {
        save_with_fleet(&self.path, proc, &self.ctx, self.fleet_out.as_deref())
    }

    fn keep_fleet(&mut self, json: &dyn Fn() -> Option<Vec<u8>>) {
        self.fleet_out = json();
    }

    fn take_fleet(&mut self) -> Option<String> {
        self.fleet_in.take()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::processor::Options;

    #[test]
    fn a_state_file_that_cannot_be_saved_is_found_at_start() {
        let dir = tempfile::tempdir().unwrap();
        assert!(check_writable(&dir.path().join("m.state")).is_ok());
        let missing = dir.path().join("nope/m.state");
        let e = check_writable(&missing).unwrap_err().to_string();
        assert!(e.contains("does not exist: create it (`mkdir -p "), "{e}");
        let e = check_writable(dir.path()).unwrap_err().to_string();
        assert!(e.contains("is a folder: give --state a file name"), "{e}");
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            0,
            "the probe is removed"
        );
    }
    use crate::processor::tests::program;
    use crate::processor::versions::Selector;
    use lineproto::RecordSplitter;

    fn processor(spec: &str) -> Processor {
        Processor::new(
            program(spec),
            Options {
                passthrough: false,
                instance_by: vec!["robot".into()],
                ..Options::default()
            },
        )
        .unwrap()
    }

    fn feed(p: &mut Processor, input: &str) -> String {
        let mut s = RecordSplitter::default();
        s.push(input.as_bytes());
        let mut out = Vec::new();
        while let Some(r) = s.next_record() {
            p.record(&r, &mut out);
        }
        p.end_of_read();
        String::from_utf8(out).unwrap()
    }

    const OLD: &str =
        "in x: Events[Int]\ndef c = count(x)\ndef s = count(filter(x, x > 0))\nout c\nout s\n";
    const NEW: &str =
        "in x: Events[Int]\ndef c = count(x)\ndef s = count(filter(x, x > 1))\nout c\nout s\n";

    /// Instances running different versions (a rollout) are each saved with their own
    /// program's keys, and restored into the running program stream by stream: robot a, saved
    /// by the new version, continues everything; robot b, saved by the old one, keeps `c` and
    /// starts `s` afresh, and one line says so.
    #[test]
    fn each_instance_is_saved_by_its_own_program_and_restored_by_stream() {
        let ctx = Context {
            instance_by: vec!["robot".into()],
            ..Context::default()
        };
        let mut p = processor(OLD);
        p.accept_version(
            "new",
            "",
            program(NEW),
            0,
            Selector::parse("robot=a").unwrap(),
        )
        .unwrap();
        assert_eq!(
            feed(&mut p, "m,robot=a x=2i 100\nm,robot=b x=2i 100\n"),
            "tessla,robot=a c=1i,s=1i 100\ntessla,robot=b c=1i,s=1i 100\n"
        );
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("state.json");
        assert_eq!(save(&path, &p, &ctx).unwrap(), 2);
        let file: StateFile = serde_json::from_slice(&fs::read(&path).unwrap()).unwrap();
        assert_eq!(file.version, 3);
        assert_eq!(file.programs.len(), 2);
        let of = |robot: &str| {
            let i = file
                .instances
                .iter()
                .find(|s| s.key == [Some(robot.to_string())])
                .unwrap();
            &file.programs[i.program]
        };
        assert_eq!(
            of("a").fingerprint,
            entry::program_fingerprint(&program(NEW))
        );
        assert_eq!(
            of("b").fingerprint,
            entry::program_fingerprint(&program(OLD))
        );

        let mut q = processor(NEW);
        let (outcome, notes, fleet) = load_quiet(&path, &mut q, &ctx);
        assert_eq!(outcome, Outcome::Restored(2));
        assert_eq!(fleet, None, "no fleet level was saved");
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(
            notes[0].contains("holds state saved by another program"),
            "{notes:?}"
        );
        assert!(
            notes[0].ends_with("reset: outputs s, 2 internal streams"),
            "{notes:?}"
        );
        assert_eq!(
            feed(&mut q, "m,robot=a x=2i 200\nm,robot=b x=2i 200\n"),
            "tessla,robot=a c=2i,s=2i 200\ntessla,robot=b c=2i,s=1i 200\n"
        );
    }

    /// Only the options refuse a file: another --set, --base-time or --instance-by.
    #[test]
    fn the_fingerprint_covers_the_options_only() {
        let base = Context {
            set: vec!["delta=0.5".into()],
            base_time: "0".into(),
            instance_by: vec!["robot".into()],
        };
        let fp = fingerprint(&base);
        assert_eq!(fp, fingerprint(&base.clone()));
        for other in [
            Context {
                set: vec!["delta=0.6".into()],
                ..base.clone()
            },
            Context {
                base_time: "1".into(),
                ..base.clone()
            },
            Context {
                instance_by: vec!["topic".into()],
                ..base.clone()
            },
        ] {
            assert_ne!(fingerprint(&other), fp, "{other:?}");
        }
    }

    /// The fleet level's JSON the step loop hands over is written as `"fleet"` after the
    /// instances and given back as it is at load; a file without it loads as before.
    #[test]
    fn the_fleet_level_is_saved_beside_the_instances_and_given_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("state.json");
        let ctx = Context {
            instance_by: vec!["robot".into()],
            ..Context::default()
        };
        let mut p = processor(OLD);
        feed(&mut p, "m,robot=a x=1i 10\n");
        let fleet = br#"{"inputs":["c"],"level":{"front":10}}"#;
        assert_eq!(save_with_fleet(&path, &p, &ctx, Some(fleet)).unwrap(), 1);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(
            text.trim_end()
                .ends_with(r#"],"fleet":{"inputs":["c"],"level":{"front":10}}}"#)
        );
        let mut q = processor(OLD);
        let (outcome, got) = load_with_fleet(&path, &mut q, &ctx);
        assert_eq!(outcome, Outcome::Restored(1));
        assert_eq!(got.as_deref().map(str::as_bytes), Some(&fleet[..]));
        // Without it (earlier versions): the same instances, no fleet level.
        save(&path, &p, &ctx).unwrap();
        assert!(
            !std::fs::read_to_string(&path)
                .unwrap()
                .contains("\"fleet\"")
        );
        let mut q = processor(OLD);
        assert_eq!(
            load_with_fleet(&path, &mut q, &ctx),
            (Outcome::Restored(1), None)
        );
    }

    /// A message the broker redelivers after a restart (the same record again) is still a
    /// repeat: each instance's newest records are saved with it. A robot that stayed on its
    /// version because its records did not fit a rollout's stays there after the restart.
    #[test]
    fn a_restart_keeps_what_recognises_repeats_and_what_a_robot_could_not_read() {
        const V1: &str = "in x: Events[Int]\ndef v = x\nout v\n";
        const V2: &str = "in x: Events[Bool]\ndef v = x\nout v\n";
        let ctx = Context {
            instance_by: vec!["robot".into()],
            ..Context::default()
        };
        let rolled = || {
            let mut p = processor(V1);
            p.accept_version("v2", "", program(V2), 1000, Selector::all())
                .unwrap();
            p
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("state.json");
        let run = |restart: bool| {
            let mut p = rolled();
            let mut out = feed(&mut p, "m,robot=r1 x=1i 500\nm,robot=r1 x=2i 1100\n");
            if restart {
                assert_eq!(save(&path, &p, &ctx).unwrap(), 1);
                p = rolled();
                assert_eq!(load_quiet(&path, &mut p, &ctx).0, Outcome::Restored(1));
            }
            // The second record again (redelivered), then a new one.
            out.push_str(&feed(
                &mut p,
                "m,robot=r1 x=2i 1100\nm,robot=r1 x=3i 1200\n",
            ));
            (out, p.counters.duplicates)
        };
        let once = run(false);
        assert_eq!(
            once.0,
            "tessla,robot=r1 v=1i 500\ntessla,robot=r1 v=2i 1100\ntessla,robot=r1 v=3i 1200\n"
        );
        assert_eq!(once.1, 1);
        let restarted = run(true);
        assert_eq!(restarted.0, once.0);
        assert_eq!(
            restarted.1, 1,
            "the redelivered record is a repeat after the restart too"
        );
    }

    /// Found by the combination test: a rollout committed while a robot was silent, starting
    /// before the robot's last record (late for it), switches the robot at its next record,
    /// where that record's fit is checked. A restart in between restored the robot straight
    /// into the new version (no record to check, a different carry), so a robot that would
    /// have stayed off it (its records do not fit) lost its count. Saved with its version, it
    /// is restored into the version it ran and switches (or not) at its next record, as
    /// without the restart.
    #[test]
    fn a_restart_does_not_switch_a_robot_to_a_rollout_committed_while_it_was_silent() {
        const V1: &str = "in x: Events[Int]\ndef c = count(x)\nout c\n";
        const V2: &str = "in x: Events[Bool]\ndef c = count(x)\nout c\n";
        let ctx = Context {
            instance_by: vec!["robot".into()],
            ..Context::default()
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("state.json");
        let run = |restart: bool| {
            let mut p = processor(V1);
            let mut out = feed(&mut p, "m,robot=r1 x=1i 500\nm,robot=r1 x=2i 600\n");
            // Committed while r1 is silent, from before its last record.
            let late = |p: &mut Processor| {
                p.accept_version("v2", "", program(V2), 550, Selector::all())
                    .unwrap();
            };
            late(&mut p);
            if restart {
                save(&path, &p, &ctx).unwrap();
                p = processor(V1);
                late(&mut p);
                assert_eq!(load_quiet(&path, &mut p, &ctx).0, Outcome::Restored(1));
            }
            out.push_str(&feed(&mut p, "m,robot=r1 x=3i 700\n"));
            out
        };
        let once = run(false);
        assert_eq!(
            once, "tessla,robot=r1 c=1i 500\ntessla,robot=r1 c=2i 600\ntessla,robot=r1 c=3i 700\n",
            "r1's Int does not fit the Bool version: it stays, its count goes on"
        );
        assert_eq!(run(true), once);
    }

    /// A rollout from T = 1000 for r1; r1's record stamped T - 1 arrives when its last step is
    /// at T - 1, so it is stepped at T by the old version (the stamp decides). Two late records
    /// stamped before T after it are judged by the old version too, whether or not the process
    /// was stopped and restarted with its state in between.
    #[test]
    fn a_restart_keeps_the_version_the_record_stamps_give() {
        const V1: &str = "in x: Events[Int]\ndef v = x\nout v\n";
        const V2: &str = "in x: Events[Int]\ndef v = x * 10\nout v\n";
        let ctx = Context {
            instance_by: vec!["robot".into()],
            ..Context::default()
        };
        let rolled = || {
            let mut p = processor(V1);
            let r1 = Selector::parse("robot=r1").unwrap();
            p.accept_version("v2", "", program(V2), 1000, r1).unwrap();
            p
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("state.json");
        let run = |restart: bool| {
            let mut p = rolled();
            let mut out = feed(&mut p, "m,robot=r1 x=1i 999\nm,robot=r1 x=2i 999\n");
            if restart {
                assert_eq!(save(&path, &p, &ctx).unwrap(), 1);
                p = rolled();
                assert_eq!(load_quiet(&path, &mut p, &ctx).0, Outcome::Restored(1));
            }
            out.push_str(&feed(&mut p, "m,robot=r1 x=3i 500\nm,robot=r1 x=4i 500\n"));
            out.push_str(&feed(&mut p, "m,robot=r1 x=5i 1100\n"));
            out
        };
        let once = run(false);
        assert_eq!(
            once,
            "tessla,robot=r1 v=1i 999\ntessla,robot=r1 v=2i 1000\n\
             tessla,robot=r1 v=3i 1001\ntessla,robot=r1 v=4i 1002\n\
             tessla,robot=r1 v=50i 1100\n"
        );
        assert_eq!(run(true), once);
    }

    /// A file written before instances carried their horizon still loads: each instance is
    /// restored into the version its clock gives.
    #[test]
    fn a_file_without_horizons_restores_each_instance_at_its_clock() {
        const V1: &str = "in x: Events[Int]\ndef v = x\nout v\n";
        const V2: &str = "in x: Events[Int]\ndef v = x * 10\nout v\n";
        let ctx = Context {
            instance_by: vec!["robot".into()],
            ..Context::default()
        };
        let rolled = || {
            let mut p = processor(V1);
            let r1 = Selector::parse("robot=r1").unwrap();
            p.accept_version("v2", "", program(V2), 1000, r1).unwrap();
            p
        };
        let mut p = rolled();
        feed(&mut p, "m,robot=r1 x=1i 999\nm,robot=r1 x=2i 999\n");
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("state.json");
        save(&path, &p, &ctx).unwrap();
        let text = fs::read_to_string(&path).unwrap();
        assert!(text.contains("\"horizon\":999,"), "{text}");
        fs::write(&path, text.replace("\"horizon\":999,", "")).unwrap();
        let mut q = rolled();
        assert_eq!(load_quiet(&path, &mut q, &ctx).0, Outcome::Restored(1));
        assert_eq!(
            feed(&mut q, "m,robot=r1 x=3i 500\n"),
            "tessla,robot=r1 v=30i 1001\n"
        );
    }
}
