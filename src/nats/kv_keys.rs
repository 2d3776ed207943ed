//! Names in the NATS key-value bucket: an instance key as a KV key ([`kv_key`]: injective, only
//! characters NATS allows), a partition's lease key, and a lease key's partition name read back.

use crate::processor::instance_table::Key;

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

pub(crate) fn kv_key_part_of(name: &str) -> String {
    let mut s = String::new();
    key_part(&Some(name.to_string()), &mut s);
    s
}

/// The partition name of lease key `lease.v<name>` (its encoding undone for the usual names).
pub(crate) fn partition_of(key: &str) -> String {
    let part = key.strip_prefix("lease.v").unwrap_or(key);
    let mut out = String::new();
    let mut rest = part;
    while let Some(i) = rest.find('_') {
        out.push_str(&rest[..i]);
        match rest
            .get(i + 1..i + 3)
            .and_then(|h| u8::from_str_radix(h, 16).ok())
        {
            Some(b) => {
                out.push(char::from(b));
                rest = &rest[i + 3..];
            }
            None => {
                out.push('_');
                rest = &rest[i + 1..];
            }
        }
    }
    out.push_str(rest);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

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

    #[test]
    fn a_lease_key_gives_back_its_partition() {
        assert_eq!(partition_of("lease.vp0"), "p0");
        assert_eq!(partition_of("lease.vp_2e1"), "p.1");
    }
}
