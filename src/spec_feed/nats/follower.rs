//! The running process's side of the spec channel ([`NatsFeed`]): every rollout and decision
//! read at start, then watched for; each handed to the step loop; the process's outcomes
//! written back to its status key, renewed every [`super::HEARTBEAT`].

use super::bucket::*;
use super::layout::*;
use super::{HEARTBEAT, LOOK_AGAIN};
use crate::log::{self, mask};
use crate::nats::conn::{Conn, Failure, violation};
use crate::nats::url::Url;
use crate::spec_feed::status::now_ns;
use crate::spec_feed::{Channel, Event, Outcome};
use async_nats::jetstream::{self, kv};
use futures_util::StreamExt;
use std::collections::BTreeSet;
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A running process's view of the channel (module doc).
pub struct NatsFeed {
    url: Url,
    /// Keeps the NATS thread (and the watching task on it) alive.
    conn: Conn,
    arrivals: mpsc::Receiver<Event>,
    /// The highest revision of a rollout handed out so far.
    last: u64,
    /// The latest status to write (key, status); the writer task puts whichever is newest,
    /// and again every [`HEARTBEAT`].
    status: tokio::sync::watch::Sender<Option<(String, Status)>>,
    /// The bucket, once it exists (the last status is written there as the process stops).
    store: tokio::sync::watch::Receiver<Option<kv::Store>>,
}

impl NatsFeed {
    /// Connect, read every rollout so far (blocking, at start, before the first record), and
    /// start watching for new ones. A bucket that does not exist yet is no error (nothing was
    /// published): it is looked for every 2 s. `trust`: the public keys whose signatures count
    /// (none: a configuration error).
    pub fn connect(url: &Url, trust: &[String]) -> Result<(NatsFeed, Vec<Event>), Failure> {
        if trust.is_empty() {
            return Err(Failure::Config(
                "a spec channel needs the operator's public key (--spec-trust KEY)".into(),
            ));
        }
        let conn =
            Conn::start().map_err(|e| Failure::Io(format!("cannot start the NATS thread: {e}")))?;
        let trust: Arc<[String]> = trust.to_vec().into();
        let (u, t) = (url.clone(), Arc::clone(&trust));
        let (opened, first) = conn
            .call(async move {
                let opened = open(u.clone(), false).await?;
                let first = match &opened.store {
                    Some(store) => read_patiently(store, &t).await.map_err(|e| {
                        Failure::Io(match violation(&opened.violations) {
                            Some(v) => denied(&u, &v),
                            None => format!("spec channel {}: {e}", u.shown()),
                        })
                    })?,
                    None => Vec::new(),
                };
                Ok::<_, Failure>((opened, first))
            })
            .ok_or_else(|| Failure::Io("the NATS thread stopped".to_string()))??;
        let exists = opened.store.is_some();
        let proposals = first.iter().filter(|e| matches!(e, Event::Proposal(_)));
        let known: BTreeSet<u64> = proposals.map(Event::revision).collect();
        let decided: BTreeSet<u64> = first
            .iter()
            .filter(|e| matches!(e, Event::Decision { .. }))
            .map(Event::revision)
            .collect();
        let last = known.last().copied().unwrap_or(0);
        let rollouts = first
            .iter()
            .filter(|e| matches!(e, Event::Proposal(_)))
            .count();
        let (tx, arrivals) = mpsc::channel();
        let (status, status_rx) = tokio::sync::watch::channel(None);
        let (store_tx, store_rx) = tokio::sync::watch::channel(opened.store.clone());
        // Every new rollout and decision, checked, to the feed.
        let (t, txx) = (Arc::clone(&trust), tx.clone());
        conn.handle.spawn(watch_keys(
            url.clone(),
            store_rx.clone(),
            "rollout",
            revision_of,
            known,
            move |store, revision, entry| {
                let (t, tx) = (Arc::clone(&t), txx.clone());
                async move {
                    let a = arrival(&store, revision, &entry.value, &t).await;
                    tx.send(Event::Proposal(a)).is_ok()
                }
            },
        ));
        conn.handle.spawn(watch_keys(
            url.clone(),
            store_rx.clone(),
            "decision",
            decided_revision_of,
            decided,
            move |_, revision, entry| {
                let decision = decision_of(revision, &entry.value, &trust);
                let sent = tx.send(Event::Decision { revision, decision }).is_ok();
                async move { sent }
            },
        ));
        conn.handle
            .spawn(find_bucket(opened.js, url.clone(), opened.store, store_tx));
        conn.handle.spawn(write_status(
            url.clone(),
            status_rx,
            store_rx.clone(),
            opened.violations,
        ));
        log_info!(
            "{}",
            if exists {
                format!(
                    "spec: following the spec channel {}: {rollouts} rollout(s) so far",
                    url.shown(),
                )
            } else {
                format!(
                    "spec: the spec channel {} has no bucket yet (the first `tessla-telegraf spec \
                     publish` creates it); looking for it every {}s",
                    url.shown(),
                    LOOK_AGAIN.as_secs()
                )
            }
        );
        Ok((
            NatsFeed {
                url: url.clone(),
                conn,
                arrivals,
                last,
                status,
                store: store_rx,
            },
            first,
        ))
    }

