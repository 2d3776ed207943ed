//! Parsing one line-protocol record into a [`Metric`].
//!
//! Owns: the conversion from the `influxdb-line-protocol` crate's parse result to owned metrics,
//! and the places where Telegraf's parser differs from the crate (research note §5): a trailing
//! `\r` is accepted, `#` comment lines and blank lines are "no metric", out-of-range floats
//! (`1e400`, which the crate reads as infinity) are rejected as Telegraf does, and a repeated
//! tag or field key keeps the last value.

use influxdb_line_protocol::FieldValue as CrateValue;

#[derive(Debug, Clone, PartialEq)]
pub enum FieldValue {
    Float(f64),
    Int(i64),
    UInt(u64),
    Bool(bool),
    Str(String),
}

/// One parsed metric. Tags keep input order; fields keep input order (last value of a key wins).
#[derive(Debug, Clone, PartialEq)]
pub struct Metric {
    pub measurement: String,
    pub tags: Vec<(String, String)>,
    pub fields: Vec<(String, FieldValue)>,
    /// Nanoseconds since the epoch, if the record had a timestamp.
    pub timestamp: Option<i64>,
}

impl Metric {
    pub fn tag(&self, key: &str) -> Option<&str> {
        self.tags
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    pub fn field(&self, key: &str) -> Option<&FieldValue> {
        self.fields.iter().find(|(k, _)| k == key).map(|(_, v)| v)
    }
}

/// Why a record is not a metric.
#[derive(Debug, Clone, PartialEq)]
pub struct ParseError {
    /// 1-based column (in characters) where the problem was found, when known.
    pub column: usize,
    pub reason: String,
    /// The start of the record, at most 60 characters, with control characters escaped.
    pub excerpt: String,
}

impl std::fmt::Display for ParseError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "column {}: {} (near `{}`)",
            self.column, self.reason, self.excerpt
        )
    }
}

fn excerpt(text: &str) -> String {
    let mut s: String = text.chars().take(60).flat_map(char::escape_debug).collect();
    if text.chars().count() > 60 {
        s.push('…');
    }
    s
}

/// Parse one record (as cut by [`crate::RecordSplitter`]). `Ok(None)`: a blank or comment line.
pub fn parse_record(bytes: &[u8]) -> Result<Option<Metric>, ParseError> {
    let text = match std::str::from_utf8(bytes) {
        Ok(t) => t,
        Err(e) => {
            let lossy = String::from_utf8_lossy(bytes);
            return Err(ParseError {
                column: String::from_utf8_lossy(&bytes[..e.valid_up_to()])
                    .chars()
                    .count()
                    + 1,
                reason: "invalid UTF-8".into(),
                excerpt: excerpt(&lossy),
            });
        }
    };
    let trimmed = text
        .strip_suffix('\n')
        .unwrap_or(text)
        .strip_suffix('\r')
        .unwrap_or_else(|| text.strip_suffix('\n').unwrap_or(text));
    let body = trimmed.trim_start();
    if body.trim().is_empty() || body.starts_with('#') {
        return Ok(None);
    }
    if let Some(pos) = body.find('\0') {
        return Err(ParseError {
            column: body[..pos].chars().count() + 1,
            reason: "NUL byte in the record".into(),
            excerpt: excerpt(body),
        });
    }
    let mut lines = influxdb_line_protocol::parse_lines(body);
    let parsed = match lines.next() {
        Some(Ok(p)) => p,
        Some(Err(e)) => {
            let reason = e.to_string();
            return Err(ParseError {
                column: column_of(body, &reason),
                reason,
                excerpt: excerpt(body),
            });
        }
        None => return Ok(None),
    };
    if lines.next().is_some() {
        return Err(ParseError {
            column: 1,
            reason: "more than one record on this line".into(),
            excerpt: excerpt(body),
        });
    }
    let mut tags: Vec<(String, String)> = Vec::new();
    for (k, v) in parsed.series.tag_set.iter().flatten() {
        let (k, v) = (k.as_str().to_string(), v.as_str().to_string());
        match tags.iter_mut().find(|(tk, _)| *tk == k) {
            Some(slot) => slot.1 = v,
            None => tags.push((k, v)),
        }
    }
    let mut fields: Vec<(String, FieldValue)> = Vec::with_capacity(parsed.field_set.len());
    for (k, v) in parsed.field_set.iter() {
        let value = match v {
            CrateValue::F64(f) if !f.is_finite() => {
                return Err(ParseError {
                    column: body
                        .find(k.as_str())
                        .map_or(1, |i| body[..i].chars().count() + 1),
                    reason: format!("field `{}`: float value out of range", k.as_str()),
                    excerpt: excerpt(body),
                });
            }
            CrateValue::F64(f) => FieldValue::Float(*f),
            CrateValue::I64(i) => FieldValue::Int(*i),
            CrateValue::U64(u) => FieldValue::UInt(*u),
            CrateValue::Boolean(b) => FieldValue::Bool(*b),
            CrateValue::String(s) => FieldValue::Str(s.as_str().to_string()),
        };
        let k = k.as_str().to_string();
        match fields.iter_mut().find(|(fk, _)| *fk == k) {
            Some(slot) => slot.1 = value,
            None => fields.push((k, value)),
        }
    }
    Ok(Some(Metric {
        measurement: parsed.series.measurement.as_str().to_string(),
        tags,
        fields,
        timestamp: parsed.timestamp,
    }))
}

