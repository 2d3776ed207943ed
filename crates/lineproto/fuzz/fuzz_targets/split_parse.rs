//! Fuzz target: arbitrary bytes, cut at an input-chosen chunk size, through the splitter and the
//! parser. Checks: no panic, records concatenate back to the input (unless cut as oversized),
//! memory stays bounded, every successful parse has at least one field.
#![no_main]

use libfuzzer_sys::fuzz_target;
use lineproto::{RecordSplitter, parse_record};

fuzz_target!(|data: &[u8]| {
    let Some((&chunk, input)) = data.split_first() else {
        return;
    };
    let chunk = usize::from(chunk).max(1);
    let limit = 4096;
    let mut s = RecordSplitter::new(limit);
    let mut joined = Vec::new();
    let mut any_oversized = false;
    let mut handle = |r: lineproto::Record| {
        if r.oversized {
            any_oversized = true;
            assert!(r.bytes.len() <= lineproto::OVERSIZED_HEAD);
        } else {
            joined.extend_from_slice(&r.bytes);
        }
        if let Ok(Some(m)) = parse_record(&r.bytes) {
            assert!(!m.fields.is_empty());
            assert!(!m.measurement.is_empty());
        }
    };
    for c in input.chunks(chunk) {
        s.push(c);
        assert!(s.buffered() <= limit);
        while let Some(r) = s.next_record() {
            handle(r);
        }
    }
    while let Some(r) = s.finish() {
        handle(r);
    }
    if !any_oversized {
        assert!(input.starts_with(&joined));
        assert!(input[joined.len()..].iter().all(u8::is_ascii_whitespace));
    }
});
