//! The twin behind an MQTT broker (`simulate --broker`): the simulated robot publishes its
//! message as the robot's JSON on topic `tessla` and executes what arrives on `action`, so the
//! whole pipeline (broker, Telegraf, our processor) is driven by a simulated physical twin.
//!
//! Owns: the lock-step exchange (publish one message, wait for one action or the timeout) and
//! turning Telegraf's JSON action (`outputs.mqtt`, `data_format = "json"`) back into a line of
//! line protocol for the run's output. Publishing reuses [`crate::replay`]'s [`Publisher`] and
//! message builder; the subscription is a second rumqttc client here (the publisher's
//! connection thread only counts acknowledgements).

use super::closed_loop::{Message, Reply, Twin, TwinError};
use super::gate::Action;
use super::in_process::action_of;
use crate::log;
use crate::replay::Sample;
use crate::replay::message::{MessageOptions, to_json};
use crate::replay::mqtt::{Broker, MqttError, Publisher};
use lineproto::{FieldValue, LineWriter, Metric};
use rumqttc::{Client, Event, MqttOptions, Packet, QoS, RecvTimeoutError};
use serde_json::Value;
use std::sync::mpsc::{Receiver, channel};
use std::time::Duration;

pub struct MqttTwin {
    publisher: Option<Publisher>,
    actions: Receiver<Vec<u8>>,
    subscriber: Client,
    topic: String,
    timeout: Duration,
    time_key: Option<String>,
    /// Messages that got no action within the timeout.
    pub unanswered: usize,
}

impl MqttTwin {
    /// Connect, subscribe to `action_topic` and wait until the broker confirmed it.
    pub fn connect(
        broker: &Broker,
        topic: &str,
        action_topic: &str,
        timeout: Duration,
        time_key: Option<String>,
    ) -> Result<MqttTwin, TwinError> {
        let id = format!("tessla-telegraf-simulate-{}", std::process::id());
        let publisher =
            Publisher::connect(broker, &format!("{id}-pub"), QoS::AtLeastOnce, timeout)?;
        let mut options = MqttOptions::new(format!("{id}-sub"), broker.host.clone(), broker.port);
        options.set_keep_alive(Duration::from_secs(30));
        options.set_max_packet_size(1 << 20, 1 << 20);
        let (client, mut connection) = Client::new(options, 64);
        client
            .subscribe(action_topic, QoS::AtLeastOnce)
            .map_err(|e| TwinError::Subscriber {
                broker: broker.to_string(),
                error: e.to_string(),
            })?;
        let (tx, rx) = channel();
        let (ready_tx, ready_rx) = channel::<Result<(), TwinError>>();
        let name = broker.to_string();
        std::thread::spawn(move || {
            let mut ready = false;
            loop {
                match connection.recv_timeout(Duration::from_millis(200)) {
                    Ok(Ok(Event::Incoming(Packet::SubAck(_)))) => {
                        ready = true;
                        let _ = ready_tx.send(Ok(()));
                    }
                    Ok(Ok(Event::Incoming(Packet::Publish(p)))) => {
                        if tx.send(p.payload.to_vec()).is_err() {
                            return;
                        }
                    }
                    Ok(Ok(_)) | Err(RecvTimeoutError::Timeout) => {}
                    Ok(Err(e)) => {
                        if !ready {
                            let _ = ready_tx.send(Err(TwinError::Subscriber {
                                broker: name.clone(),
                                error: e.to_string(),
                            }));
                        } else {
                            log_error!("MQTT broker {name}: {e}");
                        }
                        return;
                    }
                    Err(RecvTimeoutError::Disconnected) => return,
                }
            }
        });
        match ready_rx.recv_timeout(timeout) {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(e),
            Err(_) => {
                return Err(TwinError::NoSubAck {
                    broker: broker.to_string(),
                    seconds: timeout.as_secs_f64(),
                });
            }
        }
        Ok(MqttTwin {
            publisher: Some(publisher),
            actions: rx,
            subscriber: client,
            topic: topic.to_string(),
            timeout,
            time_key,
            unanswered: 0,
        })
    }

    /// Wait until the broker acknowledged every message, then disconnect.
    pub fn finish(mut self) -> Result<usize, MqttError> {
        let _ = self.subscriber.disconnect();
        match self.publisher.take() {
            Some(p) => p.finish(self.timeout),
            None => Ok(0),
        }
    }
}

