//! Fuzz target: names and a string value taken from the input are written with the LineWriter;
//! the line must always parse back, with the exact field values.
#![no_main]

use libfuzzer_sys::fuzz_target;
use lineproto::{FieldValue, LineWriter, parse_record};

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let mut parts = text.split('\u{1}');
    let measurement = parts.next().unwrap_or("m");
    let tag_key = parts.next().unwrap_or("t");
    let tag_value = parts.next().unwrap_or("v");
    let field_key = parts.next().unwrap_or("f");
    let string = parts.next().unwrap_or("");
    let float = f64::from_bits(
        data.iter()
            .fold(0u64, |h, &b| h.rotate_left(5) ^ u64::from(b)),
    );
    let mut w = LineWriter::new(measurement);
    w.tag(tag_key, tag_value)
        .field(field_key, &FieldValue::Str(string.to_string()))
        .field("x", &FieldValue::Float(float));
    let Some(line) = w.finish(Some(1)).0 else {
        return;
    };
    let m = match parse_record(line.as_bytes()) {
        Ok(Some(m)) => m,
        other => panic!("writer output {line:?} did not parse: {other:?}"),
    };
    if float.is_finite() {
        assert_eq!(m.field("x"), Some(&FieldValue::Float(float)));
    }
    // Unless the field key was unwritable or read back as `x` (then the float overwrote it).
    if m.fields.len() == 2 {
        assert!(
            m.fields
                .iter()
                .any(|(_, v)| *v == FieldValue::Str(string.to_string()))
        );
    }
});
