//! Values of TeSSLa streams and functions.
//!
//! Shared data, beside the IR rather than in `crate::runtime`: IR constants, annotation
//! arguments and folded constants are values, so the front end builds them as the runtime
//! does. This module imports nothing from the crate; the semantics of values (operators,
//! natives) are the runtime's.
//!
//! Owns: [`Value`] (what an event carries), [`RuntimeError`] (errors as values), the types of
//! function values ([`Callable`]) and natives ([`NativeFn`]) and how each is called
//! ([`call_function_value`], [`call_native`]), and the
//! TeSSLa output format of a value (`Display`: `()`, `Some(3)`, `List(1, 2)`, strings unquoted).
//! Scalars are inline (no heap allocation); compound values share their payload with `Arc`.
//!
//! `Int` is unbounded, as in TeSSLa's interpreter (Scala's `BigInt`): a result that does not
//! fit 64 bits becomes [`Value::BigInt`], and one that fits again becomes [`Value::Int`]
//! ([`Value::from_big`]), so each integer has exactly one form and the 64-bit path stays the
//! fast one. Specs rely on this: `pseudoInfty + resetTime < time(e)` with both at `i64::MAX`.

use std::fmt;
use std::sync::Arc;

#[derive(Debug, Clone)]
pub enum Value {
    Unit,
    Bool(bool),
    Int(i64),
    /// An `Int` outside 64 bits (never one that fits: see [`Value::from_big`]).
    BigInt(Arc<num_bigint::BigInt>),
    Float(f64),
    Str(Arc<str>),
    None,
    Some(Arc<Value>),
    List(Arc<Vec<Value>>),
    Tuple(Arc<[Value]>),
    /// Fields sorted by name.
    Record(Arc<[(Arc<str>, Value)]>),
    /// A set: distinct elements in TeSSLa's order (see [`Coll`]; equality ignores the order).
    Set(Arc<Coll<Value>>),
    /// A map: distinct keys in TeSSLa's order (see [`Coll`]; equality ignores the order).
    Map(Arc<Coll<(Value, Value)>>),
    /// A function value (a lambda or a named function passed to `lift`, `fold`, ...).
    Closure(Arc<dyn Callable>),
    Error(RuntimeError),
}

impl PartialEq for Value {
    fn eq(&self, other: &Self) -> bool {
        use Value::*;
        match (self, other) {
            (Unit, Unit) | (None, None) => true,
            (Bool(a), Bool(b)) => a == b,
            (Int(a), Int(b)) => a == b,
            (BigInt(a), BigInt(b)) => a == b,
            (Float(a), Float(b)) => a == b,
            (Str(a), Str(b)) => a == b,
            (Some(a), Some(b)) => a == b,
            (List(a), List(b)) => a == b,
            (Tuple(a), Tuple(b)) => a == b,
            (Record(a), Record(b)) => a == b,
            (Set(a), Set(b)) => a.len() == b.len() && a.iter().all(|x| b.contains(x)),
            (Map(a), Map(b)) => a.len() == b.len() && a.iter().all(|kv| b.contains(kv)),
            (Closure(a), Closure(b)) => Arc::ptr_eq(a, b),
            (Error(a), Error(b)) => a == b,
            _ => false,
        }
    }
}

impl Value {
    /// The value of an integer of any size: `Int` when it fits 64 bits, else `BigInt`.
    pub fn from_big(b: num_bigint::BigInt) -> Value {
        match i64::try_from(&b) {
            Ok(i) => Value::Int(i),
            Err(_) => Value::BigInt(Arc::new(b)),
        }
    }

    /// An integer value of either form as a big integer.
    pub fn as_big(&self) -> Option<num_bigint::BigInt> {
        match self {
            Value::Int(i) => Some((*i).into()),
            Value::BigInt(b) => Some((**b).clone()),
            _ => None,
        }
    }
}

