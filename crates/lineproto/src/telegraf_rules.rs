//! Telegraf's line-protocol grammar where it differs from the `influxdb-line-protocol` crate.
//!
//! Owns: one scan over a record (without its line ending) that rejects what Telegraf's parser
//! rejects but the crate accepts, and rewrites what Telegraf accepts but the crate rejects or
//! reads differently, so that the crate then yields Telegraf's metric (Telegraf's grammar:
//! influxdata/telegraf `plugins/parsers/influx/machine.go.rl`; the crate's readings as tried
//! against `influxdb-line-protocol` 2.0.0):
//! - separators may be tab, VT or FF as well as space (crate: space only) -> rewritten to space;
//! - floats `.5`, `-.5`, `5.`, `5.e3` (crate rejects) -> `0.5`, `-0.5`, `5.0`, `5.0e3`;
//! - integers with leading zeros `007i` (crate reads 7) -> rejected;
//! - `\\` in measurement, tag keys/values and field keys stays two backslashes in Telegraf (crate
//!   makes one) -> doubled so the crate's unescaping gives Telegraf's text;
//! - a tag or field key without `=` (`m,a,b=c`, `m a,b=1`; crate reads key `a,b`), a field set
//!   ending in a comma (crate ignores it), an unterminated string, NUL outside strings -> rejected.
//!
//! The rest (value syntax, timestamps, ranges) is left to the crate. Only ASCII bytes are looked at
//! or rewritten, so multi-byte UTF-8 characters pass through whole.

use std::borrow::Cow;

/// A rule violation: byte offset into the scanned text and the reason.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Fault {
    pub at: usize,
    pub reason: String,
}

fn fault(at: usize, reason: impl Into<String>) -> Fault {
    Fault {
        at,
        reason: reason.into(),
    }
}

