//! TeSSLa's immutable `Set[T]` and `Map[K, V]` value functions (`Set.add`, `Map.get`, ...)
//! and the few `List` functions the core natives lack (`List.isEmpty`, `List.zip`, ...).
//!
//! Owns: these pure functions (listed by name in `builtins`) over [`Value::Set`] / [`Value::Map`]. Elements are kept in
//! insertion order (values have no total order or hash: floats and closures), so membership is a
//! linear scan; sets in monitors are small. Errors in arguments are handled by the caller (the
//! compiler never passes an error value into a value function).

use crate::value::{RuntimeError, Value};
use std::sync::Arc;

fn bad(name: &str, a: &[Value]) -> Value {
    Value::Error(RuntimeError::Other(
        format!("{name}: unexpected arguments {a:?}").into(),
    ))
}

fn call(f: &Value, args: &[Value]) -> Value {
    match f {
        Value::Closure(c) => c.call(args),
        other => Value::Error(RuntimeError::Other(
            format!("{other:?} is not a function").into(),
        )),
    }
}

/// `List.empty`, `Set.empty`, `Map.empty`.
pub fn empty_list() -> Value {
    Value::List(Arc::new(Vec::new()))
}

pub fn empty_set() -> Value {
    Value::Set(Arc::new(Vec::new()))
}

pub fn empty_map() -> Value {
    Value::Map(Arc::new(Vec::new()))
}

fn with(s: &Arc<Vec<Value>>, x: &Value) -> Arc<Vec<Value>> {
    if s.contains(x) {
        return s.clone();
    }
    let mut v = (**s).clone();
    v.push(x.clone());
    Arc::new(v)
}

pub fn set_add(a: &[Value]) -> Value {
    match a {
        [Value::Set(s), x] => Value::Set(with(s, x)),
        _ => bad("Set.add", a),
    }
}

pub fn set_contains(a: &[Value]) -> Value {
    match a {
        [Value::Set(s), x] => Value::Bool(s.contains(x)),
        _ => bad("Set.contains", a),
    }
}

pub fn set_remove(a: &[Value]) -> Value {
    match a {
        [Value::Set(s), x] => Value::Set(Arc::new(s.iter().filter(|e| *e != x).cloned().collect())),
        _ => bad("Set.remove", a),
    }
}

pub fn set_size(a: &[Value]) -> Value {
    match a {
        [Value::Set(s)] => Value::Int(i64::try_from(s.len()).unwrap_or(i64::MAX)),
        _ => bad("Set.size", a),
    }
}

pub fn set_union(a: &[Value]) -> Value {
    match a {
        [Value::Set(x), Value::Set(y)] => {
            Value::Set(y.iter().fold(x.clone(), |acc, e| with(&acc, e)))
        }
        _ => bad("Set.union", a),
    }
}

pub fn set_intersection(a: &[Value]) -> Value {
    match a {
        [Value::Set(x), Value::Set(y)] => Value::Set(Arc::new(
            x.iter().filter(|e| y.contains(e)).cloned().collect(),
        )),
        _ => bad("Set.intersection", a),
    }
}

pub fn set_minus(a: &[Value]) -> Value {
    match a {
        [Value::Set(x), Value::Set(y)] => Value::Set(Arc::new(
            x.iter().filter(|e| !y.contains(e)).cloned().collect(),
        )),
        _ => bad("Set.minus", a),
    }
}

pub fn set_fold(a: &[Value]) -> Value {
    match a {
        [Value::Set(s), init, f] => {
            let mut acc = init.clone();
            for x in s.iter() {
                acc = call(f, &[acc, x.clone()]);
                if matches!(acc, Value::Error(_)) {
                    break;
                }
            }
            acc
        }
        _ => bad("Set.fold", a),
    }
}

pub fn set_map(a: &[Value]) -> Value {
    match a {
        [Value::Set(s), f] => {
            let mut out = Arc::new(Vec::new());
            for x in s.iter() {
                let y = call(f, std::slice::from_ref(x));
                if matches!(y, Value::Error(_)) {
                    return y;
                }
                out = with(&out, &y);
            }
            Value::Set(out)
        }
        _ => bad("Set.map", a),
    }
}

fn map_with(m: &[(Value, Value)], k: &Value, v: &Value) -> Value {
    let mut out: Vec<(Value, Value)> = m.to_vec();
    match out.iter_mut().find(|(key, _)| key == k) {
        Some(entry) => entry.1 = v.clone(),
        None => out.push((k.clone(), v.clone())),
    }
    Value::Map(Arc::new(out))
}

pub fn map_add(a: &[Value]) -> Value {
    match a {
        [Value::Map(m), k, v] => map_with(m, k, v),
        _ => bad("Map.add", a),
    }
}

pub fn map_contains(a: &[Value]) -> Value {
    match a {
        [Value::Map(m), k] => Value::Bool(m.iter().any(|(key, _)| key == k)),
        _ => bad("Map.contains", a),
    }
}

