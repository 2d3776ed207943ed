//! tessla-syntax: TeSSLa 1.2 source text -> AST with spans, and the diagnostics every phase uses.
//!
//! Owns: source files and spans (`source`), diagnostics and their rendering (`diag`), the AST
//! (`ast`), and parsing. It knows nothing about types or evaluation (see `tessla-engine`).
//!
#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

pub mod ast;
pub mod diag;
pub mod include;
pub mod lexer;
pub mod parser;

pub use parser::{parse, parse_expr};
pub mod source;
