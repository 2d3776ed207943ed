//! What `--state nats://HOST:PORT[,HOST:PORT...]/BUCKET[?options]` says: servers, bucket,
//! partition lease and its TTL, replicas, the login ([`Auth`]: user and password, token, NKey
//! seed, `.creds` file) and TLS files, each option checked with a message that names it and
//! never shows a secret.

use super::secrets::{Secret, SecretSource};
use crate::log::mask;
use std::time::Duration;

/// Default lease TTL: a standby takes over this long after the holder's last renewal.
pub const DEFAULT_TTL: Duration = Duration::from_secs(3);

/// How the process authenticates to NATS (the client crate does the protocol).
#[derive(Debug, Clone, Default, PartialEq)]
pub enum Auth {
    #[default]
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

/// Why a `nats://` URL is refused. Every message shows the URL with its secrets masked
/// (`shown`) and names what is at fault ([`Problem`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UrlError {
    /// The URL's shape (scheme, servers, bucket, the user-info): told with the expected form.
    #[error("`{shown}`: {why} (expected {FORM})")]
    Form { shown: String, why: Problem },
    /// The bucket's name, an option, or the login the options make.
    #[error("`{shown}`: {why}")]
    Option { shown: String, why: Problem },
}

/// What is wrong in a `nats://` URL, as told after the URL itself.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Problem {
    #[error(
        "scheme `{0}://` is not a state store (a file: give its path; NATS over TLS: \
         nats://...?tls-ca=PATH)"
    )]
    Scheme(String),
    #[error(
        "not a URL: `nats:` must be followed by `//` (to name a file called so, write ./nats:...)"
    )]
    NoSlashes,
    #[error("no bucket")]
    NoBucket,
    #[error("no server")]
    NoServer,
    #[error("bucket `{0}` must be letters, digits, `_` or `-`")]
    BadBucket(String),
    #[error("the user or password is not UTF-8 once decoded")]
    NotUtf8,
    #[error(
        "more than one way to authenticate (user and password, token, nkey-file, creds: pick one)"
    )]
    TwoLogins,
    #[error("user={0} needs a password: password-env=VAR or password-file=PATH")]
    NoPassword(String),
    #[error("a password needs a user: user=NAME (or nats://USER@...)")]
    NoUser,
    #[error("`{0}` needs a value")]
    NoValue(String),
    #[error("ttl `{value}`: {why}")]
    Ttl {
        value: String,
        why: humantime::DurationError,
    },
    #[error("ttl must be at least 200ms")]
    TtlTooShort,
    #[error("replicas must be 1 to 5")]
    Replicas,
    #[error("tls must be 1 or 0")]
    TlsFlag,
    /// An unknown option, shown without its value when it may hold a secret.
    #[error(
        "unknown option `{0}` (known: lease=NAME, ttl=DURATION, replicas=N, \
         user=NAME, password-env=VAR, password-file=PATH, token-env=VAR, token-file=PATH, \
         nkey-file=PATH, creds=PATH, tls=1, tls-ca=PATH, tls-cert=PATH, tls-key=PATH)"
    )]
    Unknown(String),
    #[error("a client certificate needs both tls-cert=PATH and tls-key=PATH")]
    HalfCertificate,
}

/// A user name or password as written in the URL, `%XX` escapes decoded.
fn percent_decode(s: &str) -> Result<String, Problem> {
    percent_encoding::percent_decode_str(s)
        .decode_utf8()
        .map(|d| d.into_owned())
        .map_err(|_| Problem::NotUtf8)
}

/// `host:port` of each server in `hosts` (comma-separated; the port defaults to 4222).
fn servers(hosts: &str) -> Vec<String> {
    hosts
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
        .collect()
}

/// The login written before the `@`: `USER:PASSWORD`, or a token.
fn userinfo_auth(userinfo: Option<&str>) -> Result<Auth, Problem> {
    Ok(match userinfo {
        None => Auth::None,
        Some(info) => match info.split_once(':') {
            Some((user, password)) => Auth::UserPassword {
                user: percent_decode(user)?,
                password: SecretSource::Given(Secret::new(percent_decode(password)?)),
            },
            None => Auth::Token(SecretSource::Given(Secret::new(percent_decode(info)?))),
        },
    })
}

/// The login options as the URL gives them, before they are checked to make one way in.
#[derive(Default)]
struct Login {
    /// From the user-info, or a token, NKey or creds option.
    auth: Auth,
    /// `user=NAME`.
    user: Option<String>,
    /// `password-env=VAR` or `password-file=PATH`.
    password: Option<SecretSource>,
}

impl Login {
    /// Take `a` as the way in, unless there is one already.
    fn set(&mut self, a: Auth) -> Result<(), Problem> {
        if self.auth != Auth::None {
            return Err(Problem::TwoLogins);
        }
        self.auth = a;
        Ok(())
    }

