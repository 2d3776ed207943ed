//! The fleet checkpoint's store in the state bucket (docs/fleet.md, "A fleet of NATS
//! partitions", "The fleet checkpoint"): what it holds ([`Checkpoint`]: the partitions' table
//! and the fleet level after an entry), how it is written (deflated JSON cut in parts under the
//! server's `max_payload`, `fleet.cp.<seq>.<n>`, then a head `fleet.checkpoint` naming them with
//! their SHA-256, so a checkpoint of any size is stored and a reader never takes a half-written
//! one), how it is read (the head, its parts, the digest checked; a head replaced while it is
//! read is read again; the one-key JSON of earlier versions is read too), and the trimming once
//! a head is stored (the entries the checkpoint before covered, the parts of older heads).
//! A checkpoint is taken on the step loop as a cheap copy ([`Taken`]: the maps and monitor
//! values are shared) and converted, encoded, deflated and hashed off it ([`Taken::encode`] in
//! a blocking task, then [`store`]). When and what to checkpoint is decided by [`super::nats`].

use super::level::{LevelCopy, LevelState};
use super::watermark::{Partitions, PartsState};
use async_nats::jetstream::kv;
use sha2::{Digest, Sha256};
use std::io::{Read, Write};
use std::time::{Duration, Instant};

/// The head of the fleet checkpoint (earlier versions: the whole checkpoint as one JSON value).
pub const HEAD_KEY: &str = "fleet.checkpoint";
/// The parts of the checkpoint covering stream sequence `seq`: `fleet.cp.<seq>.<n>`.
const PARTS: &str = "fleet.cp";
/// The largest part; smaller when the server's `max_payload` is (half of it).
const MAX_PART: usize = 512 * 1024;
/// A head replaced while its parts were read (their deletion follows): read again at most
/// this many times.
const READS: usize = 5;
/// At most this much is reserved ahead from a head's sizes (a hint: a bad head allocates no
/// more).
const CAPACITY: usize = 64 << 20;

/// The fleet checkpoint: the fleet level after the entry at `seq`.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Checkpoint {
    pub seq: u64,
    /// `fleet.written` when it was taken.
    pub written: u64,
    pub table: PartsState,
    pub level: LevelState,
}

/// A checkpoint as taken on the step loop: the level and the partitions' table copied (values
/// shared, not converted), turned into a [`Checkpoint`]'s JSON off the step loop.
pub struct Taken {
    pub seq: u64,
    pub written: u64,
    pub table: Partitions,
    pub level: LevelCopy,
}

impl Taken {
    /// The JSON of the [`Checkpoint`]: `Ok(None)` when the level holds a value a checkpoint
    /// cannot keep (a function value).
    pub fn encode(&self) -> Result<Option<Vec<u8>>, String> {
        let Some(level) = self.level.state() else {
            return Ok(None);
        };
        let c = Checkpoint {
            seq: self.seq,
            written: self.written,
            table: self.table.state(),
            level,
        };
        serde_json::to_vec(&c)
            .map(Some)
            .map_err(|e| format!("cannot encode it: {e}"))
    }
}

/// The head (`fleet.checkpoint`): the parts holding the deflated JSON of a [`Checkpoint`].
#[derive(serde::Serialize, serde::Deserialize)]
struct Head {
    /// The stream sequence the checkpoint covers (its parts' keys name it).
    seq: u64,
    parts: u32,
    /// Bytes stored (the parts, deflated) and of the JSON.
    bytes: u64,
    json: u64,
    /// SHA-256 of the stored bytes, hex.
    sha256: String,
}

/// What storing one checkpoint took.
pub struct Stored {
    pub json: usize,
    pub bytes: usize,
    pub parts: usize,
    pub compress: Duration,
    pub put: Duration,
    /// The stream sequence of its first part: older parts may be deleted.
    pub first: u64,
}

/// The size of a part for a server whose `max_payload` is `max_payload`.
pub fn part_size(max_payload: usize) -> usize {
    (max_payload / 2).clamp(1024, MAX_PART)
}

