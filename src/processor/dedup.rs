//! Exact duplicates: the same robot message delivered twice.
//!
//! Owns: recognising a record that repeats one of its instance's recent records exactly (same
//! timestamp, same measurement, same tags, same fields with the same values, in any order), so the
//! processor can drop it instead of treating it as a late record.
//!
//! Why: with MQTT QoS 1 (what the shipped confs use) the broker resends a message whose
//! acknowledgement it did not get, and Telegraf parses it again. Telegraf builds the fields from a
//! Go map, so the resent metric's fields come in another order: records are compared by an
//! order-independent 64-bit digest of their content, among the last [`WINDOW`] records of the
//! same instance. Records without a timestamp are never duplicates (each gets the wall clock).

use lineproto::{FieldValue, Metric};

/// How many recent records of one instance a record is compared with (a resent message comes
/// back right after the reconnect, before anything newer of the same robot).
pub const WINDOW: usize = 32;

/// The recent records of one instance: (timestamp, digest), oldest overwritten first.
#[derive(Debug, Default, Clone)]
pub struct Recent {
    seen: Vec<(i64, u64)>,
    next: usize,
    /// The newest timestamp ever remembered: a record newer than it repeats none of `seen`
    /// (the usual case, records in time order), so the window is not searched.
    newest: Option<i64>,
    /// The instance's last measurement and tags, with their part of the digest.
    head: Head,
}

/// A record's measurement and tags (its `head`: its bytes up to the space before the fields,
/// kept when they have no escapes) with their part of the digest: the records of one instance
/// usually repeat them (about 150 instructions of a P2 record's digest). Not saved.
#[derive(Debug, Default, Clone)]
struct Head {
    bytes: Vec<u8>,
    sum: u64,
    known: bool,
}

/// How many of an instance's newest records are saved with it (`--state`): a message the broker
/// redelivers after a restart is still recognised as a repeat of one of them.
pub const SAVED: usize = 8;

impl Recent {
    /// Its newest [`SAVED`] records (time, digest), oldest first: what `--state` keeps.
    pub fn saved(&self) -> Vec<(i64, u64)> {
        let (old, new) = self.seen.split_at(self.next.min(self.seen.len()));
        let all: Vec<(i64, u64)> = new.iter().chain(old).copied().collect();
        all[all.len().saturating_sub(SAVED)..].to_vec()
    }

    /// The window of an instance restored with `saved` ([`Recent::saved`]).
    pub fn restored(saved: &[(i64, u64)]) -> Recent {
        let seen: Vec<(i64, u64)> = saved.iter().rev().take(WINDOW).rev().copied().collect();
        Recent {
            newest: seen.iter().map(|&(t, _)| t).max(),
            // The ring is overwritten from the start once it is full.
            next: 0,
            seen,
            head: Head::default(),
        }
    }

    /// Whether `m` (timestamp `ts`, parsed from `raw`) repeats a recent record; if not, it is
    /// remembered.
    pub fn is_duplicate(&mut self, ts: i64, m: &Metric, raw: &[u8], keys: &mut ListKeys) -> bool {
        let d = digest(m, raw, &mut self.head, keys);
        let newer = self.newest.is_none_or(|n| ts > n);
        if !newer && self.seen.iter().any(|&(t, x)| t == ts && x == d) {
            return true;
        }
        if newer {
            self.newest = Some(ts);
        }
        if self.seen.len() < WINDOW {
            self.seen.push((ts, d));
        } else {
            if let Some(s) = self.seen.get_mut(self.next) {
                *s = (ts, d);
            }
            self.next = (self.next + 1) % WINDOW;
        }
        false
    }
}