    /// The one way in: `user=` and a password option make a user and password, or complete the
    /// user-info's.
    fn resolve(mut self) -> Result<Auth, Problem> {
        match (self.user.take(), self.password.take()) {
            (Some(user), Some(password)) => self.set(Auth::UserPassword { user, password })?,
            (Some(user), None) => match &mut self.auth {
                Auth::UserPassword { user: u, .. } => *u = user,
                _ => return Err(Problem::NoPassword(user)),
            },
            (None, Some(password)) => match &mut self.auth {
                Auth::UserPassword { password: p, .. } => *p = password,
                _ => return Err(Problem::NoUser),
            },
            (None, None) => {}
        }
        Ok(self.auth)
    }
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
    /// Parse `--state nats://...`. Every message names the option at fault and shows the URL
    /// with its secrets masked.
    pub fn parse(s: &str) -> Result<Url, UrlError> {
        let shown = mask(s);
        let form = |why: Problem| UrlError::Form {
            shown: shown.clone(),
            why,
        };
        let option = |why: Problem| UrlError::Option {
            shown: shown.clone(),
            why,
        };
        let rest = match s.split_once("://") {
            Some((scheme, rest)) if scheme.eq_ignore_ascii_case("nats") => rest,
            Some((scheme, _)) => return Err(form(Problem::Scheme(scheme.to_string()))),
            None => return Err(form(Problem::NoSlashes)),
        };
        let (rest, query) = rest.split_once('?').unwrap_or((rest, ""));
        // The user-info ends at the last `@` (a bucket name has none).
        let (userinfo, rest) = match rest.rsplit_once('@') {
            Some((info, rest)) => (Some(info), rest),
            None => (None, rest),
        };
        let (hosts, bucket) = rest
            .split_once('/')
            .ok_or_else(|| form(Problem::NoBucket))?;
        let servers = servers(hosts);
        if servers.is_empty() {
            return Err(form(Problem::NoServer));
        }
        if bucket.is_empty()
            || !bucket
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err(option(Problem::BadBucket(bucket.to_string())));
        }
        let mut url = Url {
            servers,
            bucket: bucket.to_string(),
            lease: None,
            ttl: DEFAULT_TTL,
            replicas: 1,
            auth: Auth::None,
            tls: Tls::default(),
        };
        let mut login = Login {
            auth: userinfo_auth(userinfo).map_err(&form)?,
            ..Login::default()
        };
        for pair in query.split('&').filter(|p| !p.is_empty()) {
            url.option(pair, &mut login).map_err(option)?;
        }
        url.auth = login.resolve().map_err(option)?;
        if url.tls.cert.is_some() != url.tls.key.is_some() {
            return Err(option(Problem::HalfCertificate));
        }
        if url.tls.ca.is_some() || url.tls.cert.is_some() {
            url.tls.required = true;
        }
        Ok(url)
    }

    /// Apply one `KEY=VALUE` of the query; the login options are gathered in `login`.
    fn option(&mut self, pair: &str, login: &mut Login) -> Result<(), Problem> {
        let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
        let path = || -> Result<std::path::PathBuf, Problem> {
            if v.is_empty() {
                Err(Problem::NoValue(k.to_string()))
            } else {
                Ok(std::path::PathBuf::from(v))
            }
        };
        match k {
            "lease" if !v.is_empty() => self.lease = Some(v.to_string()),
            "ttl" => {
                self.ttl = humantime::parse_duration(v).map_err(|why| Problem::Ttl {
                    value: v.to_string(),
                    why,
                })?;
                if self.ttl < Duration::from_millis(200) {
                    return Err(Problem::TtlTooShort);
                }
            }
            "replicas" => {
                self.replicas = v
                    .parse()
                    .ok()
                    .filter(|n| (1..=5).contains(n))
                    .ok_or(Problem::Replicas)?;
            }
            "user" if !v.is_empty() => login.user = Some(v.to_string()),
            "password-env" if !v.is_empty() => login.password = Some(SecretSource::Env(v.into())),
            "password-file" => login.password = Some(SecretSource::File(path()?)),
            "token-env" if !v.is_empty() => login.set(Auth::Token(SecretSource::Env(v.into())))?,
            "token-file" => login.set(Auth::Token(SecretSource::File(path()?)))?,
            "nkey-file" => login.set(Auth::NKey(path()?))?,
            "creds" => login.set(Auth::Creds(path()?))?,
            "tls" => {
                self.tls.required = match v {
                    "1" | "true" | "yes" | "" => true,
                    "0" | "false" | "no" => false,
                    _ => return Err(Problem::TlsFlag),
                }
            }
            "tls-ca" => self.tls.ca = Some(path()?),
            "tls-cert" => self.tls.cert = Some(path()?),
            "tls-key" => self.tls.key = Some(path()?),
            _ => {
                let shown_pair = if k.contains("password") || k.contains("token") {
                    format!("{k}=***")
                } else {
                    pair.to_string()
                };
                return Err(Problem::Unknown(shown_pair));
            }
        }
        Ok(())
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
    pub(crate) fn identity(&self) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nats::secrets::{Secret, SecretSource};

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
            let e = Url::parse(bad).unwrap_err().to_string();
            assert!(e.contains("nats://"), "{bad}: {e}");
        }
        let e = Url::parse("nats://u:Sup3rSecret@a/b?x=1")
            .unwrap_err()
            .to_string();
        assert!(!e.contains("Sup3rSecret") && e.contains("u:***@a/b"), "{e}");
    }
}
