//! The real Telegraf, as the tests run it: the binaries `tools/build-telegraf.sh` builds from
//! Telegraf's Go module at the pinned versions ([`VERSIONS`]), a shipped conf with only its
//! endpoints rewritten ([`Rewrite`]), started as `telegraf --config FILE` with our release-test
//! binary as its `processors.execd` child, its log kept in a file, stopped with SIGTERM as
//! systemd stops it (or killed).
//!
//! When a pinned build is missing: with `REQUIRE_SERVERS=1` (set by `.ci/run`, which builds
//! both) the test fails; otherwise it prints how to build it, leaves a note for `make test`'s
//! skip banner and the test skips itself, as for a missing server.
//!
//! Also what turns Telegraf's deliveries back into records: [`influx_rows`] reads a measurement
//! out of InfluxDB with its tags and field types, [`to_lines`] writes those rows as line
//! protocol, so that an offline `run` can be fed exactly what Telegraf fed the monitor.
//!
//! Our binary, which a conf's `processors.execd` runs, is passed in ([`Rewrite::robot`],
//! [`offline`]): the root crate's tests pass `CARGO_BIN_EXE_tessla-telegraf`
//! (tests/support/real_telegraf.rs), bench/telegraf_delay.rs the release build.

use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The floor the README names and the newest release, both built by `tools/build-telegraf.sh`.
pub const VERSIONS: [&str; 2] = ["v1.33.3", "v1.39.3"];

/// Where `tools/build-telegraf.sh` puts its builds (`TELEGRAF_CACHE`, else the user's cache).
pub fn cache_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("TELEGRAF_CACHE") {
        return PathBuf::from(dir);
    }
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(std::env::var_os("HOME").unwrap_or_else(|| "/root".into())).join(".cache")
        });
    base.join("tessla-telegraf").join("telegraf")
}

/// The Telegraf binary of `version`, or `None` after saying how to build it (a failure when
/// `REQUIRE_SERVERS=1`).
pub fn binary(version: &str) -> Option<PathBuf> {
    let path = cache_dir().join(version).join("telegraf");
    if path.is_file() {
        return Some(path);
    }
    let hint = format!(
        "Telegraf {version} not built (looked for {}): run `bash tools/build-telegraf.sh` \
         (needs Go 1.26 and the Go module proxy; `make setup` does it)",
        path.display()
    );
    if std::env::var("REQUIRE_SERVERS").is_ok_and(|v| v == "1") {
        panic!("REQUIRE_SERVERS=1 but {hint}");
    }
    eprintln!("SKIPPED: {hint}");
    let dir = crate::paths::skip_dir();
    let _ = std::fs::create_dir_all(&dir);
    let _ = std::fs::write(
        dir.join(format!("needs-telegraf-{version}")),
        format!("{hint}\n"),
    );
    None
}

/// Every pinned version that is built (see [`binary`] for a missing one).
pub fn versions() -> Vec<(&'static str, PathBuf)> {
    VERSIONS
        .iter()
        .filter_map(|v| binary(v).map(|b| (*v, b)))
        .collect()
}

/// The text of a shipped file, by its path in the repository.
pub fn shipped(path: &str) -> String {
    let full = crate::paths::workspace_root().join(path);
    std::fs::read_to_string(&full).unwrap_or_else(|e| panic!("{}: {e}", full.display()))
}

/// Substitutions that move a shipped conf onto the test's servers. Each `from` must occur in
/// the conf, so a conf that changes its endpoints fails the test instead of reaching a real
/// server on a default port.
#[derive(Default)]
pub struct Rewrite(Vec<(String, String)>);

impl Rewrite {
    pub fn new() -> Rewrite {
        Rewrite::default()
    }

    pub fn replace(mut self, from: &str, to: impl Into<String>) -> Rewrite {
        self.0.push((from.to_string(), to.into()));
        self
    }

    /// The broker, InfluxDB and our binary (`bin`): what every shipped robot conf names.
    pub fn robot(bin: impl AsRef<Path>, mqtt_port: u16, influx_url: Option<&str>) -> Rewrite {
        Rewrite::robot_without_binary(mqtt_port, influx_url).replace(
            "\"/usr/bin/tessla-telegraf\"",
            format!("{:?}", bin.as_ref().display().to_string()),
        )
    }