/// The robot's JSON for a message: replay's message builder on a sample with its fields.
fn sample_of(message: &Message) -> Sample {
    let mut fields = vec![
        (
            "expectedSpeed".to_string(),
            FieldValue::Float(message.expected_speed),
        ),
        (
            "actualSpeed".to_string(),
            FieldValue::Str(message.actual_speed_text()),
        ),
        (
            "expectedAngular".to_string(),
            FieldValue::Float(message.expected_angular),
        ),
        (
            "actualAngular".to_string(),
            FieldValue::Float((message.actual_angular * 1e4).round() / 1e4),
        ),
    ];
    fields.extend(
        message
            .lidar
            .iter()
            .enumerate()
            .map(|(i, r)| (format!("lidar_{i}"), FieldValue::Float(*r))),
    );
    Sample {
        line: 0,
        time_ns: Some(message.time_ns),
        fields,
    }
}

/// An action message of Telegraf's JSON serializer as a metric.
fn metric_of(json: &Value) -> Option<Metric> {
    let name = json.get("name")?.as_str()?.to_string();
    let mut tags: Vec<(String, String)> = json
        .get("tags")
        .and_then(Value::as_object)
        .map(|t| {
            t.iter()
                .filter_map(|(k, v)| v.as_str().map(|v| (k.clone(), v.to_string())))
                .collect()
        })
        .unwrap_or_default();
    tags.sort();
    let fields = json
        .get("fields")?
        .as_object()?
        .iter()
        .filter_map(|(k, v)| {
            let value = match v {
                Value::Bool(b) => FieldValue::Bool(*b),
                Value::String(s) => FieldValue::Str(s.clone()),
                // An integer beyond a float's 53 bits (`valid_until`, in ns) stays exact.
                Value::Number(n) => match n.as_i64() {
                    Some(i) if i.unsigned_abs() > 1 << 53 => FieldValue::Int(i),
                    _ => FieldValue::Float(n.as_f64()?),
                },
                _ => return None,
            };
            Some((k.clone(), value))
        })
        .collect();
    Some(Metric {
        measurement: name,
        tags,
        fields,
        timestamp: None,
        overwritten: 0,
        list: Default::default(),
    })
}

impl Twin for MqttTwin {
    fn exchange(&mut self, line: &str, message: &Message, _: i64) -> Result<Reply, TwinError> {
        // An action that arrived after its message timed out belongs to no message now.
        while self.actions.try_recv().is_ok() {}
        let options = MessageOptions {
            string_fields: vec!["actualSpeed".into()],
            time_key: self.time_key.clone(),
        };
        let payload = to_json(&sample_of(message), &options).to_string();
        let publisher = self.publisher.as_mut().ok_or(TwinError::Closed)?;
        publisher.publish(&self.topic, payload.into_bytes())?;
        let mut lines = line.as_bytes().to_vec();
        let mut received_ns = None;
        let metric = match self.actions.recv_timeout(self.timeout) {
            Ok(payload) => {
                // Without the robot's time in the message, Telegraf stamps it (and so the action
                // and its `valid_until`) with its own clock: judge it by the wall clock here.
                if self.time_key.is_none() {
                    received_ns = std::time::SystemTime::now()
                        .duration_since(std::time::UNIX_EPOCH)
                        .ok()
                        .and_then(|d| i64::try_from(d.as_nanos()).ok());
                }
                serde_json::from_slice::<Value>(&payload)
                    .ok()
                    .as_ref()
                    .and_then(metric_of)
            }
            Err(_) => {
                self.unanswered += 1;
                log::warn_limited("no action", || {
                    format!(
                        "no action within {} s of the message at {} ns; the robot keeps its own command",
                        self.timeout.as_secs_f64(),
                        message.time_ns
                    )
                });
                None
            }
        };
        let action: Option<Action> = metric.as_ref().and_then(action_of);
        if let Some(m) = &metric {
            let mut w = LineWriter::new(&m.measurement);
            for (k, v) in &m.tags {
                w.tag(k, v);
            }
            for (k, v) in &m.fields {
                w.field(k, v);
            }
            if let Some(l) = w.finish(Some(message.time_ns)).0 {
                lines.extend_from_slice(l.as_bytes());
            }
        }
        Ok(Reply {
            lines,
            action,
            received_ns,
        })
    }
}
