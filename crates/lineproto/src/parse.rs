//! Parsing one line-protocol record into a [`Metric`].
//!
//! Owns: the conversion from the `influxdb-line-protocol` crate's parse result to owned metrics,
//! and the places where Telegraf's parser (influxdata/telegraf
//! `plugins/parsers/influx/machine.go.rl`) differs from the crate (`influxdb-line-protocol`
//! 2.0.0): a trailing `\r` is accepted, `#` comment lines and blank lines are "no metric", the
//! grammar differences handled in `crate::telegraf_rules` (tabs, `.5`, leading zeros, `\\`, ...),
//! out-of-range floats (`1e400`, which the crate reads as infinity) are rejected as Telegraf does,
//! and a repeated tag or field key keeps the last value (Telegraf overwrites).
//!
//! Deviation kept on purpose: invalid UTF-8 anywhere is an error (Telegraf, in Go, does not
//! check), because the crate parses `&str`; Telegraf's own serializer only writes valid UTF-8
//! for JSON-derived metrics.

// The parsed record's types, here too where they always were (`lineproto::parse::Metric`).
pub use crate::metric::{FieldValue, Metric};
use crate::telegraf_rules;
use influxdb_line_protocol::FieldValue as CrateValue;

/// Why a record is not a metric.
#[derive(Debug, Clone, PartialEq)]
pub struct ParseError {
    /// 1-based column (in characters) where the problem was found, when known.
    pub column: usize,
    /// What is wrong, in words (`missing fields`, `invalid number`, ...).
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

impl std::error::Error for ParseError {}

/// At most 60 characters of `text` (control characters escaped), `…` marking a cut.
fn excerpt(text: &str) -> String {
    const MAX: usize = 60;
    let mut out = String::new();
    let mut len = 0;
    for c in text.chars() {
        let esc = c.escape_debug();
        if len + esc.len() > MAX {
            out.push('…');
            break;
        }
        len += esc.len();
        out.extend(esc);
    }
    out
}

/// Parse one record (as cut by [`crate::RecordSplitter`]). `Ok(None)`: a blank or comment line.
///
/// Plain records (the usual output of Telegraf's serializers) take a hand-written fast path
/// (`crate::fast`); every other record takes the full path below with the same result.
pub fn parse_record(bytes: &[u8]) -> Result<Option<Metric>, ParseError> {
    let mut m = Metric::default();
    Ok(parse_record_into(bytes, &mut m)?.then_some(m))
}

/// [`parse_record`] into `m`, reusing its strings and vectors (the step loop parses every record
/// into one scratch metric, so plain records allocate nothing). `Ok(false)`: a blank or comment
/// line (`m` then holds garbage, as after an error).
pub fn parse_record_into(bytes: &[u8], m: &mut Metric) -> Result<bool, ParseError> {
    if let Ok(text) = std::str::from_utf8(bytes)
        && crate::fast::parse_plain_into(text, m)
    {
        return Ok(true);
    }
    // The full path captures no list: its metric has every field in `fields`.
    m.list.clear_record();
    match parse_record_full(bytes)? {
        Some(full) => {
            let list = std::mem::take(&mut m.list);
            *m = full;
            m.list = list;
            Ok(true)
        }
        None => Ok(false),
    }
}

/// The full path: Telegraf's rules ([`crate::telegraf_rules`]) on top of the crate's parser.
pub(crate) fn parse_record_full(bytes: &[u8]) -> Result<Option<Metric>, ParseError> {
    let text = match std::str::from_utf8(bytes) {
        Ok(t) => t,
        Err(e) => {
            let lossy = String::from_utf8_lossy(bytes);
            return Err(ParseError {
                column: String::from_utf8_lossy(bytes.get(..e.valid_up_to()).unwrap_or_default())
                    .chars()
                    .count()
                    + 1,
                reason: "invalid UTF-8".into(),
                excerpt: excerpt(&lossy),
            });
        }
    };
    let line = text.strip_suffix('\n').unwrap_or(text);
    let line = line.strip_suffix('\r').unwrap_or(line);
    let body = line.trim_start_matches([' ', '\t', '\r', '\x0b', '\x0c']);
    // Columns are reported over the whole record, leading blanks included.
    let lead = line.len() - body.len();
    let column = |byte: usize| {
        line.get(..lead + byte)
            .map_or(1, |head| head.chars().count() + 1)
    };
    if body.trim().is_empty() || body.starts_with('#') {
        return Ok(None);
    }
    let fixed = telegraf_rules::normalize(body).map_err(|f| ParseError {
        column: column(f.at),
        reason: f.reason,
        excerpt: excerpt(body),
    })?;
    let mut lines = influxdb_line_protocol::parse_lines(&fixed);
    let parsed = match lines.next() {
        Some(Ok(p)) => p,
        Some(Err(e)) => {
            let reason = e.to_string();
            return Err(ParseError {
                column: column(offset_of(body, &reason)),
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
                    column: column(body.find(k.as_str()).unwrap_or(0)),
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
        fields.push((k.as_str().to_string(), value));
    }
    let overwritten = keep_last_of_each_key(&mut fields);
    Ok(Some(Metric {
        measurement: parsed.series.measurement.as_str().to_string(),
        tags,
        fields,
        timestamp: parsed.timestamp,
        overwritten,
        list: Default::default(),
    }))
}

/// Telegraf overwrites a repeated field: keep the first position, the last value. Records
/// rarely repeat keys, so first check cheaply (a sort of borrowed keys: O(n log n) for the
/// 360-field lidar line) before rebuilding with an index by key (linear: a record of 100k
/// fields with a repeated key must not cost 100k² comparisons). Returns how many values were
/// overwritten.
fn keep_last_of_each_key(fields: &mut Vec<(String, FieldValue)>) -> usize {
    let mut keys: Vec<&str> = fields.iter().map(|(k, _)| k.as_str()).collect();
    keys.sort_unstable();
    if keys.windows(2).all(|w| w.first() != w.last()) {
        return 0;
    }
    let before = fields.len();
    let mut out: Vec<(String, FieldValue)> = Vec::with_capacity(before);
    let mut slots: std::collections::HashMap<String, usize> =
        std::collections::HashMap::with_capacity(before);
    for (k, v) in fields.drain(..) {
        match slots.get(&k).and_then(|&i| out.get_mut(i)) {
            Some(slot) => slot.1 = v,
            None => {
                slots.insert(k.clone(), out.len());
                out.push((k, v));
            }
        }
    }
    *fields = out;
    before - fields.len()
}

/// The crate reports no position; point at the offending text when its message quotes it.
fn offset_of(body: &str, reason: &str) -> usize {
    reason
        .split('\'')
        .nth(1)
        .filter(|q| !q.is_empty())
        .and_then(|q| body.find(q))
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_are_std_errors() {
        fn is_error<E: std::error::Error>() {}
        is_error::<ParseError>();
        is_error::<crate::NotFinite>();
    }

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
    fn a_repeated_key_among_100k_fields_is_resolved_in_linear_time() {
        // Regression (hostile input): the rebuild was quadratic, ~5·10⁹ key comparisons here.
        let mut line = String::from("m dup=1i");
        for i in 0..100_000 {
            line.push_str(&format!(",f{i}=1i"));
        }
        line.push_str(",dup=2i 5\n");
        let m = ok(&line);
        assert_eq!(m.fields.len(), 100_001);
        assert_eq!(m.overwritten, 1);
        assert_eq!(
            m.fields.first(),
            Some(&("dup".to_string(), FieldValue::Int(2)))
        );
    }

    /// The scratch metric is reused: a record with a repeated key must not leave its count on
    /// the plain records parsed into the same metric after it.
    #[test]
    fn reused_metric_forgets_overwritten_count() {
        let mut m = Metric::default();
        assert_eq!(parse_record_into(b"m a=1,a=2 1\n", &mut m), Ok(true));
        assert_eq!(m.overwritten, 1);
        assert_eq!(parse_record_into(b"m a=1,b=2 2\n", &mut m), Ok(true));
        assert_eq!(m.overwritten, 0);
    }

    #[test]
    fn types_crlf_comments_and_duplicates() {
        let m = ok("m a=1i,b=2u,c=true,d=\"x\\\"y\",a=3i 5\r\n");
        assert_eq!(m.fields.len(), 4);
        assert_eq!(m.overwritten, 1);
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
            "m a=1 9999999999999999999",
            "m a=18446744073709551616u 1",
            "m a=-1u 1",
            "m a=1.5i 1",
            "m a=yes 1",
            "m,t= a=1 1",
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

    #[test]
    fn reads_telegraf_forms_the_crate_alone_gets_wrong() {
        let m = ok("m,t=a\\\\b\tc=.5,d=5.,e=-.25e1\t7\n");
        assert_eq!(
            m.tag("t"),
            Some("a\\\\b"),
            "Telegraf keeps `\\\\` as two backslashes"
        );
        assert_eq!(m.field("c"), Some(&FieldValue::Float(0.5)));
        assert_eq!(m.field("d"), Some(&FieldValue::Float(5.0)));
        assert_eq!(m.field("e"), Some(&FieldValue::Float(-2.5)));
        assert_eq!(m.timestamp, Some(7));
        assert_eq!(
            ok("m s=\"a\0b\" 1").field("s"),
            Some(&FieldValue::Str("a\0b".into()))
        );
        assert_eq!(parse_record(b"  \t# indented comment \"\n").unwrap(), None);
    }

    #[test]
    fn columns_count_characters_of_the_whole_record() {
        let e = parse_record("  m,t=\u{e9} a=007i 1".as_bytes()).unwrap_err();
        assert_eq!(e.column, 11, "{e:?}");
        assert!(e.reason.contains("leading zero"), "{e:?}");
        let e = parse_record(b"m a=1,b=1e400 1").unwrap_err();
        assert_eq!(e.column, 7, "{e:?}");
        let e = parse_record(b"m,a,b=c f=1 1").unwrap_err();
        assert_eq!(e.column, 3, "{e:?}");
    }

    #[test]
    fn excerpts_are_short_and_escaped() {
        let long = format!("m\t{} 1", "x".repeat(500));
        let e = parse_record(long.as_bytes()).unwrap_err();
        assert!(e.excerpt.chars().count() <= 61, "{}", e.excerpt);
        assert!(e.excerpt.starts_with("m\\t"), "{}", e.excerpt);
    }
}
