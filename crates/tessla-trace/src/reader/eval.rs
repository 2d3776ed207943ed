//! A trace value's constant expression, parsed with `tessla_syntax::parse_expr` and evaluated
//! here (see the parent module for why not by the engine's folding): operators, `if`, tuples,
//! records, options, lists, sets and maps, with TeSSLa's own error wording.

use super::*;

/// [`read_value`] by the general parser: any constant expression, and the messages for text
/// that is none.
pub(super) fn read_expression(text: &str, line: usize) -> Result<Value, ReadError> {
    check_escapes(text).map_err(|m| ReadError::malformed(line, m.to_string()))?;
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

/// Why a trace value's text is no trace value (TeSSLa's wording where it has one).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub(super) enum EvalError {
    /// An escape TeSSLa does not know (the character after the backslash).
    #[error("Invalid escape sequence '\\{0}' in string")]
    Escape(char),
    /// A string without its closing quote.
    #[error("unterminated string")]
    Unterminated,
    /// A number with a time unit (the unit).
    #[error("time units (`{0}`) are not allowed in traces")]
    TimeUnit(String),
    /// `f"..."`.
    #[error("format strings are not allowed in traces")]
    FormatString,
    /// A record member given twice.
    #[error("member {0} is given twice")]
    TwiceGiven(String),
    /// A name that is not `true`, `false` or `None`.
    #[error("`{0}` is not a value")]
    NotAValue(String),
    /// A call of something other than a name.
    #[error("only `Some`, `List`, `Set` and `Map` may be called in traces")]
    Callee,
    /// A named argument.
    #[error("named argument `{0}` in a trace value")]
    NamedArgument(String),
    /// A call that makes no trace value (the function and its argument count).
    #[error("`{0}` with {1} arguments is not a trace value")]
    Call(String, usize),
    /// `&&` or `||` with an operand that is not a Bool (the operator, the operand shown).
    #[error("`{0}` needs Bool operands, found {1}")]
    Logic(&'static str, String),
    /// An `if` whose condition is not a Bool (shown).
    #[error("an `if` condition must be a Bool, found {0}")]
    Condition(String),
    /// Anything but constants, operators and `if`.
    #[error("only constants, operators and `if` are allowed in trace values")]
    NotConstant,
    /// A right operand of `&&`/`||` that is not a Bool (shown).
    #[error("expected a Bool, found {0}")]
    NotBool(String),
    /// An `Int` operation that overflows.
    #[error("Int overflow")]
    Overflow,
    /// Division by zero.
    #[error("Division by zero")]
    DivisionByZero,
    /// A unary operator on a value it does not apply to.
    #[error("operator `{0}` does not apply to {1}")]
    Unary(&'static str, String),
    /// A binary operator on values it does not apply to.
    #[error("operator `{0}` does not apply to {1} and {2}")]
    Binary(&'static str, String, String),
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
fn check_escapes(text: &str) -> Result<(), EvalError> {
    let mut in_str = false;
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        match c {
            '"' => in_str = !in_str,
            '\\' if in_str => match chars.next() {
                Some('n' | 'r' | 't' | 'a' | '\\' | '"' | '$' | '%') => {}
                Some(o) => return Err(EvalError::Escape(o)),
                None => return Err(EvalError::Unterminated),
            },
            _ => {}
        }
    }
    Ok(())
}

/// Evaluate a constant trace expression, or say why it is not a trace value.
fn eval(e: &Expr) -> Result<Value, EvalError> {
    match &e.kind {
        ExprKind::Int { value, unit: None } => Ok(Value::from_big((*value).into())),
        ExprKind::Int { unit: Some(u), .. } => Err(EvalError::TimeUnit(u.name.to_string())),
        ExprKind::Float(f) => Ok(Value::Float(*f)),
        ExprKind::Str { parts, format } => {
            if *format {
                return Err(EvalError::FormatString);
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
                    return Err(EvalError::TwiceGiven(name.name.to_string()));
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
            other => Err(EvalError::NotAValue(other.to_string())),
        },
        ExprKind::Call {
            function,
            type_args,
            args: Some(args),
        } if type_args.is_empty() => {
            let ExprKind::Var(f) = &function.kind else {
                return Err(EvalError::Callee);
            };
            if let Some(a) = args.iter().find_map(|a| a.name.as_ref()) {
                return Err(EvalError::NamedArgument(a.name.to_string()));
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
                ("Set", _) => Ok(tessla_engine::collections::set_of(vals)),
                ("Map", n) if n % 2 == 0 => {
                    let mut map: Vec<(Value, Value)> = Vec::with_capacity(n / 2);
                    let mut it = vals.into_iter();
                    while let (Some(k), Some(v)) = (it.next(), it.next()) {
                        map.push((k, v));
                    }
                    // A repeated key keeps the last value, as Scala's `toMap` does.
                    Ok(tessla_engine::collections::map_of(map))
                }
                (other, n) => Err(EvalError::Call(other.to_string(), n)),
            }
        }
        ExprKind::Unary { op, operand } => unary(*op, eval(operand)?),
        ExprKind::Binary { op, lhs, rhs } => match op {
            BinOp::And => match eval(lhs)? {
                Value::Bool(false) => Ok(Value::Bool(false)),
                Value::Bool(true) => bool_of(eval(rhs)?),
                v => Err(EvalError::Logic("&&", show(&v))),
            },
            BinOp::Or => match eval(lhs)? {
                Value::Bool(true) => Ok(Value::Bool(true)),
                Value::Bool(false) => bool_of(eval(rhs)?),
                v => Err(EvalError::Logic("||", show(&v))),
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
            v => Err(EvalError::Condition(show(&v))),
        },
        _ => Err(EvalError::NotConstant),
    }
}

fn bool_of(v: Value) -> Result<Value, EvalError> {
    match v {
        Value::Bool(_) => Ok(v),
        v => Err(EvalError::NotBool(show(&v))),
    }
}

/// An operator's semantics are the engine's ([`tessla_engine::ops`]); only the messages
/// are the trace reader's.
fn op_error(e: OpError, undefined: impl FnOnce() -> EvalError) -> EvalError {
    match e {
        OpError::Overflow => EvalError::Overflow,
        OpError::DivisionByZero => EvalError::DivisionByZero,
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

fn unary(op: UnaryOp, v: Value) -> Result<Value, EvalError> {
    match (op, v) {
        // A negative float literal: `-1.5` (TeSSLa's trace lexer reads it as one literal).
        (UnaryOp::Neg, Value::Float(f)) => Ok(Value::Float(-f)),
        (op, v) => ops::unary(op.into(), &v)
            .map_err(|e| op_error(e, || EvalError::Unary(unary_symbol(op), show(&v)))),
    }
}

fn binary(op: BinOp, a: Value, b: Value) -> Result<Value, EvalError> {
    ops::binary(op.into(), &a, &b)
        .map_err(|e| op_error(e, || EvalError::Binary(op.symbol(), show(&a), show(&b))))
}

/// A value as TeSSLa shows it in input errors (strings quoted).
pub(super) fn show(v: &Value) -> String {
    match v {
        Value::Str(s) => format!("{s:?}"),
        other => other.to_string(),
    }
}
