//! The fleet's spec channel: a JetStream key-value bucket (default `tessla_specs`) beside the
//! state bucket, named by a URL in `--state`'s syntax with its login and TLS options (the
//! connection, its failures and their messages are `nats::conn`'s).
//!
//! Owns the bucket's layout (`docs/state-and-reload.md`, "Spec versions across a fleet"):
//! - `bundle.<id>`: a version's [`Bundle`] as JSON (`id` = [`Bundle::id`]);
//! - `rollout.<revision>`: a signed rollout record ([`super::sign`]), revisions 1, 2, 3, …,
//!   append-only: each is created with the KV `create`, so two publishers never take one
//!   revision (the later one retries with the next);
//! - `decision.<revision>`: the fleet's signed decision on that rollout ([`Decision`]: commit
//!   or abort, with the votes), created once with the KV `create`;
//! - `status.<host>.<partition>.pid<N>` (`status.<host>.pid<N>` without a partition): a
//!   process's outcomes ([`Status`]): its votes and what each decision did there, rewritten
//!   every [`HEARTBEAT`] so a publisher sees it is alive.
//!
//! Two sides: [`NatsFeed`], what a running process follows (every rollout and decision
//! verified against the trusted keys and a rollout's bundle against its digest, handed to the
//! step loop; its outcomes written back), and [`Operator`], what `tessla-telegraf spec` reads,
//! publishes and decides with.

use super::bundle::Bundle;
use super::sign::{self, Record};
use super::status::now_ns;
use super::{Arrival, BASE, Channel, Decision, Event, Outcome, Rollout};
use crate::log::{self, mask};
use crate::nats::conn::{Conn, Failure, connect, violation};
use crate::nats::kv_keys::kv_key_part_of;
use crate::nats::url::{DEFAULT_TTL, Url};
use crate::processor::versions::Selector;
use async_nats::jetstream::{self, kv};
use futures_util::StreamExt;
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
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
pub fn parse_url(s: &str) -> Result<Url, String> {
    let url = Url::parse(&with_default_bucket(s)).map_err(|e| format!("spec channel {e}"))?;
    if url.lease.is_some() || url.ttl != DEFAULT_TTL {
        return Err(format!(
            "spec channel `{}`: lease= and ttl= are --state's options (the partition lease); a \
             spec channel has none",
            mask(s)
        ));
    }
    Ok(url)
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

/// What a process writes to its status key: its outcomes so far, for `spec status`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Status {
    pub host: String,
    /// The partition (`--state`'s lease name), or empty.
    #[serde(default)]
    pub partition: String,
    pub pid: u32,
    /// When it was written (ns since the Unix epoch, the process's wall clock).
    pub time: i64,
    pub outcomes: Vec<Outcome>,
    /// Written by the process as it stopped (its key is no longer renewed): a publisher does
    /// not wait for its vote.
    #[serde(default)]
    pub stopped: bool,
}

/// The status key of a process: `status.<host>.<partition>.pid<N>`, or `status.<host>.pid<N>`
/// without a partition (host and partition written as the state bucket writes a tag value:
/// injective, only characters NATS allows). The pid keeps apart the processes of one host that
/// run one partition (its primary and its standbys); a restarted process writes a new key and
/// its old one, no longer renewed, reads as stopped or silent (`spec status`), and is no voter.
/// Keys written by earlier versions (`status.<host>.<partition>`) are still read: the status
/// names its own host, partition and pid.
pub fn status_key(host: &str, partition: &str, pid: u32) -> String {
    if partition.is_empty() {
        format!("status.{}.pid{pid}", kv_key_part_of(host))
    } else {
        format!(
            "status.{}.{}.pid{pid}",
            kv_key_part_of(host),
            kv_key_part_of(partition)
        )
    }
}

fn rollout_key(revision: u64) -> String {
    format!("rollout.{revision}")
}

fn decision_key(revision: u64) -> String {
    format!("decision.{revision}")
}

fn bundle_key(id: &str) -> String {
    format!("bundle.{id}")
}

/// The revision of a `rollout.<revision>` key.
fn revision_of(key: &str) -> Option<u64> {
    numbered(key, "rollout.")
}

/// The revision of a `decision.<revision>` key.
fn decided_revision_of(key: &str) -> Option<u64> {
    numbered(key, "decision.")
}

fn numbered(key: &str, prefix: &str) -> Option<u64> {
    let digits = key.strip_prefix(prefix)?;
    // Written as `rollout_key` writes it: no sign, no leading zero.
    digits
        .parse()
        .ok()
        .filter(|r: &u64| *r > 0 && r.to_string() == digits)
}

/// The connection, the JetStream context and the bucket (`None`: it does not exist yet).
struct Opened {
    js: jetstream::Context,
    store: Option<kv::Store>,
    violations: Arc<Mutex<Vec<String>>>,
    /// The bucket was made by this call.
    created: bool,
}

