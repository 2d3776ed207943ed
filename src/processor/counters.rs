//! The processor's counters (records, events, outputs, and each reason a record or value was not
//! evaluated), added up over `--threads` workers, and the summary line printed from them.

use super::Processor;

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Counters {
    pub records: u64,
    pub events: u64,
    pub outputs: u64,
    pub parse_errors: u64,
    pub late: u64,
    /// Records refused for a timestamp beyond `--max-ahead` of the wall clock.
    pub ahead: u64,
    pub dropped_values: u64,
    /// Monitor instances created.
    pub instances: u64,
    /// Monitor instances evicted (LRU or idle).
    pub evicted: u64,
    /// Exact repeats of a recent record, dropped ([`dedup`](super::dedup)).
    pub duplicates: u64,
    /// Instances switched to another spec version ([`versions`](super::versions)).
    pub switched: u64,
    /// Times a robot's record did not fit the version a rollout gave it, so it stayed on the
    /// last version it can run ([`Versions::target_fitting`](super::versions::Versions::target_fitting)).
    pub unfit: u64,
}

impl Counters {
    /// Add `other`'s counts (a `--threads` worker's, at the end of a run). Every field: the
    /// summary must not depend on the thread count.
    pub fn add(&mut self, other: &Counters) {
        let Counters {
            records,
            events,
            outputs,
            parse_errors,
            late,
            ahead,
            dropped_values,
            instances,
            evicted,
            duplicates,
            switched,
            unfit,
        } = other;
        self.records += records;
        self.events += events;
        self.outputs += outputs;
        self.parse_errors += parse_errors;
        self.late += late;
        self.ahead += ahead;
        self.dropped_values += dropped_values;
        self.instances += instances;
        self.evicted += evicted;
        self.duplicates += duplicates;
        self.switched += switched;
        self.unfit += unfit;
    }
}

impl Processor {
    /// The one-line summary printed at the end of a run.
    pub fn summary(&self) -> String {
        let c = &self.counters;
        let mut s = format!(
            "summary: {} records, {} events, {} outputs, {} parse errors, {} late records, {} ahead of the clock, {} dropped values, {} duplicates",
            c.records,
            c.events,
            c.outputs,
            c.parse_errors,
            c.late,
            c.ahead,
            c.dropped_values,
            c.duplicates
        );
        if !self.opts.instance_by.is_empty() {
            s.push_str(&format!(
                ", {} instances, {} evicted",
                c.instances, c.evicted
            ));
        }
        if c.switched > 0 {
            s.push_str(&format!(", {} switched spec version", c.switched));
        }
        if c.unfit > 0 {
            s.push_str(&format!(
                ", {} kept a version a rollout's could not read",
                c.unfit
            ));
        }
        s
    }
}
