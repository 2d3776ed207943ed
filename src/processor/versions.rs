//! Spec versions in force at once in one processor, and which one each instance runs.
//!
//! Owns: the [`Selector`] of a rollout (which instances, by their `--instance-by` tags), the
//! table of versions (the spec the process started with, then each accepted one) and the rules
//! that map (instance, event time) to a version: the newest accepted rollout whose selector
//! picks the instance and whose start is at or before the time, else the spec the process
//! started with.

use super::instance_table::Key;
use crate::telegraf::binding::{self, BindingError, FieldPattern, InputBinding, TimeBinding};
use crate::telegraf::encode;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::sync::Arc;
use tessla_engine::snapshot;
use tessla_engine::{Monitor, Program};

/// One spec version a processor can run: its program and what reading metrics into it and
/// writing its outputs needs.
pub struct Version {
    /// Its identity (`Bundle::id`), the value of the version tag.
    pub id: String,
    /// The operator's label, if any.
    pub label: String,
    pub program: Arc<Program>,
    /// Every node's stable key (`snapshot::node_keys`): a switch carries state by them.
    pub(super) keys: Vec<u64>,
    pub(super) bindings: Vec<InputBinding>,
    /// Its `@TelegrafTime` inputs: the record's own time at each step a record makes.
    pub(super) times: Vec<TimeBinding>,
    /// How its outputs are written, prepared once: only its own instances' lines use it.
    pub(super) encodings: encode::Prepared,
}

impl Version {
    /// Fails when an input annotation is malformed. `measurement`: `--measurement`, where
    /// outputs without an annotation go.
    pub fn new(
        id: String,
        label: String,
        program: Arc<Program>,
        measurement: &str,
    ) -> Result<Version, BindingError> {
        Ok(Version {
            keys: snapshot::node_keys(&program),
            bindings: binding::bindings(&program)?,
            times: binding::time_bindings(&program)?,
            encodings: encode::Prepared::new(encode::encodings(&program), measurement),
            id,
            label,
            program,
        })
    }

    /// The outputs whose streams start afresh when an instance of `from` continues in this
    /// version (each output once, in the spec's order).
    pub fn reset_from(&self, from: &Version) -> Vec<String> {
        let old = super::carry::stream_keys(&from.program, &from.keys);
        super::carry::Reset::between(&old, &self.program).outputs
    }

    /// `monitor` (of another version) continued in this one: each stream whose key is
    /// unchanged keeps its state, every other starts afresh (as a SIGHUP reload).
    pub(super) fn carry(&self, from: &Version, monitor: &Monitor) -> Monitor {
        let snap = snapshot::snapshot_with_keys(monitor, &from.keys);
        snapshot::restore_with_keys(Arc::clone(&self.program), &snap, &self.keys)
    }
}

/// Why a version does not fit the metrics this process has seen ([`check_against`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Unfit {
    /// An input whose field the metrics carry but never convert to its type.
    #[error("input `{input}` cannot read the metrics this process receives: {reason}")]
    Unreadable { input: String, reason: String },
    /// No input of the version is fed (the measurements seen, comma-separated).
    #[error(
        "none of its inputs is fed by the metrics this process receives (measurements {measurements}); check their @TelegrafIn annotations"
    )]
    Unfed { measurements: String },
}

/// A metric that a version cannot read ([`fits`]): the input and why its field does not convert.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("input `{input}`: {reason}")]
pub struct Misfit {
    /// The input's name.
    pub input: String,
    /// Why the field does not convert.
    pub reason: String,
}

/// A selector that does not parse: the clause and what it lacks.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SelectorError {
    /// A clause without `=`.
    #[error("`{0}` is not TAG=VALUE[,VALUE...] (for example robot=r1,r2)")]
    NotPair(String),
    /// A clause with an empty tag or no value.
    #[error("`{0}` needs a tag and at least one value (for example robot=r1,r2)")]
    Empty(String),
}

