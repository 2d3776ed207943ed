//! Java's `String.format` for one argument, as TeSSLa's `String.format` (and its format strings,
//! `f"${x}%.2f"`) use it: `%[index$][flags][width][.precision]conversion`, with Java's rules for
//! TeSSLa's values (an `Int` is a Java `BigInteger`, a `Float` a `double`).
//!
//! Owns: [`java_format`] (a whole format string, one argument), [`format_value`] (one
//! conversion, for format strings) and the number layouts behind them: floats are rounded half
//! up on their shortest decimal digits (Java's `Formatter`: `%.1f` of 0.25 is `0.3`), `%e` has a
//! signed two-digit exponent, `%a` is Java's hex float, negative `%x`/`%o` are a sign and the
//! magnitude (BigInteger), `,` groups by three. Hand-written: no crate implements Java's
//! `Formatter`, and the rules are small.

use crate::value::Value;

/// The largest width or precision formatted (a larger one is an error, not a huge string).
const MAX_FIELD: usize = 10_000;

/// The flags of one conversion.
#[derive(Debug, Default, Clone, Copy)]
struct Flags {
    left: bool,
    plus: bool,
    space: bool,
    alt: bool,
    zero: bool,
    group: bool,
    paren: bool,
}

/// One parsed conversion.
#[derive(Debug, Clone, Copy)]
struct Spec {
    flags: Flags,
    width: Option<usize>,
    prec: Option<usize>,
    conv: char,
}

/// What Java's `String.format` would throw for, in our words (each a Java
/// `IllegalFormatException`); `body` is a conversion's text after its `%`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FormatError {
    #[error("width `{0}` is too large")]
    WidthTooLarge(String),
    #[error("precision `{0}` is too large")]
    PrecisionTooLarge(String),
    #[error("a `.` must be followed by a precision")]
    PrecisionMissing,
    #[error("a `%` conversion lacks its conversion character")]
    ConversionMissing,
    #[error("`%{0}` lacks a conversion character")]
    NoConversionCharacter(String),
    #[error("unexpected `{rest}` after the conversion `{conv}`")]
    AfterConversion { rest: char, conv: char },
    #[error("a width or precision above {max} in `%{0}` is not supported", max = MAX_FIELD)]
    FieldTooLarge(String),
    #[error("the `-` and `0` flags need a width (`%{0}`)")]
    FlagNeedsWidth(String),
    #[error("conflicting flags in `%{0}`")]
    ConflictingFlags(String),
    #[error("`%<` refers to no earlier argument")]
    NoEarlierArgument,
    #[error("bad argument index in `%{0}`")]
    BadArgumentIndex(String),
    #[error("`%{body}` asks for argument {index}, but there is one argument")]
    OneArgument { body: String, index: usize },
    #[error("flags not allowed with `%{0}`")]
    FlagsNotAllowed(char),
    #[error("`#` and a precision are not allowed with `%d`")]
    AltOrPrecisionWithD,
    #[error("`,` and a precision are not allowed with `%{0}`")]
    GroupOrPrecision(char),
    #[error("`(` is not allowed with `%a`")]
    ParenWithA,
    #[error("`%{conv}` cannot format {what}")]
    Mismatch { conv: char, what: &'static str },
}

