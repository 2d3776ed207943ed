//! The front end: a parsed spec (`tessla_syntax`) to the IR (`crate::ir`), one pass a module, in
//! the order a spec takes them:
//!
//! 1. `prelude`: the bundled standard library, added to the spec's files as TeSSLa's own;
//! 2. `resolve`: syntax -> resolved (which definition, input or member each name means; the
//!    name rules);
//! 3. `typeck`: resolved -> typed (the type rules; the types by expression the lowering takes);
//! 4. `lower`: typed -> IR (stream nodes, value code, the function table), finished by the IR's
//!    own pass `crate::ir::schedule` (evaluation order, cross-step slots).
//!
//! `crate::load` drives them. A pass reaches the runtime only through `crate::builtins`.

pub mod lower;
pub mod prelude;
pub mod resolve;
pub mod typeck;
