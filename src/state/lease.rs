//! The partition lease ([`Lease`]): one key per partition in the state bucket, held by one
//! process at a time (created if absent, renewed by compare-and-set on its revision, taken over
//! by compare-and-set when it has not changed for the lease TTL, deleted on a clean stop), with
//! the operator mistakes caught: a lease live in another bucket refuses the start, a long
//! standby reports partitions nobody holds.

use crate::nats::conn::{Conn, REQUEST_TIMEOUT, hostname};
use crate::nats::kv_keys::{kv_key_part_of, partition_of};
use async_nats::jetstream::{self, kv};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Another KV bucket of the account where `key` (a lease) is live: present and renewed within
/// the TTL (its revision changes while watched). `None` also when the account may not list
/// streams (the shipped permissions allow one bucket only, which rules the mistake out).
pub(super) async fn lease_elsewhere(
    js: jetstream::Context,
    own: String,
    key: String,
    ttl: Duration,
) -> Option<(String, String)> {
    use futures_util::StreamExt;
    let names: Vec<String> = tokio::time::timeout(REQUEST_TIMEOUT * 2, async {
        js.stream_names()
            .filter_map(|n| async move { n.ok() })
            .collect::<Vec<String>>()
            .await
    })
    .await
    .ok()?;
    for bucket in names
        .iter()
        .filter_map(|n| n.strip_prefix("KV_"))
        .filter(|b| *b != own)
    {
        let Ok(store) = js.get_key_value(bucket).await else {
            continue;
        };
        let Ok(Some(first)) = store.entry(&key).await else {
            continue;
        };
        if first.operation != kv::Operation::Put {
            continue;
        }
        // A holder renews every TTL/4: a live lease changes within half a TTL.
        tokio::time::sleep(ttl / 2).await;
        if let Ok(Some(second)) = store.entry(&key).await
            && second.operation == kv::Operation::Put
            && second.revision != first.revision
        {
            return Some((
                bucket.to_string(),
                String::from_utf8_lossy(&second.value).into_owned(),
            ));
        }
    }
    None
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    /// Waiting for the lease.
    Standby,
    /// Holding it at `revision`; the last renewal that succeeded was sent at `renewed`.
    Active { revision: u64, renewed: Instant },
}

struct LeaseState {
    mode: Mode,
    /// The lease went to another process since the last [`Lease::take_lost`].
    lost: bool,
    /// Released on a clean stop: the task ends.
    released: bool,
    /// The revision at which this process last took the lease: its generation (the fleet
    /// level keys what a partition sends by it, docs/fleet.md).
    generation: u64,
}

/// A partition lease: at most one process of the partition's group steps its monitors.
pub struct Lease {
    shared: Arc<Mutex<LeaseState>>,
    pub name: String,
    ttl: Duration,
    store: kv::Store,
    handle: tokio::runtime::Handle,
    /// This process's name in the lease key (`host:pid`).
    holder: String,
}

impl Lease {
    /// Start holding (or waiting for) the lease of partition `name` in the bucket `store`: one
    /// attempt now (a lone process starts active), then a task on the connection's thread
    /// renews or waits for it.
    pub(crate) fn start(conn: &Conn, store: &kv::Store, name: String, ttl: Duration) -> Lease {
        let key = format!("lease.{}", kv_key_part_of(&name));
        let shared = Arc::new(Mutex::new(LeaseState {
            mode: Mode::Standby,
            lost: false,
            released: false,
            generation: 0,
        }));
        let holder = format!("{}:{}", hostname(), std::process::id());
        let lease = Lease {
            shared: Arc::clone(&shared),
            name: name.clone(),
            ttl,
            store: store.clone(),
            handle: conn.handle.clone(),
            holder: holder.clone(),
        };
        // The first attempt before any record is read: a lone process starts active.
        let (first_store, k, h) = (store.clone(), key.clone(), holder.clone());
        let sent = Instant::now();
        let first = conn.call(async move {
            let mut seen = None;
            let taken = try_take(&first_store, &k, &h, ttl, &mut seen).await;
            (taken, seen)
        });
        let (taken, seen) = first.unwrap_or((None, None));
        let holding = taken.is_some();
        if let (Some(revision), Ok(mut s)) = (taken, shared.lock()) {
            s.generation = revision;
            s.mode = Mode::Active {
                revision,
                renewed: sent,
            };
        }
        log_info!(
            "lease: partition {name}: {}",
            if holding {
                format!("held by this process ({holder})")
            } else {
                format!(
                    "held by another process; standing by until it is released or lapses for {}",
                    humantime::format_duration(ttl)
                )
            }
        );
        conn.handle
            .spawn(lease_task(store.clone(), key, holder, ttl, shared, seen));
        lease
    }

