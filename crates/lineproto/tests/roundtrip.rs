//! Property tests: what the writer writes, the splitter cuts and the parser reads back.

use lineproto::{FieldValue, LineWriter, Metric, RecordSplitter, parse_record};
use proptest::prelude::*;

/// Names the writer represents exactly: no backslash, no control character.
fn exact_name() -> impl Strategy<Value = String> {
    "[a-zA-Z0-9_ ,=\"#.é😀-]{1,10}"
}

/// Any text at all, for the "always valid" properties.
fn any_name() -> impl Strategy<Value = String> {
    prop_oneof![
        "[a-z\\\\ ,=\"\t\n\r\u{b}\u{c}\u{0}#é]{0,10}",
        any::<String>(),
    ]
}

fn value() -> impl Strategy<Value = FieldValue> {
    prop_oneof![
        any::<f64>()
            .prop_filter("finite", |f| f.is_finite())
            .prop_map(FieldValue::Float),
        any::<i64>().prop_map(FieldValue::Int),
        any::<u64>().prop_map(FieldValue::UInt),
        any::<bool>().prop_map(FieldValue::Bool),
        any::<String>().prop_map(FieldValue::Str),
        "[\"\\\\\n\r a]{0,8}".prop_map(FieldValue::Str),
    ]
}

fn dedup<T>(v: Vec<(String, T)>) -> Vec<(String, T)> {
    let mut out: Vec<(String, T)> = Vec::new();
    for (k, x) in v {
        match out.iter_mut().find(|(ok, _)| *ok == k) {
            Some(slot) => slot.1 = x,
            None => out.push((k, x)),
        }
    }
    out
}

fn write(m: &Metric) -> Option<String> {
    let mut w = LineWriter::new(&m.measurement);
    for (k, v) in &m.tags {
        w.tag(k, v);
    }
    for (k, v) in &m.fields {
        w.field(k, v);
    }
    w.finish(m.timestamp).0
}

fn same_value(a: &FieldValue, b: &FieldValue) -> bool {
    match (a, b) {
        // -0.0 == 0.0 numerically; compare bits so the sign must survive too.
        (FieldValue::Float(x), FieldValue::Float(y)) => x.to_bits() == y.to_bits(),
        _ => a == b,
    }
}

