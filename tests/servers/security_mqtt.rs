//! `replay` through a secured Mosquitto: the shipped `telegraf/mosquitto/mosquitto.conf` (TLS
//! only, no anonymous clients, a password file) and `telegraf/mosquitto/acl` (a robot publishes
//! only its own telemetry and reads only its own actions), with certificates made now by the
//! shipped `telegraf/fleet-nats/make-test-certs.sh`. Checked: `replay` publishes through it with
//! `--username`, `--password-env` and `--tls-ca` (and a client certificate); a robot cannot
//! publish to another robot's `action` topic; a wrong password, an untrusted CA, a plain client
//! on the TLS port and no login at all are each refused with their own message (exit 3); the
//! password never appears in any output.

use crate::support::nats_cluster;
use crate::support::servers;

use rumqttc::{Client, Event, MqttOptions, Packet, QoS, TlsConfiguration, Transport};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

use crate::support::BIN;

/// The marker passwords: none may appear in any output.
const ROBOT1_PW: &str = "Mark3r-robot1-pw";
const ROBOT2_PW: &str = "Mark3r-robot2-pw";
const TELEGRAF_PW: &str = "Mark3r-telegraf-pw";

struct Broker {
    port: u16,
    certs: PathBuf,
    server: servers::Server,
}

impl Broker {
    fn start() -> Option<Broker> {
        Self::start_with("")
    }

    /// The shipped conf with `extra` appended (settings of its listener).
    fn start_with(extra: &str) -> Option<Broker> {
        let mosquitto = servers::require("mosquitto", "mosquitto")?;
        let dir = tempfile::tempdir().unwrap();
        let certs = dir.path().join("certs");
        nats_cluster::make_certs(&certs);
        // Mosquitto started as root drops to its own user: let it read the test-only key.
        if let Ok(meta) = std::fs::metadata(certs.join("server-key.pem")) {
            use std::os::unix::fs::PermissionsExt;
            let mut p = meta.permissions();
            p.set_mode(0o644);
            std::fs::set_permissions(certs.join("server-key.pem"), p).unwrap();
        }
        let passwd = dir.path().join("passwd");
        let tool = servers::require("mosquitto_passwd", "mosquitto")?;
        for (i, (user, pw)) in [
            ("telegraf", TELEGRAF_PW),
            ("robot1", ROBOT1_PW),
            ("robot2", ROBOT2_PW),
        ]
        .iter()
        .enumerate()
        {
            let mut c = Command::new(&tool);
            if i == 0 {
                c.arg("-c");
            }
            let out = c
                .args(["-b", passwd.to_str().unwrap(), user, pw])
                .output()
                .unwrap();
            assert!(out.status.success(), "{out:?}");
        }
        let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("telegraf/mosquitto");
        let port = servers::free_port();
        let conf = std::fs::read_to_string(shipped.join("mosquitto.conf"))
            .unwrap()
            .replace("/etc/mosquitto/passwd", passwd.to_str().unwrap())
            .replace("/etc/mosquitto/acl", shipped.join("acl").to_str().unwrap())
            .replace("/etc/mosquitto/certs", certs.to_str().unwrap())
            .replace("listener 8883", &format!("listener {port} 127.0.0.1"));
        assert!(
            conf.contains(&format!("listener {port} 127.0.0.1")),
            "{conf}"
        );
        let conf = format!("{conf}{extra}\nlog_dest stdout\npersistence false\n");
        let server =
            servers::Server::start(&mosquitto, &["-c"], dir, port, "mosquitto.conf", &conf);
        Some(Broker {
            port,
            certs,
            server,
        })
    }

    fn log(&self) -> String {
        self.server.log()
    }

    /// A subscriber logged in as `user`, over TLS; returns once subscribed.
    fn subscribe(&self, user: &str, pw: &str, topic: &str) -> Receiver<(String, Vec<u8>)> {
        let mut o = MqttOptions::new(format!("sub-{user}"), "127.0.0.1", self.port);
        o.set_credentials(user, pw);
        o.set_transport(Transport::tls_with_config(TlsConfiguration::Simple {
            ca: std::fs::read(self.certs.join("ca.pem")).unwrap(),
            alpn: None,
            client_auth: None,
        }));
        let (client, mut connection) = Client::new(o, 64);
        client.subscribe(topic, QoS::AtLeastOnce).unwrap();
        let (tx, rx) = channel();
        let (ready_tx, ready_rx) = channel();
        std::thread::spawn(move || {
            let _client = client;
            for event in connection.iter() {
                match event {
                    Ok(Event::Incoming(Packet::SubAck(_))) => {
                        let _ = ready_tx.send(());
                    }
                    Ok(Event::Incoming(Packet::Publish(p))) => {
                        if tx.send((p.topic.clone(), p.payload.to_vec())).is_err() {
                            return;
                        }
                    }
                    Ok(_) => {}
                    Err(_) => return,
                }
            }
        });
        ready_rx
            .recv_timeout(Duration::from_secs(20))
            .expect("SUBACK from mosquitto");
        rx
    }