    /// Whether this process may step its monitors now: it holds the lease and its last successful
    /// renewal was *sent* less than half the TTL ago. A standby takes over only when the
    /// lease revision it sees has not changed for a whole TTL, so the two never overlap while
    /// both clocks run at the same rate (see the docs for pauses).
    pub fn holding(&self) -> bool {
        let Ok(s) = self.shared.lock() else {
            return false;
        };
        match s.mode {
            Mode::Active { renewed, .. } => renewed.elapsed() < self.ttl / 2,
            Mode::Standby => false,
        }
    }

    /// The lease's generation while this process holds it (the bucket revision at which it took
    /// it: a later holder's is higher); `None` while not holding.
    pub fn generation(&self) -> Option<u64> {
        if !self.holding() {
            return None;
        }
        self.shared.lock().ok().map(|s| s.generation)
    }

    /// Whether the lease went to another process since the last call.
    pub fn take_lost(&self) -> bool {
        self.shared
            .lock()
            .map(|mut s| std::mem::take(&mut s.lost))
            .unwrap_or(false)
    }

    /// The lease key's entry as the server has it now (`Some(None)`: absent); `None` when the
    /// server does not answer in time.
    fn key_now(&self) -> Option<Option<kv::Entry>> {
        let store = self.store.clone();
        let key = format!("lease.{}", kv_key_part_of(&self.name));
        let (tx, rx) = std::sync::mpsc::channel();
        self.handle.spawn(async move {
            let _ = tx.send(store.entry(key).await);
        });
        match rx.recv_timeout(REQUEST_TIMEOUT * 2) {
            Ok(Ok(e)) => Some(e),
            _ => None,
        }
    }

    /// Whether nobody holds the lease now: its key absent or deleted (released on a clean
    /// stop). A lease whose holder died is not free until it lapses; unknown (the server does
    /// not answer in time) is not free either.
    pub fn free(&self) -> bool {
        match self.key_now() {
            Some(None) => true,
            Some(Some(e)) => e.operation != kv::Operation::Put,
            None => false,
        }
    }

    /// The lease's TTL.
    pub fn ttl(&self) -> Duration {
        self.ttl
    }

    /// The lease key as the server has it now: its revision (every renewal changes it) and
    /// whether this process wrote it; `None` when absent, deleted (released) or not known (the
    /// server does not answer in time).
    pub fn current(&self) -> Option<(u64, bool)> {
        match self.key_now() {
            Some(Some(e)) if e.operation == kv::Operation::Put => {
                Some((e.revision, e.value.as_ref() == self.holder.as_bytes()))
            }
            _ => None,
        }
    }

    /// Give the lease up (after the last save), so a standby takes over at once.
    pub fn release(&self) {
        let revision = match self.shared.lock() {
            Ok(mut s) => {
                s.released = true;
                match s.mode {
                    Mode::Active { revision, .. } => Some(revision),
                    Mode::Standby => None,
                }
            }
            Err(_) => None,
        };
        let Some(revision) = revision else {
            return;
        };
        let store = self.store.clone();
        let key = format!("lease.{}", kv_key_part_of(&self.name));
        let (tx, rx) = std::sync::mpsc::channel();
        self.handle.spawn(async move {
            let _ = tx.send(store.delete_expect_revision(key, Some(revision)).await);
        });
        match rx.recv_timeout(REQUEST_TIMEOUT * 2) {
            Ok(Ok(())) => log_info!("lease: released partition {}", self.name),
            Ok(Err(e)) => log_warn!(
                "lease: cannot release partition {}: {e}; the standby takes over after the TTL",
                self.name
            ),
            Err(_) => {}
        }
    }
}

/// One attempt of a standby to take the lease: when absent or deleted, or when its revision
/// has not changed for `ttl` since `seen` noted it. Returns the new revision when taken.
async fn try_take(
    store: &kv::Store,
    key: &str,
    holder: &str,
    ttl: Duration,
    seen: &mut Option<(u64, Instant)>,
) -> Option<u64> {
    let value = || bytes::Bytes::from(holder.to_string());
    match store.entry(key).await {
        Ok(None) => store.create(key, value()).await.ok(),
        Ok(Some(e)) if e.operation != kv::Operation::Put => {
            store.update(key, value(), e.revision).await.ok()
        }
        Ok(Some(e)) => match *seen {
            Some((r, since)) if r == e.revision && since.elapsed() >= ttl => {
                store.update(key, value(), e.revision).await.ok()
            }
            Some((r, _)) if r == e.revision => None,
            _ => {
                *seen = Some((e.revision, Instant::now()));
                None
            }
        },
        Err(_) => None,
    }
}

