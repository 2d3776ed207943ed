//! `--state nats://...`: monitor state in a JetStream key-value bucket, shared by the processes
//! of a fleet. Owns: opening the bucket (creating it when absent), one entry per instance (the format of [`super::entry`]), restoring an
//! instance when its first record arrives, saving every instance, and setting a foreign or
//! corrupt entry aside (`aside.<key>.<unix seconds>`, with a warning). The design and its
//! guarantees are in `docs/book/src/state-and-reload.md` ("Shared state on NATS").

use super::entry::Programs;
use super::lease::Lease;
use super::lease::lease_elsewhere;
use super::restore::Restorer;
use super::{Backend, Context, entry, fingerprint};
use crate::nats::conn::{Conn, Failure, connect, err, permission_failure, violation};
use crate::nats::kv_keys::kv_key;
use crate::nats::kv_keys::kv_key_part_of;
use crate::nats::url::Url;
use crate::processor::Processor;
use crate::processor::instance_table::Key;
use async_nats::jetstream::kv;
use async_nats::jetstream::{self, stream};
use std::collections::HashSet;
use std::io;
use std::time::Duration;

/// Connect and open (or create) the bucket.
async fn open(url: Url) -> Result<kv::Store, Failure> {
    let (client, violations) = connect(&url).await?;
    let js = jetstream::new(client.clone());
    // Before the bucket is looked up (or created): the partition's lease live in another bucket
    // means the processes of one partition were given different buckets; each would step the
    // partition's monitors and every action would be sent twice.
    if let Some(name) = &url.lease {
        let key = format!("lease.{}", kv_key_part_of(name));
        if let Some((bucket, holder)) =
            lease_elsewhere(js.clone(), url.bucket.clone(), key, url.ttl).await
        {
            return Err(Failure::Config(format!(
                "partition {name}'s lease is held in bucket {bucket} by {holder}, who renews it, but this \
                 process was given bucket {}: the processes of one partition must name the same bucket \
                 (in another, each would step the partition's monitors and every action would be sent \
                 twice). Fix --state of whichever is wrong; two fleets sharing a NATS account need \
                 different lease names",
                url.bucket
            )));
        }
    }
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
        if let Some(v) = violation(&violations) {
            return Err(Failure::Io(permission_failure(&url, &v)));
        }
        if client.connection_state() != async_nats::connection::State::Connected {
            return Err(Failure::Io(format!(
                "cannot connect to {}: the connection was lost (is nats-server running there?)",
                url.shown()
            )));
        }
        match create(&js, &url).await {
            Ok(store) => {
                log_info!(
                    "state: created bucket {} ({} replicas); every process of the fleet must name this bucket",
                    url.bucket,
                    url.replicas
                );
                return Ok(store);
            }
            Err(Failure::Io(e)) => last = e,
            Err(config) => return Err(config),
        }
        if let Some(v) = violation(&violations) {
            return Err(Failure::Io(permission_failure(&url, &v)));
        }
    }
    Err(Failure::Io(last))
}

/// Create the bucket of `url`. A replica count the server cannot honour (`replicas=3` on a
/// single server, not a cluster) is [`Failure::Config`] naming the URL option and the value that
/// works; any other failure is [`Failure::Io`].
pub(crate) async fn create(js: &jetstream::Context, url: &Url) -> Result<kv::Store, Failure> {
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
    js.get_or_create_stream(config).await.map_err(|e| {
        let text = e.to_string();
        if url.replicas > 1 && replicas_refused(&text) {
            Failure::Config(replicas_message(url, &text))
        } else {
            Failure::Io(format!("cannot create bucket {}: {text}", url.bucket))
        }
    })?;
    js.get_key_value(url.bucket.clone())
        .await
        .map_err(|e| Failure::Io(format!("cannot open bucket {}: {e}", url.bucket)))
}

/// Whether the server refused a bucket for its replica count (nats-server: "replicas > 1 not
/// supported in non-clustered mode").
fn replicas_refused(error: &str) -> bool {
    error.contains("non-clustered mode") || error.contains("insufficient resources")
}

