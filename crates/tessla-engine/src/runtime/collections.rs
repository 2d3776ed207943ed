//! TeSSLa's immutable `Set[T]` and `Map[K, V]` value functions (`Set.add`, `Map.get`, ...)
//! and the few `List` functions the core natives lack (`List.isEmpty`, `List.zip`, ...).
//!
//! Owns: these pure functions (listed by name in `builtins`) over [`Value::Set`] / [`Value::Map`],
//! and the order TeSSLa prints and folds them in (Scala 2.13's: insertion order up to four
//! elements; from the fifth, hashed, iterated in the order of Scala's hash trie over Scala's
//! hash of each element, `##`, and hashed for good). The hash is known for Int, Float, Bool,
//! String and Unit elements; a hashed collection holding other values keeps insertion order.
//! A hashed collection whose elements' hashes are all known is held as that hash trie
//! ([`Trie`]): membership, `Map.get` and adding or replacing an element walk one path of it,
//! so a map of thousands of items (one state per item) costs per event what a small one does.
//! Other collections are lists, where membership is a linear scan (values have no total
//! order), and a removal turns a trie into the list of its elements, order kept. Errors
//! in arguments are handled by the caller (the compiler never passes an error value into a
//! value function).

use crate::value::{Coll, RuntimeError, Trie, Value};
use std::collections::BTreeMap;
use std::sync::Arc;

/// Scala's `##` of a value, where we know it: an `Int` is a `BigInt` (its `Int` or `Long`
/// hash), a `Float` a `Double` (`Statics.doubleHash`), a `String` Java's `hashCode`.
fn scala_hash(v: &Value) -> Option<i32> {
    fn long_hash(l: i64) -> i32 {
        if l == i64::from(l as i32) {
            l as i32
        } else {
            (l ^ (l >> 32)) as i32 // Java's Long.hashCode (the high half xor the low)
        }
    }
    Some(match v {
        Value::Int(i) => long_hash(*i),
        Value::Float(d) => {
            let d = *d;
            if d == f64::from(d as i32) {
                d as i32
            } else if d == (d as i64) as f64 && d.abs() < 9.2e18 {
                long_hash(d as i64)
            } else if d == f64::from(d as f32) {
                (d as f32).to_bits() as i32
            } else {
                let b = if d.is_nan() {
                    0x7ff8_0000_0000_0000u64
                } else {
                    d.to_bits()
                };
                (b ^ (b >> 32)) as i32
            }
        }
        Value::Bool(true) => 1231,
        Value::Bool(false) => 1237,
        Value::Unit => 0,
        Value::Str(s) => s
            .encode_utf16()
            .fold(0i32, |h, c| h.wrapping_mul(31).wrapping_add(i32::from(c))),
        _ => return None,
    })
}

/// Scala's spreading of a hash over the trie's levels (`Hashing.improve`).
fn improve(h: i32) -> u32 {
    let mut h = h.wrapping_add(!(h << 9));
    h ^= ((h as u32) >> 14) as i32;
    h = h.wrapping_add(h << 4);
    (h ^ ((h as u32) >> 10) as i32) as u32
}

/// The order of a hash trie's elements (by index into the improved hashes): at each level,
/// first the elements alone in their 5-bit slot, by slot, then the shared slots' sub-tries.
fn trie_order(hashes: &[(u32, usize)], shift: u32, out: &mut Vec<usize>) {
    if hashes.len() <= 1 || shift >= 32 {
        out.extend(hashes.iter().map(|(_, i)| *i));
        return;
    }
    let mut slots: BTreeMap<u32, Vec<(u32, usize)>> = BTreeMap::new();
    for &(h, i) in hashes {
        slots.entry((h >> shift) & 31).or_default().push((h, i));
    }
    for group in slots.values().filter(|g| g.len() == 1) {
        out.push(group[0].1);
    }
    for group in slots.values().filter(|g| g.len() > 1) {
        trie_order(group, shift + 5, out);
    }
}

