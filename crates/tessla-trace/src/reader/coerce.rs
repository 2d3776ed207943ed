//! A read value against the input's declared type: whether it fits, and the conversions TeSSLa
//! makes (an integer where a float is declared, a record `{_1 = a}` as a tuple, ...).

use super::eval::show;
use super::*;

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

/// Why a read value is not of its input's type (TeSSLa's wording; values as [`show`] writes
/// them, types in the engine's notation).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub(super) enum CoerceError {
    /// A value of another type.
    #[error("{value} is not of type {ty}.")]
    Mismatch { value: String, ty: Type },
    /// A record without a member its type has.
    #[error("Expected {ty} but {member} is missing.")]
    Missing { ty: Type, member: String },
    /// A record with a member its type lacks.
    #[error("Expected {ty} but found the extra member {member}.")]
    Extra { ty: Type, member: String },
    /// Something other than a record where a record is declared.
    #[error("Expected {ty} but found {value}.")]
    NotRecord { ty: Type, value: String },
}

/// `v` as a value of type `t`, or why it is not one (TeSSLa's wording; types in the engine's
/// notation, `tessla_engine::Type`'s `Display`).
pub(super) fn coerce(v: Value, t: &Type) -> Result<Value, CoerceError> {
    if fits(&v, t) {
        return Ok(v);
    }
    let mismatch = |v: &Value| CoerceError::Mismatch {
        value: show(v),
        ty: t.clone(),
    };
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
                    .ok_or_else(|| CoerceError::Missing {
                        ty: t.clone(),
                        member: n.to_string(),
                    })?;
                out.push((n.as_str().into(), coerce(x, ft)?));
            }
            if let Some((extra, _)) = fs.iter().find(|(k, _)| !ts.iter().any(|(n, _)| **k == **n)) {
                return Err(CoerceError::Extra {
                    ty: t.clone(),
                    member: extra.to_string(),
                });
            }
            out.sort_by(|a, b| a.0.cmp(&b.0));
            Ok(Value::Record(out.into()))
        }
        (v, Type::Record(_)) => Err(CoerceError::NotRecord {
            ty: t.clone(),
            value: show(&v),
        }),
        (v, _) => Err(mismatch(&v)),
    }
}
