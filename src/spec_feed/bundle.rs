//! A spec version as it travels: the main `.tessla` file and every file it includes, read once
//! where it is published and loaded from memory wherever it is run ([`Bundle`]), with an
//! identity that depends only on the texts and the include names as written ([`Bundle::id`]).

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::cell::RefCell;
use std::path::Path;
use tessla_engine::{LoadError, LoadOptions, Loaded};
use tessla_syntax::include::{ResolveError, Resolver};

/// One file of a bundle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BundleFile {
    /// The name the loader gave it where it was read (a path, or `<bundled>/NAME`): shown in
    /// diagnostics.
    pub name: String,
    pub text: String,
}

/// One resolution the loader made: the file `from` (an index into [`Bundle::files`], `None`
/// for the main file) named `written`, which is file `file`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Link {
    pub from: Option<usize>,
    pub written: String,
    pub file: usize,
}

/// A spec and its includes, loadable without the file system.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Bundle {
    pub files: Vec<BundleFile>,
    pub links: Vec<Link>,
}

impl Bundle {
    /// Load the spec at `path` from the file system (as `run --spec` does) and keep every file
    /// it read. Fails as loading fails (the diagnostic names file, line and column).
    pub fn read(path: &Path, options: &LoadOptions) -> Result<(Bundle, Loaded), LoadError> {
        let inner = tessla_engine::file_resolver(options);
        Bundle::record(&path.display().to_string(), &inner, options)
    }

    /// Load the spec `root` through `resolver` and keep every file it read.
    pub fn record(
        root: &str,
        resolver: &dyn Resolver,
        options: &LoadOptions,
    ) -> Result<(Bundle, Loaded), LoadError> {
        let recorder = Recorder {
            inner: resolver,
            bundle: RefCell::new(Bundle {
                files: Vec::new(),
                links: Vec::new(),
            }),
        };
        let loaded = tessla_engine::load_with(root, &recorder, options)?;
        Ok((recorder.bundle.into_inner(), loaded))
    }

    /// Compile the bundle with this process's options (`--set`, `--base-time`).
    pub fn load(&self, options: &LoadOptions) -> Result<Loaded, LoadError> {
        let root = self.files.first().map_or("", |f| f.name.as_str());
        tessla_engine::load_with(root, self, options)
    }

    /// The content's identity: the SHA-256 of every file's text and the names its includes
    /// were written with, in loading order (not where the files were read, so one spec
    /// published from two folders is one version), as 64 hex digits.
    pub fn digest(&self) -> String {
        let mut h = Sha256::new();
        for link in &self.links {
            let from = link.from.map_or(u64::MAX, |f| f as u64);
            h.update(from.to_le_bytes());
            // The main file's name as written is a path: only the file itself counts.
            let written = match link.from {
                Some(_) => link.written.as_str(),
                None => "",
            };
            h.update((written.len() as u64).to_le_bytes());
            h.update(written.as_bytes());
            h.update((link.file as u64).to_le_bytes());
        }
        for f in &self.files {
            h.update((f.text.len() as u64).to_le_bytes());
            h.update(f.text.as_bytes());
        }
        h.finalize().iter().map(|b| format!("{b:02x}")).collect()
    }

    /// The short identity every output's version tag and every message shows: the digest's
    /// first 12 hex digits.
    pub fn id(&self) -> String {
        let mut d = self.digest();
        d.truncate(12);
        d
    }
}

/// Loading from memory: each name resolves as it did where the bundle was read.
impl Resolver for Bundle {
    fn resolve(&self, from: Option<&str>, name: &str) -> Result<(String, String), ResolveError> {
        let from_index = match from {
            None => None,
            Some(f) => Some(
                self.files
                    .iter()
                    .position(|x| x.name == f)
                    .ok_or_else(|| ResolveError(format!("`{f}` is not in the spec bundle")))?,
            ),
        };
        let link = self
            .links
            .iter()
            .find(|l| l.from == from_index && (from_index.is_none() || l.written == name))
            .ok_or_else(|| {
                ResolveError(format!(
                    "`{name}` is not in the spec bundle (it was not read where the bundle was made)"
                ))
            })?;
        let file = self
            .files
            .get(link.file)
            .ok_or_else(|| ResolveError(format!("the spec bundle's link to `{name}` is broken")))?;
        Ok((file.name.clone(), file.text.clone()))
    }
}

/// Resolves through `inner` and records what it returned.
struct Recorder<'a> {
    inner: &'a dyn Resolver,
    bundle: RefCell<Bundle>,
}

impl Resolver for Recorder<'_> {
    fn resolve(&self, from: Option<&str>, name: &str) -> Result<(String, String), ResolveError> {
        let (canonical, text) = self.inner.resolve(from, name)?;
        let mut b = self.bundle.borrow_mut();
        let from_index = from.and_then(|f| b.files.iter().position(|x| x.name == f));
        let file = match b.files.iter().position(|x| x.name == canonical) {
            Some(i) => i,
            None => {
                b.files.push(BundleFile {
                    name: canonical.clone(),
                    text: text.clone(),
                });
                b.files.len() - 1
            }
        };
        let link = Link {
            from: from_index,
            written: name.to_string(),
            file,
        };
        if !b.links.contains(&link) {
            b.links.push(link);
        }
        Ok((canonical, text))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) {
        std::fs::write(dir.join(name), text).unwrap();
    }

    #[test]
    fn a_bundle_loads_without_the_files_and_names_its_content() {
        let base = std::env::temp_dir().join(format!("bundle-{}", std::process::id()));
        let (a, b) = (base.join("a"), base.join("b"));
        for d in [&a, &b] {
            std::fs::create_dir_all(d).unwrap();
            write(d, "lib.tessla", "def double(x: Events[Int]) = x * 2\n");
            write(
                d,
                "main.tessla",
                "include \"lib.tessla\"\nin x: Events[Int]\nout double(x) as d\n",
            );
        }
        let opts = LoadOptions::default();
        let (bundle, _) = Bundle::read(&a.join("main.tessla"), &opts).unwrap();
        assert_eq!(bundle.files.len(), 2);
        std::fs::remove_dir_all(&a).unwrap();
        let loaded = bundle.load(&opts).unwrap();
        assert_eq!(loaded.program.outputs.len(), 1);
        // The same texts read from another folder: the same version.
        let (other, _) = Bundle::read(&b.join("main.tessla"), &opts).unwrap();
        assert_eq!(other.id(), bundle.id());
        // A changed include: another version.
        write(&b, "lib.tessla", "def double(x: Events[Int]) = x + x\n");
        let (changed, _) = Bundle::read(&b.join("main.tessla"), &opts).unwrap();
        assert_ne!(changed.id(), bundle.id());
        assert_eq!(bundle.id().len(), 12);
        std::fs::remove_dir_all(&base).unwrap();
    }
}
