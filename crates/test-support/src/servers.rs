//! Real servers for the pipeline tests: Mosquitto and InfluxDB 1.x, each started on a free
//! 127.0.0.1 port with a temporary data folder and stopped (killed and reaped) on drop; and
//! [`Server`], the same for a server run from a conf of the test's own (a secured broker, a
//! single nats-server).
//!
//! When a server binary is missing: with `REQUIRE_SERVERS=1` (set by `.ci/run`) the test fails;
//! otherwise `start` prints how to install it and returns `None`, and the test skips itself.

use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A free TCP port on 127.0.0.1 (see [`fresh_port`]).
pub fn free_port() -> u16 {
    fresh_port(|| {
        TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port()
    })
}

/// A free port from `bind_any` (bind port 0, read the port, release it), never one this process
/// was given before, TCP or UDP: the tests run at once in one process, the kernel may hand a
/// just-released port out again before a child has bound it, and a server given the same port
/// twice (a NATS node's client, cluster and MQTT ports, say) fails to start.
pub fn fresh_port(mut bind_any: impl FnMut() -> u16) -> u16 {
    static GIVEN: std::sync::Mutex<Vec<u16>> = std::sync::Mutex::new(Vec::new());
    let mut given = GIVEN.lock().unwrap_or_else(|e| e.into_inner());
    loop {
        let port = bind_any();
        if !given.contains(&port) {
            given.push(port);
            return port;
        }
    }
}

fn find_binary(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .chain([PathBuf::from("/usr/sbin"), PathBuf::from("/usr/bin")])
        .map(|dir| dir.join(name))
        .find(|candidate| candidate.is_file())
}

/// The binary, or `None` after explaining how to get it (panics when servers are required).
pub fn require(name: &str, package: &str) -> Option<PathBuf> {
    if let Some(path) = find_binary(name) {
        return Some(path);
    }
    let hint = format!(
        "`{name}` not found: install it with `sudo apt-get install {package}` \
         (Debian/Ubuntu; .ci/run installs mosquitto, influxdb and nats-server)"
    );
    if std::env::var("REQUIRE_SERVERS").is_ok_and(|v| v == "1") {
        panic!("REQUIRE_SERVERS=1 but {hint}");
    }
    eprintln!("SKIPPED: {hint}");
    // The note `make test` prints loudly at the end (tools/test-skips.sh), as
    // tessla_suite::note_skip leaves for a missing suite; best effort, the message above stands.
    let dir = crate::paths::skip_dir();
    let _ = std::fs::create_dir_all(&dir);
    let _ = std::fs::write(dir.join(format!("needs-{name}")), format!("{hint}\n"));
    None
}

/// A server process started from a conf file in a temporary folder (its output in a log file
/// there), ready once it accepts connections on 127.0.0.1:`port`; killed and reaped on drop.
/// [`Mosquitto`] and [`Influxd`] are ones; tests start others with a conf of their own.
pub struct Server {
    pub port: u16,
    /// The temporary folder: the conf, the log and whatever the test put there.
    pub dir: tempfile::TempDir,
    child: Child,
    log: PathBuf,
}

