//! `--state nats://HOST:PORT[,HOST:PORT...]/BUCKET[?options]`: monitor state in a JetStream
//! key-value bucket, shared by the processes of a fleet, and the partition lease.
//!
//! Owns: parsing the URL ([`Url`], with its login: user and password, token, NKey seed, `.creds`
//! file, TLS files; secrets never shown, [`mask`] for any text), the connection (async-nats on a
//! runtime thread of its own, so lease renewals go on while the step loop is busy; credentials and
//! TLS through the crate's own options; refused credentials, TLS, an unreachable server and a
//! denied permission each told apart, [`Failure`]), bucket creation, instance keys as NATS
//! KV keys ([`kv_key`]), one entry per instance (the format of [`super::state`]: magic, version,
//! fingerprint), restoring an instance when its first record arrives, saving every instance,
//! setting a foreign or corrupt entry aside (`aside.<key>.<unix seconds>`, with a warning), and
//! the lease ([`Lease`]): one key per partition, held by one process at a time (create if absent,
//! renewed by compare-and-set on its revision, taken over by compare-and-set when it has not
//! changed for the lease TTL, deleted on a clean stop), with the operator mistakes caught: a lease
//! live in another bucket refuses the start, a long standby reports partitions nobody holds.
//! The design and its guarantees are in
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

/// A secret (password, token, NKey seed): never shown, also not by `{:?}`.
#[derive(Clone, PartialEq)]
pub struct Secret(String);

impl Secret {
    pub fn new(s: impl Into<String>) -> Secret {
        Secret(s.into())
    }

    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl std::fmt::Debug for Secret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("***")
    }
}

/// Where a secret comes from: the URL itself, an environment variable or a file (the last two
/// keep it out of `ps` and of Telegraf's config).
#[derive(Debug, Clone, PartialEq)]
pub enum SecretSource {
    Given(Secret),
    Env(String),
    File(std::path::PathBuf),
}

impl SecretSource {
    /// The secret, read now (a file's trailing newline removed). The error names the variable
    /// or file, never the value.
    pub fn read(&self, what: &str) -> Result<Secret, String> {
        let value = match self {
            SecretSource::Given(s) => return Ok(s.clone()),
            SecretSource::Env(var) => std::env::var(var).map_err(|_| {
                format!("the {what} is to come from environment variable {var}, which is not set (or not UTF-8)")
            })?,
            SecretSource::File(path) => std::fs::read_to_string(path)
                .map_err(|e| format!("cannot read the {what} from {}: {e}", path.display()))?
                .trim_end_matches(['\r', '\n'])
                .to_string(),
        };
        if value.is_empty() {
            return Err(format!("the {what} from {} is empty", self.origin()));
        }
        Ok(Secret(value))
    }

    fn origin(&self) -> String {
        match self {
            SecretSource::Given(_) => "the URL".into(),
            SecretSource::Env(v) => format!("environment variable {v}"),
            SecretSource::File(p) => p.display().to_string(),
        }
    }
}

/// How the process authenticates to NATS (the client crate does the protocol).
#[derive(Debug, Clone, PartialEq)]
pub enum Auth {
    None,
    /// `nats://USER:PASSWORD@...`, or `?user=USER&password-env=VAR` / `password-file=PATH`.
    UserPassword {
        user: String,
        password: SecretSource,
    },
    /// `nats://TOKEN@...`, or `?token-env=VAR` / `token-file=PATH`.
    Token(SecretSource),
    /// `?nkey-file=PATH`: a file holding an NKey seed (`SU...`).
    NKey(std::path::PathBuf),
    /// `?creds=PATH`: a `.creds` file (user JWT and NKey seed, as `nsc` writes it).
    Creds(std::path::PathBuf),
}

/// TLS settings: `?tls=1` (require TLS), `tls-ca=PATH`, `tls-cert=PATH` and `tls-key=PATH`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Tls {
    pub required: bool,
    pub ca: Option<std::path::PathBuf>,
    pub cert: Option<std::path::PathBuf>,
    pub key: Option<std::path::PathBuf>,
}

