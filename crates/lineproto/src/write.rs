//! Writing line protocol that Telegraf's parser reads back unchanged.
//!
//! Owns: escaping of measurements, tag keys/values and field keys (Telegraf's serializer rules,
//! influxdata/telegraf `plugins/serializers/influx`, and what its parser reads back unchanged:
//! tab/LF/FF/CR as `\t` `\n` `\f` `\r`, comma and space (and `=` outside measurements)
//! backslash-escaped, backslashes themselves not escaped, trailing backslashes dropped), string
//! field values (`"` and `\` escaped), value formatting (Float in shortest round-trip form with no
//! exponent, Int `5i`, UInt `5u`), and [`LineWriter`] for whole lines. Hand-written instead of the
//! crate's builder, which writes NaN/inf, empty tag values and raw newlines in tags that Telegraf
//! rejects, and doubles backslashes Telegraf keeps doubled (`influxdb-line-protocol` 2.0.0's
//! builder, tried).
//!
//! Where a name cannot be represented exactly the writer stays valid rather than exact: other
//! control characters become `\xNN` text, and a backslash run of odd length right before a
//! character that gets escaped (or before `"`) gains one backslash, so that it cannot pair with
//! the escape (Telegraf's own serializer writes a broken line there).

use crate::metric::FieldValue;

/// A Float that is NaN or infinite cannot be written as line protocol.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NotFinite;

impl std::fmt::Display for NotFinite {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("a Float that is NaN or infinite cannot be written as line protocol")
    }
}

impl std::error::Error for NotFinite {}

/// Where the writers append: a `String`, or a byte buffer such as a processor's output (a
/// verdict line written straight into it, without a line buffer and its copy). Only UTF-8
/// text is appended.
pub trait Text {
    /// Append `s`.
    fn push_str(&mut self, s: &str);
    /// Append one ASCII byte (`b < 0x80`).
    fn push_ascii(&mut self, b: u8);
    /// Remove the last byte, which is ASCII.
    fn pop_ascii(&mut self);
}

impl Text for String {
    #[inline(always)]
    fn push_str(&mut self, s: &str) {
        String::push_str(self, s);
    }
    #[inline(always)]
    fn push_ascii(&mut self, b: u8) {
        self.push(char::from(b));
    }
    #[inline(always)]
    fn pop_ascii(&mut self) {
        self.pop();
    }
}

impl Text for Vec<u8> {
    #[inline(always)]
    fn push_str(&mut self, s: &str) {
        self.extend_from_slice(s.as_bytes());
    }
    #[inline(always)]
    fn push_ascii(&mut self, b: u8) {
        self.push(b);
    }
    #[inline(always)]
    fn pop_ascii(&mut self) {
        self.pop();
    }
}

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

