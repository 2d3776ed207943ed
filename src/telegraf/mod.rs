//! The Telegraf binding: how a spec's streams meet Telegraf's metrics.
//!
//! Owns: how a spec's inputs bind to metrics ([`binding`]: `@TelegrafIn`, indexed `_*` fields,
//! value conversion) and how outputs become metrics ([`encode`]: `@TelegrafOut`,
//! `@TelegrafField`, the default grouped metric). The processor ([`crate::processor`]) steps
//! monitors with them.

pub mod binding;
pub mod encode;
