//! Saved instances turned back into monitors, the same way for every backend and the same way
//! as a SIGHUP reload carries them: each instance continues in the program its key runs now
//! (`Processor::program_for` at its saved horizon, or clock for state without one: the version
//! it ran, whatever late records moved its clock past), every stream whose key the saved program had
//! keeps its value and armed timer, every other starts afresh.
//!
//! Owns: the running programs' node keys, computed once per program however many instances
//! are restored into it, and the line that says what a restore from another program reset
//! (once per pair of saved and running program, in the wording of `processor::carry`).

use super::entry::{SavedProgram, program_fingerprint};
use crate::processor::carry::Reset;
use crate::processor::instance_table::Key;
use crate::processor::{Continuity, Processor};
use std::collections::HashSet;
use std::sync::Arc;
use tessla_engine::snapshot::{self, Snapshot};
use tessla_engine::{Monitor, Program};

/// A running program instances are restored into.
struct Running {
    program: Arc<Program>,
    node_keys: Vec<u64>,
    fingerprint: String,
}

/// Restores saved instances into a processor's programs (one per backend, kept while it runs).
pub struct Restorer {
    /// Where the state comes from, for the log (the file, the bucket's URL).
    place: String,
    running: Vec<Running>,
    /// (saved program, running program) fingerprints whose difference was logged.
    reported: HashSet<(String, String)>,
}

impl Restorer {
    pub fn new(place: String) -> Restorer {
        Restorer {
            place,
            running: Vec::new(),
            reported: HashSet::new(),
        }
    }

    /// Instance `key`'s monitor, continued from `snap` (saved by a monitor of `saved`, with
    /// `c`: see `Processor::restore_instance_at`) in the program it runs in `proc`. The second
    /// value is the line to log (info) when `saved` is
    /// another program and this pair was not reported yet: what starts afresh.
    pub fn restore(
        &mut self,
        proc: &Processor,
        key: &Key,
        saved: &SavedProgram,
        snap: &Snapshot,
        c: &Continuity,
    ) -> (Monitor, Option<String>) {
        let clock = [snap.pending, snap.last_evaluated]
            .into_iter()
            .flatten()
            .fold(snap.t0, i64::max);
        let running = running_for(&mut self.running, proc.program_for_saved(key, c, clock));
        let monitor =
            snapshot::restore_with_keys(Arc::clone(&running.program), snap, &running.node_keys);
        let mut note = None;
        if saved.fingerprint != running.fingerprint {
            let pair = (saved.fingerprint.clone(), running.fingerprint.clone());
            if !self.reported.contains(&pair) {
                // Sorted as written; sorted again in case a file was edited by hand.
                let mut keys = saved.keys.clone();
                keys.sort_unstable();
                let reset = Reset::between(&keys, &running.program);
                note = Some(format!(
                    "state: {} holds state saved by another program (fingerprint {}, this run {}); restored by stream: {}",
                    self.place,
                    saved.fingerprint,
                    running.fingerprint,
                    reset.describe()
                ));
                self.reported.insert(pair);
            }
        }
        (monitor, note)
    }
}

/// `program`'s keys in `running`, computed when it is first met. Programs no processor holds
/// any more (replaced by a reload) are dropped first.
fn running_for<'a>(running: &'a mut Vec<Running>, program: &Arc<Program>) -> &'a Running {
    running.retain(|r| Arc::strong_count(&r.program) > 1);
    let i = match running
        .iter()
        .position(|r| Arc::ptr_eq(&r.program, program))
    {
        Some(i) => i,
        None => {
            running.push(Running {
                node_keys: snapshot::node_keys(program),
                fingerprint: program_fingerprint(program),
                program: Arc::clone(program),
            });
            running.len() - 1
        }
    };
    // In bounds: found there, or just pushed.
    &running[i]
}