pub fn map_get(a: &[Value]) -> Value {
    match a {
        [Value::Map(m), k] => m
            .iter()
            .find(|(key, _)| key == k)
            .map(|(_, v)| v.clone())
            .unwrap_or_else(|| {
                Value::Error(RuntimeError::Other(format!("Map.get: no key {k}").into()))
            }),
        _ => bad("Map.get", a),
    }
}

pub fn map_get_or_else(a: &[Value]) -> Value {
    match a {
        [Value::Map(m), k, d] => m
            .iter()
            .find(|(key, _)| key == k)
            .map_or_else(|| d.clone(), |(_, v)| v.clone()),
        _ => bad("Map.getOrElse", a),
    }
}

pub fn map_remove(a: &[Value]) -> Value {
    match a {
        [Value::Map(m), k] => Value::Map(Arc::new(
            m.iter().filter(|(key, _)| key != k).cloned().collect(),
        )),
        _ => bad("Map.remove", a),
    }
}

pub fn map_size(a: &[Value]) -> Value {
    match a {
        [Value::Map(m)] => Value::Int(i64::try_from(m.len()).unwrap_or(i64::MAX)),
        _ => bad("Map.size", a),
    }
}

pub fn map_keys(a: &[Value]) -> Value {
    match a {
        [Value::Map(m)] => Value::List(Arc::new(m.iter().map(|(k, _)| k.clone()).collect())),
        _ => bad("Map.keys", a),
    }
}

pub fn map_fold(a: &[Value]) -> Value {
    match a {
        [Value::Map(m), init, f] => {
            let mut acc = init.clone();
            for (k, v) in m.iter() {
                acc = call(f, &[acc, k.clone(), v.clone()]);
                if matches!(acc, Value::Error(_)) {
                    break;
                }
            }
            acc
        }
        _ => bad("Map.fold", a),
    }
}

/// `Map.map(m, (k, v) => (k2, v2))`.
pub fn map_map(a: &[Value]) -> Value {
    match a {
        [Value::Map(m), f] => {
            let mut out = Value::Map(Arc::new(Vec::new()));
            for (k, v) in m.iter() {
                match call(f, &[k.clone(), v.clone()]) {
                    Value::Tuple(t) if t.len() == 2 => {
                        if let Value::Map(cur) = &out {
                            out = map_with(cur, &t[0], &t[1]);
                        }
                    }
                    e @ Value::Error(_) => return e,
                    other => {
                        return Value::Error(RuntimeError::Other(
                            format!("Map.map: the function returned {other}, not a pair").into(),
                        ));
                    }
                }
            }
            out
        }
        _ => bad("Map.map", a),
    }
}

pub fn list_is_empty(a: &[Value]) -> Value {
    match a {
        [Value::List(l)] => Value::Bool(l.is_empty()),
        _ => bad("List.isEmpty", a),
    }
}

pub fn list_zip(a: &[Value]) -> Value {
    match a {
        [Value::List(x), Value::List(y)] => Value::List(Arc::new(
            x.iter()
                .zip(y.iter())
                .map(|(p, q)| Value::Tuple(vec![p.clone(), q.clone()].into()))
                .collect(),
        )),
        _ => bad("List.zip", a),
    }
}

pub fn list_zip_with_index(a: &[Value]) -> Value {
    match a {
        [Value::List(x)] => Value::List(Arc::new(
            x.iter()
                .zip(0i64..)
                .map(|(p, i)| Value::Tuple(vec![Value::Int(i), p.clone()].into()))
                .collect(),
        )),
        _ => bad("List.zipWithIndex", a),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(xs: &[i64]) -> Value {
        Value::Set(Arc::new(xs.iter().map(|x| Value::Int(*x)).collect()))
    }

    #[test]
    fn sets_ignore_duplicates_and_order() {
        let s = set_add(&[set_add(&[set(&[1]), Value::Int(2)]), Value::Int(1)]);
        assert_eq!(s.to_string(), "Set(1, 2)");
        assert_eq!(s, set(&[2, 1]));
        assert_ne!(s, set(&[1]));
        assert_eq!(set_remove(&[s, Value::Int(1)]).to_string(), "Set(2)");
        assert_eq!(
            set_intersection(&[set(&[1, 2, 3]), set(&[3, 2, 9])]),
            set(&[2, 3])
        );
    }

    #[test]
    fn maps_replace_values_of_existing_keys() {
        let m = map_add(&[empty_map(), Value::Int(1), Value::Int(10)]);
        let m = map_add(&[m, Value::Int(1), Value::Int(11)]);
        assert_eq!(m.to_string(), "Map(1 -> 11)");
        assert_eq!(map_get(&[m.clone(), Value::Int(1)]), Value::Int(11));
        assert!(matches!(map_get(&[m, Value::Int(2)]), Value::Error(_)));
    }
}