fn escape_name<T: Text + ?Sized>(out: &mut T, s: &str, escape_eq: bool) {
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
        for _ in 0..run + usize::from(pad) {
            out.push_ascii(b'\\');
        }
        run = 0;
        match esc {
            Some(e) => out.push_str(e),
            None if other_control => out.push_str(&format!("\\x{:02x}", u32::from(c))),
            None => out.push_str(c.encode_utf8(&mut [0; 4])),
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
pub fn write_measurement<T: Text + ?Sized>(out: &mut T, name: &str) {
    escape_name(out, name, false);
}

/// Append an escaped tag key.
pub fn write_tag_key<T: Text + ?Sized>(out: &mut T, key: &str) {
    escape_name(out, key, true);
}

/// Append an escaped tag value.
pub fn write_tag_value<T: Text + ?Sized>(out: &mut T, value: &str) {
    escape_name(out, value, true);
}

/// Append an escaped field key.
pub fn write_field_key<T: Text + ?Sized>(out: &mut T, key: &str) {
    escape_name(out, key, true);
}

/// Append a field value in line-protocol form; NaN and infinite floats are refused.
pub fn write_field_value(out: &mut String, value: &FieldValue) -> Result<(), NotFinite> {
    write_value(out, value)
}

/// Append a timestamp (decimal nanoseconds).
pub fn write_timestamp<T: Text + ?Sized>(out: &mut T, ts: i64) {
    out.push_str(itoa::Buffer::new().format(ts));
}

/// Whether `name` can be written as a tag key, tag value or field key: not empty once trailing
/// backslashes are dropped ([`LineWriter`] skips such tags and fields).
pub fn name_is_writable(name: &str) -> bool {
    writable_name(name)
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
    /// A line for `measurement`; tags, then fields, then [`LineWriter::finish`].
    pub fn new(measurement: &str) -> LineWriter {
        // Room for a typical verdict metric (measurement, a few tags, several fields, timestamp)
        // without growing.
        LineWriter::with_buffer(measurement, String::with_capacity(256))
    }

    /// Like [`LineWriter::new`], building the line in `line` (cleared first): with
    /// [`LineWriter::finish_into`] one buffer serves every line, no allocation per line.
    pub fn with_buffer(measurement: &str, mut line: String) -> LineWriter {
        line.clear();
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
            self.line.push(' ');
            self.line.push_str(itoa::Buffer::new().format(ts));
        }
        self.line.push('\n');
        (Some(self.line), self.skipped)
    }

    /// Like [`LineWriter::finish`], appending the line (if any) to `out`; gives the buffer back
    /// for the next [`LineWriter::with_buffer`].
    pub fn finish_into(self, timestamp: Option<i64>, out: &mut Vec<u8>) -> (String, usize) {
        let mut line = String::new();
        let skipped = self.skipped;
        let (written, _) = self.finish_with(timestamp, &mut line);
        if written {
            out.extend_from_slice(line.as_bytes());
        }
        line.clear();
        (line, skipped)
    }

    fn finish_with(mut self, timestamp: Option<i64>, into: &mut String) -> (bool, usize) {
        let ok = self.fields > 0 && self.measurement_ok;
        if ok {
            if let Some(ts) = timestamp {
                self.line.push(' ');
                self.line.push_str(itoa::Buffer::new().format(ts));
            }
            self.line.push('\n');
        }
        *into = std::mem::take(&mut self.line);
        (ok, self.skipped)
    }
}

/// Append a field value in line-protocol form.
pub fn write_value(out: &mut String, value: &FieldValue) -> Result<(), NotFinite> {
    match value {
        FieldValue::Float(f) if !f.is_finite() => return Err(NotFinite),
        FieldValue::Float(f) => write_float(out, *f),
        FieldValue::Int(i) => write_int(out, *i),
        FieldValue::UInt(u) => {
            out.push_str(itoa::Buffer::new().format(*u));
            out.push('u');
        }
        FieldValue::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
        FieldValue::Str(s) => write_string(out, s),
    }
    Ok(())
}

/// Append an Int field value (`-5i`).
pub fn write_int<T: Text + ?Sized>(out: &mut T, i: i64) {
    out.push_str(itoa::Buffer::new().format(i));
    out.push_ascii(b'i');
}

/// Append a String field value, quoted, `"` and `\` escaped.
pub fn write_string<T: Text + ?Sized>(out: &mut T, s: &str) {
    out.push_ascii(b'"');
    // Runs without `"` or `\\` are copied whole.
    let mut rest = s;
    while let Some(i) = rest.find(['"', '\\']) {
        let (run, tail) = rest.split_at(i);
        out.push_str(run);
        out.push_ascii(b'\\');
        let (c, tail) = tail.split_at(1);
        out.push_str(c);
        rest = tail;
    }
    out.push_str(rest);
    out.push_ascii(b'"');
}

/// Append a finite float exactly as Rust's `Display` writes it: the shortest digits that read
/// back to the same value (the closest such when there are several), no exponent, no `.0`
/// (`87`, `-0`, `0.0000001`, `1000000000000000000000`).
///
/// The digits come from the `zmij` crate (dtolnay's successor to `ryu`, already in the tree
/// through serde_json; same shortest-and-closest rule as `Display`, faster:
/// `cargo bench -p lineproto --bench codec -- format_f64`; float formatting was the largest
/// single item of a P2 record's profile); only its exponent form is rewritten here. The two differ where the value lies exactly halfway
/// between two shortest candidates (zmij, like ryu, rounds such a tie to even, `Display` up:
/// exactly 1658206780088562.25 is `...562.2` for zmij, `...562.3` for `Display`); `is_tie` finds those
/// values exactly and they are written by `Display` itself. A test compares both on millions of
/// values.
pub fn write_float<T: Text + ?Sized>(out: &mut T, f: f64) {
    let mut buf = zmij::Buffer::new();
    let s = buf.format_finite(f);
    // Usual case: zmij wrote plain decimal form `-?\d+\.\d+` (at most 17 significant digits).
    // Its exponent form ends in `e` and two to four more bytes (`1e21`, `1.5e-308`), so only
    // those four places are looked at; the point is looked for (a short loop, not `str::find`'s
    // searcher) only where a tie is possible.
    let body = s.strip_prefix('-').unwrap_or(s);
    let bytes = body.as_bytes();
    let n = bytes.len();
    let at = |back: usize| n.checked_sub(back).and_then(|i| bytes.get(i)) == Some(&b'e');
    if !(at(2) || at(3) || at(4) || at(5)) {
        if bytes.ends_with(b".0") {
            // A whole number: below 2^53 exact, above it even, never halfway at this digit.
            if body.len() < 18 {
                out.push_str(s.get(..s.len() - 2).unwrap_or(s));
                return;
            }
        } else if body.len() < 17 || !may_tie(f) {
            // Too few digits for a tie (see below), or a binary exponent no tie has.
            out.push_str(s);
            return;
        } else if let Some(dot) = bytes.iter().position(|&b| b == b'.') {
            let frac_len = body.len() - dot - 1;
            if !is_tie(f, body.bytes(), -(frac_len as i32) - 1) {
                out.push_str(s);
            } else {
                out.push_str(&f.to_string());
            }
            return;
        }
    }
    let (neg, s) = match s.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, s),
    };
    let (mantissa, exp) = match s.split_once('e') {
        Some((m, e)) => (m, e.parse::<i32>().unwrap_or(0)),
        None => (s, 0),
    };
    let (int, frac) = mantissa.split_once('.').unwrap_or((mantissa, ""));
    // The significant digits `int ++ frac` without leading and trailing zeros, and where the
    // decimal point goes relative to their start (zmij writes at most 17 digits and a few zeros).
    let digits_all = int.len() + frac.len();
    let mut digits = [0u8; 40];
    let mut n = 0;
    for b in int.bytes().chain(frac.bytes()) {
        if let Some(d) = digits.get_mut(n) {
            *d = b;
        }
        n += 1;
    }
    let n = n.min(digits.len());
    let lead = digits.iter().take(n).take_while(|&&d| d == b'0').count();
    let trail = digits
        .iter()
        .take(n)
        .skip(lead)
        .rev()
        .take_while(|&&d| d == b'0')
        .count();
    let sig = digits.get(lead..n - trail).unwrap_or_default();
    if neg {
        out.push_ascii(b'-');
    }
    if sig.is_empty() {
        out.push_ascii(b'0');
        return;
    }
    let point = int.len() as i32 + exp - lead as i32;
    let len = sig.len() as i32;
    // Ties need more digits than a double's 15.65 decimal digits leave room for below 16.
    if n != digits_all || (len >= 16 && is_tie(f, sig.iter().copied(), point - len - 1)) {
        if neg {
            out.pop_ascii();
        }
        out.push_str(&f.to_string());
        return;
    }
    // `sig` holds ASCII digits only.
    let sig = std::str::from_utf8(sig).unwrap_or_default();
    if point <= 0 {
        out.push_str("0.");
        for _ in 0..-point {
            out.push_ascii(b'0');
        }
        out.push_str(sig);
    } else if point >= len {
        out.push_str(sig);
        for _ in 0..point - len {
            out.push_ascii(b'0');
        }
    } else {
        let (a, b) = sig.split_at(point as usize);
        out.push_str(a);
        out.push_ascii(b'.');
        out.push_str(b);
    }
}