/// `s` with every character after the `%` parsed; `Err` names what Java rejects.
fn parse_spec(body: &str) -> Result<Spec, FormatError> {
    let mut chars = body.chars().peekable();
    let mut flags = Flags::default();
    while let Some(&c) = chars.peek() {
        match c {
            '-' => flags.left = true,
            '+' => flags.plus = true,
            ' ' => flags.space = true,
            '#' => flags.alt = true,
            '0' => flags.zero = true,
            ',' => flags.group = true,
            '(' => flags.paren = true,
            _ => break,
        }
        chars.next();
    }
    let num = |chars: &mut std::iter::Peekable<std::str::Chars>| {
        let mut s = String::new();
        while let Some(&c) = chars.peek() {
            if !c.is_ascii_digit() {
                break;
            }
            s.push(c);
            chars.next();
        }
        s
    };
    let w = num(&mut chars);
    let width = if w.is_empty() {
        None
    } else {
        Some(
            w.parse::<usize>()
                .map_err(|_| FormatError::WidthTooLarge(w.clone()))?,
        )
    };
    let prec = if chars.peek() == Some(&'.') {
        chars.next();
        let p = num(&mut chars);
        if p.is_empty() {
            return Err(FormatError::PrecisionMissing);
        }
        Some(
            p.parse::<usize>()
                .map_err(|_| FormatError::PrecisionTooLarge(p.clone()))?,
        )
    } else {
        None
    };
    let conv = chars.next().ok_or(FormatError::ConversionMissing)?;
    if let Some(rest) = chars.next() {
        return Err(FormatError::AfterConversion { rest, conv });
    }
    if width.max(prec).is_some_and(|n| n > MAX_FIELD) {
        return Err(FormatError::FieldTooLarge(body.to_string()));
    }
    let spec = Spec {
        flags,
        width,
        prec,
        conv,
    };
    if (flags.left || flags.zero) && width.is_none() {
        return Err(FormatError::FlagNeedsWidth(body.to_string()));
    }
    if flags.left && flags.zero || flags.plus && flags.space {
        return Err(FormatError::ConflictingFlags(body.to_string()));
    }
    Ok(spec)
}

/// `fmt` with its conversions applied to the single argument `v`, as Java's
/// `String.format(Locale.ROOT, fmt, v)`. `Err`: what Java would throw for, in our words.
pub fn java_format(fmt: &str, v: &Value) -> Result<String, FormatError> {
    let mut out = String::new();
    let mut rest = fmt;
    let mut next_arg = 1usize;
    let mut used_any = false;
    while let Some(pos) = rest.find('%') {
        out.push_str(&rest[..pos]);
        let after = &rest[pos + 1..];
        // The conversion ends at the first letter, or at `%`.
        let end = after
            .char_indices()
            .find(|(_, c)| c.is_ascii_alphabetic() || *c == '%')
            .map(|(i, c)| i + c.len_utf8())
            .ok_or_else(|| FormatError::NoConversionCharacter(after.to_string()))?;
        let mut body = &after[..end];
        rest = &after[end..];
        // An argument index: `1$` or `<`.
        let mut index = None;
        if let Some(b) = body.strip_prefix('<') {
            if !used_any {
                return Err(FormatError::NoEarlierArgument);
            }
            index = Some(1);
            body = b;
        } else if let Some(d) = body.find('$') {
            let n: usize = body[..d]
                .parse()
                .map_err(|_| FormatError::BadArgumentIndex(body.to_string()))?;
            index = Some(n);
            body = &body[d + 1..];
        }
        let spec = parse_spec(body)?;
        match spec.conv {
            '%' => out.push_str(&justify("%".into(), &spec)),
            'n' => out.push('\n'),
            _ => {
                let n = index.unwrap_or_else(|| {
                    let n = next_arg;
                    next_arg += 1;
                    n
                });
                if n != 1 {
                    return Err(FormatError::OneArgument {
                        body: body.to_string(),
                        index: n,
                    });
                }
                used_any = true;
                out.push_str(&format_one(&spec, v)?);
            }
        }
    }
    out.push_str(rest);
    Ok(out)
}

/// A format string's conversion (`%.2f`, with its `%`) applied to `v`; where Java would reject
/// it, the value's plain text.
pub fn format_value(spec: &str, v: &Value) -> String {
    let body = spec.strip_prefix('%').unwrap_or(spec);
    parse_spec(body)
        .and_then(|s| format_one(&s, v))
        .unwrap_or_else(|_| v.to_string())
}

/// Pads `s` with spaces to the width (left-justified with `-`).
fn justify(s: String, spec: &Spec) -> String {
    let len = s.chars().count();
    match spec.width {
        Some(w) if len < w => {
            let pad = " ".repeat(w - len);
            if spec.flags.left { s + &pad } else { pad + &s }
        }
        _ => s,
    }
}

fn mismatch(spec: &Spec, v: &Value) -> FormatError {
    let what = match v {
        Value::Int(_) => "an Int",
        Value::Float(_) => "a Float",
        Value::Bool(_) => "a Bool",
        Value::Str(_) => "a String",
        _ => "this value",
    };
    FormatError::Mismatch {
        conv: spec.conv,
        what,
    }
}

