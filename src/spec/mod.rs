//! The spec front end: source text -> checked [`crate::engine::Program`].
//!
//! Pipeline: `source` (files and spans) -> `lexer`/`parser` (AST with spans, `ast`) ->
//! `include` (loads includes relative to the including file, detects loops) -> checking
//! (names, macros, types, recursion) -> lowering to the engine's IR. Every problem becomes a
//! `diag::Diagnostic` naming file, line and column.

pub mod ast;
pub mod diag;
pub mod source;
