//! The semantics of TeSSLa's operators, once: arithmetic, comparison, bitwise and boolean
//! operators on values.
//!
//! Owns: [`binary`] and [`unary`] (the result of an operator on two or one non-error values, or
//! why there is none), their forms on values ([`binary_value`], [`unary_value`]: an error
//! operand is the result, no result is an error value), `Operators.add` and friends as natives
//! ([`natives`]), the inline scalar fast path [`ScalarOp::eval`] and its form on values
//! [`ScalarOp::eval_values`] (which must agree with
//! [`binary`]; a test checks it) and [`shift_left`]. The lowering (operators in specs,
//! `Operators.add` and friends, the stream builtins that add) and the trace reader (operators in
//! trace values) both call these, so an operator cannot mean one thing in a spec and another in a
//! trace.
//!
//! Semantics follow TeSSLa's reference interpreter on its unbounded integers, restricted to
//! 64 bits: a result outside `i64` is an overflow; `x << s` with a negative `s` shifts right (and
//! `x >> s` with a negative `s` shifts left), as `BigInt.<<` does; division and remainder by zero
//! are their own error. `&&` and `||` here are strict; the trace reader short-circuits them
//! itself.

use crate::ir::{BinOp, UnaryOp};
use crate::ir::{Scalar, ScalarOp};
use crate::value::{RuntimeError, Value};

/// Why an operator has no value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OpError {
    /// The result does not fit in 64 bits.
    Overflow,
    /// `x / 0` or `x % 0`.
    DivisionByZero,
    /// The operator is not defined for the operands' types.
    Undefined,
}

impl std::fmt::Display for OpError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            OpError::Overflow => "Integer overflow",
            OpError::DivisionByZero => "Division by zero",
            OpError::Undefined => "operator not defined for these operands",
        })
    }
}

impl std::error::Error for OpError {}

/// `a op b` for two values that are not errors (callers propagate error values first).
pub fn binary(op: BinOp, a: &Value, b: &Value) -> Result<Value, OpError> {
    use Value::*;
    let ovf = OpError::Overflow;
    Ok(match (op, a, b) {
        // 64 bits first; a result outside them is computed again unbounded (`big`).
        (BinOp::Add, Int(x), Int(y)) => x.checked_add(*y).map_or_else(|| big(op, a, b), Int),
        (BinOp::Sub, Int(x), Int(y)) => x.checked_sub(*y).map_or_else(|| big(op, a, b), Int),
        (BinOp::Mul, Int(x), Int(y)) => x.checked_mul(*y).map_or_else(|| big(op, a, b), Int),
        (BinOp::Div | BinOp::Mod, Int(_), Int(0)) => return Err(OpError::DivisionByZero),
        (BinOp::Div, Int(x), Int(y)) => x.checked_div(*y).map_or_else(|| big(op, a, b), Int),
        (BinOp::Mod, Int(x), Int(y)) => x.checked_rem(*y).map_or_else(|| big(op, a, b), Int),
        (_, Int(_) | BigInt(_), Int(_) | BigInt(_))
            if integer_op(op) && (matches!(a, BigInt(_)) || matches!(b, BigInt(_))) =>
        {
            if matches!(op, BinOp::Div | BinOp::Mod) && matches!(b, Int(0)) {
                return Err(OpError::DivisionByZero);
            }
            big(op, a, b)
        }
        (BinOp::Add, Str(x), Str(y)) => Str(format!("{x}{y}").into()),
        (BinOp::FAdd, Float(x), Float(y)) => Float(x + y),
        (BinOp::FSub, Float(x), Float(y)) => Float(x - y),
        (BinOp::FMul, Float(x), Float(y)) => Float(x * y),
        (BinOp::FDiv, Float(x), Float(y)) => Float(x / y),
        (BinOp::Lt, Int(x), Int(y)) => Bool(x < y),
        (BinOp::Gt, Int(x), Int(y)) => Bool(x > y),
        (BinOp::Le, Int(x), Int(y)) => Bool(x <= y),
        (BinOp::Ge, Int(x), Int(y)) => Bool(x >= y),
        (BinOp::FLt, Float(x), Float(y)) => Bool(x < y),
        (BinOp::FGt, Float(x), Float(y)) => Bool(x > y),
        (BinOp::FLe, Float(x), Float(y)) => Bool(x <= y),
        (BinOp::FGe, Float(x), Float(y)) => Bool(x >= y),
        (BinOp::Eq, x, y) => Bool(x == y),
        (BinOp::Ne, x, y) => Bool(x != y),
        (BinOp::And, Bool(x), Bool(y)) => Bool(*x && *y),
        (BinOp::Or, Bool(x), Bool(y)) => Bool(*x || *y),
        (BinOp::BitAnd, Int(x), Int(y)) => Int(x & y),
        (BinOp::BitOr, Int(x), Int(y)) => Int(x | y),
        (BinOp::BitXor, Int(x), Int(y)) => Int(x ^ y),
        (BinOp::Shl, Int(x), Int(y)) => shift_big(*x, *y).ok_or(ovf)?,
        (BinOp::Shr, Int(x), Int(y)) => match y.checked_neg() {
            Option::Some(n) => shift_big(*x, n).ok_or(ovf)?,
            // A shift right by more than 63 places: only the sign is left.
            Option::None => Int(if *x < 0 { -1 } else { 0 }),
        },
        _ => return Err(OpError::Undefined),
    })
}