/// Check `v`'s bindings against metrics this process has seen (none seen: nothing to check).
/// Refused: an input whose field the metrics carry but never converts to its type, or a
/// version none of whose inputs any of them feeds.
pub fn check_against(v: &Version, samples: &[lineproto::Metric]) -> Result<(), Unfit> {
    if samples.is_empty() || v.bindings.is_empty() {
        return Ok(());
    }
    let mut fed = false;
    for b in &v.bindings {
        let mut converted = false;
        let mut failure = None;
        for m in samples.iter().filter(|m| b.matches(m)) {
            match b.extract(m) {
                Some(Ok(_)) => converted = true,
                Some(Err(e)) => failure = failure.or(Some(e.reason)),
                None => {}
            }
        }
        fed |= converted;
        if let (false, Some(reason)) = (converted, failure) {
            return Err(Unfit::Unreadable {
                input: b.name.clone(),
                reason,
            });
        }
    }
    if !fed {
        let seen: Vec<&str> = samples.iter().map(|m| m.measurement.as_str()).collect();
        return Err(Unfit::Unfed {
            measurements: seen.join(", "),
        });
    }
    Ok(())
}

/// Whether version `v` can read `m`: `Err` names an input whose field `m` carries but does not
/// convert to the input's type (a metric that feeds none of its inputs fits: nothing in it
/// contradicts the version).
pub fn fits(v: &Version, m: &lineproto::Metric) -> Result<(), Misfit> {
    for b in v.bindings.iter().filter(|b| b.matches(m)) {
        if let Some(Err(e)) = b.extract(m) {
            return Err(Misfit {
                input: b.name.clone(),
                reason: e.reason,
            });
        }
    }
    Ok(())
}

/// From event time `from` on, the instances `selector` picks run version `version` (an index
/// into the versions of [`Versions`]).
#[derive(Clone)]
pub struct Rule {
    pub version: usize,
    pub from: i64,
    pub selector: Selector,
}

/// The versions a processor holds and the rules choosing between them. Version 0 is the spec
/// the process runs without rules (its `--spec`; a SIGHUP replaces it).
pub struct Versions {
    pub(super) list: Vec<Version>,
    /// In the order accepted: a later rule wins over an earlier one.
    pub(super) rules: Vec<Rule>,
    /// `--instance-by`: what selectors name.
    by: Vec<String>,
}

impl Versions {
    pub fn new(base: Version, by: Vec<String>) -> Versions {
        Versions {
            list: vec![base],
            rules: Vec::new(),
            by,
        }
    }

    /// The version without rules.
    pub fn base(&self) -> &Version {
        // `list` is never empty: `new` puts the base in and nothing removes it.
        &self.list[0]
    }

    pub fn get(&self, v: usize) -> &Version {
        self.list.get(v).unwrap_or_else(|| self.base())
    }

    /// The one list pattern (`lidar_` of `lidar_*`) whose elements the parser may read straight
    /// into an array instead of into the metric's fields ([`lineproto::ListCapture`]): the only
    /// indexed pattern of every version held, when no exact field of any version starts with it
    /// (that field would not be found among the fields). `None`: the parser captures nothing.
    pub fn list_to_capture(&self) -> Option<String> {
        let bindings = || self.list.iter().flat_map(|v| &v.bindings);
        let mut prefix: Option<&str> = None;
        for b in bindings() {
            if let FieldPattern::Indexed(p) = &b.field {
                match prefix {
                    Some(q) if q != p => return None,
                    _ => prefix = Some(p),
                }
            }
        }
        let p = prefix.filter(|p| !p.is_empty())?;
        bindings()
            .all(|b| match &b.field {
                FieldPattern::Exact(f) => !f.starts_with(p),
                FieldPattern::Indexed(_) => true,
            })
            .then(|| p.to_string())
    }

