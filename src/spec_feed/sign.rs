//! Who may publish a spec version: a rollout record is signed with the operator's NKey seed
//! (ed25519) and a process runs it only when the signature verifies with a key it was told to
//! trust (`--spec-trust`). A spec steers robots, so write access to the channel's bucket is not
//! enough.
//!
//! Owns: the records a channel stores signed, a rollout's proposal and the fleet's decision on
//! it ([`seal`], [`Record::verify`], [`Signable`]), the canonical JSON the signature covers
//! ([`canonical_json`]), reading the signing seed and the trusted keys, and every reason a
//! record is refused, each saying which.
//!
//! A record: `{"format":"tessla-telegraf-rollout/1","rollout":{…},"signer":"O…","signature":"…"}`
//! (a decision: `tessla-telegraf-decision/1` and `decision`). The signature (128 hex digits) is
//! the signer's ed25519 signature of the kind's domain line (rollouts: [`DOMAIN`]) followed by
//! the canonical JSON of the signed object as stored (so fields a later version adds are
//! covered too). The rollout names its bundle's full SHA-256, so the signature covers the
//! bundle; a decision names its rollout's revision and digest.

use super::{Decision, Rollout};
use crate::nats::secrets::{SecretError, SecretSource};
use nkeys::KeyPair;
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::{Map, Value};
use std::path::Path;

/// A rollout record's `format`.
pub const FORMAT: &str = "tessla-telegraf-rollout/1";

/// What every signed rollout starts with, so that a rollout signature can never be taken for
/// the signature of anything else made with the same key (a NATS login's nonce, a JWT, a
/// decision).
pub const DOMAIN: &[u8] = b"tessla-telegraf rollout signature v1\n";

/// What the channel stores signed: its record's `format`, the member holding it, the domain
/// line its signature starts with, and what a message calls it.
pub trait Signable: Serialize + DeserializeOwned {
    const FORMAT: &'static str;
    const FIELD: &'static str;
    const DOMAIN: &'static [u8];
}

impl Signable for Rollout {
    const FORMAT: &'static str = FORMAT;
    const FIELD: &'static str = "rollout";
    const DOMAIN: &'static [u8] = DOMAIN;
}

impl Signable for Decision {
    const FORMAT: &'static str = "tessla-telegraf-decision/1";
    const FIELD: &'static str = "decision";
    const DOMAIN: &'static [u8] = b"tessla-telegraf decision signature v1\n";
}

/// The environment variable `spec publish` and `spec rollback` read the seed from without
/// `--sign-key-file`.
pub const SIGN_KEY_ENV: &str = "TESSLA_SIGN_KEY";

/// `value` as canonical JSON: objects with their keys sorted (by their UTF-8 bytes), no white
/// space, strings escaped as serde_json escapes them, numbers as serde_json writes them. Two
/// equal values always give the same text, whatever order or spacing they were read with.
pub fn canonical_json(value: &Value) -> String {
    let mut out = String::new();
    write_canonical(value, &mut out);
    out
}

fn write_canonical(value: &Value, out: &mut String) {
    match value {
        Value::Object(map) => {
            let mut keys: Vec<&String> = map.keys().collect();
            keys.sort();
            out.push('{');
            for (i, k) in keys.into_iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                write_string(k, out);
                out.push(':');
                if let Some(v) = map.get(k) {
                    write_canonical(v, out);
                }
            }
            out.push('}');
        }
        Value::Array(items) => {
            out.push('[');
            for (i, v) in items.iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                write_canonical(v, out);
            }
            out.push(']');
        }
        Value::String(s) => write_string(s, out),
        // Null, booleans and numbers: serde_json's text (one form per value).
        other => out.push_str(&other.to_string()),
    }
}

fn write_string(s: &str, out: &mut String) {
    out.push_str(&Value::String(s.to_string()).to_string());
}

/// The bytes a signature covers: the kind's domain line and the canonical JSON of the object.
fn message(domain: &[u8], body: &Value) -> Vec<u8> {
    let mut m = domain.to_vec();
    m.extend_from_slice(canonical_json(body).as_bytes());
    m
}