proptest! {
    #[test]
    fn exact_metrics_round_trip(
        measurement in exact_name().prop_filter("not a comment", |m| !m.starts_with('#')),
        tags in prop::collection::vec((exact_name(), exact_name()), 0..4),
        fields in prop::collection::vec((exact_name(), value()), 1..6),
        timestamp in prop::option::of(any::<i64>()),
    ) {
        let m = Metric { measurement, tags: dedup(tags), fields: dedup(fields), timestamp, overwritten: 0, list: Default::default() };
        let line = write(&m).unwrap();
        let back = parse_record(line.as_bytes()).unwrap().unwrap();
        prop_assert_eq!(&back.measurement, &m.measurement);
        prop_assert_eq!(&back.tags, &m.tags);
        prop_assert_eq!(back.timestamp, m.timestamp);
        prop_assert_eq!(back.fields.len(), m.fields.len());
        for ((k1, v1), (k2, v2)) in back.fields.iter().zip(&m.fields) {
            prop_assert_eq!(k1, k2);
            prop_assert!(same_value(v1, v2), "{:?} vs {:?} in {:?}", v1, v2, line);
        }
    }

    #[test]
    fn any_names_give_a_valid_line_with_exact_values(
        measurement in any_name(),
        tags in prop::collection::vec((any_name(), any_name()), 0..4),
        fields in prop::collection::vec((any_name(), value()), 1..6),
    ) {
        let m = Metric { measurement, tags, fields, timestamp: Some(1), overwritten: 0, list: Default::default() };
        let Some(line) = write(&m) else {
            // Only an unwritable measurement or no writable field key may prevent a line.
            prop_assert!(
                !lineproto::measurement_is_writable(&m.measurement)
                    || m.fields.iter().all(|(k, _)| k.trim_end_matches('\\').is_empty())
            );
            return Ok(());
        };
        let back = parse_record(line.as_bytes());
        prop_assert!(matches!(back, Ok(Some(_))), "{:?} -> {:?}", line, back);
        let back = back.unwrap().unwrap();
        prop_assert_eq!(back.timestamp, Some(1));
        // Field values are always exact, whatever their keys became.
        let written: Vec<&FieldValue> = m.fields.iter()
            .filter(|(k, _)| !k.trim_end_matches('\\').is_empty())
            .map(|(_, v)| v)
            .collect();
        let read: Vec<&FieldValue> = back.fields.iter().map(|(_, v)| v).collect();
        if back.fields.len() == written.len() {
            for (a, b) in read.iter().zip(&written) {
                prop_assert!(same_value(a, b), "{:?} vs {:?} in {:?}", a, b, line);
            }
        }
    }

    #[test]
    fn split_then_parse_recovers_every_written_line(
        metrics in prop::collection::vec(
            (exact_name().prop_filter("not a comment", |m| !m.starts_with('#')),
             prop::collection::vec((exact_name(), value()), 1..4)),
            1..8),
        chunk in 1usize..64,
    ) {
        let lines: Vec<String> = metrics.into_iter().enumerate()
            .filter_map(|(i, (measurement, fields))| write(&Metric {
                measurement, tags: vec![], fields: dedup(fields), timestamp: Some(i as i64), overwritten: 0, list: Default::default(),
            }))
            .collect();
        let input: Vec<u8> = lines.concat().into_bytes();
        let mut s = RecordSplitter::default();
        let mut recs = Vec::new();
        for c in input.chunks(chunk) {
            s.push(c);
            while let Some(r) = s.next_record() { recs.push(r); }
        }
        while let Some(r) = s.finish() { recs.push(r); }
        prop_assert_eq!(recs.len(), lines.len());
        let mut line_no = 1;
        for (r, l) in recs.iter().zip(&lines) {
            prop_assert_eq!(&r.bytes, l.as_bytes());
            prop_assert_eq!(r.line, line_no);
            line_no += l.matches('\n').count() as u64;
            prop_assert!(matches!(parse_record(&r.bytes), Ok(Some(_))));
        }
    }

    #[test]
    fn arbitrary_bytes_never_panic_and_concatenate_back(
        input in prop::collection::vec(
            prop_oneof![any::<u8>(), prop::sample::select(b"m a=\"\\\n, #\t1i".to_vec())], 0..300),
        chunk in 1usize..32,
    ) {
        let mut s = RecordSplitter::new(100);
        let mut recs = Vec::new();
        for c in input.chunks(chunk) {
            s.push(c);
            while let Some(r) = s.next_record() { recs.push(r); }
        }
        while let Some(r) = s.finish() { recs.push(r); }
        let mut joined = Vec::new();
        for r in &recs {
            let _ = parse_record(&r.bytes);
            if !r.oversized { joined.extend_from_slice(&r.bytes); }
        }
        if recs.iter().all(|r| !r.oversized) {
            let trimmed_tail = input.len() - joined.len();
            prop_assert!(input.starts_with(&joined));
            prop_assert!(input[joined.len()..].iter().all(u8::is_ascii_whitespace),
                "{} bytes lost", trimmed_tail);
        }
    }
}

#[test]
fn unwritable_measurements_produce_no_line() {
    for name in ["", "#x", "\\", "#"] {
        let mut w = LineWriter::new(name);
        w.field("a", &FieldValue::Int(1));
        assert_eq!(w.finish(None).0, None, "{name:?}");
    }
    assert!(lineproto::measurement_is_writable(" #x"));
}

#[test]
fn odd_backslash_runs_before_escapes_stay_valid() {
    let mut w = LineWriter::new("m\\,x");
    w.tag("k\\", "v\\ w").field("f\\=", &FieldValue::Int(1));
    let line = w.finish(None).0.unwrap();
    assert_eq!(line, "m\\\\\\,x,k=v\\\\\\ w f\\\\\\==1i\n");
    let m = parse_record(line.as_bytes()).unwrap().unwrap();
    assert_eq!(m.measurement, "m\\\\,x");
    assert_eq!(m.tags, vec![("k".into(), "v\\\\ w".into())]);
    assert_eq!(m.field("f\\\\="), Some(&FieldValue::Int(1)));
    // even runs and backslashes before ordinary characters are exact
    let mut w = LineWriter::new("a\\\\b\\c");
    w.field("x", &FieldValue::Bool(false));
    let line = w.finish(None).0.unwrap();
    let m = parse_record(line.as_bytes()).unwrap().unwrap();
    assert_eq!(m.measurement, "a\\\\b\\c");
}