    /// The broker and InfluxDB only (a conf that runs no child, the UDP wiring).
    pub fn robot_without_binary(mqtt_port: u16, influx_url: Option<&str>) -> Rewrite {
        let mut r = Rewrite::new().replace(
            "tcp://127.0.0.1:1883",
            format!("tcp://127.0.0.1:{mqtt_port}"),
        );
        if let Some(url) = influx_url {
            r = r.replace("http://127.0.0.1:8086", url);
        }
        r
    }

    /// The monitors' `--state` files in `dir` instead of the systemd drop-in's StateDirectory
    /// (each test its own, as tests run at once).
    pub fn state_in(self, dir: &Path) -> Rewrite {
        self.replace("/var/lib/tessla-telegraf", dir.display().to_string())
    }

    /// The variant `telegraf.conf`'s comment describes: the robot's own time in each message
    /// (`json_time_key = "time"`, nanoseconds) instead of the time Telegraf parsed it.
    pub fn robots_time(self) -> Rewrite {
        self.replace(
            "  json_string_fields = [\"actualSpeed\"]\n",
            "  json_string_fields = [\"actualSpeed\"]\n  json_time_key = \"time\"\n  json_time_format = \"unix_ns\"\n",
        )
    }

    pub fn apply(&self, conf: &str) -> String {
        let mut text = conf.to_string();
        for (from, to) in &self.0 {
            assert!(
                text.contains(from.as_str()),
                "the conf no longer names {from:?}"
            );
            text = text.replace(from.as_str(), to);
        }
        text
    }
}

/// The conf with its `processors.execd` rewired: `processors.clone` (order 1) adds the tag
/// `tessla_copy` to a copy of each robot metric; the execd processor (order 2) takes only that
/// copy (`tagpass`), removes the tag (`tagexclude`) and runs with `--no-passthrough`.
pub fn clone_wiring(conf: &str) -> Result<String, &'static str> {
    let header = "[[processors.execd]]\n";
    let at = conf
        .find(header)
        .ok_or("the conf has no [[processors.execd]]")?;
    let command = conf[at..]
        .find("command = [")
        .map(|c| at + c)
        .ok_or("the execd processor has no command")?;
    let end = conf[command..]
        .find(']')
        .map(|e| command + e)
        .ok_or("the execd command does not end")?;
    let next = conf[at + header.len()..]
        .find("\n[")
        .map(|n| at + header.len() + n + 1)
        .unwrap_or(conf.len());
    Ok(format!(
        "{}[[processors.clone]]\n  order = 1\n  namepass = [\"mqtt_consumer\"]\n  \
         [processors.clone.tags]\n    tessla_copy = \"1\"\n\n{header}  order = 2\n  \
         tagexclude = [\"tessla_copy\"]\n{}, \"--no-passthrough\"{}  \
         [processors.execd.tagpass]\n    tessla_copy = [\"1\"]\n\n{}",
        &conf[..at],
        &conf[at + header.len()..end],
        &conf[end..next],
        &conf[next..]
    ))
}

/// A running Telegraf: `telegraf --config FILE` in a temporary folder, its log (stderr) in
/// `telegraf.log` there. Killed on drop unless stopped.
pub struct Telegraf {
    pub version: String,
    child: Option<Child>,
    pub dir: tempfile::TempDir,
    log: PathBuf,
}

impl Telegraf {
    /// Start `binary` on `conf` (written to the folder as `telegraf.conf`) with `env` added to
    /// its environment; waits until every MQTT or NATS input says it is connected and
    /// subscribed, so that nothing published after this returns is missed.
    pub fn start(version: &str, binary: &Path, conf: &str, env: &[(&str, &str)]) -> Telegraf {
        Self::start_with(version, binary, conf, env, &[])
    }

