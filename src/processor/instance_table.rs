//! The table of monitor instances, one per distinct value of the `--instance-by` tags.
//!
//! Owns: keys (the values of the instance tags in a metric; a missing tag is part of the key as
//! "absent"), slots that stay valid while an instance lives, least-recently-used order for
//! `--max-instances`, and wall-clock idleness for `--instance-idle`.
//! What an instance holds is up to the caller (`pool.rs` stores a monitor and its tags, and decides
//! when one is created and evicted).
//! Also: the instance key of a record, read in one place ([`key_values`] from its bytes,
//! [`key_of`] from a parsed metric), and so which worker thread a record's instance belongs to
//! ([`shard_of`], `--threads`) and which instance a shared store restores for it
//! ([`record_key`]).

use lineproto::Metric;
use std::collections::{BTreeMap, HashMap};
use std::time::{Duration, Instant};

/// The values of the instance tags in one metric, in `--instance-by` order.
pub type Key = Vec<Option<String>>;

struct Slot<T> {
    key: Key,
    value: T,
    /// Position in `lru`.
    seq: u64,
    last_used: Instant,
}

/// Instances by key, with LRU order. Slot indices are reused after eviction.
pub struct Table<T> {
    slots: Vec<Option<Slot<T>>>,
    free: Vec<usize>,
    index: HashMap<Key, usize>,
    lru: BTreeMap<u64, usize>,
    next_seq: u64,
}

impl<T> Default for Table<T> {
    fn default() -> Self {
        Table {
            slots: Vec::new(),
            free: Vec::new(),
            index: HashMap::new(),
            lru: BTreeMap::new(),
            next_seq: 0,
        }
    }
}

impl<T> Table<T> {
    pub fn len(&self) -> usize {
        self.index.len()
    }

    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// The slot of `key`, marked as used now.
    pub fn find(&mut self, key: &Key, now: Instant) -> Option<usize> {
        let i = *self.index.get(key)?;
        self.touch(i, now);
        Some(i)
    }

    fn touch(&mut self, i: usize, now: Instant) {
        let seq = self.next_seq;
        if let Some(Some(s)) = self.slots.get_mut(i) {
            self.lru.remove(&s.seq);
            s.seq = seq;
            s.last_used = now;
            self.lru.insert(seq, i);
            self.next_seq += 1;
        }
    }

    /// The slot of `key` when it was last used more than `idle` before `now` (not marked used).
    pub fn idle_slot(&self, key: &Key, idle: Duration, now: Instant) -> Option<usize> {
        let &i = self.index.get(key)?;
        self.idle_at(i, idle, now).then_some(i)
    }

    /// Whether slot `i` was last used more than `idle` before `at`.
    pub fn idle_at(&self, i: usize, idle: Duration, at: Instant) -> bool {
        self.slots
            .get(i)
            .and_then(|s| s.as_ref())
            .is_some_and(|s| at.saturating_duration_since(s.last_used) > idle)
    }

    /// When the least recently used instance was last used.
    pub fn oldest_use(&self) -> Option<Instant> {
        let (_, &i) = self.lru.first_key_value()?;
        Some(self.slots.get(i)?.as_ref()?.last_used)
    }

    /// Insert a new instance (the caller has checked that `key` is absent); returns its slot.
    pub fn insert(&mut self, key: Key, value: T, now: Instant) -> usize {
        let seq = self.next_seq;
        self.next_seq += 1;
        let slot = Slot {
            key: key.clone(),
            value,
            seq,
            last_used: now,
        };
        let i = match self.free.pop() {
            Some(i) => {
                if let Some(s) = self.slots.get_mut(i) {
                    *s = Some(slot);
                }
                i
            }
            None => {
                self.slots.push(Some(slot));
                self.slots.len() - 1
            }
        };
        self.index.insert(key, i);
        self.lru.insert(seq, i);
        i
    }

    pub fn get_mut(&mut self, i: usize) -> Option<&mut T> {
        self.slots
            .get_mut(i)
            .and_then(|s| s.as_mut())
            .map(|s| &mut s.value)
    }

