//! Cutting a byte stream into line-protocol records.
//!
//! Owns: [`RecordSplitter`], which receives bytes as they arrive and yields complete records. A
//! newline ends a record unless it is inside a quoted string field value (Telegraf's serializer
//! writes newlines in string fields raw: influxdata/telegraf `plugins/serializers/influx`). A quote
//! opens a string only where a field value starts (right after `=` in the field set), so quotes in
//! names, tags, comments or timestamps never swallow the following lines. Outside strings every
//! newline ends the record, even after a backslash: Telegraf's serializer never writes a raw
//! newline there, and ending the record keeps a bad line from costing the next one.
//!
//! Hand-written rather than the crate's `split_lines`: that needs the whole input as one `&str`,
//! while we stream bytes (possibly invalid UTF-8), track line numbers, and bound memory per record.

use std::collections::VecDeque;

/// One record: its exact bytes (for byte-identical pass-through) and where it started.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// The record's bytes including its final newline (absent for a truncated last record).
    pub bytes: Vec<u8>,
    /// 1-based number of the physical input line the record starts on.
    pub line: u64,
    /// The record was longer than the splitter's limit: `bytes` holds only its first
    /// [`OVERSIZED_HEAD`] bytes and the rest, up to the record's end, was discarded.
    pub oversized: bool,
}

impl Record {
    /// This record borrowed.
    pub fn view(&self) -> RecordRef<'_> {
        RecordRef {
            bytes: &self.bytes,
            line: self.line,
            oversized: self.oversized,
        }
    }
}

/// One record borrowed from the bytes handed to [`RecordSplitter::push_with`] (or from the
/// splitter's buffer, for a record that spans reads): the same fields as [`Record`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordRef<'a> {
    /// The record's bytes, as [`Record::bytes`].
    pub bytes: &'a [u8],
    /// Its first physical input line (1-based), as [`Record::line`].
    pub line: u64,
    /// Cut at the splitter's limit, as [`Record::oversized`].
    pub oversized: bool,
}

impl RecordRef<'_> {
    /// An owned copy.
    pub fn to_record(&self) -> Record {
        Record {
            bytes: self.bytes.to_vec(),
            line: self.line,
            oversized: self.oversized,
        }
    }
}

/// A buffer kept between records larger than this is given back after its record (an oversized
/// or very long record does not pin its memory).
const KEEP_BUF: usize = 1 << 20;

/// How many bytes of an oversized record are kept for the error message.
pub const OVERSIZED_HEAD: usize = 256;

/// Default per-record limit: 16 MiB, far above a 360-sample lidar line (~7 KiB).
pub const DEFAULT_MAX_RECORD: usize = 16 * 1024 * 1024;

/// Where in a record the scanner is (Telegraf's grammar, reduced to what decides record ends).
/// States are row numbers of [`TABLE`].
mod st {
    /// Leading whitespace: nothing seen yet.
    pub const START: u8 = 0;
    /// A line whose first non-blank byte is `#`.
    pub const COMMENT: u8 = 1;
    /// Measurement and tag set.
    pub const NAME: u8 = 2;
    /// Measurement and tag set, right after a backslash (the next byte is taken as is).
    pub const NAME_ESC: u8 = 3;
    /// Whitespace between the tag set and the field set.
    pub const BEFORE_FIELDS: u8 = 4;
    /// A field key.
    pub const FIELD_KEY: u8 = 5;
    /// A field key, right after a backslash.
    pub const FIELD_KEY_ESC: u8 = 6;
    /// Right after a field key's `=`: a `"` here opens a string.
    pub const AFTER_EQ: u8 = 7;
    /// An unquoted field value, or the rest of a field after its closing quote.
    pub const VALUE: u8 = 8;
    /// Inside a quoted string field value.
    pub const STR: u8 = 9;
    /// Inside a string, right after a backslash.
    pub const STR_ESC: u8 = 10;
    /// The timestamp and anything after it.
    pub const REST: u8 = 11;
    /// Not a state: the byte ends the record.
    pub const END: u8 = 0xff;
}

const fn is_sep(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\x0b' | b'\x0c')
}

