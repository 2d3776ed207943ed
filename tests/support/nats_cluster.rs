//! A real 3-node nats-server cluster for the fleet tests: JetStream and the MQTT gateway on
//! every node, free 127.0.0.1 ports, a temporary folder, the subject mapping of
//! `telegraf/fleet-nats/mapping.conf` (or the same mapping for another partition count), and
//! nodes killed and reaped on drop. With `REQUIRE_SERVERS=1` a missing `nats-server` fails the
//! test; otherwise `start` explains how to install it and returns `None`.
//!
//! Include with `#[path = "support/nats_cluster.rs"] mod nats_cluster;`, after
//! `#[path = "support/servers.rs"] mod servers;` (port and binary lookup).
#![allow(dead_code)]

use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub use crate::servers::free_port;

/// `nats-server`, or `None` after explaining how to get it (panics when servers are required).
pub fn require_nats_server() -> Option<PathBuf> {
    crate::servers::require("nats-server", "nats-server")
}

/// The shipped mapping (`telegraf/fleet-nats/mapping.conf`, 2 partitions).
pub fn shipped_mapping() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("telegraf/fleet-nats/mapping.conf");
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
}

impl Cluster {
    /// Three nodes with `mapping` (text of a NATS config `mappings` block); returns once every
    /// node listens for clients and MQTT and JetStream has a meta leader.
    pub fn start(mapping: &str) -> Option<Cluster> {
        let binary = require_nats_server()?;
        let dir = tempfile::tempdir().unwrap();
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
            let text = format!(
                "server_name: {name}\nlisten: 127.0.0.1:{}\njetstream {{ store_dir: \"{}\" }}\n\
                 cluster {{ name: test-fleet\n listen: 127.0.0.1:{}\n routes: [{}] }}\n\
                 mqtt {{ listen: 127.0.0.1:{} }}\n{mapping}\n",
                p.client,
                store.display(),
                p.cluster,
                routes.join(", "),
                p.mqtt
            );
            std::fs::write(&conf, text).unwrap();
            let log = dir.path().join(format!("{name}.log"));
            let out = std::fs::File::create(&log).unwrap();
            let child = Command::new(&binary)
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
        let cluster = Cluster { nodes, dir };
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
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let ok = rt.block_on(async {
            let deadline = Instant::now() + Duration::from_secs(60);
            while Instant::now() < deadline {
                if let Ok(client) = async_nats::connect(url.as_str()).await
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
