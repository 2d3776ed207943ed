//! A hand-written fast path for the plain records Telegraf's serializers write most of the time.
//!
//! Owns: parsing, in one pass and without the `influxdb-line-protocol` crate, the records whose
//! every part is plain: names and tag values without escapes, spaces-only separators, quoted
//! strings without backslashes or line breaks, decimal numbers without exponent or leading zeros,
//! `true`/`false`, distinct tag keys. Anything else returns `None` and [`crate::parse_record`]
//! takes its full path (Telegraf's rules on top of the crate), so results never differ: the
//! tests compare both paths on every accepted form.
//!
//! Hand-written on purpose (house rule: say why): parsing through the crate plus the Telegraf
//! rule scan cost about 2 µs per two-field robot record, the largest part of the whole record
//! path; this path is several times faster (`cargo bench -p lineproto --bench codec`, groups
//! `parse_p2` and `parse_lidar360`, figures in BENCHMARKS.md).

use crate::parse::{FieldValue, Metric};

/// A byte allowed in a plain name or tag value: printable, not a line-protocol delimiter.
/// Bytes >= 0x80 belong to UTF-8 characters (the record was validated as UTF-8 before).
#[inline]
fn plain(b: u8) -> bool {
    b > b' ' && b != b',' && b != b'=' && b != b'\\' && b != b'"' && b != 0x7f
}

struct Cursor<'a> {
    s: &'a str,
    i: usize,
}

impl<'a> Cursor<'a> {
    #[inline]
    fn peek(&self) -> Option<u8> {
        self.s.as_bytes().get(self.i).copied()
    }

    /// A run of plain bytes (at least one).
    #[inline]
    fn name(&mut self) -> Option<&'a str> {
        let b = self.s.as_bytes();
        let start = self.i;
        while b.get(self.i).is_some_and(|&c| plain(c)) {
            self.i += 1;
        }
        // Plain bytes stop only at ASCII delimiters, so both ends are character boundaries.
        (self.i > start).then(|| self.s.get(start..self.i)).flatten()
    }

    #[inline]
    fn eat(&mut self, c: u8) -> bool {
        if self.peek() == Some(c) {
            self.i += 1;
            true
        } else {
            false
        }
    }
}

/// Parse `text` (one record, its line ending included or not) when it is plain; `None` otherwise.
pub(crate) fn parse_plain(text: &str) -> Option<Metric> {
    let text = text.strip_suffix('\n').unwrap_or(text);
    let text = text.strip_suffix('\r').unwrap_or(text);
    let mut c = Cursor { s: text, i: 0 };
    if c.peek() == Some(b'#') {
        return None;
    }
    let measurement = c.name()?.to_string();
    let mut tags: Vec<(String, String)> = Vec::new();
    while c.eat(b',') {
        let k = c.name()?;
        if !c.eat(b'=') {
            return None;
        }
        let v = c.name()?;
        if tags.iter().any(|(tk, _)| tk == k) {
            return None;
        }
        tags.push((k.to_string(), v.to_string()));
    }
    if !c.eat(b' ') {
        return None;
    }
    let mut fields: Vec<(String, FieldValue)> = Vec::new();
    loop {
        let k = c.name()?;
        if !c.eat(b'=') {
            return None;
        }
        let v = value(&mut c)?;
        fields.push((k.to_string(), v));
        if !c.eat(b',') {
            break;
        }
    }
    let timestamp = match c.peek() {
        None => None,
        Some(b' ') => {
            c.i += 1;
            let t = c.s.get(c.i..)?;
            let digits = t.strip_prefix('-').unwrap_or(t);
            if digits.is_empty()
                || !digits.bytes().all(|d| d.is_ascii_digit())
                || (digits.len() > 1 && digits.starts_with('0'))
            {
                return None;
            }
            Some(t.parse::<i64>().ok()?)
        }
        Some(_) => return None,
    };
    if has_duplicate_keys(&fields) {
        return None;
    }
    Some(Metric {
        measurement,
        tags,
        fields,
        timestamp,
    })
}

