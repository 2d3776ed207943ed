//! `--state nats://...` against real nats-servers that let no one in: the 3-node cluster secured
//! as shipped (`telegraf/fleet-nats/`: TLS, the users and permissions of `accounts.conf`), and
//! single servers that log users in by token or NKey. Checked: every way to log in that the
//! README lists works (user and password in the URL, from an environment variable or a file,
//! a client certificate, a token, an NKey seed); an unauthenticated client, a wrong password, a
//! user without the state permission, an untrusted CA and an unreachable server are each
//! refused with their own message and exit 3; a malformed URL is exit 2 with the expected
//! form; a marker password appears in no output of `run`, `check` or `replay`, at any log
//! level. Also the operator mistakes of a fleet: a standby given another bucket is refused at
//! start, a process given another partition's lease name warns while it stands by.

use crate::support::child;
use crate::support::live_child::LiveChild;
use crate::support::nats_cluster;
use crate::support::servers;

use nats_cluster::Cluster;
use std::path::Path;
use std::process::{Child, Command, Stdio};

use crate::support::BIN;

/// A password that must never be printed.
const MARKER: &str = "Mark3r-S3cret-pw";

/// `run --state URL` on one record at debug level, with `env`; (stdout + stderr, exit code).
/// Fails if MARKER or any of `secrets` appears in the output.
fn run_state(url: &str, env: &[(&str, &str)], secrets: &[String]) -> (String, i32) {
    let mut child = child::command(&[
        "run",
        "--no-passthrough",
        "--log-level",
        "debug",
        "--state",
        url,
    ])
    .envs(env.iter().copied())
    .spawn()
    .unwrap();
    {
        use std::io::Write;
        let mut stdin = child.stdin.take().unwrap();
        let _ = stdin.write_all(b"m x=1 1\n");
    }
    let out = child.wait_with_output().unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    for s in secrets.iter().map(String::as_str).chain([MARKER]) {
        assert!(
            !text.contains(s),
            "a secret in the output of {url}:\n{text}"
        );
    }
    (text, out.status.code().unwrap_or(-1))
}