/// Why an operator's key (a signing seed, a public key to trust) cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    #[error(
        "it is not an NKey seed (a line starting with `S`, as `tessla-telegraf spec keygen` prints it)"
    )]
    NotASeed,
    #[error("it is not a valid NKey seed ({0})")]
    BadSeed(nkeys::error::Error),
    /// Neither `--sign-key-file` nor [`SIGN_KEY_ENV`].
    #[error(
        "no signing key: give the operator's seed with --sign-key-file FILE or the \
         environment variable {SIGN_KEY_ENV} (make one with `tessla-telegraf spec keygen`; \
         every process must trust its public key with --spec-trust)"
    )]
    NoSigningKey,
    #[error(transparent)]
    Unreadable(#[from] SecretError),
    /// The seed read from `origin` is no seed.
    #[error("the signing seed from {origin}: {why}")]
    Seed { origin: String, why: Box<KeyError> },
    /// A seed where a public key belongs (its first two characters).
    #[error(
        "`{0}…` looks like a seed, which is secret: give the public key (the `public key:` line of \
         `tessla-telegraf spec keygen`), and keep the seed on the operator's machine"
    )]
    SeedNotPublic(String),
    #[error("`{key}` is not an NKey public key ({why})")]
    NotAPublicKey {
        key: String,
        why: nkeys::error::Error,
    },
    /// A key given with `--spec-trust` that is no public key.
    #[error("--spec-trust: {0}")]
    Given(Box<KeyError>),
    #[error("--spec-trust-file {path}: {why}")]
    TrustFile { path: String, why: std::io::Error },
    /// A line of the `--spec-trust-file` that is no public key.
    #[error("{path}:{line}: {why}")]
    TrustLine {
        path: String,
        line: usize,
        why: Box<KeyError>,
    },
    /// Neither `--spec-trust` nor `--spec-trust-file` gave a key.
    #[error(
        "a spec channel needs the operator's public key: --spec-trust KEY (or --spec-trust-file \
         FILE); `tessla-telegraf spec keygen` makes a key pair"
    )]
    NoTrustedKey,
}

/// Why a record cannot be signed (`what`: the kind's [`Signable::FIELD`]).
#[derive(Debug, thiserror::Error)]
pub enum SealError {
    #[error("{what}: {why}")]
    Json {
        what: &'static str,
        why: serde_json::Error,
    },
    #[error("cannot sign with this seed: {0}")]
    Sign(nkeys::error::Error),
}

/// The signing key from its seed (`S…`, as `spec keygen` or `nk -gen` writes it).
pub fn signing_key(seed: &str) -> Result<KeyPair, KeyError> {
    let seed = seed.trim();
    if !seed.starts_with('S') {
        return Err(KeyError::NotASeed);
    }
    KeyPair::from_seed(seed).map_err(KeyError::BadSeed)
}

/// The signing key of `spec publish`/`rollback`: the seed in `file`, or else in the environment
/// variable [`SIGN_KEY_ENV`] (never on the command line, where `ps` shows it).
pub fn read_signing_key(file: Option<&Path>) -> Result<KeyPair, KeyError> {
    let source = match file {
        Some(f) => SecretSource::File(f.to_path_buf()),
        None => {
            if std::env::var_os(SIGN_KEY_ENV).is_none() {
                return Err(KeyError::NoSigningKey);
            }
            SecretSource::Env(SIGN_KEY_ENV.into())
        }
    };
    let seed = source.read("signing seed")?;
    signing_key(seed.expose()).map_err(|e| KeyError::Seed {
        origin: source.origin(),
        why: Box::new(e),
    })
}

/// A public key as `--spec-trust` gives it, checked (`O…`, `A…`, `U…`: any NKey public key).
pub fn check_public_key(key: &str) -> Result<String, KeyError> {
    let key = key.trim();
    if key.starts_with('S') {
        return Err(KeyError::SeedNotPublic(key.chars().take(2).collect()));
    }
    KeyPair::from_public_key(key)
        .map(|_| key.to_string())
        .map_err(|why| KeyError::NotAPublicKey {
            key: key.to_string(),
            why,
        })
}

