//! One parsed record: a [`Metric`] and its [`FieldValue`]s.
//!
//! Owns: the record types the parsers ([`crate::parse`] and its fast path) fill and the writer
//! ([`crate::write`]) reads; they depend on nothing else in the crate but the list a metric may
//! hold apart ([`crate::list`]).

use crate::list::ListCapture;

/// A field's value, in the line protocol's five types.
#[derive(Debug, Clone, PartialEq)]
pub enum FieldValue {
    /// A float (`1.5`, `1e3`; a number without a suffix).
    Float(f64),
    /// A signed integer (`42i`).
    Int(i64),
    /// An unsigned integer (`42u`).
    UInt(u64),
    /// A boolean (`t`, `true`, `F`, `false`, ...).
    Bool(bool),
    /// A string (`"text"`, its escapes undone).
    Str(String),
}

/// One parsed metric. Tags keep input order; fields keep input order (last value of a key wins).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Metric {
    /// The measurement's name, its escapes undone.
    pub measurement: String,
    /// The tags as (key, value), escapes undone.
    pub tags: Vec<(String, String)>,
    /// The fields as (key, value), escapes undone.
    pub fields: Vec<(String, FieldValue)>,
    /// Nanoseconds since the epoch, if the record had a timestamp.
    pub timestamp: Option<i64>,
    /// Field values overwritten by a later value of the same key (0 for a well-formed record).
    pub overwritten: usize,
    /// The fields of one list pattern, when the caller asked for them apart (see
    /// [`ListCapture`]); then they are not in `fields`.
    pub list: ListCapture,
}

impl Metric {
    /// The value of tag `key`, if the metric has it.
    pub fn tag(&self, key: &str) -> Option<&str> {
        self.tags
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// The value of field `key`, if the metric has it. (Inline: a binding looks up each
    /// record's fields by name.)
    #[inline]
    pub fn field(&self, key: &str) -> Option<&FieldValue> {
        self.fields.iter().find(|(k, _)| k == key).map(|(_, v)| v)
    }

    /// This metric with the captured list elements back among its fields (after the others), as
    /// a parser that captures nothing gives it, field order aside.
    pub fn with_list_as_fields(&self) -> Metric {
        let mut m = self.clone();
        if self.list.holds_record() {
            let prefix = String::from_utf8_lossy(self.list.prefix());
            m.fields.extend(
                self.list
                    .elements()
                    .map(|(i, f)| (format!("{prefix}{i}"), FieldValue::Float(f))),
            );
        }
        m.list.clear_record();
        m
    }
}
