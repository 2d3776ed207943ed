//! The literal cursor: plain literals and tuples of them read without the parser (`literal`),
//! and the typed reading of the fast path (`crate::fast`) on the same cursor. It takes only
//! what the parser reads the same way and leaves everything else, and every message, to it.

use super::*;

/// The value of `text` when it is a plain literal or a tuple of them (what most traces hold):
/// a decimal `Int` within 18 digits, a decimal `Float`, `true`, `false`, `()`, a string without
/// escapes or `$`/`%`, each maybe negated (`-`) and surrounded by spaces. `None` for anything
/// else, which the general parser then reads (and reports, when it is not a value): the fast
/// path accepts nothing the parser would read differently or refuse.
pub(super) fn literal(text: &str) -> Option<Value> {
    let mut p = Lit {
        b: text.as_bytes(),
        i: 0,
    };
    let v = p.value(0)?;
    p.spaces();
    (p.i == p.b.len()).then_some(v)
}

/// The cursor of [`literal`], and of the typed reading of the fast path (`crate::fast`).
pub(crate) struct Lit<'a> {
    pub(crate) b: &'a [u8],
    pub(crate) i: usize,
}

impl Lit<'_> {
    #[inline(always)]
    fn peek(&self) -> Option<u8> {
        self.b.get(self.i).copied()
    }

    #[inline(always)]
    pub(crate) fn spaces(&mut self) {
        while matches!(self.peek(), Some(b' ' | b'\t')) {
            self.i += 1;
        }
    }

    /// A `,` (after spaces), or `None`.
    #[inline(always)]
    fn comma(&mut self) -> Option<()> {
        self.spaces();
        (self.peek() == Some(b',')).then(|| self.i += 1)
    }

    /// Whether a `)` follows (after spaces); it is consumed.
    #[inline(always)]
    fn close(&mut self) -> bool {
        self.spaces();
        let close = self.peek() == Some(b')');
        if close {
            self.i += 1;
        }
        close
    }

    fn digits(&mut self) -> usize {
        let start = self.i;
        while self.peek().is_some_and(|c| c.is_ascii_digit()) {
            self.i += 1;
        }
        self.i - start
    }

    fn value(&mut self, depth: usize) -> Option<Value> {
        self.spaces();
        match self.peek()? {
            b'-' | b'0'..=b'9' => self.number(),
            b'"' => self.string(),
            b't' | b'f' => self.boolean(),
            b'(' if depth < 8 => {
                self.i += 1;
                self.spaces();
                if self.peek() == Some(b')') {
                    self.i += 1;
                    return Some(Value::Unit);
                }
                // Two to four elements: `(x)` is `x` in parentheses and `(x,)` a tuple, both
                // left to the parser, as are longer tuples.
                let a = self.value(depth + 1)?;
                self.comma()?;
                let b = self.value(depth + 1)?;
                if self.close() {
                    return Some(Value::Tuple(Arc::new([a, b])));
                }
                self.comma()?;
                let c = self.value(depth + 1)?;
                if self.close() {
                    return Some(Value::Tuple(Arc::new([a, b, c])));
                }
                self.comma()?;
                let d = self.value(depth + 1)?;
                self.close().then(|| Value::Tuple(Arc::new([a, b, c, d])))
            }
            _ => None,
        }
    }

    /// What [`Lit::value`] reads, when it is a value of type `ty` (what [`fits`] it), without
    /// reading anything of another type: `None` otherwise. The fast path reads by the input's
    /// declared type, so it never builds a value only to find it does not fit.
    #[inline(always)]
    pub(crate) fn typed(&mut self, ty: &Type, depth: usize) -> Option<Value> {
        match ty {
            Type::Tuple(ts) if ts.iter().all(|t| !matches!(t, Type::Tuple(_))) => {
                self.flat_tuple(ts, depth)
            }
            Type::Tuple(ts) => self.tuple(ts, depth),
            _ => self.scalar(ty, depth),
        }
    }

    /// [`Lit::tuple`] for a tuple of scalars: every element read in place, no call per element
    /// (what most traces hold: `(1, 2)`).
    #[inline(always)]
    fn flat_tuple(&mut self, ts: &[Type], depth: usize) -> Option<Value> {
        self.spaces();
        if depth >= 8 || self.peek()? != b'(' {
            return None;
        }
        self.i += 1;
        let d = depth + 1;
        match ts {
            [ta, tb] => {
                let a = self.scalar(ta, d)?;
                self.comma()?;
                let b = self.scalar(tb, d)?;
                self.close().then(|| Value::Tuple(Arc::new([a, b])))
            }
            [ta, tb, tc] => {
                let a = self.scalar(ta, d)?;
                self.comma()?;
                let b = self.scalar(tb, d)?;
                self.comma()?;
                let c = self.scalar(tc, d)?;
                self.close().then(|| Value::Tuple(Arc::new([a, b, c])))
            }
            [ta, tb, tc, td] => {
                let a = self.scalar(ta, d)?;
                self.comma()?;
                let b = self.scalar(tb, d)?;
                self.comma()?;
                let c = self.scalar(tc, d)?;
                self.comma()?;
                let d = self.scalar(td, d)?;
                self.close().then(|| Value::Tuple(Arc::new([a, b, c, d])))
            }
            _ => None,
        }
    }

    /// [`Lit::typed`] for a type that is no tuple.
    #[inline(always)]
    fn scalar(&mut self, ty: &Type, depth: usize) -> Option<Value> {
        self.spaces();
        match ty {
            Type::Int => self.int(),
            Type::Float => match self.peek()? {
                b'-' | b'0'..=b'9' => self.number().filter(|v| matches!(v, Value::Float(_))),
                _ => None,
            },
            Type::Bool => self.boolean(),
            Type::String => match self.peek()? {
                b'"' => self.string(),
                _ => None,
            },
            Type::Unit if depth < 8 => {
                (self.peek()? == b'(').then(|| self.i += 1)?;
                self.close().then_some(Value::Unit)
            }
            _ => None,
        }
    }

    /// [`Lit::typed`] for a tuple type: as [`Lit::value`], two to four elements.
    fn tuple(&mut self, ts: &[Type], depth: usize) -> Option<Value> {
        self.spaces();
        if depth >= 8 || self.peek()? != b'(' {
            return None;
        }
        self.i += 1;
        // An element: a scalar read in place, a tuple by a call.
        let elem = |p: &mut Self, t: &Type| match t {
            Type::Tuple(ts) => p.tuple(ts, depth + 1),
            _ => p.scalar(t, depth + 1),
        };
        match ts {
            [ta, tb] => {
                let a = elem(self, ta)?;
                self.comma()?;
                let b = elem(self, tb)?;
                self.close().then(|| Value::Tuple(Arc::new([a, b])))
            }
            [ta, tb, tc] => {
                let a = elem(self, ta)?;
                self.comma()?;
                let b = elem(self, tb)?;
                self.comma()?;
                let c = elem(self, tc)?;
                self.close().then(|| Value::Tuple(Arc::new([a, b, c])))
            }
            [ta, tb, tc, td] => {
                let a = elem(self, ta)?;
                self.comma()?;
                let b = elem(self, tb)?;
                self.comma()?;
                let c = elem(self, tc)?;
                self.comma()?;
                let d = elem(self, td)?;
                self.close().then(|| Value::Tuple(Arc::new([a, b, c, d])))
            }
            _ => None,
        }
    }

    /// What [`Lit::number`] reads when it is an `Int`, in one pass over the digits.
    #[inline(always)]
    fn int(&mut self) -> Option<Value> {
        let neg = self.peek() == Some(b'-');
        if neg {
            self.i += 1;
        }
        let start = self.i;
        let mut n: i64 = 0;
        while let Some(&c) = self.b.get(self.i) {
            let d = c.wrapping_sub(b'0');
            if d > 9 {
                break;
            }
            n = n.wrapping_mul(10).wrapping_add(i64::from(d));
            self.i += 1;
        }
        let len = self.i - start;
        // As `number`: no hex, no leading zeros, at most 18 digits (no overflow), and no `.`,
        // exponent or name after the digits.
        if len == 0 || len > 18 || (len > 1 && self.b.get(start) == Some(&b'0')) {
            return None;
        }
        if self
            .peek()
            .is_some_and(|c| c.is_ascii_alphanumeric() || c == b'_' || c == b'.')
        {
            return None;
        }
        Some(Value::Int(if neg { -n } else { n }))
    }

    /// A string literal without escapes, `$` or `%` (at the opening quote).
    fn string(&mut self) -> Option<Value> {
        let start = self.i + 1;
        let len = self.b.get(start..)?.iter().position(|&c| c == b'"')?;
        let body = self.b.get(start..start + len)?;
        if body.iter().any(|&c| matches!(c, b'\\' | b'$' | b'%')) {
            return None;
        }
        self.i = start + len + 1;
        Some(Value::Str(std::str::from_utf8(body).ok()?.into()))
    }

    /// `true` or `false`, not followed by a name character (`trueish` is a name).
    fn boolean(&mut self) -> Option<Value> {
        let rest = self.b.get(self.i..)?;
        let (word, v) = if rest.starts_with(b"true") {
            (4, true)
        } else if rest.starts_with(b"false") {
            (5, false)
        } else {
            return None;
        };
        if rest
            .get(word)
            .is_some_and(|&c| c.is_ascii_alphanumeric() || c == b'_')
        {
            return None;
        }
        self.i += word;
        Some(Value::Bool(v))
    }

    /// `-`? digits, then `.` digits and/or an exponent for a float; the lexer's forms only.
    fn number(&mut self) -> Option<Value> {
        let neg = self.peek() == Some(b'-');
        if neg {
            self.i += 1;
        }
        let digits_at = self.i;
        let n = self.digits();
        // No hex, no leading zeros (`0x1f`, `007`): left to the parser.
        if n == 0 || n > 18 || (n > 1 && self.b.get(digits_at) == Some(&b'0')) {
            return None;
        }
        let mut float = false;
        if self.peek() == Some(b'.') {
            self.i += 1;
            if self.digits() == 0 {
                return None;
            }
            float = true;
        }
        if self.peek() == Some(b'e') {
            self.i += 1;
            if matches!(self.peek(), Some(b'+' | b'-')) {
                self.i += 1;
            }
            if self.digits() == 0 {
                return None;
            }
            float = true;
        }
        // A literal followed by a name or a `.` (`1x`, `1.e`) is not a plain literal.
        if self
            .peek()
            .is_some_and(|c| c.is_ascii_alphanumeric() || c == b'_' || c == b'.')
        {
            return None;
        }
        let text = self.b.get(digits_at..self.i)?;
        if float {
            let f: f64 = std::str::from_utf8(text).ok()?.parse().ok()?;
            Some(Value::Float(if neg { -f } else { f }))
        } else {
            // At most 18 digits: no overflow.
            let i = text.iter().fold(0i64, |n, d| n * 10 + i64::from(d - b'0'));
            Some(Value::Int(if neg { -i } else { i }))
        }
    }
}
