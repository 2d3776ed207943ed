//! tessla-telegraf: a TeSSLa runtime-verification engine that runs as a Telegraf
//! `processors.execd` plugin.
//!
//! Data flows one way: bytes in ([`lineproto`] or [`trace`]) -> input events bound to streams
//! ([`telegraf`]) -> the evaluation engine ([`engine`], running a program built by the front end
//! [`spec`]) -> output events -> bytes out. [`transport`] moves the bytes (stdin/stdout, UDP);
//! [`cli`] wires the subcommands.

pub mod cli;
pub mod engine;
pub mod spec;
