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

use crate::list::{Capture, ListKey};
use crate::metric::{FieldValue, Metric};
use std::cell::Cell;

/// A byte allowed in a plain name or tag value: printable, not a line-protocol delimiter.
/// Bytes >= 0x80 belong to UTF-8 characters (the record was validated as UTF-8 before).
#[inline]
fn plain(b: u8) -> bool {
    PLAIN[usize::from(b)]
}

/// [`plain`] as a table: names are scanned a byte at a time (364 keys in a lidar record), and a
/// lookup is cheaper than the six comparisons it replaces.
static PLAIN: [bool; 256] = {
    let mut t = [false; 256];
    let mut b = 0;
    while b < 256 {
        let c = b as u8;
        t[b] = c > b' ' && c != b',' && c != b'=' && c != b'\\' && c != b'"' && c != 0x7f;
        b += 1;
    }
    t
};

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
        (self.i > start)
            .then(|| self.s.get(start..self.i))
            .flatten()
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
#[cfg(test)]
pub(crate) fn parse_plain(text: &str) -> Option<Metric> {
    let mut m = Metric::default();
    parse_plain_into(text, &mut m).then_some(m)
}

/// Overwrite `m` with `text`'s metric when `text` is plain (true); `m`'s strings and vectors are
/// reused, so a steady stream of records allocates nothing here. On false `m` holds garbage.
pub(crate) fn parse_plain_into(text: &str, m: &mut Metric) -> bool {
    parse_into(text, m).is_some()
}

fn set(dst: &mut String, src: &str) {
    dst.clear();
    dst.push_str(src);
}

fn parse_into(text: &str, m: &mut Metric) -> Option<()> {
    let text = text.strip_suffix('\n').unwrap_or(text);
    let text = text.strip_suffix('\r').unwrap_or(text);
    let mut c = Cursor { s: text, i: 0 };
    if c.peek() == Some(b'#') {
        return None;
    }
    set(&mut m.measurement, c.name()?);
    let mut nt = 0;
    while c.eat(b',') {
        let k = c.name()?;
        if !c.eat(b'=') {
            return None;
        }
        let v = c.name()?;
        if m.tags.iter().take(nt).any(|(tk, _)| tk == k) {
            return None;
        }
        match m.tags.get_mut(nt) {
            Some((tk, tv)) => {
                set(tk, k);
                set(tv, v);
            }
            None => m.tags.push((k.to_string(), v.to_string())),
        }
        nt += 1;
    }
    m.tags.truncate(nt);
    if !c.eat(b' ') {
        return None;
    }
    // Two copies of the field loop: a record without a list to read apart pays no test for it.
    let nf = match m.list.active() {
        Some(cap) => {
            cap.begin();
            read_fields::<true>(&mut c, &mut m.fields, Some(cap))?
        }
        None => read_fields::<false>(&mut c, &mut m.fields, None)?,
    };
    m.fields.truncate(nf);
    m.timestamp = match c.peek() {
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
            Some(timestamp(digits, digits.len() != t.len())?)
        }
        Some(_) => return None,
    };
    if has_duplicate_keys(&m.fields) {
        return None;
    }
    m.overwritten = 0;
    Some(())
}

/// A timestamp's value from its digits (checked to be ASCII digits, without sign), `neg` when a
/// `-` preceded them; `None` outside i64 (what `str::parse::<i64>` gives, without its generic
/// radix handling: every record has a 19-digit timestamp).
#[inline]
fn timestamp(digits: &str, neg: bool) -> Option<i64> {
    let b = digits.as_bytes();
    let v = if b.len() <= 19 {
        // At most 19 digits are below 10^19 < 2^64: no overflow to check. Read eight at a time
        // (a nanosecond timestamp is 19 digits: three alone, then two blocks of eight).
        let (head, blocks) = b.split_at(b.len() % 8);
        let mut v: u64 = 0;
        for &d in head {
            v = v * 10 + u64::from(d - b'0');
        }
        for block in blocks.chunks_exact(8) {
            let eight = block.first_chunk::<8>().map_or(0, |c| eight_digits(*c));
            v = v * 100_000_000 + eight;
        }
        v
    } else {
        let mut v: u64 = 0;
        for &d in b {
            v = v.checked_mul(10)?.checked_add(u64::from(d - b'0'))?;
        }
        v
    };
    if neg {
        0i64.checked_sub_unsigned(v)
    } else {
        i64::try_from(v).ok()
    }
}

