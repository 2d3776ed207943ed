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
    Lines::new(std::slice::from_ref(output)).write(out, ts, 0, value)
}

/// The outputs of a program, ready to write their events: each output's fixed part
/// (`: name = `) made once, so a line is its timestamp, that part and its value, put together
/// in one reused buffer and written at once.
pub struct Lines<'a> {
    outputs: &'a [OutputInfo],
    /// Per output: `: name = `.
    fixed: Vec<Vec<u8>>,
    line: Vec<u8>,
}

impl<'a> Lines<'a> {
    /// A writer of the lines of `outputs` (the program's outputs, by index).
    pub fn new(outputs: &'a [OutputInfo]) -> Lines<'a> {
        let fixed = outputs
            .iter()
            .map(|o| format!(": {} = ", o.name).into_bytes())
            .collect();
        Lines {
            outputs,
            fixed,
            line: Vec::with_capacity(64),
        }
    }

    /// Write an event of output `index` (nothing for an index without an output).
    #[inline]
    pub fn write(
        &mut self,
        out: &mut impl Write,
        ts: i64,
        index: usize,
        value: &Value,
    ) -> io::Result<()> {
        let (Some(output), Some(fixed)) = (self.outputs.get(index), self.fixed.get(index)) else {
            return Ok(());
        };
        if output.raw {
            return writeln!(out, "{value}");
        }
        // The common events (an integer, a boolean) without the formatting machinery
        // (`itoa` writes integers as `Display` does).
        let line = &mut self.line;
        line.clear();
        let mut digits = itoa::Buffer::new();
        line.extend_from_slice(digits.format(ts).as_bytes());
        line.extend_from_slice(fixed);
        match value {
            Value::Bool(true) => line.extend_from_slice(b"true\n"),
            Value::Bool(false) => line.extend_from_slice(b"false\n"),
            Value::Int(i) => {
                line.extend_from_slice(digits.format(*i).as_bytes());
                line.push(b'\n');
            }
            _ => return writeln!(out, "{ts}: {} = {value}", output.name),
        }
        out.write_all(line)
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
        // The integers and booleans written without `Display` are written as it writes them.
        let mut buf = Vec::new();
        for (ts, v) in [
            (0, Value::Int(0)),
            (i64::MAX, Value::Int(i64::MIN)),
            (-1, Value::Int(-1234567890)),
            (12, Value::Bool(true)),
            (13, Value::Bool(false)),
        ] {
            write_event(&mut buf, ts, &output("b", false), &v).unwrap();
        }
        let long = "n".repeat(100);
        write_event(&mut buf, 1, &output(&long, false), &Value::Int(5)).unwrap();
        assert_eq!(
            String::from_utf8(buf).unwrap(),
            format!(
                "0: b = 0\n{}: b = {}\n-1: b = -1234567890\n12: b = true\n13: b = false\n\
                 1: {long} = 5\n",
                i64::MAX,
                i64::MIN
            )
        );
    }
}