/// A runtime error carried as a value (TeSSLa propagates errors through the streams).
#[derive(Debug, Clone, PartialEq)]
pub enum RuntimeError {
    DivisionByZero,
    Overflow,
    GetSomeOfNone,
    IndexOutOfBounds,
    NonPositiveDelay,
    Other(Arc<str>),
}

/// A native implementation: well-typed, error-free arguments in, a value (maybe an error) out.
/// Data as much as code: the IR names natives by these pointers (`ir::Callee::Native`), the
/// builtins table lists them, and `runtime::natives` implements them.
pub type NativeFn = fn(&[Value]) -> Value;

/// A function value. Implemented by the evaluator for compiled lambdas (and by the constant
/// fold, `ir::fold`, for the lambdas it makes); natives that take functions (`List.fold`,
/// `Map.map` ...) call them through this trait.
pub trait Callable: fmt::Debug + Send + Sync {
    fn call(&self, args: &[Value]) -> Value;
}

/// Most calls of a spec's functions nested in one another, in one evaluation (the runtime's
/// and the constant fold's alike).
pub const MAX_CALL_DEPTH: u32 = 100_000;

/// Stack a call needs left before it runs; below it, the next calls run on a new segment.
const CALL_RED_ZONE: usize = 128 * 1024;
const CALL_STACK_SEGMENT: usize = 2 * 1024 * 1024;

thread_local! {
    /// Calls of a spec's functions running now on this thread, nested.
    static CALL_DEPTH: std::cell::Cell<u32> = const { std::cell::Cell::new(0) };
}

/// Run `call`, one call of a spec's function (the runtime's compiled code or the constant
/// fold), nested in the calls running now on this thread. It runs on a stack that grows on the
/// heap, so a recursion as deep as [`MAX_CALL_DEPTH`] needs no large thread stack; a call
/// deeper than that (a recursion that never ends, or one too deep for its argument) is an
/// error value, as TeSSLa's runtime errors are: the output is dropped with a warning and the
/// monitor goes on, where the process would die of a stack overflow (or, growing its stack,
/// of memory).
#[inline]
pub fn nested_call(call: impl FnOnce() -> Value) -> Value {
    CALL_DEPTH.with(|depth| {
        let d = depth.get();
        if d >= MAX_CALL_DEPTH {
            return calls_too_deep();
        }
        depth.set(d + 1);
        let v = stacker::maybe_grow(CALL_RED_ZONE, CALL_STACK_SEGMENT, call);
        depth.set(d);
        v
    })
}

#[cold]
fn calls_too_deep() -> Value {
    Value::Error(RuntimeError::Other(
        format!(
            "function calls nested more than {MAX_CALL_DEPTH} deep (a recursion that does not \
             end, or is too deep for this input)"
        )
        .into(),
    ))
}

/// Call a native strictly: the first error argument is the result. The one calling convention
/// of natives, for the runtime and the constant fold.
#[inline]
pub fn call_native(f: NativeFn, args: &[Value]) -> Value {
    if let Some(e) = args.iter().find(|v| matches!(v, Value::Error(_))) {
        return e.clone();
    }
    f(args)
}

/// Call the function value that is the first argument with the others (an error when it is
/// no function), for the runtime and the constant fold.
pub fn call_function_value(args: &[Value]) -> Value {
    match args.first() {
        Some(Value::Closure(c)) => c.call(&args[1..]),
        other => Value::Error(RuntimeError::Other(
            format!("{:?} is not a function", other.unwrap_or(&Value::Unit)).into(),
        )),
    }
}

impl PartialEq for dyn Callable {
    /// Function values are equal only when they are the same function object.
    fn eq(&self, other: &Self) -> bool {
        std::ptr::addr_eq(self as *const Self, other as *const Self)
    }
}

