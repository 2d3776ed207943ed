//! Publishing to an MQTT broker with rumqttc (MQTT 3.1.1, plain TCP or TLS).
//!
//! [`Broker`] parses `mqtt://HOST:PORT` (also `tcp://`, or a bare `HOST[:PORT]`; port 1883 by
//! default) and `mqtts://HOST:PORT` (also `ssl://`; TLS, port 8883 by default). [`Login`] holds
//! the user name, password and TLS files (rumqttc's own TLS support does the handshake). [`Publisher::connect`] waits for the broker's CONNACK so an unreachable broker is
//! reported up front, naming it; a background thread then drives the connection and counts
//! acknowledgements, and [`Publisher::finish`] waits for them before disconnecting, so every
//! message published with QoS 1 or 2 is known to have reached the broker.

use rumqttc::{Client, Connection, Event, MqttOptions, Outgoing, Packet, QoS, RecvTimeoutError};
use std::fmt;
use std::str::FromStr;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Where the broker listens.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Broker {
    pub host: String,
    pub port: u16,
    /// `mqtts://`: TLS.
    pub tls: bool,
}

impl fmt::Display for Broker {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let scheme = if self.tls { "mqtts" } else { "mqtt" };
        if self.host.contains(':') {
            write!(f, "{scheme}://[{}]:{}", self.host, self.port)
        } else {
            write!(f, "{scheme}://{}:{}", self.host, self.port)
        }
    }
}

/// How the client logs in: user name and password (MQTT CONNECT), and the TLS files: the CA
/// that signed the broker's certificate, and a client certificate and key when the broker asks
/// for one. The password is never shown (`{:?}` included).
#[derive(Clone, Default)]
pub struct Login {
    pub username: Option<String>,
    pub password: Option<String>,
    /// PEM contents: the CA, then (certificate, key).
    pub ca: Option<Vec<u8>>,
    pub client: Option<(Vec<u8>, Vec<u8>)>,
}

impl fmt::Debug for Login {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Login")
            .field("username", &self.username)
            .field("password", &self.password.as_ref().map(|_| "***"))
            .field("ca", &self.ca.is_some())
            .field("client", &self.client.is_some())
            .finish()
    }
}

/// A broker address that does not parse: the address as shown (secrets masked) and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("bad broker address {shown:?}: {why} (expected mqtt://HOST:PORT or mqtts://HOST:PORT)")]
pub struct BrokerError {
    /// The address given, its secrets masked.
    pub shown: String,
    /// What is wrong with it.
    pub why: BadBroker,
}

/// What is wrong with a broker address.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BadBroker {
    /// A scheme other than mqtt/tcp/mqtts/ssl.
    #[error("scheme {0:?} is not supported, only mqtt:// (plain TCP) and mqtts:// (TLS)")]
    Scheme(String),
    /// `user:password@` in the address.
    #[error("credentials do not go in the address: use --username and --password-env VAR")]
    Credentials,
    /// An IPv6 host without its `]`.
    #[error("unclosed '['")]
    Unclosed,
    /// Nothing before the port.
    #[error("no host")]
    NoHost,
    /// A port that is not 1..65535.
    #[error("port {0:?} is not a number 1..65535")]
    Port(String),
}

/// A `--qos` other than 0, 1 or 2.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("--qos must be 0, 1 or 2, not {0}")]
pub struct QosError(pub u8);