/// The scanner's transition on one byte. A newline ends the record unless it is inside a string;
/// a backslash in a name or key takes the next byte as is (a newline still ends the record).
const fn next(state: u8, b: u8) -> u8 {
    use st::*;
    if b == b'\n' && state != STR && state != STR_ESC {
        return END;
    }
    match state {
        START => match b {
            b' ' | b'\t' | b'\r' | b'\x0b' | b'\x0c' => START,
            b'#' => COMMENT,
            b'\\' => NAME_ESC,
            _ => NAME,
        },
        NAME => match b {
            b'\\' => NAME_ESC,
            b if is_sep(b) => BEFORE_FIELDS,
            _ => NAME,
        },
        NAME_ESC => NAME,
        BEFORE_FIELDS | FIELD_KEY => match b {
            b'\\' => FIELD_KEY_ESC,
            b'=' => AFTER_EQ,
            b if is_sep(b) => {
                if state == BEFORE_FIELDS {
                    BEFORE_FIELDS
                } else {
                    REST
                }
            }
            _ => FIELD_KEY,
        },
        FIELD_KEY_ESC => FIELD_KEY,
        AFTER_EQ | VALUE => match b {
            b'"' if state == AFTER_EQ => STR,
            b',' => FIELD_KEY,
            b if is_sep(b) => REST,
            _ => VALUE,
        },
        STR => match b {
            b'\\' => STR_ESC,
            b'"' => VALUE,
            _ => STR,
        },
        STR_ESC => STR,
        COMMENT => COMMENT,
        _ => REST,
    }
}

/// Rows of 256 transitions, one row per state (16 rows, so that `(state & 15) * 256 + byte` is
/// always in bounds). Table-driven because the scanner runs over every input byte: this is about
/// twice as fast as matching on (state, byte) (`cargo bench -p lineproto --bench codec`, `split_*`).
static TABLE: [u8; 16 * 256] = {
    let mut t = [st::REST; 16 * 256];
    let mut s = 0;
    while s < 12 {
        let mut b = 0;
        while b < 256 {
            t[s * 256 + b] = next(s as u8, b as u8);
            b += 1;
        }
        s += 1;
    }
    t
};

#[inline]
fn step(state: u8, b: u8) -> u8 {
    TABLE[usize::from(state & 15) * 256 + usize::from(b)]
}

/// Where the record ends in `seg` (scanned from `state`), found without stepping over every
/// byte: only a `"` can open a string, so the first newline ends the record unless the state
/// right after the last quote before it is inside a string. `None`: undecided here (inside a
/// string now, no newline in `seg`, or the newline is inside a string); step byte by byte.
/// This keeps a 360-beam lidar record (one string field anywhere in it: Telegraf writes fields
/// in random order) from being stepped over byte by byte.
///
/// One pass finds the first newline and follows the quotes before it as
/// [`in_string_possible`] does (a P2 record has a string field: four searches became one); a
/// backslash before the newline hands over to [`quick_end_searches`], which decides the same
/// way in separate searches.
fn quick_end(state: u8, seg: &[u8]) -> Option<usize> {
    if state == st::STR || state == st::STR_ESC {
        return None;
    }
    let (mut outside, mut inside) = (true, false);
    let mut last_quote = None;
    for at in memchr::memchr3_iter(b'\n', b'"', b'\\', seg) {
        match seg.get(at) {
            Some(b'"') => {
                let may_open = at == 0 || seg.get(at - 1) == Some(&b'=');
                (outside, inside) = (outside || inside, outside && may_open);
                last_quote = Some(at);
            }
            Some(b'\n') => {
                let Some(q) = last_quote.filter(|_| inside) else {
                    return Some(at);
                };
                let after = seg.get(..=q)?.iter().fold(state, |s, &b| step(s, b));
                return (after != st::STR).then_some(at);
            }
            _ => return quick_end_searches(state, seg),
        }
    }
    None
}

/// [`quick_end`] by separate searches: the first newline, the last quote before it, then
/// [`in_string_possible`] (what a record with a backslash takes).
fn quick_end_searches(state: u8, seg: &[u8]) -> Option<usize> {
    let nl = memchr::memchr(b'\n', seg)?;
    let head = seg.get(..nl)?;
    let q = match memchr::memrchr(b'"', head) {
        None => return Some(nl),
        Some(q) => q,
    };
    if !in_string_possible(head) {
        return Some(nl);
    }
    let after = head.get(..=q)?.iter().fold(state, |s, &b| step(s, b));
    (after != st::STR).then_some(nl)
}