/// Java's `Double.toString`, which TeSSLa's interpreter output uses: `23.0`, `1.0E63`,
/// `1.0E-5`, `Infinity`, `NaN`.
pub fn java_float(f: f64) -> String {
    if f.is_nan() {
        return "NaN".into();
    }
    if f.is_infinite() {
        return if f > 0.0 { "Infinity" } else { "-Infinity" }.into();
    }
    if f == 0.0 {
        return if f.is_sign_negative() { "-0.0" } else { "0.0" }.into();
    }
    let a = f.abs();
    if (1e-3..1e7).contains(&a) {
        let s = format!("{f}");
        if s.contains('.') { s } else { format!("{s}.0") }
    } else {
        // Shortest round-trip digits in scientific form, then Java's layout.
        let s = format!("{f:e}");
        let (mant, exp) = s.split_once('e').unwrap_or((&s, "0"));
        let mant = if mant.contains('.') {
            mant.to_string()
        } else {
            format!("{mant}.0")
        };
        format!("{mant}E{exp}")
    }
}

/// The elements of a set or the entries of a map, in the order TeSSLa prints and folds them:
/// Scala 2.13's immutable collections keep insertion order up to four elements; a fifth makes
/// them hashed (`HashSet`, `HashMap`), iterated in the order of their hash trie, and they stay
/// hashed when they shrink again. `runtime::collections` keeps the order; this type only holds
/// it. Dereferences to the elements.
///
/// A hashed collection may be held as a [`Trie`] (Scala's hash trie itself, built by
/// `runtime::collections`): then looking up, adding and replacing take a path of the trie, not
/// the whole collection, and the elements in order are made from it once, when first asked for.
#[derive(Clone)]
pub struct Coll<T> {
    items: std::sync::OnceLock<Vec<T>>,
    trie: Option<Trie<T>>,
    /// Grown past four elements once (Scala's hashed representation).
    pub hashed: bool,
}

impl<T: Clone> Coll<T> {
    /// `items`, already in their order, hashed or not.
    pub fn new(items: Vec<T>, hashed: bool) -> Self {
        Coll {
            items: items.into(),
            trie: None,
            hashed,
        }
    }

    /// A hashed collection held as its trie.
    pub fn from_trie(trie: Trie<T>) -> Self {
        Coll {
            items: std::sync::OnceLock::new(),
            trie: Some(trie),
            hashed: true,
        }
    }

    /// The trie, when the collection is held as one.
    pub fn trie(&self) -> Option<&Trie<T>> {
        self.trie.as_ref()
    }

    pub fn into_items(self) -> Vec<T> {
        let Coll { items, trie, .. } = self;
        match (items.into_inner(), trie) {
            (Some(v), _) => v,
            (None, Some(t)) => t.items(),
            (None, None) => Vec::new(),
        }
    }

