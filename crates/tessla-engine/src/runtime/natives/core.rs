//! Value-level functions on scalars, strings, options and lists (the `extern` names the checker
//! also reaches by their TeSSLa names: `pow`, `List.size`, `getSome` ...).
//!
//! Owns: their semantics, with TeSSLa's error rules: integer overflow, division by zero,
//! `getSome(None)`, an index out of bounds and `floatToInt` of NaN are runtime errors (values).

use crate::value::{RuntimeError, Value};
use std::sync::Arc;

fn err(e: RuntimeError) -> Value {
    Value::Error(e)
}

fn type_err(name: &str, args: &[Value]) -> Value {
    err(RuntimeError::Other(
        format!("{name}: unexpected arguments {args:?}").into(),
    ))
}

pub fn int_to_float(a: &[Value]) -> Value {
    match a {
        [Value::Int(i)] => Value::Float(*i as f64),
        [Value::BigInt(i)] => {
            Value::Float(num_traits::ToPrimitive::to_f64(&**i).unwrap_or(f64::NAN))
        }
        _ => type_err("intToFloat", a),
    }
}

pub fn float_to_int(a: &[Value]) -> Value {
    match a {
        [Value::Float(f)] if f.is_finite() && f.abs() < 9.2e18 => Value::Int(f.trunc() as i64),
        // TeSSLa's `Int` is unbounded, and a large float converts through its shortest
        // decimal form, as Java's `BigDecimal.valueOf` does: `4.2E24` is
        // 4200000000000000000000000 (not the double's binary value, ...251658240).
        [Value::Float(f)] if f.is_finite() => {
            decimal_trunc(*f).map_or(err(RuntimeError::Overflow), Value::from_big)
        }
        [Value::Float(_)] => err(RuntimeError::Overflow),
        _ => type_err("floatToInt", a),
    }
}

/// The integer part of `f`'s shortest round-trip decimal form.
fn decimal_trunc(f: f64) -> Option<num_bigint::BigInt> {
    let text = format!("{f:e}");
    let (mantissa, exp) = text.split_once('e')?;
    let exp: i64 = exp.parse().ok()?;
    let negative = mantissa.starts_with('-');
    let mantissa = mantissa.trim_start_matches('-');
    let (int, frac) = mantissa.split_once('.').unwrap_or((mantissa, ""));
    let digits = format!("{int}{frac}");
    // The value is 0.digits × 10^(len(int) + exp): keep the digits before the point.
    let point = i64::try_from(int.len()).ok()? + exp;
    let kept: String = if point <= 0 {
        "0".into()
    } else {
        let point = usize::try_from(point).ok()?;
        if point >= digits.len() {
            format!("{digits}{}", "0".repeat(point - digits.len()))
        } else {
            digits[..point].to_string()
        }
    };
    let b: num_bigint::BigInt = kept.parse().ok()?;
    Some(if negative { -b } else { b })
}

fn float1(name: &str, a: &[Value], f: fn(f64) -> f64) -> Value {
    match a {
        [Value::Float(x)] => Value::Float(f(*x)),
        _ => type_err(name, a),
    }
}

pub fn sin(a: &[Value]) -> Value {
    float1("sin", a, f64::sin)
}
pub fn cos(a: &[Value]) -> Value {
    float1("cos", a, f64::cos)
}
pub fn tan(a: &[Value]) -> Value {
    float1("tan", a, f64::tan)
}
pub fn atan(a: &[Value]) -> Value {
    float1("atan", a, f64::atan)
}
pub fn sqrt(a: &[Value]) -> Value {
    float1("sqrt", a, f64::sqrt)
}

pub fn pow(a: &[Value]) -> Value {
    match a {
        [Value::Float(x), Value::Float(y)] => Value::Float(x.powf(*y)),
        _ => type_err("pow", a),
    }
}

pub fn log(a: &[Value]) -> Value {
    match a {
        [Value::Float(x), Value::Float(b)] => Value::Float(x.ln() / b.ln()),
        [Value::Float(x)] => Value::Float(x.ln()),
        _ => type_err("log", a),
    }
}

