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
use std::hash::{Hash, Hasher};

/// How many recent records of one instance a record is compared with (a resent message comes
/// back right after the reconnect, before anything newer of the same robot).
pub const WINDOW: usize = 32;

/// The recent records of one instance: (timestamp, digest), oldest overwritten first.
#[derive(Debug, Default, Clone)]
pub struct Recent {
    seen: Vec<(i64, u64)>,
    next: usize,
}

impl Recent {
    /// Whether `m` (timestamp `ts`) repeats a recent record; if not, it is remembered.
    pub fn is_duplicate(&mut self, ts: i64, m: &Metric) -> bool {
        let d = digest(m);
        if self.seen.iter().any(|&(t, x)| t == ts && x == d) {
            return true;
        }
        if self.seen.len() < WINDOW {
            self.seen.push((ts, d));
        } else {
            self.seen[self.next] = (ts, d);
            self.next = (self.next + 1) % WINDOW;
        }
        false
    }
}

/// Order-independent digest of a metric's measurement, tags and fields: each pair is hashed
/// alone, mixed, and the results summed.
fn digest(m: &Metric) -> u64 {
    let mut sum = pair_hash(0, m.measurement.as_bytes(), |_| {});
    for (k, v) in &m.tags {
        sum = sum.wrapping_add(pair_hash(1, k.as_bytes(), |h| v.hash(h)));
    }
    for (k, v) in &m.fields {
        sum = sum.wrapping_add(pair_hash(2, k.as_bytes(), |h| match v {
            FieldValue::Float(f) => (0u8, f.to_bits()).hash(h),
            FieldValue::Int(i) => (1u8, *i).hash(h),
            FieldValue::UInt(u) => (2u8, *u).hash(h),
            FieldValue::Bool(b) => (3u8, *b).hash(h),
            FieldValue::Str(s) => (4u8, s).hash(h),
        }));
    }
    sum ^ (m.fields.len() as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
}

fn pair_hash(kind: u8, key: &[u8], value: impl FnOnce(&mut rustc_hash::FxHasher)) -> u64 {
    let mut h = rustc_hash::FxHasher::default();
    h.write_u8(kind);
    h.write(key);
    h.write_u8(0xff);
    value(&mut h);
    // splitmix64's finalizer: spreads Fx's output so that sums of pair hashes do not collide.
    let mut z = h.finish();
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn metric(line: &str) -> Metric {
        let mut m = Metric::default();
        assert!(lineproto::parse_record_into(line.as_bytes(), &mut m).unwrap());
        m
    }

    #[test]
    fn the_same_message_in_another_field_order_is_a_duplicate() {
        let mut r = Recent::default();
        let ts = 1_700_000_000_000_000_000;
        assert!(!r.is_duplicate(ts, &metric("m,topic=t a=1,b=2,s=\"x\" 1")));
        assert!(r.is_duplicate(ts, &metric("m,topic=t b=2,s=\"x\",a=1 1")));
        // Another value, another field set, another time, another tag: not a duplicate.
        assert!(!r.is_duplicate(ts, &metric("m,topic=t a=1,b=3,s=\"x\" 1")));
        assert!(!r.is_duplicate(ts, &metric("m,topic=t a=1,b=2 1")));
        assert!(!r.is_duplicate(ts + 1, &metric("m,topic=t a=1,b=2,s=\"x\" 1")));
        assert!(!r.is_duplicate(ts, &metric("m,topic=u a=1,b=2,s=\"x\" 1")));
        // Swapped values between keys are different records.
        assert!(!r.is_duplicate(ts, &metric("m,topic=t a=2,b=1,s=\"x\" 1")));
        // Int 1 and float 1 differ.
        assert!(!r.is_duplicate(ts, &metric("m,topic=t a=1i,b=2,s=\"x\" 1")));
    }

    #[test]
    fn only_the_last_window_records_are_remembered() {
        let mut r = Recent::default();
        let m = metric("m a=1 1");
        for t in 0..WINDOW as i64 {
            assert!(!r.is_duplicate(t, &m));
        }
        assert!(r.is_duplicate(0, &m));
        assert!(!r.is_duplicate(WINDOW as i64, &m));
        // Record 0 was overwritten by the newest one.
        assert!(!r.is_duplicate(0, &m));
        assert!(r.is_duplicate(WINDOW as i64 - 1, &m));
    }
}
