//! The twin in-process: the robot message goes through the same [`Processor`] as `run` (the
//! binding, the engine, the output encoding), and the `action` metric is read back from the
//! line protocol it writes.
//!
//! Owns: feeding one message as one record and evaluating its step at once (as the stdio
//! transport does when no more input is waiting), and reading an `action` metric into an
//! [`Action`] ([`action_of`], shared with the MQTT twin).

use super::closed_loop::{Message, Reply, Twin};
use super::gate::Action;
use crate::processor::Processor;
use lineproto::{FieldValue, Metric, Record, RecordSplitter, parse_record};

pub struct InProcess {
    processor: Processor,
    line: u64,
}

impl InProcess {
    pub fn new(processor: Processor) -> InProcess {
        InProcess { processor, line: 0 }
    }

    /// The processor's summary line (records, events, outputs, errors).
    pub fn summary(&self) -> String {
        self.processor.summary()
    }
}

impl Twin for InProcess {
    fn exchange(&mut self, line: &str, _message: &Message) -> Result<Reply, String> {
        self.line += 1;
        let record = Record {
            bytes: line.as_bytes().to_vec(),
            line: self.line,
            oversized: false,
        };
        let mut lines = Vec::new();
        self.processor.record(&record, &mut lines);
        self.processor.end_of_read();
        let action = metrics(&lines)
            .iter()
            .filter(|m| m.measurement == "action")
            .find_map(action_of);
        Ok(Reply {
            lines,
            action,
            received_ns: None,
        })
    }
}

/// Every metric in a block of line protocol (unreadable lines are skipped).
pub fn metrics(bytes: &[u8]) -> Vec<Metric> {
    let mut splitter = RecordSplitter::default();
    splitter.push(bytes);
    let mut records = Vec::new();
    while let Some(r) = splitter.next_record() {
        records.push(r);
    }
    records.extend(splitter.finish());
    records
        .iter()
        .filter_map(|r| parse_record(&r.bytes).ok().flatten())
        .collect()
}

fn number(v: &FieldValue) -> Option<f64> {
    match v {
        FieldValue::Float(f) => Some(*f),
        FieldValue::Int(i) => Some(*i as f64),
        FieldValue::UInt(u) => Some(*u as f64),
        FieldValue::Str(s) => s.trim().parse().ok(),
        FieldValue::Bool(_) => None,
    }
}

/// An integer field: an Int or UInt, or a whole Float (Telegraf's JSON does not keep the type).
fn integer(v: &FieldValue) -> Option<i64> {
    match v {
        FieldValue::Int(i) => Some(*i),
        FieldValue::UInt(u) => i64::try_from(*u).ok(),
        FieldValue::Float(f) if f.fract() == 0.0 && f.abs() < 9.2e18 => Some(*f as i64),
        FieldValue::Str(s) => s.trim().parse().ok(),
        _ => None,
    }
}

/// The action in an `action` metric: its `speed` (required), `augmented`, `speed_mse`, `seq`,
/// `valid_until` and timestamp.
pub fn action_of(metric: &Metric) -> Option<Action> {
    let speed = metric.field("speed").and_then(number)?;
    let augmented = matches!(metric.field("augmented"), Some(FieldValue::Bool(true)));
    let speed_mse = metric.field("speed_mse").and_then(number);
    Some(Action {
        speed,
        augmented,
        speed_mse,
        seq: metric.field("seq").and_then(integer),
        valid_until: metric.field("valid_until").and_then(integer),
        time_ns: metric.timestamp,
    })
}