pub fn abs(a: &[Value]) -> Value {
    match a {
        [Value::Int(i)] => i.checked_abs().map_or_else(
            || Value::from_big(num_bigint::BigInt::from(*i).magnitude().clone().into()),
            Value::Int,
        ),
        [Value::BigInt(i)] => Value::from_big(i.magnitude().clone().into()),
        [Value::Float(f)] => Value::Float(f.abs()),
        _ => type_err("abs", a),
    }
}

pub fn max(a: &[Value]) -> Value {
    match a {
        [Value::Int(x), Value::Int(y)] => Value::Int(*x.max(y)),
        [
            x @ (Value::Int(_) | Value::BigInt(_)),
            y @ (Value::Int(_) | Value::BigInt(_)),
        ] => {
            if x.as_big() >= y.as_big() {
                x.clone()
            } else {
                y.clone()
            }
        }
        [Value::Float(x), Value::Float(y)] => Value::Float(x.max(*y)),
        _ => type_err("max", a),
    }
}

pub fn min(a: &[Value]) -> Value {
    match a {
        [Value::Int(x), Value::Int(y)] => Value::Int(*x.min(y)),
        [
            x @ (Value::Int(_) | Value::BigInt(_)),
            y @ (Value::Int(_) | Value::BigInt(_)),
        ] => {
            if x.as_big() <= y.as_big() {
                x.clone()
            } else {
                y.clone()
            }
        }
        [Value::Float(x), Value::Float(y)] => Value::Float(x.min(*y)),
        _ => type_err("min", a),
    }
}

pub fn to_string(a: &[Value]) -> Value {
    match a {
        [v] => Value::Str(v.to_string().into()),
        _ => type_err("toString", a),
    }
}

pub fn concat(a: &[Value]) -> Value {
    match a {
        [Value::Str(x), Value::Str(y)] => Value::Str(format!("{x}{y}").into()),
        _ => type_err("String.concat", a),
    }
}

/// `String.format(formatString, value)`: Java's `String.format` of one value (`runtime::format`);
/// a format Java rejects (a missing argument, `%d` of a Float, ...) is a run-time error.
pub fn string_format(a: &[Value]) -> Value {
    match a {
        [Value::Str(f), v] => match crate::runtime::format::java_format(f, v) {
            Ok(s) => Value::Str(s.into()),
            Err(e) => err(RuntimeError::Other(
                format!("String.format(\"{f}\", {v}): {e}").into(),
            )),
        },
        _ => type_err("String.format", a),
    }
}

/// The marker field of a `CTF` value: the record `trace --ctf` builds for a CTF event, with the
/// event's name here and one field per key prefix of TeSSLa (`context`, `eventcontext`,
/// `eventheader`, `packetcontext`, `fields`), each a record of the decoded struct (`Unit` when
/// the trace has none). Not an identifier, so no TeSSLa record has it.
pub const CTF_MARKER: &str = "$ctf";

/// `CTF.getInt(event, key)`: the integer member at `key` (TeSSLa's key rules: see `ctf_get`).
pub fn ctf_get_int(a: &[Value]) -> Value {
    ctf_get(a, "Int", |v| matches!(v, Value::Int(_) | Value::BigInt(_)))
}

/// `CTF.getString(event, key)`: the string member at `key`.
pub fn ctf_get_string(a: &[Value]) -> Value {
    ctf_get(a, "String", |v| matches!(v, Value::Str(_)))
}

