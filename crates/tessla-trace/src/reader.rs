//! TeSSLa's input trace format, one event per line: `TS: name = value`, `TS: name` (a unit
//! event), comments (`--`, `#`) and blank lines.
//!
//! A value is a constant TeSSLa expression, as in TeSSLa's interpreter: literals (ints, hex
//! ints, floats, strings with escapes and `${...}` interpolation, `true`/`false`, `()`),
//! tuples, `Some(x)`/`None`, `List(...)`, records `{a = 1}`/`${a: 1}`, operators and
//! `if then else`. It is parsed with `tessla_syntax::parse_expr` (the spec grammar is a superset
//! of the trace grammar) and evaluated here, then checked against the input's declared type (a
//! record `{_1 = a, _2 = b}` is a tuple, as TeSSLa treats tuples as records). `Set(...)` and
//! `Map(k -> v, ...)` build set and map values (`->` only occurs in maps, so it is read as a
//! comma and the arguments are paired). Plain literals and tuples of them, what most traces
//! hold, are read by a fast path first (`literal`); it takes only what the parser reads the
//! same way, and leaves everything else (and every message) to it. Whole event lines of that
//! kind are read before this module sees them, by the input's type (`crate::fast`, with
//! `Lit`'s typed reading); what that path leaves comes here as before. Integers are unbounded, as
//! TeSSLa's `Int`. Operators mean what they mean in a spec: their semantics are
//! `tessla_engine::runtime::ops` (so a negative shift shifts the other way, as TeSSLa's
//! unbounded integers do).
//!
//! The evaluator is the trace reader's own, not the engine's constant folding: the engine folds
//! typed IR code after type checking and lowering, while a trace value is typed by its value
//! (an operator applies to the values it meets, `-1.5` is a float, a record `{_1 = a}` may
//! stand for a tuple, an integer literal beyond 64 bits is read), is checked against the
//! declared type only afterwards, and has TeSSLa's own error wording. What they share is the
//! engine's: operators (`ops`), sets and maps (`collections`), values and the type notation
//! (`Type`'s `Display`).

use std::sync::Arc;
use tessla_engine::runtime::ops::{self, OpError};
use tessla_engine::{Program, Type, Value};
use tessla_syntax::ast::{BinOp, Expr, ExprKind, StrPart, UnaryOp};
use tessla_syntax::source::FileId;

/// One input event of a trace.
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    /// 1-based line number in the trace.
    pub line: usize,
    pub ts: i64,
    /// Index into `Program::inputs`.
    pub input: usize,
    pub value: Value,
}

/// Why a trace line could not be read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ReadErrorKind {
    /// Not an event line, an undeclared input, a value that does not fit the declared type.
    Malformed,
    /// A value this engine cannot represent (the message names the feature).
    Unsupported,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReadError {
    pub kind: ReadErrorKind,
    /// 1-based line number in the trace.
    pub line: usize,
    pub message: String,
}

impl std::fmt::Display for ReadError {
    /// `line N: message`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line {}: {}", self.line, self.message)
    }
}

impl std::error::Error for ReadError {}

impl ReadError {
    fn malformed(line: usize, message: impl Into<String>) -> ReadError {
        ReadError {
            kind: ReadErrorKind::Malformed,
            line,
            message: message.into(),
        }
    }
}

/// One event of a trace as read: on a declared input, or on a stream the spec does not declare
/// (its value was read, but not checked against a type).
#[derive(Debug, Clone, PartialEq)]
pub enum Read {
    Event(Event),
    Undeclared { line: usize, ts: i64, name: String },
}

/// Read one line of a trace: `None` for blank and comment lines. An event on an undeclared
/// stream is an error (see [`parse_line_any`] to keep it).
pub fn parse_line(raw: &str, line: usize, program: &Program) -> Option<Result<Event, ReadError>> {
    parse_line_any(raw, line, program).map(|r| {
        r.and_then(|read| match read {
            Read::Event(e) => Ok(e),
            Read::Undeclared { line, name, .. } => Err(undeclared(line, &name, program)),
        })
    })
}

/// Read one line of a trace: `None` for blank and comment lines.
pub fn parse_line_any(
    raw: &str,
    line: usize,
    program: &Program,
) -> Option<Result<Read, ReadError>> {
    let l = trim(strip_comment(raw));
    if l.is_empty() {
        return None;
    }
    Some(parse_event(l, line, program))
}

