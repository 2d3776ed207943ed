//! Reading a recorded run written as CSV with a header row.
//!
//! Columns: a time column (`time_ns`, `timestamp_ns` or rosbag's `%time`: integer nanoseconds;
//! `time`, `timestamp` or `t`: seconds, fractions allowed), lidar either as one column `lidar`
//! holding all ranges separated by spaces or `;`, or as columns `lidar_<i>` / `lidar.<i>`, and any
//! other column as a field of that name. An empty cell is an absent field. A cell is a number
//! when it parses as one (`nan` too: it is published as JSON `null`, i.e. a missing beam),
//! `true`/`false` a boolean, anything else a string.

use super::{FieldValue, Recording, Sample, SkippedRecord};

/// How a column is used.
#[derive(Debug, Clone, PartialEq)]
enum Column {
    TimeNs,
    TimeSeconds,
    LidarList,
    Field(String),
}

fn classify(header: &str) -> Column {
    let name = header.trim();
    match name {
        "time_ns" | "timestamp_ns" | "%time" => Column::TimeNs,
        "time" | "timestamp" | "t" => Column::TimeSeconds,
        "lidar" => Column::LidarList,
        _ => match name.strip_prefix("lidar.") {
            Some(index) if !index.is_empty() && index.bytes().all(|b| b.is_ascii_digit()) => {
                Column::Field(format!("lidar_{index}"))
            }
            _ => Column::Field(name.to_string()),
        },
    }
}

/// Why a recording cannot be read at all (a bad row is skipped, not an error).
#[derive(Debug, thiserror::Error)]
pub enum CsvError {
    /// The header row does not parse.
    #[error("cannot read the CSV header: {0}")]
    Header(csv::Error),
    /// The header row is empty.
    #[error("the CSV header names no columns")]
    NoColumns,
}

/// Why one row is skipped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
enum RowError {
    #[error("{cells} cells but the header has {columns} columns")]
    TooManyCells { cells: usize, columns: usize },
    #[error("time {0:?} is not an integer of nanoseconds")]
    TimeNs(String),
    #[error("time {0:?} is not a number of seconds")]
    TimeSeconds(String),
    #[error("lidar range {0} {1:?} is not a number")]
    Lidar(usize, String),
}

/// Read every row of `text` (the header is the first row).
pub fn read(text: &str) -> Result<Recording, CsvError> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let columns: Vec<Column> = reader
        .headers()
        .map_err(CsvError::Header)?
        .iter()
        .map(classify)
        .collect();
    if columns.is_empty() {
        return Err(CsvError::NoColumns);
    }
    let mut recording = Recording::default();
    for row in reader.records() {
        let row = match row {
            Ok(row) => row,
            Err(e) => {
                let line = e.position().map_or(0, |p| p.line() as usize);
                recording.skipped.push(SkippedRecord {
                    line,
                    reason: format!("unreadable CSV row: {e}"),
                });
                continue;
            }
        };
        let line = row.position().map_or(0, |p| p.line() as usize);
        match read_row(&columns, &row) {
            Ok((time_ns, fields)) => recording.samples.push(Sample {
                line,
                time_ns,
                fields,
            }),
            Err(why) => recording.skipped.push(SkippedRecord {
                line,
                reason: why.to_string(),
            }),
        }
    }
    Ok(recording)
}

type Row = (Option<i64>, Vec<(String, FieldValue)>);