/// `op a` for a value that is not an error.
pub fn unary(op: UnaryOp, a: &Value) -> Result<Value, OpError> {
    Ok(match (op, a) {
        (UnaryOp::Not, Value::Bool(b)) => Value::Bool(!b),
        (UnaryOp::BitNot, Value::Int(i)) => Value::Int(!i),
        (UnaryOp::Neg, Value::Int(i)) => match i.checked_neg() {
            Some(n) => Value::Int(n),
            None => Value::from_big(-num_bigint::BigInt::from(*i)),
        },
        (UnaryOp::Neg, Value::BigInt(i)) => Value::from_big(-(**i).clone()),
        (UnaryOp::FNeg, Value::Float(f)) => Value::Float(-f),
        _ => return Err(OpError::Undefined),
    })
}

/// The operators defined on integers of any size: arithmetic and comparisons.
pub fn integer_op(op: BinOp) -> bool {
    matches!(
        op,
        BinOp::Add
            | BinOp::Sub
            | BinOp::Mul
            | BinOp::Div
            | BinOp::Mod
            | BinOp::Lt
            | BinOp::Gt
            | BinOp::Le
            | BinOp::Ge
    )
}

/// `a op b` on integers of any size (TeSSLa's `Int` is unbounded): arithmetic and comparisons.
/// The divisor is not zero (checked by the caller); division truncates towards zero and the
/// remainder takes the dividend's sign, as for 64 bits.
fn big(op: BinOp, a: &Value, b: &Value) -> Value {
    let (Some(x), Some(y)) = (a.as_big(), b.as_big()) else {
        return Value::Error(RuntimeError::Other("not an integer".into()));
    };
    match op {
        BinOp::Add => Value::from_big(x + y),
        BinOp::Sub => Value::from_big(x - y),
        BinOp::Mul => Value::from_big(x * y),
        BinOp::Div => Value::from_big(x / y),
        BinOp::Mod => Value::from_big(x % y),
        BinOp::Lt => Value::Bool(x < y),
        BinOp::Gt => Value::Bool(x > y),
        BinOp::Le => Value::Bool(x <= y),
        BinOp::Ge => Value::Bool(x >= y),
        _ => Value::Error(RuntimeError::Other(
            format!(
                "`{}` is not defined for integers beyond 64 bits",
                op.symbol()
            )
            .into(),
        )),
    }
}

