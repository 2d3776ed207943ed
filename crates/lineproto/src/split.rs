//! Cutting a byte stream into line-protocol records.
//!
//! Owns: [`RecordSplitter`], which receives bytes as they arrive and yields complete records. A
//! newline ends a record unless it is inside a quoted string field value (Telegraf's serializer
//! writes newlines in string fields raw, research note §2.1). A quote opens a string only where
//! a field value starts (right after `=` in the field set), so quotes in names, tags, comments or
//! timestamps never swallow the following lines. Outside strings every newline ends the record,
//! even after a backslash: Telegraf's serializer never writes a raw newline there, and ending the
//! record keeps a bad line from costing the next one.
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

/// How many bytes of an oversized record are kept for the error message.
pub const OVERSIZED_HEAD: usize = 256;

/// Default per-record limit: 16 MiB, far above a 360-sample lidar line (~7 KiB).
pub const DEFAULT_MAX_RECORD: usize = 16 * 1024 * 1024;

/// Where in a record the scanner is (Telegraf's grammar, reduced to what decides record ends).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Leading whitespace: nothing seen yet.
    Start,
    /// A line whose first non-blank byte is `#`.
    Comment,
    /// Measurement and tag set.
    Name,
    /// Whitespace between the tag set and the field set.
    BeforeFields,
    /// A field key.
    FieldKey,
    /// Right after a field key's `=`: a `"` here opens a string.
    AfterEq,
    /// An unquoted field value, or the rest of a field after its closing quote.
    Value,
    /// Inside a quoted string field value.
    Str,
    /// Inside a string, right after a backslash.
    StrEscape,
    /// The timestamp and anything after it.
    Rest,
}

fn is_sep(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\x0b' | b'\x0c')
}

/// Streaming, quote-aware record splitter with a per-record size limit.
#[derive(Debug)]
pub struct RecordSplitter {
    buf: Vec<u8>,
    state: State,
    /// In `Name` or `FieldKey`: the previous byte was an unconsumed backslash.
    escape: bool,
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
            state: State::Start,
            escape: false,
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
        let mut start = 0;
        for (i, &b) in bytes.iter().enumerate() {
            if b == b'\n' {
                self.line += 1;
            }
            if self.step(b) {
                let end = i + 1;
                self.end_record(bytes.get(start..end).unwrap_or_default());
                start = end;
            } else if !self.discarding && self.buf.len() + (i + 1 - start) > self.max_record {
                self.buf
                    .extend_from_slice(bytes.get(start..=i).unwrap_or_default());
                self.cut_oversized();
                start = i + 1;
            }
        }
        if !self.discarding {
            self.buf
                .extend_from_slice(bytes.get(start..).unwrap_or_default());
        }
    }

    /// Advance the scanner over one byte; true when the byte ends the record.
    fn step(&mut self, b: u8) -> bool {
        use State::*;
        if b == b'\n' && !matches!(self.state, Str | StrEscape) {
            return true;
        }
        if self.escape {
            self.escape = false;
            return false;
        }
        self.state = match (self.state, b) {
            (Start, b' ' | b'\t' | b'\r' | b'\x0b' | b'\x0c') => Start,
            (Start, b'#') => Comment,
            (Start | Name, b'\\') => {
                self.escape = true;
                Name
            }
            (Start | Name, b) if is_sep(b) => BeforeFields,
            (Start | Name, _) => Name,
            (BeforeFields, b) if is_sep(b) => BeforeFields,
            (BeforeFields | FieldKey, b'\\') => {
                self.escape = true;
                FieldKey
            }
            (BeforeFields | FieldKey, b'=') => AfterEq,
            (FieldKey, b) if is_sep(b) => Rest,
            (BeforeFields | FieldKey, _) => FieldKey,
            (AfterEq, b'"') => Str,
            (AfterEq | Value, b',') => FieldKey,
            (AfterEq | Value, b) if is_sep(b) => Rest,
            (AfterEq | Value, _) => Value,
            (Str, b'\\') => StrEscape,
            (Str, b'"') => Value,
            (Str, _) | (StrEscape, _) => Str,
            (Comment, _) => Comment,
            (Rest, _) => Rest,
        };
        false
    }

    /// The record ends with `tail` (the last bytes of this push, newline included).
    fn end_record(&mut self, tail: &[u8]) {
        if self.discarding {
            self.discarding = false;
        } else {
            self.buf.extend_from_slice(tail);
            let bytes = std::mem::take(&mut self.buf);
            self.ready.push_back(Record {
                bytes,
                line: self.record_line,
                oversized: false,
            });
        }
        self.reset_record();
    }

    /// The buffered record passed the limit: report its head, drop the rest as it arrives.
    fn cut_oversized(&mut self) {
        let mut head = std::mem::take(&mut self.buf);
        head.truncate(OVERSIZED_HEAD);
        self.ready.push_back(Record {
            bytes: head,
            line: self.record_line,
            oversized: true,
        });
        self.discarding = true;
    }

    fn reset_record(&mut self) {
        self.state = State::Start;
        self.escape = false;
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
        }
    }

    #[test]
    fn oversized_record_cut_at_eof_yields_nothing_more() {
        let input = vec![b'x'; 3000];
        let rs = all(&input, 100, 1024);
        assert_eq!(rs.len(), 1);
        assert!(rs[0].oversized);
    }
}