    /// The least recently used instance, if the table holds more than `max`, or if it was
    /// last used more than `idle` before `now`.
    pub fn evictable(&self, max: usize, idle: Option<Duration>, now: Instant) -> Option<usize> {
        let (_, &i) = self.lru.first_key_value()?;
        let s = self.slots.get(i)?.as_ref()?;
        let too_many = self.index.len() > max;
        let too_idle = idle.is_some_and(|d| now.saturating_duration_since(s.last_used) > d);
        (too_many || too_idle).then_some(i)
    }

    /// Every instance, least recently used first.
    pub fn iter_lru(&self) -> impl Iterator<Item = (&Key, &T)> {
        self.lru.values().filter_map(|&i| {
            let s = self.slots.get(i)?.as_ref()?;
            Some((&s.key, &s.value))
        })
    }

    /// Every instance's slot and value, in no particular order.
    pub fn slots_mut(&mut self) -> impl Iterator<Item = (usize, &mut T)> {
        self.slots
            .iter_mut()
            .enumerate()
            .filter_map(|(i, s)| Some((i, &mut s.as_mut()?.value)))
    }

    /// Every instance's value, in no particular order.
    pub fn values_mut(&mut self) -> impl Iterator<Item = &mut T> {
        self.slots.iter_mut().flatten().map(|s| &mut s.value)
    }

    /// Remove slot `i`, returning its key and value.
    /// The key of the instance in slot `i`.
    pub fn key(&self, i: usize) -> Option<&Key> {
        self.slots.get(i)?.as_ref().map(|s| &s.key)
    }

    /// Every instance's key and slot.
    pub fn keys(&self) -> impl Iterator<Item = (&Key, &usize)> {
        self.index.iter()
    }

    pub fn remove(&mut self, i: usize) -> Option<(Key, T)> {
        let s = self.slots.get_mut(i)?.take()?;
        self.lru.remove(&s.seq);
        self.index.remove(&s.key);
        self.free.push(i);
        Some((s.key, s.value))
    }
}

/// The values of the `instance_by` tags in a parsed metric: its instance key.
pub fn key_of(instance_by: &[String], m: &Metric) -> Key {
    instance_by
        .iter()
        .map(|t| m.tag(t).map(str::to_string))
        .collect()
}

/// What [`key_values`] hands the values of a record's instance tags to.
pub trait KeySink {
    /// The value of the next instance tag, in `--instance-by` order (`None`: absent).
    fn value(&mut self, v: Option<&[u8]>);
    /// Forget the values given so far: they start again from the first tag.
    fn restart(&mut self);
}

/// The instance key of the record `bytes`, the one routine every caller reads it with (the
/// `--threads` shard, [`shard_of`]; a shared store's restore, [`record_key`]): the value of
/// each `instance_by` tag in order, given to `sink`; `false` when the record does not parse
/// (then nothing is given, or `restart` was the last call). Read from the raw series key when it
/// holds no backslash or quote and no instance tag twice (the values are then exactly the
/// parsed ones, as [`key_of`] reads them); otherwise from the parsed record.
///
/// It runs for every record of a `--threads` run, on the thread that routes every record, so
/// it finds the end of the series key with `memchr` (a vectorised search) and reads the tags in
/// one loop, without allocating.
#[inline]
pub fn key_values<S: KeySink>(bytes: &[u8], instance_by: &[String], sink: &mut S) -> bool {
    if let Some(series) = plain_series(bytes) {
        let mut from_raw = true;
        for t in instance_by {
            match raw_tag(series, t.as_bytes()) {
                Some(v) => sink.value(v),
                None => {
                    from_raw = false;
                    break;
                }
            }
        }
        if from_raw {
            return true;
        }
        sink.restart();
    }
    let Ok(Some(m)) = lineproto::parse_record(bytes) else {
        return false;
    };
    for t in instance_by {
        sink.value(m.tag(t).map(str::as_bytes));
    }
    true
}

/// Which of `shards` workers owns the instance of the record `bytes`: its instance key
/// ([`key_values`]) hashed, so the same key always gives the same shard and an instance lives
/// in one worker. A record that does not parse goes to shard 0 (it only produces its error
/// there). Hashed with `FxHasher` (rustc-hash: a multiply per word, the high bits rotated down
/// by `finish`) instead of the keyed SipHash of `DefaultHasher`.
pub fn shard_of(bytes: &[u8], instance_by: &[String], shards: usize) -> usize {
    use std::hash::Hasher;
    if shards <= 1 {
        return 0;
    }
    let mut h = ShardHash(rustc_hash::FxHasher::default());
    if !key_values(bytes, instance_by, &mut h) {
        return 0;
    }
    (h.0.finish() % shards as u64) as usize
}

