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
pub(crate) mod front;
pub(crate) mod ir;
pub mod load;
// Crate-private: its public parts are re-exported below (the README, "Public API"); its
// documentation may link to the private IR.
#[allow(rustdoc::private_intra_doc_links)]
pub(crate) mod runtime;
pub mod value;

pub use builtins::{Natives, RegisterError};
pub use front::lower::time::{BaseTimeError, parse_base_time};
pub use ir::schedule::Cycle;
pub use ir::{Annotation, InputInfo, OutputInfo, Type};
pub use load::{LoadError, LoadOptions, Loaded, file_resolver, load_file, load_with};
pub use runtime::exec::Program;
pub use runtime::format::{FormatError, java_format};
pub use runtime::monitor::{InputError, Monitor, OutputEvent};
pub use runtime::natives::core::{CTF_MARKER, ctf_get_int};
pub use runtime::snapshot;
pub use value::{Callable, RuntimeError, Value};

/// TeSSLa's Set and Map values built and read outside a spec (an application's natives, a trace
/// reader): the functions the builtins `Map_add`, `Map_contains`, ... run, their arguments as a
/// slice, and the constructors from Rust collections.
pub mod collections {
    pub use crate::runtime::collections::{
        empty_map, empty_set, map_add, map_contains, map_get, map_get_or_else, map_of, map_remove,
        set_add, set_contains, set_of,
    };
}

/// TeSSLa's arithmetic, comparison and bit operators on values, as the monitors evaluate them
/// (for an application that evaluates expressions of its own with the same semantics, such as a
/// trace reader).
pub mod ops {
    pub use crate::ir::{BinOp, UnaryOp};
    pub use crate::runtime::ops::{OpError, binary, unary};
}
