//! The spec channel's bucket as both sides read it: opened (created when the operator
//! publishes), its keys listed without a consumer, and each rollout, bundle and decision read
//! and checked (signature by a trusted key, revision, digest).

use super::layout::*;
use crate::log::mask;
use crate::nats::conn::{Failure, connect, violation};
use crate::nats::url::Url;
use crate::processor::versions::Selector;
use crate::spec_feed::bundle::Bundle;
use crate::spec_feed::error::RolloutError;
use crate::spec_feed::sign::Record;
use crate::spec_feed::{Arrival, BASE, Decision, Event, Rollout};
use async_nats::jetstream::{self, kv};
use futures_util::StreamExt;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The connection, the JetStream context and the bucket (`None`: it does not exist yet).
pub(super) struct Opened {
    pub(super) js: jetstream::Context,
    pub(super) store: Option<kv::Store>,
    pub(super) violations: Arc<Mutex<Vec<String>>>,
    /// The bucket was made by this call.
    pub(super) created: bool,
}

/// Connect and open the channel's bucket; `create`: make it when missing (the operator's
/// commands that publish; with the replicas of the URL).
pub(super) async fn open(url: Url, create: bool) -> Result<Opened, Failure> {
    let (client, violations) = connect(&url).await?;
    let js = jetstream::new(client.clone());
    let stream = format!("KV_{}", url.bucket);
    let missing = match js.get_stream(&stream).await {
        Ok(_) => false,
        Err(e) => match e.kind() {
            jetstream::context::GetStreamErrorKind::JetStream(j)
                if j.error_code() == jetstream::ErrorCode::STREAM_NOT_FOUND =>
            {
                true
            }
            _ => {
                if let Some(v) = violation(&violations) {
                    return Err(Failure::Io(denied(&url, &v)));
                }
                return Err(Failure::Io(format!(
                    "cannot open the spec channel {}: {e}",
                    url.shown()
                )));
            }
        },
    };
    let store = if !missing {
        Some(js.get_key_value(url.bucket.clone()).await.map_err(|e| {
            Failure::Io(match violation(&violations) {
                Some(v) => denied(&url, &v),
                None => format!("cannot open the spec channel {}: {e}", url.shown()),
            })
        })?)
    } else if create {
        let store = crate::state::nats::create(&js, &url).await.map_err(|e| {
            match (violation(&violations), e) {
                (Some(v), _) => Failure::Io(denied(&url, &v)),
                (None, e) => e,
            }
        })?;
        log_info!(
            "spec: created the spec channel's bucket {} ({} replicas); every process names it with --spec-channel",
            url.bucket,
            url.replicas
        );
        Some(store)
    } else {
        None
    };
    Ok(Opened {
        js,
        store,
        violations,
        created: missing && create,
    })
}

/// A request the server refused (opening, reading or creating the bucket): who, where, and what
/// the login needs.
pub(super) fn denied(url: &Url, text: &str) -> String {
    format!(
        "not permitted at {}: the server denied this login ({}) access to the spec channel's \
         bucket {b}: {}; a process's user needs to read stream KV_{b} (its info, consumers, \
         message gets) and to write $KV.{b}.status.>, the operator's user (admin) everything \
         of the bucket (telegraf/fleet-nats/accounts.conf)",
        url.shown(),
        url.identity(),
        mask(text),
        b = url.bucket
    )
}

/// Why the bucket's keys or entries could not be read.
#[derive(Debug, thiserror::Error)]
pub(super) enum BucketError {
    /// The stream's subject list (the bucket's keys).
    #[error("cannot list the spec channel's keys: {0}")]
    Keys(#[from] jetstream::stream::InfoError),
    /// One entry, as a process reads the channel.
    #[error("cannot read {key} from the spec channel: {source}")]
    Entry { key: String, source: kv::EntryError },
    /// One entry, as the operator's commands list the channel (their messages name the channel
    /// already).
    #[error("cannot read {key}: {source}")]
    Listed { key: String, source: kv::EntryError },
    /// [`read_patiently`] gave up.
    #[error(
        "its rollouts could not be read within {} s, three times; is the server overloaded?",
        READ_PATIENCE.as_secs()
    )]
    TooSlow,
}

/// The revisions of every rollout in the bucket, in order.
pub(super) async fn revisions(store: &kv::Store) -> Result<Vec<u64>, BucketError> {
    numbered_keys(store, revision_of).await
}

/// The revisions of every key `of` reads a revision from, in order.
pub(super) async fn numbered_keys(
    store: &kv::Store,
    of: fn(&str) -> Option<u64>,
) -> Result<Vec<u64>, BucketError> {
    let mut out: Vec<u64> = key_names(store)
        .await?
        .iter()
        .filter_map(|k| of(k))
        .collect();
    out.sort_unstable();
    out.dedup();
    Ok(out)
}

/// Every key of the bucket (a deleted one too: its marker is a message; readers take `Put`
/// entries only), from the stream's subject list: requests and answers, no consumer.
/// `Store::keys` creates an ordered push consumer per call and waits until it reports everything
/// delivered; the status keys every process rewrites every 2 s kept that from ending within the
/// 30 s bound on a loaded machine (a rollback in the real-process tests failed so).
pub(super) async fn key_names(store: &kv::Store) -> Result<Vec<String>, BucketError> {
    let mut subjects = store
        .stream
        .info_with_subjects(format!("{}>", store.prefix))
        .await?;
    let mut out = Vec::new();
    while let Some(s) = subjects.next().await {
        let (subject, _) = s?;
        if let Some(k) = subject.strip_prefix(store.prefix.as_str()) {
            out.push(k.to_string());
        }
    }
    Ok(out)
}

