//! A trace value's constant expression, parsed with `tessla_syntax::parse_expr` and evaluated
//! here (see the parent module for why not by the engine's folding): operators, `if`, tuples,
//! records, options, lists, sets and maps, with TeSSLa's own error wording.

use super::*;

/// [`read_value`] by the general parser: any constant expression, and the messages for text
/// that is none.
pub(super) fn read_expression(text: &str, line: usize) -> Result<Value, ReadError> {
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
pub(super) fn show(v: &Value) -> String {
    match v {
        Value::Str(s) => format!("{s:?}"),
        other => other.to_string(),
    }
}
