//! Native (Rust) implementations of the language's value functions (`core`). An application
//! adds natives of its own with `crate::builtins::Natives`.
//!
//! Owns: the implementations. Names, kinds and signatures are in `crate::builtins`; a native
//! reached only through `extern("name")` is declared with its TeSSLa signature in a library
//! spec (`def f(a: Int): Int = extern("f")`), and the checker types calls from that declaration. Natives are strict: the evaluator passes no
//! `Value::Error` argument to a native (it propagates the first error itself), so an
//! implementation only handles well-typed, error-free values. Natives that take functions call
//! them through [`crate::value::Callable`]; their type is [`crate::value::NativeFn`].

pub mod core;
