//! tessla-engine: checks a parsed TeSSLa spec, lowers it to a flat core IR and evaluates it.
//!
//! A spec flows text -> syntax (`tessla_syntax`) -> resolved (`resolve`) -> checked (`typeck`,
//! reading `builtins`) -> IR (`lower`, then `schedule`; the IR is `ir`, all data: stream nodes,
//! value code and a function table, listed by `ir::print`) -> closures (`exec`, compiled from the
//! IR's code when a program's first monitor is created) -> monitor (`monitor`, with `snapshot`,
//! whose stream identities hash the IR's structure). `load` runs the pipeline up to the IR.
//! Semantics used on the way: `ops` (operators), `natives` and
//! `collections` (value functions), `format` (format strings), `value` (what events carry).

pub mod builtins;
pub mod collections;
pub mod exec;
pub mod format;
pub mod ir;
pub mod load;
pub mod lower;
pub mod monitor;
pub mod natives;
pub mod ops;
pub mod prelude;
pub mod resolve;
pub mod schedule;
pub mod snapshot;
pub mod typeck;
pub mod value;

pub use exec::Program;
pub use ir::{Annotation, InputInfo, OutputInfo, Type};
pub use load::{LoadError, LoadOptions, Loaded, load_file, load_with};
pub use monitor::{InputError, Monitor, OutputEvent};
pub use value::{Callable, RuntimeError, Value};
