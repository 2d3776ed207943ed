//! tessla-engine: checks a parsed TeSSLa spec, lowers it to a flat core IR and evaluates it.
//!
//! Owns: type checking (`typeck`, run before compilation), name resolution and macro expansion
//! (`compile`), the IR (`ir`), values (`value`), monitor instances (`monitor`) and their
//! snapshots (`snapshot`).

pub mod builtins;
pub mod collections;
pub mod compile;
pub mod ir;
pub mod load;
pub mod monitor;
pub mod natives;
pub mod ops;
pub mod snapshot;
pub mod typeck;
pub mod value;

pub use ir::{Annotation, InputInfo, OutputInfo, Program, Type};
pub use load::{LoadError, LoadOptions, Loaded, load_file, load_with};
pub use monitor::{InputError, Monitor, OutputEvent};
pub use value::{Callable, RuntimeError, Value};