/// The crate reports no position; point at the offending text when its message quotes it.
fn column_of(body: &str, reason: &str) -> usize {
    let quoted = reason.split('\'').nth(1).filter(|q| !q.is_empty());
    quoted
        .and_then(|q| body.find(q))
        .map_or(1, |i| body[..i].chars().count() + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok(s: &str) -> Metric {
        parse_record(s.as_bytes()).unwrap().unwrap()
    }

    #[test]
    fn parses_the_telegraf_json_shape() {
        let m = ok(
            "mqtt_consumer,host=h,topic=tessla actualSpeed=\"0.05\",expectedSpeed=0.1,lidar_0=1.5 1700000000000000000\n",
        );
        assert_eq!(m.measurement, "mqtt_consumer");
        assert_eq!(m.tag("topic"), Some("tessla"));
        assert_eq!(
            m.field("actualSpeed"),
            Some(&FieldValue::Str("0.05".into()))
        );
        assert_eq!(m.field("expectedSpeed"), Some(&FieldValue::Float(0.1)));
        assert_eq!(m.timestamp, Some(1_700_000_000_000_000_000));
    }

    #[test]
    fn types_crlf_comments_and_duplicates() {
        let m = ok("m a=1i,b=2u,c=true,d=\"x\\\"y\",a=3i 5\r\n");
        assert_eq!(m.fields.len(), 4);
        assert_eq!(m.field("a"), Some(&FieldValue::Int(3)));
        assert_eq!(m.field("b"), Some(&FieldValue::UInt(2)));
        assert_eq!(m.field("d"), Some(&FieldValue::Str("x\"y".into())));
        assert_eq!(parse_record(b"# comment\n").unwrap(), None);
        assert_eq!(parse_record(b"   \n").unwrap(), None);
        assert!(ok("m a=1").timestamp.is_none());
    }

    #[test]
    fn rejects_what_telegraf_rejects_with_a_place() {
        for bad in [
            "m a=1e400 1",
            "m a=NaN 1",
            "m 1",
            "m a=99999999999999999999i 1",
            "m a=1 99999999999999999999",
            "m a=\"unterminated 1",
        ] {
            let e = parse_record(bad.as_bytes()).unwrap_err();
            assert!(!e.reason.is_empty() && e.column >= 1, "{bad}: {e:?}");
        }
        let e = parse_record(b"m a=\xff 1").unwrap_err();
        assert_eq!(e.reason, "invalid UTF-8");
        assert_eq!(e.column, 5);
        assert!(parse_record(b"m a=1\0 1").is_err());
    }
}