#[test]
fn a_secured_cluster_lets_in_only_the_right_login_and_says_why_not() {
    let Some(cluster) =
        Cluster::start_secured(&nats_cluster::shipped_mapping(), &["robot1".to_string()])
    else {
        return;
    };
    let hosts = cluster.hosts();
    let certs = cluster.certs();
    let ca = certs.join("ca.pem").display().to_string();
    let pw = cluster.password("fleet-p0");
    let secrets: Vec<String> = ["fleet-p0", "fleet-p1", "admin", "robot1"]
        .iter()
        .map(|u| cluster.password(u))
        .collect();
    let bucket = "tessla_state";

    // The ways in: password in the URL, from an environment variable, from a file, plus a
    // client certificate.
    let (out, code) = run_state(
        &format!("nats://fleet-p0:{pw}@{hosts}/{bucket}?tls-ca={ca}&lease=p0"),
        &[],
        &secrets,
    );
    assert_eq!(code, 0, "{out}");
    assert!(
        out.contains("state: saved 1 monitor instances to nats://fleet-p0:***@"),
        "{out}"
    );
    let (out, code) = run_state(
        &format!("nats://{hosts}/{bucket}?user=fleet-p0&password-env=PW&tls-ca={ca}"),
        &[("PW", &pw)],
        &secrets,
    );
    assert_eq!(code, 0, "{out}");
    let file = cluster.dir().join("p0.password");
    std::fs::write(&file, format!("{pw}\n")).unwrap();
    let (out, code) = run_state(
        &format!(
            "nats://{hosts}/{bucket}?user=fleet-p0&password-file={}&tls-ca={ca}&tls-cert={}&tls-key={}",
            file.display(),
            certs.join("client.pem").display(),
            certs.join("client-key.pem").display()
        ),
        &[],
        &secrets,
    );
    assert_eq!(code, 0, "{out}");

    // An unauthenticated client.
    let (out, code) = run_state(
        &format!("nats://{hosts}/{bucket}?tls-ca={ca}"),
        &[],
        &secrets,
    );
    assert_eq!(code, 3, "{out}");
    assert!(
        out.contains("E! state: authorization failed at nats://127.0.0.1:")
            && out.contains("the server requires credentials and none were given"),
        "{out}"
    );
    // A wrong password (the marker: never printed).
    let (out, code) = run_state(
        &format!("nats://fleet-p0:{MARKER}@{hosts}/{bucket}?tls-ca={ca}"),
        &[],
        &secrets,
    );
    assert_eq!(code, 3, "{out}");
    assert!(
        out.contains("E! state: authorization failed at nats://fleet-p0:***@127.0.0.1:")
            && out.contains("the server refused this process's credentials (as user `fleet-p0`"),
        "{out}"
    );
    // A user without the state permission: the shipped permissions allow bucket tessla_state
    // only (so a process given another bucket cannot start either).
    let (out, code) = run_state(
        &format!("nats://{hosts}/other_state?user=fleet-p0&password-env=PW&tls-ca={ca}"),
        &[("PW", &pw)],
        &secrets,
    );
    assert_eq!(code, 3, "{out}");
    assert!(
        out.contains("E! state: not permitted at nats://fleet-p0:***@")
            && out.contains("access to bucket other_state")
            && out.contains("Permissions Violation"),
        "{out}"
    );
    // A robot (MQTT only) is no monitor.
    let (out, code) = run_state(
        &format!("nats://{hosts}/{bucket}?user=robot1&password-env=PW&tls-ca={ca}"),
        &[("PW", &cluster.password("robot1"))],
        &secrets,
    );
    assert_eq!(code, 3, "{out}");
    assert!(out.contains("E! state: authorization failed"), "{out}");
    // TLS: a CA that did not sign the servers' certificates, and none at all.
    for url in [
        format!(
            "nats://{hosts}/{bucket}?user=fleet-p0&password-env=PW&tls-ca={}",
            certs.join("other-ca.pem").display()
        ),
        format!("nats://{hosts}/{bucket}?user=fleet-p0&password-env=PW"),
    ] {
        let (out, code) = run_state(&url, &[("PW", &pw)], &secrets);
        assert_eq!(code, 3, "{out}");
        assert!(
            out.contains("E! state: TLS failed with nats://fleet-p0:***@")
                && out.contains("invalid peer certificate"),
            "{out}"
        );
    }
    // Mistakes in the login settings themselves: exit 2, naming the variable or file.
    let (out, code) = run_state(
        &format!(
            "nats://{hosts}/{bucket}?user=fleet-p0&password-env=TESSLA_TEST_UNSET&tls-ca={ca}"
        ),
        &[],
        &secrets,
    );
    assert_eq!(code, 2, "{out}");
    assert!(
        out.contains("environment variable TESSLA_TEST_UNSET, which is not set"),
        "{out}"
    );
    let (out, code) = run_state(
        &format!(
            "nats://{hosts}/{bucket}?user=fleet-p0&password-env=PW&tls-ca=/nonexistent/ca.pem"
        ),
        &[("PW", &pw)],
        &secrets,
    );
    assert_eq!(code, 2, "{out}");
    assert!(out.contains("TLS file /nonexistent/ca.pem"), "{out}");
}

/// A single nats-server with JetStream and `conf` (text), on a free port; killed on drop.
fn single(conf: &str) -> Option<servers::Server> {
    let binary = nats_cluster::require_nats_server()?;
    let dir = tempfile::tempdir().unwrap();
    let port = servers::free_port();
    let conf = format!(
        "listen: 127.0.0.1:{port}\njetstream {{ store_dir: \"{}\" }}\n{conf}\n",
        dir.path().join("js").display()
    );
    Some(servers::Server::start(
        &binary,
        &["-c"],
        dir,
        port,
        "nats.conf",
        &conf,
    ))
}