/// Order-independent digest of a metric's measurement, tags and fields: each (kind, key, value)
/// pair is digested alone into 64 bits, and the pair digests are summed.
///
/// Why distinct records practically never collide: the timestamp is compared exactly, not
/// digested, and a record is compared with at most [`WINDOW`] others. A pair digest is a
/// folded multiply (the 128-bit product's halves xor-ed, as in wyhash and foldhash) of the key's
/// digest (itself folded multiplies of the key's bytes and length, under a seed for the kind and
/// the value's type) and the value's bits, each xor-ed with a distinct constant: every output bit
/// depends on every bit of key and value, so pair digests of different pairs behave like
/// independent 64-bit random values, and two different sets of pairs have equal sums with a
/// chance about 2^-64 (a sum of random values is as uniform as one of them). The field count is
/// mixed in besides. Even 10^12 records each compared with 32 others sharing their timestamp
/// would collide with a chance near 2^-64 * 32 * 10^12 < 10^-6. The digest is not keyed: records
/// crafted to collide could make one of them dropped; the records come from the operator's own
/// robots. Hand-written (before: `FxHasher` over kind, key and value plus splitmix64's finaliser
/// per pair; no hash crate in the tree gives a fixed-seed hasher this cheap): a few dozen
/// instructions per field (`lidar`: 360 fields a record).
///
/// A record whose list elements the parser read apart ([`lineproto::ListCapture`]) has the same
/// digest as read into fields: each element's key digest (`lidar_12` as Float key) comes from
/// [`ListKeys`].
///
/// The measurement's and tags' part is taken from `head` when `m`'s record (`raw`) starts with
/// the same measurement and tags ([`Head`]).
fn digest(m: &Metric, raw: &[u8], head: &mut Head, keys: &mut ListKeys) -> u64 {
    let mut sum = head_digest(m, raw, head);
    for (k, v) in &m.fields {
        let (seed, bits) = match v {
            FieldValue::Float(f) => (K[2], f.to_bits()),
            FieldValue::Int(i) => (K[3], *i as u64),
            FieldValue::UInt(u) => (K[4], *u),
            FieldValue::Bool(b) => (K[6], u64::from(*b)),
            FieldValue::Str(s) => (K[7], bytes_digest(K[5], s.as_bytes())),
        };
        sum = sum.wrapping_add(pair(bytes_digest(seed, k.as_bytes()), bits));
    }
    let mut fields = m.fields.len();
    if m.list.holds_record() {
        // Each element beside its key's digest; NaN marks a missing element.
        for (v, &key) in m.list.values().iter().zip(keys.for_list(&m.list)) {
            if !v.is_nan() {
                sum = sum.wrapping_add(pair(key, v.to_bits()));
            }
        }
        fields += m.list.count();
    }
    sum ^ (fields as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
}

/// The measurement's and tags' part of [`digest`]: the sum of their digests.
fn head_sum(m: &Metric) -> u64 {
    let mut sum = bytes_digest(K[0], m.measurement.as_bytes());
    for (k, v) in &m.tags {
        sum = sum.wrapping_add(pair(
            bytes_digest(K[1], k.as_bytes()),
            bytes_digest(K[5], v.as_bytes()),
        ));
    }
    sum
}

/// [`head_sum`], `known`'s when `raw` starts with the same head as its record did; else made,
/// and kept in `known`.
///
/// Why the head's bytes decide: `len`, the length `m`'s measurement and tags have written
/// without escapes, is where a record without escapes in its head has the space after it. When
/// `raw` has no backslash before `len` and a space at `len`, its head ends at or before `len`
/// (a space inside a head is escaped), so `raw[..len]` alone decided `m`'s measurement and tags:
/// a record starting with the same `len` bytes and a space has the same ones.
#[inline]
fn head_digest(m: &Metric, raw: &[u8], known: &mut Head) -> u64 {
    let len = m.measurement.len()
        + m.tags
            .iter()
            .map(|(k, v)| k.len() + v.len() + 2)
            .sum::<usize>();
    let head = raw.get(..len).filter(|_| raw.get(len) == Some(&b' '));
    // The known head has no backslash: equal bytes have none either (searched only when a head
    // is kept).
    if known.known && head == Some(known.bytes.as_slice()) {
        return known.sum;
    }
    let sum = head_sum(m);
    if let Some(h) = head.filter(|h| memchr::memchr(b'\\', h).is_none()) {
        known.bytes.clear();
        known.bytes.extend_from_slice(h);
        known.sum = sum;
        known.known = true;
    }
    sum
}

/// The digests of the Float keys `<prefix><index>` of a captured list, by index, made once (a
/// key digest per beam per record was a quarter of a lidar record's digest).
#[derive(Debug, Default)]
pub struct ListKeys {
    prefix: Vec<u8>,
    digests: Vec<u64>,
}

impl ListKeys {
    /// The key digests for `list`'s prefix, at least as many as its record's length.
    fn for_list(&mut self, list: &lineproto::ListCapture) -> &[u64] {
        if self.prefix != list.prefix() {
            self.prefix = list.prefix().to_vec();
            self.digests.clear();
        }
        let want = list.values().len();
        if self.digests.len() < want {
            let mut key = self.prefix.clone();
            for i in self.digests.len()..want {
                key.truncate(self.prefix.len());
                key.extend_from_slice(i.to_string().as_bytes());
                self.digests.push(bytes_digest(K[2], &key));
            }
        }
        &self.digests
    }
}

/// Constants with no structure (hex digits of pi, as foldhash and wyhash use).
const K: [u64; 8] = [
    0x243f_6a88_85a3_08d3,
    0x1319_8a2e_0370_7344,
    0xa409_3822_299f_31d0,
    0x082e_fa98_ec4e_6c89,
    0x4528_21e6_38d0_1377,
    0xbe54_66cf_34e9_0c6c,
    0xc0ac_29b7_c97c_50dd,
    0x3f84_d5b5_b547_0917,
];

/// The 128-bit product's halves xor-ed.
#[inline(always)]
fn fold(a: u64, b: u64) -> u64 {
    let p = u128::from(a) * u128::from(b);
    (p as u64) ^ ((p >> 64) as u64)
}

/// A pair's digest from its key's digest and its value's bits.
#[inline(always)]
fn pair(key: u64, value: u64) -> u64 {
    fold(key ^ K[0], value ^ K[1])
}

/// Digest of a byte string under `seed` (a kind: measurement, tag key, field key of a value
/// type, string value): its length and every byte, 16 at a time, through folded multiplies.
#[inline]
fn bytes_digest(seed: u64, b: &[u8]) -> u64 {
    let len = b.len();
    let mut s = seed ^ (len as u64).wrapping_mul(K[4]);
    let (x, y) = if len <= 16 {
        if len >= 8 {
            (word8(b.first_chunk()), word8(b.last_chunk()))
        } else if len >= 4 {
            (word4(b.first_chunk()), word4(b.last_chunk()))
        } else if let (Some(&f), Some(&l)) = (b.first(), b.last()) {
            let mid = b.get(len / 2).copied().unwrap_or(0);
            (u64::from(f) | (u64::from(mid) << 8), u64::from(l))
        } else {
            (0, 0)
        }
    } else {
        let mut rest = b;
        while let Some((c, r)) = rest.split_first_chunk::<16>() {
            if r.is_empty() {
                break;
            }
            s = fold(word8(c.first_chunk()) ^ K[5], word8(c.last_chunk()) ^ s);
            rest = r;
        }
        // The last 16 bytes (overlapping the chunks before when the length is not a multiple).
        let tail = b.get(len - 16..).unwrap_or_default();
        (word8(tail.first_chunk()), word8(tail.last_chunk()))
    };
    fold(x ^ K[6], y ^ s)
}

#[inline(always)]
fn word8(c: Option<&[u8; 8]>) -> u64 {
    c.map_or(0, |c| u64::from_le_bytes(*c))
}

#[inline(always)]
fn word4(c: Option<&[u8; 4]>) -> u64 {
    c.map_or(0, |c| u64::from(u32::from_le_bytes(*c)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn metric(line: &str) -> Metric {
        let mut m = Metric::default();
        assert!(lineproto::parse_record_into(line.as_bytes(), &mut m).unwrap());
        m
    }

    /// The digest of `m` made afresh.
    fn fresh(m: &Metric) -> u64 {
        digest(m, b"", &mut Head::default(), &mut ListKeys::default())
    }

    /// [`Recent::is_duplicate`] on `line` parsed.
    fn dup(r: &mut Recent, ts: i64, line: &str, k: &mut ListKeys) -> bool {
        r.is_duplicate(ts, &metric(line), line.as_bytes(), k)
    }

    /// The head's part of the digest taken from the record before is the one made afresh,
    /// whatever heads come in turn: the same, another tag value, escapes (a space, a comma, an
    /// equals sign inside a name), a head that only starts like the one before, no tags.
    #[test]
    fn a_head_known_from_the_record_before_gives_the_digest_made_afresh() {
        let lines = [
            "mqtt_consumer,host=turtlebot3,topic=tessla a=0.015,b=\"0.0226\" 1",
            "mqtt_consumer,host=turtlebot3,topic=tessla a=0.015,b=\"0.0196\" 2",
            "mqtt_consumer,host=turtlebot3,topic=tessla2 a=0.015 2",
            "mqtt_consumer,host=turtlebot3,topic=tessla a=0.015 2",
            "mqtt_consumer,host=turtlebot3,topic=tess\\ la a=0.015 2",
            "mqtt_consumer,host=turtlebot3,topic=tess\\,la a=0.015 2",
            "mqtt_consumer,host=turtlebot3,topic=tess\\=la a=0.015 2",
            "mqtt_consumer,host=turtlebot3,topic=tess la=0.015 2",
            "mqtt_consumer,host=turtlebot3,topic=tess a=1 2",
            "mqtt\\ consumer,host=turtlebot3,topic=tessla a=0.015 2",
            "mqtt_consumer,topic=tessla,host=turtlebot3 a=0.015 2",
            "mqtt_consumer a=0.015 2",
            "m a=1 1",
        ];
        let (mut h, mut k) = (Head::default(), ListKeys::default());
        for round in 0..3 {
            for (i, line) in lines.iter().enumerate() {
                let m = metric(line);
                let known = digest(&m, line.as_bytes(), &mut h, &mut k);
                assert_eq!(known, fresh(&m), "{line} (round {round})");
                // The same record again, and the one after it, with the head now known.
                assert_eq!(digest(&m, line.as_bytes(), &mut h, &mut k), fresh(&m));
                let next = lines[(i + 1) % lines.len()];
                let n = metric(next);
                let got = digest(&n, next.as_bytes(), &mut h, &mut k);
                assert_eq!(got, fresh(&n), "{line} then {next}");
            }
        }
    }

    /// A record whose list the parser read apart has the digest it has read into fields, so a
    /// redelivery is found across the moment the processor starts reading lists apart.
    #[test]
    fn a_list_read_apart_has_the_digest_of_its_fields() {
        let mut keys = ListKeys::default();
        for line in [
            "m,t=a lidar_2=1.5,x=1i,lidar_0=0,lidar_10=2.4749999046325684 5",
            "m lidar_0=1 5",
            "m lidar_count=2i,lidar_1=3 5",
            "m x=1 5",
        ] {
            let plain = metric(line);
            let mut apart = Metric::default();
            apart.list.set_prefix(Some("lidar_"), 100);
            assert!(lineproto::parse_record_into(line.as_bytes(), &mut apart).unwrap());
            assert!(apart.list.holds_record(), "{line}");
            assert_eq!(
                apart.list.count() + apart.fields.len(),
                plain.fields.len(),
                "{line}"
            );
            assert_eq!(
                digest(&plain, line.as_bytes(), &mut Head::default(), &mut keys),
                digest(&apart, line.as_bytes(), &mut Head::default(), &mut keys),
                "{line}"
            );
        }
    }

    #[test]
    fn the_same_message_in_another_field_order_is_a_duplicate() {
        let mut r = Recent::default();
        let mut k = ListKeys::default();
        let ts = 1_700_000_000_000_000_000;
        assert!(!dup(&mut r, ts, "m,topic=t a=1,b=2,s=\"x\" 1", &mut k));
        assert!(dup(&mut r, ts, "m,topic=t b=2,s=\"x\",a=1 1", &mut k));
        // Another value, another field set, another time, another tag: not a duplicate.
        assert!(!dup(&mut r, ts, "m,topic=t a=1,b=3,s=\"x\" 1", &mut k));
        assert!(!dup(&mut r, ts, "m,topic=t a=1,b=2 1", &mut k));
        assert!(!dup(&mut r, ts + 1, "m,topic=t a=1,b=2,s=\"x\" 1", &mut k));
        assert!(!dup(&mut r, ts, "m,topic=u a=1,b=2,s=\"x\" 1", &mut k));
        // Swapped values between keys are different records.
        assert!(!dup(&mut r, ts, "m,topic=t a=2,b=1,s=\"x\" 1", &mut k));
        // Int 1 and float 1 differ.
        assert!(!dup(&mut r, ts, "m,topic=t a=1i,b=2,s=\"x\" 1", &mut k));
    }

    /// Records that differ in one key byte (at any length, through the 16-byte chunks), in one
    /// value or in the value's type all have distinct digests.
    #[test]
    fn near_records_have_distinct_digests() {
        let mut seen = std::collections::HashSet::new();
        let mut n = 0;
        for len in 0..40 {
            for pos in 0..len {
                for b in [b'a', b'b', b'\\', b'z'] {
                    let mut key = vec![b'k'; len];
                    key[pos] = b;
                    let key = String::from_utf8(key).unwrap();
                    for v in [
                        FieldValue::Float(1.0),
                        FieldValue::Int(1),
                        FieldValue::UInt(1),
                        FieldValue::Bool(true),
                        FieldValue::Str("1".into()),
                        FieldValue::Float(0.25),
                    ] {
                        let m = Metric {
                            measurement: "m".into(),
                            fields: vec![
                                (key.clone(), v),
                                ("x".into(), FieldValue::Int(len as i64)),
                            ],
                            ..Default::default()
                        };
                        seen.insert(fresh(&m));
                        n += 1;
                    }
                }
            }
        }
        assert_eq!(seen.len(), n);
        let mut distinct = std::collections::HashSet::new();
        let mut total = 0;
        for i in 0..200_000u64 {
            let m = Metric {
                measurement: "mqtt_consumer".into(),
                tags: vec![("robot".into(), format!("tb3-{:05}", i % 1000))],
                fields: vec![
                    ("lidar_1".into(), FieldValue::Float(i as f64 * 0.001)),
                    ("lidar_2".into(), FieldValue::Float((i / 7) as f64)),
                ],
                ..Default::default()
            };
            distinct.insert(fresh(&m));
            total += 1;
        }
        assert_eq!(distinct.len(), total);
    }

    #[test]
    fn only_the_last_window_records_are_remembered() {
        let mut r = Recent::default();
        let mut k = ListKeys::default();
        let m = metric("m a=1 1");
        let raw = b"m a=1 1";
        for t in 0..WINDOW as i64 {
            assert!(!r.is_duplicate(t, &m, raw, &mut k));
        }
        assert!(r.is_duplicate(0, &m, raw, &mut k));
        assert!(!r.is_duplicate(WINDOW as i64, &m, raw, &mut k));
        // Record 0 was overwritten by the newest one.
        assert!(!r.is_duplicate(0, &m, raw, &mut k));
        assert!(r.is_duplicate(WINDOW as i64 - 1, &m, raw, &mut k));
    }
}