/// Why connecting, publishing or finishing failed; each names the broker. The texts of
/// rumqttc's errors are kept as text (they name no secret).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MqttError {
    /// `mqtts://` without `--tls-ca`.
    #[error("{0} is TLS: --tls-ca PATH must name the CA that signed its certificate")]
    NeedsCa(Broker),
    /// No CONNACK before the deadline.
    #[error("cannot reach MQTT broker {broker}: no answer within {seconds} s")]
    NoAnswer { broker: Broker, seconds: f64 },
    /// The broker refused the user name or password.
    #[error(
        "MQTT broker {broker} refused the login ({who}: {code}); check --username and the \
         password in the variable --password-env names"
    )]
    LoginRefused {
        broker: Broker,
        who: String,
        code: String,
    },
    /// The broker refused the connection for another reason.
    #[error("MQTT broker {broker} refused the connection ({who}): {code}")]
    Refused {
        broker: Broker,
        who: String,
        code: String,
    },
    /// The TLS handshake failed.
    #[error(
        "TLS failed with MQTT broker {broker}: {error}; check --tls-ca (the CA that signed the \
         broker's certificate), the host name against the certificate, and --tls-cert/--tls-key \
         when the broker asks for a client certificate"
    )]
    Tls { broker: Broker, error: String },
    /// A certificate was refused outside the handshake proper.
    #[error(
        "TLS failed with MQTT broker {broker}: {error}; check --tls-ca, --tls-cert and --tls-key"
    )]
    Certificate { broker: Broker, error: String },
    /// A plain connection reset: perhaps the broker speaks TLS.
    #[error(
        "cannot reach MQTT broker {broker}: {error} (does the broker expect TLS? then write mqtts://)"
    )]
    Reset { broker: Broker, error: String },
    /// No broker answered, or the client closed.
    #[error("cannot reach MQTT broker {broker}: {error}")]
    Unreachable { broker: Broker, error: String },
    /// The client refused a message.
    #[error("MQTT broker {broker}: {error}")]
    Client { broker: Broker, error: String },
    /// Not every message was acknowledged in time.
    #[error("MQTT broker {broker} acknowledged {acked} of {published} messages within {seconds} s")]
    Unacknowledged {
        broker: Broker,
        acked: usize,
        published: usize,
        seconds: f64,
    },
    /// The connection failed after connecting.
    #[error("connection to MQTT broker {broker} lost: {error}")]
    Lost { broker: Broker, error: String },
}

impl FromStr for Broker {
    type Err = BrokerError;

    fn from_str(text: &str) -> Result<Self, BrokerError> {
        let shown = crate::log::mask(text);
        let bad = |why: BadBroker| BrokerError {
            shown: shown.to_string(),
            why,
        };
        let (tls, rest) = match text.split_once("://") {
            Some(("mqtt" | "tcp", rest)) => (false, rest),
            Some(("mqtts" | "ssl", rest)) => (true, rest),
            Some((scheme, _)) => {
                return Err(bad(BadBroker::Scheme(scheme.to_string())));
            }
            None => (false, text),
        };
        if rest.contains('@') {
            return Err(bad(BadBroker::Credentials));
        }
        let rest = rest.trim_end_matches('/');
        let (host, port) = if let Some(v6) = rest.strip_prefix('[') {
            let (host, after) = v6.split_once(']').ok_or_else(|| bad(BadBroker::Unclosed))?;
            (host, after.strip_prefix(':'))
        } else {
            match rest.rsplit_once(':') {
                Some((host, port)) => (host, Some(port)),
                None => (rest, None),
            }
        };
        if host.is_empty() {
            return Err(bad(BadBroker::NoHost));
        }
        let port = match port {
            Some(p) => p
                .parse::<u16>()
                .ok()
                .filter(|p| *p != 0)
                .ok_or_else(|| bad(BadBroker::Port(p.to_string())))?,
            None if tls => 8883,
            None => 1883,
        };
        Ok(Broker {
            host: host.to_string(),
            port,
            tls,
        })
    }
}

/// Why connecting failed, in the user's terms: the broker refused the login, TLS failed, or no
/// broker answered. The error texts of rumqttc name no secret.
fn connect_failure(broker: &Broker, login: &Login, e: &rumqttc::ConnectionError) -> MqttError {
    use rumqttc::{ConnectReturnCode as C, ConnectionError as E};
    let who = match &login.username {
        Some(u) => format!("as user `{u}`"),
        None => "without a user name".into(),
    };
    let broker = broker.clone();
    let error = e.to_string();
    match e {
        E::ConnectionRefused(C::BadUserNamePassword | C::NotAuthorized) => {
            MqttError::LoginRefused {
                broker,
                who,
                code: format!("{e:?}"),
            }
        }
        E::ConnectionRefused(code) => MqttError::Refused {
            broker,
            who,
            code: format!("{code:?}"),
        },
        E::Tls(_) => MqttError::Tls { broker, error },
        _ if broker.tls && error.to_ascii_lowercase().contains("certificate") => {
            MqttError::Certificate { broker, error }
        }
        _ if !broker.tls && error.contains("reset by peer") => MqttError::Reset { broker, error },
        _ => MqttError::Unreachable { broker, error },
    }
}