/// The value of eight ASCII digits, the first the most significant: all eight at once in one
/// 64-bit word (pairs, then fours, then the eight: three multiplies instead of eight).
#[inline(always)]
fn eight_digits(block: [u8; 8]) -> u64 {
    let v = u64::from_le_bytes(block).wrapping_sub(0x3030_3030_3030_3030);
    // Each even byte: ten times its digit plus the next (at most 99, no carry).
    let v = v.wrapping_mul(10).wrapping_add(v >> 8);
    let pairs_02 = v & 0x0000_00ff_0000_00ff;
    let pairs_13 = (v >> 16) & 0x0000_00ff_0000_00ff;
    (pairs_02
        .wrapping_mul(100 + (1_000_000 << 32))
        .wrapping_add(pairs_13.wrapping_mul(1 + (10_000 << 32))))
        >> 32
}

/// A whole string that is a short decimal float (`-?int(.frac)?`, at most 15 digits, no leading
/// zero, nothing around it): its value, exactly what `str::parse::<f64>` gives; `None` for any
/// other string (the caller then parses it the general way).
pub fn short_decimal(s: &str) -> Option<f64> {
    match short_float(s.as_bytes(), 0) {
        Some((f, end)) if end == s.len() => Some(f),
        _ => None,
    }
}

/// One field value at the cursor, consumed, written into `out` (a string slot keeps its buffer).
/// The usual value, a short decimal float (360 in a lidar record), is tried first and written
/// over the slot's float in place; anything else is read by [`other_value`].
#[inline]
fn value(c: &mut Cursor<'_>, out: &mut FieldValue) -> Option<()> {
    let Some((f, end)) = short_float(c.s.as_bytes(), c.i) else {
        return other_value(c, out);
    };
    match out {
        // The slot held a float: overwritten in place, nothing to drop.
        FieldValue::Float(x) => *x = f,
        other => *other = FieldValue::Float(f),
    }
    c.i = end;
    Some(())
}

/// The field set at the cursor: each field into `fields` (reusing its slots), or, with
/// `CAPTURE`, each element of the list into `capture` (see [`Capture`]). The count of `fields`
/// used; `None` when the record is not plain (or its list needs the full path).
#[inline(always)]
fn read_fields<const CAPTURE: bool>(
    c: &mut Cursor<'_>,
    fields: &mut Vec<(String, FieldValue)>,
    mut capture: Option<&mut Capture>,
) -> Option<usize> {
    let mut nf = 0;
    loop {
        // A run of list elements (the usual fields of a lidar record).
        if CAPTURE && let Some(cap) = capture.as_deref_mut() {
            match elements(cap, c)? {
                Run::FieldsEnd => break,
                Run::OtherKey => {}
            }
        }
        let k = c.name()?;
        if !c.eat(b'=') {
            return None;
        }
        if CAPTURE && let Some(cap) = capture.as_deref_mut() {
            match cap.classify(k.as_bytes()) {
                ListKey::Other => {}
                ListKey::Element(i) => {
                    if !cap.set(i, float_value(c)?) {
                        return None;
                    }
                    if !c.eat(b',') {
                        break;
                    }
                    continue;
                }
                ListKey::Unusual => return None,
            }
        }
        match fields.get_mut(nf) {
            Some((fk, fv)) => {
                set(fk, k);
                value(c, fv)?;
            }
            None => {
                let mut fv = FieldValue::Bool(false);
                value(c, &mut fv)?;
                fields.push((k.to_string(), fv));
            }
        }
        nf += 1;
        if !c.eat(b',') {
            break;
        }
    }
    Some(nf)
}

/// Where a run of list elements stopped.
enum Run {
    /// The last field was an element.
    FieldsEnd,
    /// The cursor is at a key that is not read as an element.
    OtherKey,
}

/// The list elements from the cursor on, each key read once, until a key that is not
/// `<prefix><canonical index>=` (a tight loop of its own: 360 of them in a lidar record).
/// `None`: a repeated element or one that is not a Float, which the full path reads.
#[inline]
fn elements(cap: &mut Capture, c: &mut Cursor<'_>) -> Option<Run> {
    while let Some((i, at)) = cap.element_at(c.s.as_bytes(), c.i) {
        c.i = at;
        if !cap.set(i, float_value(c)?) {
            return None;
        }
        if !c.eat(b',') {
            return Some(Run::FieldsEnd);
        }
    }
    Some(Run::OtherKey)
}