/// The hash of an instance key, for [`shard_of`].
struct ShardHash(rustc_hash::FxHasher);

impl KeySink for ShardHash {
    #[inline]
    fn value(&mut self, v: Option<&[u8]>) {
        std::hash::Hash::hash(&v, &mut self.0);
    }
    #[inline]
    fn restart(&mut self) {
        self.0 = rustc_hash::FxHasher::default();
    }
}

/// The instance key of the record `bytes` ([`key_values`]) as the processor's instances hold
/// it; `None` when the record does not parse (or a tag value is not UTF-8, which the parser
/// refuses).
pub fn record_key(bytes: &[u8], instance_by: &[String]) -> Option<Key> {
    let mut sink = KeyCollect {
        key: Vec::with_capacity(instance_by.len()),
        utf8: true,
    };
    (key_values(bytes, instance_by, &mut sink) && sink.utf8).then_some(sink.key)
}

/// An instance key collected from [`key_values`], for [`record_key`].
struct KeyCollect {
    key: Key,
    /// Every value given was UTF-8.
    utf8: bool,
}

impl KeySink for KeyCollect {
    fn value(&mut self, v: Option<&[u8]>) {
        let v = v.and_then(|b| match std::str::from_utf8(b) {
            Ok(s) => Some(s.to_string()),
            Err(_) => {
                self.utf8 = false;
                None
            }
        });
        self.key.push(v);
    }
    fn restart(&mut self) {
        self.key.clear();
        self.utf8 = true;
    }
}

/// The series key of `bytes` (up to the first space, tab or line end) when it is plain: not
/// empty, not a comment, and no backslash or quote in it.
fn plain_series(bytes: &[u8]) -> Option<&[u8]> {
    // The first space or quote character; a tab or line end can only come before it.
    let first = memchr::memchr3(b' ', b'\\', b'"', bytes).unwrap_or(bytes.len());
    let head = bytes.get(..first)?;
    let end = memchr::memchr3(b'\t', b'\n', b'\r', head).unwrap_or(first);
    let series = bytes.get(..end)?;
    let plain = end < first || !matches!(bytes.get(first), Some(b'\\' | b'"'));
    (plain && !series.is_empty() && series.first() != Some(&b'#')).then_some(series)
}

