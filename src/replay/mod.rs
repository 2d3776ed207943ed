//! Replay of a recorded robot run to MQTT (`tessla-telegraf replay`).
//!
//! Owns the data path of the `replay` subcommand: a recorded run (line protocol as in our
//! fixtures, or CSV with a header) is read into [`Sample`]s ([`read_lp`], [`read_csv`]), each
//! sample becomes the robot's JSON message ([`message`]), [`pacing`] decides when it is due, and
//! [`mqtt`] publishes it. The command line lives in `crate::cli::replay`.

pub mod message;
pub mod mqtt;
pub mod pacing;
pub mod read_csv;
pub mod read_lp;

use std::fmt;

/// One recorded robot message: an optional timestamp and its fields, in source order.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// 1-based line in the source file, for messages.
    pub line: usize,
    /// Nanoseconds since the epoch, when the recording has a time.
    pub time_ns: Option<i64>,
    /// Field name and value; lidar beams appear as `lidar_<i>`.
    pub fields: Vec<(String, FieldValue)>,
}

/// A field value as recorded: the line-protocol codec's own type.
pub use lineproto::FieldValue;

/// A record of the input that could not be read; reading goes on with the next one.
#[derive(Debug, Clone, PartialEq)]
pub struct SkippedRecord {
    pub line: usize,
    pub reason: String,
}

impl fmt::Display for SkippedRecord {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}: {}", self.line, self.reason)
    }
}

/// What a reader made of a whole file.
#[derive(Debug, Default)]
pub struct Recording {
    pub samples: Vec<Sample>,
    pub skipped: Vec<SkippedRecord>,
}

/// The index `i` of a field named `lidar_<i>`, if it is one.
pub fn lidar_index(name: &str) -> Option<usize> {
    let digits = name.strip_prefix("lidar_")?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::lidar_index;

    #[test]
    fn lidar_index_reads_only_plain_indices() {
        assert_eq!(lidar_index("lidar_0"), Some(0));
        assert_eq!(lidar_index("lidar_359"), Some(359));
        assert_eq!(lidar_index("lidar_"), None);
        assert_eq!(lidar_index("lidar_x"), None);
        assert_eq!(lidar_index("lidar_-1"), None);
        assert_eq!(lidar_index("expectedSpeed"), None);
    }
}