fn is_sep(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\x0b' | b'\x0c')
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Section {
    Measurement,
    TagKey,
    TagValue,
    FieldKey,
    Timestamp,
}

/// Check `text` against Telegraf's rules and rewrite it into what the crate reads the same way.
pub(crate) fn normalize(text: &str) -> Result<Cow<'_, str>, Fault> {
    let b = text.as_bytes();
    let at = |i: usize| b.get(i).copied();
    // (start, end, replacement), in increasing position order.
    let mut edits: Vec<(usize, usize, &'static str)> = Vec::new();
    let mut section = Section::Measurement;
    let mut key_start = 0;
    let mut i = 0;
    while let Some(c) = at(i) {
        if section == Section::Timestamp {
            if is_sep(c) && c != b' ' {
                edits.push((i, i + 1, " "));
            }
            i += 1;
            continue;
        }
        match c {
            b'\\' => {
                if at(i + 1) == Some(b'\\') {
                    edits.push((i, i + 2, "\\\\\\\\"));
                }
                // Skip the escaped byte only when it is ASCII; a multi-byte character's
                // continuation bytes never match a rule anyway.
                i += if at(i + 1).is_some_and(|n| n.is_ascii()) {
                    2
                } else {
                    1
                };
                continue;
            }
            0 => return Err(fault(i, "NUL byte outside a string field")),
            c if is_sep(c) => match section {
                Section::Measurement | Section::TagValue => {
                    while let Some(s) = at(i).filter(|&s| is_sep(s)) {
                        if s != b' ' {
                            edits.push((i, i + 1, " "));
                        }
                        i += 1;
                    }
                    section = Section::FieldKey;
                    key_start = i;
                    continue;
                }
                Section::TagKey => return Err(fault(key_start, "tag key without `=value`")),
                _ => return Err(fault(key_start, "field key without `=value`")),
            },
            b',' => match section {
                Section::Measurement | Section::TagValue => {
                    section = Section::TagKey;
                    key_start = i + 1;
                }
                Section::TagKey => return Err(fault(key_start, "tag key without `=value`")),
                _ => return Err(fault(key_start, "field key without `=value`")),
            },
            b'=' if section == Section::TagKey => section = Section::TagValue,
            b'=' if section == Section::FieldKey => {
                let (next, more) = field_value(text, i + 1, key_start, &mut edits)?;
                i = next;
                if more {
                    key_start = i;
                } else {
                    section = Section::Timestamp;
                }
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    if edits.is_empty() {
        return Ok(Cow::Borrowed(text));
    }
    let mut out = String::with_capacity(text.len() + 8);
    let mut prev = 0;
    for (start, end, with) in edits {
        let Some(piece) = text.get(prev..start) else {
            return Err(fault(start, "internal: rewrite off a character boundary"));
        };
        out.push_str(piece);
        out.push_str(with);
        prev = end;
    }
    out.push_str(text.get(prev..).unwrap_or_default());
    Ok(Cow::Owned(out))
}

/// Scan the field value starting at byte `start`. Returns where scanning continues and whether
/// another field follows (a comma was consumed) rather than the timestamp section.
fn field_value(
    text: &str,
    start: usize,
    key_start: usize,
    edits: &mut Vec<(usize, usize, &'static str)>,
) -> Result<(usize, bool), Fault> {
    let b = text.as_bytes();
    let at = |i: usize| b.get(i).copied();
    let key = text.get(key_start..start.saturating_sub(1)).unwrap_or("");
    let mut i = start;
    if at(i) == Some(b'"') {
        i += 1;
        loop {
            match at(i) {
                None => return Err(fault(start, format!("field `{key}`: unterminated string"))),
                Some(b'\\') => i += 2,
                Some(b'"') => break,
                Some(_) => i += 1,
            }
        }
        i += 1;
    } else {
        while let Some(c) = at(i) {
            if c == b',' || is_sep(c) || c == b'\\' {
                break;
            }
            i += 1;
        }
        if i == start {
            return Err(fault(start, format!("field `{key}` has no value")));
        }
        number_fixes(b.get(start..i).unwrap_or_default(), start, key, edits)?;
    }
    match at(i) {
        None => Ok((i, false)),
        Some(b',') => {
            if at(i + 1).is_none_or(is_sep) {
                return Err(fault(i, "field set ends with a comma"));
            }
            Ok((i + 1, true))
        }
        Some(c) if is_sep(c) => Ok((i, false)),
        Some(_) => Err(fault(
            i,
            format!("field `{key}`: unexpected character after the value"),
        )),
    }
}

/// A bare value that is neither a number nor one of Telegraf's booleans (`t`, `true`, `True`,
/// `TRUE` and the same for false): the crate would report only "No fields were provided".
/// NaN and infinities get their own words, since they are what a robot's float usually is.
fn not_a_value(tok: &[u8], start: usize, key: &str) -> Result<(), Fault> {
    const BOOLS: [&[u8]; 10] = [
        b"t", b"T", b"true", b"True", b"TRUE", b"f", b"F", b"false", b"False", b"FALSE",
    ];
    if BOOLS.contains(&tok) {
        return Ok(());
    }
    let text = String::from_utf8_lossy(tok);
    let lower = text.to_ascii_lowercase();
    let bare = lower.trim_start_matches(['+', '-']);
    let reason = if matches!(bare, "nan" | "inf" | "infinity") {
        format!(
            "field `{key}`: the value {text} is not a number line protocol accepts (only finite \
             numbers are; leave the field out, or send it as a string: {key}=\"{text}\")"
        )
    } else {
        format!(
            "field `{key}`: `{text}` is not a value (line protocol takes a number such as 1.5, \
             2i or 3u, true/false, or a string in double quotes)"
        )
    };
    Err(fault(start, reason))
}

/// Telegraf's number forms the crate does not share (see the module comment).
fn number_fixes(
    tok: &[u8],
    start: usize,
    key: &str,
    edits: &mut Vec<(usize, usize, &'static str)>,
) -> Result<(), Fault> {
    let Some(&first) = tok.first() else {
        return Ok(());
    };
    if !(first == b'-' || first == b'.' || first.is_ascii_digit()) {
        return not_a_value(tok, start, key);
    }
    let sign = usize::from(first == b'-');
    if tok.get(sign).is_some_and(u8::is_ascii_alphabetic) {
        return not_a_value(tok, start, key);
    }
    if let Some((&last, digits)) = tok.split_last()
        && (last == b'i' || last == b'u')
    {
        let digits = digits.get(sign..).unwrap_or_default();
        if digits.len() > 1 && digits.first() == Some(&b'0') {
            return Err(fault(
                start,
                format!("field `{key}`: integer with a leading zero"),
            ));
        }
        return Ok(());
    }
    let mantissa_end = tok
        .iter()
        .position(|&c| c == b'e' || c == b'E')
        .unwrap_or(tok.len());
    let mantissa = tok.get(sign..mantissa_end).unwrap_or_default();
    if mantissa.len() > 1 {
        if mantissa.first() == Some(&b'.') {
            edits.push((start + sign, start + sign, "0"));
        }
        if mantissa.last() == Some(&b'.') {
            edits.push((start + mantissa_end, start + mantissa_end, "0"));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn norm(s: &str) -> String {
        normalize(s).unwrap().into_owned()
    }

    #[test]
    fn rewrites_what_the_crate_reads_differently() {
        assert_eq!(norm("m\ta=1\t5"), "m a=1 5");
        assert_eq!(norm("m,t=x\x0b\x0ca=1 5"), "m,t=x  a=1 5");
        assert_eq!(
            norm("m a=.5,b=-.5,c=5.,d=5.e3,e=-5.E-2,f=0.5 1"),
            "m a=0.5,b=-0.5,c=5.0,d=5.0e3,e=-5.0E-2,f=0.5 1"
        );
        assert_eq!(norm(r"m\\x,t\\=v\\ f\\=1"), r"m\\\\x,t\\\\=v\\\\ f\\\\=1");
        assert_eq!(norm(r#"m s="a\\b" 1"#), r#"m s="a\\b" 1"#);
        assert!(matches!(normalize("m a=1 1"), Ok(Cow::Borrowed(_))));
    }

    #[test]
    fn rejects_what_telegraf_rejects() {
        for (bad, at) in [
            ("m a=007i 1", 4),
            ("m a=-01u 1", 4),
            ("m,a,b=c f=1", 2),
            ("m a,b=1", 2),
            ("m a=1, 1", 5),
            ("m a=1,", 5),
            ("m a= 1", 4),
            ("m a=\"open", 4),
            ("m a=\"x\"y 1", 7),
            ("m\0 a=1", 1),
        ] {
            let f = normalize(bad).unwrap_err();
            assert_eq!(f.at, at, "{bad:?}: {f:?}");
        }
        assert!(normalize("m a=0i,b=-0i,c=0u,d=10i 1").is_ok());
        assert!(normalize("m a=t,b=F,c=true,d=False,e=TRUE 1").is_ok());
        for (bad, at, says) in [
            ("m battery=NaN 1", 10, "the value NaN is not a number"),
            ("m x=1,battery=-inf 1", 14, "the value -inf is not a number"),
            (
                "m battery=+Infinity 1",
                10,
                "the value +Infinity is not a number",
            ),
            ("m battery=full 1", 10, "`full` is not a value"),
        ] {
            let f = normalize(bad).unwrap_err();
            assert_eq!(f.at, at, "{bad:?}: {f:?}");
            assert!(f.reason.contains(says), "{bad:?}: {f:?}");
            assert!(f.reason.contains("field `battery`"), "{bad:?}: {f:?}");
        }
        assert!(normalize("m s=\"nul \0 inside\" 1").is_ok());
    }
}