/// `a op b` as a value: an error operand is the result, a missing result is an error value.
/// `&&` and `||` are lazy in their right operand, as in TeSSLa: `false && e` is `false` and
/// `true || e` is `true` even when `e` is an error (`Map.contains(m, k) && Map.get(m, k) > 0`).
pub fn binary_value(op: BinOp, a: &Value, b: &Value) -> Value {
    match (op, a) {
        (BinOp::And, Value::Bool(false)) | (BinOp::Or, Value::Bool(true)) => return a.clone(),
        (_, Value::Error(_)) => return a.clone(),
        _ => {}
    }
    if let Value::Error(_) = b {
        return b.clone();
    }
    binary(op, a, b).unwrap_or_else(|e| {
        Value::Error(match e {
            OpError::Overflow => RuntimeError::Overflow,
            OpError::DivisionByZero => RuntimeError::DivisionByZero,
            OpError::Undefined => RuntimeError::Other(
                format!("`{}` is not defined for {a:?} and {b:?}", op.symbol()).into(),
            ),
        })
    })
}

/// `op a` as a value: an error operand is the result, a missing result is an error value.
pub fn unary_value(op: UnaryOp, a: &Value) -> Value {
    if let Value::Error(_) = a {
        return a.clone();
    }
    unary(op, a).unwrap_or_else(|e| {
        Value::Error(match e {
            OpError::Overflow => RuntimeError::Overflow,
            OpError::DivisionByZero => RuntimeError::DivisionByZero,
            OpError::Undefined => {
                RuntimeError::Other(format!("{op:?} is not defined for {a:?}").into())
            }
        })
    })
}

/// `==` and `!=` on two values that are not errors: two scalars of the same kind (Float, Int,
/// Bool) computed inline, others (tuples, strings ...) by `Value`'s equality, as [`binary`]
/// does, without [`binary_value`]'s way there; `None` for anything else (an error operand,
/// another operator: the general path decides).
#[inline(always)]
pub fn eq_values(op: BinOp, a: &Value, b: &Value) -> Option<Value> {
    let ne = match op {
        BinOp::Eq => false,
        BinOp::Ne => true,
        _ => return None,
    };
    let eq = match (a, b) {
        (Value::Float(x), Value::Float(y)) => x == y,
        (Value::Int(x), Value::Int(y)) => x == y,
        (Value::Bool(x), Value::Bool(y)) => x == y,
        (Value::Error(_), _) | (_, Value::Error(_)) => return None,
        _ => a == b,
    };
    Some(Value::Bool(eq != ne))
}

/// `!b` and `-.f` computed inline; `None` for anything else (the general path,
/// [`unary_value`], decides).
#[inline(always)]
pub fn unary_fast(op: UnaryOp, a: &Value) -> Option<Value> {
    match (op, a) {
        (UnaryOp::Not, Value::Bool(b)) => Some(Value::Bool(!b)),
        (UnaryOp::FNeg, Value::Float(f)) => Some(Value::Float(-f)),
        _ => None,
    }
}

/// TeSSLa's `Operators.<name>` functions as natives (`slift(x, y, Operators.add)`); missing
/// operands are Unit, which no operator accepts.
pub mod natives {
    use super::{binary_value, unary_value};
    use crate::ir::{BinOp, UnaryOp};
    use crate::value::Value;

    fn operand(a: &[Value], i: usize) -> Value {
        a.get(i).cloned().unwrap_or(Value::Unit)
    }

    macro_rules! bin {
        ($($name:ident => $op:expr),+ $(,)?) => {
            $(pub fn $name(a: &[Value]) -> Value {
                binary_value($op, &operand(a, 0), &operand(a, 1))
            })+
        };
    }
    macro_rules! un {
        ($($name:ident => $op:expr),+ $(,)?) => {
            $(pub fn $name(a: &[Value]) -> Value {
                unary_value($op, &operand(a, 0))
            })+
        };
    }
    bin! {
        add => BinOp::Add, sub => BinOp::Sub, mul => BinOp::Mul, div => BinOp::Div,
        rem => BinOp::Mod, lt => BinOp::Lt, gt => BinOp::Gt, le => BinOp::Le, ge => BinOp::Ge,
        eq => BinOp::Eq, ne => BinOp::Ne, fadd => BinOp::FAdd, fsub => BinOp::FSub,
        fmul => BinOp::FMul, fdiv => BinOp::FDiv, flt => BinOp::FLt, fgt => BinOp::FGt,
        fle => BinOp::FLe, fge => BinOp::FGe, and => BinOp::And, or => BinOp::Or,
        bitand => BinOp::BitAnd, bitor => BinOp::BitOr, bitxor => BinOp::BitXor,
        shl => BinOp::Shl, shr => BinOp::Shr,
    }
    un! {
        not => UnaryOp::Not, neg => UnaryOp::Neg, fneg => UnaryOp::FNeg, bitflip => UnaryOp::BitNot,
    }
}