/// `items` in hash-trie order by `key`; unchanged when a key's hash is unknown.
fn hash_ordered<T: Clone>(items: &[T], key: impl Fn(&T) -> &Value) -> Vec<T> {
    let hashes: Option<Vec<(u32, usize)>> = items
        .iter()
        .enumerate()
        .map(|(i, x)| scala_hash(key(x)).map(|h| (improve(h), i)))
        .collect();
    match hashes {
        Some(h) => {
            let mut order = Vec::with_capacity(items.len());
            trie_order(&h, 0, &mut order);
            order.into_iter().map(|i| items[i].clone()).collect()
        }
        None => items.to_vec(),
    }
}

/// The improved Scala hash of `v`, when known (the key of a [`Trie`]).
fn trie_hash(v: &Value) -> Option<u32> {
    scala_hash(v).map(improve)
}

/// A hashed collection of `items` (already in their order): as a trie when every key's hash is
/// known (the trie's order is [`hash_ordered`]'s), else as the list, in the order given.
fn hashed_coll<T: Clone>(items: Vec<T>, key: impl Fn(&T) -> &Value) -> Coll<T> {
    let mut t = Trie::default();
    for x in &items {
        match trie_hash(key(x)) {
            Some(h) => t = t.insert(h, x.clone(), &key),
            None => return Coll::new(items, true),
        }
    }
    Coll::from_trie(t)
}

/// Whether `c` holds an element whose key is `k`.
fn has_key<T: Clone>(c: &Coll<T>, k: &Value, key: impl Fn(&T) -> &Value) -> bool {
    find_key(c, k, key).is_some()
}

/// The element of `c` whose key is `k`.
fn find_key<'a, T: Clone>(c: &'a Coll<T>, k: &Value, key: impl Fn(&T) -> &Value) -> Option<&'a T> {
    match c.trie() {
        // Every key of a trie has a known hash; a key without one is none of them.
        Some(t) => t.get(trie_hash(k)?, k, key),
        None => c.iter().find(|x| key(x) == k),
    }
}

/// The set of `items` (duplicates dropped) as Scala builds it by adding them one by one.
pub fn set_of(items: Vec<Value>) -> Value {
    let mut s = Arc::new(Coll::default());
    for x in &items {
        s = with(&s, x);
    }
    Value::Set(s)
}

/// The map of `entries` (a repeated key keeps its place and takes the later value) as Scala
/// builds it by adding them one by one.
pub fn map_of(entries: Vec<(Value, Value)>) -> Value {
    let mut m = Value::Map(Arc::new(Coll::default()));
    for (k, v) in &entries {
        if let Value::Map(cur) = &m {
            m = map_with(cur, k, v);
        }
    }
    m
}

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
    Value::Set(Arc::new(Coll::default()))
}

pub fn empty_map() -> Value {
    Value::Map(Arc::new(Coll::default()))
}

/// `s` with `x` (Scala's `incl`): appended while the set stays at four elements or fewer,
/// otherwise hashed.
fn with(s: &Arc<Coll<Value>>, x: &Value) -> Arc<Coll<Value>> {
    if has_key(s, x, |x| x) {
        return s.clone();
    }
    if let (Some(t), Some(h)) = (s.trie(), trie_hash(x)) {
        return Arc::new(Coll::from_trie(t.insert(h, x.clone(), |x| x)));
    }
    let mut v: Vec<Value> = s.to_vec();
    v.push(x.clone());
    if s.hashed || v.len() > 4 {
        Arc::new(hashed_coll(hash_ordered(&v, |x| x), |x| x))
    } else {
        Arc::new(Coll::new(v, false))
    }
}

/// The elements of `s` that `keep` (order and representation kept, as Scala's `filter`).
fn filtered(s: &Coll<Value>, keep: impl Fn(&Value) -> bool) -> Value {
    let items: Vec<Value> = s.iter().filter(|e| keep(e)).cloned().collect();
    Value::Set(Arc::new(Coll::new(items, s.hashed)))
}

pub fn set_add(a: &[Value]) -> Value {
    match a {
        [Value::Set(s), x] => Value::Set(with(s, x)),
        _ => bad("Set.add", a),
    }
}

pub fn set_contains(a: &[Value]) -> Value {
    match a {
        [Value::Set(s), x] => Value::Bool(has_key(s, x, |x| x)),
        _ => bad("Set.contains", a),
    }
}

