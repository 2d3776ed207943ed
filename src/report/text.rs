//! Numbers and text for people, as the report's terminal views, pages and charts show them.
//!
//! Owns: [`short`] (a number in at most 4 significant digits) and [`wrap`] (word-wrapping under a
//! head); they depend on nothing else in the report.

/// A number for people: at most 4 significant digits (a whole number from 1000 to a million in
/// full), never `-0`.
pub fn short(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return if v.is_finite() {
            "0".into()
        } else {
            v.to_string()
        };
    }
    let s = if v.abs() >= 1e-3 && v.abs() < 1e6 {
        // Four significant digits: as many decimals as the magnitude leaves (none from 1000 on,
        // where the whole number is shown).
        let magnitude = v.abs().log10().floor() as i32;
        let decimals = usize::try_from(3 - magnitude).unwrap_or(0);
        let text = format!("{v:.decimals$}");
        if text.contains('.') {
            text.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            text
        }
    } else {
        // `5.000e-4` as `5e-4`, `1.250e-5` as `1.25e-5`.
        let text = format!("{v:.3e}");
        match text.split_once('e') {
            Some((mantissa, exp)) if mantissa.contains('.') => {
                let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
                format!("{mantissa}e{exp}")
            }
            _ => text,
        }
    };
    if s == "-0" { "0".into() } else { s }
}

/// `head` then `text`, word-wrapped so no line is wider than `width` (unless one word is);
/// continuation lines indented under the text, `extra_indent` further.
pub fn wrap(head: &str, text: &str, width: usize, extra_indent: usize) -> String {
    let indent = " ".repeat(head.chars().count() + extra_indent);
    let mut out = String::new();
    let mut line = head.to_string();
    let mut empty = true;
    for word in text.split(' ').filter(|w| !w.is_empty()) {
        let len = line.chars().count() + usize::from(!empty) + word.chars().count();
        if !empty && len > width {
            out.push_str(&line);
            out.push('\n');
            line = indent.clone();
            empty = true;
        }
        if !empty {
            line.push(' ');
        }
        line.push_str(word);
        empty = false;
    }
    out.push_str(&line);
    out.push('\n');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_for_people_never_show_minus_zero() {
        assert_eq!(short(-0.0), "0");
        assert_eq!(short(-0.00001), "-1e-5");
        assert_eq!(short(0.0005), "5e-4");
        assert_eq!(short(0.0000125), "1.25e-5");
        assert_eq!(short(0.0575), "0.0575");
        assert_eq!(short(0.099999999), "0.1");
        assert_eq!(short(-0.00004), "-4e-5");
        assert_eq!(short(123.456), "123.5");
        assert_eq!(short(80.6455), "80.65");
        assert_eq!(short(9.99996), "10");
        assert_eq!(short(1.5999999999999996), "1.6");
        assert_eq!(short(4321.7), "4322");
        assert_eq!(short(0.0012346), "0.001235");
    }

    #[test]
    fn wraps_at_commas() {
        let w = wrap("   1.0 s ", "aaaa bbbb, cccc dddd, eeee", 22, 0);
        assert_eq!(
            w,
            "   1.0 s aaaa bbbb,\n         cccc dddd,\n         eeee\n"
        );
        assert_eq!(wrap("  ", "a b c", 5, 2), "  a b\n    c\n");
        for line in w.lines() {
            assert!(line.chars().count() <= 22);
        }
    }
}
