//! A real 3-node nats-server cluster for the fleet tests: JetStream and the MQTT gateway on
//! every node, free 127.0.0.1 ports, a temporary folder, the subject mapping of
//! `telegraf/fleet-nats/mapping.conf` (or the same mapping for another partition count), and
//! nodes killed and reaped on drop. With `REQUIRE_SERVERS=1` a missing `nats-server` fails the
//! test; otherwise `start` explains how to install it and returns `None`.
//!
//! [`Cluster::start_secured`] runs the shipped security instead (`telegraf/fleet-nats/`): TLS on
//! client, route and MQTT connections with certificates made now by the shipped
//! `make-test-certs.sh`, and the users and permissions of `accounts.conf` (its example robots
//! replaced by the test's), each with a password made for the run ([`Cluster::login`]).
//!
//! Uses its sibling [`crate::servers`] (port and binary lookup); bench/fleet_nats.rs uses both.

use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// One fleet at a time in this process: a test that runs a cluster with several monitoring
/// processes (stand-in or real Telegrafs) and times a takeover against the lease TTL holds this
/// for its run (tests/servers/fleet_nats.rs, tests/servers/telegraf_real_nats.rs), so that two
/// such fleets never share the machine's 2 cores. Smaller tests may still run beside one, as
/// libtest runs two at once.
pub fn one_fleet_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static FLEET: std::sync::Mutex<()> = std::sync::Mutex::new(());
    FLEET.lock().unwrap_or_else(|e| e.into_inner())
}

pub use crate::servers::free_port;

/// `nats-server`, or `None` after explaining how to get it (panics when servers are required).
pub fn require_nats_server() -> Option<PathBuf> {
    crate::servers::require("nats-server", "nats-server")
}