/// "Undeclared input stream NAME" (TeSSLa's message), with the declared inputs nearest to it.
pub fn undeclared(line: usize, name: &str, program: &Program) -> ReadError {
    let near = tessla_syntax::diag::nearest(name, program.inputs.iter().map(|i| i.name.as_str()));
    let mut message = format!("Undeclared input stream {name}");
    if !near.is_empty() {
        let near: Vec<String> = near.iter().map(|n| format!("`{n}`")).collect();
        message.push_str(&format!(" (did you mean {}?)", near.join(" or ")));
    }
    ReadError::malformed(line, message)
}

/// A CSV trace as TeSSLa's interpreter reads it (`--csv`): a header `time,a,b` (the first
/// column's name is not used) and then lines `TS,value,value` with one column per stream; an
/// empty column is no event. Columns are TeSSLa expressions, split at top-level commas (a
/// string, tuple or list may hold commas), so this is not RFC 4180 CSV: a quote opens a TeSSLa
/// string literal, not a quoted field.
#[derive(Debug, Default)]
pub struct CsvReader {
    header: Option<Vec<String>>,
}

impl CsvReader {
    /// The events of one line (none for the header, blank and comment lines).
    pub fn parse_line(
        &mut self,
        raw: &str,
        line: usize,
        program: &Program,
    ) -> Result<Vec<Read>, ReadError> {
        let l = strip_comment(raw).trim();
        if l.is_empty() {
            return Ok(Vec::new());
        }
        let columns = split_top_level_commas(l);
        let Some(header) = &self.header else {
            let names: Vec<String> = columns.iter().map(|c| c.trim().to_string()).collect();
            let ident = |n: &str| {
                n.chars()
                    .next()
                    .is_some_and(|c| c.is_alphabetic() || c == '_')
                    && n.chars().all(|c| c.is_alphanumeric() || c == '_')
            };
            if names.len() < 2 || !names.iter().all(|n| ident(n)) {
                return Err(ReadError::malformed(
                    line,
                    "No header row found: the first line of a CSV trace names the columns, \
                     `time,stream1,stream2,...`",
                ));
            }
            self.header = Some(names.into_iter().skip(1).collect());
            return Ok(Vec::new());
        };
        let mut columns = columns.into_iter();
        let ts = parse_ts(columns.next().unwrap_or(""), line)?;
        let mut out = Vec::new();
        for (k, text) in columns.enumerate() {
            let text = text.trim();
            if text.is_empty() {
                continue;
            }
            let Some(name) = header.get(k) else {
                return Err(ReadError::malformed(
                    line,
                    format!(
                        "{} value columns, but the header names {} streams",
                        k + 1,
                        header.len()
                    ),
                ));
            };
            out.push(event(ts, name, Some(text), line, program)?);
        }
        Ok(out)
    }
}