    /// The same versions and rules, built again (a `--threads` worker's own).
    pub fn duplicate(&self) -> Result<Versions, BindingError> {
        let list = self
            .list
            .iter()
            .map(|v| {
                let m = v.encodings.default_measurement();
                Version::new(v.id.clone(), v.label.clone(), Arc::clone(&v.program), m)
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Versions {
            list,
            rules: self.rules.clone(),
            by: self.by.clone(),
        })
    }

    /// The index of the version with `id`, if held.
    pub fn find(&self, id: &str) -> Option<usize> {
        self.list.iter().position(|v| v.id == id)
    }

    /// Whether any rule exists (without one, every instance runs the base: nothing to check
    /// per record).
    #[inline]
    pub fn has_rules(&self) -> bool {
        !self.rules.is_empty()
    }

    /// The version instance `key` runs at event time `t`.
    pub fn target(&self, key: &Key, t: i64) -> usize {
        self.target_skipping(key, t, &[]).0
    }

    /// [`Versions::target`] passing over the rules (by index) in `unfit`, whose versions the
    /// instance's records do not fit: the version and the rule that gives it (`None`: the
    /// base).
    pub fn target_skipping(&self, key: &Key, t: i64, unfit: &[usize]) -> (usize, Option<usize>) {
        self.rules
            .iter()
            .enumerate()
            .rev()
            .find(|(i, r)| r.from <= t && !unfit.contains(i) && r.selector.matches(&self.by, key))
            .map_or((0, None), |(i, r)| (r.version, Some(i)))
    }

    /// The version instance `key` (running `current`) runs at `t`, passing over the rules in
    /// `unfit` and those whose version record `m` does not fit ([`fits`]) while `current`
    /// reads it (a record no version reads, a bad value, says nothing about the new one): each
    /// of those is added to `unfit` and handed to `refused` with why. Robots stay on the last
    /// version they can run.
    pub fn target_fitting(
        &self,
        key: &Key,
        t: i64,
        (m, current): (&lineproto::Metric, usize),
        unfit: &mut Vec<usize>,
        mut refused: impl FnMut(usize, String),
    ) -> usize {
        loop {
            let (v, rule) = self.target_skipping(key, t, unfit);
            let Some(rule) = rule else { return v };
            if v == current {
                return v;
            }
            match fits(self.get(v), m) {
                Err(why) if fits(self.get(current), m).is_ok() => {
                    unfit.push(rule);
                    refused(rule, why.to_string());
                }
                _ => return v,
            }
        }
    }

    /// A rule's identity across processes and restarts: its version's id and its start.
    pub fn rule_id(&self, rule: usize) -> Option<(String, i64)> {
        let r = self.rules.get(rule)?;
        Some((self.get(r.version).id.clone(), r.from))
    }

    /// The index of the rule with identity `id` ([`Versions::rule_id`]), if held.
    pub fn rule_of(&self, id: &(String, i64)) -> Option<usize> {
        (0..self.rules.len()).find(|&i| self.rule_id(i).as_ref() == Some(id))
    }

    /// The first time in `(after, upto]` at which a rule picking `key` starts, if any: where
    /// an instance moving from `after` to `upto` may have to switch.
    pub fn next_start(&self, key: &Key, after: i64, upto: i64) -> Option<i64> {
        self.rules
            .iter()
            .filter(|r| r.from > after && r.from <= upto && r.selector.matches(&self.by, key))
            .map(|r| r.from)
            .min()
    }

    /// The outputs that start afresh in the instances `selector` picks when they switch to
    /// version `new` at `from` (a rule not accepted yet): those whose definition differs between
    /// the version such an instance runs just before `from` and `new`, each once, in `new`'s
    /// order. Exact whatever instances are live: it looks at representative keys (see
    /// `Versions::representatives`); when there would be too many of them, at every version
    /// some instance could run before.
    pub fn reset_for(&self, new: usize, from: i64, selector: &Selector) -> Vec<String> {
        let before = from.saturating_sub(1);
        let mut olds: Vec<usize> = match self.representatives(selector) {
            Some(keys) => keys
                .iter()
                .filter(|k| selector.matches(&self.by, k))
                .map(|k| self.target(k, before))
                .collect(),
            None => std::iter::once(0)
                .chain(self.rules.iter().map(|r| r.version))
                .collect(),
        };
        olds.sort_unstable();
        olds.dedup();
        let new_version = self.get(new);
        let mut reset = std::collections::HashSet::new();
        for old in olds.into_iter().filter(|&o| o != new) {
            reset.extend(new_version.reset_from(self.get(old)));
        }
        new_version
            .program
            .outputs
            .iter()
            .map(|o| &o.name)
            .filter(|n| reset.remove(*n))
            .cloned()
            .collect()
    }

    /// Keys standing for every instance `selector` may pick, as far as the rules tell them
    /// apart: per `--instance-by` tag, the values `selector` names for it, or, when it names
    /// none, each value a rule's selector names for it, one value none names, and the tag
    /// absent. `None`: more than [`REPRESENTATIVES`] of them.
    fn representatives(&self, selector: &Selector) -> Option<Vec<Key>> {
        let mut keys: Vec<Key> = vec![Vec::new()];
        for tag in &self.by {
            let named = |s: &Selector| -> Vec<String> {
                s.clauses()
                    .iter()
                    .filter(|(t, _)| t == tag)
                    .flat_map(|(_, vs)| vs.iter().cloned())
                    .collect()
            };
            let mut values: Vec<Option<String>> = named(selector).into_iter().map(Some).collect();
            if values.is_empty() {
                let mut all: Vec<String> =
                    self.rules.iter().flat_map(|r| named(&r.selector)).collect();
                all.sort_unstable();
                all.dedup();
                let mut other = String::from("~");
                while all.contains(&other) {
                    other.push('~');
                }
                values = all.into_iter().map(Some).collect();
                values.push(Some(other));
                values.push(None);
            }
            values.sort_unstable();
            values.dedup();
            if keys.len().saturating_mul(values.len()) > REPRESENTATIVES {
                return None;
            }
            keys = keys
                .iter()
                .flat_map(|k| {
                    values.iter().map(move |v| {
                        let mut k = k.clone();
                        k.push(v.clone());
                        k
                    })
                })
                .collect();
        }
        Some(keys)
    }

    /// Whether any version holds a `delay`.
    pub fn has_delays(&self) -> bool {
        self.list.iter().any(|v| !v.program.delays.is_empty())
    }
}

/// Most representative keys [`Versions::reset_for`] looks at (a few per rollout in practice).
const REPRESENTATIVES: usize = 4096;

/// Which instances a rollout is for: `TAG=V1,V2[;TAG=V3...]` (every clause must hold); empty:
/// every instance.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Selector {
    clauses: Vec<(String, Vec<String>)>,
}

