//! `--state nats://HOST:PORT[,HOST:PORT...]/BUCKET[?options]`: monitor state in a JetStream
//! key-value bucket, shared by the processes of a fleet, and the partition lease.
//!
//! Owns: parsing the URL ([`Url`]), the connection (async-nats on a runtime thread of its own,
//! so lease renewals go on while the step loop is busy), bucket creation, instance keys as NATS
//! KV keys ([`kv_key`]), one entry per instance (the format of [`super::state`]: magic, version,
//! fingerprint), restoring an instance when its first record arrives, saving every instance,
//! setting a foreign or corrupt entry aside (`aside.<key>.<unix seconds>`, with a warning), and
//! the lease ([`Lease`]): one key per partition, held by one process at a time (create if absent,
//! renewed by compare-and-set on its revision, taken over by compare-and-set when it has not
//! changed for the lease TTL, deleted on a clean stop). The design and its guarantees are in
//! `docs/state-and-reload.md` ("Shared state on NATS").

use super::instances::Key;
use super::processor::Processor;
use super::state::{self, Backend, Context};
use crate::log::{self, Level};
use async_nats::jetstream::{self, kv, stream};
use std::collections::HashSet;
use std::future::Future;
use std::io;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Default lease TTL: a standby takes over this long after the holder's last renewal.
pub const DEFAULT_TTL: Duration = Duration::from_secs(3);
/// How long any one request to NATS may take.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(2);

/// A parsed `--state nats://...` value.
#[derive(Debug, Clone, PartialEq)]
pub struct Url {
    /// `host:port`, tried in order (the client reconnects to any of them).
    pub servers: Vec<String>,
    pub bucket: String,
    /// `?lease=NAME`: the partition this process serves; one process at a time holds it.
    pub lease: Option<String>,
    /// `?ttl=3s`: the lease TTL.
    pub ttl: Duration,
    /// `?replicas=3`: replicas of the bucket when this process creates it.
    pub replicas: usize,
}

impl Url {
    pub fn parse(s: &str) -> Result<Url, String> {
        let rest = s
            .strip_prefix("nats://")
            .ok_or_else(|| format!("`{s}`: expected nats://HOST:PORT/BUCKET"))?;
        let (rest, query) = rest.split_once('?').unwrap_or((rest, ""));
        let (hosts, bucket) = rest
            .split_once('/')
            .ok_or_else(|| format!("`{s}`: no bucket (expected nats://HOST:PORT/BUCKET)"))?;
        let servers: Vec<String> = hosts
            .split(',')
            .map(str::trim)
            .filter(|h| !h.is_empty())
            .map(|h| {
                if h.contains(':') {
                    h.to_string()
                } else {
                    format!("{h}:4222")
                }
            })
            .collect();
        if servers.is_empty() {
            return Err(format!("`{s}`: no server"));
        }
        if bucket.is_empty()
            || !bucket
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err(format!(
                "`{s}`: bucket `{bucket}` must be letters, digits, `_` or `-`"
            ));
        }
        let mut url = Url {
            servers,
            bucket: bucket.to_string(),
            lease: None,
            ttl: DEFAULT_TTL,
            replicas: 1,
        };
        for pair in query.split('&').filter(|p| !p.is_empty()) {
            let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
            match k {
                "lease" if !v.is_empty() => url.lease = Some(v.to_string()),
                "ttl" => {
                    url.ttl = humantime::parse_duration(v)
                        .map_err(|e| format!("`{s}`: ttl `{v}`: {e}"))?;
                    if url.ttl < Duration::from_millis(200) {
                        return Err(format!("`{s}`: ttl must be at least 200ms"));
                    }
                }
                "replicas" => {
                    url.replicas = v
                        .parse()
                        .ok()
                        .filter(|n| (1..=5).contains(n))
                        .ok_or_else(|| format!("`{s}`: replicas must be 1 to 5"))?;
                }
                _ => {
                    return Err(format!(
                        "`{s}`: unknown option `{pair}` (known: lease=NAME, ttl=DURATION, replicas=N)"
                    ));
                }
            }
        }
        Ok(url)
    }

    fn shown(&self) -> String {
        format!("nats://{}/{}", self.servers.join(","), self.bucket)
    }
}

/// One value of an instance key as NATS KV key characters: letters, digits and `-` as they
/// are, any other byte as `_` and two hex digits; `v` before a present value, `n` for an
/// absent tag. Injective, so two instances never share an entry.
fn key_part(v: &Option<String>, out: &mut String) {
    match v {
        None => out.push('n'),
        Some(s) => {
            out.push('v');
            for b in s.bytes() {
                if b.is_ascii_alphanumeric() || b == b'-' {
                    out.push(char::from(b));
                } else {
                    out.push_str(&format!("_{b:02x}"));
                }
            }
        }
    }
}

