//! tessla-engine: checks a parsed TeSSLa spec, lowers it to a flat core IR and evaluates it.
//!
//! A spec flows text -> syntax (`tessla_syntax`) -> resolved (`resolve`) -> checked (`typeck`,
//! reading `builtins`) ->
//! IR (`lower`, then `schedule`; the IR is `ir`) -> monitor (`monitor`, with `snapshot`).
//! `load` runs the whole pipeline. Semantics used on the way: `ops` (operators), `natives` and
//! `collections` (value functions), `format` (format strings), `value` (what events carry).

pub mod builtins;
pub mod collections;
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

pub use ir::{Annotation, InputInfo, OutputInfo, Program, Type};
pub use load::{LoadError, LoadOptions, Loaded, load_file, load_with};
pub use monitor::{InputError, Monitor, OutputEvent};
pub use value::{Callable, RuntimeError, Value};