/// Whether the scanner may be inside a string at the end of `head` (started outside one),
/// decided from the quotes alone when `head` has no backslash: a string then opens only at a
/// quote right after `=` (the only way into [`st::AFTER_EQ`]) and closes at the next quote, so
/// the two possibilities "outside" and "inside" are followed over the quotes. `true` (take the
/// exact byte-by-byte scan) when a backslash is present or "inside" stays possible.
fn in_string_possible(head: &[u8]) -> bool {
    if memchr::memchr(b'\\', head).is_some() {
        return true;
    }
    let (mut outside, mut inside) = (true, false);
    for q in memchr::memchr_iter(b'"', head) {
        let may_open = q == 0 || head.get(q - 1) == Some(&b'=');
        (outside, inside) = (outside || inside, outside && may_open);
    }
    inside
}

fn newlines(bytes: &[u8]) -> u64 {
    memchr::memchr_iter(b'\n', bytes).count() as u64
}

/// Streaming, quote-aware record splitter with a per-record size limit.
#[derive(Debug)]
pub struct RecordSplitter {
    buf: Vec<u8>,
    state: u8,
    /// Physical line the scanner is on (1-based).
    line: u64,
    /// Physical line the current record started on.
    record_line: u64,
    max_record: usize,
    /// The current record passed the limit: drop its bytes until it ends.
    discarding: bool,
    ready: VecDeque<Record>,
}

impl Default for RecordSplitter {
    fn default() -> Self {
        RecordSplitter::new(DEFAULT_MAX_RECORD)
    }
}

impl RecordSplitter {
    /// A splitter that reports and skips records longer than `max_record` bytes (at least
    /// [`OVERSIZED_HEAD`]).
    pub fn new(max_record: usize) -> RecordSplitter {
        RecordSplitter {
            buf: Vec::new(),
            state: st::START,
            line: 1,
            record_line: 1,
            max_record: max_record.max(OVERSIZED_HEAD),
            discarding: false,
            ready: VecDeque::new(),
        }
    }

    /// Add bytes read from the input; complete records become available from
    /// [`RecordSplitter::next_record`].
    pub fn push(&mut self, bytes: &[u8]) {
        let mut ready = std::mem::take(&mut self.ready);
        self.push_with(bytes, |r| ready.push_back(r.to_record()));
        self.ready = ready;
    }

