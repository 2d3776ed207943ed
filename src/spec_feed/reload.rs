//! SIGHUP: reload the spec file (and its includes) without losing the monitors' state.
//!
//! Owns: where the spec comes from ([`SpecSource`]: a file, or the bundled robot monitors, which
//! never change while running, so their reload keeps everything) and the reload itself: a spec
//! that fails to check is reported with its full diagnostic and the running one stays; a good
//! one replaces it for every instance, each stream whose key (see
//! `tessla_engine::snapshot`) is unchanged keeping its state, and the streams that start
//! afresh are logged.

use super::bundle::Bundle;
use crate::processor::Processor;
use crate::processor::carry::{self, Reset};
use crate::processor::versions::{self, Version};
use std::path::PathBuf;
use std::sync::Arc;
use tessla_engine::snapshot;
use tessla_engine::{LoadError, LoadOptions, Loaded};

/// The spec `run` loads at start and on every SIGHUP.
#[derive(Debug, Clone)]
pub struct SpecSource {
    /// `--spec`; `None`: the bundled robot monitors.
    pub path: Option<PathBuf>,
    pub options: LoadOptions,
}

impl SpecSource {
    /// Load the spec: the compiled program and the bundle it was read from (its id names the
    /// version).
    pub fn load(&self) -> Result<(Loaded, Bundle), LoadError> {
        let (bundle, loaded) = match &self.path {
            Some(p) => Bundle::read(p, &self.options)?,
            None => Bundle::record(
                crate::bundled::DEFAULT,
                &crate::bundled::resolver(),
                &self.options,
            )?,
        };
        Ok((loaded, bundle))
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
    /// The new spec did not check (or bind); the old one keeps running. Why (the diagnostic).
    Refused(String),
    /// Replaced: the names of the outputs whose streams start afresh, and how many internal
    /// streams do.
    Replaced {
        id: String,
        reset_outputs: Vec<String>,
        reset_internal: usize,
    },
}

/// Reload `src` into every processor of the run (`procs`: one per thread; every record before
/// it was evaluated with the old spec, so no step is open). `why` says what asked for it
/// (`SIGHUP`, `spec file changed`). Its bindings are checked against `samples` (every
/// thread's, as a rollout's are): an input that cannot read the metrics the process receives
/// refuses it. Logs the outcome once.
pub fn reload(
    src: &SpecSource,
    why: &str,
    procs: &mut [&mut Processor],
    samples: &[lineproto::Metric],
) -> Reloaded {
    log_info!("{why}: reloading {}", src.describe());
    let (loaded, bundle) = match src.load() {
        Ok(l) => l,
        Err(e) => {
            let diag = e.render();
            log_error!(
                "reload: {} has errors; the running spec stays in use\n{diag}",
                src.describe()
            );
            return Reloaded::Refused(diag);
        }
    };
    if !loaded.warnings.is_empty() {
        log_warn!(
            "{}",
            tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, false)
        );
    }
    let new = loaded.program;
    if new.outputs.is_empty() {
        // The same rule as at start-up (exit 2 there): a spec without outputs would silently
        // stop every verdict and action.
        let why = "it has no outputs, so it would check nothing and write nothing (add `out NAME` for each stream to report)";
        log_error!(
            "reload: {}: {why}; the running spec stays in use",
            src.describe()
        );
        return Reloaded::Refused(why.to_string());
    }
    let Some(first) = procs.first() else {
        return Reloaded::Refused("no processor".into());
    };
    let checked = Version::new(String::new(), String::new(), Arc::clone(&new), "tessla")
        .map_err(|e| e.to_string())
        .and_then(|v| versions::check_against(&v, samples).map_err(|e| e.to_string()));
    if let Err(e) = checked {
        log_error!(
            "reload: {}: {e}; the running spec stays in use",
            src.describe()
        );
        return Reloaded::Refused(e);
    }
    let old = Arc::clone(first.program());
    let old_keys = snapshot::node_keys(&old);
    let new_keys = snapshot::node_keys(&new);
    let reset = Reset::between(&carry::stream_keys(&old, &old_keys), &new);
    let id = bundle.id();
    let mut instances = 0;
    for proc in procs.iter_mut() {
        let result = proc.replace_program(Arc::clone(&new), &id, |m| {
            let snap = snapshot::snapshot_with_keys(m, &old_keys);
            snapshot::restore_with_keys(Arc::clone(&new), &snap, &new_keys)
        });
        if let Err(e) = result {
            // The same for every processor: the first refuses before any changed.
            log_error!(
                "reload: {}: {e}; the running spec stays in use",
                src.describe()
            );
            return Reloaded::Refused(e.to_string());
        }
        instances += proc.instance_count();
    }
    log_info!(
        "reload: spec version {id} for {instances} instances; {}",
        reset.describe()
    );
    let Reset {
        outputs: reset_outputs,
        internal: reset_internal,
        ..
    } = reset;
    Reloaded::Replaced {
        id,
        reset_outputs,
        reset_internal,
    }
}
