//! TeSSLa's input trace format: `TS: name = value`, `TS: name` (a unit event), comments (`--`,
//! `#`) and blank lines. Values: integers, floats, strings with escapes, `true`/`false`, `()`,
//! tuples, `Some(x)`/`None`, `List(...)`, records `{a = 1}`; each checked against the input's
//! declared element type.

use std::sync::Arc;
use tessla_engine::{Program, Type, Value};

#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    pub line: usize,
    pub ts: i64,
    pub input: usize,
    pub value: Value,
}

/// The events of a trace in order; a malformed line is an `Err` naming it.
pub fn events<'a>(
    text: &'a str,
    program: &'a Program,
) -> impl Iterator<Item = Result<Event, String>> + 'a {
    text.lines().enumerate().filter_map(move |(i, raw)| {
        let line = i + 1;
        let l = strip_comment(raw).trim();
        if l.is_empty() {
            return None;
        }
        Some(parse_line(l, line, program))
    })
}

/// The line without a trailing `#` or `--` comment (outside string literals).
fn strip_comment(line: &str) -> &str {
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
            b'#' if !in_str => return &line[..i],
            b'-' if !in_str && bytes.get(i + 1) == Some(&b'-') => return &line[..i],
            _ => {}
        }
    }
    line
}

fn parse_line(l: &str, line: usize, program: &Program) -> Result<Event, String> {
    let (ts, rest) = l
        .split_once(':')
        .ok_or_else(|| format!("line {line}: expected `TIMESTAMP: name = value`"))?;
    let ts: i64 = ts
        .trim()
        .parse()
        .map_err(|_| format!("line {line}: `{}` is not an integer timestamp", ts.trim()))?;
    let (name, value) = match rest.split_once('=') {
        Some((n, v)) => (n.trim(), Some(v.trim())),
        None => (rest.trim(), None),
    };
    let input = program
        .input_index(name)
        .ok_or_else(|| format!("line {line}: undeclared input stream `{name}`"))?;
    let ty = &program.inputs[input].ty;
    let value = match value {
        None => Value::Unit,
        Some(v) => {
            let mut p = ValueParser {
                s: v.as_bytes(),
                pos: 0,
            };
            let val = p
                .value()
                .ok_or_else(|| format!("line {line}: cannot read the value `{v}`"))?;
            p.ws();
            if p.pos != p.s.len() {
                return Err(format!(
                    "line {line}: unexpected text after the value `{v}`"
                ));
            }
            val
        }
    };
    if !fits(&value, ty) {
        return Err(format!(
            "line {line}: value `{value}` of `{name}` does not have the declared type {ty:?}"
        ));
    }
    Ok(Event {
        line,
        ts,
        input,
        value,
    })
}

fn fits(v: &Value, t: &Type) -> bool {
    match (v, t) {
        (_, Type::Unknown) => true,
        (Value::Unit, Type::Unit)
        | (Value::Bool(_), Type::Bool)
        | (Value::Int(_), Type::Int)
        | (Value::Float(_), Type::Float)
        | (Value::Str(_), Type::String)
        | (Value::None, Type::Option(_)) => true,
        (Value::Some(x), Type::Option(t)) => fits(x, t),
        (Value::List(l), Type::List(t)) => l.iter().all(|x| fits(x, t)),
        (Value::Tuple(xs), Type::Tuple(ts)) => {
            xs.len() == ts.len() && xs.iter().zip(ts).all(|(x, t)| fits(x, t))
        }
        (Value::Record(_), Type::Record(_)) => true,
        _ => false,
    }
}

struct ValueParser<'a> {
    s: &'a [u8],
    pos: usize,
}