/// A member of a CTF event as TeSSLa finds it: `prefix:path` picks a section (`context`,
/// `eventcontext`, `eventheader`, `packetcontext`, `fields`), no prefix means `fields`; the path
/// is a member name, else a dotted path through nested structs. TeSSLa's errors: `Unknown prefix`,
/// `Key "k" not found`, `Value for key "k" is not of type T` (enums, floats, arrays and variants
/// are members of other types).
fn ctf_get(a: &[Value], ty: &str, is: fn(&Value) -> bool) -> Value {
    let (Some(Value::Record(event)), Some(Value::Str(key))) = (a.first(), a.get(1)) else {
        let what = a.first().map_or_else(String::new, |v| format!("`{v}` "));
        return err(RuntimeError::Other(
            format!("CTF.get{ty}: {what}is not a CTF event object (those come from `trace --ctf`)")
                .into(),
        ));
    };
    let (prefix, path) = key.split_once(':').unwrap_or(("fields", key));
    const PREFIXES: [&str; 5] = [
        "context",
        "eventcontext",
        "eventheader",
        "packetcontext",
        "fields",
    ];
    if !PREFIXES.contains(&prefix) {
        return err(RuntimeError::Other(
            format!(
                "Unknown prefix \"{prefix}\". Available prefixes are context, eventcontext, eventheader, packetcontext and fields"
            )
            .into(),
        ));
    }
    fn member<'v>(v: &'v Value, name: &str) -> Option<&'v Value> {
        match v {
            Value::Record(fs) => fs.iter().find(|(n, _)| &**n == name).map(|(_, v)| v),
            _ => None,
        }
    }
    fn find<'v>(v: &'v Value, key: &str) -> Option<&'v Value> {
        if let Some(m) = member(v, key) {
            return Some(m);
        }
        let (head, tail) = key.split_once('.')?;
        match member(v, head)? {
            inner @ Value::Record(_) => find(inner, tail),
            _ => None,
        }
    }
    let section = event.iter().find(|(n, _)| &**n == prefix).map(|(_, v)| v);
    match section.and_then(|s| find(s, path)) {
        Some(v) if is(v) => v.clone(),
        Some(_) => err(RuntimeError::Other(
            format!("Value for key \"{key}\" is not of type {ty}").into(),
        )),
        None => err(RuntimeError::Other(
            format!("Key \"{key}\" not found").into(),
        )),
    }
}

pub fn some(a: &[Value]) -> Value {
    match a {
        [v] => Value::Some(Arc::new(v.clone())),
        _ => type_err("Some", a),
    }
}

pub fn is_none(a: &[Value]) -> Value {
    match a {
        [Value::None] => Value::Bool(true),
        [Value::Some(_)] => Value::Bool(false),
        _ => type_err("isNone", a),
    }
}

pub fn is_some(a: &[Value]) -> Value {
    match a {
        [Value::None] => Value::Bool(false),
        [Value::Some(_)] => Value::Bool(true),
        _ => type_err("isSome", a),
    }
}

pub fn get_some(a: &[Value]) -> Value {
    match a {
        [Value::Some(v)] => (**v).clone(),
        [Value::None] => err(RuntimeError::GetSomeOfNone),
        _ => type_err("getSome", a),
    }
}

pub fn get_some_or_else(a: &[Value]) -> Value {
    match a {
        [Value::Some(v), _] => (**v).clone(),
        [Value::None, d] => d.clone(),
        _ => type_err("getSomeOrElse", a),
    }
}

pub fn list_size(a: &[Value]) -> Value {
    match a {
        [Value::List(l)] => Value::Int(l.len() as i64),
        _ => type_err("List.size", a),
    }
}

pub fn list_append(a: &[Value]) -> Value {
    match a {
        [Value::List(l), v] => {
            let mut l = (**l).clone();
            l.push(v.clone());
            Value::List(Arc::new(l))
        }
        _ => type_err("List.append", a),
    }
}

pub fn list_prepend(a: &[Value]) -> Value {
    match a {
        [v, Value::List(l)] => {
            let mut n = Vec::with_capacity(l.len() + 1);
            n.push(v.clone());
            n.extend(l.iter().cloned());
            Value::List(Arc::new(n))
        }
        _ => type_err("List.prepend", a),
    }
}

pub fn list_get(a: &[Value]) -> Value {
    match a {
        [Value::List(l), Value::Int(i)] => usize::try_from(*i)
            .ok()
            .and_then(|i| l.get(i))
            .cloned()
            .unwrap_or(err(RuntimeError::IndexOutOfBounds)),
        _ => type_err("List.get", a),
    }
}

pub fn list_set(a: &[Value]) -> Value {
    match a {
        [Value::List(l), Value::Int(i), v] => {
            match usize::try_from(*i).ok().filter(|i| *i < l.len()) {
                Some(i) => {
                    let mut n = (**l).clone();
                    n[i] = v.clone();
                    Value::List(Arc::new(n))
                }
                None => err(RuntimeError::IndexOutOfBounds),
            }
        }
        _ => type_err("List.set", a),
    }
}

