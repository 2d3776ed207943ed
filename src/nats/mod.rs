//! NATS as the state store and the spec channel both use it: the connection and its failures
//! ([`conn`]), what a `nats://` URL says ([`url`]), the secrets it logs in with ([`secrets`]),
//! and the names of keys in a key-value bucket ([`kv_keys`]). The state store (`state::nats`,
//! `state::lease`) and the spec channel (`spec_feed::nats`) build on these; neither owns them.

pub mod conn;
pub mod kv_keys;
pub mod secrets;
pub mod url;
