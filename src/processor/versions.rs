//! Spec versions in force at once in one processor, and which one each instance runs.
//!
//! Owns: the [`Selector`] of a rollout (which instances, by their `--instance-by` tags), the
//! table of versions (the spec the process started with, then each accepted one) and the rules
//! that map (instance, event time) to a version: the newest accepted rollout whose selector
//! picks the instance and whose start is at or before the time, else the spec the process
//! started with.

use super::instances::Key;
use serde::{Deserialize, Serialize};
use std::fmt;

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

    pub fn is_all(&self) -> bool {
        self.clauses.is_empty()
    }

    pub fn parse(s: &str) -> Result<Selector, String> {
        let mut clauses = Vec::new();
        for clause in s.split(';').map(str::trim).filter(|c| !c.is_empty()) {
            let (tag, values) = clause.split_once('=').ok_or_else(|| {
                format!("`{clause}` is not TAG=VALUE[,VALUE...] (for example robot=r1,r2)")
            })?;
            let tag = tag.trim();
            let values: Vec<String> = values
                .split(',')
                .map(|v| v.trim().to_string())
                .filter(|v| !v.is_empty())
                .collect();
            if tag.is_empty() || values.is_empty() {
                return Err(format!(
                    "`{clause}` needs a tag and at least one value (for example robot=r1,r2)"
                ));
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
    type Error = String;
    fn try_from(s: String) -> Result<Selector, String> {
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
}