/// Whether [`is_tie`] can hold for `f` at some scale: `|f| = m * 2^e` (`m` odd) with `e`
/// within 26 of zero. Most values with 17 digits (sensor readings, their differences) have `e`
/// near -60 and skip the search for the point.
#[inline]
fn may_tie(f: f64) -> bool {
    let bits = f.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i32;
    let frac = bits & ((1u64 << 52) - 1);
    let (m, e) = if biased == 0 {
        (frac, -1074)
    } else {
        (frac | (1u64 << 52), biased - 1075)
    };
    m != 0 && (e + m.trailing_zeros() as i32).unsigned_abs() <= 26
}

/// Whether `|f|` is exactly `(sig ++ "5") * 10^j` (`sig`'s digits, other bytes skipped), the midpoint between the decimal `sig` (at
/// the same scale) and its neighbour: exact integer arithmetic on `f = m * 2^e` (m odd), where
/// equality with the odd `N * 10^j = N * 5^j * 2^j` needs `e == j` and `m * 5^-j == N`
/// (or `m == N * 5^j`).
fn is_tie(f: f64, sig: impl Iterator<Item = u8>, j: i32) -> bool {
    let bits = f.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i32;
    let frac = bits & ((1u64 << 52) - 1);
    let (mut m, mut e) = if biased == 0 {
        (frac, -1074)
    } else {
        (frac | (1u64 << 52), biased - 1075)
    };
    if m == 0 {
        return false;
    }
    let tz = m.trailing_zeros();
    m >>= tz;
    e += tz as i32;
    if e != j || j.unsigned_abs() > 26 {
        return false;
    }
    let mut n: u128 = 0;
    for d in sig.filter(u8::is_ascii_digit) {
        n = n.saturating_mul(10).saturating_add(u128::from(d - b'0'));
    }
    let n = n * 10 + 5;
    let p = 5u128.pow(j.unsigned_abs());
    if j < 0 {
        u128::from(m) * p == n
    } else {
        u128::from(m) == n * p
    }
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

    fn check_float(f: f64) {
        let mut s = String::new();
        write_float(&mut s, f);
        assert_eq!(s, format!("{f}"), "bits {:#x}", f.to_bits());
    }

    /// `write_float` writes exactly what `Display` writes: on every kind of finite value (random
    /// bit patterns cover all exponents, short decimals are the usual sensor values, and the
    /// neighbours of powers of ten and of halfway cases are where two shortest forms compete).
    #[test]
    fn write_float_equals_display_on_millions_of_values() {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0x9e37_79b9);
        let mut next = move || rand::RngCore::next_u64(&mut rng);
        let mut n = 0;
        for _ in 0..1_000_000 {
            let f = f64::from_bits(next());
            if f.is_finite() {
                check_float(f);
                n += 1;
            }
        }
        for _ in 0..500_000 {
            let r = next();
            let scale = 10f64.powi((r % 12) as i32);
            let f = ((r >> 8) % 10_000_000) as f64 / scale;
            check_float(f);
            check_float(-f);
            check_float(f64::from_bits(f.to_bits() + 1));
            n += 3;
        }
        // Exact halves and quarters where 16 and 17 digits meet: ties between two candidates.
        for i in 0..200_000u64 {
            for (base, scale) in [(1u64 << 52, 0.25), (1u64 << 53, 0.5), (1u64 << 51, 0.125)] {
                check_float(((base + i * 7919) as f64) * scale);
                n += 1;
            }
        }
        for e in -324..=308 {
            let p: f64 = format!("1e{e}").parse().unwrap();
            for d in [-2i64, -1, 0, 1, 2] {
                let bits = (p.to_bits() as i64 + d) as u64;
                let f = f64::from_bits(bits);
                if f.is_finite() {
                    check_float(f);
                    n += 1;
                }
            }
        }
        for f in [
            0.0,
            -0.0,
            1.0,
            87.0,
            0.1,
            f64::MAX,
            f64::MIN,
            f64::MIN_POSITIVE,
            5e-324,
            -937625523621561.3,
            1e21,
            1e-7,
            123456789012345680.0,
        ] {
            check_float(f);
        }
        assert!(n > 2_000_000);
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
