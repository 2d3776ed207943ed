//! TeSSLa's format strings (`f"${x}%.2f"`): printf-style conversions with Java's layout of
//! floats (`%e` with a two-digit signed exponent, `%a` as Java's hex float).
//!
//! Owns: [`format_value`], the text of one value under one conversion.

use crate::value::Value;

/// Java's `%e` exponent layout: `4.2e0` -> `4.2e+00`.
fn java_exp(s: &str) -> String {
    match s.split_once('e') {
        Some((m, e)) => match e.parse::<i32>() {
            Ok(x) => format!("{m}e{}{:02}", if x < 0 { '-' } else { '+' }, x.abs()),
            Err(_) => s.to_string(),
        },
        None => s.to_string(),
    }
}

/// Java's `%a` for a normal double: `0x1.0ccccdp2` (hex digits rounded half-up to `prec`;
/// without a precision, trailing zeros dropped, at least one digit).
fn java_hex_float(f: f64, prec: Option<usize>) -> String {
    let bits = f.to_bits();
    let sign = if f < 0.0 { "-" } else { "" };
    let mut exp = ((bits >> 52) & 0x7ff) as i64 - 1023;
    let mut mant = bits & ((1u64 << 52) - 1);
    let digits = match prec {
        Some(p) if p < 13 => {
            let p = p.max(1);
            let shift = 52 - 4 * p as u32;
            mant = (mant + (1u64 << (shift - 1))) >> shift;
            if mant >> (4 * p) != 0 {
                // Rounded up to the next power of two.
                mant = 0;
                exp += 1;
            }
            format!("{mant:0width$x}", width = p)
        }
        _ => {
            let d = format!("{mant:013x}");
            let t = d.trim_end_matches('0');
            if t.is_empty() {
                "0".to_string()
            } else {
                t.to_string()
            }
        }
    };
    format!("{sign}0x1.{digits}p{exp}")
}

/// A printf-style format of one value (`%d`, `%.2f`, `%s`, `%x`, `%e`, `%a`); best effort.
pub fn format_value(spec: &str, v: &Value) -> String {
    let conv = spec.chars().last().unwrap_or('s');
    // The flags/width/precision between `%` and the conversion character (char-safe).
    let inner: String = spec.chars().skip(1).collect();
    let mut body_chars: Vec<char> = inner.chars().collect();
    body_chars.pop();
    let body_owned: String = body_chars.into_iter().collect();
    let body = body_owned.as_str();
    let (width, prec) = match body.split_once('.') {
        Some((w, p)) => (w, p.parse::<usize>().ok()),
        None => (body, None),
    };
    let flags: String = width
        .chars()
        .take_while(|c| "-+ #0,(".contains(*c))
        .collect();
    let left = flags.contains('-');
    let zero = flags.contains('0') && !left;
    let width: usize = width
        .trim_start_matches(['-', '+', ' ', '#', '0', ',', '('])
        .parse()
        .unwrap_or(0);
    let s = match (conv, v) {
        ('d', Value::Int(i)) => i.to_string(),
        ('x', Value::Int(i)) => format!("{i:x}"),
        ('X', Value::Int(i)) => format!("{i:X}"),
        ('o', Value::Int(i)) => format!("{i:o}"),
        ('f', Value::Float(f)) => format!("{f:.*}", prec.unwrap_or(6)),
        ('e', Value::Float(f)) if f.is_finite() => java_exp(&format!("{f:.*e}", prec.unwrap_or(6))),
        ('a', Value::Float(f)) if f.is_normal() => java_hex_float(*f, prec),
        _ => v.to_string(),
    };
    let len = s.chars().count();
    if len < width {
        let pad = width - len;
        if left {
            format!("{s}{}", " ".repeat(pad))
        } else if zero {
            format!("{}{s}", "0".repeat(pad))
        } else {
            format!("{}{s}", " ".repeat(pad))
        }
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn java_float_formats() {
        assert_eq!(format_value("%.8e", &Value::Float(4.2)), "4.20000000e+00");
        assert_eq!(format_value("%.2e", &Value::Float(0.0123)), "1.23e-02");
        assert_eq!(format_value("%.6a", &Value::Float(4.2)), "0x1.0ccccdp2");
        assert_eq!(format_value("%.6a", &Value::Float(23.13)), "0x1.72147bp4");
        assert_eq!(format_value("%a", &Value::Float(1.0)), "0x1.0p0");
        assert_eq!(format_value("%-4s", &Value::Str("ab".into())), "ab  ");
    }

    #[test]
    fn format_specs_never_panic() {
        for spec in ["%", "%d", "%é", "%5.2f", "%08.3e", "%x", "%-3s"] {
            let _ = format_value(spec, &Value::Float(1.5));
            let _ = format_value(spec, &Value::Int(42));
        }
        assert_eq!(format_value("%5.2f", &Value::Float(1.23456)), " 1.23");
        assert_eq!(format_value("%04d", &Value::Int(42)), "0042");
    }
}