#[test]
fn token_and_nkey_logins() {
    let Some(server) = single(&format!("authorization {{ token: \"{MARKER}\" }}")) else {
        return;
    };
    let p = server.port;
    let (out, code) = run_state(&format!("nats://{MARKER}@127.0.0.1:{p}/b"), &[], &[]);
    assert_eq!(code, 0, "{out}");
    assert!(out.contains("nats://***@127.0.0.1:"), "{out}");
    let (out, code) = run_state(
        &format!("nats://127.0.0.1:{p}/b?token-env=TOKEN"),
        &[("TOKEN", MARKER)],
        &[],
    );
    assert_eq!(code, 0, "{out}");
    let (out, code) = run_state(
        &format!("nats://127.0.0.1:{p}/b?token-env=TOKEN"),
        &[("TOKEN", "not-the-token")],
        &[],
    );
    assert_eq!(code, 3, "{out}");
    assert!(
        out.contains("authorization failed")
            && out.contains("with a token (from environment variable TOKEN)"),
        "{out}"
    );
    drop(server);

    let user = nkeys::KeyPair::new_user();
    let seed = user.seed().unwrap();
    let Some(server) = single(&format!(
        "authorization {{ users: [ {{ nkey: {} }} ] }}",
        user.public_key()
    )) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let seed_file = dir.path().join("user.nk");
    std::fs::write(&seed_file, format!("{seed}\n")).unwrap();
    let url = format!(
        "nats://127.0.0.1:{}/b?nkey-file={}",
        server.port,
        seed_file.display()
    );
    let (out, code) = run_state(&url, &[], std::slice::from_ref(&seed));
    assert_eq!(code, 0, "{out}");
    let other = nkeys::KeyPair::new_user().seed().unwrap();
    std::fs::write(&seed_file, &other).unwrap();
    let (out, code) = run_state(&url, &[], &[seed.clone(), other]);
    assert_eq!(code, 3, "{out}");
    assert!(
        out.contains("authorization failed") && out.contains("NKey seed"),
        "{out}"
    );
}

/// A server that asks for a client certificate (`verify: true`): without one the handshake
/// fails (a TLS failure, exit 3); with the test client certificate the process gets in.
#[test]
fn a_client_certificate_where_the_server_asks_for_one() {
    let certs = tempfile::tempdir().unwrap();
    nats_cluster::make_certs(certs.path());
    let c = certs.path().display();
    let Some(server) = single(&format!(
        "tls {{ cert_file: \"{c}/server.pem\", key_file: \"{c}/server-key.pem\", \
         ca_file: \"{c}/ca.pem\", verify: true, timeout: 2 }}"
    )) else {
        return;
    };
    let base = format!("nats://127.0.0.1:{}/b?tls-ca={c}/ca.pem", server.port);
    let (out, code) = run_state(&base, &[], &[]);
    assert_eq!(code, 3, "{out}");
    assert!(
        out.contains("E! state: TLS failed with nats://127.0.0.1:"),
        "{out}"
    );
    let (out, code) = run_state(
        &format!("{base}&tls-cert={c}/client.pem&tls-key={c}/client-key.pem"),
        &[],
        &[],
    );
    assert_eq!(code, 0, "{out}");
}

