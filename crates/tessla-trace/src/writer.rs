//! TeSSLa's output trace format: one `TS: name = value` line per output event (the value as
//! `Value`'s Display prints it), or only the value for `@raw` outputs.

use std::io::{self, Write};
use tessla_engine::{OutputInfo, Value};

/// Write one output event in TeSSLa's format.
pub fn write_event(
    out: &mut impl Write,
    ts: i64,
    output: &OutputInfo,
    value: &Value,
) -> io::Result<()> {
    if output.raw {
        writeln!(out, "{value}")
    } else {
        writeln!(out, "{ts}: {} = {value}", output.name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tessla_engine::Type;

    fn output(name: &str, raw: bool) -> OutputInfo {
        OutputInfo {
            name: name.to_string(),
            ty: Type::Int,
            annotations: Vec::new(),
            raw,
        }
    }

    #[test]
    fn events_print_as_tessla_does() {
        let mut buf = Vec::new();
        write_event(&mut buf, 3, &output("x + 1", false), &Value::Int(4)).unwrap();
        write_event(&mut buf, 5, &output("r", true), &Value::Str("hello".into())).unwrap();
        write_event(&mut buf, 7, &output("f", false), &Value::Float(2.0)).unwrap();
        assert_eq!(
            String::from_utf8(buf).unwrap(),
            "3: x + 1 = 4\nhello\n7: f = 2.0\n"
        );
    }
}