fn hex(digest: &[u8]) -> String {
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

fn deflate(json: &[u8]) -> std::io::Result<Vec<u8>> {
    let mut e = flate2::write::DeflateEncoder::new(
        Vec::with_capacity(json.len() / 4),
        flate2::Compression::fast(),
    );
    e.write_all(json)?;
    e.finish()
}

fn inflate(bytes: &[u8], json: u64) -> std::io::Result<Vec<u8>> {
    let mut out = Vec::with_capacity(usize::try_from(json).unwrap_or(0).min(CAPACITY));
    flate2::read::DeflateDecoder::new(bytes).read_to_end(&mut out)?;
    Ok(out)
}

/// Store `json` (a [`Checkpoint`] covering stream sequence `seq`): its parts first, then the
/// head naming them, so that a reader finds either the head before or this one, whole.
pub async fn store(
    store: &kv::Store,
    seq: u64,
    json: bytes::Bytes,
    part: usize,
) -> Result<Stored, String> {
    let started = Instant::now();
    let raw = json.clone();
    let body = tokio::task::spawn_blocking(move || deflate(&raw))
        .await
        .map_err(|e| format!("cannot compress it: {e}"))?
        .map_err(|e| format!("cannot compress it: {e}"))?;
    let compress = started.elapsed();
    let started = Instant::now();
    let body = bytes::Bytes::from(body);
    let mut first = None;
    let mut n = 0u32;
    for at in (0..body.len().max(1)).step_by(part.max(1)) {
        let chunk = body.slice(at..(at + part).min(body.len()));
        let rev = store
            .put(format!("{PARTS}.{seq}.{n}"), chunk)
            .await
            .map_err(|e| format!("cannot put its part {n}: {e}"))?;
        first.get_or_insert(rev);
        n += 1;
    }
    let head = Head {
        seq,
        parts: n,
        bytes: body.len() as u64,
        json: json.len() as u64,
        sha256: hex(&Sha256::digest(&body)),
    };
    let head = serde_json::to_vec(&head).map_err(|e| format!("cannot encode its head: {e}"))?;
    store
        .put(HEAD_KEY, head.into())
        .await
        .map_err(|e| format!("cannot put its head: {e}"))?;
    Ok(Stored {
        json: json.len(),
        bytes: body.len(),
        parts: n as usize,
        compress,
        put: started.elapsed(),
        first: first.unwrap_or(0),
    })
}

/// After a checkpoint is stored: delete the entries (`fleet.m.>`) up to stream sequence
/// `entries` (the checkpoint before it covered; 0: none) and every checkpoint part older than
/// `parts` (the new checkpoint's first), with the stream's purge (no delete markers).
pub async fn trim(store: &kv::Store, entries: u64, parts: u64) {
    if entries > 0 {
        let filter = format!("{}fleet.m.>", store.prefix);
        if let Err(e) = store
            .stream
            .purge()
            .filter(filter)
            .sequence(entries.saturating_add(1))
            .await
        {
            crate::log::warn_limited("fleet trim", || {
                format!("fleet: cannot delete the entries up to {entries}: {e}")
            });
        }
    }
    if parts > 0 {
        let filter = format!("{}{PARTS}.>", store.prefix);
        if let Err(e) = store.stream.purge().filter(filter).sequence(parts).await {
            crate::log::warn_limited("fleet trim parts", || {
                format!("fleet: cannot delete the fleet checkpoint's older parts: {e}")
            });
        }
    }
}

/// What reading the checkpoint took.
pub struct Loaded {
    pub checkpoint: Checkpoint,
    /// Bytes read (the parts, or the one-key checkpoint), parts, time.
    pub bytes: usize,
    pub parts: usize,
    pub took: Duration,
}

/// Read the fleet checkpoint: `Ok(None)` when there is none; `Err` (a message) when there is
/// one that cannot be read whole.
pub async fn load(store: &kv::Store) -> Result<Option<Loaded>, String> {
    let started = Instant::now();
    let mut last = String::new();
    for _ in 0..READS {
        let Some(head) = store
            .get(HEAD_KEY)
            .await
            .map_err(|e| format!("cannot read {HEAD_KEY}: {e}"))?
        else {
            return Ok(None);
        };
        let Ok(h) = serde_json::from_slice::<Head>(&head) else {
            // The one-key checkpoint of earlier versions.
            let checkpoint = serde_json::from_slice::<Checkpoint>(&head)
                .map_err(|e| format!("{HEAD_KEY} is no fleet checkpoint: {e}"))?;
            return Ok(Some(Loaded {
                checkpoint,
                bytes: head.len(),
                parts: 1,
                took: started.elapsed(),
            }));
        };
        match read_parts(store, &h).await {
            Ok(json) => {
                let checkpoint = serde_json::from_slice::<Checkpoint>(&json)
                    .map_err(|e| format!("the fleet checkpoint is not one: {e}"))?;
                return Ok(Some(Loaded {
                    checkpoint,
                    bytes: h.bytes as usize,
                    parts: h.parts as usize,
                    took: started.elapsed(),
                }));
            }
            // A newer head may have replaced this one and its parts gone: read the head again.
            Err(e) => last = e,
        }
    }
    Err(last)
}

async fn read_parts(store: &kv::Store, h: &Head) -> Result<Vec<u8>, String> {
    let mut body = Vec::with_capacity(usize::try_from(h.bytes).unwrap_or(0).min(CAPACITY));
    for n in 0..h.parts {
        let key = format!("{PARTS}.{}.{n}", h.seq);
        let part = store
            .get(&key)
            .await
            .map_err(|e| format!("cannot read {key}: {e}"))?
            .ok_or_else(|| format!("part {key} of the fleet checkpoint is missing"))?;
        body.extend_from_slice(&part);
    }
    if hex(&Sha256::digest(&body)) != h.sha256 || body.len() as u64 != h.bytes {
        return Err(format!(
            "the parts of the fleet checkpoint at stream sequence {} do not match its digest",
            h.seq
        ));
    }
    inflate(&body, h.json).map_err(|e| format!("cannot inflate the fleet checkpoint: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deflate_then_inflate_gives_the_bytes_back() {
        let json = br#"{"seq":3,"maps":["tessla/r1","tessla/r2","tessla/r1"]}"#.repeat(100);
        let d = deflate(&json).unwrap();
        assert!(d.len() < json.len() / 4);
        assert_eq!(inflate(&d, json.len() as u64).unwrap(), json);
        assert!(inflate(b"not deflate at all", 10).is_err());
    }

    #[test]
    fn parts_stay_under_half_the_servers_max_payload() {
        assert_eq!(part_size(1024 * 1024), 512 * 1024);
        assert_eq!(part_size(64 * 1024), 32 * 1024);
        assert_eq!(part_size(8 * 1024 * 1024), MAX_PART);
        assert_eq!(part_size(0), 1024);
    }

    #[test]
    fn a_head_is_told_from_an_earlier_one_key_checkpoint() {
        let old = br#"{"seq":1,"written":1,"table":{},"level":{}}"#;
        assert!(serde_json::from_slice::<Head>(old).is_err());
        let h = Head {
            seq: 7,
            parts: 2,
            bytes: 10,
            json: 40,
            sha256: "ab".into(),
        };
        let back: Head = serde_json::from_slice(&serde_json::to_vec(&h).unwrap()).unwrap();
        assert_eq!(
            (back.seq, back.parts, back.sha256),
            (7, 2, "ab".to_string())
        );
    }
}