/// `x << s` on unbounded integers: a negative `s` shifts right (arithmetically); a result
/// outside `i64` is `None` (an overflow).
pub fn shift_left(x: i64, s: i64) -> Option<i64> {
    if s < 0 {
        let r = u32::try_from(s.unsigned_abs()).unwrap_or(u32::MAX).min(63);
        return Some(x >> r);
    }
    if x == 0 {
        return Some(0);
    }
    let r = u32::try_from(s).ok().filter(|r| *r < 64)?;
    let shifted = x.checked_shl(r)?;
    (shifted >> r == x).then_some(shifted)
}

/// `x << s` with an unbounded result (TeSSLa's `Int`); `None` only for a shift so far left
/// that the number would not fit in memory we are willing to spend (more than 65,536 bits).
fn shift_big(x: i64, s: i64) -> Option<Value> {
    match shift_left(x, s) {
        Some(v) => Some(Value::Int(v)),
        None => {
            let s = usize::try_from(s).ok().filter(|s| *s <= 65_536)?;
            Some(Value::from_big(num_bigint::BigInt::from(x) << s))
        }
    }
}

impl ScalarOp {
    /// The result on scalar operands of the operator's types, or `None` otherwise (the general
    /// path, [`binary`], then decides: overflow is an error value, other types are errors).
    #[inline]
    pub fn eval(self, a: Scalar, b: Scalar) -> Option<Scalar> {
        use Scalar::{B, F, I};
        use ScalarOp::*;
        Some(match (self, a, b) {
            (FAdd, F(x), F(y)) => F(x + y),
            (FSub, F(x), F(y)) => F(x - y),
            (FMul, F(x), F(y)) => F(x * y),
            (FDiv, F(x), F(y)) => F(x / y),
            (FLt, F(x), F(y)) => B(x < y),
            (FGt, F(x), F(y)) => B(x > y),
            (FLe, F(x), F(y)) => B(x <= y),
            (FGe, F(x), F(y)) => B(x >= y),
            (IAdd, I(x), I(y)) => I(x.checked_add(y)?),
            (ISub, I(x), I(y)) => I(x.checked_sub(y)?),
            (ILt, I(x), I(y)) => B(x < y),
            (IGt, I(x), I(y)) => B(x > y),
            (ILe, I(x), I(y)) => B(x <= y),
            (IGe, I(x), I(y)) => B(x >= y),
            (And, B(x), B(y)) => B(x && y),
            (Or, B(x), B(y)) => B(x || y),
            _ => return None,
        })
    }