pub fn list_head(a: &[Value]) -> Value {
    match a {
        [Value::List(l)] => l
            .first()
            .cloned()
            .unwrap_or(err(RuntimeError::IndexOutOfBounds)),
        _ => type_err("List.head", a),
    }
}

pub fn list_last(a: &[Value]) -> Value {
    match a {
        [Value::List(l)] => l
            .last()
            .cloned()
            .unwrap_or(err(RuntimeError::IndexOutOfBounds)),
        _ => type_err("List.last", a),
    }
}

pub fn list_tail(a: &[Value]) -> Value {
    match a {
        [Value::List(l)] => Value::List(Arc::new(l.iter().skip(1).cloned().collect())),
        _ => type_err("List.tail", a),
    }
}

pub fn list_init(a: &[Value]) -> Value {
    match a {
        [Value::List(l)] => Value::List(Arc::new(
            l.iter().take(l.len().saturating_sub(1)).cloned().collect(),
        )),
        _ => type_err("List.init", a),
    }
}

/// `List.fold(list, init, f)`: `f(acc, x)` over the elements, left to right.
pub fn list_fold(a: &[Value]) -> Value {
    match a {
        [Value::List(l), init, Value::Closure(f)] => {
            let mut acc = init.clone();
            for x in l.iter() {
                acc = f.call(&[acc, x.clone()]);
                if matches!(acc, Value::Error(_)) {
                    break;
                }
            }
            acc
        }
        _ => type_err("List.fold", a),
    }
}

/// `List.map(list, f)`.
/// `Option.map(o, f)`: `Some(f(x))` for `Some(x)`, `None` for `None`.
pub fn option_map(a: &[Value]) -> Value {
    match a {
        [Value::None, Value::Closure(_)] => Value::None,
        [Value::Some(x), Value::Closure(f)] => match f.call(std::slice::from_ref(&**x)) {
            e @ Value::Error(_) => e,
            v => Value::Some(Arc::new(v)),
        },
        _ => type_err("Option.map", a),
    }
}

/// `Option.flatMap(o, f)`: `f(x)` for `Some(x)`, `None` for `None`.
pub fn option_flat_map(a: &[Value]) -> Value {
    match a {
        [Value::None, Value::Closure(_)] => Value::None,
        [Value::Some(x), Value::Closure(f)] => f.call(std::slice::from_ref(&**x)),
        _ => type_err("Option.flatMap", a),
    }
}

pub fn list_map(a: &[Value]) -> Value {
    match a {
        [Value::List(l), Value::Closure(f)] => Value::List(Arc::new(
            l.iter().map(|x| f.call(std::slice::from_ref(x))).collect(),
        )),
        _ => type_err("List.map", a),
    }
}