/// The shipped mapping (`telegraf/fleet-nats/mapping.conf`, 2 partitions).
pub fn shipped_mapping() -> String {
    let path = crate::paths::workspace_root().join("telegraf/fleet-nats/mapping.conf");
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The shipped mapping with `partitions` partitions instead of 2.
pub fn mapping(partitions: usize) -> String {
    let text = shipped_mapping();
    assert!(text.contains("{{partition(2,1)}}"), "mapping.conf changed");
    text.replace(
        "{{partition(2,1)}}",
        &format!("{{{{partition({partitions},1)}}}}"),
    )
}

/// One node's ports.
#[derive(Debug, Clone, Copy)]
pub struct Ports {
    pub client: u16,
    pub cluster: u16,
    pub mqtt: u16,
}

pub struct Node {
    pub ports: Ports,
    child: Option<Child>,
    log: PathBuf,
}

pub struct Cluster {
    pub nodes: Vec<Node>,
    dir: tempfile::TempDir,
    /// The secured cluster's certificates folder and (user, password) pairs.
    security: Option<Security>,
}

struct Security {
    certs: PathBuf,
    passwords: Vec<(String, String)>,
}

/// How a test-side client logs in: nothing on an open cluster; a user, its password and the
/// test CA on a secured one. (No `Debug`: it holds a password.)
#[derive(Clone)]
pub struct Login {
    pub user: Option<String>,
    pub password: String,
    pub ca: Option<PathBuf>,
}

impl Login {
    pub fn open() -> Login {
        Login {
            user: None,
            password: String::new(),
            ca: None,
        }
    }

    pub async fn connect(&self, url: &str) -> Result<async_nats::Client, async_nats::ConnectError> {
        let mut o = async_nats::ConnectOptions::new();
        if let Some(user) = &self.user {
            o = o.user_and_password(user.clone(), self.password.clone());
        }
        if let Some(ca) = &self.ca {
            o = o.add_root_certificates(ca.clone()).require_tls(true);
        }
        o.connect(url).await
    }
}

/// The shipped `accounts.conf` with its example robots replaced by `robots` (same entry each).
pub fn shipped_accounts(robots: &[String]) -> String {
    let path = crate::paths::workspace_root().join("telegraf/fleet-nats/accounts.conf");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let begin = text
        .find("# robots begin")
        .expect("accounts.conf: # robots begin");
    let end = text
        .find("# robots end")
        .expect("accounts.conf: # robots end");
    let block = &text[begin..end];
    let first = block.find('{').unwrap();
    let close = block[first..].find("\n    }").unwrap() + first + 6;
    let template = &block[first..close];
    assert!(
        template.contains("robot1") && template.contains("ROBOT1"),
        "{template}"
    );
    let entries: Vec<String> = robots
        .iter()
        .map(|r| {
            template
                .replace("robot1", r)
                .replace("ROBOT1", &r.to_ascii_uppercase())
        })
        .collect();
    format!(
        "{}# robots begin\n    {}\n    {}",
        &text[..begin],
        entries.join("\n    "),
        &text[end..]
    )
}

/// The users of `accounts.conf` (fleet-p0, fleet-p1, admin and the robots), each with a password
/// made for this run, passed to nats-server as the environment variables the file names.
fn passwords(robots: &[String]) -> Vec<(String, String)> {
    let seed = std::process::id() as u64 ^ Instant::now().elapsed().as_nanos() as u64;
    ["fleet-p0", "fleet-p1", "admin"]
        .iter()
        .map(|s| s.to_string())
        .chain(robots.iter().cloned())
        .enumerate()
        .map(|(i, user)| {
            (
                user,
                format!("Pw{:x}x{i}", seed.wrapping_mul(0x9e37_79b9_7f4a_7c15)),
            )
        })
        .collect()
}

fn password_var(user: &str) -> String {
    match user {
        "admin" => "FLEET_ADMIN_PASSWORD".into(),
        _ => format!("{}_PASSWORD", user.to_ascii_uppercase().replace('-', "_")),
    }
}

/// Make the test certificates with the shipped script into `dir`.
pub fn make_certs(dir: &Path) {
    let script = crate::paths::workspace_root().join("telegraf/fleet-nats/make-test-certs.sh");
    let out = Command::new("bash")
        .arg(&script)
        .arg(dir)
        .output()
        .unwrap_or_else(|e| panic!("bash {}: {e}", script.display()));
    assert!(
        out.status.success(),
        "{} failed (is openssl installed? tools/setup.sh installs it): {}",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
}

impl Cluster {
    /// Three nodes with `mapping` (text of a NATS config `mappings` block); returns once every
    /// node listens for clients and MQTT and JetStream has a meta leader.
    pub fn start(mapping: &str) -> Option<Cluster> {
        Self::launch(mapping, None)
    }

    /// Three nodes with the shipped security (module doc) and robot users `robots`.
    pub fn start_secured(mapping: &str, robots: &[String]) -> Option<Cluster> {
        Self::launch(mapping, Some(robots))
    }

    fn launch(mapping: &str, robots: Option<&[String]>) -> Option<Cluster> {
        let binary = require_nats_server()?;
        let dir = tempfile::tempdir().unwrap();
        let security = robots.map(|robots| {
            let certs = dir.path().join("certs");
            make_certs(&certs);
            std::fs::write(dir.path().join("accounts.conf"), shipped_accounts(robots)).unwrap();
            Security {
                certs,
                passwords: passwords(robots),
            }
        });
        let ports: Vec<Ports> = (0..3)
            .map(|_| Ports {
                client: free_port(),
                cluster: free_port(),
                mqtt: free_port(),
            })
            .collect();
        let routes: Vec<String> = ports
            .iter()
            .map(|p| format!("nats-route://127.0.0.1:{}", p.cluster))
            .collect();
        let mut nodes = Vec::new();
        for (i, p) in ports.iter().enumerate() {
            let name = format!("n{}", i + 1);
            let store = dir.path().join(&name);
            let conf = dir.path().join(format!("{name}.conf"));
            let text = match &security {
                None => format!(
                    "server_name: {name}\nlisten: 127.0.0.1:{}\njetstream {{ store_dir: \"{}\" }}\n\
                     cluster {{ name: test-fleet\n listen: 127.0.0.1:{}\n routes: [{}] }}\n\
                     mqtt {{ listen: 127.0.0.1:{} }}\n{mapping}\n",
                    p.client,
                    store.display(),
                    p.cluster,
                    routes.join(", "),
                    p.mqtt
                ),
                // As telegraf/fleet-nats/common.conf, on loopback ports and the test certificates.
                Some(sec) => {
                    let c = sec.certs.display();
                    let tls = format!(
                        "cert_file: \"{c}/server.pem\", key_file: \"{c}/server-key.pem\", \
                         ca_file: \"{c}/ca.pem\", timeout: 2"
                    );
                    format!(
                        "server_name: {name}\nlisten: 127.0.0.1:{}\ntls {{ {tls} }}\n\
                         jetstream {{ store_dir: \"{}\" }}\n\
                         cluster {{ name: test-fleet\n listen: 127.0.0.1:{}\n tls {{ {tls}, verify: true }}\n routes: [{}] }}\n\
                         mqtt {{ listen: 127.0.0.1:{}\n tls {{ {tls} }} }}\n\
                         include ./accounts.conf\n{mapping}\n",
                        p.client,
                        store.display(),
                        p.cluster,
                        routes.join(", "),
                        p.mqtt
                    )
                }
            };
            std::fs::write(&conf, text).unwrap();
            let log = dir.path().join(format!("{name}.log"));
            let out = std::fs::File::create(&log).unwrap();
            let mut command = Command::new(&binary);
            if let Some(sec) = &security {
                for (user, password) in &sec.passwords {
                    command.env(password_var(user), password);
                }
            }
            let child = command
                .args(["-c", conf.to_str().unwrap()])
                .stdin(Stdio::null())
                .stdout(out.try_clone().unwrap())
                .stderr(out)
                .spawn()
                .unwrap_or_else(|e| panic!("cannot start {}: {e}", binary.display()));
            nodes.push(Node {
                ports: *p,
                child: Some(child),
                log,
            });
        }
        let cluster = Cluster {
            nodes,
            dir,
            security,
        };
        for n in 0..3 {
            cluster.wait_port(n, cluster.nodes[n].ports.client);
            cluster.wait_port(n, cluster.nodes[n].ports.mqtt);
        }
        cluster.wait_for_jetstream();
        Some(cluster)
    }

    fn wait_port(&self, n: usize, port: u16) {
        let deadline = Instant::now() + Duration::from_secs(60);
        while Instant::now() < deadline {
            if TcpStream::connect(("127.0.0.1", port)).is_ok() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        panic!(
            "nats node {n} did not listen on {port} within 60 s; log:\n{}",
            self.log(n)
        );
    }

    /// Until a JetStream request (the account info) is answered: the cluster has a leader.
    fn wait_for_jetstream(&self) {
        let url = self.url(0);
        let login = self.login("admin");
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let ok = rt.block_on(async {
            let deadline = Instant::now() + Duration::from_secs(60);
            while Instant::now() < deadline {
                if let Ok(client) = login.connect(url.as_str()).await
                    && let Ok(reply) = client.request("$JS.API.INFO", "".into()).await
                    && serde_json::from_slice::<serde_json::Value>(&reply.payload)
                        .is_ok_and(|v| v.get("error").is_none())
                {
                    return true;
                }
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
            false
        });
        assert!(ok, "JetStream not ready within 60 s; log:\n{}", self.log(0));
    }

    /// `nats://127.0.0.1:PORT` of node `n`.
    pub fn url(&self, n: usize) -> String {
        format!("nats://127.0.0.1:{}", self.nodes[n].ports.client)
    }

    /// `127.0.0.1:PORT,127.0.0.1:PORT,...` of every node, for `--state nats://...`.
    pub fn hosts(&self) -> String {
        self.nodes
            .iter()
            .map(|n| format!("127.0.0.1:{}", n.ports.client))
            .collect::<Vec<_>>()
            .join(",")
    }

    /// How `user` of `accounts.conf` logs in (an open cluster: no login at all).
    pub fn login(&self, user: &str) -> Login {
        match &self.security {
            None => Login::open(),
            Some(sec) => Login {
                user: Some(user.to_string()),
                password: self.password(user),
                ca: Some(sec.certs.join("ca.pem")),
            },
        }
    }

    /// The password of `user` on the secured cluster.
    pub fn password(&self, user: &str) -> String {
        self.security
            .as_ref()
            .and_then(|s| s.passwords.iter().find(|(u, _)| u == user))
            .map(|(_, p)| p.clone())
            .unwrap_or_else(|| panic!("no user {user}"))
    }

    /// The test certificates' folder (`ca.pem`, `client.pem`, ...) of the secured cluster.
    pub fn certs(&self) -> PathBuf {
        self.security
            .as_ref()
            .map(|s| s.certs.clone())
            .expect("a secured cluster")
    }

    pub fn log(&self, n: usize) -> String {
        std::fs::read_to_string(&self.nodes[n].log).unwrap_or_default()
    }

    /// SIGKILL node `n` (a machine gone).
    pub fn kill(&mut self, n: usize) {
        if let Some(mut c) = self.nodes[n].child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    pub fn dir(&self) -> &Path {
        self.dir.path()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        for n in 0..self.nodes.len() {
            self.kill(n);
        }
    }
}
