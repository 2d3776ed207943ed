//! Runtime values of TeSSLa streams and functions.
//!
//! Owns: [`Value`] (what an event carries), [`RuntimeError`] (errors as values), and the
//! TeSSLa output format of a value (`Display`: `()`, `Some(3)`, `List(1, 2)`, strings unquoted).
//! Scalars are inline (no heap allocation); compound values share their payload with `Arc`.

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