/// Connect and open the channel's bucket; `create`: make it when missing (the operator's
/// commands that publish; with the replicas of the URL).
async fn open(url: Url, create: bool) -> Result<Opened, Failure> {
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
fn denied(url: &Url, text: &str) -> String {
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

/// The revisions of every rollout in the bucket, in order.
async fn revisions(store: &kv::Store) -> Result<Vec<u64>, String> {
    numbered_keys(store, revision_of).await
}

/// The revisions of every key `of` reads a revision from, in order.
async fn numbered_keys(store: &kv::Store, of: fn(&str) -> Option<u64>) -> Result<Vec<u64>, String> {
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
async fn key_names(store: &kv::Store) -> Result<Vec<String>, String> {
    let bad = |e: &dyn std::fmt::Display| format!("cannot list the spec channel's keys: {e}");
    let mut subjects = store
        .stream
        .info_with_subjects(format!("{}>", store.prefix))
        .await
        .map_err(|e| bad(&e))?;
    let mut out = Vec::new();
    while let Some(s) = subjects.next().await {
        let (subject, _) = s.map_err(|e| bad(&e))?;
        if let Some(k) = subject.strip_prefix(store.prefix.as_str()) {
            out.push(k.to_string());
        }
    }
    Ok(out)
}

/// The rollout stored as `rollout.<revision>`, checked: its record read, its revision the key's,
/// its signature by a trusted key, and its bundle (fetched) hashing to its digest.
async fn arrival(store: &kv::Store, revision: u64, value: &[u8], trust: &[String]) -> Arrival {
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
                },
                bundle: Err(why.clone()),
            };
        }
    };
    let stored_as = rollout.revision;
    rollout.revision = revision;
    let bundle = if stored_as != revision {
        Err(format!(
            "it says it is revision {stored_as} but is stored as {}: a rollout copied from elsewhere",
            rollout_key(revision)
        ))
    } else {
        match record.verify(trust) {
            Err(why) => Err(why),
            Ok(()) => fetch_bundle(store, &rollout).await,
        }
    };
    Arrival { rollout, bundle }
}

/// The bundle of a verified rollout, checked against its digest (the `base` marker has none: an
/// empty bundle).
async fn fetch_bundle(store: &kv::Store, r: &Rollout) -> Result<Bundle, String> {
    if r.id == BASE {
        if !r.digest.is_empty() {
            return Err(
                "it names the base version (the spec each process started with) with a digest"
                    .into(),
            );
        }
        return Ok(Bundle {
            files: Vec::new(),
            links: Vec::new(),
        });
    }
    if r.digest.len() != 64 || !r.digest.starts_with(&r.id) || r.id.len() != 12 {
        return Err(format!(
            "its version id {} is not the first 12 digits of its digest {}",
            r.id, r.digest
        ));
    }
    let key = bundle_key(&r.id);
    let bytes = match store.get(key.as_str()).await {
        Ok(Some(b)) => b,
        Ok(None) => return Err(format!("its bundle {key} is not in the spec channel")),
        Err(e) => return Err(format!("its bundle {key} cannot be read: {e}")),
    };
    let bundle: Bundle = serde_json::from_slice(&bytes)
        .map_err(|e| format!("its bundle {key} is not a spec bundle: {e}"))?;
    let digest = bundle.digest();
    if digest != r.digest {
        return Err(format!(
            "its bundle {key} does not hash to the digest the rollout was signed with (it hashes \
             to {digest}): the bundle was changed after publishing"
        ));
    }
    Ok(bundle)
}

/// The decision stored as `decision.<revision>`, checked: its record read, signed by a trusted
/// key, and for the revision its key names.
fn decision_of(revision: u64, value: &[u8], trust: &[String]) -> Result<Decision, String> {
    let record = Record::<Decision>::parse(value);
    let d = record.body.clone()?;
    record.verify(trust)?;
    if d.revision != revision {
        return Err(format!(
            "it says it decides revision {} but is stored as {}",
            d.revision,
            decision_key(revision)
        ));
    }
    Ok(d)
}

/// Every rollout and decision so far, checked, in revision order (each decision before its
/// rollout).
async fn read_all(store: &kv::Store, trust: &[String]) -> Result<Vec<Event>, String> {
    let mut out = Vec::new();
    for r in numbered_keys(store, decided_revision_of).await? {
        let key = decision_key(r);
        match store.entry(key.as_str()).await {
            Ok(Some(e)) if e.operation == kv::Operation::Put => out.push(Event::Decision {
                revision: r,
                decision: decision_of(r, &e.value, trust),
            }),
            Ok(_) => {}
            Err(e) => return Err(format!("cannot read {key} from the spec channel: {e}")),
        }
    }
    for r in revisions(store).await? {
        let key = rollout_key(r);
        match store.entry(key.as_str()).await {
            Ok(Some(e)) if e.operation == kv::Operation::Put => {
                out.push(Event::Proposal(arrival(store, r, &e.value, trust).await));
            }
            Ok(_) => {}
            Err(e) => return Err(format!("cannot read {key} from the spec channel: {e}")),
        }
    }
    Ok(out)
}