/// The KV key of instance `key`: `i.` and one part per `--instance-by` tag, joined by `.`.
pub fn kv_key(key: &Key) -> String {
    let mut s = String::from("i");
    for v in key {
        s.push('.');
        key_part(v, &mut s);
    }
    s
}

/// The runtime thread that owns the connection; requests are sent to it and waited for.
struct Conn {
    handle: tokio::runtime::Handle,
    _stop: tokio::sync::oneshot::Sender<()>,
}

impl Conn {
    fn start() -> io::Result<Conn> {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        let handle = rt.handle().clone();
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        std::thread::Builder::new()
            .name("nats".into())
            .spawn(move || {
                rt.block_on(async {
                    // Drives the runtime until `Conn` is dropped (the sender's drop is the
                    // stop signal, so the receiver's error is the expected ending).
                    stopped.await.ok();
                });
            })?;
        Ok(Conn {
            handle,
            _stop: stop,
        })
    }

    /// Run `f` on the connection's thread and wait for it (blocks the calling thread).
    fn call<T: Send + 'static>(&self, f: impl Future<Output = T> + Send + 'static) -> Option<T> {
        let (tx, rx) = std::sync::mpsc::channel();
        self.handle.spawn(async move {
            let _ = tx.send(f.await);
        });
        rx.recv().ok()
    }
}

fn err(e: impl std::fmt::Display) -> io::Error {
    io::Error::other(e.to_string())
}

/// Connect and open (or create) the bucket.
async fn open(url: Url) -> Result<kv::Store, String> {
    let client = async_nats::ConnectOptions::new()
        .request_timeout(Some(REQUEST_TIMEOUT))
        .connection_timeout(REQUEST_TIMEOUT)
        .retry_on_initial_connect()
        .connect(url.servers.clone())
        .await
        .map_err(|e| format!("cannot connect to {}: {e}", url.servers.join(",")))?;
    let js = jetstream::new(client.clone());
    // Processes of a fleet start together: another may be creating the bucket right now, and
    // a bucket just created may take a moment to answer everywhere. Try a few times.
    let mut last = String::new();
    for attempt in 0..5u32 {
        if attempt > 0 {
            tokio::time::sleep(Duration::from_millis(300) * attempt).await;
        }
        if let Ok(store) = js.get_key_value(url.bucket.clone()).await {
            return Ok(store);
        }
        if client.connection_state() != async_nats::connection::State::Connected {
            return Err(format!(
                "cannot connect to {}: no server answered (is nats-server running there?)",
                url.servers.join(",")
            ));
        }
        match create(&js, &url).await {
            Ok(store) => return Ok(store),
            Err(e) => last = e,
        }
    }
    Err(last)
}

async fn create(js: &jetstream::Context, url: &Url) -> Result<kv::Store, String> {
    // The bucket as `nats kv add` makes it, except that reads go to the stream leader
    // (allow_direct off): a process taking over must see every entry its predecessor wrote.
    let config = stream::Config {
        name: format!("KV_{}", url.bucket),
        subjects: vec![format!("$KV.{}.>", url.bucket)],
        max_messages_per_subject: 1,
        num_replicas: url.replicas,
        discard: stream::DiscardPolicy::New,
        allow_rollup: true,
        deny_delete: true,
        allow_direct: false,
        ..Default::default()
    };
    js.get_or_create_stream(config)
        .await
        .map_err(|e| format!("cannot create bucket {}: {e}", url.bucket))?;
    js.get_key_value(url.bucket.clone())
        .await
        .map_err(|e| format!("cannot open bucket {}: {e}", url.bucket))
}

/// The bucket backend of `--state nats://...`.
pub struct NatsBackend {
    url: Url,
    conn: Conn,
    store: kv::Store,
    fingerprint: String,
    /// Instances already looked up (or created) in this process: not restored again.
    seen: HashSet<Key>,
}

impl NatsBackend {
    /// Connect (waiting for the servers as long as it takes, as Telegraf restarts us anyway).
    pub fn connect(url: &Url, proc: &Processor, ctx: &Context) -> Result<NatsBackend, String> {
        let conn = Conn::start().map_err(|e| format!("cannot start the NATS thread: {e}"))?;
        let store = conn
            .call(open(url.clone()))
            .ok_or_else(|| "the NATS thread stopped".to_string())??;
        Ok(NatsBackend {
            url: url.clone(),
            conn,
            store,
            fingerprint: state::fingerprint(proc.program(), ctx),
            seen: HashSet::new(),
        })
    }

