//! Runtime values of TeSSLa streams and functions.
//!
//! Owns: [`Value`] (what an event carries), [`RuntimeError`] (errors as values), and the
//! TeSSLa output format of a value (`Display`: `()`, `Some(3)`, `List(1, 2)`, strings unquoted).
//! Scalars are inline (no heap allocation); compound values share their payload with `Arc`.

use std::fmt;
use std::sync::Arc;

#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Unit,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(Arc<str>),
    None,
    Some(Arc<Value>),
    List(Arc<Vec<Value>>),
    Tuple(Arc<[Value]>),
    /// Fields sorted by name.
    Record(Arc<[(Arc<str>, Value)]>),
    /// A function value (a lambda or a named function passed to `lift`, `fold`, ...).
    Closure(Arc<dyn Callable>),
    Error(RuntimeError),
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

/// A function value. Implemented by the evaluator for compiled lambdas; natives that take
/// functions (`List.fold`, `Map.map` ...) call them through this trait.
pub trait Callable: fmt::Debug + Send + Sync {
    fn call(&self, args: &[Value]) -> Value;
}

impl PartialEq for dyn Callable {
    /// Function values are equal only when they are the same function object.
    fn eq(&self, other: &Self) -> bool {
        std::ptr::addr_eq(self as *const Self, other as *const Self)
    }
}
