//! The fleet's spec channel: a JetStream key-value bucket (default `tessla_specs`) beside the
//! state bucket, named by a URL in `--state`'s syntax with its login and TLS options (the
//! connection, its failures and their messages are `nats::conn`'s).
//!
//! Owns the bucket's layout (`docs/book/src/state-and-reload.md`, "Spec versions across a fleet"):
//! - `bundle.<id>`: a version's [`Bundle`](super::bundle::Bundle) as JSON (`id` =
//!   [`Bundle::id`](super::bundle::Bundle::id));
//! - `rollout.<revision>`: a signed rollout record ([`super::sign`]), revisions 1, 2, 3, …,
//!   append-only: each is created with the KV `create`, so two publishers never take one
//!   revision (the later one retries with the next);
//! - `decision.<revision>`: the fleet's signed decision on that rollout ([`Decision`](super::Decision): commit
//!   or abort, with the votes), created once with the KV `create`;
//! - `status.<host>.<partition>.pid<N>` (`status.<host>.pid<N>` without a partition): a
//!   process's outcomes ([`Status`]): its votes and what each decision did there, rewritten
//!   every [`HEARTBEAT`] so a publisher sees it is alive.
//!
//! Two sides: [`NatsFeed`], what a running process follows (every rollout and decision
//! verified against the trusted keys and a rollout's bundle against its digest, handed to the
//! step loop; its outcomes written back), and [`Operator`], what `tessla-telegraf spec` reads,
//! publishes and decides with.
//!
//! Split by concern: [`layout`] names the keys, [`bucket`] opens the bucket and reads and checks
//! what is in it, [`follower`] is the running process's side, [`operator`] the command's.

pub mod bucket;
pub mod follower;
pub mod layout;
pub mod operator;

pub use follower::NatsFeed;
pub use layout::{Status, status_key};
pub use operator::{Decided, Listed, Operator, Reported, StatusError};

use crate::log::mask;
use crate::nats::url::{DEFAULT_TTL, Url, UrlError};
use std::time::Duration;

/// The bucket a channel URL without one names.
pub const DEFAULT_BUCKET: &str = "tessla_specs";

/// How often a process looks again for a channel bucket that does not exist yet.
const LOOK_AGAIN: Duration = Duration::from_secs(2);

/// How often a process rewrites its status key (with the same outcomes): the publisher counts
/// a process whose key was written within [`LIVE`] before its rollout as one whose vote it
/// waits for.
pub const HEARTBEAT: Duration = Duration::from_secs(2);

/// A process whose status key is older than this (by the server's clock) when a rollout is
/// proposed is taken to be gone: its vote is not waited for.
pub const LIVE: Duration = Duration::from_secs(10);

/// Parse a channel URL: `--state`'s syntax (`nats://HOST:PORT[,...][/BUCKET][?login, TLS,
/// replicas]`), the bucket [`DEFAULT_BUCKET`] when none is named. The partition options of
/// `--state` (`lease=`, `ttl=`) are refused: a channel has no lease.
pub fn parse_url(s: &str) -> Result<Url, ChannelUrlError> {
    let url = Url::parse(&with_default_bucket(s))?;
    if url.lease.is_some() || url.ttl != DEFAULT_TTL {
        return Err(ChannelUrlError::Lease(mask(s)));
    }
    Ok(url)
}

/// Why a spec channel URL is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChannelUrlError {
    /// Not a URL in `--state`'s syntax.
    #[error("spec channel {0}")]
    Url(#[from] UrlError),
    /// A partition option (`lease=`, `ttl=`); the URL as shown, its secrets masked.
    #[error(
        "spec channel `{0}`: lease= and ttl= are --state's options (the partition lease); a \
         spec channel has none"
    )]
    Lease(String),
}

/// `s` with `/tessla_specs` after the hosts when it names no bucket.
fn with_default_bucket(s: &str) -> String {
    let Some((scheme, rest)) = s.split_once("://") else {
        return s.to_string();
    };
    let (main, query) = match rest.split_once('?') {
        Some((m, q)) => (m, Some(q)),
        None => (rest, None),
    };
    let hosts = main.rsplit_once('@').map_or(main, |(_, h)| h);
    let main = if !hosts.contains('/') {
        format!("{main}/{DEFAULT_BUCKET}")
    } else if hosts.ends_with('/') {
        format!("{main}{DEFAULT_BUCKET}")
    } else {
        main.to_string()
    };
    match query {
        Some(q) => format!("{scheme}://{main}?{q}"),
        None => format!("{scheme}://{main}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_channel_url_is_a_state_url_with_a_default_bucket_and_no_lease() {
        let u = parse_url("nats://a:1,b:2").unwrap();
        assert_eq!(u.bucket, DEFAULT_BUCKET);
        assert_eq!(u.servers, ["a:1", "b:2"]);
        let u = parse_url("nats://u:p%2Fq@a:1/?replicas=3&tls-ca=/ca.pem").unwrap();
        assert_eq!((u.bucket.as_str(), u.replicas), (DEFAULT_BUCKET, 3));
        assert!(u.tls.required);
        assert_eq!(parse_url("nats://a/specs2").unwrap().bucket, "specs2");
        let e = parse_url("nats://a/b?lease=p0").unwrap_err().to_string();
        assert!(e.contains("lease="), "{e}");
        let e = parse_url("nats://u:Secr3t@a/b?x=1")
            .unwrap_err()
            .to_string();
        assert!(e.contains("spec channel") && !e.contains("Secr3t"), "{e}");
        assert!(parse_url("/a/file").is_err());
    }
}