/// Parse `0`, `1` or `2` into a QoS.
pub fn parse_qos(level: u8) -> Result<QoS, QosError> {
    match level {
        0 => Ok(QoS::AtMostOnce),
        1 => Ok(QoS::AtLeastOnce),
        2 => Ok(QoS::ExactlyOnce),
        other => Err(QosError(other)),
    }
}

/// A connected client that publishes in order.
pub struct Publisher {
    broker: Broker,
    client: Client,
    acked: Arc<AtomicUsize>,
    error: Arc<Mutex<Option<MqttError>>>,
    driver: Option<JoinHandle<()>>,
    published: usize,
    qos: QoS,
}

impl Publisher {
    /// Connect and wait for the broker to accept us, at most `timeout`.
    pub fn connect(
        broker: &Broker,
        client_id: &str,
        qos: QoS,
        timeout: Duration,
    ) -> Result<Self, MqttError> {
        Self::connect_with(broker, client_id, qos, timeout, &Login::default())
    }

    /// [`Publisher::connect`] with a login (credentials, TLS). A refused login, a TLS failure
    /// and an unreachable broker each say so.
    pub fn connect_with(
        broker: &Broker,
        client_id: &str,
        qos: QoS,
        timeout: Duration,
        login: &Login,
    ) -> Result<Self, MqttError> {
        let mut options = MqttOptions::new(client_id, broker.host.clone(), broker.port);
        if let Some(user) = &login.username {
            options.set_credentials(user.clone(), login.password.clone().unwrap_or_default());
        }
        if broker.tls {
            let Some(ca) = login.ca.clone() else {
                return Err(MqttError::NeedsCa(broker.clone()));
            };
            options.set_transport(rumqttc::Transport::tls_with_config(
                rumqttc::TlsConfiguration::Simple {
                    ca,
                    alpn: None,
                    client_auth: login.client.clone(),
                },
            ));
        }
        options.set_keep_alive(Duration::from_secs(30));
        // A 360-beam scan is ~7 KB of JSON, over rumqttc's 10 KiB default only for larger scans,
        // but long recordings may carry more: allow up to 1 MiB either way.
        options.set_max_packet_size(1 << 20, 1 << 20);
        let (client, mut connection) = Client::new(options, 64);
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(MqttError::NoAnswer {
                    broker: broker.clone(),
                    seconds: timeout.as_secs_f64(),
                });
            }
            match connection.recv_timeout(left) {
                Ok(Ok(Event::Incoming(Packet::ConnAck(_)))) => break,
                Ok(Ok(_)) => {}
                Ok(Err(e)) => return Err(connect_failure(broker, login, &e)),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(MqttError::Unreachable {
                        broker: broker.clone(),
                        error: "client closed".into(),
                    });
                }
            }
        }
        let acked = Arc::new(AtomicUsize::new(0));
        let error = Arc::new(Mutex::new(None));
        let driver = {
            let acked = Arc::clone(&acked);
            let error = Arc::clone(&error);
            let broker = broker.clone();
            std::thread::spawn(move || drive(connection, &broker, &acked, &error))
        };
        Ok(Publisher {
            broker: broker.clone(),
            client,
            acked,
            error,
            driver: Some(driver),
            published: 0,
            qos,
        })
    }

    /// Queue one message (blocks while the client's queue is full).
    pub fn publish(&mut self, topic: &str, payload: Vec<u8>) -> Result<(), MqttError> {
        if let Some(e) = self.failure() {
            return Err(e);
        }
        self.client
            .publish(topic, self.qos, false, payload)
            .map_err(|e| {
                self.failure().unwrap_or_else(|| MqttError::Client {
                    broker: self.broker.clone(),
                    error: e.to_string(),
                })
            })?;
        self.published += 1;
        Ok(())
    }

    /// Messages the broker has acknowledged so far (QoS 1 and 2 only).
    pub fn acknowledged(&self) -> usize {
        self.acked.load(Ordering::SeqCst)
    }

    /// Wait (at most `timeout`) until every message is acknowledged, then disconnect.
    pub fn finish(mut self, timeout: Duration) -> Result<usize, MqttError> {
        let deadline = Instant::now() + timeout;
        if self.qos != QoS::AtMostOnce {
            while self.acknowledged() < self.published {
                if let Some(e) = self.failure() {
                    return Err(e);
                }
                if Instant::now() >= deadline {
                    return Err(MqttError::Unacknowledged {
                        broker: self.broker.clone(),
                        acked: self.acknowledged(),
                        published: self.published,
                        seconds: timeout.as_secs_f64(),
                    });
                }
                std::thread::sleep(Duration::from_millis(5));
            }
        }
        let _ = self.client.disconnect();
        if let Some(driver) = self.driver.take() {
            let _ = driver.join();
        }
        match self.failure() {
            Some(e) => Err(e),
            None => Ok(self.published),
        }
    }

    fn failure(&self) -> Option<MqttError> {
        self.error.lock().ok().and_then(|e| e.clone())
    }
}