    pub fn len(&self) -> usize {
        match (&self.trie, self.items.get()) {
            (Some(t), _) => t.len,
            (None, Some(v)) => v.len(),
            (None, None) => 0,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl<T: Clone + PartialEq> PartialEq for Coll<T> {
    fn eq(&self, other: &Self) -> bool {
        self.hashed == other.hashed && **self == **other
    }
}

impl<T: Clone + fmt::Debug> fmt::Debug for Coll<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Coll")
            .field("items", &**self)
            .field("hashed", &self.hashed)
            .finish()
    }
}

impl<T: Clone> Default for Coll<T> {
    fn default() -> Self {
        Coll::new(Vec::new(), false)
    }
}

impl<T: Clone> std::ops::Deref for Coll<T> {
    type Target = Vec<T>;
    fn deref(&self) -> &Vec<T> {
        self.items.get_or_init(|| match &self.trie {
            Some(t) => t.items(),
            None => Vec::new(),
        })
    }
}

/// Elements already in order; more than four make a hashed collection.
impl<T: Clone> From<Vec<T>> for Coll<T> {
    fn from(items: Vec<T>) -> Self {
        let hashed = items.len() > 4;
        Coll::new(items, hashed)
    }
}

impl<T: Clone> FromIterator<T> for Coll<T> {
    fn from_iter<I: IntoIterator<Item = T>>(iter: I) -> Self {
        iter.into_iter().collect::<Vec<T>>().into()
    }
}

/// A persistent hash trie in Scala 2.13's layout (CHAMP): at each level, 5 bits of the
/// (improved) hash choose a slot; an element alone in its slot is held in the node, slots
/// shared by several elements hold a child node for the next 5 bits; past 32 bits, elements
/// with equal hashes are kept in insertion order. In order, a node's own elements come first,
/// by slot, then its children's, by slot: the order Scala iterates `HashSet` and `HashMap` in.
/// Updates copy one path (at most seven nodes of at most 32 entries). Elements are never
/// removed (a removal leaves the trie for a plain list, see `runtime::collections`), so a
/// trie is exactly the one Scala builds by adding its elements one by one.
#[derive(Clone)]
pub struct Trie<T> {
    root: Arc<TrieNode<T>>,
    len: usize,
}

#[derive(Clone)]
struct TrieNode<T> {
    /// Elements alone in their slot, by slot, with their hashes (past 32 bits: all elements,
    /// in insertion order).
    data: Vec<(u32, T)>,
    /// Shared slots, by slot.
    children: Vec<(u32, Arc<TrieNode<T>>)>,
}

const TRIE_BITS: u32 = 32;

fn slot(hash: u32, shift: u32) -> u32 {
    (hash >> shift) & 31
}

impl<T: Clone> Default for Trie<T> {
    fn default() -> Self {
        Trie {
            root: Arc::new(TrieNode {
                data: Vec::new(),
                children: Vec::new(),
            }),
            len: 0,
        }
    }
}

impl<T: Clone> Trie<T> {
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The element whose key (`key`) equals `k`, hashed `hash`.
    pub fn get(&self, hash: u32, k: &Value, key: impl Fn(&T) -> &Value) -> Option<&T> {
        let mut node = &*self.root;
        let mut shift = 0;
        loop {
            if shift >= TRIE_BITS {
                return node.data.iter().map(|(_, x)| x).find(|x| key(x) == k);
            }
            let s = slot(hash, shift);
            if let Some((_, x)) = node.data.iter().find(|(h, _)| slot(*h, shift) == s) {
                return (key(x) == k).then_some(x);
            }
            node = &node.children.iter().find(|(cs, _)| *cs == s)?.1;
            shift += 5;
        }
    }

    /// The trie with `x` (hashed `hash`): an element with an equal key is replaced in place.
    pub fn insert(&self, hash: u32, x: T, key: impl Fn(&T) -> &Value) -> Trie<T> {
        let (root, added) = insert_at(&self.root, hash, x, 0, &key);
        Trie {
            root: Arc::new(root),
            len: self.len + usize::from(added),
        }
    }