/// One conversion of `v`.
fn format_one(spec: &Spec, v: &Value) -> Result<String, FormatError> {
    let f = &spec.flags;
    let upper = spec.conv.is_ascii_uppercase();
    let s = match (spec.conv.to_ascii_lowercase(), v) {
        ('s', _) | ('b', _) => {
            if f.alt || f.plus || f.space || f.zero || f.group || f.paren {
                return Err(FormatError::FlagsNotAllowed(spec.conv));
            }
            let text = match (spec.conv.to_ascii_lowercase(), v) {
                ('b', Value::Bool(b)) => b.to_string(),
                ('b', _) => "true".to_string(),
                _ => v.to_string(),
            };
            let text = match spec.prec {
                Some(p) => text.chars().take(p).collect(),
                None => text,
            };
            justify(text, spec)
        }
        ('d', Value::Int(i)) => {
            if f.alt || spec.prec.is_some() {
                return Err(FormatError::AltOrPrecisionWithD);
            }
            let mut digits = i.unsigned_abs().to_string();
            if f.group {
                digits = group(&digits);
            }
            signed(*i < 0, "", digits, spec)
        }
        ('o' | 'x', Value::Int(i)) => {
            if f.group || spec.prec.is_some() {
                return Err(FormatError::GroupOrPrecision(spec.conv));
            }
            let m = i.unsigned_abs();
            let (digits, prefix) = if spec.conv.eq_ignore_ascii_case(&'x') {
                (format!("{m:x}"), "0x")
            } else {
                (format!("{m:o}"), "0")
            };
            signed(*i < 0, if f.alt { prefix } else { "" }, digits, spec)
        }
        ('e' | 'f' | 'g' | 'a', Value::Float(x)) => float(*x, spec)?,
        _ => return Err(mismatch(spec, v)),
    };
    Ok(if upper { s.to_uppercase() } else { s })
}

/// Sign, prefix, zero padding and justification around the digits of a number.
fn signed(neg: bool, prefix: &str, digits: String, spec: &Spec) -> String {
    let f = &spec.flags;
    let (lead, trail) = match (neg, f.paren) {
        (true, true) => ("(", ")"),
        (true, false) => ("-", ""),
        (false, _) if f.plus => ("+", ""),
        (false, _) if f.space => (" ", ""),
        _ => ("", ""),
    };
    let mut s = format!("{lead}{prefix}");
    if f.zero {
        let used = s.chars().count() + digits.chars().count() + trail.len();
        if let Some(w) = spec.width.filter(|w| *w > used) {
            s.push_str(&"0".repeat(w - used));
        }
    }
    s.push_str(&digits);
    s.push_str(trail);
    justify(s, spec)
}