    /// Rollouts and decisions that arrived since the last call, in revision order, each once;
    /// never blocks.
    pub fn poll(&mut self) -> Vec<Event> {
        let mut got: Vec<Event> = self.arrivals.try_iter().collect();
        if got.is_empty() {
            return got;
        }
        got.sort_by_key(Event::revision);
        let mut out = Vec::with_capacity(got.len());
        for e in got {
            let r = e.revision();
            if matches!(e, Event::Proposal(_)) && r <= self.last {
                log_warn!(
                    "spec: {} arrived after rollout {} in {}: ignored (rollouts take effect in \
                         revision order; publish with `tessla-telegraf spec publish`, which takes the \
                         next revision)",
                    rollout_key(r),
                    self.last,
                    self.url.shown()
                );
                continue;
            }
            if matches!(e, Event::Proposal(_)) {
                self.last = r;
            }
            out.push(e);
        }
        out
    }

    /// Write this process's outcomes to its status key (best effort, in the background: a
    /// failure is a `W!` line, never fatal; a newer report replaces one not yet written).
    pub fn report(&mut self, host: &str, partition: &str, outcomes: &[Outcome]) {
        let pid = std::process::id();
        let status = Status {
            host: host.to_string(),
            partition: partition.to_string(),
            pid,
            time: now_ns(),
            outcomes: outcomes.to_vec(),
            stopped: false,
        };
        let _ = self
            .status
            .send(Some((status_key(host, partition, pid), status)));
    }
}

impl Drop for NatsFeed {
    /// The process stops: its status is written once more, marked stopped, so a publisher
    /// does not wait for its vote (best effort, at most `REQUEST_TIMEOUT`).
    fn drop(&mut self) {
        let Some((key, mut status)) = self.status.borrow().clone() else {
            return;
        };
        let Some(store) = self.store.borrow().clone() else {
            return;
        };
        status.stopped = true;
        status.time = now_ns();
        let Ok(bytes) = serde_json::to_vec(&status) else {
            return;
        };
        let put = async move {
            tokio::time::timeout(
                crate::nats::conn::REQUEST_TIMEOUT,
                store.put(key.as_str(), bytes.into()),
            )
            .await
        };
        let _ = self.conn.call(put);
    }
}

impl Channel for NatsFeed {
    fn poll(&mut self) -> Vec<Event> {
        NatsFeed::poll(self)
    }

    fn report(&mut self, host: &str, partition: &str, outcomes: &[Outcome]) {
        NatsFeed::report(self, host, partition, outcomes);
    }
}

/// Look for the bucket every [`LOOK_AGAIN`] until it exists (the first `spec publish` makes
/// it), then hand it to the tasks waiting for it.
async fn find_bucket(
    js: jetstream::Context,
    url: Url,
    store: Option<kv::Store>,
    store_tx: tokio::sync::watch::Sender<Option<kv::Store>>,
) {
    if store.is_some() {
        return;
    }
    loop {
        tokio::time::sleep(LOOK_AGAIN).await;
        if let Ok(s) = js.get_key_value(url.bucket.clone()).await {
            log_info!(
                "spec: the spec channel {} exists now; following it",
                url.shown()
            );
            let _ = store_tx.send(Some(s));
            // Keep the sender (and so the receivers' last value) alive.
            std::future::pending::<()>().await;
        }
    }
}

