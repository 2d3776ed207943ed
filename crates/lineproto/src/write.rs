//! Writing line protocol that Telegraf's parser reads back unchanged.
//!
//! Owns: escaping of measurements, tag keys/values and field keys (Telegraf's serializer rules,
//! research note §2.1/§2.4: tab/LF/FF/CR as `\t` `\n` `\f` `\r`, comma and space (and `=`
//! outside measurements) backslash-escaped, backslashes themselves not escaped, trailing
//! backslashes dropped), string field values (`"` and `\` escaped), value formatting (Float in
//! shortest round-trip form with no exponent, Int `5i`, UInt `5u`), and [`LineWriter`] for whole
//! lines. Hand-written instead of the crate's builder, which writes NaN/inf, empty tag values and
//! raw newlines in tags that Telegraf rejects, and doubles backslashes Telegraf keeps doubled
//! (research note §5.3).
//!
//! Where a name cannot be represented exactly the writer stays valid rather than exact: other
//! control characters become `\xNN` text, and a backslash run of odd length right before a
//! character that gets escaped (or before `"`) gains one backslash, so that it cannot pair with
//! the escape (Telegraf's own serializer writes a broken line there).

use crate::parse::FieldValue;
use std::fmt::Write as _;

/// A Float that is NaN or infinite cannot be written as line protocol.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NotFinite;

/// The escape written for `c` in a name, if it needs one.
fn name_escape(c: char, escape_eq: bool) -> Option<&'static str> {
    Some(match c {
        '\t' => "\\t",
        '\n' => "\\n",
        '\u{c}' => "\\f",
        '\r' => "\\r",
        ',' => "\\,",
        ' ' => "\\ ",
        '=' if escape_eq => "\\=",
        _ => return None,
    })
}

fn escape_name(out: &mut String, s: &str, escape_eq: bool) {
    // Fast path: most names need no escape at all.
    if !s.bytes().any(|b| {
        b < b' ' || b == 0x7f || b == b'\\' || b == b',' || b == b' ' || (escape_eq && b == b'=')
    }) {
        out.push_str(s);
        return;
    }
    let mut run = 0usize; // pending backslashes
    for c in s.chars() {
        if c == '\\' {
            run += 1;
            continue;
        }
        let esc = name_escape(c, escape_eq);
        let other_control = esc.is_none() && c.is_control() && c.is_ascii();
        let pad = run % 2 == 1 && (esc.is_some() || other_control || c == '"');
        out.extend(std::iter::repeat_n('\\', run + usize::from(pad)));
        run = 0;
        match esc {
            Some(e) => out.push_str(e),
            None if other_control => {
                let _ = write!(out, "\\x{:02x}", u32::from(c));
            }
            None => out.push(c),
        }
    }
    // Trailing backslashes cannot be written (Telegraf's serializer drops them too).
}

/// Whether `name` can be written as a measurement Telegraf reads back: not empty, and not
/// starting with `#` (such a line is a comment) once trailing backslashes are dropped.
pub fn measurement_is_writable(name: &str) -> bool {
    let name = name.trim_end_matches('\\');
    !name.is_empty() && !name.starts_with('#')
}

/// Append an escaped measurement name (see [`measurement_is_writable`] for names that cannot be).
pub fn write_measurement(out: &mut String, name: &str) {
    escape_name(out, name, false);
}

/// Append an escaped tag key.
pub fn write_tag_key(out: &mut String, key: &str) {
    escape_name(out, key, true);
}

/// Append an escaped tag value.
pub fn write_tag_value(out: &mut String, value: &str) {
    escape_name(out, value, true);
}

/// Append an escaped field key.
pub fn write_field_key(out: &mut String, key: &str) {
    escape_name(out, key, true);
}

/// Append a field value in line-protocol form; NaN and infinite floats are refused.
pub fn write_field_value(out: &mut String, value: &FieldValue) -> Result<(), NotFinite> {
    write_value(out, value)
}

fn writable_name(s: &str) -> bool {
    !s.trim_end_matches('\\').is_empty()
}

/// Builds one line: `measurement[,tags] fields [timestamp]\n`. Fields with non-finite floats are
/// skipped (counted in [`LineWriter::finish`]'s result); a line with no field is not written.
#[derive(Debug)]
pub struct LineWriter {
    line: String,
    measurement_ok: bool,
    fields: usize,
    in_fields: bool,
    skipped: usize,
}

impl LineWriter {
    pub fn new(measurement: &str) -> LineWriter {
        // Room for a typical verdict metric (measurement, a few tags, several fields, timestamp)
        // without growing.
        let mut line = String::with_capacity(256);
        escape_name(&mut line, measurement, false);
        LineWriter {
            line,
            measurement_ok: measurement_is_writable(measurement),
            fields: 0,
            in_fields: false,
            skipped: 0,
        }
    }

    /// Add a tag (before any field). Tags with an empty key or value are skipped, as Telegraf does.
    pub fn tag(&mut self, key: &str, value: &str) -> &mut Self {
        if self.in_fields || !writable_name(key) || !writable_name(value) {
            return self;
        }
        self.line.push(',');
        escape_name(&mut self.line, key, true);
        self.line.push('=');
        escape_name(&mut self.line, value, true);
        self
    }

    /// Add a field; a NaN or infinite Float, or an empty key, is skipped and counted.
    pub fn field(&mut self, key: &str, value: &FieldValue) -> &mut Self {
        let not_finite = matches!(value, FieldValue::Float(f) if !f.is_finite());
        if not_finite || !writable_name(key) {
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

    /// The finished line (with `\n`), or `None` when every field was skipped or the measurement
    /// cannot be written ([`measurement_is_writable`]); and the number of fields skipped for
    /// being NaN or infinite or having an empty key.
    pub fn finish(mut self, timestamp: Option<i64>) -> (Option<String>, usize) {
        if self.fields == 0 || !self.measurement_ok {
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