/// `1234567` -> `1,234,567`.
fn group(digits: &str) -> String {
    let n = digits.len();
    let mut out = String::with_capacity(n + n / 3);
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (n - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// The shortest decimal digits of a finite `x >= 0` and the exponent of the first:
/// `x = d0.d1d2... * 10^exp`.
fn decimal_digits(x: f64) -> (Vec<u8>, i32) {
    let s = format!("{x:e}");
    let (m, e) = s.split_once('e').unwrap_or((s.as_str(), "0"));
    let digits: Vec<u8> = m
        .bytes()
        .filter(u8::is_ascii_digit)
        .map(|b| b - b'0')
        .collect();
    (digits, e.parse().unwrap_or(0))
}

/// Keeps the first `keep` digits (possibly none, or fewer than zero: the value rounds to 0),
/// rounding half up; a carry out of the first digit raises `exp`.
fn round_half_up(digits: &mut Vec<u8>, exp: &mut i32, keep: i64) {
    if keep < 0 {
        digits.clear();
        return;
    }
    let keep = keep as usize;
    if digits.len() <= keep {
        return;
    }
    let up = digits[keep] >= 5;
    digits.truncate(keep);
    if up {
        let mut i = digits.len();
        loop {
            if i == 0 {
                digits.insert(0, 1);
                *exp += 1;
                break;
            }
            i -= 1;
            if digits[i] == 9 {
                digits[i] = 0;
            } else {
                digits[i] += 1;
                break;
            }
        }
    }
}

/// The digit of place value `10^p`.
fn digit_at(digits: &[u8], exp: i32, p: i32) -> u8 {
    let i = exp as i64 - p as i64;
    if i < 0 {
        0
    } else {
        digits.get(i as usize).copied().unwrap_or(0)
    }
}

/// `x >= 0` in fixed notation with `prec` decimals.
fn fixed(x: f64, prec: usize, spec: &Spec) -> String {
    let (mut digits, mut exp) = decimal_digits(x);
    let keep = exp as i64 + 1 + prec as i64;
    round_half_up(&mut digits, &mut exp, keep);
    let mut int: String = (0..=exp.max(0))
        .rev()
        .map(|p| char::from(b'0' + digit_at(&digits, exp, p)))
        .collect();
    if spec.flags.group {
        int = group(&int);
    }
    let frac: String = (1..=prec as i32)
        .map(|p| char::from(b'0' + digit_at(&digits, exp, -p)))
        .collect();
    if prec > 0 {
        format!("{int}.{frac}")
    } else if spec.flags.alt {
        format!("{int}.")
    } else {
        int
    }
}

/// `x >= 0` in scientific notation with `prec` decimals.
fn scientific(x: f64, prec: usize, spec: &Spec) -> String {
    let (mut digits, mut exp) = decimal_digits(x);
    round_half_up(&mut digits, &mut exp, prec as i64 + 1);
    if x == 0.0 {
        exp = 0;
    }
    let d = |i: usize| char::from(b'0' + digits.get(i).copied().unwrap_or(0));
    let frac: String = (1..=prec).map(d).collect();
    let point = if prec > 0 || spec.flags.alt { "." } else { "" };
    let sign = if exp < 0 { '-' } else { '+' };
    format!("{}{point}{frac}e{sign}{:02}", d(0), exp.abs())
}

/// A `%e`, `%f`, `%g` or `%a` of a float.
fn float(x: f64, spec: &Spec) -> Result<String, FormatError> {
    let conv = spec.conv.to_ascii_lowercase();
    if conv == 'g' && spec.flags.alt || conv == 'a' && spec.flags.group {
        return Err(FormatError::FlagsNotAllowed(spec.conv));
    }
    if !x.is_finite() {
        let text = if x.is_nan() { "NaN" } else { "Infinity" };
        let s = match (x < 0.0, spec.flags) {
            (true, f) if f.paren => format!("({text})"),
            (true, _) => format!("-{text}"),
            (false, f) if f.plus && !x.is_nan() => format!("+{text}"),
            (false, f) if f.space && !x.is_nan() => format!(" {text}"),
            _ => text.to_string(),
        };
        return Ok(justify(s, spec));
    }
    let neg = x.is_sign_negative() && x != 0.0 || x == 0.0 && x.is_sign_negative();
    let a = x.abs();
    let body = match conv {
        'f' => fixed(a, spec.prec.unwrap_or(6), spec),
        'e' => scientific(a, spec.prec.unwrap_or(6), spec),
        'g' => {
            let p = match spec.prec {
                Some(0) => 1,
                Some(p) => p,
                None => 6,
            };
            if a == 0.0 {
                fixed(a, p - 1, spec)
            } else {
                let (mut digits, mut exp) = decimal_digits(a);
                round_half_up(&mut digits, &mut exp, p as i64);
                if exp >= -4 && (exp as i64) < p as i64 {
                    fixed(a, (p as i64 - 1 - exp as i64) as usize, spec)
                } else {
                    scientific(a, p - 1, spec)
                }
            }
        }
        _ => {
            if spec.flags.paren {
                return Err(FormatError::ParenWithA);
            }
            java_hex_float(a, spec.prec)
        }
    };
    Ok(signed(neg, "", body, spec))
}

/// Java's `%a` of `f >= 0`: `0x1.0ccccdp2` (hex digits rounded half-up to `prec`; without a
/// precision, trailing zeros dropped, at least one digit); subnormals as `0x0.…p-1022`.
fn java_hex_float(f: f64, prec: Option<usize>) -> String {
    if f == 0.0 {
        return "0x0.0p0".to_string();
    }
    let bits = f.to_bits();
    let subnormal = !f.is_normal();
    let mut exp = if subnormal {
        -1022
    } else {
        ((bits >> 52) & 0x7ff) as i64 - 1023
    };
    let mut mant = bits & ((1u64 << 52) - 1);
    let lead = if subnormal { 0 } else { 1 };
    let digits = match prec {
        Some(p) if p < 13 && !subnormal => {
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
    format!("0x{lead}.{digits}p{exp}")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn j(fmt: &str, v: Value) -> String {
        java_format(fmt, &v).unwrap_or_else(|e| format!("error: {e}"))
    }

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
        for spec in [
            "%",
            "%d",
            "%é",
            "%5.2f",
            "%08.3e",
            "%x",
            "%-3s",
            "%.f",
            "%99999999999999999999d",
        ] {
            let _ = format_value(spec, &Value::Float(1.5));
            let _ = format_value(spec, &Value::Int(42));
            let _ = java_format(spec, &Value::Int(i64::MIN));
            let _ = java_format(spec, &Value::Float(f64::MIN_POSITIVE / 4.0));
        }
        // Every flag, width, precision and conversion over awkward values.
        let values = [
            Value::Int(0),
            Value::Int(i64::MIN),
            Value::Int(i64::MAX),
            Value::Float(0.0),
            Value::Float(-0.0),
            Value::Float(f64::MAX),
            Value::Float(f64::MIN_POSITIVE / 3.0),
            Value::Float(f64::NAN),
            Value::Float(f64::NEG_INFINITY),
            Value::Float(9.5e-5),
            Value::Str("é".into()),
            Value::Bool(true),
            Value::Unit,
        ];
        for flags in ["", "-", "+", " ", "#", "0", ",", "(", "-#", "+0,", "(0"] {
            for field in ["", "1", "12", ".0", ".3", "8.15", "30.20"] {
                for conv in "bBsSdoxXeEfgGaAcnh%".chars() {
                    for v in &values {
                        let _ = java_format(&format!("%{flags}{field}{conv}"), v);
                    }
                }
            }
        }
        assert_eq!(format_value("%5.2f", &Value::Float(1.23456)), " 1.23");
        assert_eq!(format_value("%04d", &Value::Int(42)), "0042");
    }

    #[test]
    fn java_rules() {
        // Half up on the shortest decimal digits, as Java's Formatter.
        assert_eq!(j("%.1f", Value::Float(0.25)), "0.3");
        assert_eq!(j("%.1f", Value::Float(0.15)), "0.2");
        assert_eq!(j("%.2f", Value::Float(2.675)), "2.68");
        assert_eq!(j("%.0f", Value::Float(0.5)), "1");
        assert_eq!(j("%.0f", Value::Float(0.04)), "0");
        assert_eq!(j("%.2f", Value::Float(9.999)), "10.00");
        assert_eq!(j("%f", Value::Float(-1.5)), "-1.500000");
        assert_eq!(j("%,.2f", Value::Float(1234567.891)), "1,234,567.89");
        assert_eq!(j("%e", Value::Float(0.0)), "0.000000e+00");
        assert_eq!(j("%.2e", Value::Float(9.999)), "1.00e+01");
        assert_eq!(j("%E", Value::Float(12345.0)), "1.234500E+04");
        assert_eq!(j("%g", Value::Float(0.0001)), "0.000100000");
        assert_eq!(j("%g", Value::Float(123456789.0)), "1.23457e+08");
        assert_eq!(j("%g", Value::Float(0.0)), "0.00000");
        assert_eq!(j("%08.2f", Value::Float(-3.25159)), "-0003.25");
        assert_eq!(j("%+.1f", Value::Float(2.0)), "+2.0");
        assert_eq!(j("%(.1f", Value::Float(-2.0)), "(2.0)");
        assert_eq!(j("%f", Value::Float(f64::NAN)), "NaN");
        assert_eq!(j("%+f", Value::Float(f64::NEG_INFINITY)), "-Infinity");
        // Ints are BigIntegers: a negative hex is a sign and the magnitude.
        assert_eq!(j("%#05x", Value::Int(5)), "0x005");
        assert_eq!(j("%#x", Value::Int(10000)), "0x2710");
        assert_eq!(j("%x", Value::Int(-255)), "-ff");
        assert_eq!(j("%X", Value::Int(255)), "FF");
        assert_eq!(j("%#o", Value::Int(8)), "010");
        assert_eq!(j("%,d", Value::Int(-1234567)), "-1,234,567");
        assert_eq!(j("%+d", Value::Int(5)), "+5");
        assert_eq!(j("% d", Value::Int(5)), " 5");
        assert_eq!(j("%(d", Value::Int(-5)), "(5)");
        assert_eq!(j("%-5d|", Value::Int(42)), "42   |");
        assert_eq!(j("%d", Value::Int(i64::MIN)), "-9223372036854775808");
        // Text, booleans, literal text and `%%`, argument indices.
        assert_eq!(j("<%s>", Value::Str("hi".into())), "<hi>");
        assert_eq!(j("%.2s", Value::Str("hello".into())), "he");
        assert_eq!(j("%S", Value::Str("hi".into())), "HI");
        assert_eq!(j("%b", Value::Bool(false)), "false");
        assert_eq!(j("%b", Value::Int(0)), "true");
        assert_eq!(j("100%% of %d", Value::Int(3)), "100% of 3");
        assert_eq!(j("%1$d=%<d", Value::Int(3)), "3=3");
        assert_eq!(
            j("%s", Value::Some(std::sync::Arc::new(Value::Int(1)))),
            "Some(1)"
        );
        assert_eq!(j("no conversion", Value::Int(1)), "no conversion");
    }

    #[test]
    fn java_rejections() {
        for (fmt, v) in [
            ("%d", Value::Float(1.0)),
            ("%f", Value::Int(1)),
            ("%d %d", Value::Int(1)),
            ("%2$d", Value::Int(1)),
            ("%-d", Value::Int(1)),
            ("%#d", Value::Int(1)),
            ("%q", Value::Int(1)),
            ("%c", Value::Int(65)),
            ("%", Value::Int(1)),
            ("%<d", Value::Int(1)),
            ("%2000000000d", Value::Int(1)),
            ("%.2000000000f", Value::Float(1.0)),
        ] {
            assert!(java_format(fmt, &v).is_err(), "{fmt}");
        }
    }

    /// Each rejection is its own error, and says what Java rejects in the words
    /// `String.format`'s run-time error carries.
    #[test]
    fn rejections_are_typed_and_worded() {
        for (fmt, v, want, text) in [
            (
                "%d",
                Value::Float(1.0),
                FormatError::Mismatch {
                    conv: 'd',
                    what: "a Float",
                },
                "`%d` cannot format a Float",
            ),
            (
                "%d %d",
                Value::Int(1),
                FormatError::OneArgument {
                    body: "d".into(),
                    index: 2,
                },
                "`%d` asks for argument 2, but there is one argument",
            ),
            (
                "%-d",
                Value::Int(1),
                FormatError::FlagNeedsWidth("-d".into()),
                "the `-` and `0` flags need a width (`%-d`)",
            ),
            (
                "%<d",
                Value::Int(1),
                FormatError::NoEarlierArgument,
                "`%<` refers to no earlier argument",
            ),
            (
                "%.20000f",
                Value::Float(1.0),
                FormatError::FieldTooLarge(".20000f".into()),
                "a width or precision above 10000 in `%.20000f` is not supported",
            ),
            (
                "%2000000000000000000000d",
                Value::Int(1),
                FormatError::WidthTooLarge("2000000000000000000000".into()),
                "width `2000000000000000000000` is too large",
            ),
            (
                "%,a",
                Value::Float(1.0),
                FormatError::FlagsNotAllowed('a'),
                "flags not allowed with `%a`",
            ),
            (
                "abc %",
                Value::Int(1),
                FormatError::NoConversionCharacter(String::new()),
                "`%` lacks a conversion character",
            ),
        ] {
            let got = java_format(fmt, &v);
            assert_eq!(got.as_ref().err(), Some(&want), "{fmt}");
            assert_eq!(
                got.err().map(|e| e.to_string()).as_deref(),
                Some(text),
                "{fmt}"
            );
        }
    }
}