    /// Add bytes read from the input and hand each complete record to `each` at once, borrowed:
    /// a record that lies inside `bytes` is not copied (the step loop passes it through straight
    /// from the read buffer), one that spans reads comes from the splitter's buffer, which keeps
    /// its capacity. Records still waiting from [`RecordSplitter::push`] are handed out first.
    pub fn push_with(&mut self, bytes: &[u8], mut each: impl FnMut(RecordRef<'_>)) {
        while let Some(r) = self.ready.pop_front() {
            each(r.view());
        }
        let mut start = 0;
        let mut i = 0;
        while i < bytes.len() {
            // Bytes before `lim` cannot make the current record pass the limit.
            let lim = if self.discarding {
                bytes.len()
            } else {
                (start + self.max_record.saturating_sub(self.buf.len())).min(bytes.len())
            };
            let seg = bytes.get(i..lim).unwrap_or_default();
            let mut state = self.state;
            let mut end = quick_end(state, seg).map(|nl| i + nl);
            let quick = end.is_some();
            if end.is_none() {
                for (j, &b) in seg.iter().enumerate() {
                    state = step(state, b);
                    if state == st::END {
                        end = Some(i + j);
                        break;
                    }
                }
            }
            match end {
                // `quick_end` found the first newline of `seg`: the only one up to `e`.
                Some(e) if quick => {
                    self.line += 1;
                    self.end_record(bytes.get(start..=e).unwrap_or_default(), &mut each);
                    start = e + 1;
                    i = e + 1;
                }
                Some(e) => {
                    self.line += newlines(bytes.get(i..=e).unwrap_or_default());
                    self.end_record(bytes.get(start..=e).unwrap_or_default(), &mut each);
                    start = e + 1;
                    i = e + 1;
                }
                None => {
                    self.line += newlines(bytes.get(i..lim).unwrap_or_default());
                    self.state = state;
                    i = lim;
                    // At the limit: the next byte either ends the record or makes it oversized.
                    if let Some(&b) = bytes.get(lim) {
                        self.line += u64::from(b == b'\n');
                        let next = step(state, b);
                        if next == st::END {
                            self.end_record(bytes.get(start..=lim).unwrap_or_default(), &mut each);
                        } else {
                            self.state = next;
                            self.buf
                                .extend_from_slice(bytes.get(start..=lim).unwrap_or_default());
                            self.cut_oversized(&mut each);
                        }
                        start = lim + 1;
                        i = lim + 1;
                    }
                }
            }
        }
        if !self.discarding {
            self.buf
                .extend_from_slice(bytes.get(start..).unwrap_or_default());
        }
    }

    /// The record ends with `tail` (the last bytes of this push, newline included).
    fn end_record(&mut self, tail: &[u8], each: &mut impl FnMut(RecordRef<'_>)) {
        if self.discarding {
            self.discarding = false;
        } else if self.buf.is_empty() {
            each(RecordRef {
                bytes: tail,
                line: self.record_line,
                oversized: false,
            });
        } else {
            self.buf.extend_from_slice(tail);
            each(RecordRef {
                bytes: &self.buf,
                line: self.record_line,
                oversized: false,
            });
            self.clear_buf();
        }
        self.reset_record();
    }

    /// The buffered record passed the limit: report its head, drop the rest as it arrives.
    fn cut_oversized(&mut self, each: &mut impl FnMut(RecordRef<'_>)) {
        each(RecordRef {
            bytes: self.buf.get(..OVERSIZED_HEAD).unwrap_or(&self.buf),
            line: self.record_line,
            oversized: true,
        });
        self.clear_buf();
        self.discarding = true;
    }

    /// Empty the record buffer, keeping its capacity unless it grew large.
    fn clear_buf(&mut self) {
        if self.buf.capacity() > KEEP_BUF {
            self.buf = Vec::new();
        } else {
            self.buf.clear();
        }
    }

    fn reset_record(&mut self) {
        self.state = st::START;
        self.record_line = self.line;
    }

    /// The next complete record, if any.
    pub fn next_record(&mut self) -> Option<Record> {
        self.ready.pop_front()
    }

    /// At end of input: the remaining complete records, then the unterminated last record if it
    /// holds anything but whitespace (an unterminated string field keeps everything after its
    /// opening quote in that record). Returns `None` once everything was handed out.
    pub fn finish(&mut self) -> Option<Record> {
        if let Some(r) = self.ready.pop_front() {
            return Some(r);
        }
        let bytes = std::mem::take(&mut self.buf);
        let line = self.record_line;
        self.discarding = false;
        self.reset_record();
        if bytes.iter().all(u8::is_ascii_whitespace) {
            return None;
        }
        Some(Record {
            bytes,
            line,
            oversized: false,
        })
    }

    /// True when no complete record is waiting.
    pub fn is_empty(&self) -> bool {
        self.ready.is_empty()
    }

    /// Bytes of the current, still incomplete record held in memory.
    pub fn buffered(&self) -> usize {
        self.buf.len()
    }

    /// True while a record has begun and not yet ended: bytes of it are held, or it passed the
    /// limit and its rest is being skipped (nothing held, but input is still arriving). A step
    /// loop must not take this for silence.
    pub fn in_record(&self) -> bool {
        !self.buf.is_empty() || self.discarding
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all(input: &[u8], chunk: usize, max: usize) -> Vec<Record> {
        let mut s = RecordSplitter::new(max);
        let mut out = Vec::new();
        for c in input.chunks(chunk) {
            s.push(c);
            while let Some(r) = s.next_record() {
                out.push(r);
            }
        }
        while let Some(r) = s.finish() {
            out.push(r);
        }
        out
    }

    /// [`all`] through [`RecordSplitter::push_with`] (borrowed records, copied here).
    fn all_with(input: &[u8], chunk: usize, max: usize) -> Vec<Record> {
        let mut s = RecordSplitter::new(max);
        let mut out = Vec::new();
        for c in input.chunks(chunk) {
            s.push_with(c, |r| out.push(r.to_record()));
            assert!(s.buffered() <= max, "memory stays bounded");
        }
        while let Some(r) = s.finish() {
            out.push(r);
        }
        out
    }

    fn texts(rs: &[Record]) -> Vec<String> {
        rs.iter()
            .map(|r| String::from_utf8_lossy(&r.bytes).into_owned())
            .collect()
    }

    #[test]
    fn splits_on_newlines_outside_strings_whatever_the_chunking() {
        let input = b"m a=1 1\nm s=\"x\ny\",b=2 2\nm,t=a\\ b c=\"q\\\"\n\" 3\nlast a=1";
        for chunk in [1, 2, 5, 100] {
            let rs = all(input, chunk, 1024);
            assert_eq!(rs.len(), 4, "chunk {chunk}: {rs:?}");
            assert_eq!(rs[0].bytes, b"m a=1 1\n");
            assert_eq!(rs[1].bytes, b"m s=\"x\ny\",b=2 2\n");
            assert_eq!(rs[1].line, 2);
            assert_eq!(rs[2].line, 4);
            assert_eq!(rs[3].bytes, b"last a=1");
            assert_eq!(rs[3].line, 6);
            assert!(rs.iter().all(|r| !r.oversized));
        }
    }

    #[test]
    fn concatenated_records_reproduce_the_input() {
        let input: &[u8] = b"\n# c \"q\n m,t=\"x a=\"1\n2\",b=\"\" 5\r\nm\\\n a=1\n\xff\"\nend";
        for chunk in [1, 3, 7, 1000] {
            let rs = all(input, chunk, 1024);
            let joined: Vec<u8> = rs.iter().flat_map(|r| r.bytes.clone()).collect();
            assert_eq!(joined, input, "chunk {chunk}");
        }
    }

    #[test]
    fn quotes_outside_field_values_do_not_open_strings() {
        for input in [
            "m,t=a\"b f=1 1\nm f=2 2\n",
            "# a comment with a \" quote\nm f=2 2\n",
            "m f\"x=1 1\nm f=2 2\n",
            "m f=1 1\"\nm f=2 2\n",
            "m f=1x\"y 1\nm f=2 2\n",
        ] {
            let rs = all(input.as_bytes(), 3, 1024);
            assert_eq!(
                texts(&rs).last().map(String::as_str),
                Some("m f=2 2\n"),
                "{input:?}"
            );
            assert_eq!(rs.len(), 2, "{input:?}");
        }
    }

    #[test]
    fn a_string_after_a_tab_separator_or_comma_is_quoted() {
        let rs = all(b"m\ta=1,s=\"x\ny\"\tb 9\nm a=1\n", 4, 1024);
        assert_eq!(texts(&rs), ["m\ta=1,s=\"x\ny\"\tb 9\n", "m a=1\n"]);
        assert_eq!(rs[1].line, 3);
    }

    #[test]
    fn a_backslash_before_a_newline_outside_strings_does_not_join_lines() {
        let rs = all(b"m,t=a\\\nm a=1 2\n", 2, 1024);
        assert_eq!(texts(&rs), ["m,t=a\\\n", "m a=1 2\n"]);
        assert_eq!(rs[1].line, 2);
    }

    #[test]
    fn escaped_newlines_inside_strings_count_as_lines() {
        let rs = all(b"m s=\"a\\\nb\" 1\nm a=1\n", 1, 1024);
        assert_eq!(rs.len(), 2);
        assert_eq!(rs[1].line, 3);
    }

    #[test]
    fn unterminated_string_keeps_the_rest_in_one_record_at_eof() {
        let rs = all(b"m a=1\nm s=\"open 1\nm b=2 2\n", 5, 1024);
        assert_eq!(texts(&rs), ["m a=1\n", "m s=\"open 1\nm b=2 2\n"]);
    }

    #[test]
    fn blank_tail_is_not_a_record() {
        let rs = all(b"m a=1\n  \t", 2, 1024);
        assert_eq!(rs.len(), 1);
    }

    #[test]
    fn oversized_records_are_cut_and_the_rest_survives() {
        let mut input = b"m a=1 1\nm s=\"".to_vec();
        input.extend(std::iter::repeat_n(b'x', 5000));
        // the newline inside the oversized string must not end the oversized record
        input.extend(b"\ny\"\nm a=3 3\n");
        for chunk in [1, 64, 10_000] {
            let mut s = RecordSplitter::new(1024);
            let mut rs = Vec::new();
            for c in input.chunks(chunk) {
                s.push(c);
                assert!(s.buffered() <= 1024, "memory stays bounded");
                while let Some(r) = s.next_record() {
                    rs.push(r);
                }
            }
            while let Some(r) = s.finish() {
                rs.push(r);
            }
            assert_eq!(rs.len(), 3, "chunk {chunk}: {rs:?}");
            assert!(rs[1].oversized);
            assert_eq!(rs[1].bytes.len(), OVERSIZED_HEAD);
            assert!(rs[1].bytes.starts_with(b"m s=\"xxx"));
            assert_eq!(rs[1].line, 2);
            assert_eq!(rs[2].bytes, b"m a=3 3\n");
            assert_eq!(rs[2].line, 4);
            assert_eq!(
                all_with(&input, chunk, 1024),
                rs,
                "push_with, chunk {chunk}"
            );
        }
    }

    /// Records handed out borrowed equal the owned ones, line numbers and cuts included, and
    /// records still waiting from `push` come first.
    #[test]
    fn push_with_hands_out_what_push_queues() {
        let input = b"m a=1 1\nm s=\"x\ny\",b=2 2\nm,t=a\\ b c=\"q\\\"\n\" 3\nlast a=1\n\n# c\n";
        for chunk in [1, 2, 5, 100] {
            assert_eq!(all_with(input, chunk, 1024), all(input, chunk, 1024));
        }
        let mut s = RecordSplitter::default();
        s.push(b"m a=1 1\n");
        let mut got = Vec::new();
        s.push_with(b"m a=2 2\n", |r| got.push((r.bytes.to_vec(), r.line)));
        assert_eq!(
            got,
            [(b"m a=1 1\n".to_vec(), 1), (b"m a=2 2\n".to_vec(), 2)]
        );
    }

    /// The shortcut of [`quick_end`] and the limit handling give exactly the records of a plain
    /// byte-by-byte scan, on many small random inputs and chunkings.
    #[test]
    fn records_equal_a_byte_by_byte_scan() {
        fn reference(input: &[u8]) -> Vec<Vec<u8>> {
            let (mut out, mut cur, mut state) = (Vec::new(), Vec::new(), st::START);
            for &b in input {
                cur.push(b);
                state = step(state, b);
                if state == st::END {
                    out.push(std::mem::take(&mut cur));
                    state = st::START;
                }
            }
            if !cur.iter().all(u8::is_ascii_whitespace) {
                out.push(cur);
            }
            out
        }
        let alphabet = b"ab\"\\\n=, #\t";
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0x2545_f491);
        let mut next = move || rand::RngCore::next_u64(&mut rng);
        for _ in 0..20_000 {
            let mut input = Vec::new();
            for _ in 0..(next() % 80) {
                input.push(alphabet[(next() % alphabet.len() as u64) as usize]);
            }
            let want = reference(&input);
            for chunk in [1, 3, 64] {
                let with: Vec<Vec<u8>> = all_with(&input, chunk, 1 << 20)
                    .into_iter()
                    .map(|r| r.bytes)
                    .collect();
                assert_eq!(with, want, "push_with, chunk {chunk}");
                let got: Vec<Vec<u8>> = all(&input, chunk, 1 << 20)
                    .into_iter()
                    .map(|r| r.bytes)
                    .collect();
                assert_eq!(
                    got,
                    want,
                    "{:?} chunk {chunk}",
                    String::from_utf8_lossy(&input)
                );
            }
        }
    }

    #[test]
    fn a_record_being_skipped_is_still_a_record_in_progress() {
        let mut s = RecordSplitter::new(OVERSIZED_HEAD);
        assert!(!s.in_record());
        s.push(b"m v=1 1\n");
        assert!(!s.in_record());
        s.push(&[b'x'; 300]);
        // Past the limit: cut and reported, its rest skipped as it arrives; nothing is held.
        assert_eq!(s.buffered(), 0);
        assert!(s.in_record());
        s.push(&[b'x'; 300]);
        assert!(s.in_record());
        s.push(b"x\nm v=2 2\n");
        assert!(!s.in_record());
        let rs: Vec<_> = std::iter::from_fn(|| s.next_record()).collect();
        assert_eq!(rs.len(), 3);
        assert!(rs[1].oversized);
        assert_eq!(rs[2].bytes, b"m v=2 2\n");
    }

    #[test]
    fn oversized_record_cut_at_eof_yields_nothing_more() {
        let input = vec![b'x'; 3000];
        let rs = all(&input, 100, 1024);
        assert_eq!(rs.len(), 1);
        assert!(rs[0].oversized);
    }
}