/// What to write instead of the URL's `replicas=N` the server refused.
pub(crate) fn replicas_message(url: &Url, error: &str) -> String {
    format!(
        "the URL option replicas={} of {} asks for {} copies of bucket {}, which the server \
         cannot keep ({error}): a single nats-server (not a cluster) takes replicas=1; a \
         cluster takes at most its number of servers",
        url.replicas,
        url.shown(),
        url.replicas,
        url.bucket
    )
}

/// The bucket backend of `--state nats://...`.
pub struct NatsBackend {
    url: Url,
    conn: Conn,
    store: kv::Store,
    fingerprint: String,
    /// Restores each instance into the program it runs here, stream by stream.
    restorer: Restorer,
    /// Instances already looked up (or created) in this process: not restored again.
    seen: HashSet<Key>,
}

impl NatsBackend {
    /// Connect (once: an unreachable server, refused credentials, a TLS or permission failure
    /// stop the process with a message saying which; Telegraf restarts it after `restart_delay`).
    pub fn connect(url: &Url, ctx: &Context) -> Result<NatsBackend, Failure> {
        let conn =
            Conn::start().map_err(|e| Failure::Io(format!("cannot start the NATS thread: {e}")))?;
        let store = conn
            .call(open(url.clone()))
            .ok_or_else(|| Failure::Io("the NATS thread stopped".to_string()))??;
        Ok(NatsBackend {
            url: url.clone(),
            conn,
            store,
            fingerprint: fingerprint(ctx),
            restorer: Restorer::new(url.shown()),
            seen: HashSet::new(),
        })
    }

    /// Start holding (or waiting for) the lease named in the URL, if any. (A lease live in
    /// another bucket was refused by [`NatsBackend::connect`].)
    pub fn lease(&self) -> Option<Lease> {
        let name = self.url.lease.clone()?;
        Some(Lease::start(&self.conn, &self.store, name, self.url.ttl))
    }

    /// Put `bytes` aside as `aside.<key>.<unix seconds>` and delete `key`'s entry.
    fn set_aside(&self, key: &str, bytes: bytes::Bytes) -> Option<String> {
        let aside = format!("aside.{key}.{}", entry::unix_now());
        let store = self.store.clone();
        let (k, a) = (key.to_string(), aside.clone());
        let ok = self.conn.call(async move {
            store.put(&a, bytes).await.is_ok() && store.delete(&k).await.is_ok()
        });
        (ok == Some(true)).then_some(aside)
    }
}

impl Backend for NatsBackend {
    fn describe(&self) -> String {
        self.url.shown()
    }

    /// Nothing is read at start: each instance is read when its first record arrives.
    fn load(&mut self, _proc: &mut Processor) {
        log_info!(
            "state: using bucket {}; each instance is restored from it when its first record arrives",
            self.url.shown()
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
                log_warn!(
                    "state: cannot read {name} from {}: {e}; the instance starts fresh",
                    self.url.shown()
                );
                return;
            }
            None => return,
        };
        match entry::decode_entry(&entry.value, &self.fingerprint, key) {
            Ok(saved) => {
                let (monitor, note) = self.restorer.restore(
                    proc,
                    key,
                    &saved.program,
                    &saved.monitor,
                    &saved.continuity,
                );
                if let Some(note) = note {
                    log_info!("{}", note);
                }
                log_debug!("state: restored {name} from {}", self.url.shown());
                proc.restore_instance_at(key.clone(), monitor, saved.continuity);
            }
            Err(why) => {
                let aside = self.set_aside(&name, entry.value);
                log_warn!(
                    "state: {name} in {} not used: {why}; {}; the instance starts fresh",
                    self.url.shown(),
                    match aside {
                        Some(a) => format!("put aside as {a}"),
                        None => "could not put it aside".into(),
                    }
                );
            }
        }
    }

    fn save(&mut self, proc: &Processor) -> io::Result<usize> {
        // Each instance with the keys of its own program, computed once per program.
        let mut programs = Programs::default();
        let mut unsaved = 0;
        let entries: Vec<(String, bytes::Bytes)> = proc
            .saved_instances()
            .map(|(key, m, c)| {
                let fp = &self.fingerprint;
                let (bytes, u) = entry::encode_entry(&mut programs, fp, key, m, &c);
                unsaved += u;
                (kv_key(key), bytes::Bytes::from(bytes))
            })
            .collect();
        entry::warn_unsaved(unsaved);
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