/// A Float value at the cursor, consumed (`None` for any other value).
#[inline(always)]
fn float_value(c: &mut Cursor<'_>) -> Option<f64> {
    if let Some((f, end)) = short_float(c.s.as_bytes(), c.i) {
        c.i = end;
        return Some(f);
    }
    let mut v = FieldValue::Bool(false);
    other_value(c, &mut v)?;
    match v {
        FieldValue::Float(f) if f.is_finite() => Some(f),
        _ => None,
    }
}

/// [`value`] for a string, a boolean, an integer or a float that is not short.
#[inline(never)]
fn other_value(c: &mut Cursor<'_>, out: &mut FieldValue) -> Option<()> {
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
        match out {
            FieldValue::Str(dst) => set(dst, s),
            other => *other = FieldValue::Str(s.to_string()),
        }
        return Some(());
    }
    while b.get(c.i).is_some_and(|&x| x != b',' && x != b' ') {
        c.i += 1;
    }
    let tok = c.s.get(start..c.i)?;
    *out = match tok {
        "true" => FieldValue::Bool(true),
        "false" => FieldValue::Bool(false),
        _ => number(tok)?,
    };
    Some(())
}

/// The usual field value, a short decimal float (`-?int(.frac)?`, at most 15 digits, no
/// leading zero), read in the same pass that finds its end: its value (the same arithmetic as
/// [`number`]) and the index after it. `None` for anything else, which [`number`] then reads.
#[inline]
fn short_float(b: &[u8], start: usize) -> Option<(f64, usize)> {
    let neg = b.get(start) == Some(&b'-');
    let mut i = start + usize::from(neg);
    let int_start = i;
    let mut mantissa: u64 = 0;
    while let Some(d) = b.get(i).filter(|d| d.is_ascii_digit()) {
        mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(d - b'0'));
        i += 1;
    }
    let int_len = i - int_start;
    if int_len == 0 || (int_len > 1 && b.get(int_start) == Some(&b'0')) {
        return None;
    }
    let mut frac_len = 0;
    if b.get(i) == Some(&b'.') {
        i += 1;
        while let Some(d) = b.get(i).filter(|d| d.is_ascii_digit()) {
            mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(d - b'0'));
            i += 1;
            frac_len += 1;
        }
        if frac_len == 0 {
            return None;
        }
    }
    if !matches!(b.get(i), None | Some(b',' | b' ')) || int_len + frac_len > 15 {
        return None;
    }
    // At most 15 digits: below 2^63, so the signed conversion (one instruction) is exact.
    let x = mantissa as i64 as f64 / POW10.get(frac_len)?;
    Some((if neg { -x } else { x }, i))
}

/// Powers of ten exactly representable as f64.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// A decimal number token: `-?int(.frac)?` float, `-?int` followed by `i`, `int` followed by `u`.
/// Short floats (at most 15 digits) are computed as `digits / 10^frac` (exact operands, one
/// correctly rounded division: Clinger's fast path, the same value `str::parse` gives); longer
/// ones and integers near the limits go through `str::parse`.
#[inline]
fn number(tok: &str) -> Option<FieldValue> {
    let (num, kind) = match tok.as_bytes().last()? {
        b'i' => (tok.get(..tok.len() - 1)?, b'i'),
        b'u' => (tok.get(..tok.len() - 1)?, b'u'),
        _ => (tok, b'f'),
    };
    let unsigned = num.strip_prefix('-').unwrap_or(num);
    let neg = unsigned.len() != num.len();
    let b = unsigned.as_bytes();
    let mut mantissa: u64 = 0;
    let mut int_len = 0;
    while let Some(d) = b.get(int_len).filter(|d| d.is_ascii_digit()) {
        mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(d - b'0'));
        int_len += 1;
    }
    if int_len == 0 || (int_len > 1 && b.first() == Some(&b'0')) {
        return None;
    }
    let mut frac_len = None;
    if b.get(int_len) == Some(&b'.') {
        let mut n = 0;
        while let Some(d) = b.get(int_len + 1 + n).filter(|d| d.is_ascii_digit()) {
            mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(d - b'0'));
            n += 1;
        }
        if n == 0 {
            return None;
        }
        frac_len = Some(n);
    }
    let len = int_len + frac_len.map_or(0, |n| n + 1);
    if len != b.len() {
        return None;
    }
    match (kind, frac_len) {
        (b'f', f) => {
            let digits = int_len + f.unwrap_or(0);
            match POW10.get(f.unwrap_or(0)) {
                Some(p) if digits <= 15 => {
                    let x = mantissa as f64 / p;
                    Some(FieldValue::Float(if neg { -x } else { x }))
                }
                _ => finite(num.parse::<f64>().ok()?),
            }
        }
        (b'i', None) => num.parse::<i64>().ok().map(FieldValue::Int),
        (b'u', None) if !neg => num.parse::<u64>().ok().map(FieldValue::UInt),
        _ => None,
    }
}

