//! Writing line protocol that Telegraf's parser reads back unchanged.
//!
//! Owns: escaping of measurements, tag keys/values and field keys (Telegraf's serializer rules:
//! tab/LF/FF/CR as `\t` `\n` `\f` `\r`, comma and space (and `=` outside measurements)
//! backslash-escaped, trailing backslashes dropped), string field values (`"` and `\` escaped),
//! and value formatting (Float shortest round-trip with no exponent, Int `5i`, UInt `5u`).
//! Hand-written instead of the crate's builder, which writes NaN/inf, empty tag values and raw
//! newlines in tags that Telegraf rejects (research note §5.3).

use crate::parse::FieldValue;
use std::fmt::Write as _;

/// A Float that is NaN or infinite cannot be written as line protocol.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NotFinite;

fn escape_name(out: &mut String, s: &str, escape_eq: bool) {
    let s = s.trim_end_matches('\\');
    for c in s.chars() {
        match c {
            '\t' => out.push_str("\\t"),
            '\n' => out.push_str("\\n"),
            '\u{c}' => out.push_str("\\f"),
            '\r' => out.push_str("\\r"),
            ',' | ' ' => {
                out.push('\\');
                out.push(c);
            }
            '=' if escape_eq => out.push_str("\\="),
            c => out.push(c),
        }
    }
}

/// Builds one line: `measurement[,tags] fields [timestamp]\n`. Fields with non-finite floats are
/// skipped (counted in [`LineWriter::finish`]'s result); a line with no field is not written.
#[derive(Debug)]
pub struct LineWriter {
    line: String,
    fields: usize,
    in_fields: bool,
    skipped: usize,
}

impl LineWriter {
    pub fn new(measurement: &str) -> LineWriter {
        let mut line = String::with_capacity(64);
        escape_name(&mut line, measurement, false);
        LineWriter {
            line,
            fields: 0,
            in_fields: false,
            skipped: 0,
        }
    }

    /// Add a tag (before any field). Tags with an empty key or value are skipped, as Telegraf does.
    pub fn tag(&mut self, key: &str, value: &str) -> &mut Self {
        if self.in_fields
            || key.trim_end_matches('\\').is_empty()
            || value.trim_end_matches('\\').is_empty()
        {
            return self;
        }
        self.line.push(',');
        escape_name(&mut self.line, key, true);
        self.line.push('=');
        escape_name(&mut self.line, value, true);
        self
    }

    /// Add a field; a NaN or infinite Float is skipped and counted.
    pub fn field(&mut self, key: &str, value: &FieldValue) -> &mut Self {
        if let FieldValue::Float(f) = value
            && !f.is_finite()
        {
            self.skipped += 1;
            return self;
        }
        self.line.push(if self.in_fields { ',' } else { ' ' });
        self.in_fields = true;
        escape_name(&mut self.line, key, true);
        self.line.push('=');
        // write_value cannot fail here: non-finite floats were filtered above.
        let _ = write_value(&mut self.line, value);
        self.fields += 1;
        self
    }

    /// The finished line (with `\n`), or `None` when every field was skipped; and the number of
    /// fields skipped for being NaN or infinite.
    pub fn finish(mut self, timestamp: Option<i64>) -> (Option<String>, usize) {
        if self.fields == 0 {
            return (None, self.skipped);
        }
        if let Some(ts) = timestamp {
            let _ = write!(self.line, " {ts}");
        }
        self.line.push('\n');
        (Some(self.line), self.skipped)
    }
}

/// Append a field value in line-protocol form.
pub fn write_value(out: &mut String, value: &FieldValue) -> Result<(), NotFinite> {
    match value {
        FieldValue::Float(f) if !f.is_finite() => return Err(NotFinite),
        // Rust's Display for f64 is the shortest round-trip form and never uses an exponent.
        FieldValue::Float(f) => {
            let _ = write!(out, "{f}");
        }
        FieldValue::Int(i) => {
            let _ = write!(out, "{i}i");
        }
        FieldValue::UInt(u) => {
            let _ = write!(out, "{u}u");
        }
        FieldValue::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
        FieldValue::Str(s) => {
            out.push('"');
            for c in s.chars() {
                if c == '"' || c == '\\' {
                    out.push('\\');
                }
                out.push(c);
            }
            out.push('"');
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parse::parse_record;

    #[test]
    fn escapes_and_round_trips() {
        let mut w = LineWriter::new("my meas,x");
        w.tag("robot id", "a=b,c").tag("empty", "");
        w.field("speed", &FieldValue::Float(0.1))
            .field("n", &FieldValue::Int(-5))
            .field("u", &FieldValue::UInt(7))
            .field("ok", &FieldValue::Bool(true))
            .field("s", &FieldValue::Str("a \"q\" \\ \nz".into()))
            .field("whole", &FieldValue::Float(87.0))
            .field("bad", &FieldValue::Float(f64::NAN));
        let (line, skipped) = w.finish(Some(42));
        let line = line.unwrap();
        assert_eq!(skipped, 1);
        assert!(
            line.contains("whole=87,") || line.contains("whole=87 "),
            "{line}"
        );
        let m = parse_record(line.as_bytes()).unwrap().unwrap();
        assert_eq!(m.measurement, "my meas,x");
        assert_eq!(m.tags, vec![("robot id".to_string(), "a=b,c".to_string())]);
        assert_eq!(m.field("speed"), Some(&FieldValue::Float(0.1)));
        assert_eq!(
            m.field("s"),
            Some(&FieldValue::Str("a \"q\" \\ \nz".into()))
        );
        assert_eq!(m.field("bad"), None);
        assert_eq!(m.timestamp, Some(42));
    }

    #[test]
    fn a_line_without_fields_is_not_written() {
        let mut w = LineWriter::new("m");
        w.field("x", &FieldValue::Float(f64::INFINITY));
        assert_eq!(w.finish(Some(1)), (None, 1));
    }

    #[test]
    fn large_and_small_floats_have_no_exponent() {
        let mut s = String::new();
        write_value(&mut s, &FieldValue::Float(1e21)).unwrap();
        s.push(' ');
        write_value(&mut s, &FieldValue::Float(1e-7)).unwrap();
        assert_eq!(s, "1000000000000000000000 0.0000001");
    }
}