/// `ite(c, a, b)`: `a` if `c` else `b` (any values, also functions).
pub fn ite(a: &[Value]) -> Value {
    match a {
        [Value::Bool(true), x, _] => x.clone(),
        [Value::Bool(false), _, y] => y.clone(),
        [e @ Value::Error(_), ..] => e.clone(),
        _ => Value::Error(RuntimeError::Other("ite: expected (Bool, A, A)".into())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn int(i: i64) -> Value {
        Value::Int(i)
    }
    fn list(items: &[i64]) -> Value {
        Value::List(Arc::new(items.iter().map(|i| Value::Int(*i)).collect()))
    }

    #[derive(Debug)]
    struct Add;
    impl crate::value::Callable for Add {
        fn call(&self, args: &[Value]) -> Value {
            match args {
                [Value::Int(a), Value::Int(b)] => a
                    .checked_add(*b)
                    .map_or(err(RuntimeError::Overflow), Value::Int),
                [Value::Int(a)] => Value::Int(a * 10),
                _ => err(RuntimeError::Other("bad".into())),
            }
        }
    }

    #[test]
    fn float_conversions_truncate_and_reject_nan() {
        assert_eq!(float_to_int(&[Value::Float(-2.7)]), int(-2));
        assert_eq!(
            float_to_int(&[Value::Float(f64::NAN)]),
            err(RuntimeError::Overflow)
        );
        // TeSSLa's Int is unbounded: large floats convert through their decimal form.
        assert_eq!(
            float_to_int(&[Value::Float(1e30)]).to_string(),
            "1000000000000000000000000000000"
        );
        assert_eq!(
            float_to_int(&[Value::Float(4.2e24)]).to_string(),
            "4200000000000000000000000"
        );
        assert_eq!(
            float_to_int(&[Value::Float(-1.5e19)]).to_string(),
            "-15000000000000000000"
        );
        assert_eq!(
            decimal_trunc(12.5).map(|b| b.to_string()),
            Some("12".into())
        );
        assert_eq!(decimal_trunc(-0.5).map(|b| b.to_string()), Some("0".into()));
        assert_eq!(int_to_float(&[int(3)]), Value::Float(3.0));
        assert_eq!(
            int_to_float(&[float_to_int(&[Value::Float(1e63)])]),
            Value::Float(1e63)
        );
    }

    #[test]
    fn math_functions_follow_f64_and_integers_are_unbounded() {
        assert_eq!(
            pow(&[Value::Float(2.0), Value::Float(10.0)]),
            Value::Float(1024.0)
        );
        assert_eq!(
            log(&[Value::Float(8.0), Value::Float(2.0)]),
            Value::Float(3.0)
        );
        assert_eq!(abs(&[int(i64::MIN)]).to_string(), "9223372036854775808");
        assert_eq!(abs(&[int(-4)]), int(4));
        assert_eq!(max(&[int(3), int(7)]), int(7));
        assert_eq!(
            min(&[Value::Float(3.5), Value::Float(-1.0)]),
            Value::Float(-1.0)
        );
        assert!(matches!(
            pow(&[int(1)]),
            Value::Error(RuntimeError::Other(_))
        ));
    }

    #[test]
    fn options_and_strings() {
        let s = some(&[int(5)]);
        assert_eq!(s.to_string(), "Some(5)");
        assert_eq!(get_some(std::slice::from_ref(&s)), int(5));
        assert_eq!(get_some(&[Value::None]), err(RuntimeError::GetSomeOfNone));
        assert_eq!(get_some_or_else(&[Value::None, int(9)]), int(9));
        assert_eq!(is_some(&[s]), Value::Bool(true));
        assert_eq!(is_none(&[Value::None]), Value::Bool(true));
        let ab = concat(&[Value::Str("a".into()), Value::Str("b".into())]);
        assert_eq!(ab, Value::Str("ab".into()));
        assert_eq!(to_string(&[Value::Float(1.0)]), Value::Str("1.0".into()));
    }

    #[test]
    fn lists_build_index_and_fold() {
        let l = list_append(&[list(&[1, 2]), int(3)]);
        assert_eq!(l, list(&[1, 2, 3]));
        assert_eq!(list_prepend(&[int(0), l.clone()]), list(&[0, 1, 2, 3]));
        assert_eq!(list_size(std::slice::from_ref(&l)), int(3));
        assert_eq!(list_get(&[l.clone(), int(1)]), int(2));
        assert_eq!(
            list_get(&[l.clone(), int(3)]),
            err(RuntimeError::IndexOutOfBounds)
        );
        assert_eq!(
            list_get(&[l.clone(), int(-1)]),
            err(RuntimeError::IndexOutOfBounds)
        );
        assert_eq!(list_set(&[l.clone(), int(0), int(9)]), list(&[9, 2, 3]));
        assert_eq!(
            list_set(&[l.clone(), int(5), int(9)]),
            err(RuntimeError::IndexOutOfBounds)
        );
        assert_eq!(list_head(std::slice::from_ref(&l)), int(1));
        assert_eq!(list_last(std::slice::from_ref(&l)), int(3));
        assert_eq!(list_tail(std::slice::from_ref(&l)), list(&[2, 3]));
        assert_eq!(list_init(std::slice::from_ref(&l)), list(&[1, 2]));
        assert_eq!(list_head(&[list(&[])]), err(RuntimeError::IndexOutOfBounds));
        assert_eq!(list_init(&[list(&[])]), list(&[]));
        let add = Value::Closure(Arc::new(Add));
        assert_eq!(list_fold(&[l.clone(), int(100), add.clone()]), int(106));
        assert_eq!(
            list_fold(&[list(&[i64::MAX, 1]), int(0), add.clone()]),
            err(RuntimeError::Overflow)
        );
        assert_eq!(list_map(&[l, add]), list(&[10, 20, 30]));
    }
}
