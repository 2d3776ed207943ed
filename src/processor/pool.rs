//! The processor's monitor instances: which instance a record belongs to (one, or one per value
//! of the `--instance-by` tags), creating it with the tags its output lines carry (the static
//! `--tag`s and its instance tags), and evicting past `--max-instances` (this thread's share)
//! or after `--instance-idle` (by its own silence only: at its next record, or by the wall
//! clock when the input is silent, never because of other instances' records). The step
//! watchdog learns each instance's name here. The table that holds them, and the keys, are
//! `instance_table.rs`'s.

use super::clock::Anchor;
use super::instance_table::{Key, Table, key_of};
use super::versions::Versions;
use super::{Counters, Options};
use crate::log;
use crate::telegraf::encode;
use crate::watchdog::Lane;
use lineproto::Metric;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tessla_engine::Monitor;

/// One monitor and the tags its output lines carry (static tags and instance tags).
pub(super) struct Instance {
    pub(super) monitor: Monitor,
    /// The spec version it runs (an index into `Versions`).
    pub(super) version: usize,
    /// When it last settled its version (`Processor::settle`): how many rules there were, and
    /// the next start of one that picks it (`i64::MAX`: none). Until the rules change or that
    /// start comes, its version stays.
    pub(super) settled: (usize, i64),
    /// The latest event time its version was settled for: its first step's time, then the
    /// largest time `Processor::settle` was asked for (a record's stamp, not the time a late
    /// record is stepped at). The rules at the horizon give its version; saved with it.
    pub(super) horizon: i64,
    /// Rules (by index) whose version this instance's records do not fit: it stays on the last
    /// version it can run ([`Versions::target_fitting`]). Saved with it.
    pub(super) unfit: Vec<usize>,
    pub(super) tags: Vec<(String, String)>,
    /// Its `tags` as its verdict lines carry them after the measurement (escaped once, and
    /// again when a tag is set: [`Instance::set_tag`]).
    pub(super) escaped_tags: String,
    /// Its key as the fleet level names it: the `--instance-by` values joined by `,`.
    pub(super) fleet_key: Arc<str>,
    pub(super) recent: super::dedup::Recent,
    /// Never reused: tells this instance's queued deadlines from a former occupant's of its slot.
    pub(super) id: u64,
    /// The instance's last record (or its restore): where its silent time is measured from.
    pub(super) anchor: Option<Anchor>,
    /// When its next `delay` firing falls due by the wall clock.
    pub(super) deadline: Option<Instant>,
    /// The deadline of its entry in the queue, if it has one.
    pub(super) queued: Option<Instant>,
}

/// The instances and the rules they live by.
pub(super) struct Pool {
    pub(super) table: Table<Instance>,
    /// `--instance-by`.
    pub(super) by: Vec<String>,
    /// `--tag`s.
    tags: Vec<(String, String)>,
    /// `--version-tag`.
    version_tag: Option<String>,
    /// `--instance-idle`.
    idle: Option<Duration>,
    /// `--max-instances`: the most kept over all threads.
    pub(super) total: usize,
    /// Most instances kept here: the total, or this thread's share of it.
    pub(super) keep: usize,
    /// The slot of the only instance, when there is one that is never evicted.
    single: Option<usize>,
    /// Stands in for "now" when no idle limit needs the clock.
    epoch: Instant,
    next_id: u64,
    /// With `--fleet-spec`: the fleet keys of the instances evicted since the last drain.
    pub(super) left: Option<Vec<Arc<str>>>,
}

impl Pool {
    pub(super) fn new(opts: &Options) -> Pool {
        Pool {
            table: Table::default(),
            by: opts.instance_by.clone(),
            tags: opts.tags.clone(),
            version_tag: opts.version_tag.clone(),
            idle: opts.instance_idle,
            total: opts.max_instances,
            keep: opts.max_instances.max(1),
            single: None,
            epoch: Instant::now(),
            next_id: 0,
            left: None,
        }
    }

    /// The time instances are used at: the wall clock `wall` with `--instance-idle`, a
    /// constant without.
    #[inline]
    pub(super) fn now(&self, wall: Instant) -> Instant {
        if self.idle.is_some() {
            wall
        } else {
            self.epoch
        }
    }

    /// With `--instance-idle`: whether instance `slot` was idle past the limit at `at`.
    pub(super) fn idle_at(&self, slot: usize, at: Instant) -> bool {
        self.idle.is_some_and(|d| self.table.idle_at(slot, d, at))
    }

