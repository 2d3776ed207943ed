//! The connection to NATS: async-nats on a runtime thread of its own (so lease renewals go on
//! while the step loop is busy), credentials and TLS through the crate's own options, and
//! every way that can fail told apart ([`Failure`]: refused
//! credentials, TLS, an unreachable server, a denied permission).

use super::url::{Auth, Url};

use super::secrets::SecretSource;
use crate::log::mask;
use std::future::Future;
use std::io;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// How long any one request to NATS may take.
pub(crate) const REQUEST_TIMEOUT: Duration = Duration::from_secs(2);

/// The runtime thread that owns the connection; requests are sent to it and waited for.
pub(crate) struct Conn {
    pub(crate) handle: tokio::runtime::Handle,
    _stop: tokio::sync::oneshot::Sender<()>,
}

impl Conn {
    pub(crate) fn start() -> io::Result<Conn> {
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
    pub(crate) fn call<T: Send + 'static>(
        &self,
        f: impl Future<Output = T> + Send + 'static,
    ) -> Option<T> {
        let (tx, rx) = std::sync::mpsc::channel();
        self.handle.spawn(async move {
            let _ = tx.send(f.await);
        });
        rx.recv().ok()
    }
}

pub(crate) fn err(e: impl std::fmt::Display) -> io::Error {
    io::Error::other(e.to_string())
}

/// Why connecting failed: a mistake in the URL's credentials or TLS files (exit 2), or the
/// connection itself (exit 3; unreachable, refused credentials, TLS, permissions).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Failure {
    /// A mistake in the URL's credentials or TLS files.
    #[error("{0}")]
    Config(String),
    /// The connection: unreachable, refused credentials, TLS, permissions.
    #[error("{0}")]
    Io(String),
}

impl Failure {
    /// A configuration mistake, told as `e` tells it.
    pub fn config(e: impl std::fmt::Display) -> Failure {
        Failure::Config(e.to_string())
    }

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
                    log_debug!("state: NATS server error: {}", mask(&text));
                    if let Ok(mut v) = violations.lock() {
                        v.push(text);
                    }
                }
            }
        });
    options = match &url.auth {
        Auth::None => options,
        Auth::UserPassword { user, password } => {
            let password = password.read("NATS password").map_err(Failure::config)?;
            options.user_and_password(user.clone(), password.expose().to_string())
        }
        Auth::Token(t) => {
            let token = t.read("NATS token").map_err(Failure::config)?;
            options.token(token.expose().to_string())
        }
        Auth::NKey(path) => {
            let seed = SecretSource::File(path.clone())
                .read("NKey seed")
                .map_err(Failure::config)?;
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
/// Connect to `url`'s servers with its login and TLS: the client, and the list into which the
/// server's permission violations are put (see [`violation`]).
pub(crate) async fn connect(
    url: &Url,
) -> Result<(async_nats::Client, Arc<Mutex<Vec<String>>>), Failure> {
    let violations = Arc::new(Mutex::new(Vec::new()));
    let options = connect_options(url, Arc::clone(&violations)).await?;
    let client = options
        .connect(url.servers.clone())
        .await
        .map_err(|e| Failure::Io(connect_failure(url, &e)))?;
    Ok((client, violations))
}

fn connect_failure(url: &Url, e: &async_nats::ConnectError) -> String {
    use async_nats::ConnectErrorKind as K;
    let at = url.shown();
    // The crate's error text names no secret (kind and source: an I/O or TLS error).
    let detail = mask(&e.to_string());
    match e.kind() {
        K::AuthorizationViolation | K::Authentication if url.auth == Auth::None => format!(
            "authorization failed at {at}: the server requires credentials and none were given \
             ({detail}); add user=NAME&password-env=VAR (or token-env, nkey-file, creds) to --state \
             (the book, \"Security\")"
        ),
        K::AuthorizationViolation | K::Authentication => format!(
            "authorization failed at {at}: the server refused this process's credentials ({}; {detail}); \
             check the user and password, token, nkey-file or creds in --state against the server's \
             accounts (the book, \"Security\")",
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
pub(crate) fn looks_like_tls(url: &Url, detail: &str) -> bool {
    let d = detail.to_ascii_lowercase();
    d.contains("certificate")
        || d.contains("tls")
        || d.contains("handshake")
        || (url.tls.required && !d.contains("refused"))
}

pub(crate) fn tls_failure(at: &str, detail: &str) -> String {
    format!(
        "TLS failed with {at}: {detail}; check tls-ca=PATH (the CA that signed the servers' \
             certificates), the server name in the URL against the certificate, and tls-cert/tls-key \
             when the servers ask for a client certificate (and that the server speaks TLS)"
    )
}

/// A permission violation the server reported for this connection, if any.
pub(crate) fn violation(violations: &Mutex<Vec<String>>) -> Option<String> {
    violations.lock().ok().and_then(|v| {
        v.iter()
            .find(|t| t.to_ascii_lowercase().contains("permissions violation"))
            .cloned()
    })
}

pub(crate) fn permission_failure(url: &Url, text: &str) -> String {
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

pub fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|s| s.trim().to_string())
        .unwrap_or_else(|_| "host".into())
}