/// The keys a process trusts: `--spec-trust KEY[,KEY]` and the lines of `--spec-trust-file`
/// (one key a line; blank lines and `#` comments ignored), each checked. None at all is an
/// error: a process with a spec channel must know whom to trust.
pub fn trusted_keys(given: &[String], file: Option<&Path>) -> Result<Vec<String>, KeyError> {
    let mut keys = Vec::new();
    for k in given.iter().map(|k| k.trim()).filter(|k| !k.is_empty()) {
        keys.push(check_public_key(k).map_err(|e| KeyError::Given(Box::new(e)))?);
    }
    if let Some(path) = file {
        let text = std::fs::read_to_string(path).map_err(|why| KeyError::TrustFile {
            path: path.display().to_string(),
            why,
        })?;
        for (n, line) in text.lines().enumerate() {
            let line = line.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            keys.push(check_public_key(line).map_err(|e| KeyError::TrustLine {
                path: path.display().to_string(),
                line: n + 1,
                why: Box::new(e),
            })?);
        }
    }
    if keys.is_empty() {
        return Err(KeyError::NoTrustedKey);
    }
    keys.sort();
    keys.dedup();
    Ok(keys)
}

/// The record of `body` (a rollout or a decision), signed with `key`.
pub fn seal<T: Signable>(body: &T, key: &KeyPair) -> Result<Vec<u8>, SealError> {
    let json = |why| SealError::Json {
        what: T::FIELD,
        why,
    };
    let value = serde_json::to_value(body).map_err(json)?;
    let signature = key
        .sign(&message(T::DOMAIN, &value))
        .map_err(SealError::Sign)?;
    let mut record = Map::new();
    record.insert("format".into(), Value::String(T::FORMAT.into()));
    record.insert(T::FIELD.into(), value);
    record.insert("signer".into(), Value::String(key.public_key()));
    record.insert("signature".into(), Value::String(hex(&signature)));
    serde_json::to_vec(&Value::Object(record)).map_err(json)
}

/// Why a signed record (a rollout, a decision) cannot be used: it cannot be read, or its
/// signature is missing, by a key not trusted, or does not verify. `what` is the kind's
/// [`Signable::FIELD`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RecordError {
    #[error("it is not a {what} record (not JSON: {why})")]
    NotJson { what: &'static str, why: String },
    #[error("it is not a {what} record (not a JSON object)")]
    NotAnObject { what: &'static str },
    #[error(
        "its format is `{found}`, not `{expected}` (written by another version of tessla-telegraf?)"
    )]
    OtherFormat {
        found: String,
        expected: &'static str,
    },
    #[error("it is not a {what} record (no `format`: {expected})")]
    NoFormat {
        what: &'static str,
        expected: &'static str,
    },
    #[error("it is not a {what} record (no `{what}`)")]
    NoBody { what: &'static str },
    #[error("its {what} cannot be read: {why}")]
    BadBody { what: &'static str, why: String },
    #[error("it cannot be read, so its signature cannot be checked")]
    Unreadable,
    #[error(
        "it is unsigned: only {what}s signed with the operator's key count (publish with \
         `tessla-telegraf spec publish`, which signs)"
    )]
    Unsigned { what: &'static str },
    #[error(
        "it is signed by key {signer}, which this process does not trust (--spec-trust): \
         only the operator's key may publish"
    )]
    Untrusted { signer: String },
    /// `why`: not a public key, the signature not hex, or the wrong signature.
    #[error(
        "its signature does not verify with key {signer} ({why}): the record was changed \
         after it was signed"
    )]
    DoesNotVerify { signer: String, why: &'static str },
}

/// A record read back, before its signature is checked.
#[derive(Debug, Clone)]
pub struct Record<T: Signable = Rollout> {
    /// The rollout (or decision) it holds (`Err`: why there is none).
    pub body: Result<T, RecordError>,
    /// The public key it names as its signer, if any.
    pub signer: Option<String>,
    value: Option<Value>,
    signature: Option<String>,
}