/// The value of tag `key` in a plain series key (`Some(None)`: absent); `None` when the key
/// appears twice, or holds a `=` or `,` (the parsed record answers those).
fn raw_tag<'a>(series: &'a [u8], key: &[u8]) -> Option<Option<&'a [u8]>> {
    if memchr::memchr2(b'=', b',', key).is_some() {
        return None;
    }
    let mut found = None;
    // Past the measurement, each tag is `k=v` (or a bare `k`, value empty) up to the next
    // comma. Tags are a few bytes long: a plain loop beats `memchr`'s set-up on them.
    let comma = |s: &[u8]| s.iter().position(|&b| b == b',');
    let mut rest = match comma(series) {
        Some(c) => series.get(c + 1..)?,
        None => return Some(None),
    };
    loop {
        let len = comma(rest).unwrap_or(rest.len());
        let tag = rest.get(..len)?;
        let value = match tag.strip_prefix(key).map(<[u8]>::split_first) {
            Some(None) => Some(&[][..]),
            Some(Some((b'=', v))) => Some(v),
            _ => None,
        };
        if let Some(v) = value {
            if found.is_some() {
                return None;
            }
            found = Some(v);
        }
        match rest.get(len + 1..) {
            Some(r) => rest = r,
            None => break,
        }
    }
    Some(found)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn k(s: &str) -> Key {
        vec![Some(s.to_string())]
    }

    #[test]
    fn least_recently_used_is_evicted_first() {
        let now = Instant::now();
        let mut t = Table::default();
        let a = t.insert(k("a"), 1, now);
        let b = t.insert(k("b"), 2, now);
        assert_eq!(t.evictable(2, None, now), None);
        t.insert(k("c"), 3, now);
        assert_eq!(t.evictable(2, None, now), Some(a));
        // Using `a` makes `b` the oldest.
        assert_eq!(t.find(&k("a"), now), Some(a));
        assert_eq!(t.evictable(2, None, now), Some(b));
        assert_eq!(t.remove(b), Some((k("b"), 2)));
        assert_eq!(t.evictable(2, None, now), None);
        assert_eq!(t.find(&k("b"), now), None);
        // The freed slot is reused.
        assert_eq!(t.insert(k("d"), 4, now), b);
        assert_eq!(t.get_mut(b), Some(&mut 4));
        assert_eq!(t.len(), 3);
    }

    #[test]
    fn iteration_follows_lru_order() {
        let now = Instant::now();
        let mut t = Table::default();
        t.insert(k("a"), 1, now);
        t.insert(k("b"), 2, now);
        t.find(&k("a"), now);
        let order: Vec<i32> = t.iter_lru().map(|(_, v)| *v).collect();
        assert_eq!(order, [2, 1]);
        for v in t.values_mut() {
            *v *= 10;
        }
        let order: Vec<i32> = t.iter_lru().map(|(_, v)| *v).collect();
        assert_eq!(order, [20, 10]);
    }

    #[test]
    fn idle_instances_are_evictable() {
        let then = Instant::now();
        let later = then + Duration::from_secs(5);
        let mut t = Table::default();
        let a = t.insert(k("a"), (), then);
        let b = t.insert(k("b"), (), later);
        let idle = Some(Duration::from_secs(2));
        assert_eq!(t.evictable(10, idle, later), Some(a));
        t.remove(a);
        assert_eq!(t.evictable(10, idle, later), None);
        assert_eq!(
            t.evictable(10, idle, later + Duration::from_secs(3)),
            Some(b)
        );
    }

    /// A record's shard depends only on its instance key, whether read from the raw series key
    /// or from the parsed record (escapes elsewhere in the series key force the parse).
    #[test]
    fn shards_follow_the_instance_key() {
        let by = vec!["robot".to_string()];
        for n in [2, 3, 7] {
            for r in 0..50 {
                let plain = format!("m,robot=r{r} x=1 1");
                let other_tags = format!("n,a=1,robot=r{r},z=2 y=\"s\" 2");
                let escaped = format!("m,robot=r{r},t=a\\ b x=1 1");
                let s = shard_of(plain.as_bytes(), &by, n);
                assert!(s < n);
                assert_eq!(s, shard_of(other_tags.as_bytes(), &by, n), "{other_tags}");
                assert_eq!(s, shard_of(escaped.as_bytes(), &by, n), "{escaped}");
            }
            let absent = shard_of(b"m x=1 1", &by, n);
            assert_eq!(absent, shard_of(b"m,t=a\\ b x=1 1", &by, n));
        }
        // Eight robots use both of two shards (the reload test relies on it).
        let used: std::collections::BTreeSet<usize> = (0..8)
            .map(|r| shard_of(format!("m,robot=r{r} x=1i 10\n").as_bytes(), &by, 2))
            .collect();
        assert_eq!(used.len(), 2);
        assert_eq!(shard_of(b"m,robot=a x=1 1", &by, 1), 0);
    }

    /// The raw reading of a series key takes the same tags as the plain definition it speeds
    /// up (split at commas, then at the first `=`; the series key ends at the first space, tab
    /// or line end; a backslash or quote before it, or a tag twice, leaves it to the parser),
    /// over many random short records.
    #[test]
    fn raw_tags_equal_a_plain_split() {
        fn reference(bytes: &[u8], key: &[u8]) -> Option<Option<Vec<u8>>> {
            let end = bytes
                .iter()
                .position(|b| b" \t\n\r".contains(b))
                .unwrap_or(bytes.len());
            let series = &bytes[..end];
            if series.is_empty()
                || series[0] == b'#'
                || series.iter().any(|b| b"\\\"".contains(b))
                || key.iter().any(|b| b"=,".contains(b))
            {
                return None;
            }
            let mut found = None;
            for kv in series.split(|&b| b == b',').skip(1) {
                let mut it = kv.splitn(2, |&b| b == b'=');
                if it.next() == Some(key) {
                    if found.is_some() {
                        return None;
                    }
                    found = Some(it.next().unwrap_or_default().to_vec());
                }
            }
            Some(found)
        }
        let alphabet = b"ab=, \t\n\\\"#r";
        let keys: [&[u8]; 4] = [b"a", b"ab", b"a=b", b""];
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(35);
        for _ in 0..50_000 {
            let len = rng.random_range(0..24);
            let input: Vec<u8> = (0..len)
                .map(|_| alphabet[rng.random_range(0..alphabet.len())])
                .collect();
            for key in keys {
                let got = plain_series(&input)
                    .and_then(|s| raw_tag(s, key))
                    .map(|v| v.map(<[u8]>::to_vec));
                assert_eq!(
                    got,
                    reference(&input, key),
                    "{:?} key {:?}",
                    String::from_utf8_lossy(&input),
                    String::from_utf8_lossy(key)
                );
            }
        }
    }

    /// The key read from a record's bytes is the one the processor reads from the parsed
    /// metric ([`key_of`]), and its shard is that key's hash, over many random records: escaped
    /// and quoted tags, missing tags, a tag twice, any tag order, any `--instance-by`.
    #[test]
    fn the_key_from_the_bytes_is_the_parsed_metrics_key() {
        use rand::seq::SliceRandom;
        use rand::{Rng, SeedableRng};
        use std::hash::{Hash, Hasher};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(36);
        let pieces = [
            "a", "r1", "tb3", "\\ ", "\\,", "\\=", "\"", "é", "x", "=", "\\\\", "#",
        ];
        let names = ["robot", "zone", "host", "a"];
        let bys: [&[&str]; 5] = [
            &["robot"],
            &["zone", "robot"],
            &["robot", "missing"],
            &[],
            &["a"],
        ];
        let value = |rng: &mut rand_chacha::ChaCha8Rng| -> String {
            (0..rng.random_range(1..4))
                .map(|_| pieces[rng.random_range(0..pieces.len())])
                .collect()
        };
        let mut parsed = 0;
        for _ in 0..20_000 {
            let mut tags = Vec::new();
            for n in names {
                if rng.random_bool(0.6) {
                    tags.push(format!("{n}={}", value(&mut rng)));
                }
            }
            if rng.random_bool(0.1) {
                tags.push(format!("robot={}", value(&mut rng)));
            }
            tags.shuffle(&mut rng);
            let mut line = if rng.random_bool(0.1) {
                format!("m{}", value(&mut rng))
            } else {
                "m".to_string()
            };
            for t in &tags {
                line.push(',');
                line.push_str(t);
            }
            line.push_str(match rng.random_range(0..3) {
                0 => " x=1i 5\n",
                1 => " s=\"a b,c=d\"",
                _ => "\tx=2",
            });
            let by: Vec<String> = bys[rng.random_range(0..bys.len())]
                .iter()
                .map(|s| s.to_string())
                .collect();
            let bytes = line.as_bytes();
            let Ok(Some(m)) = lineproto::parse_record(bytes) else {
                continue;
            };
            parsed += 1;
            let key = key_of(&by, &m);
            assert_eq!(
                record_key(bytes, &by),
                Some(key.clone()),
                "{line:?} by {by:?}"
            );
            let mut h = rustc_hash::FxHasher::default();
            for v in &key {
                v.as_deref().map(str::as_bytes).hash(&mut h);
            }
            for n in [2, 3, 5] {
                let want = (h.finish() % n as u64) as usize;
                assert_eq!(shard_of(bytes, &by, n), want, "{line:?} by {by:?}");
            }
        }
        assert!(parsed > 10_000, "{parsed} records parsed");
    }

    /// A fleet's robots spread evenly: 10,000 robot names over 2, 3 and 4 shards, each shard
    /// within 5% of its even part.
    #[test]
    fn shards_spread_a_fleet_evenly() {
        let by = vec!["robot".to_string()];
        for n in [2, 3, 4] {
            let mut count = vec![0usize; n];
            for r in 0..10_000 {
                let line = format!("mqtt_consumer,host=dt,robot=tb3-{r:05},topic=t x=1 1\n");
                count[shard_of(line.as_bytes(), &by, n)] += 1;
            }
            let even = 10_000 / n;
            for c in &count {
                assert!(c.abs_diff(even) * 20 < even, "{n} shards: {count:?}");
            }
        }
    }
}