pub fn set_remove(a: &[Value]) -> Value {
    match a {
        [Value::Set(s), x] if !has_key(s, x, |x| x) => Value::Set(s.clone()),
        [Value::Set(s), x] => filtered(s, |e| e != x),
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
        [Value::Set(x), Value::Set(y)] => filtered(x, |e| y.contains(e)),
        _ => bad("Set.intersection", a),
    }
}

pub fn set_minus(a: &[Value]) -> Value {
    match a {
        [Value::Set(x), Value::Set(y)] => filtered(x, |e| !y.contains(e)),
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
            let mut out = Arc::new(Coll::default());
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

/// `m` with `k` bound to `v` (Scala's `updated`): an existing key keeps its place; a new one
/// is appended while the map stays at four entries or fewer, otherwise the map is hashed.
fn map_with(m: &Coll<(Value, Value)>, k: &Value, v: &Value) -> Value {
    if let (Some(t), Some(h)) = (m.trie(), trie_hash(k)) {
        let t = t.insert(h, (k.clone(), v.clone()), |(k, _)| k);
        return Value::Map(Arc::new(Coll::from_trie(t)));
    }
    let mut out: Vec<(Value, Value)> = m.to_vec();
    match out.iter_mut().find(|(key, _)| key == k) {
        Some(entry) => {
            entry.1 = v.clone();
            return Value::Map(Arc::new(Coll::new(out, m.hashed)));
        }
        None => out.push((k.clone(), v.clone())),
    }
    if m.hashed || out.len() > 4 {
        Value::Map(Arc::new(hashed_coll(
            hash_ordered(&out, |(k, _)| k),
            |(k, _)| k,
        )))
    } else {
        Value::Map(Arc::new(Coll::new(out, false)))
    }
}

pub fn map_add(a: &[Value]) -> Value {
    match a {
        [Value::Map(m), k, v] => map_with(m, k, v),
        _ => bad("Map.add", a),
    }
}

pub fn map_contains(a: &[Value]) -> Value {
    match a {
        [Value::Map(m), k] => Value::Bool(has_key(m, k, |(k, _)| k)),
        _ => bad("Map.contains", a),
    }
}

pub fn map_get(a: &[Value]) -> Value {
    match a {
        [Value::Map(m), k] => find_key(m, k, |(k, _)| k)
            .map(|(_, v)| v.clone())
            .unwrap_or_else(|| {
                Value::Error(RuntimeError::Other(format!("Map.get: no key {k}").into()))
            }),
        _ => bad("Map.get", a),
    }
}

pub fn map_get_or_else(a: &[Value]) -> Value {
    match a {
        [Value::Map(m), k, d] => {
            find_key(m, k, |(k, _)| k).map_or_else(|| d.clone(), |(_, v)| v.clone())
        }
        _ => bad("Map.getOrElse", a),
    }
}

pub fn map_remove(a: &[Value]) -> Value {
    match a {
        [Value::Map(m), k] => Value::Map(Arc::new(Coll::new(
            m.iter().filter(|(key, _)| key != k).cloned().collect(),
            m.hashed,
        ))),
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
            let mut out = empty_map();
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
        set_of(xs.iter().map(|x| Value::Int(*x)).collect())
    }

    #[test]
    fn scala_orders_and_names_sets_as_tessla_prints_them() {
        // Set1..Set4 keep insertion order; the fifth element makes a HashSet in hash-trie
        // order, which stays a HashSet when it shrinks.
        let s = set(&[1, 2, 3, 4]);
        assert_eq!(s.to_string(), "Set(1, 2, 3, 4)");
        let s = set_add(&[s, Value::Int(5)]);
        assert_eq!(s.to_string(), "HashSet(5, 1, 2, 3, 4)");
        let s = set_remove(&[s, Value::Int(2)]);
        assert_eq!(s.to_string(), "HashSet(5, 1, 3, 4)");
        let s = set_remove(&[set_remove(&[s, Value::Int(3)]), Value::Int(4)]);
        assert_eq!(s.to_string(), "HashSet(5, 1)");
        assert_eq!(set_add(&[s, Value::Int(3)]).to_string(), "HashSet(5, 1, 3)");
        // Java's String.hashCode and Scala's Double hash.
        assert_eq!(scala_hash(&Value::Str("ab".into())), Some(3105));
        assert_eq!(scala_hash(&Value::Float(2.0)), Some(2));
        assert_eq!(scala_hash(&Value::Float(0.5)), Some(0x3f00_0000));
        assert_eq!(scala_hash(&Value::Int(1 << 40)), Some(256));
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

    /// Sets and maps held as tries keep the order the list representation gives (Scala's):
    /// the order of `hash_ordered` over the elements in insertion order, equal hashes included.
    #[test]
    fn tries_keep_scalas_order() {
        // Int(0) and 2^32 + 1 have the same hash (Java's Long.hashCode); so do "Aa" and "BB".
        let mut keys: Vec<Value> = vec![
            Value::Int(0),
            Value::Int((1 << 32) + 1),
            Value::Str("Aa".into()),
            Value::Str("BB".into()),
            Value::Float(2.5),
            Value::Bool(true),
            Value::Unit,
        ];
        let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0x9e37_79b9);
        for _ in 0..600 {
            let x = rand::RngCore::next_u64(&mut rng);
            keys.push(match x % 3 {
                0 => Value::Int((x >> 8) as i64 % 5000),
                1 => Value::Str(format!("item{}", (x >> 8) % 700).into()),
                _ => Value::Int((x >> 4) as i64),
            });
        }
        let (mut set, mut map) = (empty_set(), empty_map());
        let mut order: Vec<Value> = Vec::new();
        for (n, k) in keys.iter().enumerate() {
            set = set_add(&[set, k.clone()]);
            map = map_add(&[map, k.clone(), Value::Int(n as i64)]);
            if !order.contains(k) {
                order.push(k.clone());
            }
            let expected = if order.len() > 4 {
                hash_ordered(&order, |x| x)
            } else {
                order.clone()
            };
            let (Value::Set(s), Value::Map(m)) = (&set, &map) else {
                panic!("not a set and a map");
            };
            assert_eq!(***s, expected, "after {n} additions");
            let got: Vec<Value> = m.iter().map(|(k, _)| k.clone()).collect();
            assert_eq!(got, expected, "after {n} additions");
            assert_eq!((s.len(), m.len()), (expected.len(), expected.len()));
            assert!(order.len() <= 4 || s.trie().is_some() && m.trie().is_some());
        }
        for (n, k) in keys.iter().enumerate() {
            assert_eq!(set_contains(&[set.clone(), k.clone()]), Value::Bool(true));
            let last = keys.iter().rposition(|x| x == k).unwrap_or(n);
            assert_eq!(map_get(&[map.clone(), k.clone()]), Value::Int(last as i64));
        }
        assert_eq!(
            map_get_or_else(&[map.clone(), Value::Str("none".into()), Value::Int(-1)]),
            Value::Int(-1)
        );
        // A value without a known hash leaves the trie for the list, in the order so far.
        let t = Value::Tuple(vec![Value::Int(1)].into());
        let Value::Map(before) = &map else {
            panic!("not a map")
        };
        let before: Vec<Value> = before.iter().map(|(k, _)| k.clone()).collect();
        let with_t = map_add(&[map.clone(), t.clone(), Value::Unit]);
        let Value::Map(m) = &with_t else {
            panic!("not a map")
        };
        assert!(m.trie().is_none() && m.hashed);
        let got: Vec<Value> = m.iter().map(|(k, _)| k.clone()).collect();
        assert_eq!(got[..got.len() - 1], before[..]);
        assert_eq!(got.last(), Some(&t));
        // A removal keeps the order (and the hashed form), as before tries.
        let removed = map_remove(&[map.clone(), keys[0].clone()]);
        let Value::Map(r) = &removed else {
            panic!("not a map")
        };
        let got: Vec<Value> = r.iter().map(|(k, _)| k.clone()).collect();
        let mut want = before.clone();
        want.retain(|k| *k != keys[0]);
        assert_eq!(got, want);
        assert!(r.hashed);
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
