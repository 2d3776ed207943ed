//! The operator's side of the spec channel ([`Operator`]): what `tessla-telegraf spec` reads
//! (rollouts, decisions, statuses, with their signers), publishes and decides with.

use super::bucket::*;
use super::layout::*;
use super::{HEARTBEAT, LOOK_AGAIN};
use crate::log::mask;
use crate::nats::conn::{Conn, Failure, violation};
use crate::nats::url::Url;
use crate::spec_feed::bundle::Bundle;
use crate::spec_feed::error::RolloutError;
use crate::spec_feed::sign::{self, Record, RecordError};
use crate::spec_feed::status::now_ns;
use crate::spec_feed::{Decision, Rollout};
use async_nats::jetstream::kv;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A rollout as `spec list` shows it: read from its key, with its signer (not checked: the
/// operator's command has no trust list; the processes check).
#[derive(Debug, Clone)]
pub struct Listed {
    pub revision: u64,
    pub rollout: Result<Rollout, RecordError>,
    pub signer: Option<String>,
    /// When the server stored it (ns since the Unix epoch, the server's clock).
    pub written: i64,
}

/// A decision as the operator's command reads it (its signature not checked: `Err` only when
/// it cannot be read), with its signer.
#[derive(Debug, Clone)]
pub struct Decided {
    pub revision: u64,
    pub decision: Result<Decision, RecordError>,
    pub signer: Option<String>,
}

/// When the server stored `e` (ns since the Unix epoch): a clock every reader shares.
fn server_ns(e: &kv::Entry) -> i64 {
    i64::try_from(e.created.unix_timestamp_nanos()).unwrap_or(i64::MAX)
}

/// Why a status key cannot be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("not a status: {0}")]
pub struct StatusError(String);

/// A status key as `spec status` reads it: its name and the status (`Err`: why it cannot be
/// read).
#[derive(Debug, Clone)]
pub struct Reported {
    pub key: String,
    pub status: Result<Status, StatusError>,
    /// When the server stored it (ns since the Unix epoch, the server's clock): how fresh it is.
    pub written: i64,
}

/// The operator's side of the channel: read rollouts and statuses, publish.
pub struct Operator {
    url: Url,
    conn: Conn,
    store: Option<kv::Store>,
    violations: Arc<Mutex<Vec<String>>>,
    created: bool,
}

impl Operator {
    /// Connect; `create`: make the bucket when it does not exist (publishing).
    pub fn connect(url: &Url, create: bool) -> Result<Operator, Failure> {
        let conn =
            Conn::start().map_err(|e| Failure::Io(format!("cannot start the NATS thread: {e}")))?;
        let opened = conn
            .call(open(url.clone(), create))
            .ok_or_else(|| Failure::Io("the NATS thread stopped".to_string()))??;
        Ok(Operator {
            url: url.clone(),
            conn,
            store: opened.store,
            violations: opened.violations,
            created: opened.created,
        })
    }

    /// Whether this command made the bucket (processes started before it exist look for it
    /// every `LOOK_AGAIN` and report within a [`HEARTBEAT`] of finding it).
    pub fn created(&self) -> bool {
        self.created
    }

    /// How long after making the bucket the processes that were waiting for it have all
    /// reported.
    pub fn settling() -> Duration {
        LOOK_AGAIN + HEARTBEAT + Duration::from_millis(500)
    }

    /// Whether the bucket exists.
    pub fn exists(&self) -> bool {
        self.store.is_some()
    }

    pub fn url(&self) -> &Url {
        &self.url
    }

    /// A failure of a request: "not permitted" when the server reported a violation.
    fn failure(&self, what: &str, e: impl std::fmt::Display) -> Failure {
        Failure::Io(match violation(&self.violations) {
            Some(v) => denied(&self.url, &v),
            None => format!("spec channel {}: {what}: {e}", self.url.shown()),
        })
    }

    /// Run one request of the command on the NATS thread, bounded by [`READ_PATIENCE`] (three
    /// times for a listing): a stalled server makes the command fail with exit 3, never hang.
    fn run<T: Send + 'static>(
        &self,
        f: impl std::future::Future<Output = T> + Send + 'static,
    ) -> Result<T, Failure> {
        let patience = READ_PATIENCE * 3;
        self.conn
            .call(async move { tokio::time::timeout(patience, f).await })
            .ok_or_else(|| Failure::Io("the NATS thread stopped".to_string()))?
            .map_err(|_| {
                Failure::Io(format!(
                    "spec channel {}: the server did not answer within {} s",
                    self.url.shown(),
                    patience.as_secs()
                ))
            })
    }

    /// Every rollout, in revision order.
    pub fn rollouts(&self) -> Result<Vec<Listed>, Failure> {
        let Some(store) = self.store.clone() else {
            return Ok(Vec::new());
        };
        let got = self.run(async move {
            let mut out = Vec::new();
            for r in revisions(&store).await? {
                let key = rollout_key(r);
                match store.entry(key.as_str()).await {
                    Ok(Some(e)) if e.operation == kv::Operation::Put => {
                        let rec = Record::<Rollout>::parse(&e.value);
                        out.push(Listed {
                            revision: r,
                            rollout: rec.body,
                            signer: rec.signer,
                            written: server_ns(&e),
                        });
                    }
                    Ok(_) => {}
                    Err(source) => return Err(BucketError::Listed { key, source }),
                }
            }
            Ok(out)
        })?;
        got.map_err(|e| self.failure("reading the rollouts", e))
    }

    /// Every process's status, in key order.
    pub fn statuses(&self) -> Result<Vec<Reported>, Failure> {
        let Some(store) = self.store.clone() else {
            return Ok(Vec::new());
        };
        let got = self.run(async move {
            let mut names: Vec<String> = key_names(&store)
                .await?
                .into_iter()
                .filter(|k| k.starts_with("status."))
                .collect();
            names.sort();
            let mut out = Vec::new();
            for k in names {
                match store.entry(k.as_str()).await {
                    Ok(Some(e)) if e.operation == kv::Operation::Put => {
                        let s = serde_json::from_slice::<Status>(&e.value)
                            .map_err(|e| StatusError(e.to_string()));
                        out.push(Reported {
                            key: k,
                            status: s,
                            written: server_ns(&e),
                        });
                    }
                    Ok(_) => {}
                    Err(source) => return Err(BucketError::Listed { key: k, source }),
                }
            }
            Ok(out)
        })?;
        got.map_err(|e| self.failure("reading the statuses", e))
    }

    /// Every decision, in revision order.
    pub fn decisions(&self) -> Result<Vec<Decided>, Failure> {
        let Some(store) = self.store.clone() else {
            return Ok(Vec::new());
        };
        let got = self.run(async move {
            let mut out = Vec::new();
            for r in numbered_keys(&store, decided_revision_of).await? {
                let key = decision_key(r);
                match store.entry(key.as_str()).await {
                    Ok(Some(e)) if e.operation == kv::Operation::Put => {
                        let rec = Record::<Decision>::parse(&e.value);
                        out.push(Decided {
                            revision: r,
                            decision: rec.body,
                            signer: rec.signer,
                        });
                    }
                    Ok(_) => {}
                    Err(source) => return Err(BucketError::Listed { key, source }),
                }
            }
            Ok(out)
        })?;
        got.map_err(|e| self.failure("reading the decisions", e))
    }

    /// Store `decision`, signed with `key`, as `decision.<revision>` with the KV `create`: a
    /// revision is decided once. `Ok(None)`: stored; `Ok(Some(d))`: another command decided it
    /// first, and `d` is what it decided (the record that counts).
    pub fn decide(
        &self,
        decision: &Decision,
        key: &nkeys::KeyPair,
    ) -> Result<Option<Result<Decision, RolloutError>>, Failure> {
        let Some(store) = self.store.clone() else {
            return Err(Failure::Io(format!(
                "spec channel {}: no bucket",
                self.url.shown()
            )));
        };
        let bytes = sign::seal(decision, key).map_err(Failure::config)?;
        let k = decision_key(decision.revision);
        let kk = k.clone();
        let s = store.clone();
        let created = self.run(async move { s.create(kk.as_str(), bytes.into()).await })?;
        match created {
            Ok(_) => Ok(None),
            Err(e) if e.kind() == kv::CreateErrorKind::AlreadyExists => {
                let kk = k.clone();
                let got = self.run(async move { store.get(kk.as_str()).await })?;
                match got {
                    Ok(Some(v)) => Ok(Some(
                        Record::<Decision>::parse(&v)
                            .body
                            .map_err(RolloutError::from),
                    )),
                    Ok(None) => Ok(Some(Err(RolloutError::Vanished(k)))),
                    Err(e) => Err(self.failure("reading the decision", e)),
                }
            }
            Err(e) => Err(self.refused(&k, e)),
        }
    }

    /// Check that the bundle of `r` is in the channel and hashes to its digest (a rollback
    /// publishes an earlier version again).
    pub fn check_bundle(&self, r: &Rollout) -> Result<(), RolloutError> {
        let Some(store) = self.store.clone() else {
            return Err(RolloutError::NoBucket);
        };
        let r = r.clone();
        self.run(async move { fetch_bundle(&store, &r).await.map(|_| ()) })?
    }

    /// Put `bundle` (none for the base marker), then `rollout` signed with `key` as the next
    /// revision (its `revision` is set here: taken with the KV `create`, the next one tried
    /// when another publisher took it). Returns the rollout as published and when the server
    /// stored it (ns, the server's clock).
    pub fn publish(
        &self,
        bundle: Option<&Bundle>,
        mut rollout: Rollout,
        key: &nkeys::KeyPair,
    ) -> Result<(Rollout, i64), Failure> {
        let Some(store) = self.store.clone() else {
            return Err(Failure::Io(format!(
                "spec channel {}: no bucket",
                self.url.shown()
            )));
        };
        if let Some(b) = bundle {
            let bytes = serde_json::to_vec(b)
                .map_err(|e| Failure::Config(format!("the spec bundle: {e}")))?;
            let k = bundle_key(&b.id());
            let s = store.clone();
            let kk = k.clone();
            let put = self.run(async move { s.put(kk.as_str(), bytes.into()).await })?;
            if let Err(e) = put {
                return Err(self.refused(&k, e));
            }
        }
        let s = store.clone();
        let mut revision = self
            .run(async move { revisions(&s).await })?
            .map_err(|e| self.failure("reading the rollouts", e))?
            .last()
            .copied()
            .unwrap_or(0);
        // Each try takes the next revision; 100 publishers at once would be a fleet of operators.
        for _ in 0..100 {
            revision += 1;
            rollout.revision = revision;
            let bytes = sign::seal(&rollout, key).map_err(Failure::config)?;
            let s = store.clone();
            let k = rollout_key(revision);
            let kk = k.clone();
            let created = self.run(async move { s.create(kk.as_str(), bytes.into()).await })?;
            match created {
                Ok(_) => {
                    let s = store.clone();
                    let entry = self.run(async move { s.entry(k.as_str()).await })?;
                    let written = match entry {
                        Ok(Some(e)) => server_ns(&e),
                        _ => now_ns(),
                    };
                    return Ok((rollout, written));
                }
                Err(e) if e.kind() == kv::CreateErrorKind::AlreadyExists => continue,
                Err(e) => return Err(self.refused(&k, e)),
            }
        }
        Err(Failure::Io(format!(
            "spec channel {}: 100 revisions in a row were taken by other publishers; try again",
            self.url.shown()
        )))
    }

    /// A write that failed: "not permitted" (this login may not publish) or why.
    fn refused(&self, key: &str, e: impl std::fmt::Display) -> Failure {
        Failure::Io(match violation(&self.violations) {
            Some(v) => format!(
                "not permitted at {}: the server refused this login ({}) to write {key} in bucket \
                 {}: {}; only the operator's login may publish spec versions (the shipped \
                 telegraf/fleet-nats/accounts.conf gives that right to admin alone; the processes' \
                 users may write only status.> keys)",
                self.url.shown(),
                self.url.identity(),
                self.url.bucket,
                mask(&v)
            ),
            None => format!("spec channel {}: cannot write {key}: {e}", self.url.shown()),
        })
    }
}