/// Drive the connection until we disconnect or it fails; count acknowledgements.
fn drive(
    mut connection: Connection,
    broker: &Broker,
    acked: &AtomicUsize,
    error: &Mutex<Option<MqttError>>,
) {
    let mut disconnect_sent: Option<Instant> = None;
    loop {
        if disconnect_sent.is_some_and(|t| t.elapsed() > Duration::from_secs(2)) {
            return;
        }
        match connection.recv_timeout(Duration::from_millis(100)) {
            Ok(Ok(Event::Incoming(Packet::PubAck(_) | Packet::PubComp(_)))) => {
                acked.fetch_add(1, Ordering::SeqCst);
            }
            Ok(Ok(Event::Outgoing(Outgoing::Disconnect))) => {
                // The DISCONNECT packet is written; the broker now closes the socket.
                disconnect_sent = Some(Instant::now());
            }
            Ok(Ok(_)) | Err(RecvTimeoutError::Timeout) => {}
            Ok(Err(e)) => {
                if disconnect_sent.is_none()
                    && let Ok(mut slot) = error.lock()
                {
                    *slot = Some(MqttError::Lost {
                        broker: broker.clone(),
                        error: e.to_string(),
                    });
                }
                return;
            }
            Err(RecvTimeoutError::Disconnected) => return,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn broker_addresses() {
        let b: Broker = "mqtt://127.0.0.1:1884".parse().unwrap();
        assert_eq!(
            b,
            Broker {
                host: "127.0.0.1".into(),
                port: 1884,
                tls: false
            }
        );
        assert_eq!(b.to_string(), "mqtt://127.0.0.1:1884");
        let b: Broker = "localhost".parse().unwrap();
        assert_eq!(b.port, 1883);
        let b: Broker = "tcp://[::1]:99/".parse().unwrap();
        assert_eq!(
            b,
            Broker {
                host: "::1".into(),
                port: 99,
                tls: false
            }
        );
        assert_eq!(b.to_string(), "mqtt://[::1]:99");
        let b: Broker = "mqtts://h".parse().unwrap();
        assert_eq!((b.port, b.tls), (8883, true));
        assert_eq!(b.to_string(), "mqtts://h:8883");
        assert!(
            "http://h:1"
                .parse::<Broker>()
                .unwrap_err()
                .to_string()
                .contains("not supported")
        );
        let e = "mqtt://u:Secr3t@h:1".parse::<Broker>().unwrap_err();
        assert_eq!(e.why, BadBroker::Credentials);
        let e = e.to_string();
        assert!(!e.contains("Secr3t"), "{e}");
        assert!(e.contains("--password-env"), "{e}");
        assert_eq!(
            "mqtt://h:x".parse::<Broker>().unwrap_err().to_string(),
            "bad broker address \"mqtt://h:x\": port \"x\" is not a number 1..65535 \
             (expected mqtt://HOST:PORT or mqtts://HOST:PORT)"
        );
        assert!(
            "mqtt://:1"
                .parse::<Broker>()
                .unwrap_err()
                .to_string()
                .contains("no host")
        );
    }

    #[test]
    fn unreachable_broker_is_named() {
        // A port nobody listens on: bind, learn the port, close.
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let broker = Broker {
            host: "127.0.0.1".into(),
            port,
            tls: false,
        };
        let err = Publisher::connect(&broker, "t", QoS::AtLeastOnce, Duration::from_secs(5))
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains(&format!("mqtt://127.0.0.1:{port}")), "{err}");
    }
}