    /// [`ScalarOp::eval`] on values: the same result, without copying the operands out and the
    /// result back (what the evaluator's operator nodes run).
    #[inline(always)]
    pub fn eval_values(self, a: &Value, b: &Value) -> Option<Value> {
        use ScalarOp::*;
        Some(match (a, b) {
            (Value::Float(x), Value::Float(y)) => match self {
                FAdd => Value::Float(x + y),
                FSub => Value::Float(x - y),
                FMul => Value::Float(x * y),
                FDiv => Value::Float(x / y),
                FLt => Value::Bool(x < y),
                FGt => Value::Bool(x > y),
                FLe => Value::Bool(x <= y),
                FGe => Value::Bool(x >= y),
                _ => return None,
            },
            (Value::Int(x), Value::Int(y)) => match self {
                IAdd => Value::Int(x.checked_add(*y)?),
                ISub => Value::Int(x.checked_sub(*y)?),
                ILt => Value::Bool(x < y),
                IGt => Value::Bool(x > y),
                ILe => Value::Bool(x <= y),
                IGe => Value::Bool(x >= y),
                _ => return None,
            },
            (Value::Bool(x), Value::Bool(y)) => match self {
                And => Value::Bool(*x && *y),
                Or => Value::Bool(*x || *y),
                _ => return None,
            },
            _ => return None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ir::scalar_op;

    #[test]
    fn integers_are_unbounded_and_come_back_to_64_bits() {
        let max = Value::Int(i64::MAX);
        let two_max = binary(BinOp::Add, &max, &max).unwrap();
        assert_eq!(two_max.to_string(), "18446744073709551614");
        assert!(matches!(two_max, Value::BigInt(_)));
        // Back inside 64 bits: the plain form again, equal to any other 64-bit value.
        let back = binary(BinOp::Sub, &two_max, &max).unwrap();
        assert_eq!(back, max);
        assert!(matches!(back, Value::Int(_)));
        assert_eq!(
            binary(BinOp::Lt, &two_max, &Value::Int(5)).unwrap(),
            Value::Bool(false)
        );
        assert_eq!(
            binary(BinOp::Mul, &max, &Value::Int(-2))
                .unwrap()
                .to_string(),
            "-18446744073709551614"
        );
        assert_eq!(
            binary(BinOp::Div, &two_max, &Value::Int(0)),
            Err(OpError::DivisionByZero)
        );
        assert_eq!(
            unary(UnaryOp::Neg, &Value::Int(i64::MIN))
                .unwrap()
                .to_string(),
            "9223372036854775808"
        );
    }

    #[test]
    fn and_or_ignore_an_error_they_do_not_need() {
        let e = Value::Error(RuntimeError::IndexOutOfBounds);
        let f = Value::Bool(false);
        let t = Value::Bool(true);
        assert_eq!(binary_value(BinOp::And, &f, &e), f);
        assert_eq!(binary_value(BinOp::Or, &t, &e), t);
        assert_eq!(binary_value(BinOp::And, &t, &e), e);
        assert_eq!(binary_value(BinOp::Or, &e, &t), e);
    }

    const ALL: [BinOp; 26] = [
        BinOp::Mul,
        BinOp::Div,
        BinOp::Mod,
        BinOp::FMul,
        BinOp::FDiv,
        BinOp::Add,
        BinOp::Sub,
        BinOp::FAdd,
        BinOp::FSub,
        BinOp::Shl,
        BinOp::Shr,
        BinOp::BitAnd,
        BinOp::BitOr,
        BinOp::BitXor,
        BinOp::Eq,
        BinOp::Ne,
        BinOp::Lt,
        BinOp::Gt,
        BinOp::Le,
        BinOp::Ge,
        BinOp::FLt,
        BinOp::FGt,
        BinOp::FLe,
        BinOp::FGe,
        BinOp::And,
        BinOp::Or,
    ];

    fn samples() -> Vec<Value> {
        let mut v: Vec<Value> = [0, 1, -1, 2, 63, 64, -64, i64::MAX, i64::MIN]
            .into_iter()
            .map(Value::Int)
            .collect();
        v.extend(
            [0.0, -0.0, 1.5, -2.25, f64::NAN, f64::INFINITY]
                .into_iter()
                .map(Value::Float),
        );
        v.extend([Value::Bool(true), Value::Bool(false)]);
        v
    }

    /// [`samples`] and values that are no scalars, errors among them.
    fn all_samples() -> Vec<Value> {
        let mut v = samples();
        let t = |a: i64, b: i64| Value::Tuple(vec![Value::Int(a), Value::Int(b)].into());
        v.extend([
            t(1, 2),
            t(1, 3),
            t(1, 2),
            Value::Tuple(vec![Value::Float(f64::NAN), Value::Int(1)].into()),
            Value::Str("a".into()),
            Value::Str("b".into()),
            Value::Unit,
            Value::None,
            Value::Some(std::sync::Arc::new(Value::Int(1))),
            Value::from_big(num_bigint::BigInt::from(i64::MAX) * 4),
            Value::Error(RuntimeError::DivisionByZero),
            Value::Error(RuntimeError::Overflow),
        ]);
        v
    }

    #[test]
    fn the_scalar_fast_path_agrees_with_the_general_path() {
        for op in ALL {
            let Some(sop) = scalar_op(op) else { continue };
            for a in samples() {
                for b in samples() {
                    // On values: what `eval` gives, and nothing for other operand types.
                    let on_values = sop.eval_values(&a, &b);
                    let (Some(x), Some(y)) = (Scalar::of(&a), Scalar::of(&b)) else {
                        assert!(on_values.is_none(), "{op:?} on {a:?}, {b:?}");
                        continue;
                    };
                    assert_eq!(
                        format!("{on_values:?}"),
                        format!("{:?}", sop.eval(x, y).map(Scalar::value)),
                        "{op:?} on {a:?}, {b:?}"
                    );
                    if let Some(fast) = sop.eval(x, y) {
                        let slow = binary(op, &a, &b);
                        assert_eq!(
                            format!("{:?}", Ok::<_, OpError>(fast.value())),
                            format!("{slow:?}"),
                            "{op:?} on {a:?}, {b:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn the_inline_equality_and_negation_agree_with_the_general_path() {
        for op in ALL {
            for a in all_samples() {
                for b in all_samples() {
                    if let Some(fast) = eq_values(op, &a, &b) {
                        assert!(matches!(op, BinOp::Eq | BinOp::Ne));
                        assert_eq!(
                            format!("{fast:?}"),
                            format!("{:?}", binary_value(op, &a, &b)),
                            "{op:?} on {a:?}, {b:?}"
                        );
                    }
                }
            }
        }
        for op in [UnaryOp::Not, UnaryOp::BitNot, UnaryOp::Neg, UnaryOp::FNeg] {
            for a in samples() {
                if let Some(fast) = unary_fast(op, &a) {
                    assert_eq!(
                        format!("{fast:?}"),
                        format!("{:?}", unary_value(op, &a)),
                        "{op:?} on {a:?}"
                    );
                }
            }
        }
        assert!(eq_values(BinOp::Ne, &Value::Float(0.5), &Value::Float(0.25)).is_some());
        assert!(unary_fast(UnaryOp::Not, &Value::Bool(true)).is_some());
    }

    #[test]
    fn shifts_follow_unbounded_integers() {
        let i = |x| Value::Int(x);
        assert_eq!(binary(BinOp::Shl, &i(1), &i(3)), Ok(i(8)));
        assert_eq!(binary(BinOp::Shl, &i(8), &i(-3)), Ok(i(1)));
        assert_eq!(binary(BinOp::Shl, &i(-8), &i(-100)), Ok(i(-1)));
        assert_eq!(binary(BinOp::Shr, &i(1), &i(-3)), Ok(i(8)));
        assert_eq!(binary(BinOp::Shr, &i(-8), &i(1)), Ok(i(-4)));
        assert_eq!(binary(BinOp::Shr, &i(5), &i(i64::MIN)), Ok(i(0)));
        assert_eq!(
            binary(BinOp::Shl, &i(1), &i(63)).map(|v| v.to_string()),
            Ok("9223372036854775808".to_string()),
            "2^63 is beyond 64 bits, and TeSSLa's Int is unbounded"
        );
        assert_eq!(
            binary(BinOp::Shl, &i(1), &i(1 << 40)),
            Err(OpError::Overflow),
            "too large to hold"
        );
        assert_eq!(binary(BinOp::Shl, &i(0), &i(1000)), Ok(i(0)));
    }

    #[test]
    fn division_by_zero_and_undefined_operands() {
        let i = |x| Value::Int(x);
        assert_eq!(
            binary(BinOp::Mod, &i(1), &i(0)),
            Err(OpError::DivisionByZero)
        );
        assert_eq!(
            binary(BinOp::Div, &i(i64::MIN), &i(-1)).map(|v| v.to_string()),
            Ok("9223372036854775808".to_string())
        );
        assert_eq!(
            binary(BinOp::Add, &i(1), &Value::Float(1.0)),
            Err(OpError::Undefined)
        );
        assert_eq!(
            unary(UnaryOp::Neg, &Value::Float(1.0)),
            Err(OpError::Undefined)
        );
    }
}