    /// As [`Telegraf::start`] with extra command-line flags.
    pub fn start_with(
        version: &str,
        binary: &Path,
        conf: &str,
        env: &[(&str, &str)],
        flags: &[&str],
    ) -> Telegraf {
        let dir = tempfile::tempdir().unwrap();
        let conf_path = dir.path().join("telegraf.conf");
        std::fs::write(&conf_path, conf).unwrap();
        let log = dir.path().join("telegraf.log");
        let child = Command::new(binary)
            .arg("--config")
            .arg(&conf_path)
            .args(flags)
            .envs(env.iter().copied())
            .current_dir(crate::paths::workspace_root())
            .stdin(Stdio::null())
            .stdout(std::fs::File::create(dir.path().join("telegraf.out")).unwrap())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .unwrap_or_else(|e| panic!("{}: {e}", binary.display()));
        let t = Telegraf {
            version: version.to_string(),
            child: Some(child),
            dir,
            log,
        };
        let inputs = conf.matches("[[inputs.mqtt_consumer]]").count()
            + conf.matches("[[inputs.nats_consumer]]").count();
        t.wait_for(
            |log| {
                log.lines()
                    .filter(|l| {
                        // mqtt_consumer logs "Connected [...]" (then subscribes: wait for the
                        // broker's SUBSCRIBE too), nats_consumer "Started the NATS consumer
                        // service" once subscribed.
                        (l.contains("[inputs.mqtt_consumer]") && l.contains("Connected"))
                            || (l.contains("[inputs.nats_consumer]")
                                && l.contains("Started the NATS consumer service"))
                    })
                    .count()
                    >= inputs
            },
            Duration::from_secs(30),
            "its inputs to connect",
        );
        t
    }

    pub fn pid(&self) -> u32 {
        self.child.as_ref().map(|c| c.id()).unwrap_or(0)
    }