impl Selector {
    /// Every instance.
    pub fn all() -> Selector {
        Selector::default()
    }

    /// Its clauses: a tag and the values it accepts (every clause must hold).
    pub fn clauses(&self) -> &[(String, Vec<String>)] {
        &self.clauses
    }

    pub fn is_all(&self) -> bool {
        self.clauses.is_empty()
    }

    pub fn parse(s: &str) -> Result<Selector, SelectorError> {
        let mut clauses = Vec::new();
        for clause in s.split(';').map(str::trim).filter(|c| !c.is_empty()) {
            let (tag, values) = clause
                .split_once('=')
                .ok_or_else(|| SelectorError::NotPair(clause.to_string()))?;
            let tag = tag.trim();
            let values: Vec<String> = values
                .split(',')
                .map(|v| v.trim().to_string())
                .filter(|v| !v.is_empty())
                .collect();
            if tag.is_empty() || values.is_empty() {
                return Err(SelectorError::Empty(clause.to_string()));
            }
            clauses.push((tag.to_string(), values));
        }
        Ok(Selector { clauses })
    }

    /// The tags it names that are not in `by` (`--instance-by`): such a selector can pick no
    /// instance by them.
    pub fn unknown_tags<'a>(&'a self, by: &[String]) -> Vec<&'a str> {
        self.clauses
            .iter()
            .map(|(t, _)| t.as_str())
            .filter(|t| !by.iter().any(|b| b == t))
            .collect()
    }

    /// Whether the instance with `key` (tag values in `by` order) is picked.
    pub fn matches(&self, by: &[String], key: &Key) -> bool {
        self.clauses.iter().all(|(tag, values)| {
            by.iter()
                .position(|b| b == tag)
                .and_then(|i| key.get(i))
                .and_then(|v| v.as_deref())
                .is_some_and(|v| values.iter().any(|x| x == v))
        })
    }
}

