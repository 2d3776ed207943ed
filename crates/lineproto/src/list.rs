//! The fields of one list pattern (`lidar_0`..`lidar_359` of `lidar_*`): their keys and the
//! array a record's elements can be read into.
//!
//! Owns: a pattern's prefix compared with keys ([`Prefix`]), the index in a key ([`list_index`],
//! the rule the binding of `<prefix>*` follows), and [`ListCapture`], the elements of one record
//! read straight into an array by the fast parser. Depends on nothing else in the crate.

/// The Float fields `<prefix><index>` of one list pattern (`lidar_0`..`lidar_359`), read by the
/// fast parser straight into an array by index instead of into the fields of a [`crate::Metric`]: a 360-beam
/// scan then costs no key string per beam, no duplicate-key table and no second pass to gather
/// the list. Off until [`ListCapture::set_prefix`] names a prefix.
///
/// A record's fields go here only when nothing about them is unusual; otherwise the record takes
/// the full parser, which captures nothing ([`ListCapture::holds_record`] is false), so the
/// consumers of a metric see either every element here or none. Taken here: a key of the prefix
/// and a canonical index (`0`, or digits without a leading zero, below the limit) with a Float
/// value, once. The full path for: a key of the prefix whose rest is another index form
/// ([`list_index`] takes it but it is not canonical: `007`, `+7`, past the limit), a canonical
/// key repeated, or holding anything but a Float. Keys of the prefix whose rest is no index at
/// all (`lidar_count`) stay ordinary fields.
#[derive(Debug, Clone, Default)]
pub struct ListCapture(Option<Box<Capture>>);

/// A [`ListCapture`] asked for: the prefix and the current record's elements.
#[derive(Debug, Clone, Default)]
pub(crate) struct Capture {
    prefix: Vec<u8>,
    /// [`Prefix`]'s word of `prefix`.
    word: Option<(u64, u64)>,
    /// Indices at or past this take the full path.
    limit: usize,
    /// Whether the parser captures (a prefix is set and every byte of it can be in a plain key).
    enabled: bool,
    /// By index, the record's elements: NaN where it has none (a captured value is never NaN:
    /// the parsers give finite floats only, so NaN marks a missing element and an element not
    /// yet seen).
    values: Vec<f64>,
    /// Whether the current record was captured.
    on: bool,
    count: usize,
    /// One past the largest index of the current record.
    len: usize,
}

/// What a field key is to a [`ListCapture`].
pub(crate) enum ListKey {
    /// Not an element of the list: an ordinary field.
    Other,
    /// The element at this canonical index.
    Element(usize),
    /// An element named another way: the record takes the full path.
    Unusual,
}

impl ListCapture {
    /// Capture the fields `<prefix><index>` with indices below `limit` (`None`: capture nothing;
    /// nor for a prefix with a byte a plain key cannot hold: a space, `,`, `=`, `\\`, `"`, a
    /// control byte).
    pub fn set_prefix(&mut self, prefix: Option<&str>, limit: usize) {
        match prefix.filter(|p| !p.is_empty()) {
            None => {
                if self.0.is_some() {
                    self.0 = None;
                }
            }
            Some(p) => {
                if self
                    .0
                    .as_ref()
                    .is_none_or(|c| c.prefix != p.as_bytes() || c.limit != limit)
                {
                    self.0 = Some(Box::new(Capture::new(p.as_bytes(), limit)));
                }
            }
        }
    }

    /// The prefix asked for (empty: none).
    pub fn prefix(&self) -> &[u8] {
        self.0.as_ref().map_or(&[], |c| &c.prefix)
    }

    /// The capture the parser is to fill, if one was asked for with a prefix it can take.
    #[inline]
    pub(crate) fn active(&mut self) -> Option<&mut Capture> {
        self.0.as_deref_mut().filter(|c| c.enabled)
    }

    /// The current record was not captured (the full parser read it).
    pub(crate) fn clear_record(&mut self) {
        if let Some(c) = &mut self.0 {
            c.clear_record();
        }
    }

    /// This record's capture, when it was captured.
    #[inline]
    fn record(&self) -> Option<&Capture> {
        self.0.as_deref().filter(|c| c.on)
    }

    /// Whether the metric's record was captured: its elements are here and none is in `fields`.
    #[inline]
    pub fn holds_record(&self) -> bool {
        self.record().is_some()
    }

