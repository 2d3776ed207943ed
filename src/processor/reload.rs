//! SIGHUP: reload the spec file (and its includes) without losing the monitors' state.
//!
//! Owns: where the spec comes from ([`SpecSource`]: a file, or the bundled robot monitors, which
//! never change while running, so their reload keeps everything) and the reload itself: a spec
//! that fails to check is reported with its full diagnostic and the running one stays; a good
//! one replaces it for every instance, each stream whose key (see
//! `tessla_engine::runtime::snapshot`) is unchanged keeping its state, and the streams that start
//! afresh are logged.

use crate::log::{self, Level};
use crate::processor::Processor;
use std::path::PathBuf;
use std::sync::Arc;
use tessla_engine::runtime::snapshot;
use tessla_engine::{LoadError, LoadOptions, Loaded};

/// The spec `run` loads at start and on every SIGHUP.
#[derive(Debug, Clone)]
pub struct SpecSource {
    /// `--spec`; `None`: the bundled robot monitors.
    pub path: Option<PathBuf>,
    pub options: LoadOptions,
}

impl SpecSource {
    pub fn load(&self) -> Result<Loaded, LoadError> {
        match &self.path {
            Some(p) => tessla_engine::load_file(p, &self.options),
            None => crate::bundled::load(&self.options),
        }
    }

    pub fn describe(&self) -> String {
        match &self.path {
            Some(p) => p.display().to_string(),
            None => "the bundled robot monitors".into(),
        }
    }
}

/// What a reload did.
#[derive(Debug, PartialEq)]
pub enum Reloaded {
    /// The new spec did not check (or bind); the old one keeps running.
    Refused,
    /// Replaced: the names of the outputs whose streams start afresh, and how many internal
    /// streams do.
    Replaced {
        reset_outputs: Vec<String>,
        reset_internal: usize,
    },
}

/// Reload `src` into `proc` (every record before it was evaluated with the old spec, so no
/// step is open). Logs the outcome.
pub fn reload(src: &SpecSource, proc: &mut Processor) -> Reloaded {
    log::log(
        Level::Info,
        &format!("SIGHUP: reloading {}", src.describe()),
    );
    let loaded = match src.load() {
        Ok(l) => l,
        Err(e) => {
            log::log(
                Level::Error,
                &format!(
                    "reload: {} has errors; the running spec stays in use\n{}",
                    src.describe(),
                    e.render()
                ),
            );
            return Reloaded::Refused;
        }
    };
    if !loaded.warnings.is_empty() {
        log::log(
            Level::Warn,
            &tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, false),
        );
    }
    let new = loaded.program;
    if new.outputs.is_empty() {
        // The same rule as at start-up (exit 2 there): a spec without outputs would silently
        // stop every verdict and action.
        log::log(
            Level::Error,
            &format!(
                "reload: {} has no outputs, so it would check nothing and write nothing; \
                 the running spec stays in use (add `out NAME` for each stream to report)",
                src.describe()
            ),
        );
        return Reloaded::Refused;
    }
    let old = Arc::clone(proc.program());
    let changed = snapshot::changed_nodes(&old, &new);
    let old_keys = snapshot::node_keys(&old);
    let new_keys = snapshot::node_keys(&new);
    let result = proc.replace_program(Arc::clone(&new), |m| {
        let snap = snapshot::snapshot_with_keys(m, &old_keys);
        snapshot::restore_with_keys(Arc::clone(&new), &snap, &new_keys)
    });
    if let Err(e) = result {
        log::log(
            Level::Error,
            &format!(
                "reload: {}: {e}; the running spec stays in use",
                src.describe()
            ),
        );
        return Reloaded::Refused;
    }
    let mut reset_outputs: Vec<String> = new
        .outputs
        .iter()
        .zip(&new.output_nodes)
        .filter(|(_, n)| changed.binary_search(n).is_ok())
        .map(|(o, _)| o.name.clone())
        .collect();
    reset_outputs.dedup();
    let reset_internal = changed
        .iter()
        .filter(|n| !new.output_nodes.contains(n))
        .count();
    let instances = proc.instance_count();
    let kept = new.order.len().saturating_sub(changed.len());
    let msg = if changed.is_empty() {
        format!(
            "reload: spec reloaded for {instances} instances; nothing changed, every stream keeps its state"
        )
    } else {
        format!(
            "reload: spec reloaded for {instances} instances; {kept} streams keep their state; reset: {}{} internal streams",
            if reset_outputs.is_empty() {
                String::new()
            } else {
                format!("outputs {}, ", reset_outputs.join(", "))
            },
            reset_internal
        )
    };
    log::log(Level::Info, &msg);
    Reloaded::Replaced {
        reset_outputs,
        reset_internal,
    }
}
