//! Reading a recorded run written as InfluxDB line protocol (the shape of our fixtures, i.e.
//! what Telegraf's `mqtt_consumer` JSON parser makes of the robot's messages).
//!
//! Records are cut quote-aware with `influxdb_line_protocol::split_lines` (string fields may
//! hold raw newlines) and parsed one by one, so a bad record is reported with its line number
//! and skipped.

use super::{FieldValue, Recording, Sample, SkippedRecord};
use influxdb_line_protocol::{FieldValue as LpValue, parse_lines, split_lines};

/// A file's bytes as text a reader takes: a line that is not valid UTF-8 is reported (line
/// number, column of the first bad byte) and blanked, so line numbers stay right and the rest
/// of the file is read, as `run` skips such a line. Used for line protocol and CSV alike.
pub fn valid_lines(bytes: &[u8]) -> (String, Vec<SkippedRecord>) {
    if let Ok(text) = std::str::from_utf8(bytes) {
        return (text.to_string(), Vec::new());
    }
    let mut text = String::with_capacity(bytes.len());
    let mut skipped = Vec::new();
    for (i, line) in bytes.split_inclusive(|&b| b == b'\n').enumerate() {
        match std::str::from_utf8(line) {
            Ok(l) => text.push_str(l),
            Err(e) => {
                let good = line.get(..e.valid_up_to()).unwrap_or_default();
                skipped.push(SkippedRecord {
                    line: i + 1,
                    reason: format!(
                        "not UTF-8 (a bad byte at column {}): {}",
                        String::from_utf8_lossy(good).chars().count() + 1,
                        excerpt(String::from_utf8_lossy(line).trim_end_matches(['\n', '\r']))
                    ),
                });
                if line.ends_with(b"\n") {
                    text.push('\n');
                }
            }
        }
    }
    (text, skipped)
}

/// Read every record of `text`; with `measurement`, only records of that measurement.
pub fn read(text: &str, measurement: Option<&str>) -> Recording {
    let mut recording = Recording::default();
    let base = text.as_ptr() as usize;
    // Line numbers are counted incrementally from the previous record's offset.
    let (mut counted_to, mut line) = (0usize, 1usize);
    for chunk in split_lines(text) {
        // `split_lines` yields sub-slices of `text`: their offset gives the line number.
        let offset = (chunk.as_ptr() as usize).saturating_sub(base);
        if let Some(between) = text.get(counted_to..offset) {
            line += between.bytes().filter(|&b| b == b'\n').count();
            counted_to = offset;
        }
        let trimmed = chunk.trim_end_matches('\r');
        for parsed in parse_lines(trimmed) {
            match parsed {
                Ok(parsed) => {
                    if measurement.is_some_and(|m| m != parsed.series.measurement.as_str()) {
                        continue;
                    }
                    let fields = parsed
                        .field_set
                        .iter()
                        .map(|(key, value)| (key.to_string(), convert(value)))
                        .collect();
                    recording.samples.push(Sample {
                        line,
                        time_ns: parsed.timestamp,
                        fields,
                    });
                }
                Err(err) => recording.skipped.push(SkippedRecord {
                    line,
                    reason: format!("not line protocol ({err}): {}", excerpt(trimmed)),
                }),
            }
        }
    }
    recording
}

fn convert(value: &LpValue<'_>) -> FieldValue {
    match value {
        LpValue::I64(v) => FieldValue::Int(*v),
        LpValue::U64(v) => FieldValue::UInt(*v),
        LpValue::F64(v) => FieldValue::Float(*v),
        LpValue::String(s) => FieldValue::Str(s.to_string()),
        LpValue::Boolean(b) => FieldValue::Bool(*b),
    }
}

/// The first 60 characters of a record, for error messages.
fn excerpt(record: &str) -> String {
    let mut short: String = record.chars().take(60).collect();
    if short.len() < record.len() {
        short.push('…');
    }
    format!("{short:?}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_fields_timestamps_and_line_numbers() {
        let text = "mqtt_consumer,topic=tessla expectedSpeed=0.1,actualSpeed=\"0.05\",lidar_1=2.5 100\n\
                    \n\
                    # comment\n\
                    mqtt_consumer,topic=tessla expectedSpeed=0.2 200\n";
        let rec = read(text, None);
        assert!(rec.skipped.is_empty(), "{:?}", rec.skipped);
        assert_eq!(rec.samples.len(), 2);
        assert_eq!(rec.samples[0].line, 1);
        assert_eq!(rec.samples[0].time_ns, Some(100));
        assert_eq!(
            rec.samples[0].fields,
            vec![
                ("expectedSpeed".to_string(), FieldValue::Float(0.1)),
                ("actualSpeed".to_string(), FieldValue::Str("0.05".into())),
                ("lidar_1".to_string(), FieldValue::Float(2.5)),
            ]
        );
        assert_eq!(rec.samples[1].line, 4);
        assert_eq!(rec.samples[1].time_ns, Some(200));
    }

    #[test]
    fn bad_record_is_reported_and_skipped() {
        let text = "m a=1 1\nthis is not valid\nm a=2 2\n";
        let rec = read(text, None);
        assert_eq!(rec.samples.len(), 2);
        assert_eq!(rec.skipped.len(), 1);
        assert_eq!(rec.skipped[0].line, 2);
        assert!(rec.skipped[0].reason.contains("this is not valid"));
    }

    #[test]
    fn a_line_that_is_not_utf8_is_skipped_alone() {
        let bytes = b"m a=1 1\nm a=\xff\xfe 2\nm a=3 3\n";
        let (text, skipped) = valid_lines(bytes);
        assert_eq!(skipped.len(), 1);
        assert_eq!(skipped[0].line, 2);
        assert!(
            skipped[0].reason.contains("column 5"),
            "{}",
            skipped[0].reason
        );
        let rec = read(&text, None);
        assert_eq!(rec.samples.len(), 2);
        assert_eq!(rec.samples[1].line, 3);
    }

    #[test]
    fn measurement_filter_keeps_only_that_measurement() {
        let text = "mqtt_consumer expectedSpeed=1 1\naction speed=2 1\n";
        let rec = read(text, Some("mqtt_consumer"));
        assert_eq!(rec.samples.len(), 1);
        assert_eq!(
            rec.samples[0].fields[0],
            ("expectedSpeed".into(), FieldValue::Float(1.0))
        );
    }

    #[test]
    fn string_field_with_raw_newline_stays_one_record() {
        let text = "m note=\"a\nb\",x=1 5\nm x=2 6\n";
        let rec = read(text, None);
        assert_eq!(rec.samples.len(), 2);
        assert_eq!(rec.samples[0].fields[0].1, FieldValue::Str("a\nb".into()));
        assert_eq!(rec.samples[1].line, 3);
    }
}
