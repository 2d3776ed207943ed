//! The workspace's folders the helpers need: its root (the shipped confs, the suite beside it)
//! and where a skipped suite leaves its note for `make test`.

use std::path::{Path, PathBuf};

/// The workspace's root folder (the nearest folder above this crate with a `Cargo.lock`).
pub fn workspace_root() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest
        .ancestors()
        .find(|d| d.join("Cargo.lock").is_file())
        .unwrap_or(manifest)
        .to_path_buf()
}

/// Where a skipped suite leaves its note for `make test` (`tools/test-skips.sh` reads
/// `$CARGO_TARGET_DIR/tmp/skipped-suites/`, `target/` without it; a relative target folder is
/// taken from the workspace's root, where `make` runs).
pub fn skip_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("target"));
    let target = if target.is_relative() {
        workspace_root().join(target)
    } else {
        target
    };
    target.join("tmp").join("skipped-suites")
}