/// `text` split at the commas outside string literals and brackets.
fn split_top_level_commas(text: &str) -> Vec<&str> {
    let mut parts = Vec::new();
    let (mut depth, mut in_str, mut escape, mut start) = (0i32, false, false, 0);
    for (i, c) in text.char_indices() {
        if escape {
            escape = false;
            continue;
        }
        match c {
            '\\' if in_str => escape = true,
            '"' => in_str = !in_str,
            '(' | '[' | '{' if !in_str => depth += 1,
            ')' | ']' | '}' if !in_str => depth -= 1,
            ',' if !in_str && depth == 0 => {
                parts.push(&text[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&text[start..]);
    parts
}

/// The events of a whole trace text, in order.
pub fn events<'a>(
    text: &'a str,
    program: &'a Program,
) -> impl Iterator<Item = Result<Event, ReadError>> + 'a {
    text.lines()
        .enumerate()
        .filter_map(move |(i, raw)| parse_line(raw, i + 1, program))
}

/// `s.trim()`, without its Unicode scan when spaces are all there is to trim (as nearly always).
fn trim(s: &str) -> &str {
    let b = s.as_bytes();
    let start = b.iter().position(|&c| c != b' ').unwrap_or(b.len());
    let end = b.iter().rposition(|&c| c != b' ').map_or(start, |e| e + 1);
    match (b.get(start), end.checked_sub(1).and_then(|e| b.get(e))) {
        (Some(x), Some(y)) if x.is_ascii_graphic() && y.is_ascii_graphic() => {
            s.get(start..end).unwrap_or(s)
        }
        _ => s.trim(),
    }
}

/// The line without a trailing `#` or `--` comment (outside string literals).
fn strip_comment(line: &str) -> &str {
    // Most lines hold no string and no comment: one quick pass over the bytes finds out.
    if !line.bytes().any(|b| matches!(b, b'#' | b'-' | b'"')) {
        return line;
    }
    let mut in_str = false;
    let mut escape = false;
    let bytes = line.as_bytes();
    for (i, &b) in bytes.iter().enumerate() {
        if escape {
            escape = false;
            continue;
        }
        match b {
            b'\\' if in_str => escape = true,
            b'"' => in_str = !in_str,
            b'#' if !in_str => return line.get(..i).unwrap_or(line),
            b'-' if !in_str && bytes.get(i + 1) == Some(&b'-') => {
                return line.get(..i).unwrap_or(line);
            }
            _ => {}
        }
    }
    line
}

fn parse_event(l: &str, line: usize, program: &Program) -> Result<Read, ReadError> {
    let (ts, rest) = l
        .split_once(':')
        .ok_or_else(|| ReadError::malformed(line, "expected `TIMESTAMP: name = value`"))?;
    let ts = parse_ts(ts, line)?;
    let (name, value) = match rest.split_once('=') {
        Some((n, v)) => (trim(n), Some(trim(v))),
        None => (trim(rest), None),
    };
    event(ts, name, value, line, program)
}

fn parse_ts(ts: &str, line: usize) -> Result<i64, ReadError> {
    let ts = trim(ts);
    // Plain digits (at most 18: no overflow) without `str::parse`.
    if (1..=18).contains(&ts.len()) && ts.bytes().all(|c| c.is_ascii_digit()) {
        return Ok(ts.bytes().fold(0, |n, d| n * 10 + i64::from(d - b'0')));
    }
    let ts: i64 = ts.parse().map_err(|_| {
        ReadError::malformed(
            line,
            format!("`{}` is not a non-negative integer timestamp", ts.trim()),
        )
    })?;
    if ts < 0 {
        return Err(ReadError::malformed(
            line,
            format!("timestamp {ts} is negative"),
        ));
    }
    Ok(ts)
}

/// The event `ts: name = value` (`value` `None` for a unit event). The value of an event on
/// an undeclared stream is read too (a bad one is an error, as in TeSSLa), but not type-checked.
fn event(
    ts: i64,
    name: &str,
    value: Option<&str>,
    line: usize,
    program: &Program,
) -> Result<Read, ReadError> {
    let Some(input) = program.input_index(name) else {
        // A value this engine cannot represent does not matter on a stream it ignores.
        if let Some(v) = value
            && let Err(e) = read_value(v, line)
            && e.kind == ReadErrorKind::Malformed
        {
            return Err(e);
        }
        return Ok(Read::Undeclared {
            line,
            ts,
            name: name.to_string(),
        });
    };
    let ty = program.inputs.get(input).map_or(&Type::Unknown, |i| &i.ty);
    let value = match value {
        None => Value::Unit,
        Some(v) => read_value(v, line)?,
    };
    let value = coerce(value, ty)
        .map_err(|why| ReadError::malformed(line, format!("input {name}: {why}")))?;
    Ok(Read::Event(Event {
        line,
        ts,
        input,
        value,
    }))
}

/// Parse and evaluate the value text of one event.
fn read_value(text: &str, line: usize) -> Result<Value, ReadError> {
    match literal(text) {
        Some(v) => Ok(v),
        None => read_expression(text, line),
    }
}

/// [`read_value`] by the general parser: any constant expression, and the messages for text
/// that is none.
fn read_expression(text: &str, line: usize) -> Result<Value, ReadError> {
    check_escapes(text).map_err(|m| ReadError::malformed(line, m))?;
    let unsupported = |feature: &str| ReadError {
        kind: ReadErrorKind::Unsupported,
        line,
        message: format!("{feature} in traces are not supported"),
    };
    let (expr, diags) = tessla_syntax::parse_expr(&arrows_as_commas(text), FileId(0));
    let expr = match (expr, diags.first()) {
        (Some(e), None) => e,
        // An integer beyond the parser's range: TeSSLa's `Int` is unbounded.
        (_, Some(d)) if d.message.contains("integer literal too large") => {
            return text
                .trim()
                .parse::<num_bigint::BigInt>()
                .map(Value::from_big)
                .map_err(|_| unsupported("Int expressions beyond 128 bits"));
        }
        (_, Some(d)) => {
            return Err(ReadError::malformed(
                line,
                format!("cannot read the value `{text}`: {}", d.message),
            ));
        }
        (None, None) => {
            return Err(ReadError::malformed(
                line,
                format!("cannot read the value `{text}`"),
            ));
        }
    };
    eval(&expr).map_err(|m| ReadError::malformed(line, format!("in the value `{text}`: {m}")))
}

/// The value of `text` when it is a plain literal or a tuple of them (what most traces hold):
/// a decimal `Int` within 18 digits, a decimal `Float`, `true`, `false`, `()`, a string without
/// escapes or `$`/`%`, each maybe negated (`-`) and surrounded by spaces. `None` for anything
/// else, which the general parser then reads (and reports, when it is not a value): the fast
/// path accepts nothing the parser would read differently or refuse.
fn literal(text: &str) -> Option<Value> {
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

/// `->` (outside string literals) replaced by `,`: in TeSSLa's trace grammar it only separates
/// a map entry's key from its value, and `Map(...)` pairs its arguments again.
fn arrows_as_commas(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut in_str = false;
    let mut escape = false;
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        if escape {
            escape = false;
        } else if c == '\\' && in_str {
            escape = true;
        } else if c == '"' {
            in_str = !in_str;
        } else if c == '-' && !in_str && chars.peek() == Some(&'>') {
            chars.next();
            out.push_str(", ");
            continue;
        }
        out.push(c);
    }
    out
}

/// TeSSLa's valid escapes; the syntax crate also reports others, but keeps `\\d` and `\d` alike
/// in the AST, so they are checked on the raw text.
fn check_escapes(text: &str) -> Result<(), String> {
    let mut in_str = false;
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        match c {
            '"' => in_str = !in_str,
            '\\' if in_str => match chars.next() {
                Some('n' | 'r' | 't' | 'a' | '\\' | '"' | '$' | '%') => {}
                Some(o) => return Err(format!("Invalid escape sequence '\\{o}' in string")),
                None => return Err("unterminated string".into()),
            },
            _ => {}
        }
    }
    Ok(())
}

/// Evaluate a constant trace expression, or say why it is not a trace value.
fn eval(e: &Expr) -> Result<Value, String> {
    match &e.kind {
        ExprKind::Int { value, unit: None } => Ok(Value::from_big((*value).into())),
        ExprKind::Int { unit: Some(u), .. } => Err(format!(
            "time units (`{}`) are not allowed in traces",
            u.name
        )),
        ExprKind::Float(f) => Ok(Value::Float(*f)),
        ExprKind::Str { parts, format } => {
            if *format {
                return Err("format strings are not allowed in traces".into());
            }
            let mut s = String::new();
            for p in parts {
                match p {
                    StrPart::Text(t) => s.push_str(t),
                    StrPart::Interp { expr, .. } => s.push_str(&eval(expr)?.to_string()),
                }
            }
            Ok(Value::Str(s.into()))
        }
        ExprKind::Tuple(items) => {
            let vals = items.iter().map(eval).collect::<Result<Vec<_>, _>>()?;
            Ok(if vals.is_empty() {
                Value::Unit
            } else {
                Value::Tuple(vals.into())
            })
        }
        ExprKind::Record(fields) => {
            let mut out: Vec<(Arc<str>, Value)> = Vec::new();
            for (name, v) in fields {
                if out.iter().any(|(n, _)| **n == *name.name) {
                    return Err(format!("member {} is given twice", name.name));
                }
                out.push((name.name.as_str().into(), eval(v)?));
            }
            out.sort_by(|a, b| a.0.cmp(&b.0));
            Ok(Value::Record(out.into()))
        }
        ExprKind::Var(id) => match id.name.as_str() {
            "true" => Ok(Value::Bool(true)),
            "false" => Ok(Value::Bool(false)),
            "None" => Ok(Value::None),
            other => Err(format!("`{other}` is not a value")),
        },
        ExprKind::Call {
            function,
            type_args,
            args: Some(args),
        } if type_args.is_empty() => {
            let ExprKind::Var(f) = &function.kind else {
                return Err("only `Some`, `List`, `Set` and `Map` may be called in traces".into());
            };
            if let Some(a) = args.iter().find_map(|a| a.name.as_ref()) {
                return Err(format!("named argument `{}` in a trace value", a.name));
            }
            let vals = args
                .iter()
                .map(|a| eval(&a.value))
                .collect::<Result<Vec<_>, _>>()?;
            match (f.name.as_str(), vals.len()) {
                ("Some", 1) => Ok(Value::Some(Arc::new(
                    vals.into_iter().next().unwrap_or(Value::Unit),
                ))),
                ("List", _) => Ok(Value::List(Arc::new(vals))),
                ("Set", _) => Ok(tessla_engine::runtime::collections::set_of(vals)),
                ("Map", n) if n % 2 == 0 => {
                    let mut map: Vec<(Value, Value)> = Vec::with_capacity(n / 2);
                    let mut it = vals.into_iter();
                    while let (Some(k), Some(v)) = (it.next(), it.next()) {
                        map.push((k, v));
                    }
                    // A repeated key keeps the last value, as Scala's `toMap` does.
                    Ok(tessla_engine::runtime::collections::map_of(map))
                }
                (other, n) => Err(format!("`{other}` with {n} arguments is not a trace value")),
            }
        }
        ExprKind::Unary { op, operand } => unary(*op, eval(operand)?),
        ExprKind::Binary { op, lhs, rhs } => match op {
            BinOp::And => match eval(lhs)? {
                Value::Bool(false) => Ok(Value::Bool(false)),
                Value::Bool(true) => bool_of(eval(rhs)?),
                v => Err(format!("`&&` needs Bool operands, found {}", show(&v))),
            },
            BinOp::Or => match eval(lhs)? {
                Value::Bool(true) => Ok(Value::Bool(true)),
                Value::Bool(false) => bool_of(eval(rhs)?),
                v => Err(format!("`||` needs Bool operands, found {}", show(&v))),
            },
            _ => binary(*op, eval(lhs)?, eval(rhs)?),
        },
        ExprKind::If {
            cond,
            then_branch,
            else_branch,
            ..
        } => match eval(cond)? {
            Value::Bool(true) => eval(then_branch),
            Value::Bool(false) => eval(else_branch),
            v => Err(format!(
                "an `if` condition must be a Bool, found {}",
                show(&v)
            )),
        },
        _ => Err("only constants, operators and `if` are allowed in trace values".into()),
    }
}

fn bool_of(v: Value) -> Result<Value, String> {
    match v {
        Value::Bool(_) => Ok(v),
        v => Err(format!("expected a Bool, found {}", show(&v))),
    }
}

/// An operator's semantics are the engine's ([`tessla_engine::runtime::ops`]); only the messages
/// are the trace reader's.
fn op_error(e: OpError, undefined: impl FnOnce() -> String) -> String {
    match e {
        OpError::Overflow => "Int overflow".into(),
        OpError::DivisionByZero => "Division by zero".into(),
        OpError::Undefined => undefined(),
    }
}

/// A unary operator as written in a trace.
fn unary_symbol(op: UnaryOp) -> &'static str {
    match op {
        UnaryOp::Not => "!",
        UnaryOp::BitNot => "~",
        UnaryOp::Neg => "-",
        UnaryOp::FNeg => "-.",
    }
}