/// Every lease of the bucket: key -> (revision, whether it is live: a put, not a delete).
async fn leases(store: &kv::Store) -> Option<std::collections::HashMap<String, (u64, bool)>> {
    use futures_util::StreamExt;
    let mut watch = store.watch_with_history("lease.>").await.ok()?;
    let mut out = std::collections::HashMap::new();
    // The bucket keeps one entry per key: the history is the current entries, then the watch
    // waits for changes (`delta` 0 marks the last one pending; none at all: no lease yet).
    while let Ok(Some(Ok(e))) = tokio::time::timeout(REQUEST_TIMEOUT, watch.next()).await {
        out.insert(
            e.key.clone(),
            (e.revision, e.operation == kv::Operation::Put),
        );
        if e.delta == 0 {
            break;
        }
    }
    Some(out)
}

/// For a process standing by a long time: the partitions whose lease nobody holds (released,
/// or not renewed for a TTL). Such a partition next to a long standby is the sign of a process
/// given another partition's lease name: its own partition's robots get no actions.
async fn report_standby(store: kv::Store, own: String, ttl: Duration, since: Instant) {
    let Some(before) = leases(&store).await else {
        return;
    };
    tokio::time::sleep(ttl).await;
    let Some(after) = leases(&store).await else {
        return;
    };
    let mut free: Vec<String> = after
        .iter()
        .filter(|(k, (revision, live))| {
            **k != own && (!*live || before.get(*k).is_some_and(|(r, _)| r == revision))
        })
        .map(|(k, _)| partition_of(k))
        .collect();
    free.sort();
    let waited = humantime::format_duration(Duration::from_secs(since.elapsed().as_secs()));
    let own_name = partition_of(&own);
    if free.is_empty() {
        log_info!(
            "lease: partition {own_name}: standing by for {waited}; its holder renews the lease"
        );
    } else {
        log_warn!(
            "lease: partition {own_name}: standing by for {waited}, while nobody holds partition(s) {}: \
                 their robots get no actions. If this Telegraf reads one of those partitions (the N in its \
                 nats_consumer subjects fleet.N.robots.*), its --state has the wrong ?lease= name",
            free.join(", ")
        );
    }
}

/// Keep the lease: renew it while held, watch it while not, take it when free or lapsed.
async fn lease_task(
    store: kv::Store,
    key: String,
    holder: String,
    ttl: Duration,
    shared: Arc<Mutex<LeaseState>>,
    // The revision a standby saw last, and since when.
    mut seen: Option<(u64, Instant)>,
) {
    let renew_every = ttl / 4;
    let poll_every = (ttl / 4).min(Duration::from_millis(100));
    // A long standby is reported (with the partitions nobody holds) after 3 TTLs, then every
    // minute (at least 20 TTLs).
    let first_report = ttl * 3;
    let report_every = (ttl * 20).max(Duration::from_secs(60));
    let mut standby_since: Option<Instant> = None;
    let mut next_report = Instant::now() + first_report;
    loop {
        let mode = match shared.lock() {
            Ok(s) if s.released => return,
            Ok(s) => s.mode,
            Err(_) => return,
        };
        match mode {
            Mode::Active { revision, .. } => {
                tokio::time::sleep(renew_every).await;
                let sent = Instant::now();
                let r = store.update(&key, holder.clone().into(), revision).await;
                let Ok(mut s) = shared.lock() else { return };
                if s.released {
                    return;
                }
                match r {
                    Ok(revision) => {
                        s.mode = Mode::Active {
                            revision,
                            renewed: sent,
                        }
                    }
                    Err(e) if e.kind() == kv::UpdateErrorKind::WrongLastRevision => {
                        log_warn!("lease: {key} was taken over by another process; standing by");
                        s.mode = Mode::Standby;
                        s.lost = true;
                        seen = None;
                    }
                    Err(e) => log_warn!("lease: cannot renew {key}: {e}; retrying"),
                }
            }
            Mode::Standby => {
                let since = *standby_since.get_or_insert_with(|| {
                    next_report = Instant::now() + first_report;
                    Instant::now()
                });
                if Instant::now() >= next_report {
                    next_report = Instant::now() + report_every;
                    tokio::spawn(report_standby(store.clone(), key.clone(), ttl, since));
                }
                tokio::time::sleep(poll_every).await;
                let sent = Instant::now();
                let taken = try_take(&store, &key, &holder, ttl, &mut seen).await;
                if let Some(revision) = taken {
                    standby_since = None;
                    let Ok(mut s) = shared.lock() else { return };
                    s.generation = revision;
                    s.mode = Mode::Active {
                        revision,
                        renewed: sent,
                    };
                    log_info!("lease: {key} taken by {holder}");
                }
            }
        }
    }
}
