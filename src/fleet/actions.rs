//! Coordinated actions: a fleet output annotated `@FleetAction(field, validity)` whose type is
//! `Events[Map[String, V]]` (robot key → action value) becomes, at each event, one `action`
//! metric per robot in the map, tagged with that robot's `--instance-by` tags (so Telegraf's MQTT
//! output routes it to the robot's topic as it does the robot's own actions) and `source=fleet`,
//! with the value in `field` and the same safety fields as robot actions (specs/lib/action.tessla):
//! `seq`, the fleet's own count of actions to that robot (1, 2, 3 ...; a robot keeps the last
//! `seq` per `source`), and `valid_until`, the fleet step's time plus `validity` (ns).

use crate::log;
use lineproto::{FieldValue, LineWriter};
use std::collections::HashMap;
use std::sync::Arc;
use tessla_engine::{Program, Value};

/// The measurement robot actions use (specs/robot.tessla).
pub const MEASUREMENT: &str = "action";

struct ActionOut {
    field: String,
    validity: i64,
}

/// A `@FleetAction` annotation without its arguments: the output and what it lacks.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ActionError {
    /// No field name (a String) given.
    #[error("fleet output `{0}`: @FleetAction needs a field name (a String)")]
    NoField(String),
    /// No validity (an Int above 0) given.
    #[error("fleet output `{0}`: @FleetAction needs a validity in ns (an Int above 0)")]
    NoValidity(String),
}

/// The action outputs of a fleet spec and each robot's sequence number.
pub struct Actions {
    /// Per fleet output: its action, if it is one.
    outs: Vec<Option<ActionOut>>,
    by: Vec<String>,
    tags: Vec<(String, String)>,
    seq: HashMap<Arc<str>, i64>,
}

impl Actions {
    /// The count of actions sent to each robot, as held (copied for a fleet checkpoint).
    pub fn seq(&self) -> &HashMap<Arc<str>, i64> {
        &self.seq
    }

    /// Go on from `counts` (a fleet checkpoint).
    pub fn set_counts(&mut self, counts: Vec<(String, i64)>) {
        self.seq = counts.into_iter().map(|(k, n)| (Arc::from(k), n)).collect();
    }

    /// The `@FleetAction` outputs of `program`; an annotation without its arguments is an error.
    pub fn new(
        program: &Program,
        by: Vec<String>,
        tags: Vec<(String, String)>,
    ) -> Result<Actions, ActionError> {
        let mut outs = Vec::new();
        for o in &program.outputs {
            let Some(a) = o.annotations.iter().find(|a| a.name == "FleetAction") else {
                outs.push(None);
                continue;
            };
            let arg = |name: &str, pos: usize| {
                a.args
                    .iter()
                    .find(|(n, _)| n == name)
                    .or_else(|| a.args.get(pos))
                    .map(|(_, v)| v.clone())
            };
            let field = match arg("field", 0) {
                Some(Value::Str(s)) => s.to_string(),
                _ => {
                    return Err(ActionError::NoField(o.name.clone()));
                }
            };
            let validity = match arg("validity", 1) {
                Some(Value::Int(i)) if i > 0 => i,
                _ => {
                    return Err(ActionError::NoValidity(o.name.clone()));
                }
            };
            outs.push(Some(ActionOut { field, validity }));
        }
        Ok(Actions {
            outs,
            by,
            tags,
            seq: HashMap::new(),
        })
    }

    /// Go on with `before`'s per-robot sequence numbers (a new fleet spec version's actions
    /// continue the numbering robots see).
    pub fn carry_seq(&mut self, before: &Actions) {
        self.seq = before.seq.clone();
    }

    pub fn is_action(&self, output: usize) -> bool {
        matches!(self.outs.get(output), Some(Some(_)))
    }

    /// Write the action metrics of output `output`'s event at `ts` with value `value` (a map
    /// from robot key to the action's value), in robot key order.
    pub fn write(&mut self, ts: i64, output: usize, value: &Value, out: &mut Vec<u8>) {
        let Some(Some(a)) = self.outs.get(output) else {
            return;
        };
        let Value::Map(m) = value else {
            log::warn_limited("fleet action", || {
                format!(
                    "fleet action `{}` at {ts}: not a map from robot key to value; not sent",
                    a.field
                )
            });
            return;
        };
        let mut entries: Vec<(&str, &Value)> = m
            .iter()
            .filter_map(|(k, v)| match k {
                Value::Str(s) => Some((&**s, v)),
                _ => None,
            })
            .collect();
        entries.sort_by(|x, y| x.0.cmp(y.0));
        for (key, v) in entries {
            let Some(fv) = field_value(v) else {
                log::warn_limited("fleet action", || {
                    format!(
                        "fleet action `{}` at {ts} for robot {key}: {v} has no line-protocol form; not sent",
                        a.field
                    )
                });
                continue;
            };
            let seq = {
                let s = self.seq.entry(Arc::from(key)).or_insert(0);
                *s += 1;
                *s
            };
            let mut tags: Vec<(&str, &str)> = self
                .tags
                .iter()
                .filter(|(k, _)| !self.by.contains(k) && k != "source")
                .map(|(k, v)| (k.as_str(), v.as_str()))
                .collect();
            let parts: Vec<&str> = if self.by.len() <= 1 {
                vec![key]
            } else {
                key.splitn(self.by.len(), ',').collect()
            };
            for (k, v) in self.by.iter().zip(parts) {
                tags.push((k.as_str(), v));
            }
            tags.push(("source", "fleet"));
            tags.sort();
            let mut w = LineWriter::new(MEASUREMENT);
            for (k, v) in &tags {
                w.tag(k, v);
            }
            w.field(&a.field, &fv)
                .field("seq", &FieldValue::Int(seq))
                .field(
                    "valid_until",
                    &FieldValue::Int(ts.saturating_add(a.validity)),
                );
            let (line, _) = w.finish(Some(ts));
            if let Some(line) = line {
                out.extend_from_slice(line.as_bytes());
            }
        }
    }
}

/// A scalar action value in line-protocol form (`Some(x)` as `x`; `None`, compounds: none).
fn field_value(v: &Value) -> Option<FieldValue> {
    Some(match v {
        Value::Unit => FieldValue::Bool(true),
        Value::Bool(b) => FieldValue::Bool(*b),
        Value::Int(i) => FieldValue::Int(*i),
        Value::Float(f) if f.is_finite() => FieldValue::Float(*f),
        Value::Str(s) => FieldValue::Str(s.to_string()),
        Value::Some(x) => return field_value(x),
        _ => return None,
    })
}