fn unary(op: UnaryOp, v: Value) -> Result<Value, String> {
    match (op, v) {
        // A negative float literal: `-1.5` (TeSSLa's trace lexer reads it as one literal).
        (UnaryOp::Neg, Value::Float(f)) => Ok(Value::Float(-f)),
        (op, v) => ops::unary(op.into(), &v).map_err(|e| {
            op_error(e, || {
                format!(
                    "operator `{}` does not apply to {}",
                    unary_symbol(op),
                    show(&v)
                )
            })
        }),
    }
}

fn binary(op: BinOp, a: Value, b: Value) -> Result<Value, String> {
    ops::binary(op.into(), &a, &b).map_err(|e| {
        op_error(e, || {
            format!(
                "operator `{}` does not apply to {} and {}",
                op.symbol(),
                show(&a),
                show(&b)
            )
        })
    })
}

/// A value as TeSSLa shows it in input errors (strings quoted).
fn show(v: &Value) -> String {
    match v {
        Value::Str(s) => format!("{s:?}"),
        other => other.to_string(),
    }
}

/// Whether `v` is a value of type `t` as it is (scalars and tuples of them: what [`coerce`]
/// would give back unchanged).
fn fits(v: &Value, t: &Type) -> bool {
    match (v, t) {
        (Value::Unit, Type::Unit)
        | (Value::Bool(_), Type::Bool)
        | (Value::Int(_) | Value::BigInt(_), Type::Int)
        | (Value::Float(_), Type::Float)
        | (Value::Str(_), Type::String) => true,
        (Value::Tuple(xs), Type::Tuple(ts)) => {
            xs.len() == ts.len() && xs.iter().zip(ts).all(|(x, t)| fits(x, t))
        }
        _ => false,
    }
}

