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
        return writeln!(out, "{value}");
    }
    // The common events (an integer, a boolean) without the formatting machinery: one buffer,
    // one write.
    let mut buf = [0u8; 96];
    let mut len = 0;
    let mut put = |bytes: &[u8]| -> bool {
        match buf.get_mut(len..len + bytes.len()) {
            Some(dst) => {
                dst.copy_from_slice(bytes);
                len += bytes.len();
                true
            }
            None => false,
        }
    };
    let mut digits = [0u8; 20];
    let fits = put(decimal(ts, &mut digits))
        && put(b": ")
        && put(output.name.as_bytes())
        && put(b" = ")
        && match value {
            Value::Bool(true) => put(b"true"),
            Value::Bool(false) => put(b"false"),
            Value::Int(i) => put(decimal(*i, &mut digits)),
            _ => false,
        }
        && put(b"\n");
    if fits {
        return out.write_all(&buf[..len]);
    }
    writeln!(out, "{ts}: {} = {value}", output.name)
}

/// `n` in decimal, as `Display` writes it, in `buf`'s tail.
fn decimal(n: i64, buf: &mut [u8; 20]) -> &[u8] {
    let mut at = buf.len();
    let mut m = n.unsigned_abs();
    loop {
        at -= 1;
        buf[at] = b'0' + (m % 10) as u8;
        m /= 10;
        if m == 0 {
            break;
        }
    }
    if n < 0 {
        at -= 1;
        buf[at] = b'-';
    }
    &buf[at..]
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