    /// Start holding (or waiting for) the lease named in the URL, if any.
    pub fn lease(&self) -> Option<Lease> {
        let name = self.url.lease.clone()?;
        let shared = Arc::new(Mutex::new(LeaseState {
            mode: Mode::Standby,
            lost: false,
            released: false,
        }));
        let lease = Lease {
            shared: Arc::clone(&shared),
            name: name.clone(),
            ttl: self.url.ttl,
            store: self.store.clone(),
            handle: self.conn.handle.clone(),
        };
        let holder = format!("{}:{}", hostname(), std::process::id());
        let key = format!("lease.{}", kv_key_part_of(&name));
        // The first attempt before any record is read: a lone process starts active.
        let (store, k, h, ttl) = (
            self.store.clone(),
            key.clone(),
            holder.clone(),
            self.url.ttl,
        );
        let sent = Instant::now();
        let first = self.conn.call(async move {
            let mut seen = None;
            let taken = try_take(&store, &k, &h, ttl, &mut seen).await;
            (taken, seen)
        });
        let (taken, seen) = first.unwrap_or((None, None));
        let holding = taken.is_some();
        if let (Some(revision), Ok(mut s)) = (taken, shared.lock()) {
            s.mode = Mode::Active {
                revision,
                renewed: sent,
            };
        }
        log::log(
            Level::Info,
            &format!(
                "lease: partition {name}: {}",
                if holding {
                    format!("held by this process ({holder})")
                } else {
                    format!(
                        "held by another process; standing by until it is released or lapses for {}",
                        humantime::format_duration(self.url.ttl)
                    )
                }
            ),
        );
        self.conn.handle.spawn(lease_task(
            self.store.clone(),
            key,
            holder,
            self.url.ttl,
            shared,
            seen,
        ));
        Some(lease)
    }

    /// Put `bytes` aside as `aside.<key>.<unix seconds>` and delete `key`'s entry.
    fn set_aside(&self, key: &str, bytes: bytes::Bytes) -> Option<String> {
        let aside = format!("aside.{key}.{}", state::unix_now());
        let store = self.store.clone();
        let (k, a) = (key.to_string(), aside.clone());
        let ok = self.conn.call(async move {
            store.put(&a, bytes).await.is_ok() && store.delete(&k).await.is_ok()
        });
        (ok == Some(true)).then_some(aside)
    }
}

fn kv_key_part_of(name: &str) -> String {
    let mut s = String::new();
    key_part(&Some(name.to_string()), &mut s);
    s
}

fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|_| "host".into())
}

impl Backend for NatsBackend {
    fn describe(&self) -> String {
        self.url.shown()
    }

    /// Nothing is read at start: each instance is read when its first record arrives.
    fn load(&mut self, _proc: &mut Processor) {
        log::log(
            Level::Info,
            &format!(
                "state: using bucket {}; each instance is restored from it when its first record arrives",
                self.url.shown()
            ),
        );
    }

    fn arriving(&mut self, key: &Key, proc: &mut Processor) {
        if self.seen.contains(key) {
            return;
        }
        self.seen.insert(key.clone());
        let name = kv_key(key);
        let store = self.store.clone();
        let k = name.clone();
        let got = self.conn.call(async move { store.entry(k).await });
        let entry = match got {
            Some(Ok(Some(e))) if e.operation == kv::Operation::Put => e,
            Some(Ok(_)) => return,
            Some(Err(e)) => {
                log::log(
                    Level::Warn,
                    &format!(
                        "state: cannot read {name} from {}: {e}; the instance starts fresh",
                        self.url.shown()
                    ),
                );
                return;
            }
            None => return,
        };
        match state::check_entry(&entry.value, proc.program(), &self.fingerprint, key) {
            Ok(monitor) => {
                log::log(
                    Level::Debug,
                    &format!("state: restored {name} from {}", self.url.shown()),
                );
                proc.restore_instance(key.clone(), monitor);
            }
            Err(why) => {
                let aside = self.set_aside(&name, entry.value);
                log::log(
                    Level::Warn,
                    &format!(
                        "state: {name} in {} not used: {why}; {}; the instance starts fresh",
                        self.url.shown(),
                        match aside {
                            Some(a) => format!("put aside as {a}"),
                            None => "could not put it aside".into(),
                        }
                    ),
                );
            }
        }
    }