/// How long one reading of the channel at start may take before it is tried again.
const READ_PATIENCE: Duration = Duration::from_secs(10);

/// [`read_all`] with a bound: a listing the server leaves unfinished (its consumer stalled) is
/// started again, at most three times in all, then it is an error: a process never hangs
/// silently at start.
async fn read_patiently(store: &kv::Store, trust: &[String]) -> Result<Vec<Event>, String> {
    for attempt in 1..=3 {
        match tokio::time::timeout(READ_PATIENCE, read_all(store, trust)).await {
            Ok(got) => return got,
            Err(_) => log_warn!(
                "spec: reading the spec channel's rollouts took over {} s (try {attempt} of 3); reading again",
                READ_PATIENCE.as_secs()
            ),
        }
    }
    Err(format!(
        "its rollouts could not be read within {} s, three times; is the server overloaded?",
        READ_PATIENCE.as_secs()
    ))
}

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

/// A rollout as `spec list` shows it: read from its key, with its signer (not checked: the
/// operator's command has no trust list; the processes check).
#[derive(Debug, Clone)]
pub struct Listed {
    pub revision: u64,
    pub rollout: Result<Rollout, String>,
    pub signer: Option<String>,
    /// When the server stored it (ns since the Unix epoch, the server's clock).
    pub written: i64,
}

/// A decision as the operator's command reads it (its signature not checked: `Err` only when
/// it cannot be read), with its signer.
#[derive(Debug, Clone)]
pub struct Decided {
    pub revision: u64,
    pub decision: Result<Decision, String>,
    pub signer: Option<String>,
}

/// When the server stored `e` (ns since the Unix epoch): a clock every reader shares.
fn server_ns(e: &kv::Entry) -> i64 {
    i64::try_from(e.created.unix_timestamp_nanos()).unwrap_or(i64::MAX)
}

/// A status key as `spec status` reads it: its name and the status (`Err`: why it cannot be
/// read).
#[derive(Debug, Clone)]
pub struct Reported {
    pub key: String,
    pub status: Result<Status, String>,
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
                    Err(e) => return Err(format!("cannot read {key}: {e}")),
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
                            .map_err(|e| format!("not a status: {e}"));
                        out.push(Reported {
                            key: k,
                            status: s,
                            written: server_ns(&e),
                        });
                    }
                    Ok(_) => {}
                    Err(e) => return Err(format!("cannot read {k}: {e}")),
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
                    Err(e) => return Err(format!("cannot read {key}: {e}")),
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
    ) -> Result<Option<Result<Decision, String>>, Failure> {
        let Some(store) = self.store.clone() else {
            return Err(Failure::Io(format!(
                "spec channel {}: no bucket",
                self.url.shown()
            )));
        };
        let bytes = sign::seal(decision, key).map_err(Failure::Config)?;
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
                    Ok(Some(v)) => Ok(Some(Record::<Decision>::parse(&v).body)),
                    Ok(None) => Ok(Some(Err(format!("{k} vanished while it was read")))),
                    Err(e) => Err(self.failure("reading the decision", e)),
                }
            }
            Err(e) => Err(self.refused(&k, e)),
        }
    }

    /// Check that the bundle of `r` is in the channel and hashes to its digest (a rollback
    /// publishes an earlier version again).
    pub fn check_bundle(&self, r: &Rollout) -> Result<(), String> {
        let Some(store) = self.store.clone() else {
            return Err("the spec channel has no bucket".into());
        };
        let r = r.clone();
        match self.run(async move { fetch_bundle(&store, &r).await.map(|_| ()) }) {
            Ok(x) => x,
            Err(f) => Err(f.message().to_string()),
        }
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
            let bytes = sign::seal(&rollout, key).map_err(Failure::Config)?;
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
        let e = parse_url("nats://a/b?lease=p0").unwrap_err();
        assert!(e.contains("lease="), "{e}");
        let e = parse_url("nats://u:Secr3t@a/b?x=1").unwrap_err();
        assert!(e.contains("spec channel") && !e.contains("Secr3t"), "{e}");
        assert!(parse_url("/a/file").is_err());
    }

    #[test]
    fn keys_name_revisions_and_processes() {
        assert_eq!(revision_of("rollout.12"), Some(12));
        assert_eq!(revision_of("rollout.0"), None);
        assert_eq!(revision_of("rollout.x"), None);
        assert_eq!(revision_of("rollout.012"), None);
        assert_eq!(revision_of("rollout.+1"), None);
        assert_eq!(revision_of("bundle.12"), None);
        assert_eq!(status_key("h.1", "p0", 7), "status.vh_2e1.vp0.pid7");
        assert_eq!(status_key("h", "", 7), "status.vh.pid7");
        // A primary and its standby on one host: two keys.
        assert_ne!(status_key("h", "p0", 7), status_key("h", "p0", 8));
    }
}
