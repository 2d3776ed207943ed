//! Fuzz target: arbitrary bytes, cut at an input-chosen chunk size, through the splitter and the
//! parser. Checks: no panic, records concatenate back to the input (unless cut as oversized),
//! memory stays bounded, every successful parse has at least one field, and a record parsed with
//! the list `l_*` read apart gives the metric it gives read into fields (field order aside), or
//! fails the same way.
#![no_main]

use libfuzzer_sys::fuzz_target;
use lineproto::{Metric, RecordSplitter, parse_record, parse_record_into};

fuzz_target!(|data: &[u8]| {
    let Some((&chunk, input)) = data.split_first() else {
        return;
    };
    let chunk = usize::from(chunk).max(1);
    let limit = 4096;
    let mut s = RecordSplitter::new(limit);
    let mut joined = Vec::new();
    let mut any_oversized = false;
    let mut apart = Metric::default();
    apart.list.set_prefix(Some("l_"), 64);
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
        match (parse_record(&r.bytes), parse_record_into(&r.bytes, &mut apart)) {
            (Ok(Some(mut want)), Ok(true)) => {
                let mut got = apart.with_list_as_fields();
                got.fields.sort_by(|a, b| a.0.cmp(&b.0));
                want.fields.sort_by(|a, b| a.0.cmp(&b.0));
                assert_eq!(got, want);
            }
            (Ok(None), Ok(false)) | (Err(_), Err(_)) => {}
            (want, got) => panic!("{want:?} against {got:?}"),
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