/// `v` as a value of type `t`, or why it is not one (TeSSLa's wording; types in the engine's
/// notation, `tessla_engine::Type`'s `Display`).
fn coerce(v: Value, t: &Type) -> Result<Value, String> {
    if fits(&v, t) {
        return Ok(v);
    }
    let mismatch = |v: &Value| format!("{} is not of type {t}.", show(v));
    match (v, t) {
        (v, Type::Unknown) => Ok(v),
        (v @ Value::Unit, Type::Unit)
        | (v @ Value::Bool(_), Type::Bool)
        | (v @ (Value::Int(_) | Value::BigInt(_)), Type::Int)
        | (v @ Value::Float(_), Type::Float)
        | (v @ Value::Str(_), Type::String)
        | (v @ Value::None, Type::Option(_)) => Ok(v),
        (Value::Some(x), Type::Option(inner)) => {
            Ok(Value::Some(Arc::new(coerce((*x).clone(), inner)?)))
        }
        (Value::List(xs), Type::List(inner)) => Ok(Value::List(Arc::new(
            xs.iter()
                .map(|x| coerce(x.clone(), inner))
                .collect::<Result<_, _>>()?,
        ))),
        (Value::Tuple(xs), Type::Tuple(ts)) if xs.len() == ts.len() => Ok(Value::Tuple(
            xs.iter()
                .zip(ts)
                .map(|(x, t)| coerce(x.clone(), t))
                .collect::<Result<Vec<_>, _>>()?
                .into(),
        )),
        // TeSSLa's tuples are records with members `_1`, `_2`, ...
        (Value::Record(fs), Type::Tuple(ts)) if fs.len() == ts.len() => {
            let mut out = Vec::with_capacity(ts.len());
            for (i, t) in ts.iter().enumerate() {
                let key = format!("_{}", i + 1);
                let x = fs
                    .iter()
                    .find(|(n, _)| **n == *key)
                    .map(|(_, x)| x.clone())
                    .ok_or_else(|| mismatch(&Value::Record(fs.clone())))?;
                out.push(coerce(x, t)?);
            }
            Ok(Value::Tuple(out.into()))
        }
        (Value::Record(fs), Type::Record(ts)) => {
            let mut out: Vec<(Arc<str>, Value)> = Vec::with_capacity(ts.len());
            for (n, ft) in ts {
                let x = fs
                    .iter()
                    .find(|(k, _)| **k == **n)
                    .map(|(_, x)| x.clone())
                    .ok_or_else(|| format!("Expected {t} but {n} is missing."))?;
                out.push((n.as_str().into(), coerce(x, ft)?));
            }
            if let Some((extra, _)) = fs.iter().find(|(k, _)| !ts.iter().any(|(n, _)| **k == **n)) {
                return Err(format!("Expected {t} but found the extra member {extra}."));
            }
            out.sort_by(|a, b| a.0.cmp(&b.0));
            Ok(Value::Record(out.into()))
        }
        (v, Type::Record(_)) => Err(format!("Expected {t} but found {}.", show(&v))),
        (v, _) => Err(mismatch(&v)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tests::program;

    fn read(spec: &str, line: &str) -> Result<Value, ReadError> {
        let p = program(spec);
        parse_line(line, 1, &p).unwrap().map(|e| e.value)
    }

    #[test]
    fn values_are_constant_expressions() {
        let spec = "in x: Events[Int]\nout x";
        assert_eq!(read(spec, "3: x = 42").unwrap(), Value::Int(42));
        assert_eq!(read(spec, "3: x = -7 # comment").unwrap(), Value::Int(-7));
        assert_eq!(read(spec, "3: x = 0xaffe").unwrap(), Value::Int(0xaffe));
        assert_eq!(read(spec, "3: x = 2 + 40 * 2").unwrap(), Value::Int(82));
        assert_eq!(
            read(spec, "3: x = if 1 < 2 then 5 else 6").unwrap(),
            Value::Int(5)
        );
        let s = "in s: Events[String]\nout s";
        assert_eq!(
            read(s, r#"1: s = "a ${2 + 40} \"q\" \$ -- no comment""#).unwrap(),
            Value::Str("a 42 \"q\" $ -- no comment".into())
        );
    }

    #[test]
    fn operators_mean_what_they_mean_in_a_spec() {
        let spec = "in x: Events[Int]\nout x";
        // A negative shift shifts the other way (TeSSLa's unbounded integers), in a trace as in
        // a spec; a result beyond 64 bits is a larger integer, not a wrapped value.
        assert_eq!(read(spec, "1: x = 8 << -3").unwrap(), Value::Int(1));
        assert_eq!(read(spec, "1: x = 1 >> -3").unwrap(), Value::Int(8));
        assert_eq!(
            read(spec, "1: x = 1 << 63").unwrap().to_string(),
            "9223372036854775808"
        );
        assert!(read(spec, "1: x = 1 / 0").is_err());
    }

    #[test]
    fn unit_events_and_comment_lines() {
        let p = program("in u: Events[Unit]\nout u");
        assert!(parse_line("  # only a comment", 1, &p).is_none());
        assert!(parse_line("-- another", 1, &p).is_none());
        assert!(parse_line("", 1, &p).is_none());
        let e = parse_line("5: u -- unit", 2, &p).unwrap().unwrap();
        assert_eq!((e.ts, e.input, e.value, e.line), (5, 0, Value::Unit, 2));
    }

    #[test]
    fn structured_values_follow_the_declared_type() {
        let spec = "in t: Events[(Int, String)]\nin o: Events[Option[List[Int]]]\n\
                    in r: Events[{x: Int, y: Float}]\nout t\nout o\nout r";
        assert_eq!(
            read(spec, r#"1: t = (1, "a")"#).unwrap(),
            Value::Tuple(vec![Value::Int(1), Value::Str("a".into())].into())
        );
        // TeSSLa's tuples are records with members _1, _2.
        assert_eq!(
            read(spec, r#"1: t = {_2 = "a", _1 = 1}"#).unwrap(),
            Value::Tuple(vec![Value::Int(1), Value::Str("a".into())].into())
        );
        assert_eq!(
            read(spec, "1: o = Some(List(1, 2))").unwrap(),
            Value::Some(Arc::new(Value::List(Arc::new(vec![
                Value::Int(1),
                Value::Int(2)
            ]))))
        );
        assert_eq!(read(spec, "1: o = None").unwrap(), Value::None);
        let r = read(spec, "1: r = ${y = 2.5, x = 1}").unwrap();
        assert_eq!(
            r,
            Value::Record(
                vec![
                    (Arc::from("x"), Value::Int(1)),
                    (Arc::from("y"), Value::Float(2.5))
                ]
                .into()
            )
        );
        let missing = read(spec, "1: r = {x: 1}").unwrap_err();
        assert_eq!(
            missing.message,
            "input r: Expected {x: Int, y: Float} but y is missing."
        );
    }

    #[test]
    fn sets_and_maps() {
        let spec = "in s: Events[Set[Int]]\nin m: Events[Map[Int, String]]\nout s\nout m";
        assert_eq!(
            read(spec, "1: s = Set(1, 2, 1)").unwrap(),
            tessla_engine::runtime::collections::set_of(vec![Value::Int(1), Value::Int(2)])
        );
        assert_eq!(
            read(spec, r#"1: m = Map(1 -> "a->b", 2 -> "c", 1 -> "d")"#).unwrap(),
            Value::Map(Arc::new(
                vec![
                    (Value::Int(1), Value::Str("d".into())),
                    (Value::Int(2), Value::Str("c".into()))
                ]
                .into()
            ))
        );
        assert_eq!(
            read(spec, "1: m = Map()").unwrap(),
            Value::Map(Arc::new(Vec::new().into()))
        );
    }

    #[test]
    fn bad_lines_say_what_is_wrong() {
        let spec = "in x: Events[Int]\nout x";
        let e = read(spec, r#"1: x = "text""#).unwrap_err();
        assert_eq!(e.message, "input x: \"text\" is not of type Int.");
        assert_eq!(e.kind, ReadErrorKind::Malformed);
        let e = read(spec, "1: y = 1").unwrap_err();
        assert_eq!(e.message, "Undeclared input stream y (did you mean `x`?)");
        let e = read(spec, "x = 1").unwrap_err();
        assert!(e.message.contains("TIMESTAMP"), "{}", e.message);
        let e = read(spec, "1: x = (1").unwrap_err();
        assert!(e.message.contains("cannot read the value"), "{}", e.message);
        let e = read(spec, "1: x = 1 / 0").unwrap_err();
        assert!(e.message.contains("Division by zero"), "{}", e.message);
        assert_eq!(
            read(spec, "1: x = 99999999999999999999999999999999999999999")
                .unwrap()
                .to_string(),
            "99999999999999999999999999999999999999999"
        );
        let s = "in s: Events[String]\nout s";
        let e = read(s, r#"1: s = "\d""#).unwrap_err();
        assert_eq!(e.message, "Invalid escape sequence '\\d' in string");
    }

    /// The fast path reads what the general parser reads, and leaves everything else to it.
    #[test]
    fn plain_literals_read_as_the_parser_reads_them() {
        let same = [
            "0",
            "7",
            "-7",
            "-0",
            "42",
            "123456789012345678",
            "-123456789012345678",
            "1.5",
            "-1.5",
            "0.25",
            "1e5",
            "1e-3",
            "1.5e+300",
            "-0.0",
            "3.0e-2",
            "true",
            "false",
            "()",
            "( )",
            r#""""#,
            r#""a b, c""#,
            r#""µ ü""#,
            "(1, 2)",
            "( 1 , -2 )",
            r#"(1, "x", true, 2.5)"#,
            "((1, 2), (3, (4, 5)))",
            "(1,2)",
            "\t5",
        ];
        for text in same {
            let fast = literal(text.trim());
            let general = read_expression(text.trim(), 1);
            assert_eq!(fast.as_ref(), general.as_ref().ok(), "{text}");
            assert!(fast.is_some(), "{text} should take the fast path");
        }
        // Left to the parser: other forms, and everything that is not a value.
        let general = [
            "007",
            "0x1f",
            "1234567890123456789",
            "1.",
            "1.e5",
            "1e",
            "1x",
            "- 1",
            "--1",
            "(1)",
            "(1,)",
            "(1, 2,)",
            "(1, 2",
            "(1 2)",
            r#""a\nb""#,
            r#""${1}""#,
            r#""50%""#,
            "trueish",
            "true1",
            "True",
            "1 + 2",
            "(1, 2, 3, 4, 5)",
            r#""open"#,
            "Some(1)",
            "None",
            "",
            "1.5.2",
            "2.5E3",
            "((((((((((1, 2), 3), 4), 5), 6), 7), 8), 9), 10), 11)",
        ];
        for text in general {
            assert_eq!(literal(text), None, "{text}");
        }
    }

    #[test]
    fn no_line_makes_the_reader_panic() {
        let spec = "in a: Events[(Int, String)]\nin b: Events[{x: Int}]\nin c: Events[Float]\n\
                    in d: Events[Map[Int, Set[String]]]\nout a\nout b\nout c\nout d";
        let p = program(spec);
        let lines = [
            r#"1: a = (1, "x${2}\"")"#,
            "2: b = ${x = -0x7fffffffffffffff - 1}",
            "3: c = -.1.5e300 *. 1e10",
            r#"4: d = Map(1 -> Set("a", "b"), 2 -> Set())"#,
            "5: a = {_1 = 9223372036854775807 + 1, _2 = \"\"}",
        ];
        let pieces = [
            "\"", "$", "${", "(", ")", "->", "\\", "µ", "--", "#", ":", "=", ",", "0x",
        ];
        let mut n = 0u64;
        for l in lines {
            for cut in 0..=l.len() {
                if !l.is_char_boundary(cut) {
                    continue;
                }
                for piece in pieces {
                    n += 1;
                    let mutated = format!("{}{piece}{}", &l[..cut], &l[cut..]);
                    let _ = parse_line(&mutated, 1, &p);
                    let _ = parse_line(&l[..cut], 1, &p);
                }
            }
        }
        assert!(n > 500);
    }
}