    /// What Telegraf has logged so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// What Telegraf wrote to its stdout (`outputs.file` with `files = ["stdout"]`).
    pub fn stdout(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("telegraf.out")).unwrap_or_default()
    }

    /// Wait until `ready` holds for the log; fails the test with the log after `timeout`.
    pub fn wait_for(&self, ready: impl Fn(&str) -> bool, timeout: Duration, what: &str) {
        let deadline = Instant::now() + timeout;
        loop {
            let log = self.log();
            if ready(&log) {
                return;
            }
            assert!(
                alive(self.pid()),
                "Telegraf {} exited while waiting for {what}; its log:\n{log}",
                self.version
            );
            assert!(
                Instant::now() < deadline,
                "Telegraf {} never showed {what} within {timeout:?}; its log:\n{log}",
                self.version
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The PIDs of Telegraf's child processes (the execd monitors).
    pub fn children(&self) -> Vec<u32> {
        children_of(self.pid())
    }

    /// Wait until Telegraf has a child process other than those in `not`, and return its PID.
    pub fn wait_child(&self, not: &[u32], timeout: Duration) -> u32 {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(pid) = self.children().into_iter().find(|p| !not.contains(p)) {
                return pid;
            }
            assert!(
                Instant::now() < deadline,
                "Telegraf {} started no new child within {timeout:?}; its log:\n{}",
                self.version,
                self.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Stop Telegraf as systemd does (SIGTERM) and wait for it; returns its log. Fails the test
    /// if it is still running after 30 s.
    pub fn stop(mut self) -> String {
        self.signal("TERM");
        self.wait_exit(Duration::from_secs(30));
        self.log()
    }

    /// As [`Telegraf::stop`], also returning what Telegraf wrote to its stdout (`outputs.file`
    /// flushes at the stop).
    pub fn stop_with_stdout(mut self) -> (String, String) {
        self.signal("TERM");
        self.wait_exit(Duration::from_secs(30));
        (self.log(), self.stdout())
    }

    /// SIGKILL Telegraf alone (a crash): its child is not signalled.
    pub fn crash(mut self) -> String {
        self.signal("KILL");
        self.wait_exit(Duration::from_secs(10));
        self.log()
    }

    pub fn signal(&self, sig: &str) {
        let status = Command::new("kill")
            .arg(format!("-{sig}"))
            .arg(self.pid().to_string())
            .status()
            .unwrap();
        assert!(status.success(), "kill -{sig} {}", self.pid());
    }

    fn wait_exit(&mut self, timeout: Duration) -> Option<std::process::ExitStatus> {
        let child = self.child.as_mut()?;
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(status) = child.try_wait().unwrap() {
                self.child = None;
                return Some(status);
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                let _ = child.wait();
                self.child = None;
                panic!(
                    "Telegraf {} did not exit within {timeout:?}; its log:\n{}",
                    self.version,
                    self.log()
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Telegraf {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let kids = children_of(child.id());
            let _ = child.kill();
            let _ = child.wait();
            for pid in kids {
                let _ = Command::new("kill")
                    .arg("-KILL")
                    .arg(pid.to_string())
                    .status();
            }
        }
    }
}

/// The PIDs whose parent is `pid` (Linux `/proc`).
pub fn children_of(pid: u32) -> Vec<u32> {
    let mut out = Vec::new();
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return out;
    };
    for task in tasks.flatten() {
        if let Ok(text) = std::fs::read_to_string(task.path().join("children")) {
            out.extend(
                text.split_whitespace()
                    .filter_map(|p| p.parse::<u32>().ok()),
            );
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// Whether process `pid` still exists (and is not a zombie).
pub fn alive(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .map(|s| {
            s.rsplit(')')
                .next()
                .and_then(|rest| rest.split_whitespace().next())
                .is_some_and(|state| state != "Z")
        })
        .unwrap_or(false)
}

/// A field value as InfluxDB returns it, typed by `SHOW FIELD KEYS`.
#[derive(Debug, Clone, PartialEq)]
pub enum Field {
    Float(f64),
    Int(i64),
    Bool(bool),
    Str(String),
}

/// One point: time (ns), tags, fields.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    pub time: i64,
    pub tags: BTreeMap<String, String>,
    pub fields: BTreeMap<String, Field>,
}

/// Every point of `measurement` in database `db`, oldest first, with tags and typed fields.
pub fn influx_rows(influx: &crate::servers::Influxd, db: &str, measurement: &str) -> Vec<Row> {
    // The points first, their tag and field keys after: a field written between the two
    // queries is then known (points keep coming while a test polls), never a type missing.
    // `GROUP BY *` puts the tags in each series (none when the measurement has none).
    let (status, v) = influx.query(
        Some(db),
        &format!("SELECT * FROM \"{measurement}\" GROUP BY * ORDER BY time"),
    );
    assert_eq!(status, 200, "{v}");
    let (_, keys) = influx.query(Some(db), &format!("SHOW TAG KEYS FROM \"{measurement}\""));
    let tag_keys: Vec<String> = keys["results"][0]["series"][0]["values"]
        .as_array()
        .map(|v| {
            v.iter()
                .filter_map(|r| r[0].as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default();
    let (_, fkeys) = influx.query(Some(db), &format!("SHOW FIELD KEYS FROM \"{measurement}\""));
    let field_types: BTreeMap<String, String> = fkeys["results"][0]["series"][0]["values"]
        .as_array()
        .map(|v| {
            v.iter()
                .filter_map(|r| Some((r[0].as_str()?.to_string(), r[1].as_str()?.to_string())))
                .collect()
        })
        .unwrap_or_default();
    let mut rows = Vec::new();
    for series in v["results"][0]["series"].as_array().into_iter().flatten() {
        let tags: BTreeMap<String, String> = series["tags"]
            .as_object()
            .map(|o| {
                o.iter()
                    .filter(|(_, v)| v.as_str().is_some_and(|s| !s.is_empty()))
                    .map(|(k, v)| (k.clone(), v.as_str().unwrap_or("").to_string()))
                    .collect()
            })
            .unwrap_or_default();
        let columns: Vec<&str> = series["columns"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_str().unwrap())
            .collect();
        for values in series["values"].as_array().into_iter().flatten() {
            let mut row = Row {
                time: values[0].as_i64().unwrap(),
                tags: tags.clone(),
                fields: BTreeMap::new(),
            };
            for (i, name) in columns.iter().enumerate().skip(1) {
                let value = &values[i];
                if value.is_null() || tag_keys.iter().any(|t| t == name) {
                    continue;
                }
                let field = match field_types.get(*name).map(String::as_str) {
                    Some("float") => Field::Float(value.as_f64().unwrap()),
                    Some("integer") => Field::Int(value.as_i64().unwrap()),
                    Some("boolean") => Field::Bool(value.as_bool().unwrap()),
                    Some("string") => Field::Str(value.as_str().unwrap().to_string()),
                    other => panic!("field {name} of {measurement}: type {other:?}"),
                };
                row.fields.insert(name.to_string(), field);
            }
            rows.push(row);
        }
    }
    rows.sort_by_key(|r| r.time);
    rows
}

fn escape_key(s: &str) -> String {
    s.replace('\\', "\\\\")
        .replace(',', "\\,")
        .replace('=', "\\=")
        .replace(' ', "\\ ")
}

/// Rows as line protocol of `measurement`, one line each, in the order given.
pub fn to_lines(measurement: &str, rows: &[Row]) -> String {
    let mut out = String::new();
    for row in rows {
        out.push_str(&escape_key(measurement));
        for (k, v) in &row.tags {
            out.push_str(&format!(",{}={}", escape_key(k), escape_key(v)));
        }
        let fields: Vec<String> = row
            .fields
            .iter()
            .map(|(k, v)| {
                let value = match v {
                    Field::Float(f) => format!("{f:?}"),
                    Field::Int(i) => format!("{i}i"),
                    Field::Bool(b) => b.to_string(),
                    Field::Str(s) => {
                        format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
                    }
                };
                format!("{}={value}", escape_key(k))
            })
            .collect();
        out.push_str(&format!(" {} {}\n", fields.join(","), row.time));
    }
    out
}

/// Our line protocol output read back into rows (by the `influxdb-line-protocol` crate, not our
/// own codec), keeping only `measurement`.
pub fn parse_lines(text: &str, measurement: &str) -> Vec<Row> {
    let mut rows = Vec::new();
    for line in influxdb_line_protocol::parse_lines(text) {
        let line = line.unwrap_or_else(|e| panic!("our output does not parse: {e}"));
        if line.series.measurement.as_str() != measurement {
            continue;
        }
        let tags = line
            .series
            .tag_set
            .iter()
            .flatten()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        let fields = line
            .field_set
            .iter()
            .map(|(k, v)| {
                use influxdb_line_protocol::FieldValue as F;
                let v = match v {
                    F::F64(f) => Field::Float(*f),
                    F::I64(i) => Field::Int(*i),
                    F::U64(u) => Field::Int(*u as i64),
                    F::Boolean(b) => Field::Bool(*b),
                    F::String(s) => Field::Str(s.to_string()),
                };
                (k.to_string(), v)
            })
            .collect();
        rows.push(Row {
            time: line.timestamp.expect("our outputs carry a timestamp"),
            tags,
            fields,
        });
    }
    rows
}

/// An action as the robot receives it: Telegraf's JSON (`outputs.mqtt`, `data_format = "json"`,
/// `json_timestamp_units = "1ms"`), as a row whose time is in ms.
pub fn action_row(payload: &[u8]) -> Row {
    let v: Value = serde_json::from_slice(payload)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(payload)));
    assert_eq!(v["name"], "action", "{v}");
    let tags = v["tags"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, v)| (k.clone(), v.as_str().unwrap().to_string()))
        .collect();
    let fields = v["fields"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, v)| {
            let f = match v {
                Value::Bool(b) => Field::Bool(*b),
                Value::String(s) => Field::Str(s.clone()),
                Value::Number(n) if n.is_i64() => Field::Int(n.as_i64().unwrap()),
                Value::Number(n) => Field::Float(n.as_f64().unwrap()),
                other => panic!("field {k}: {other}"),
            };
            (k.clone(), f)
        })
        .collect();
    Row {
        time: v["timestamp"].as_i64().unwrap(),
        tags,
        fields,
    }
}

/// Whether two fields hold the same value once through Telegraf: Telegraf's JSON writes a
/// whole float as an integer (`2`, not `2.0`) and an integer field as a number, so a JSON
/// number compares with either kind by value.
pub fn same_value(json: &Field, ours: &Field) -> bool {
    match (json, ours) {
        (Field::Int(a), Field::Float(b)) | (Field::Float(b), Field::Int(a)) => (*a as f64) == *b,
        (a, b) => a == b,
    }
}

/// A Mosquitto that logs subscriptions, so a test can wait until Telegraf has subscribed:
/// `mqtt_consumer` logs "Connected" before it sends its SUBSCRIBE (`mqtt_consumer.go`
/// `connect`). Its log goes to stderr, which Mosquitto does not buffer.
pub fn broker() -> Option<crate::servers::Mosquitto> {
    broker_with("")
}

/// As [`broker`], with `extra` lines in the broker's conf.
pub fn broker_with(extra: &str) -> Option<crate::servers::Mosquitto> {
    crate::servers::Mosquitto::start_with(&format!(
        "log_dest stderr\nlog_type error\nlog_type warning\nlog_type notice\n\
         log_type information\nlog_type subscribe\n{extra}"
    ))
}

/// Wait until a client whose id starts with `id` is subscribed to `topic`, looking at the
/// broker's log after its first `since` lines: a SUBSCRIBE (`<time>: <client> <qos> <topic>`),
/// or, when `since > 0`, a connection that finds its persistent session (the broker keeps the
/// subscription, and `mqtt_consumer` does not subscribe again when the session is present).
pub fn wait_subscribed(broker: &crate::servers::Mosquitto, id: &str, topic: &str, since: usize) {
    let deadline = Instant::now() + Duration::from_secs(60);
    let subscribed = |log: &str| {
        log.lines().skip(since).any(|l| {
            let t: Vec<&str> = l.split_whitespace().collect();
            (t.len() == 4 && t[1].starts_with(id) && t[2].len() == 1 && t[3] == topic)
                || (since > 0 && l.contains(&format!(" as {id} (")) && l.contains(", c0,"))
        })
    };
    while !subscribed(&broker.log()) {
        assert!(
            Instant::now() < deadline,
            "{id} never subscribed to {topic}; broker log:\n{}",
            broker.log()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The conf without its `table` (e.g. `[[outputs.influxdb]]`, up to the next table): for a test
/// that does not need that output. Fails if the conf has no such table.
pub fn without_table(conf: &str, table: &str) -> String {
    let mut out = String::new();
    let (mut skipping, mut dropped) = (false, false);
    for line in conf.lines() {
        let trimmed = line.trim_start();
        if trimmed.starts_with('[') {
            skipping = trimmed.starts_with(table);
            dropped |= skipping;
        }
        if !skipping {
            out.push_str(line);
            out.push('\n');
        }
    }
    assert!(dropped, "the conf no longer has a {table} table");
    out
}

/// Telegraf logged no error of its own. Before 1.37.0 it logs every stderr line of ours as an
/// error (`E! [processors.execd] stderr: "I! summary: ..."`): those are ours, at our level.
pub fn assert_no_error(version: &str, log: &str) {
    let errors: Vec<&str> = log
        .lines()
        .filter(|l| l.contains(" E! "))
        .filter(|l| !(version < "v1.37.0" && l.contains("[processors.execd] stderr: \"I! ")))
        .collect();
    assert!(
        errors.is_empty(),
        "Telegraf {version} logged errors:\n{}\nits log:\n{log}",
        errors.join("\n")
    );
}

/// Our end-of-run summary as Telegraf logged it (`summary: N records, ...`): exactly one.
pub fn summary(version: &str, log: &str) -> String {
    let lines: Vec<&str> = log.lines().filter(|l| l.contains("summary: ")).collect();
    assert_eq!(
        lines.len(),
        1,
        "Telegraf {version}: our summary, once:\n{log}"
    );
    lines[0].to_string()
}

/// The arguments after `run` of the conf's `processors.execd` command.
pub fn execd_args(conf: &str) -> Vec<String> {
    let v: toml::Value = toml::from_str(conf).unwrap();
    let command = v["processors"]["execd"][0]["command"].as_array().unwrap();
    let args: Vec<String> = command
        .iter()
        .map(|a| a.as_str().unwrap().to_string())
        .collect();
    assert_eq!(args[1], "run", "{args:?}");
    args[2..].to_vec()
}

/// An offline `run` of our binary `bin` with `args` (less `--state` and `--state-interval`: it starts from nothing,
/// as the monitor under Telegraf did) over `input`, no echo (`--no-passthrough` once): its
/// output.
pub fn offline(bin: impl AsRef<Path>, args: &[String], input: &str) -> String {
    use std::io::Write;
    let mut args = args.to_vec();
    args.retain(|a| a != "--no-passthrough");
    for flag in ["--state", "--state-interval"] {
        if let Some(i) = args.iter().position(|a| a == flag) {
            args.drain(i..i + 2);
        }
    }
    let mut child = Command::new(bin.as_ref())
        .arg("run")
        .args(&args)
        .args(["--no-passthrough", "--log-level", "warn"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let input = input.to_string();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()));
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap().unwrap();
    assert!(
        out.status.success(),
        "offline run: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}