impl fmt::Display for Selector {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let parts: Vec<String> = self
            .clauses
            .iter()
            .map(|(t, v)| format!("{t}={}", v.join(",")))
            .collect();
        f.write_str(&parts.join(";"))
    }
}

impl TryFrom<String> for Selector {
    type Error = SelectorError;
    fn try_from(s: String) -> Result<Selector, SelectorError> {
        Selector::parse(&s)
    }
}

impl From<Selector> for String {
    fn from(s: Selector) -> String {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_selector_picks_instances_by_their_tags() {
        let by = vec!["robot".to_string(), "site".to_string()];
        let s = Selector::parse("robot=r1, r2; site=lab").unwrap();
        assert_eq!(s.to_string(), "robot=r1,r2;site=lab");
        let key = |r: &str, site: Option<&str>| vec![Some(r.to_string()), site.map(String::from)];
        assert!(s.matches(&by, &key("r2", Some("lab"))));
        assert!(!s.matches(&by, &key("r3", Some("lab"))));
        assert!(!s.matches(&by, &key("r1", None)));
        assert!(Selector::parse("").unwrap().matches(&by, &key("x", None)));
        assert!(Selector::parse("robot").is_err());
        assert!(Selector::parse("robot=").is_err());
        assert_eq!(s.unknown_tags(&["robot".to_string()]), ["site"]);
    }

    fn version(spec: &str) -> Version {
        let resolver = tessla_syntax::include::MemResolver {
            files: [("t.tessla".to_string(), spec.to_string())].into(),
        };
        let loaded = tessla_engine::load_with("t.tessla", &resolver, &Default::default()).unwrap();
        Version::new("v".into(), String::new(), loaded.program, "tessla").unwrap()
    }

    /// The list read apart is the one indexed pattern of every version held, and none while
    /// a version's exact field or another pattern could take one of its keys.
    #[test]
    fn a_list_is_read_apart_only_when_no_other_input_can_take_its_keys() {
        const LIST: &str =
            "@TelegrafIn(\"m\", \"\", \"lidar_*\")\nin l: Events[List[Float]]\nout l\n";
        const X: &str = "@TelegrafIn(\"m\", \"\", \"x\")\nin x: Events[Float]\nout x\n";
        const BEAM: &str = "@TelegrafIn(\"m\", \"\", \"lidar_3\")\nin b: Events[Float]\nout b\n";
        const OTHER: &str =
            "@TelegrafIn(\"m\", \"\", \"ranges_*\")\nin r: Events[List[Float]]\nout r\n";
        let held = |specs: &[&str]| {
            let mut v = Versions::new(version(specs[0]), Vec::new());
            v.list.extend(specs[1..].iter().map(|s| version(s)));
            v.list_to_capture()
        };
        assert_eq!(held(&[LIST]).as_deref(), Some("lidar_"));
        assert_eq!(held(&[LIST, X, LIST]).as_deref(), Some("lidar_"));
        assert_eq!(held(&[X]), None);
        assert_eq!(held(&[LIST, BEAM]), None);
        assert_eq!(held(&[LIST, OTHER]), None);
    }
}