impl<T: Signable> Record<T> {
    /// Read a record (no signature checked: see [`Record::verify`]).
    pub fn parse(bytes: &[u8]) -> Record<T> {
        let what = T::FIELD;
        let none = |why: RecordError| Record {
            body: Err(why),
            signer: None,
            value: None,
            signature: None,
        };
        let record: Value = match serde_json::from_slice(bytes) {
            Ok(v) => v,
            Err(e) => {
                return none(RecordError::NotJson {
                    what,
                    why: e.to_string(),
                });
            }
        };
        let Some(obj) = record.as_object() else {
            return none(RecordError::NotAnObject { what });
        };
        match obj.get("format").and_then(Value::as_str) {
            Some(f) if f == T::FORMAT => {}
            Some(other) => {
                return none(RecordError::OtherFormat {
                    found: other.to_string(),
                    expected: T::FORMAT,
                });
            }
            None => {
                return none(RecordError::NoFormat {
                    what,
                    expected: T::FORMAT,
                });
            }
        }
        let Some(value) = obj.get(what).cloned() else {
            return none(RecordError::NoBody { what });
        };
        let text = |k: &str| obj.get(k).and_then(Value::as_str).map(str::to_string);
        Record {
            body: serde_json::from_value::<T>(value.clone()).map_err(|e| RecordError::BadBody {
                what,
                why: e.to_string(),
            }),
            signer: text("signer"),
            signature: text("signature"),
            value: Some(value),
        }
    }