#[test]
fn a_malformed_url_is_a_command_line_error_with_the_expected_form() {
    for (url, why) in [
        ("nats:/127.0.0.1:4222/b", "`nats:` must be followed by `//`"),
        ("nats:127.0.0.1:4222/b", "`nats:` must be followed by `//`"),
        (
            "nat://127.0.0.1:4222/b",
            "scheme `nat://` is not a state store",
        ),
        ("nats://127.0.0.1:4222", "no bucket"),
    ] {
        let (_, err, code) = child::run_text(&["run", "--state", url], "");
        assert_eq!(code, 2, "{url}: {err}");
        assert!(err.contains(why), "{url}: {err}");
        assert!(
            err.contains("expected nats://HOST:PORT[,HOST:PORT...]/BUCKET"),
            "{url}: {err}"
        );
    }
    // A file whose name starts so: ./ says it is a path.
    let dir = tempfile::tempdir().unwrap();
    let (_, err, code) = child::run_text(
        &[
            "run",
            "--state",
            dir.path().join("nats:x").to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
}

#[test]
fn the_marker_password_is_never_printed() {
    let port = servers::free_port();
    let url = format!("nats://monitor:{MARKER}@127.0.0.1:{port}/b");
    let cases: Vec<Vec<String>> = vec![
        // run: unreachable server, a bad option, a bad bucket, UDP mode with it, debug level.
        vec![
            "run".into(),
            "--log-level".into(),
            "debug".into(),
            "--state".into(),
            url.clone(),
        ],
        vec!["run".into(), "--state".into(), format!("{url}?nosuch=1")],
        vec!["run".into(), "--state".into(), url.replace("/b", "/b.c")],
        vec![
            "run".into(),
            "--state".into(),
            url.clone(),
            "--udp-listen".into(),
            "127.0.0.1:0".into(),
        ],
        vec!["--state".into(), format!("{url}?ttl=1ms")],
        // check: a spec named like a URL, and a stray --state.
        vec!["check".into(), url.clone()],
        vec!["check".into(), "--state".into(), url.clone()],
        // replay: credentials in the broker address, a password variable to an unreachable
        // broker, a TLS broker without a CA.
        vec![
            "replay".into(),
            "tests/fixtures/robot/recorded_run.lp".into(),
            "--broker".into(),
            format!("mqtt://robot:{MARKER}@127.0.0.1:{port}"),
        ],
        vec![
            "replay".into(),
            "tests/fixtures/robot/recorded_run.lp".into(),
            "--broker".into(),
            format!("mqtt://127.0.0.1:{port}"),
            "--username".into(),
            "robot".into(),
            "--password-env".into(),
            "MQTT_PW".into(),
        ],
        vec![
            "replay".into(),
            "tests/fixtures/robot/recorded_run.lp".into(),
            "--broker".into(),
            format!("mqtts://127.0.0.1:{port}"),
            "--username".into(),
            "robot".into(),
            "--password-env".into(),
            "MQTT_PW".into(),
        ],
    ];
    for args in cases {
        let out = Command::new(BIN)
            .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")))
            .args(&args)
            .env("MQTT_PW", MARKER)
            .stdin(Stdio::null())
            .output()
            .unwrap();
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(!out.status.success(), "{args:?}: {text}");
        assert!(
            !text.contains(MARKER),
            "{args:?} printed the password:\n{text}"
        );
    }
}

/// The fleet's operator mistakes, on an open server: a standby given another bucket than its
/// primary is refused at start; a process given another partition's lease name warns, while
/// it stands by, that a partition has no holder.
#[test]
fn fleet_mistakes_are_refused_or_loud() {
    let Some(server) = single("") else {
        return;
    };
    let base = format!("nats://127.0.0.1:{}", server.port);
    let spawn = |url: String| -> Child {
        child::command(&["run", "--no-passthrough", "--state", &url])
            .stdout(Stdio::null())
            .spawn()
            .unwrap()
    };
    let finish = |mut c: Child| -> (String, i32) {
        drop(c.stdin.take());
        let out = c.wait_with_output().unwrap();
        (
            String::from_utf8_lossy(&out.stderr).into_owned(),
            out.status.code().unwrap_or(-1),
        )
    };
    // Partition p0 was served and released (its primary now misconfigured); p1 has a holder.
    let (err, code) = finish(spawn(format!("{base}/fleet?lease=p0&ttl=1s")));
    assert_eq!(code, 0, "{err}");
    // p1's holder: a TTL of 3 s, so that a holder starved of the CPU for a second on a busy
    // machine keeps its lease (renewed every TTL/4); waited for until it says it holds it.
    let mut holder = LiveChild::spawn(&[
        "run",
        "--no-passthrough",
        "--state",
        &format!("{base}/fleet?lease=p1&ttl=3s"),
    ]);
    holder.wait_err("p1's holder taking its lease", 0, |l| {
        l.starts_with("I! lease: partition p1: held by this process")
    });

    // A standby of p1 given another bucket: refused at start (exit 2), naming both buckets,
    // before that bucket is created.
    let (err, code) = finish(spawn(format!("{base}/fleet_b?lease=p1&ttl=3s")));
    assert_eq!(code, 2, "{err}");
    assert!(!err.contains("created bucket fleet_b"), "{err}");
    assert!(
        err.contains("E! state: partition p1's lease is held in bucket fleet by ")
            && err.contains("this process was given bucket fleet_b"),
        "{err}"
    );

    // p0's process given p1's lease name: it stands by and says that p0 has no holder (its
    // first report comes after three TTLs of standing by; waited for, never slept on).
    let url = format!("{base}/fleet?lease=p1&ttl=3s");
    let mut wrong = LiveChild::spawn(&["run", "--no-passthrough", "--state", &url]);
    let line = wrong.wait_err("the standby's report", 0, |l| {
        l.starts_with("W! lease: partition p1: standing by for ")
    });
    assert!(
        line.contains("while nobody holds partition(s) p0: their robots get no actions")
            && line.contains("has the wrong ?lease= name"),
        "{line}"
    );
    let (_, err, code) = wrong.finish();
    assert_eq!(code, 0, "{err}");
    let (_, err, code) = holder.finish();
    assert_eq!(code, 0, "{err}");
    assert!(!err.contains("taken over by another process"), "{err}");
}