fn read_row(columns: &[Column], row: &csv::StringRecord) -> Result<Row, RowError> {
    if row.len() > columns.len() {
        return Err(RowError::TooManyCells {
            cells: row.len(),
            columns: columns.len(),
        });
    }
    let mut time_ns = None;
    let mut fields = Vec::new();
    for (column, cell) in columns.iter().zip(row.iter()) {
        if cell.is_empty() {
            continue;
        }
        match column {
            Column::TimeNs => {
                let ns = cell
                    .parse::<i64>()
                    .map_err(|_| RowError::TimeNs(cell.to_string()))?;
                time_ns = Some(ns);
            }
            Column::TimeSeconds => {
                let s = cell
                    .parse::<f64>()
                    .ok()
                    .filter(|s| s.is_finite() && s.abs() < 9.2e9)
                    .ok_or_else(|| RowError::TimeSeconds(cell.to_string()))?;
                time_ns = Some((s * 1e9).round() as i64);
            }
            Column::LidarList => {
                let ranges = cell
                    .split(|c: char| c == ';' || c.is_whitespace())
                    .filter(|s| !s.is_empty());
                for (i, range) in ranges.enumerate() {
                    let value = range
                        .parse::<f64>()
                        .map_err(|_| RowError::Lidar(i, range.to_string()))?;
                    fields.push((format!("lidar_{i}"), FieldValue::Float(value)));
                }
            }
            Column::Field(name) => fields.push((name.clone(), cell_value(cell))),
        }
    }
    Ok((time_ns, fields))
}

fn cell_value(cell: &str) -> FieldValue {
    if let Ok(v) = cell.parse::<f64>() {
        return FieldValue::Float(v);
    }
    match cell {
        "true" | "True" | "TRUE" => FieldValue::Bool(true),
        "false" | "False" | "FALSE" => FieldValue::Bool(false),
        _ => FieldValue::Str(cell.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_time_and_named_columns() {
        let text = "time,expectedSpeed,actualSpeed,mode\n0.5,0.1,0.05,auto\n0.7,0.1,,auto\n";
        let rec = read(text).unwrap();
        assert!(rec.skipped.is_empty());
        assert_eq!(rec.samples.len(), 2);
        assert_eq!(rec.samples[0].time_ns, Some(500_000_000));
        assert_eq!(rec.samples[0].line, 2);
        assert_eq!(
            rec.samples[0].fields,
            vec![
                ("expectedSpeed".into(), FieldValue::Float(0.1)),
                ("actualSpeed".into(), FieldValue::Float(0.05)),
                ("mode".into(), FieldValue::Str("auto".into())),
            ]
        );
        // The empty actualSpeed cell is an absent field.
        assert_eq!(rec.samples[1].fields.len(), 2);
    }

    #[test]
    fn lidar_list_column_and_ns_time() {
        let text = "time_ns,lidar\n1000,0.5 0.0;nan 3\n";
        let rec = read(text).unwrap();
        let s = &rec.samples[0];
        assert_eq!(s.time_ns, Some(1000));
        assert_eq!(s.fields.len(), 4);
        assert_eq!(s.fields[0], ("lidar_0".into(), FieldValue::Float(0.5)));
        assert_eq!(s.fields[1], ("lidar_1".into(), FieldValue::Float(0.0)));
        assert!(
            matches!(s.fields[2], (ref n, FieldValue::Float(v)) if n == "lidar_2" && v.is_nan())
        );
        assert_eq!(s.fields[3], ("lidar_3".into(), FieldValue::Float(3.0)));
    }

    #[test]
    fn dotted_lidar_columns_become_indexed_fields() {
        let rec = read("lidar.0,lidar.1\n1,2\n").unwrap();
        assert_eq!(
            rec.samples[0].fields[1],
            ("lidar_1".into(), FieldValue::Float(2.0))
        );
        assert_eq!(rec.samples[0].time_ns, None);
    }

    #[test]
    fn bad_row_is_skipped_with_its_line() {
        let rec = read("time_ns,a\nabc,1\n5,2\n1,2,3\n").unwrap();
        assert_eq!(rec.samples.len(), 1);
        assert_eq!(rec.samples[0].time_ns, Some(5));
        assert_eq!(rec.skipped.len(), 2);
        assert_eq!(rec.skipped[0].line, 2);
        assert!(rec.skipped[0].reason.contains("abc"));
        assert_eq!(rec.skipped[1].line, 4);
    }
}