    /// With `--instance-idle`: when the least recently used instance falls idle past the limit
    /// (the wall clock evicts it then, [`Pool::evict_idle`]).
    pub(super) fn idle_due(&self) -> Option<Instant> {
        let d = self.idle?;
        let last = self.table.oldest_use()?;
        Some(last + d + Duration::from_nanos(1))
    }

    /// Name every instance in `lane` (the watchdog's, set after instances were restored).
    pub(super) fn name_all(&self, lane: &Lane) {
        if self.by.is_empty() {
            return;
        }
        for (key, &slot) in self.table.keys() {
            lane.name(slot, describe(&self.by, key));
        }
    }

    /// The instance for `m`, created (starting at `ts`) when new.
    #[inline]
    pub(super) fn slot_for(
        &mut self,
        m: &Metric,
        ts: i64,
        now: Instant,
        versions: &Versions,
        counters: &mut Counters,
        lane: Option<&Lane>,
    ) -> usize {
        // One instance that is never evicted: skip the lookup.
        if let Some(i) = self.single {
            return i;
        }
        let key = key_of(&self.by, m);
        // Its own silence past `--instance-idle` evicted it: it starts afresh.
        if let Some(d) = self.idle
            && let Some(i) = self.table.idle_slot(&key, d, now)
        {
            self.evict_slot(i, false, counters, lane);
        }
        if let Some(i) = self.table.find(&key, now) {
            return i;
        }
        counters.instances += 1;
        let mut unfit = Vec::new();
        let v = if versions.has_rules() {
            let by = &self.by;
            // A new instance would otherwise start in the base version.
            versions.target_fitting(&key, ts, (m, 0), &mut unfit, |rule, why| {
                counters.unfit += 1;
                warn_unfit(by, &key, versions, rule, &why);
            })
        } else {
            0
        };
        let version = versions.get(v);
        let monitor = Monitor::starting_at(Arc::clone(&version.program), ts);
        let slot = self.insert(key, monitor, (v, &version.id), now, lane);
        if !unfit.is_empty()
            && let Some(inst) = self.table.get_mut(slot)
        {
            inst.unfit = unfit;
        }
        slot
    }

    /// Add instance `key` (absent from the table) running `monitor`; returns its slot.
    pub(super) fn insert(
        &mut self,
        key: Key,
        monitor: Monitor,
        (version, id): (usize, &str),
        now: Instant,
        lane: Option<&Lane>,
    ) -> usize {
        let mut tags: Vec<(String, String)> = self
            .tags
            .iter()
            .filter(|(k, _)| !self.by.contains(k))
            .cloned()
            .collect();
        for (k, v) in self.by.iter().zip(&key) {
            if let Some(v) = v {
                tags.push((k.clone(), v.clone()));
            }
        }
        if let Some(t) = &self.version_tag {
            tags.retain(|(k, _)| k != t);
            tags.push((t.clone(), id.to_string()));
        }
        if !self.by.is_empty() || self.version_tag.is_some() {
            tags.sort();
        }
        self.next_id += 1;
        let horizon = monitor.clock();
        let fleet_key = fleet_key(&key);
        let mut escaped_tags = String::new();
        encode::escape_tags(&mut escaped_tags, &tags);
        let i = self.table.insert(
            key,
            Instance {
                monitor,
                version,
                // Never settled: the first step with rules looks.
                settled: (usize::MAX, i64::MIN),
                unfit: Vec::new(),
                horizon,
                tags,
                escaped_tags,
                fleet_key,
                recent: Default::default(),
                id: self.next_id,
                anchor: None,
                deadline: None,
                queued: None,
            },
            now,
        );
        if self.by.is_empty() && self.idle.is_none() {
            self.single = Some(i);
        }
        if let Some(l) = lane
            && let Some(key) = self.table.key(i)
            && !self.by.is_empty()
        {
            l.name(i, describe(&self.by, key));
        }
        i
    }

    /// Evict instances past `--max-instances` (least recently used first). Nothing is pending
    /// in an instance between records (each record is evaluated at once); its armed `delay`s
    /// are dropped with it (their queue entries go stale).
    #[inline]
    pub(super) fn evict(&mut self, now: Instant, counters: &mut Counters, lane: Option<&Lane>) {
        // Most records: below the limit, nothing to look at.
        if self.table.len() <= self.keep {
            return;
        }
        self.evict_some(now, None, counters, lane);
    }

    /// Evict instances past `--max-instances`, and those idle past `--instance-idle` at `now`
    /// (the wall clock, while the input is silent).
    pub(super) fn evict_idle(
        &mut self,
        now: Instant,
        counters: &mut Counters,
        lane: Option<&Lane>,
    ) {
        if self.idle.is_none() && self.table.len() <= self.keep {
            return;
        }
        self.evict_some(now, self.idle, counters, lane);
    }