    /// The elements in Scala's order.
    pub fn items(&self) -> Vec<T> {
        fn walk<T: Clone>(n: &TrieNode<T>, out: &mut Vec<T>) {
            out.extend(n.data.iter().map(|(_, x)| x.clone()));
            for (_, c) in &n.children {
                walk(c, out);
            }
        }
        let mut out = Vec::with_capacity(self.len);
        walk(&self.root, &mut out);
        out
    }
}

/// `node` with `x` at `shift`, and whether it was added (not a replacement).
fn insert_at<T: Clone>(
    node: &TrieNode<T>,
    hash: u32,
    x: T,
    shift: u32,
    key: &impl Fn(&T) -> &Value,
) -> (TrieNode<T>, bool) {
    let mut n = node.clone();
    if shift >= TRIE_BITS {
        match n.data.iter_mut().find(|(_, y)| key(y) == key(&x)) {
            Some(e) => e.1 = x,
            None => {
                n.data.push((hash, x));
                return (n, true);
            }
        }
        return (n, false);
    }
    let s = slot(hash, shift);
    if let Some(i) = n.data.iter().position(|(h, _)| slot(*h, shift) == s) {
        if key(&n.data[i].1) == key(&x) {
            n.data[i] = (hash, x);
            return (n, false);
        }
        // Two elements share the slot now: a child holds both, the older first.
        let (oh, old) = n.data.remove(i);
        let empty = TrieNode {
            data: Vec::new(),
            children: Vec::new(),
        };
        let (c, _) = insert_at(&empty, oh, old, shift + 5, key);
        let (c, _) = insert_at(&c, hash, x, shift + 5, key);
        let at = n.children.partition_point(|(cs, _)| *cs < s);
        n.children.insert(at, (s, Arc::new(c)));
        return (n, true);
    }
    if let Some(i) = n.children.iter().position(|(cs, _)| *cs == s) {
        let (c, added) = insert_at(&n.children[i].1, hash, x, shift + 5, key);
        n.children[i].1 = Arc::new(c);
        return (n, added);
    }
    let at = n.data.partition_point(|(h, _)| slot(*h, shift) < s);
    n.data.insert(at, (hash, x));
    (n, true)
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fn list(
            f: &mut fmt::Formatter<'_>,
            open: &str,
            items: &[Value],
            close: &str,
        ) -> fmt::Result {
            f.write_str(open)?;
            for (i, v) in items.iter().enumerate() {
                if i > 0 {
                    f.write_str(", ")?;
                }
                write!(f, "{v}")?;
            }
            f.write_str(close)
        }
        match self {
            Value::Unit => f.write_str("()"),
            Value::Bool(b) => write!(f, "{b}"),
            Value::Int(i) => write!(f, "{i}"),
            Value::BigInt(i) => write!(f, "{i}"),
            Value::Float(x) => f.write_str(&java_float(*x)),
            Value::Str(s) => f.write_str(s),
            Value::None => f.write_str("None"),
            Value::Some(v) => write!(f, "Some({v})"),
            Value::List(l) => list(f, "List(", l, ")"),
            Value::Tuple(t) => list(f, "(", t, ")"),
            Value::Record(r) => {
                f.write_str("{")?;
                for (i, (k, v)) in r.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{k} = {v}")?;
                }
                f.write_str("}")
            }
            // Scala's names: small collections keep insertion order, larger ones are hashed.
            Value::Set(items) if items.hashed => list(f, "HashSet(", items, ")"),
            Value::Set(items) => list(f, "Set(", items, ")"),
            Value::Map(entries) => {
                f.write_str(if entries.hashed { "HashMap(" } else { "Map(" })?;
                for (i, (k, v)) in entries.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{k} -> {v}")?;
                }
                f.write_str(")")
            }
            Value::Closure(_) => f.write_str("<function>"),
            Value::Error(e) => write!(f, "{e}"),
        }
    }
}

impl fmt::Display for RuntimeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RuntimeError::DivisionByZero => f.write_str("Division by zero"),
            RuntimeError::Overflow => f.write_str("Integer overflow"),
            RuntimeError::GetSomeOfNone => f.write_str("Tried to get value of None"),
            RuntimeError::IndexOutOfBounds => f.write_str("Index out of bounds"),
            RuntimeError::NonPositiveDelay => f.write_str("Delay must be positive"),
            RuntimeError::Other(s) => f.write_str(s),
        }
    }
}

impl std::error::Error for RuntimeError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_print_as_java_does() {
        assert_eq!(java_float(23.0), "23.0");
        assert_eq!(java_float(1e63), "1.0E63");
        assert_eq!(java_float(1.5e-5), "1.5E-5");
        assert_eq!(java_float(0.25), "0.25");
        assert_eq!(java_float(f64::INFINITY), "Infinity");
        assert_eq!(
            Value::List(Arc::new(vec![Value::Int(1), Value::Int(2)])).to_string(),
            "List(1, 2)"
        );
    }
}
