//! Publishing to an MQTT broker with rumqttc (plain TCP, MQTT 3.1.1).
//!
//! [`Broker`] parses `mqtt://HOST:PORT` (also `tcp://`, or a bare `HOST[:PORT]`; port 1883 by
//! default). [`Publisher::connect`] waits for the broker's CONNACK so an unreachable broker is
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
}

impl fmt::Display for Broker {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.host.contains(':') {
            write!(f, "mqtt://[{}]:{}", self.host, self.port)
        } else {
            write!(f, "mqtt://{}:{}", self.host, self.port)
        }
    }
}

impl FromStr for Broker {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let bad =
            |why: &str| format!("bad broker address {text:?}: {why} (expected mqtt://HOST:PORT)");
        let rest = match text.split_once("://") {
            Some(("mqtt" | "tcp", rest)) => rest,
            Some((scheme, _)) => {
                return Err(bad(&format!(
                    "scheme {scheme:?} is not supported, only mqtt:// (plain TCP)"
                )));
            }
            None => text,
        };
        let rest = rest.trim_end_matches('/');
        let (host, port) = if let Some(v6) = rest.strip_prefix('[') {
            let (host, after) = v6.split_once(']').ok_or_else(|| bad("unclosed '['"))?;
            (host, after.strip_prefix(':'))
        } else {
            match rest.rsplit_once(':') {
                Some((host, port)) => (host, Some(port)),
                None => (rest, None),
            }
        };
        if host.is_empty() {
            return Err(bad("no host"));
        }
        let port = match port {
            Some(p) => p
                .parse::<u16>()
                .ok()
                .filter(|p| *p != 0)
                .ok_or_else(|| bad(&format!("port {p:?} is not a number 1..65535")))?,
            None => 1883,
        };
        Ok(Broker {
            host: host.to_string(),
            port,
        })
    }
}

/// Parse `0`, `1` or `2` into a QoS.
pub fn parse_qos(level: u8) -> Result<QoS, String> {
    match level {
        0 => Ok(QoS::AtMostOnce),
        1 => Ok(QoS::AtLeastOnce),
        2 => Ok(QoS::ExactlyOnce),
        other => Err(format!("--qos must be 0, 1 or 2, not {other}")),
    }
}

/// A connected client that publishes in order.
pub struct Publisher {
    broker: Broker,
    client: Client,
    acked: Arc<AtomicUsize>,
    error: Arc<Mutex<Option<String>>>,
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
    ) -> Result<Self, String> {
        let mut options = MqttOptions::new(client_id, broker.host.clone(), broker.port);
        options.set_keep_alive(Duration::from_secs(30));
        // A 360-beam scan is ~7 KB of JSON, over rumqttc's 10 KiB default only for larger scans,
        // but long recordings may carry more: allow up to 1 MiB either way.
        options.set_max_packet_size(1 << 20, 1 << 20);
        let (client, mut connection) = Client::new(options, 64);
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(format!(
                    "cannot reach MQTT broker {broker}: no answer within {} s",
                    timeout.as_secs_f64()
                ));
            }
            match connection.recv_timeout(left) {
                Ok(Ok(Event::Incoming(Packet::ConnAck(_)))) => break,
                Ok(Ok(_)) => {}
                Ok(Err(e)) => return Err(format!("cannot reach MQTT broker {broker}: {e}")),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(format!("cannot reach MQTT broker {broker}: client closed"));
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
    pub fn publish(&mut self, topic: &str, payload: Vec<u8>) -> Result<(), String> {
        if let Some(e) = self.failure() {
            return Err(e);
        }
        self.client
            .publish(topic, self.qos, false, payload)
            .map_err(|e| {
                self.failure()
                    .unwrap_or_else(|| format!("MQTT broker {}: {e}", self.broker))
            })?;
        self.published += 1;
        Ok(())
    }

    /// Messages the broker has acknowledged so far (QoS 1 and 2 only).
    pub fn acknowledged(&self) -> usize {
        self.acked.load(Ordering::SeqCst)
    }

    /// Wait (at most `timeout`) until every message is acknowledged, then disconnect.
    pub fn finish(mut self, timeout: Duration) -> Result<usize, String> {
        let deadline = Instant::now() + timeout;
        if self.qos != QoS::AtMostOnce {
            while self.acknowledged() < self.published {
                if let Some(e) = self.failure() {
                    return Err(e);
                }
                if Instant::now() >= deadline {
                    return Err(format!(
                        "MQTT broker {} acknowledged {} of {} messages within {} s",
                        self.broker,
                        self.acknowledged(),
                        self.published,
                        timeout.as_secs_f64()
                    ));
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

    fn failure(&self) -> Option<String> {
        self.error.lock().ok().and_then(|e| e.clone())
    }
}

/// Drive the connection until we disconnect or it fails; count acknowledgements.
fn drive(
    mut connection: Connection,
    broker: &Broker,
    acked: &AtomicUsize,
    error: &Mutex<Option<String>>,
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
                    *slot = Some(format!("connection to MQTT broker {broker} lost: {e}"));
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
                port: 1884
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
                port: 99
            }
        );
        assert_eq!(b.to_string(), "mqtt://[::1]:99");
        assert!(
            "mqtts://h:1"
                .parse::<Broker>()
                .unwrap_err()
                .contains("not supported")
        );
        assert!("mqtt://h:x".parse::<Broker>().unwrap_err().contains("port"));
        assert!(
            "mqtt://:1"
                .parse::<Broker>()
                .unwrap_err()
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
        };
        let err = Publisher::connect(&broker, "t", QoS::AtLeastOnce, Duration::from_secs(5))
            .err()
            .unwrap();
        assert!(err.contains(&format!("mqtt://127.0.0.1:{port}")), "{err}");
    }
}