    #[inline(never)]
    fn evict_some(
        &mut self,
        now: Instant,
        idle: Option<Duration>,
        counters: &mut Counters,
        lane: Option<&Lane>,
    ) {
        while let Some(i) = self.table.evictable(self.keep, idle, now) {
            let full = self.table.len() > self.keep;
            if !self.evict_slot(i, full, counters, lane) {
                break;
            }
        }
    }

    /// Evict instance `slot` (`full`: for `--max-instances`, else for idleness), counted and
    /// warned about; false when the slot is empty.
    pub(super) fn evict_slot(
        &mut self,
        slot: usize,
        full: bool,
        counters: &mut Counters,
        lane: Option<&Lane>,
    ) -> bool {
        let (max, total) = (self.keep, self.total);
        let Some((key, inst)) = self.table.remove(slot) else {
            return false;
        };
        if let Some(left) = &mut self.left {
            left.push(inst.fleet_key);
        }
        if let Some(l) = lane {
            l.forget(slot);
        }
        counters.evicted += 1;
        let by = &self.by;
        log::warn_limited("instance evicted", || {
            let why = if full {
                format!("least recently used, --max-instances {total}")
            } else {
                "idle longer than --instance-idle".to_string()
            };
            let share = if full && max != total {
                format!(" (the threads share the total: this one keeps {max})")
            } else {
                String::new()
            };
            format!(
                "monitor instance {} evicted ({why}); its state starts afresh with its next record{share}",
                describe(by, &key)
            )
        });
        true
    }
}

/// The error of a robot whose record does not fit the version a rollout gives it (rate-limited):
/// it stays on the last version it can run.
pub(super) fn warn_unfit(by: &[String], key: &Key, versions: &Versions, rule: usize, why: &str) {
    log::error_limited("unfit version", || {
        let (id, from) = versions.rule_id(rule).unwrap_or_default();
        format!(
            "spec version {id} (in force from {}) cannot read the records of monitor instance {}: {why}; it stays on the last version it can run (counted as `unfit` in the summary)",
            super::clock::show_time(from),
            describe(by, key)
        )
    });
}

impl Instance {
    /// Set its tag `name` to `value` ([`set_tag`]), its escaped tags with it.
    pub(super) fn set_tag(&mut self, name: &str, value: &str) {
        set_tag(&mut self.tags, name, value);
        encode::escape_tags(&mut self.escaped_tags, &self.tags);
    }
}

/// Set tag `name` to `value` in `tags` (sorted by name, as [`Pool::insert`] makes them).
pub(super) fn set_tag(tags: &mut Vec<(String, String)>, name: &str, value: &str) {
    match tags.binary_search_by(|(k, _)| k.as_str().cmp(name)) {
        Ok(i) => {
            if let Some(t) = tags.get_mut(i) {
                t.1 = value.to_string();
            }
        }
        Err(i) => tags.insert(i, (name.to_string(), value.to_string())),
    }
}

/// The fleet level's name for instance `key`: its `--instance-by` values joined by `,` (an
/// absent tag as the empty string).
pub(super) fn fleet_key(key: &Key) -> Arc<str> {
    let parts: Vec<&str> = key.iter().map(|v| v.as_deref().unwrap_or("")).collect();
    Arc::from(parts.join(","))
}

pub(super) fn describe(instance_by: &[String], key: &Key) -> String {
    instance_by
        .iter()
        .zip(key)
        .map(|(k, v)| format!("{k}={}", v.as_deref().unwrap_or("(absent)")))
        .collect::<Vec<_>>()
        .join(",")
}

/// " (instance robot=a)" for the instance of `m`; without `--instance-by` (one instance), the
/// record's measurement and tags, which name the robot (" (mqtt_consumer,host=tb3,topic=tessla)"),
/// cut at [`NOTE_MAX`] bytes with the full size said. Built only inside a warning's closure: a
/// rate-limited warning costs no allocation.
pub(super) fn instance_note(instance_by: &[String], m: &Metric) -> String {
    let what = if instance_by.is_empty() {
        let mut s = m.measurement.clone();
        for (k, v) in &m.tags {
            s.push(',');
            s.push_str(k);
            s.push('=');
            s.push_str(v);
        }
        s
    } else {
        format!(
            "instance {}",
            describe(instance_by, &key_of(instance_by, m))
        )
    };
    format!(" ({})", crate::log::cut(&what, NOTE_MAX))
}

/// Longest instance or tag description in a warning.
const NOTE_MAX: usize = 200;
