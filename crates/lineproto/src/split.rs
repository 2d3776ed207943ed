//! Cutting a byte stream into line-protocol records.
//!
//! Owns: [`RecordSplitter`], which receives bytes as they arrive and yields complete records. A
//! newline ends a record unless it is inside a quoted string field (Telegraf writes newlines in
//! string fields raw). Hand-written: the crate's `split_lines` needs the whole input as `&str`,
//! while we must stream bytes (possibly invalid UTF-8) and bound memory per record.

/// One record: its exact bytes (for byte-identical pass-through) and where it started.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// The record's bytes including its final newline (absent for a truncated last record).
    pub bytes: Vec<u8>,
    /// 1-based number of the physical input line the record starts on.
    pub line: u64,
    /// The record was longer than the splitter's limit: `bytes` holds only its beginning and the
    /// rest up to the next newline was discarded.
    pub oversized: bool,
}

/// Streaming, quote-aware record splitter with a per-record size limit.
#[derive(Debug)]
pub struct RecordSplitter {
    buf: Vec<u8>,
    /// Bytes of `buf` already scanned.
    scanned: usize,
    escape: bool,
    in_quote: bool,
    in_fields: bool,
    line: u64,
    record_line: u64,
    max_record: usize,
    discarding: bool,
    ready: std::collections::VecDeque<Record>,
}

impl Default for RecordSplitter {
    fn default() -> Self {
        RecordSplitter::new(16 * 1024 * 1024)
    }
}

impl RecordSplitter {
    /// A splitter that cuts records longer than `max_record` bytes.
    pub fn new(max_record: usize) -> RecordSplitter {
        RecordSplitter {
            buf: Vec::new(),
            scanned: 0,
            escape: false,
            in_quote: false,
            in_fields: false,
            line: 1,
            record_line: 1,
            max_record: max_record.max(64),
            discarding: false,
            ready: std::collections::VecDeque::new(),
        }
    }

    /// Add bytes read from the input.
    pub fn push(&mut self, bytes: &[u8]) {
        for &b in bytes {
            if self.discarding {
                if b == b'\n' {
                    self.line += 1;
                    self.discarding = false;
                    self.reset_record();
                }
                continue;
            }
            self.buf.push(b);
            if self.escape {
                self.escape = false;
            } else {
                match b {
                    b'\\' => self.escape = true,
                    b' ' if !self.in_quote => self.in_fields = true,
                    b'"' if self.in_fields => self.in_quote = !self.in_quote,
                    b'\n' => {
                        self.line += 1;
                        if !self.in_quote {
                            let bytes = std::mem::take(&mut self.buf);
                            self.ready.push_back(Record {
                                bytes,
                                line: self.record_line,
                                oversized: false,
                            });
                            self.reset_record();
                            continue;
                        }
                    }
                    _ => {}
                }
            }
            if b == b'\n' && self.escape {
                self.line += 1;
            }
            if self.buf.len() > self.max_record {
                let mut head = std::mem::take(&mut self.buf);
                head.truncate(256);
                self.ready.push_back(Record {
                    bytes: head,
                    line: self.record_line,
                    oversized: true,
                });
                self.discarding = true;
            }
        }
        self.scanned = self.buf.len();
    }

    fn reset_record(&mut self) {
        self.escape = false;
        self.in_quote = false;
        self.in_fields = false;
        self.record_line = self.line;
    }

    /// The next complete record, if any.
    pub fn next_record(&mut self) -> Option<Record> {
        self.ready.pop_front()
    }

    /// At end of input: the unterminated last record, if it holds anything but whitespace.
    pub fn finish(&mut self) -> Option<Record> {
        if let Some(r) = self.ready.pop_front() {
            return Some(r);
        }
        let bytes = std::mem::take(&mut self.buf);
        let line = self.record_line;
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
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all(input: &[u8], chunk: usize) -> Vec<Record> {
        let mut s = RecordSplitter::new(1024);
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

    #[test]
    fn splits_on_newlines_outside_strings_whatever_the_chunking() {
        let input = b"m a=1 1\nm s=\"x\ny\",b=2 2\nm,t=a\\ b c=\"q\\\"\n\" 3\nlast a=1";
        for chunk in [1, 2, 5, 100] {
            let rs = all(input, chunk);
            assert_eq!(rs.len(), 4, "chunk {chunk}: {rs:?}");
            assert_eq!(rs[0].bytes, b"m a=1 1\n");
            assert_eq!(rs[1].bytes, b"m s=\"x\ny\",b=2 2\n");
            assert_eq!(rs[1].line, 2);
            assert_eq!(rs[2].line, 4);
            assert_eq!(rs[3].bytes, b"last a=1");
            assert_eq!(rs[3].line, 6);
        }
    }

    #[test]
    fn quotes_in_tags_do_not_open_strings() {
        let rs = all(b"m,t=a\"b f=1 1\nm f=2 2\n", 3);
        assert_eq!(rs.len(), 2);
    }

    #[test]
    fn oversized_records_are_cut_and_the_rest_survives() {
        let mut input = b"m a=1 1\nm s=\"".to_vec();
        input.extend(std::iter::repeat_n(b'x', 5000));
        input.extend(b"\"\nm a=3 3\n");
        let rs = all(&input, 64);
        assert_eq!(
            rs.len(),
            3,
            "{:?}",
            rs.iter().map(|r| r.oversized).collect::<Vec<_>>()
        );
        assert!(rs[1].oversized);
        assert_eq!(rs[2].bytes, b"m a=3 3\n");
    }
}
