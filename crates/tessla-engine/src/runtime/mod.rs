//! The runtime: what runs a lowered program ([`exec::Program`]) over events. Nothing here reads
//! syntax, names or types; everything starts from the IR (`crate::ir`) and values
//! (`crate::value`), the data the front end hands over.
//!
//! In the order a program meets them: `exec` (the IR's value code compiled into closures, once
//! per program: [`exec::Program`] is the IR with its compiled code), `flat` (the typed plan a
//! program of scalars also gets, made beside that code), `monitor` (one instance's state and the
//! step semantics: the plan's step when there is one and it has an answer, else the general
//! one), `snapshot` (a monitor's state as data, keyed by stable stream
//! identities, for restarts and reloads). The semantics they call: `ops` (operators), `natives`
//! and `collections` (value functions, which the builtins table names), `format` (Java's format
//! strings).
//!
//! Imports run one way: `snapshot` reads `monitor`, `monitor` runs `exec` and `flat`, `exec`
//! makes `flat`'s plan, and all of them read
//! `ops`, `natives`, `collections` and `format`, which read only values (and `ops` the IR's
//! operators, `crate::ir::op`). The front end reaches the runtime only through the builtins
//! table (`crate::builtins`: the natives' function pointers, the semantics of primitives for
//! constant folding), and `load` hands the finished IR over as an [`exec::Program`].

pub mod collections;
pub mod exec;
pub mod flat;
pub mod format;
pub mod monitor;
pub mod natives;
pub mod ops;
pub mod snapshot;