impl Server {
    /// Write `conf` to `dir/conf_name`, run `binary` with `args` and the conf's path, and wait
    /// (30 s at most) until it listens on `port`; fails the test, with the log, if it exits
    /// before or never listens.
    pub fn start(
        binary: &Path,
        args: &[&str],
        dir: tempfile::TempDir,
        port: u16,
        conf_name: &str,
        conf: &str,
    ) -> Server {
        let conf_path = dir.path().join(conf_name);
        std::fs::write(&conf_path, conf).unwrap();
        let log = dir.path().join("server.log");
        let out = std::fs::File::create(&log).unwrap();
        let err = out.try_clone().unwrap();
        let mut child = Command::new(binary)
            .args(args)
            .arg(&conf_path)
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(err)
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {}: {e}", binary.display()));
        let what = binary.display();
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if TcpStream::connect(("127.0.0.1", port)).is_ok() {
                break;
            }
            if let Ok(Some(status)) = child.try_wait() {
                panic!(
                    "{what} exited ({status}) before listening on {port}; log:\n{}",
                    std::fs::read_to_string(&log).unwrap_or_default()
                );
            }
            if Instant::now() >= deadline {
                let _ = child.kill();
                let _ = child.wait();
                panic!(
                    "{what} did not listen on 127.0.0.1:{port} within 30 s; log:\n{}",
                    std::fs::read_to_string(&log).unwrap_or_default()
                );
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        Server {
            port,
            dir,
            child,
            log,
        }
    }

    /// What the server printed so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A running Mosquitto broker.
pub struct Mosquitto {
    pub port: u16,
    _server: Server,
}

impl Mosquitto {
    pub fn start() -> Option<Mosquitto> {
        Self::start_with("")
    }

    /// A broker with `extra` lines added to the test conf (anonymous, no persistence).
    pub fn start_with(extra: &str) -> Option<Mosquitto> {
        let binary = require("mosquitto", "mosquitto")?;
        let port = free_port();
        let conf = format!(
            "listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\n\
             log_dest stdout\n{extra}"
        );
        let server = Server::start(
            &binary,
            &["-c"],
            tempfile::tempdir().unwrap(),
            port,
            "mosquitto.conf",
            &conf,
        );
        Some(Mosquitto {
            port,
            _server: server,
        })
    }

    pub fn url(&self) -> String {
        format!("mqtt://127.0.0.1:{}", self.port)
    }

    /// What the broker has logged so far.
    pub fn log(&self) -> String {
        self._server.log()
    }
}

/// A running InfluxDB 1.x server.
pub struct Influxd {
    pub port: u16,
    _server: Server,
}

impl Influxd {
    pub fn start() -> Option<Influxd> {
        let binary = require("influxd", "influxdb")?;
        let dir = tempfile::tempdir().unwrap();
        let port = free_port();
        let rpc_port = free_port();
        let d = dir.path().display().to_string();
        let conf = format!(
            "reporting-disabled = true\n\
             bind-address = \"127.0.0.1:{rpc_port}\"\n\
             [meta]\n  dir = \"{d}/meta\"\n\
             [data]\n  dir = \"{d}/data\"\n  wal-dir = \"{d}/wal\"\n  query-log-enabled = false\n\
             [http]\n  bind-address = \"127.0.0.1:{port}\"\n  log-enabled = false\n\
             [monitor]\n  store-enabled = false\n\
             [continuous_queries]\n  enabled = false\n"
        );
        let server = Server::start(
            &binary,
            &["run", "-config"],
            dir,
            port,
            "influxdb.conf",
            &conf,
        );
        let server = Influxd {
            port,
            _server: server,
        };
        // The HTTP port opens before the service is ready: wait for /ping to answer 204.
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Ok(r) = agent().get(&server.url("/ping")).call()
                && r.status() == 204
            {
                break;
            }
            assert!(
                Instant::now() < deadline,
                "influxd /ping never answered 204"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        Some(server)
    }

    pub fn url(&self, path: &str) -> String {
        format!("http://127.0.0.1:{}{path}", self.port)
    }

    /// Run an InfluxQL statement (POST /query); returns the status and the JSON answer.
    pub fn query(&self, db: Option<&str>, q: &str) -> (u16, serde_json::Value) {
        let mut request = agent()
            .post(&self.url("/query"))
            .query("q", q)
            .query("epoch", "ns");
        if let Some(db) = db {
            request = request.query("db", db);
        }
        let mut response = request.send_empty().unwrap();
        let status = response.status().as_u16();
        let body = response.body_mut().read_to_string().unwrap();
        let json = serde_json::from_str(&body)
            .unwrap_or_else(|e| panic!("influxd answered non-JSON ({e}) to {q:?}: {body}"));
        (status, json)
    }

    /// Write line protocol (POST /write, ns precision); returns the status and the body.
    pub fn write(&self, db: &str, lines: &str) -> (u16, String) {
        let mut response = agent()
            .post(&self.url("/write"))
            .query("db", db)
            .query("precision", "ns")
            .send(lines.as_bytes())
            .unwrap();
        let status = response.status().as_u16();
        (
            status,
            response.body_mut().read_to_string().unwrap_or_default(),
        )
    }
}

/// An HTTP agent that returns 4xx/5xx answers instead of failing on them.
pub fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_global(Some(Duration::from_secs(60)))
        .build()
        .into()
}