/// The bucket, once it exists (`None`: the process is ending).
async fn bucket(store: &mut tokio::sync::watch::Receiver<Option<kv::Store>>) -> Option<kv::Store> {
    store
        .wait_for(Option::is_some)
        .await
        .ok()
        .and_then(|s| s.clone())
}

/// Once the bucket exists, watch `prefix.>` (from the start of its history) and hand each new
/// put whose key `of` reads a revision from, not in `known`, to `each`; a watch that ends (the
/// connection lost for long) is started again. Returns when `each` says the feed is gone.
async fn watch_keys<F, Fut>(
    url: Url,
    mut store: tokio::sync::watch::Receiver<Option<kv::Store>>,
    prefix: &str,
    of: fn(&str) -> Option<u64>,
    mut known: BTreeSet<u64>,
    mut each: F,
) where
    F: FnMut(kv::Store, u64, kv::Entry) -> Fut,
    Fut: std::future::Future<Output = bool>,
{
    let Some(store) = bucket(&mut store).await else {
        return;
    };
    let mut warned = false;
    loop {
        match store.watch_with_history(format!("{prefix}.>")).await {
            Ok(mut watch) => {
                warned = false;
                while let Some(entry) = watch.next().await {
                    let Ok(entry) = entry else { break };
                    if entry.operation != kv::Operation::Put {
                        continue;
                    }
                    let Some(revision) = of(&entry.key) else {
                        log::warn_limited("spec-channel-key", || {
                            format!(
                                "spec: {} in {} is no {prefix} key ({prefix}.<revision>): ignored",
                                entry.key,
                                url.shown()
                            )
                        });
                        continue;
                    };
                    if !known.insert(revision) {
                        continue;
                    }
                    if !each(store.clone(), revision, entry).await {
                        return;
                    }
                }
            }
            Err(e) if !warned => {
                warned = true;
                log_warn!(
                    "spec: cannot watch the spec channel {}: {e}; trying again every second",
                    url.shown()
                );
            }
            Err(_) => {}
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
}

/// Put the newest status whenever there is one (once the bucket exists), and again every
/// [`HEARTBEAT`] with its time renewed: a publisher counts the votes of the processes whose key
/// is fresh.
async fn write_status(
    url: Url,
    mut status: tokio::sync::watch::Receiver<Option<(String, Status)>>,
    mut store: tokio::sync::watch::Receiver<Option<kv::Store>>,
    violations: Arc<Mutex<Vec<String>>>,
) {
    let mut warned = false;
    loop {
        // A new status, or the heartbeat's time: write; the process ending: stop.
        if let Ok(Err(_)) = tokio::time::timeout(HEARTBEAT, status.changed()).await {
            return;
        }
        let Some((key, mut s)) = status.borrow_and_update().clone() else {
            continue;
        };
        let Some(bucket) = store.borrow_and_update().clone() else {
            continue;
        };
        s.time = now_ns();
        let bytes = match serde_json::to_vec(&s) {
            Ok(b) => b,
            Err(e) => {
                log_warn!("spec: status not written: {e}");
                continue;
            }
        };
        match bucket.put(key.as_str(), bytes.into()).await {
            Ok(_) => warned = false,
            Err(e) if !warned => {
                warned = true;
                let why = match violation(&violations) {
                    Some(v) => format!(
                        "not permitted ({}); a process's login must be allowed to write the spec \
                         channel's status.> keys (telegraf/fleet-nats/accounts.conf)",
                        mask(&v)
                    ),
                    None => e.to_string(),
                };
                log_warn!(
                    "spec: cannot write this process's status {key} to {}: {why}; `spec status` \
                         shows an older one, and a publisher counts this process as silent",
                    url.shown()
                );
            }
            Err(_) => {}
        }
    }
}