#[inline]
fn finite(f: f64) -> Option<FieldValue> {
    f.is_finite().then_some(FieldValue::Float(f))
}

/// Whether two fields share a key: quadratic for the usual handful of fields; for long records
/// (the 360-beam lidar line) an open-addressing table of the keys seen so far, each slot holding
/// a field's index and 21 more bits of its key's hash, so that only a key whose slot and hash
/// bits both match is compared with the earlier key (almost never, unless it is a repeat).
fn has_duplicate_keys(fields: &[(String, FieldValue)]) -> bool {
    if fields.len() <= 16 {
        return fields
            .iter()
            .enumerate()
            .any(|(i, (k, _))| fields.iter().skip(i + 1).any(|(o, _)| o == k));
    }
    if fields.len() > MAX_TABLE_FIELDS {
        // Records this wide are hostile input (100k fields): an exact set keeps it linear.
        let mut keys = std::collections::HashSet::with_capacity(fields.len());
        return !fields.iter().all(|(k, _)| keys.insert(k.as_str()));
    }
    KEY_TABLE.with(|cell| {
        let (mut table, generation) = cell.take();
        let generation = generation.wrapping_add(1);
        if generation == 0 || table.len() < TABLE_SLOTS {
            // New, or every stamp used once: start again from an empty table.
            table.clear();
            table.resize(TABLE_SLOTS, 0);
        }
        let generation = generation.max(1);
        let found = table_has_duplicate_keys(fields, &mut table, u64::from(generation) << 32);
        cell.set((table, generation));
        found
    })
}

/// [`has_duplicate_keys`] with the table: a slot is taken when it carries `stamp` (this record's
/// generation in the high 32 bits), so the table is never cleared between records. At most half
/// of the slots used are full, so a probe ends after a slot or two.
fn table_has_duplicate_keys(
    fields: &[(String, FieldValue)],
    table: &mut [u64],
    stamp: u64,
) -> bool {
    let mask = (fields.len() * 2).next_power_of_two() - 1;
    for (i, (k, _)) in fields.iter().enumerate() {
        let h = key_hash(k.as_bytes());
        // The stamp, 21 bits of the hash, the field's index + 1.
        let entry = stamp | (h >> 32 & TAG_BITS) | (i as u64 + 1);
        let mut s = h as usize & mask;
        loop {
            let Some(slot) = table.get_mut(s) else {
                return true;
            };
            if *slot & STAMP_BITS != stamp {
                *slot = entry;
                break;
            }
            if *slot & !INDEX_BITS == entry & !INDEX_BITS {
                let earlier = (*slot & INDEX_BITS) as usize;
                if fields
                    .get(earlier.wrapping_sub(1))
                    .is_some_and(|(o, _)| o == k)
                {
                    return true;
                }
            }
            s = (s + 1) & mask;
        }
    }
    false
}

thread_local! {
    /// The table of [`has_duplicate_keys`] and the generation of its last record.
    static KEY_TABLE: Cell<(Vec<u64>, u32)> = const { Cell::new((Vec::new(), 0)) };
}

/// The widest record [`has_duplicate_keys`] checks with its table (index + 1 fits the low bits).
const MAX_TABLE_FIELDS: usize = 1024;
/// Slots for the widest record: twice its fields.
const TABLE_SLOTS: usize = 2 * MAX_TABLE_FIELDS;
/// The bits of a slot holding the field's index + 1, the hash bits, the generation stamp.
const INDEX_BITS: u64 = 0x7ff;
const TAG_BITS: u64 = 0xffff_f800;
const STAMP_BITS: u64 = 0xffff_ffff_0000_0000;