    /// Whether this record's elements of the pattern `prefix` are here.
    #[inline]
    pub fn holds(&self, prefix: &str) -> bool {
        self.record().is_some_and(|c| c.prefix == prefix.as_bytes())
    }

    /// How many elements the record had (0 when it was not captured).
    pub fn count(&self) -> usize {
        self.record().map_or(0, |c| c.count)
    }

    /// The list: one past the largest index the record had, every missing element NaN (empty
    /// when the record was not captured).
    pub fn values(&self) -> &[f64] {
        self.record()
            .and_then(|c| c.values.get(..c.len))
            .unwrap_or_default()
    }

    /// The record's elements, (index, value), ascending.
    pub fn elements(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.values()
            .iter()
            .enumerate()
            .filter(|(_, v)| !v.is_nan())
            .map(|(i, v)| (i, *v))
    }
}

impl Capture {
    fn new(prefix: &[u8], limit: usize) -> Capture {
        let plain = prefix
            .iter()
            .all(|&c| c > b' ' && !b",=\\\"".contains(&c) && c != 0x7f);
        Capture {
            prefix: prefix.to_vec(),
            word: Prefix::new(prefix).word,
            limit,
            enabled: plain,
            ..Capture::default()
        }
    }

    /// A record begins: none of its elements seen yet (the last record's become NaN).
    #[inline]
    pub(crate) fn begin(&mut self) {
        self.forget_values();
        self.on = true;
    }

    /// The record is not captured (the full parser read it).
    pub(crate) fn clear_record(&mut self) {
        self.forget_values();
        self.on = false;
    }

    #[inline]
    fn forget_values(&mut self) {
        if let Some(v) = self.values.get_mut(..self.len) {
            v.fill(f64::NAN);
        }
        self.count = 0;
        self.len = 0;
    }

    /// The element whose key starts `b` at `at` when it is `<prefix><canonical index>=`: its
    /// index and where its value starts. `None` for anything else (then the key is read as any
    /// other and [`ListCapture::classify`] decides). Reads the key once: the prefix a word at a
    /// time, then the digits.
    #[inline]
    pub(crate) fn element_at(&self, b: &[u8], at: usize) -> Option<(usize, usize)> {
        let key = b.get(at..)?;
        let rest = Prefix {
            bytes: &self.prefix,
            word: self.word,
        }
        .rest(key)?;
        let first = rest.first()?.wrapping_sub(b'0');
        let mut i = usize::from(first);
        let mut n = 1;
        if first > 9 {
            return None;
        }
        if first != 0 {
            while let Some(d) = rest
                .get(n)
                .map(|d| d.wrapping_sub(b'0'))
                .filter(|&d| d <= 9)
            {
                i = i * 10 + usize::from(d);
                n += 1;
                if n > 9 {
                    return None;
                }
            }
        }
        (rest.get(n) == Some(&b'=') && i < self.limit).then(|| (i, at + self.prefix.len() + n + 1))
    }

    /// What `key` is to the list.
    #[inline]
    pub(crate) fn classify(&self, key: &[u8]) -> ListKey {
        let prefix = Prefix {
            bytes: &self.prefix,
            word: self.word,
        };
        let Some(rest) = prefix.rest(key) else {
            return ListKey::Other;
        };
        if let Some(i) = canonical_index(rest)
            && i < self.limit
        {
            return ListKey::Element(i);
        }
        if list_index(rest).is_some() {
            ListKey::Unusual
        } else {
            ListKey::Other
        }
    }

    /// Element `i` is `v` (finite); false when the record set it already (a repeated key).
    #[inline]
    pub(crate) fn set(&mut self, i: usize, v: f64) -> bool {
        if i >= self.values.len() {
            self.values.resize(i + 1, f64::NAN);
        }
        match self.values.get_mut(i) {
            Some(x) if x.is_nan() => {
                *x = v;
                self.count += 1;
                self.len = self.len.max(i + 1);
                true
            }
            _ => false,
        }
    }
}