    /// Whether the record is signed by one of `trusted` and unchanged since: `Ok`, or which of
    /// unsigned, signed by a key not trusted, or a signature that does not verify.
    pub fn verify(&self, trusted: &[String]) -> Result<(), RecordError> {
        let Some(value) = &self.value else {
            return Err(RecordError::Unreadable);
        };
        let (Some(signer), Some(signature)) = (&self.signer, &self.signature) else {
            return Err(RecordError::Unsigned { what: T::FIELD });
        };
        if !trusted.iter().any(|t| t == signer) {
            return Err(RecordError::Untrusted {
                signer: signer.clone(),
            });
        }
        let bad = |why: &'static str| RecordError::DoesNotVerify {
            signer: signer.clone(),
            why,
        };
        let key = KeyPair::from_public_key(signer).map_err(|_| bad("not a public key"))?;
        let signature = unhex(signature).ok_or_else(|| bad("the signature is not hex"))?;
        key.verify(&message(T::DOMAIN, value), &signature)
            .map_err(|_| bad("wrong signature"))
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(s: &str) -> Option<Vec<u8>> {
    if !s.len().is_multiple_of(2) || !s.is_ascii() {
        return None;
    }
    (0..s.len())
        .step_by(2)
        .map(|i| s.get(i..i + 2).and_then(|h| u8::from_str_radix(h, 16).ok()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::processor::versions::Selector;

    fn rollout() -> Rollout {
        Rollout {
            revision: 3,
            id: "0123456789ab".into(),
            digest: "0123456789ab".repeat(5) + "cdef",
            label: "tighter \"delta\" ü".into(),
            from: 1_700_000_000_000_000_000,
            selector: Selector::parse("robot=r1,r2").unwrap(),
            published: 1_700_000_000_000_000_001,
            fleet: false,
        }
    }

    #[test]
    fn canonical_json_sorts_keys_and_drops_spacing() {
        let a: Value = serde_json::from_str(
            r#"{ "b": [1, {"z": null, "a": true}], "a": "x\"\n", "c": -1.5 }"#,
        )
        .unwrap();
        let b: Value =
            serde_json::from_str(r#"{"c":-1.5,"a":"x\"\n","b":[1,{"a":true,"z":null}]}"#).unwrap();
        let text = canonical_json(&a);
        assert_eq!(
            text,
            r#"{"a":"x\"\n","b":[1,{"a":true,"z":null}],"c":-1.5}"#
        );
        assert_eq!(canonical_json(&b), text);
        // Its own canonical form.
        let again: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(canonical_json(&again), text);
        // Keys by their bytes: upper case before lower case, a prefix first.
        let k: Value = serde_json::from_str(r#"{"ab":1,"a":2,"B":3,"é":4}"#).unwrap();
        assert_eq!(canonical_json(&k), r#"{"B":3,"a":2,"ab":1,"é":4}"#);
    }

    #[test]
    fn a_sealed_rollout_verifies_with_its_key_only() {
        let key = KeyPair::new_operator();
        let r = rollout();
        let bytes = seal(&r, &key).unwrap();
        let rec = Record::<Rollout>::parse(&bytes);
        assert_eq!(rec.body.as_ref().unwrap(), &r);
        assert_eq!(rec.signer.as_deref(), Some(key.public_key().as_str()));
        assert_eq!(rec.verify(&[key.public_key()]), Ok(()));
        // Another key trusted: refused as untrusted, naming the signer.
        let other = KeyPair::new_operator();
        let e = rec.verify(&[other.public_key()]).unwrap_err().to_string();
        assert!(
            e.contains("does not trust") && e.contains(&key.public_key()),
            "{e}"
        );
        // Re-spaced and reordered: still verifies (the signature covers the canonical form).
        let v: Value = serde_json::from_slice(&bytes).unwrap();
        let pretty = serde_json::to_vec_pretty(&v).unwrap();
        assert_eq!(
            Record::<Rollout>::parse(&pretty).verify(&[key.public_key()]),
            Ok(())
        );
    }

    #[test]
    fn a_changed_unsigned_or_foreign_record_is_refused_saying_why() {
        let key = KeyPair::new_operator();
        let trusted = [key.public_key()];
        let bytes = seal(&rollout(), &key).unwrap();
        // Any field changed after signing: the digest, the selector, the start.
        for (field, new) in [
            ("digest", Value::String("f".repeat(64))),
            ("selector", Value::String(String::new())),
            ("from", Value::from(0)),
        ] {
            let mut v: Value = serde_json::from_slice(&bytes).unwrap();
            v["rollout"][field] = new;
            let e = Record::<Rollout>::parse(&serde_json::to_vec(&v).unwrap())
                .verify(&trusted)
                .unwrap_err()
                .to_string();
            assert!(e.contains("does not verify"), "{field}: {e}");
        }
        // A field added to the rollout is covered too.
        let mut v: Value = serde_json::from_slice(&bytes).unwrap();
        v["rollout"]["extra"] = Value::from(1);
        assert!(
            Record::<Rollout>::parse(&serde_json::to_vec(&v).unwrap())
                .verify(&trusted)
                .is_err()
        );
        // Unsigned.
        let mut v: Value = serde_json::from_slice(&bytes).unwrap();
        v.as_object_mut().unwrap().remove("signature");
        let e = Record::<Rollout>::parse(&serde_json::to_vec(&v).unwrap())
            .verify(&trusted)
            .unwrap_err()
            .to_string();
        assert!(e.contains("unsigned"), "{e}");
        // Signed by another key that names itself: untrusted.
        let foreign = KeyPair::new_operator();
        let e = Record::<Rollout>::parse(&seal(&rollout(), &foreign).unwrap())
            .verify(&trusted)
            .unwrap_err()
            .to_string();
        assert!(e.contains("does not trust"), "{e}");
        // The trusted key named, but the signature made by another: does not verify.
        let mut v: Value = serde_json::from_slice(&seal(&rollout(), &foreign).unwrap()).unwrap();
        v["signer"] = Value::String(key.public_key());
        let e = Record::<Rollout>::parse(&serde_json::to_vec(&v).unwrap())
            .verify(&trusted)
            .unwrap_err()
            .to_string();
        assert!(e.contains("does not verify"), "{e}");
        // Not a record at all.
        let rec = Record::<Rollout>::parse(b"{\"revision\":1}");
        assert!(rec.body.is_err() && rec.verify(&trusted).is_err());
    }

    #[test]
    fn keys_are_checked_and_a_seed_is_never_taken_for_a_public_key() {
        let key = KeyPair::new_operator();
        let seed = key.seed().unwrap();
        assert_eq!(
            signing_key(&format!("{seed}\n")).unwrap().public_key(),
            key.public_key()
        );
        assert!(signing_key(&key.public_key()).is_err());
        let e = check_public_key(&seed).unwrap_err().to_string();
        assert!(e.contains("seed") && !e.contains(&seed[2..]), "{e}");
        assert!(check_public_key("Onot-a-key").is_err());
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("trust");
        let second = KeyPair::new_account().public_key();
        std::fs::write(&f, format!("# the operators\n{second}  # ops\n\n")).unwrap();
        let keys = trusted_keys(&[key.public_key()], Some(&f)).unwrap();
        assert_eq!(keys.len(), 2);
        assert!(trusted_keys(&[], None).is_err());
        std::fs::write(&f, "garbage\n").unwrap();
        let e = trusted_keys(&[], Some(&f)).unwrap_err().to_string();
        assert!(e.contains(":1:"), "{e}");
    }
}