/// The expected form of `--state nats://...`, for error messages.
pub const FORM: &str =
    "nats://HOST:PORT[,HOST:PORT...]/BUCKET[?lease=NAME&user=NAME&password-env=VAR&tls-ca=PATH...]";

/// `text` with the user-info of every `scheme://USERINFO@` (or `scheme:/USERINFO@`) replaced: `USER:***@`, or `***@`
/// for a token. For anything shown to a person (messages, logs) that may hold a URL.
pub fn mask(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    // `scheme:/` too: a path that went through normalisation loses one of the two slashes.
    while let Some(i) = rest.find(":/") {
        let slashes = rest[i + 1..].bytes().take_while(|&b| b == b'/').count();
        let (head, tail) = rest.split_at(i + 1 + slashes);
        out.push_str(head);
        // The authority ends at the first `/`, `?`, `#` or white space; its user-info at its
        // last `@`.
        let end = tail
            .find(|c: char| {
                c == '/'
                    || c == '?'
                    || c == '#'
                    || c.is_whitespace()
                    || c == '\''
                    || c == '"'
                    || c == '`'
            })
            .unwrap_or(tail.len());
        let authority = &tail[..end];
        match authority.rfind('@') {
            Some(at) => {
                let info = &authority[..at];
                match info.split_once(':') {
                    Some((user, _)) => {
                        out.push_str(user);
                        out.push_str(":***");
                    }
                    None => out.push_str("***"),
                }
                out.push_str(&authority[at..]);
            }
            None => out.push_str(authority),
        }
        rest = &tail[end..];
    }
    out.push_str(rest);
    out
}

fn percent_decode(s: &str) -> Result<String, String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = s
                .get(i + 1..i + 3)
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or("a `%` in the user or password must be followed by two hex digits")?;
            out.push(hex);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).map_err(|_| "the user or password is not UTF-8 once decoded".to_string())
}

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
    pub auth: Auth,
    pub tls: Tls,
}