/// The rollout stored as `rollout.<revision>`, checked: its record read, its revision the key's,
/// its signature by a trusted key, and its bundle (fetched) hashing to its digest.
pub(super) async fn arrival(
    store: &kv::Store,
    revision: u64,
    value: &[u8],
    trust: &[String],
) -> Arrival {
    let record = Record::<Rollout>::parse(value);
    let mut rollout = match &record.body {
        Ok(r) => r.clone(),
        Err(why) => {
            return Arrival {
                rollout: Rollout {
                    revision,
                    id: String::new(),
                    digest: String::new(),
                    label: String::new(),
                    from: 0,
                    selector: Selector::all(),
                    published: 0,
                    fleet: false,
                },
                bundle: Err(why.clone().into()),
            };
        }
    };
    let stored_as = rollout.revision;
    rollout.revision = revision;
    let bundle = if stored_as != revision {
        Err(RolloutError::RolloutMoved {
            said: stored_as,
            key: rollout_key(revision),
        })
    } else {
        match record.verify(trust) {
            Err(why) => Err(why.into()),
            Ok(()) => fetch_bundle(store, &rollout).await,
        }
    };
    Arrival { rollout, bundle }
}

/// The bundle of a verified rollout, checked against its digest (the `base` marker has none: an
/// empty bundle).
pub(super) async fn fetch_bundle(store: &kv::Store, r: &Rollout) -> Result<Bundle, RolloutError> {
    if r.id == BASE {
        if !r.digest.is_empty() {
            return Err(RolloutError::BaseWithDigest);
        }
        return Ok(Bundle {
            files: Vec::new(),
            links: Vec::new(),
        });
    }
    if r.digest.len() != 64 || !r.digest.starts_with(&r.id) || r.id.len() != 12 {
        return Err(RolloutError::IdNotOfDigest {
            id: r.id.clone(),
            digest: r.digest.clone(),
        });
    }
    let key = bundle_key(&r.id);
    let bytes = match store.get(key.as_str()).await {
        Ok(Some(b)) => b,
        Ok(None) => return Err(RolloutError::NoBundle(key)),
        Err(e) => {
            return Err(RolloutError::BundleUnreadable {
                key,
                why: e.to_string(),
            });
        }
    };
    let bundle: Bundle = match serde_json::from_slice(&bytes) {
        Ok(b) => b,
        Err(e) => {
            return Err(RolloutError::NotABundle {
                key,
                why: e.to_string(),
            });
        }
    };
    let digest = bundle.digest();
    if digest != r.digest {
        return Err(RolloutError::BundleChanged { key, digest });
    }
    Ok(bundle)
}

/// The decision stored as `decision.<revision>`, checked: its record read, signed by a trusted
/// key, and for the revision its key names.
pub(super) fn decision_of(
    revision: u64,
    value: &[u8],
    trust: &[String],
) -> Result<Decision, RolloutError> {
    let record = Record::<Decision>::parse(value);
    let d = record.body.clone()?;
    record.verify(trust)?;
    if d.revision != revision {
        return Err(RolloutError::DecisionMoved {
            said: d.revision,
            key: decision_key(revision),
        });
    }
    Ok(d)
}

/// Every rollout and decision so far, checked, in revision order (each decision before its
/// rollout).
pub(super) async fn read_all(
    store: &kv::Store,
    trust: &[String],
) -> Result<Vec<Event>, BucketError> {
    let mut out = Vec::new();
    for r in numbered_keys(store, decided_revision_of).await? {
        let key = decision_key(r);
        match store.entry(key.as_str()).await {
            Ok(Some(e)) if e.operation == kv::Operation::Put => out.push(Event::Decision {
                revision: r,
                decision: decision_of(r, &e.value, trust),
            }),
            Ok(_) => {}
            Err(source) => return Err(BucketError::Entry { key, source }),
        }
    }
    for r in revisions(store).await? {
        let key = rollout_key(r);
        match store.entry(key.as_str()).await {
            Ok(Some(e)) if e.operation == kv::Operation::Put => {
                out.push(Event::Proposal(arrival(store, r, &e.value, trust).await));
            }
            Ok(_) => {}
            Err(source) => return Err(BucketError::Entry { key, source }),
        }
    }
    Ok(out)
}

/// How long one reading of the channel at start may take before it is tried again.
pub(super) const READ_PATIENCE: Duration = Duration::from_secs(10);

/// [`read_all`] with a bound: a listing the server leaves unfinished (its consumer stalled) is
/// started again, at most three times in all, then it is an error: a process never hangs
/// silently at start.
pub(super) async fn read_patiently(
    store: &kv::Store,
    trust: &[String],
) -> Result<Vec<Event>, BucketError> {
    for attempt in 1..=3 {
        match tokio::time::timeout(READ_PATIENCE, read_all(store, trust)).await {
            Ok(got) => return got,
            Err(_) => log_warn!(
                "spec: reading the spec channel's rollouts took over {} s (try {attempt} of 3); reading again",
                READ_PATIENCE.as_secs()
            ),
        }
    }
    Err(BucketError::TooSlow)
}
