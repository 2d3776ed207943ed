//! Test-side MQTT clients (rumqttc): a subscriber that collects messages of one topic into a
//! channel, and a publisher (a robot).

use rumqttc::{Client, Event, MqttOptions, Packet, QoS};
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

fn options(id: &str, port: u16) -> MqttOptions {
    let mut o = MqttOptions::new(id, "127.0.0.1", port);
    o.set_max_packet_size(1 << 20, 1 << 20);
    o.set_keep_alive(Duration::from_secs(30));
    o
}

/// Subscribe to `topic`; returns once the broker confirmed the subscription. A connection that
/// fails before the SUBACK (a broker still starting, a reset under load) is retried with a new
/// client, up to five times, before the test fails with the last error.
pub fn subscribe(port: u16, topic: &str, id: &str) -> Receiver<(Instant, Vec<u8>)> {
    let mut last_error = String::from("no attempt made");
    for attempt in 0..5 {
        match try_subscribe(port, topic, id) {
            Ok(rx) => return rx,
            Err(e) => {
                last_error = e;
                std::thread::sleep(Duration::from_millis(100 * (attempt + 1)));
            }
        }
    }
    panic!("no SUBACK from mosquitto on port {port}: {last_error}");
}

fn try_subscribe(port: u16, topic: &str, id: &str) -> Result<Receiver<(Instant, Vec<u8>)>, String> {
    let (client, mut connection) = Client::new(options(id, port), 1024);
    client
        .subscribe(topic, QoS::AtLeastOnce)
        .map_err(|e| e.to_string())?;
    let (tx, rx) = channel();
    let (ready_tx, ready_rx) = channel::<Result<(), String>>();
    std::thread::spawn(move || {
        let _client = client; // keep the request channel open
        let mut ready = false;
        for event in connection.iter() {
            match event {
                Ok(Event::Incoming(Packet::SubAck(_))) => {
                    ready = true;
                    let _ = ready_tx.send(Ok(()));
                }
                Ok(Event::Incoming(Packet::Publish(p))) => {
                    if tx.send((Instant::now(), p.payload.to_vec())).is_err() {
                        return;
                    }
                }
                Ok(_) => {}
                Err(e) => {
                    if !ready {
                        let _ = ready_tx.send(Err(format!("{e:?}")));
                    }
                    return;
                }
            }
        }
    });
    match ready_rx.recv_timeout(Duration::from_secs(10)) {
        Ok(Ok(())) => Ok(rx),
        Ok(Err(e)) => Err(e),
        Err(e) => Err(format!("{e}")),
    }
}

/// Collect `n` messages, waiting at most `timeout` for each.
pub fn collect(
    rx: &Receiver<(Instant, Vec<u8>)>,
    n: usize,
    timeout: Duration,
) -> Vec<(Instant, Vec<u8>)> {
    let mut out = Vec::new();
    while out.len() < n {
        match rx.recv_timeout(timeout) {
            Ok(m) => out.push(m),
            Err(_) => break,
        }
    }
    out
}

/// A client connected with `opts`, its connection driven by a background thread; returns once
/// the broker has acknowledged the connection (panics after 10 s without).
pub fn connect_with(opts: MqttOptions) -> Client {
    let (client, mut connection) = Client::new(opts, 1024);
    let (ready_tx, ready_rx) = channel();
    std::thread::spawn(move || {
        for event in connection.iter() {
            match event {
                Ok(Event::Incoming(Packet::ConnAck(_))) => {
                    let _ = ready_tx.send(());
                }
                Ok(_) => {}
                Err(_) => return,
            }
        }
    });
    ready_rx
        .recv_timeout(Duration::from_secs(10))
        .expect("no CONNACK from mosquitto");
    client
}

/// A connected publisher whose connection is driven by a background thread.
pub struct Publisher {
    client: Client,
}

impl Publisher {
    pub fn connect(port: u16, id: &str) -> Publisher {
        Publisher {
            client: connect_with(options(id, port)),
        }
    }

    pub fn publish(&self, topic: &str, payload: Vec<u8>) {
        self.client
            .publish(topic, QoS::AtLeastOnce, false, payload)
            .unwrap();
    }
}