/// One field value at the cursor, consumed.
#[inline]
fn value(c: &mut Cursor<'_>) -> Option<FieldValue> {
    let b = c.s.as_bytes();
    let start = c.i;
    if c.eat(b'"') {
        let body = c.i;
        while let Some(&x) = b.get(c.i) {
            match x {
                b'"' => break,
                b'\\' | b'\n' | b'\r' => return None,
                _ => c.i += 1,
            }
        }
        let s = c.s.get(body..c.i)?;
        if !c.eat(b'"') {
            return None;
        }
        return Some(FieldValue::Str(s.to_string()));
    }
    while b.get(c.i).is_some_and(|&x| x != b',' && x != b' ') {
        c.i += 1;
    }
    let tok = c.s.get(start..c.i)?;
    match tok {
        "true" => return Some(FieldValue::Bool(true)),
        "false" => return Some(FieldValue::Bool(false)),
        _ => {}
    }
    let (num, kind) = match tok.as_bytes().last()? {
        b'i' => (tok.get(..tok.len() - 1)?, b'i'),
        b'u' => (tok.get(..tok.len() - 1)?, b'u'),
        _ => (tok, b'f'),
    };
    let unsigned = num.strip_prefix('-').unwrap_or(num);
    let (int, frac) = match unsigned.split_once('.') {
        Some((i, f)) => (i, Some(f)),
        None => (unsigned, None),
    };
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|d| d.is_ascii_digit());
    if !digits(int) || (int.len() > 1 && int.starts_with('0')) {
        return None;
    }
    match (kind, frac) {
        (b'f', None) => finite(num.parse::<f64>().ok()?),
        (b'f', Some(f)) if digits(f) => finite(num.parse::<f64>().ok()?),
        (b'i', None) => num.parse::<i64>().ok().map(FieldValue::Int),
        (b'u', None) if unsigned.len() == num.len() => num.parse::<u64>().ok().map(FieldValue::UInt),
        _ => None,
    }
}

#[inline]
fn finite(f: f64) -> Option<FieldValue> {
    f.is_finite().then_some(FieldValue::Float(f))
}

/// Whether two fields share a key: quadratic for the usual handful of fields, a sort of
/// borrowed keys for long records (the 360-beam lidar line).
fn has_duplicate_keys(fields: &[(String, FieldValue)]) -> bool {
    if fields.len() <= 16 {
        return fields
            .iter()
            .enumerate()
            .any(|(i, (k, _))| fields.iter().skip(i + 1).any(|(o, _)| o == k));
    }
    let mut keys: Vec<&str> = fields.iter().map(|(k, _)| k.as_str()).collect();
    keys.sort_unstable();
    keys.windows(2).any(|w| w.first() == w.last())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parse::parse_record_full;

    /// Every record the fast path accepts parses to the same metric on the full path.
    fn same(line: &str) -> bool {
        let fast = parse_plain(line);
        if let Some(m) = &fast {
            assert_eq!(
                parse_record_full(line.as_bytes()),
                Ok(Some(m.clone())),
                "{line:?}"
            );
        }
        fast.is_some()
    }

    #[test]
    fn plain_records_take_the_fast_path_with_the_full_paths_result() {
        for line in [
            "mqtt_consumer,host=turtlebot3,topic=tessla actualSpeed=\"0.0188\",expectedSpeed=0.015 1719231000123456789\n",
            "m a=1 1\r\n",
            "m a=-1.5,b=0,c=-0,d=10i,e=-7i,f=3u,g=true,h=false,s=\"x y,z=w\" -5",
            "m a=1",
            "m,t=ü f=\"ünï\" 0",
            "m s=\"\" 1",
            "m a=179769313486231570000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000.0 1",
            "m a=9223372036854775807i,b=18446744073709551615u 9223372036854775807",
            "m a=0.1,b=0.30000000000000004,c=123456789.987654321 1",
        ] {
            assert!(same(line), "{line:?} should be plain");
        }
    }

    #[test]
    fn anything_unusual_goes_to_the_full_path() {
        for line in [
            "# comment",
            " m a=1 1",
            "m\ta=1 1",
            "m  a=1 1",
            "m a=1  1",
            "m a=1 1 ",
            "m,t=a\\ b a=1 1",
            "m s=\"a\\\"b\" 1",
            "m s=\"a\nb\" 1",
            "m a=.5 1",
            "m a=5. 1",
            "m a=1e3 1",
            "m a=007i 1",
            "m a=01.5 1",
            "m a=-1u 1",
            "m a=1.5i 1",
            "m a=T 1",
            "m a=1,a=2 1",
            "m,t=1,t=2 a=1 1",
            "m a=1 007",
            "m a=1 99999999999999999999",
            "m a=99999999999999999999i 1",
            "m a=1,",
            "m a= 1",
            "m a 1",
            "m 1",
            "m,t= a=1 1",
            "m a=1x 1",
            "m a=NaN 1",
            "m a=\"open 1",
            "m a=1 1x",
            "m a=1 -",
            "",
        ] {
            assert!(!same(line), "{line:?} should not be plain");
        }
    }

    #[test]
    fn long_records_with_many_fields() {
        let mut line = String::from("m,host=h x=1");
        for i in 0..360 {
            line.push_str(&format!(",lidar_{i}={}.{}", i % 4, i));
        }
        line.push_str(" 17\n");
        assert!(same(&line));
        let dup = line.replace("lidar_7=", "lidar_8=");
        assert!(!same(&dup));
    }
}
