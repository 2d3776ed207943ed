//! What a monitor keeps when it continues in another program: a SIGHUP reload, a rollout's
//! switch, and saved state restored into an edited spec all carry state by stream key
//! (`tessla_engine::snapshot`), and this module is the one place that says which
//! streams start afresh and how that is worded in the log.
//!
//! Owns: the keys a program's state is known by ([`stream_keys`]: one per evaluated stream),
//! the streams of a new program that an old program's keys do not cover ([`Reset`]: the reset
//! outputs by name, the count of reset internal streams, the count kept), and its wording
//! ([`Reset::describe`]: `reset: outputs a, b, N internal streams` or `every stream keeps its
//! state`).

use tessla_engine::Program;
use tessla_engine::snapshot;

/// The keys of every evaluated stream of `program` (its evaluation order), sorted, without
/// repeats: what saved state records of the program it was saved by. `node_keys` is
/// `snapshot::node_keys(program)` (callers with many instances have it already).
pub fn stream_keys(program: &Program, node_keys: &[u64]) -> Vec<u64> {
    let mut keys: Vec<u64> = program
        .order
        .iter()
        .filter_map(|&n| node_keys.get(n).copied())
        .collect();
    keys.sort_unstable();
    keys.dedup();
    keys
}

/// What continuing a monitor of an old program in `new` starts afresh: every evaluated stream
/// of `new` whose key the old program does not have.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reset {
    /// The outputs whose stream starts afresh, each once, in the spec's order.
    pub outputs: Vec<String>,
    /// How many streams that are not outputs start afresh.
    pub internal: usize,
    /// How many streams keep their state.
    pub kept: usize,
}

impl Reset {
    /// From the old program's [`stream_keys`] (sorted) to `new`.
    pub fn between(old_keys: &[u64], new: &Program) -> Reset {
        let keys = snapshot::node_keys(new);
        let mut changed: Vec<usize> = new
            .order
            .iter()
            .copied()
            .filter(|&n| {
                keys.get(n)
                    .is_some_and(|k| old_keys.binary_search(k).is_err())
            })
            .collect();
        changed.sort_unstable();
        let mut outputs: Vec<String> = Vec::new();
        for (o, n) in new.outputs.iter().zip(&new.output_nodes) {
            if changed.binary_search(n).is_ok() && !outputs.contains(&o.name) {
                outputs.push(o.name.clone());
            }
        }
        let internal = changed
            .iter()
            .filter(|n| !new.output_nodes.contains(n))
            .count();
        Reset {
            outputs,
            internal,
            kept: new.order.len().saturating_sub(changed.len()),
        }
    }

    /// From program `old` to `new`.
    pub fn of(old: &Program, new: &Program) -> Reset {
        Reset::between(&stream_keys(old, &snapshot::node_keys(old)), new)
    }

    /// Whether every stream keeps its state.
    pub fn is_empty(&self) -> bool {
        self.outputs.is_empty() && self.internal == 0
    }

    /// The log's wording: `nothing changed, every stream keeps its state`, or `40 streams keep
    /// their state; reset: outputs a, b, 1 internal streams`.
    pub fn describe(&self) -> String {
        if self.is_empty() {
            return "nothing changed, every stream keeps its state".to_string();
        }
        format!(
            "{} streams keep their state; reset: {}{} internal streams",
            self.kept,
            if self.outputs.is_empty() {
                String::new()
            } else {
                format!("outputs {}, ", self.outputs.join(", "))
            },
            self.internal
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::processor::tests::program;

    const OLD: &str = "in x: Events[Int]\ndef c = count(x)\ndef s = x + 1\nout c\nout s\n";

    #[test]
    fn the_streams_whose_key_the_old_program_lacks_are_reset_and_named() {
        let old = program(OLD);
        let same = Reset::of(&old, &program(OLD));
        assert!(same.is_empty());
        assert_eq!(
            same.describe(),
            "nothing changed, every stream keeps its state"
        );
        // `s` changes what it computes (a new constant node and the product): both reset.
        let new = program("in x: Events[Int]\ndef c = count(x)\ndef s = x * 10\nout c\nout s\n");
        let r = Reset::of(&old, &new);
        assert_eq!(r.outputs, ["s"]);
        assert_eq!(r.kept + r.internal + 1, new.order.len());
        assert_eq!(
            r.describe(),
            format!(
                "{} streams keep their state; reset: outputs s, {} internal streams",
                r.kept, r.internal
            )
        );
        // The keys of the old program are all it takes.
        let keys = stream_keys(&old, &snapshot::node_keys(&old));
        assert!(keys.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(Reset::between(&keys, &new), r);
        // No keys at all: everything starts afresh.
        let all = Reset::between(&[], &new);
        assert_eq!(all.outputs, ["c", "s"]);
        assert_eq!(all.kept, 0);
    }
}