    fn save(&mut self, proc: &Processor) -> io::Result<usize> {
        let program = proc.program();
        let mut unsaved = 0;
        let entries: Vec<(String, bytes::Bytes)> = proc
            .monitors()
            .map(|(key, m)| {
                let (bytes, u) = state::encode_entry(program, &self.fingerprint, key, m);
                unsaved += u;
                (kv_key(key), bytes::Bytes::from(bytes))
            })
            .collect();
        if unsaved > 0 {
            log::log(
                Level::Warn,
                &format!(
                    "state: {unsaved} stream values are functions and cannot be saved; those streams restart empty"
                ),
            );
        }
        let n = entries.len();
        let store = self.store.clone();
        let result = self.conn.call(async move {
            // Up to 64 puts in flight at once.
            let mut set = tokio::task::JoinSet::new();
            let mut first_error = None;
            for (k, v) in entries {
                if set.len() >= 64
                    && let Some(Ok(Err(e))) = set.join_next().await
                {
                    first_error.get_or_insert(e);
                }
                let s = store.clone();
                set.spawn(async move { s.put(k, v).await.map(|_| ()) });
            }
            while let Some(r) = set.join_next().await {
                if let Ok(Err(e)) = r {
                    first_error.get_or_insert(e);
                }
            }
            first_error
        });
        match result {
            Some(None) => Ok(n),
            Some(Some(e)) => Err(err(e)),
            None => Err(err("the NATS thread stopped")),
        }
    }

    fn forget(&mut self) {
        self.seen.clear();
    }
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
}

/// A partition lease: at most one process of the partition's group steps its monitors.
pub struct Lease {
    shared: Arc<Mutex<LeaseState>>,
    pub name: String,
    ttl: Duration,
    store: kv::Store,
    handle: tokio::runtime::Handle,
}

impl Lease {
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

    /// Whether the lease went to another process since the last call.
    pub fn take_lost(&self) -> bool {
        self.shared
            .lock()
            .map(|mut s| std::mem::take(&mut s.lost))
            .unwrap_or(false)
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
            Ok(Ok(())) => log::log(
                Level::Info,
                &format!("lease: released partition {}", self.name),
            ),
            Ok(Err(e)) => log::log(
                Level::Warn,
                &format!(
                    "lease: cannot release partition {}: {e}; the standby takes over after the TTL",
                    self.name
                ),
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
                        log::log(
                            Level::Warn,
                            &format!("lease: {key} was taken over by another process; standing by"),
                        );
                        s.mode = Mode::Standby;
                        s.lost = true;
                        seen = None;
                    }
                    Err(e) => log::log(
                        Level::Warn,
                        &format!("lease: cannot renew {key}: {e}; retrying"),
                    ),
                }
            }
            Mode::Standby => {
                tokio::time::sleep(poll_every).await;
                let sent = Instant::now();
                let taken = try_take(&store, &key, &holder, ttl, &mut seen).await;
                if let Some(revision) = taken {
                    let Ok(mut s) = shared.lock() else { return };
                    s.mode = Mode::Active {
                        revision,
                        renewed: sent,
                    };
                    log::log(Level::Info, &format!("lease: {key} taken by {holder}"));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_parse_with_their_options() {
        let u = Url::parse("nats://a:1,b:2/state?lease=p0&ttl=2s&replicas=3").unwrap();
        assert_eq!(u.servers, ["a:1", "b:2"]);
        assert_eq!(u.bucket, "state");
        assert_eq!(u.lease.as_deref(), Some("p0"));
        assert_eq!(u.ttl, Duration::from_secs(2));
        assert_eq!(u.replicas, 3);
        let u = Url::parse("nats://host/b").unwrap();
        assert_eq!(u.servers, ["host:4222"]);
        assert_eq!((u.lease, u.ttl, u.replicas), (None, DEFAULT_TTL, 1));
        for bad in [
            "nats://a:1",
            "nats:///b",
            "nats://a/b.c",
            "nats://a/b?x=1",
            "nats://a/b?ttl=1ms",
            "nats://a/b?replicas=9",
        ] {
            assert!(Url::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn keys_are_valid_nats_keys_and_distinct() {
        let ok = |s: &str| {
            !s.is_empty()
                && !s.starts_with('.')
                && !s.ends_with('.')
                && s.bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b"-/_=.".contains(&b))
        };
        let keys: Vec<Key> = vec![
            vec![Some("robot1".into())],
            vec![Some("tessla/robot1".into())],
            vec![Some("tessla_2frobot1".into())],
            vec![Some(String::new())],
            vec![None],
            vec![Some("a.b".into()), None],
            vec![Some("a".into()), Some("b".into())],
            vec![Some("ä *>".into())],
            vec![],
        ];
        let encoded: HashSet<String> = keys.iter().map(kv_key).collect();
        assert_eq!(encoded.len(), keys.len());
        assert!(encoded.iter().all(|k| ok(k)), "{encoded:?}");
        assert_eq!(
            kv_key(&vec![Some("tessla/robot1".into())]),
            "i.vtessla_2frobot1"
        );
    }
}
