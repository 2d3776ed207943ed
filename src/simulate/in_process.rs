//! The twin in-process: the robot message goes through the same [`Processor`] as `run` (the
//! binding, the engine, the output encoding), and the `action` metric is read back from the
//! line protocol it writes.
//!
//! Owns: feeding one message as one record and evaluating its step at once (as the stdio
//! transport does when no more input is waiting), live time on the robot's clock when asked
//! ([`InProcess::live`]: the silence before a message fires its `delay`s as a real run's wall
//! clock does, so a message a link drop held back comes late), and reading an `action` metric
//! into an [`Action`] ([`action_of`], shared with the MQTT twin).

use super::closed_loop::{Message, Reply, Twin, TwinError};
use super::gate::Action;
use crate::processor::Processor;
use crate::processor::clock::Wall;
use lineproto::{FieldValue, Metric, Record, RecordSplitter, parse_record};
use std::time::{Duration, Instant};

pub struct InProcess {
    processor: Processor,
    line: u64,
    /// With live time: an instant standing for the robot's clock at `start_ns`.
    live: Option<(Instant, i64)>,
}

impl InProcess {
    pub fn new(processor: Processor) -> InProcess {
        InProcess {
            processor,
            line: 0,
            live: None,
        }
    }

    /// The processor's wall clock follows the robot's clock from `start_ns` on: before each
    /// message, the `delay`s due by its arrival fire (a silent link's `robot_silent`), as in a
    /// real run, so a message held back by a link drop is late when it comes.
    pub fn live(mut self, start_ns: i64) -> InProcess {
        self.live = Some((Instant::now(), start_ns));
        self
    }

    /// The processor's summary line (records, events, outputs, errors).
    pub fn summary(&self) -> String {
        self.processor.summary()
    }
}

impl Twin for InProcess {
    fn exchange(
        &mut self,
        line: &str,
        _message: &Message,
        arrival_ns: i64,
    ) -> Result<Reply, TwinError> {
        self.line += 1;
        let record = Record {
            bytes: line.as_bytes().to_vec(),
            line: self.line,
            oversized: false,
        };
        let mut lines = Vec::new();
        if let Some((base, start_ns)) = self.live {
            let since = u64::try_from(arrival_ns.saturating_sub(start_ns)).unwrap_or(0);
            let at = base + Duration::from_nanos(since);
            self.processor.advance_wall(at, &mut lines);
            self.processor.set_wall(Wall { at, ns: arrival_ns });
        }
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