impl ValueParser<'_> {
    fn ws(&mut self) {
        while self.s.get(self.pos).is_some_and(u8::is_ascii_whitespace) {
            self.pos += 1;
        }
    }

    fn eat(&mut self, t: &str) -> bool {
        self.ws();
        if self.s[self.pos..].starts_with(t.as_bytes()) {
            self.pos += t.len();
            true
        } else {
            false
        }
    }

    fn list(&mut self, close: u8) -> Option<Vec<Value>> {
        let mut out = Vec::new();
        self.ws();
        if self.s.get(self.pos) == Some(&close) {
            self.pos += 1;
            return Some(out);
        }
        loop {
            out.push(self.value()?);
            self.ws();
            match self.s.get(self.pos) {
                Some(b',') => self.pos += 1,
                Some(c) if *c == close => {
                    self.pos += 1;
                    return Some(out);
                }
                _ => return None,
            }
        }
    }

    fn value(&mut self) -> Option<Value> {
        self.ws();
        if self.eat("true") {
            return Some(Value::Bool(true));
        }
        if self.eat("false") {
            return Some(Value::Bool(false));
        }
        if self.eat("None") {
            return Some(Value::None);
        }
        if self.eat("Some(") {
            let v = self.value()?;
            return self.eat(")").then(|| Value::Some(Arc::new(v)));
        }
        if self.eat("List(") {
            return self.list(b')').map(|l| Value::List(Arc::new(l)));
        }
        if self.eat("(") {
            let l = self.list(b')')?;
            return Some(match l.len() {
                0 => Value::Unit,
                1 => l.into_iter().next()?,
                _ => Value::Tuple(l.into()),
            });
        }
        if self.eat("{") {
            let mut fields: Vec<(Arc<str>, Value)> = Vec::new();
            loop {
                self.ws();
                if self.eat("}") {
                    break;
                }
                let start = self.pos;
                while self
                    .s
                    .get(self.pos)
                    .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_')
                {
                    self.pos += 1;
                }
                let name = std::str::from_utf8(&self.s[start..self.pos])
                    .ok()?
                    .to_string();
                if !(self.eat("=") || self.eat(":")) {
                    return None;
                }
                fields.push((name.into(), self.value()?));
                self.eat(",");
            }
            fields.sort_by(|a, b| a.0.cmp(&b.0));
            return Some(Value::Record(fields.into()));
        }
        if self.s.get(self.pos) == Some(&b'"') {
            self.pos += 1;
            let mut out = Vec::new();
            while let Some(&c) = self.s.get(self.pos) {
                self.pos += 1;
                match c {
                    b'"' => return String::from_utf8(out).ok().map(|s| Value::Str(s.into())),
                    b'\\' => {
                        let e = *self.s.get(self.pos)?;
                        self.pos += 1;
                        out.push(match e {
                            b'n' => b'\n',
                            b't' => b'\t',
                            b'r' => b'\r',
                            other => other,
                        });
                    }
                    _ => out.push(c),
                }
            }
            return None;
        }
        let start = self.pos;
        if self.s[self.pos..].starts_with(b"0x") || self.s[self.pos..].starts_with(b"-0x") {
            let neg = self.s[self.pos] == b'-';
            self.pos += if neg { 3 } else { 2 };
            let hs = self.pos;
            while self.s.get(self.pos).is_some_and(u8::is_ascii_hexdigit) {
                self.pos += 1;
            }
            let h = std::str::from_utf8(&self.s[hs..self.pos]).ok()?;
            let v = i64::from_str_radix(h, 16).ok()?;
            return Some(Value::Int(if neg { -v } else { v }));
        }
        while self
            .s
            .get(self.pos)
            .is_some_and(|c| c.is_ascii_digit() || matches!(c, b'-' | b'+' | b'.' | b'e' | b'E'))
        {
            self.pos += 1;
        }
        let t = std::str::from_utf8(&self.s[start..self.pos]).ok()?;
        if let Ok(i) = t.parse::<i64>() {
            return Some(Value::Int(i));
        }
        t.parse::<f64>().ok().map(Value::Float)
    }
}