/// Equal when both captured the same elements of the same prefix (or neither captured).
impl PartialEq for ListCapture {
    fn eq(&self, other: &ListCapture) -> bool {
        match (self.record(), other.record()) {
            (None, None) => true,
            (Some(a), Some(b)) => {
                a.prefix == b.prefix
                    && a.count == b.count
                    && self.values().len() == other.values().len()
                    && self
                        .values()
                        .iter()
                        .zip(other.values())
                        .all(|(x, y)| x.to_bits() == y.to_bits())
            }
            _ => false,
        }
    }
}

/// A list pattern's prefix (`lidar_`), compared with a key a word at a time when both allow
/// (every key of a 360-beam scan is compared, and a call to `memcmp` per key cost more than
/// the rest of the gathering).
pub struct Prefix<'a> {
    bytes: &'a [u8],
    /// The prefix's bytes as a little-endian word and the mask of its length (prefixes of at
    /// most 8 bytes).
    word: Option<(u64, u64)>,
}

impl<'a> Prefix<'a> {
    /// The prefix `bytes`, read into a word now when it is at most 8 bytes long.
    pub fn new(bytes: &'a [u8]) -> Self {
        let word = (bytes.len() <= 8).then(|| {
            let mut w = [0u8; 8];
            w[..bytes.len()].copy_from_slice(bytes);
            let mask = u64::MAX
                .checked_shr(64 - 8 * bytes.len() as u32)
                .unwrap_or(0);
            (u64::from_le_bytes(w), mask)
        });
        Prefix { bytes, word }
    }

    /// What follows the prefix in `key`, when `key` starts with it.
    #[inline]
    pub fn rest<'k>(&self, key: &'k [u8]) -> Option<&'k [u8]> {
        if let (Some((word, mask)), Some(head)) = (self.word, key.first_chunk::<8>()) {
            if u64::from_le_bytes(*head) & mask != word {
                return None;
            }
            return key.get(self.bytes.len()..);
        }
        key.strip_prefix(self.bytes)
    }
}

/// The index in a list field's key (`lidar_123` -> 123): what `str::parse::<usize>` accepts,
/// read by hand for the usual short all-digit keys (360 of them in every lidar record).
pub fn list_index(s: &[u8]) -> Option<usize> {
    if (1..=9).contains(&s.len()) {
        let mut v = 0usize;
        for &d in s {
            let x = d.wrapping_sub(b'0');
            if x > 9 {
                return std::str::from_utf8(s).ok()?.parse::<usize>().ok();
            }
            v = v * 10 + usize::from(x);
        }
        return Some(v);
    }
    std::str::from_utf8(s).ok()?.parse::<usize>().ok()
}

/// The index when `rest` is its canonical form (`0`, or up to nine digits, the first not 0):
/// the one key of each index, so a repeated index is a repeated key.
#[inline]
fn canonical_index(rest: &[u8]) -> Option<usize> {
    let (&first, _) = rest.split_first()?;
    if rest.len() > 9 || (first == b'0' && rest.len() > 1) {
        return None;
    }
    let mut v = 0usize;
    for &d in rest {
        let x = d.wrapping_sub(b'0');
        if x > 9 {
            return None;
        }
        v = v * 10 + usize::from(x);
    }
    Some(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn list_indices_read_as_str_parse_reads_them() {
        for k in [
            "0",
            "7",
            "007",
            "359",
            "123456789",
            "1234567890",
            "+5",
            "-1",
            "",
            "1a",
            " 1",
        ] {
            assert_eq!(list_index(k.as_bytes()), k.parse::<usize>().ok(), "{k:?}");
        }
    }

    #[test]
    fn prefixes_match_as_strip_prefix_does() {
        let keys = [
            "",
            "l",
            "lidar",
            "lidar_",
            "lidar_5",
            "lidar_12",
            "lidar_359",
            "lidar_1234567",
            "lidaR_12",
            "xlidar_12",
            "lidar_abcdefgh",
            "ranges_10",
            "ranges__1",
            "ü_12345678",
        ];
        for prefix in [
            "",
            "l",
            "lidar_",
            "ranges_",
            "12345678",
            "lidar_12",
            "a_longer_prefix_",
        ] {
            let p = Prefix::new(prefix.as_bytes());
            for k in keys {
                assert_eq!(
                    p.rest(k.as_bytes()),
                    k.as_bytes().strip_prefix(prefix.as_bytes()),
                    "{prefix:?} {k:?}"
                );
            }
        }
    }
}