    /// `replay FILE --topic TOPIC` as `user` (password in $MQTT_PASSWORD), with `extra` args.
    fn replay(
        &self,
        file: &Path,
        topic: &str,
        login: Option<(&str, &str)>,
        extra: &[&str],
    ) -> (String, i32) {
        let mut c = Command::new(BIN);
        c.args([
            "replay",
            file.to_str().unwrap(),
            "--speed",
            "0",
            "--topic",
            topic,
        ]);
        if let Some((user, pw)) = login {
            c.args(["--username", user, "--password-env", "MQTT_PASSWORD"])
                .env("MQTT_PASSWORD", pw);
        }
        let out = c.args(extra).output().unwrap();
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        for marker in [ROBOT1_PW, ROBOT2_PW, TELEGRAF_PW] {
            assert!(!text.contains(marker), "a password in the output: {text}");
        }
        (text, out.status.code().unwrap_or(-1))
    }

    fn tls(&self) -> Vec<String> {
        vec![
            "--broker".into(),
            format!("mqtts://127.0.0.1:{}", self.port),
            "--tls-ca".into(),
            self.certs.join("ca.pem").display().to_string(),
        ]
    }
}

fn three_records(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(format!(
        "{}/tests/fixtures/robot/recorded_run.lp",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    let path = dir.join("three.lp");
    std::fs::write(&path, text.lines().take(3).collect::<Vec<_>>().join("\n")).unwrap();
    path
}

fn drain(rx: &Receiver<(String, Vec<u8>)>, wait: Duration) -> Vec<(String, Vec<u8>)> {
    let mut got = Vec::new();
    let deadline = Instant::now() + wait;
    while let Ok(m) = rx.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
        got.push(m);
    }
    got
}

#[test]
fn replay_publishes_through_tls_and_the_acl_keeps_robots_apart() {
    let Some(broker) = Broker::start() else {
        return;
    };
    let file = three_records(broker.server.dir.path());
    let tls = broker.tls();
    let tls: Vec<&str> = tls.iter().map(String::as_str).collect();

    // Telegraf reads every robot's telemetry; robot2 reads its own actions.
    let telemetry = broker.subscribe("telegraf", TELEGRAF_PW, "tessla/+");
    let actions2 = broker.subscribe("robot2", ROBOT2_PW, "tessla/robot2/action");

    // robot1 publishes its telemetry (also with a client certificate).
    let (out, code) = broker.replay(&file, "tessla/robot1", Some(("robot1", ROBOT1_PW)), &tls);
    assert_eq!(code, 0, "{out}\n{}", broker.log());
    assert!(out.contains("published 3 messages"), "{out}");
    let certs = &broker.certs;
    let client_cert = [
        "--tls-cert",
        &certs.join("client.pem").display().to_string(),
        "--tls-key",
        &certs.join("client-key.pem").display().to_string(),
    ]
    .map(str::to_string);
    let with_cert: Vec<&str> = tls
        .iter()
        .copied()
        .chain(client_cert.iter().map(String::as_str))
        .collect();
    let (out, code) = broker.replay(
        &file,
        "tessla/robot1",
        Some(("robot1", ROBOT1_PW)),
        &with_cert,
    );
    assert_eq!(code, 0, "{out}");
    let got = drain(&telemetry, Duration::from_secs(2));
    assert_eq!(got.len(), 6, "{got:?}");
    assert!(got.iter().all(|(t, _)| t == "tessla/robot1"));

    // robot1 cannot steer robot2 (MQTT 3.1.1 has no refusal for a publish: the broker drops it),
    // nor pose as robot2's telemetry; Telegraf's user can send robot2 its action.
    let (_, code) = broker.replay(
        &file,
        "tessla/robot2/action",
        Some(("robot1", ROBOT1_PW)),
        &tls,
    );
    assert_eq!(code, 0);
    let (_, code) = broker.replay(&file, "tessla/robot2", Some(("robot1", ROBOT1_PW)), &tls);
    assert_eq!(code, 0);
    assert!(
        drain(&actions2, Duration::from_secs(2)).is_empty(),
        "robot1 reached robot2's action topic"
    );
    assert!(
        drain(&telemetry, Duration::from_millis(500)).is_empty(),
        "robot1 published as robot2"
    );
    let (out, code) = broker.replay(
        &file,
        "tessla/robot2/action",
        Some(("telegraf", TELEGRAF_PW)),
        &tls,
    );
    assert_eq!(code, 0, "{out}");
    assert_eq!(drain(&actions2, Duration::from_secs(2)).len(), 3);
}

#[test]
fn each_refusal_says_why() {
    let Some(broker) = Broker::start() else {
        return;
    };
    let file = three_records(broker.server.dir.path());
    let tls = broker.tls();
    let tls: Vec<&str> = tls.iter().map(String::as_str).collect();

    // A wrong password.
    let (out, code) = broker.replay(&file, "tessla/robot1", Some(("robot1", ROBOT2_PW)), &tls);
    assert_eq!(code, 3, "{out}");
    assert!(
        out.contains("E! replay: MQTT broker mqtts://127.0.0.1:")
            && out.contains("refused the login (as user `robot1`"),
        "{out}"
    );
    // No login at all.
    let (out, code) = broker.replay(&file, "tessla/robot1", None, &tls);
    assert_eq!(code, 3, "{out}");
    assert!(
        out.contains("refused the login (without a user name"),
        "{out}"
    );
    // A CA that did not sign the broker's certificate.
    let other = broker.certs.join("other-ca.pem").display().to_string();
    let (out, code) = broker.replay(
        &file,
        "tessla/robot1",
        Some(("robot1", ROBOT1_PW)),
        &[
            "--broker",
            &format!("mqtts://127.0.0.1:{}", broker.port),
            "--tls-ca",
            &other,
        ],
    );
    assert_eq!(code, 3, "{out}");
    assert!(
        out.contains("E! replay: TLS failed with MQTT broker"),
        "{out}"
    );
    assert!(out.contains("invalid peer certificate"), "{out}");
    // A plain client on the TLS port.
    let (out, code) = broker.replay(
        &file,
        "tessla/robot1",
        Some(("robot1", ROBOT1_PW)),
        &["--broker", &format!("mqtt://127.0.0.1:{}", broker.port)],
    );
    assert_eq!(code, 3, "{out}");
    assert!(
        out.contains("cannot reach MQTT broker mqtt://127.0.0.1:"),
        "{out}"
    );
    // Bad command lines (exit 2): TLS without its CA, a password variable not set, credentials
    // in the address (masked in the message).
    let (out, code) = broker.replay(
        &file,
        "t",
        Some(("robot1", ROBOT1_PW)),
        &["--broker", &format!("mqtts://127.0.0.1:{}", broker.port)],
    );
    assert_eq!(code, 2, "{out}");
    assert!(out.contains("--tls-ca PATH must name the CA"), "{out}");
    let out = Command::new(BIN)
        .args(["replay", file.to_str().unwrap(), "--username", "u"])
        .args(["--password-env", "TESSLA_TEST_UNSET_VARIABLE"])
        .env_remove("TESSLA_TEST_UNSET_VARIABLE")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("TESSLA_TEST_UNSET_VARIABLE is not set"),
        "{err}"
    );
    let (out, code) = broker.replay(
        &file,
        "t",
        None,
        &[
            "--broker",
            &format!("mqtt://robot1:{ROBOT1_PW}@127.0.0.1:1"),
        ],
    );
    assert_eq!(code, 2, "{out}");
    assert!(out.contains("robot1:***@127.0.0.1:1"), "{out}");
}

/// A broker that asks for a client certificate (`require_certificate true`): without one the
/// handshake fails (exit 3, a TLS failure); with the test client certificate `replay` gets in.
#[test]
fn a_client_certificate_where_the_broker_asks_for_one() {
    let Some(broker) = Broker::start_with("require_certificate true") else {
        return;
    };
    let file = three_records(broker.server.dir.path());
    let tls = broker.tls();
    let tls: Vec<&str> = tls.iter().map(String::as_str).collect();
    let (out, code) = broker.replay(&file, "tessla/robot1", Some(("robot1", ROBOT1_PW)), &tls);
    assert_eq!(code, 3, "{out}");
    assert!(
        out.contains("E! replay: TLS failed with MQTT broker"),
        "{out}"
    );
    let cert = broker.certs.join("client.pem").display().to_string();
    let key = broker.certs.join("client-key.pem").display().to_string();
    let with_cert: Vec<&str> = tls
        .iter()
        .copied()
        .chain(["--tls-cert", cert.as_str(), "--tls-key", key.as_str()])
        .collect();
    let (out, code) = broker.replay(
        &file,
        "tessla/robot1",
        Some(("robot1", ROBOT1_PW)),
        &with_cert,
    );
    assert_eq!(code, 0, "{out}");
}
