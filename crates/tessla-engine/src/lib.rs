//! tessla-engine: checks a parsed TeSSLa spec, lowers it to a flat core IR and evaluates it.
//!
//! The road a spec takes, front end first, then the runtime:
//!
//! 1. text -> syntax: `tessla_syntax` (parser, includes, diagnostics);
//! 2. syntax -> resolved: `front::resolve` (which definition, input or member each name means);
//! 3. resolved -> typed: `front::typeck` (reading `builtins` and the bundled `front::prelude`);
//! 4. typed -> IR: `front::lower`, then `ir::schedule` (evaluation order, cross-step slots).
//!    The IR (`ir`) is all data: stream nodes, value code and a function table, listed by
//!    `ir::print`;
//! 5. IR -> monitor: `runtime` (`exec` compiles the IR's code into closures once per program,
//!    `monitor` runs instances, `snapshot` saves and restores their state; the semantics they
//!    call: `ops`, `natives`, `collections`, `format`).
//!
//! `load` drives steps 1 to 4 and hands the IR to the runtime ([`Program`]). Shared by both
//! sides: `ir` and `value` (what events and IR constants carry). The front end reaches the
//! runtime only through the builtins table (`builtins`); no runtime module imports the front
//! end, and no two modules import each other.
//!
#![doc = include_str!("../README.md")]

pub mod builtins;
pub mod front;
pub mod ir;
pub mod load;
pub mod runtime;
pub mod value;

pub use ir::{Annotation, InputInfo, OutputInfo, Type};
pub use load::{LoadError, LoadOptions, Loaded, file_resolver, load_file, load_with};
pub use runtime::exec::Program;
pub use runtime::monitor::{InputError, Monitor, OutputEvent};
pub use value::{Callable, RuntimeError, Value};
