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
//! `tessla_engine::ops` (so a negative shift shifts the other way, as TeSSLa's
//! unbounded integers do).
//!
//! The evaluator is the trace reader's own, not the engine's constant folding: the engine folds
//! typed IR code after type checking and lowering, while a trace value is typed by its value
//! (an operator applies to the values it meets, `-1.5` is a float, a record `{_1 = a}` may
//! stand for a tuple, an integer literal beyond 64 bits is read), is checked against the
//! declared type only afterwards, and has TeSSLa's own error wording. What they share is the
//! engine's: operators (`ops`), sets and maps (`collections`), values and the type notation
//! (`Type`'s `Display`).
//!
//! Here: the line form, its events and errors. Apart: `csv` (the CSV form), `literal` (the
//! literal cursor, shared with the fast path), `eval` (constant expressions) and `coerce` (a
//! value against the declared type).

mod coerce;
mod csv;
mod eval;
mod literal;

use coerce::coerce;
pub use csv::CsvReader;
use eval::read_expression;
pub(crate) use literal::Lit;
use literal::literal;
use std::sync::Arc;
use tessla_engine::ops::{self, OpError};
use tessla_engine::{Program, Type, Value};
use tessla_syntax::ast::{BinOp, Expr, ExprKind, StrPart, UnaryOp};
use tessla_syntax::source::FileId;

/// One input event of a trace.
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    /// 1-based line number in the trace.
    pub line: usize,
    /// Its timestamp, in the trace's time unit.
    pub ts: i64,
    /// Index into `Program::inputs`.
    pub input: usize,
    /// Its value, of the input's declared type.
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
/// A trace line that cannot be read: what kind of problem, where, and what.
pub struct ReadError {
    /// Malformed or unsupported.
    pub kind: ReadErrorKind,
    /// 1-based line number in the trace.
    pub line: usize,
    /// What is wrong with the line.
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
    /// An event on a declared input.
    Event(Event),
    /// An event on a stream the spec does not declare.
    Undeclared {
        /// 1-based line number in the trace.
        line: usize,
        /// Its timestamp: time still advances to it.
        ts: i64,
        /// The stream's name.
        name: String,
    },
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
            tessla_engine::collections::set_of(vec![Value::Int(1), Value::Int(2)])
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
