//! `run --watch-spec`: the spec file and every file it includes, looked at every second; a
//! change (modification time, size or presence of any of them) asks for a reload, as SIGHUP
//! does. Polling, not inotify: it works the same on every file system, including a
//! ConfigMap's symlink swap, at the cost of one `stat` per file per second.

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

/// How often the files are looked at.
pub const INTERVAL: Duration = Duration::from_secs(1);

/// What a file looked like: modification time and size (`None`: missing).
type Stamp = Option<(SystemTime, u64)>;

/// The watched spec and what it looked like when last read.
pub struct Watched {
    root: PathBuf,
    files: Vec<(PathBuf, Stamp)>,
}

fn stamp(path: &Path) -> Stamp {
    let m = std::fs::metadata(path).ok()?;
    Some((m.modified().ok()?, m.len()))
}

impl Watched {
    pub fn new(root: &Path) -> Watched {
        let mut w = Watched {
            root: root.to_path_buf(),
            files: Vec::new(),
        };
        w.rescan();
        w
    }

    /// The files to look at: the spec and the includes it names now (read from the files:
    /// an include added by an edit is watched from then on).
    fn rescan(&mut self) {
        let mut files = vec![self.root.clone()];
        let mut i = 0;
        while let Some(f) = files.get(i).cloned() {
            i += 1;
            let Ok(text) = std::fs::read_to_string(&f) else {
                continue;
            };
            for name in includes(&text) {
                let p = f
                    .parent()
                    .map_or_else(|| PathBuf::from(&name), |d| d.join(&name));
                if !files.contains(&p) {
                    files.push(p);
                }
            }
        }
        self.files = files.into_iter().map(|f| (f.clone(), stamp(&f))).collect();
    }

    /// Whether any file changed since the last call (or since it was made); the new state is
    /// what the next call compares with.
    pub fn changed(&mut self) -> bool {
        let changed = self.files.iter().any(|(f, s)| stamp(f) != *s);
        if changed {
            self.rescan();
        }
        changed
    }
}

/// The names of the `include "…"` lines of a spec (a line-level look: a commented-out include
/// is watched too, which costs one `stat`).
fn includes(text: &str) -> Vec<String> {
    text.lines()
        .filter_map(|l| l.trim_start().strip_prefix("include"))
        .filter_map(|rest| {
            let rest = rest.trim_start().strip_prefix('"')?;
            let end = rest.find('"')?;
            Some(rest[..end].to_string())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_edit_of_an_include_is_a_change() {
        let dir = std::env::temp_dir().join(format!("watch-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("lib.tessla"), "def a = 1\n").unwrap();
        std::fs::write(dir.join("m.tessla"), "include \"lib.tessla\"\nout a\n").unwrap();
        let mut w = Watched::new(&dir.join("m.tessla"));
        assert!(!w.changed());
        std::fs::write(dir.join("lib.tessla"), "def a = 22\n").unwrap();
        assert!(w.changed());
        assert!(!w.changed());
        std::fs::remove_file(dir.join("lib.tessla")).unwrap();
        assert!(w.changed());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
