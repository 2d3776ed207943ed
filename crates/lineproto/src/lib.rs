//! lineproto: InfluxDB line protocol as Telegraf reads and writes it.
//!
//! Owns: cutting a byte stream into records ([`split`], quote-aware: a string field may hold a raw
//! newline), parsing one record into a [`Metric`] ([`parse`]; the record types in `metric`, on the `influxdb-line-protocol`
//! crate with Telegraf's rules applied on top; a list pattern's elements read apart in `list`),
//! and writing metrics back with Telegraf's escaping ([`write`](mod@write)). No I/O happens here.
//!
#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

mod fast;
mod list;
mod metric;
pub mod parse;
pub mod split;
mod telegraf_rules;
pub mod write;

pub use fast::short_decimal;
pub use list::{ListCapture, Prefix, list_index};
pub use metric::{FieldValue, Metric};
pub use parse::{ParseError, parse_record, parse_record_into};
pub use split::{DEFAULT_MAX_RECORD, OVERSIZED_HEAD, Record, RecordRef, RecordSplitter};
pub use write::{
    LineWriter, NotFinite, Text, measurement_is_writable, name_is_writable, write_field_key,
    write_field_value, write_float, write_measurement, write_tag_key, write_tag_value,
    write_timestamp, write_value,
};