impl Url {
    pub fn parse(s: &str) -> Result<Url, String> {
        let shown = mask(s);
        let form = |why: String| format!("`{shown}`: {why} (expected {FORM})");
        let rest = match s.split_once("://") {
            Some((scheme, rest)) if scheme.eq_ignore_ascii_case("nats") => rest,
            Some((scheme, _)) => {
                return Err(form(format!(
                    "scheme `{scheme}://` is not a state store (a file: give its path; NATS over TLS: \
                     nats://...?tls-ca=PATH)"
                )));
            }
            None => {
                return Err(form(
                    "not a URL: `nats:` must be followed by `//` (to name a file called so, write ./nats:...)"
                        .into(),
                ));
            }
        };
        let (rest, query) = rest.split_once('?').unwrap_or((rest, ""));
        // The user-info ends at the last `@` (a bucket name has none).
        let (userinfo, rest) = match rest.rsplit_once('@') {
            Some((info, rest)) => (Some(info), rest),
            None => (None, rest),
        };
        let (hosts, bucket) = rest
            .split_once('/')
            .ok_or_else(|| form("no bucket".into()))?;
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
            return Err(form("no server".into()));
        }
        if bucket.is_empty()
            || !bucket
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err(format!(
                "`{shown}`: bucket `{bucket}` must be letters, digits, `_` or `-`"
            ));
        }
        let mut auth = match userinfo {
            None => Auth::None,
            Some(info) => match info.split_once(':') {
                Some((user, password)) => Auth::UserPassword {
                    user: percent_decode(user).map_err(&form)?,
                    password: SecretSource::Given(Secret(percent_decode(password).map_err(&form)?)),
                },
                None => Auth::Token(SecretSource::Given(Secret(
                    percent_decode(info).map_err(&form)?,
                ))),
            },
        };
        let mut url = Url {
            servers,
            bucket: bucket.to_string(),
            lease: None,
            ttl: DEFAULT_TTL,
            replicas: 1,
            auth: Auth::None,
            tls: Tls::default(),
        };
        let mut user: Option<String> = None;
        let mut password: Option<SecretSource> = None;
        let set_auth = |a: Auth, auth: &mut Auth| -> Result<(), String> {
            if *auth != Auth::None {
                return Err(format!(
                    "`{shown}`: more than one way to authenticate (user and password, token, nkey-file, creds: pick one)"
                ));
            }
            *auth = a;
            Ok(())
        };
        for pair in query.split('&').filter(|p| !p.is_empty()) {
            let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
            let path = || -> Result<std::path::PathBuf, String> {
                if v.is_empty() {
                    Err(format!("`{shown}`: `{k}` needs a value"))
                } else {
                    Ok(std::path::PathBuf::from(v))
                }
            };
            match k {
                "lease" if !v.is_empty() => url.lease = Some(v.to_string()),
                "ttl" => {
                    url.ttl = humantime::parse_duration(v)
                        .map_err(|e| format!("`{shown}`: ttl `{v}`: {e}"))?;
                    if url.ttl < Duration::from_millis(200) {
                        return Err(format!("`{shown}`: ttl must be at least 200ms"));
                    }
                }
                "replicas" => {
                    url.replicas = v
                        .parse()
                        .ok()
                        .filter(|n| (1..=5).contains(n))
                        .ok_or_else(|| format!("`{shown}`: replicas must be 1 to 5"))?;
                }
                "user" if !v.is_empty() => user = Some(v.to_string()),
                "password-env" if !v.is_empty() => password = Some(SecretSource::Env(v.into())),
                "password-file" => password = Some(SecretSource::File(path()?)),
                "token-env" if !v.is_empty() => {
                    set_auth(Auth::Token(SecretSource::Env(v.into())), &mut auth)?
                }
                "token-file" => set_auth(Auth::Token(SecretSource::File(path()?)), &mut auth)?,
                "nkey-file" => set_auth(Auth::NKey(path()?), &mut auth)?,
                "creds" => set_auth(Auth::Creds(path()?), &mut auth)?,
                "tls" => {
                    url.tls.required = match v {
                        "1" | "true" | "yes" | "" => true,
                        "0" | "false" | "no" => false,
                        _ => return Err(format!("`{shown}`: tls must be 1 or 0")),
                    }
                }
                "tls-ca" => url.tls.ca = Some(path()?),
                "tls-cert" => url.tls.cert = Some(path()?),
                "tls-key" => url.tls.key = Some(path()?),
                _ => {
                    let shown_pair = if k.contains("password") || k.contains("token") {
                        format!("{k}=***")
                    } else {
                        pair.to_string()
                    };
                    return Err(format!(
                        "`{shown}`: unknown option `{shown_pair}` (known: lease=NAME, ttl=DURATION, replicas=N, \
                         user=NAME, password-env=VAR, password-file=PATH, token-env=VAR, token-file=PATH, \
                         nkey-file=PATH, creds=PATH, tls=1, tls-ca=PATH, tls-cert=PATH, tls-key=PATH)"
                    ));
                }
            }
        }
        match (user, password) {
            (Some(user), Some(password)) => {
                set_auth(Auth::UserPassword { user, password }, &mut auth)?
            }
            (Some(user), None) => match &mut auth {
                Auth::UserPassword { user: u, .. } => *u = user,
                _ => {
                    return Err(format!(
                        "`{shown}`: user={user} needs a password: password-env=VAR or password-file=PATH"
                    ));
                }
            },
            (None, Some(password)) => match &mut auth {
                Auth::UserPassword { password: p, .. } => *p = password,
                _ => {
                    return Err(format!(
                        "`{shown}`: a password needs a user: user=NAME (or nats://USER@...)"
                    ));
                }
            },
            (None, None) => {}
        }
        if url.tls.cert.is_some() != url.tls.key.is_some() {
            return Err(format!(
                "`{shown}`: a client certificate needs both tls-cert=PATH and tls-key=PATH"
            ));
        }
        if url.tls.ca.is_some() || url.tls.cert.is_some() {
            url.tls.required = true;
        }
        url.auth = auth;
        Ok(url)
    }

    /// The URL as shown in messages: servers and bucket, the user name, never a secret.
    pub fn shown(&self) -> String {
        let who = match &self.auth {
            Auth::UserPassword { user, .. } => format!("{user}:***@"),
            Auth::Token(_) => "***@".into(),
            _ => String::new(),
        };
        format!("nats://{who}{}/{}", self.servers.join(","), self.bucket)
    }

    /// Who this process connects as, for messages.
    fn identity(&self) -> String {
        match &self.auth {
            Auth::None => "without credentials".into(),
            Auth::UserPassword { user, password } => {
                format!("as user `{user}` (password from {})", password.origin())
            }
            Auth::Token(t) => format!("with a token (from {})", t.origin()),
            Auth::NKey(p) => format!("with the NKey seed in {}", p.display()),
            Auth::Creds(p) => format!("with the credentials file {}", p.display()),
        }
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

/// Why connecting failed: a mistake in the URL's credentials or TLS files (exit 2), or the
/// connection itself (exit 3; unreachable, refused credentials, TLS, permissions).
#[derive(Debug, Clone, PartialEq)]
pub enum Failure {
    Config(String),
    Io(String),
}

impl Failure {
    pub fn message(&self) -> &str {
        match self {
            Failure::Config(m) | Failure::Io(m) => m,
        }
    }
}

/// The connect options of `url`: credentials and TLS through the client crate's own support.
async fn connect_options(
    url: &Url,
    violations: Arc<Mutex<Vec<String>>>,
) -> Result<async_nats::ConnectOptions, Failure> {
    let mut options = async_nats::ConnectOptions::new()
        .request_timeout(Some(REQUEST_TIMEOUT))
        .connection_timeout(REQUEST_TIMEOUT)
        .name(format!("tessla-telegraf {}", url.bucket))
        .event_callback(move |event| {
            let violations = Arc::clone(&violations);
            async move {
                if let async_nats::Event::ServerError(e) = event {
                    let text = e.to_string();
                    log::log(
                        Level::Debug,
                        &format!("state: NATS server error: {}", mask(&text)),
                    );
                    if let Ok(mut v) = violations.lock() {
                        v.push(text);
                    }
                }
            }
        });
    options = match &url.auth {
        Auth::None => options,
        Auth::UserPassword { user, password } => {
            let password = password.read("NATS password").map_err(Failure::Config)?;
            options.user_and_password(user.clone(), password.expose().to_string())
        }
        Auth::Token(t) => {
            let token = t.read("NATS token").map_err(Failure::Config)?;
            options.token(token.expose().to_string())
        }
        Auth::NKey(path) => {
            let seed = SecretSource::File(path.clone())
                .read("NKey seed")
                .map_err(Failure::Config)?;
            if !seed.expose().starts_with('S') {
                return Err(Failure::Config(format!(
                    "{} does not hold an NKey seed (a line starting with `SU`, as `nk -gen user` writes it)",
                    path.display()
                )));
            }
            options.nkey(seed.expose().to_string())
        }
        Auth::Creds(path) => options.credentials_file(path).await.map_err(|e| {
            // The crate's message may quote the file; say only which file and what kind.
            Failure::Config(format!(
                "cannot use the credentials file {}: {} (expected a .creds file as `nsc` writes it: a user JWT and an NKey seed)",
                path.display(),
                e.kind()
            ))
        })?,
    };
    for p in [&url.tls.ca, &url.tls.cert, &url.tls.key]
        .into_iter()
        .flatten()
    {
        if let Err(e) = std::fs::metadata(p) {
            return Err(Failure::Config(format!("TLS file {}: {e}", p.display())));
        }
    }
    if let Some(ca) = &url.tls.ca {
        options = options.add_root_certificates(ca.clone());
    }
    if let (Some(cert), Some(key)) = (&url.tls.cert, &url.tls.key) {
        options = options.add_client_certificate(cert.clone(), key.clone());
    }
    if url.tls.required {
        options = options.require_tls(true);
    }
    Ok(options)
}

/// The message for a failed connection: refused credentials, TLS, or no server, each its own.
fn connect_failure(url: &Url, e: &async_nats::ConnectError) -> String {
    use async_nats::ConnectErrorKind as K;
    let at = url.shown();
    // The crate's error text names no secret (kind and source: an I/O or TLS error).
    let detail = mask(&e.to_string());
    match e.kind() {
        K::AuthorizationViolation | K::Authentication if url.auth == Auth::None => format!(
            "authorization failed at {at}: the server requires credentials and none were given \
             ({detail}); add user=NAME&password-env=VAR (or token-env, nkey-file, creds) to --state \
             (README, \"Security\")"
        ),
        K::AuthorizationViolation | K::Authentication => format!(
            "authorization failed at {at}: the server refused this process's credentials ({}; {detail}); \
             check the user and password, token, nkey-file or creds in --state against the server's \
             accounts (README, \"Security\")",
            url.identity()
        ),
        K::Tls => tls_failure(&at, &detail),
        K::Io if looks_like_tls(url, &detail) => tls_failure(&at, &detail),
        _ => format!(
            "cannot connect to {at}: no NATS server answered ({detail}); is nats-server running there, \
             and are the hosts and ports right?"
        ),
    }
}

/// An I/O error during the TLS handshake (the crate reports some as I/O): a certificate the
/// client does not trust, or a TLS client meeting a plain server.
fn looks_like_tls(url: &Url, detail: &str) -> bool {
    let d = detail.to_ascii_lowercase();
    d.contains("certificate")
        || d.contains("tls")
        || d.contains("handshake")
        || (url.tls.required && !d.contains("refused"))
}

fn tls_failure(at: &str, detail: &str) -> String {
    format!(
        "TLS failed with {at}: {detail}; check tls-ca=PATH (the CA that signed the servers' \
             certificates), the server name in the URL against the certificate, and tls-cert/tls-key \
             when the servers ask for a client certificate (and that the server speaks TLS)"
    )
}

/// A permission violation the server reported for this connection, if any.
fn violation(violations: &Mutex<Vec<String>>) -> Option<String> {
    violations.lock().ok().and_then(|v| {
        v.iter()
            .find(|t| t.to_ascii_lowercase().contains("permissions violation"))
            .cloned()
    })
}

fn permission_failure(url: &Url, text: &str) -> String {
    format!(
        "not permitted at {}: the server denied this process ({}) access to bucket {}: {}; \
         the user's permissions must allow the JetStream API of the bucket (\"$JS.API.>\" for \
         stream KV_{b} and \"$KV.{b}.>\", see telegraf/fleet-nats/accounts.conf)",
        url.shown(),
        url.identity(),
        url.bucket,
        mask(text),
        b = url.bucket
    )
}

/// Connect and open (or create) the bucket.
async fn open(url: Url) -> Result<kv::Store, Failure> {
    let violations = Arc::new(Mutex::new(Vec::new()));
    let options = connect_options(&url, Arc::clone(&violations)).await?;
    let client = options
        .connect(url.servers.clone())
        .await
        .map_err(|e| Failure::Io(connect_failure(&url, &e)))?;
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
                log::log(
                    Level::Info,
                    &format!(
                        "state: created bucket {} ({} replicas); every process of the fleet must name this bucket",
                        url.bucket, url.replicas
                    ),
                );
                return Ok(store);
            }
            Err(e) => last = e,
        }
        if let Some(v) = violation(&violations) {
            return Err(Failure::Io(permission_failure(&url, &v)));
        }
    }
    Err(Failure::Io(last))
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
    /// Connect (once: an unreachable server, refused credentials, a TLS or permission failure
    /// stop the process with a message saying which; Telegraf restarts it after `restart_delay`).
    pub fn connect(url: &Url, proc: &Processor, ctx: &Context) -> Result<NatsBackend, Failure> {
        let conn =
            Conn::start().map_err(|e| Failure::Io(format!("cannot start the NATS thread: {e}")))?;
        let store = conn
            .call(open(url.clone()))
            .ok_or_else(|| Failure::Io("the NATS thread stopped".to_string()))??;
        Ok(NatsBackend {
            url: url.clone(),
            conn,
            store,
            fingerprint: state::fingerprint(proc.program(), ctx),
            seen: HashSet::new(),
        })
    }

    /// Start holding (or waiting for) the lease named in the URL, if any. (A lease live in
    /// another bucket was refused by [`NatsBackend::connect`].)
    pub fn lease(&self) -> Option<Lease> {
        let name = self.url.lease.clone()?;
        let key = format!("lease.{}", kv_key_part_of(&name));
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

/// Another KV bucket of the account where `key` (a lease) is live: present and renewed within
/// the TTL (its revision changes while watched). `None` also when the account may not list
/// streams (the shipped permissions allow one bucket only, which rules the mistake out).
async fn lease_elsewhere(
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
        state::warn_unsaved(unsaved);
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

/// The partition name of lease key `lease.v<name>` (its encoding undone for the usual names).
fn partition_of(key: &str) -> String {
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
        log::log(
            Level::Info,
            &format!(
                "lease: partition {own_name}: standing by for {waited}; its holder renews the lease"
            ),
        );
    } else {
        log::log(
            Level::Warn,
            &format!(
                "lease: partition {own_name}: standing by for {waited}, while nobody holds partition(s) {}: \
                 their robots get no actions. If this Telegraf reads one of those partitions (the N in its \
                 nats_consumer subjects fleet.N.robots.*), its --state has the wrong ?lease= name",
                free.join(", ")
            ),
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
    fn credentials_and_tls_parse_and_are_never_shown() {
        let u = Url::parse("nats://monitor:S%40cret@a:1/b?lease=p0").unwrap();
        assert_eq!(
            u.auth,
            Auth::UserPassword {
                user: "monitor".into(),
                password: SecretSource::Given(Secret::new("S@cret"))
            }
        );
        assert_eq!(u.shown(), "nats://monitor:***@a:1/b");
        assert!(!format!("{u:?}").contains("S@cret"));
        let u = Url::parse("nats://a:1/b?user=m&password-env=PW&tls-ca=/ca.pem").unwrap();
        assert_eq!(
            u.auth,
            Auth::UserPassword {
                user: "m".into(),
                password: SecretSource::Env("PW".into())
            }
        );
        assert!(u.tls.required);
        let u = Url::parse("nats://Tok3n@a/b").unwrap();
        assert_eq!(
            u.auth,
            Auth::Token(SecretSource::Given(Secret::new("Tok3n")))
        );
        assert_eq!(u.shown(), "nats://***@a:4222/b");
        let u = Url::parse("nats://a/b?creds=/x.creds&tls-cert=/c&tls-key=/k").unwrap();
        assert_eq!(u.auth, Auth::Creds("/x.creds".into()));
        assert_eq!(
            Url::parse("nats://a/b?nkey-file=/s.nk").unwrap().auth,
            Auth::NKey("/s.nk".into())
        );
        for bad in [
            "nats://u:p@a/b?creds=/x",
            "nats://a/b?user=u",
            "nats://a/b?password-env=X",
            "nats://a/b?tls-cert=/c",
            "nats:/a:1/b",
            "tls://a:1/b",
        ] {
            let e = Url::parse(bad).unwrap_err();
            assert!(e.contains("nats://"), "{bad}: {e}");
        }
        let e = Url::parse("nats://u:Sup3rSecret@a/b?x=1").unwrap_err();
        assert!(!e.contains("Sup3rSecret") && e.contains("u:***@a/b"), "{e}");
    }

    #[test]
    fn mask_hides_user_info_in_any_text() {
        assert_eq!(
            mask("x 'nats://u:pw@h:1,h:2/b?lease=p0' and mqtt://tok@h/ and nats://h/b"),
            "x 'nats://u:***@h:1,h:2/b?lease=p0' and mqtt://***@h/ and nats://h/b"
        );
        assert_eq!(mask("nats://u:p@ss@h/b"), "nats://u:***@h/b");
        assert_eq!(mask("`nats:/u:pw@h:1/b`"), "`nats:/u:***@h:1/b`");
        assert_eq!(mask("a: /x and 12:30"), "a: /x and 12:30");
        assert_eq!(partition_of("lease.vp0"), "p0");
        assert_eq!(partition_of("lease.vp_2e1"), "p.1");
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