/// A key's hash (rustc-hash's, as the record digest uses: a few instructions for a short key).
#[inline]
fn key_hash(key: &[u8]) -> u64 {
    use std::hash::Hasher;
    let mut h = rustc_hash::FxHasher::default();
    h.write(key);
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parse::parse_record_full;

    #[test]
    fn timestamps_read_as_str_parse_reads_them() {
        for t in [
            "0",
            "1",
            "1700000000000000000",
            "9223372036854775807",
            "9223372036854775808",
            "-9223372036854775808",
            "-9223372036854775809",
            "18446744073709551616",
            "99999999999999999999999",
            "-1",
        ] {
            let digits = t.strip_prefix('-').unwrap_or(t);
            assert_eq!(
                timestamp(digits, digits.len() != t.len()),
                t.parse::<i64>().ok(),
                "{t}"
            );
        }
    }

    /// Timestamps of every length read as `str::parse` reads them (the eight-digit blocks).
    #[test]
    fn random_timestamps_read_as_str_parse_reads_them() {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0x5eed_7153);
        let mut next = move || rand::RngCore::next_u64(&mut rng);
        for _ in 0..200_000 {
            let len = 1 + (next() % 22) as usize;
            let mut t: String = (0..len)
                .map(|_| char::from(b'0' + (next() % 10) as u8))
                .collect();
            if len > 1 && t.starts_with('0') {
                t.replace_range(..1, "1");
            }
            if next() % 4 == 0 {
                t.insert(0, '-');
            }
            let digits = t.strip_prefix('-').unwrap_or(&t);
            assert_eq!(
                timestamp(digits, digits.len() != t.len()),
                t.parse::<i64>().ok(),
                "{t}"
            );
        }
        assert_eq!(eight_digits(*b"01234567"), 1_234_567);
        assert_eq!(eight_digits(*b"99999999"), 99_999_999);
    }

    /// A short decimal string reads as `str::parse` reads it; anything else is left to it.
    #[test]
    fn short_decimal_strings_equal_str_parse() {
        for s in [
            "0.0226",
            "-0.5",
            "5",
            "-0",
            "123456789012345",
            "0.00000000000001",
        ] {
            assert_eq!(short_decimal(s), s.parse::<f64>().ok(), "{s}");
        }
        for s in [
            "",
            " 0.5",
            "0.5 ",
            "+1",
            "1.",
            ".5",
            "01",
            "1e3",
            "0.5,",
            "1234567890123456",
            "nan",
        ] {
            assert_eq!(short_decimal(s), None, "{s}");
        }
    }

    #[test]
    fn the_plain_table_is_the_rule() {
        for b in 0..=255u8 {
            let rule = b > b' ' && !b",=\\\"".contains(&b) && b != 0x7f;
            assert_eq!(plain(b), rule, "{b}");
        }
    }

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
            "m a=-0,b=-0.0,c=0.000000000000001,d=999999999999999,e=9999999999999999,f=0.0000000000000000000001 1",
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

    /// Short decimals take the division fast path; it must agree with `str::parse` exactly.
    #[test]
    fn short_decimals_equal_str_parse() {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0x9e37_79b9);
        for _ in 0..200_000 {
            let seed = rand::RngCore::next_u64(&mut rng);
            let int = seed % 100_000;
            let frac_len = ((seed >> 20) % 12) as usize;
            let frac = (seed >> 32) % 10u64.pow(frac_len as u32);
            let tok = if frac_len == 0 {
                format!("{int}")
            } else {
                format!("{int}.{frac:0frac_len$}")
            };
            let want: f64 = tok.parse().unwrap();
            assert_eq!(number(&tok), Some(FieldValue::Float(want)), "{tok}");
            let neg = format!("-{tok}");
            assert_eq!(number(&neg), Some(FieldValue::Float(-want)), "{neg}");
        }
    }

    /// The one-pass reader of short floats gives `number`'s value and ends where the token ends.
    #[test]
    fn short_float_equals_number() {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0x2545_f491);
        let mut next = move || rand::RngCore::next_u64(&mut rng);
        let alphabet = b"0123456789.-iue,";
        for _ in 0..300_000 {
            let mut tok = Vec::new();
            for _ in 0..(next() % 19) {
                tok.push(alphabet[(next() % alphabet.len() as u64) as usize]);
            }
            let text = String::from_utf8(tok).unwrap();
            let end = text.find([',', ' ']).unwrap_or(text.len());
            let want = number(&text[..end]);
            match short_float(text.as_bytes(), 0) {
                Some((f, i)) => {
                    assert_eq!(i, end, "{text}");
                    assert_eq!(want, Some(FieldValue::Float(f)), "{text}");
                }
                None => assert!(
                    !matches!(want, Some(FieldValue::Float(_)))
                        || text[..end].len() > 15
                        || text[..end].trim_start_matches('-').len() > 15,
                    "{text}: {want:?}"
                ),
            }
        }
    }

    #[test]
    fn a_reused_metric_holds_exactly_the_new_record() {
        let mut m = Metric::default();
        for line in [
            "m,a=1,b=2 s=\"x\",f=1,g=2i,h=true 5",
            "n x=\"long string\" 6",
            "o,t=v y=2u",
            "m,a=1,b=2 s=\"x\",f=1,g=2i,h=true 5",
        ] {
            assert!(parse_plain_into(line, &mut m));
            assert_eq!(Some(&m), parse_plain(line).as_ref(), "{line}");
            assert_eq!(Ok(Some(m.clone())), parse_record_full(line.as_bytes()));
        }
    }

    /// The table finds exactly the repeated keys a set finds, at every width it serves and past it.
    #[test]
    fn duplicate_keys_found_as_a_set_finds_them() {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0x2545_f491);
        let mut next = move || rand::RngCore::next_u64(&mut rng);
        for round in 0..3000 {
            let n = match round % 6 {
                0 => (next() % 20) as usize,
                1 => 360 + (next() % 8) as usize,
                2 => 1000 + (next() % 40) as usize,
                _ => (next() % 400) as usize,
            };
            let mut fields: Vec<(String, FieldValue)> = (0..n)
                .map(|i| {
                    let k = match round % 3 {
                        0 => format!("lidar_{i}"),
                        1 => format!("k{}", next() % 100_000),
                        _ => format!("{:x}", next() % (1 << (next() % 40 + 1))),
                    };
                    (k, FieldValue::Bool(true))
                })
                .collect();
            if n > 1 && round % 4 == 0 {
                // Repeat one key somewhere later.
                let a = (next() % n as u64) as usize;
                let b = (next() % n as u64) as usize;
                let k = fields[a.min(b)].0.clone();
                fields[a.max(b)].0 = k;
            }
            let mut set = std::collections::HashSet::new();
            let want = !fields.iter().all(|(k, _)| set.insert(k.clone()));
            assert_eq!(
                has_duplicate_keys(&fields),
                want,
                "round {round}, {n} fields"
            );
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

    /// Reading a list's elements apart gives the metric a parser that reads them as fields
    /// gives (field order aside), or takes the full path and captures nothing; a bad record is
    /// bad either way.
    #[test]
    fn a_list_read_apart_holds_what_the_fields_hold() {
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0x2545_f491);
        let mut next = move |m: u64| rand::RngCore::next_u64(&mut rng) % m;
        let keys = [
            "l_0",
            "l_1",
            "l_2",
            "l_10",
            "l_02",
            "l_+1",
            "l_",
            "l_x",
            "l_1x",
            "l",
            "x",
            "l_999",
            "l_1000",
            "l\\ 1",
            "l_123456789",
            "l_1234567890",
        ];
        let values = [
            "1",
            "0",
            "2.5",
            "-0.25",
            "3i",
            "4u",
            "true",
            "\"s\"",
            "1e3",
            "2.4749999046325684",
            "01",
            "1.",
            "NaN",
        ];
        let mut apart = Metric::default();
        apart.list.set_prefix(Some("l_"), 1000);
        let mut captured = 0;
        for _ in 0..20_000 {
            let n = 1 + next(8);
            let fields: Vec<String> = (0..n)
                .map(|_| {
                    let k = keys[next(keys.len() as u64) as usize];
                    let v = values[next(values.len() as u64) as usize];
                    format!("{k}={v}")
                })
                .collect();
            let line = format!("m,t=a {} 5", fields.join(","));
            let want = crate::parse_record(line.as_bytes());
            let got = crate::parse_record_into(line.as_bytes(), &mut apart);
            match (want, got) {
                (Ok(Some(mut want)), Ok(true)) => {
                    captured += usize::from(apart.list.holds_record());
                    let mut got = apart.with_list_as_fields();
                    got.fields.sort_by(|a, b| a.0.cmp(&b.0));
                    want.fields.sort_by(|a, b| a.0.cmp(&b.0));
                    assert_eq!(got, want, "{line}");
                }
                (Err(_), Err(_)) => assert!(!apart.list.holds_record(), "{line}"),
                (want, got) => panic!("{line}: {want:?} against {got:?}"),
            }
        }
        assert!(captured > 1000, "{captured}");
    }
}
