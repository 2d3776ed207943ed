//! The fleet's spec channel (`--spec-channel`, `tessla-telegraf spec ...`) against real
//! nats-servers: a publish is listed, followed by a process ([`NatsFeed`], at connect and by
//! `poll` afterwards) and reported back in `spec status`; a rollback publishes the version in
//! force before (or the base marker); a tampered bundle, an unsigned, foreign-signed, re-signed
//! or copied rollout reaches the process refused, saying why; a spec that does not check is
//! refused before anything is written; with the shipped `accounts.conf` a fleet-p0 login may
//! follow the channel and write its status but not publish (exit 3, "not permitted"); a login
//! without the channel's permissions is told what it needs.
//!
//! A missing nats-server fails these tests (never skips): the spec channel is what keeps an
//! unsigned spec off the robots.

use crate::support::child;
use crate::support::kv;
use crate::support::nats_cluster::{self, Cluster};
use crate::support::servers;

use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::{Duration, Instant};
use tessla_telegraf::spec_feed::nats::{NatsFeed, parse_url};
use tessla_telegraf::spec_feed::{Arrival, Event, Outcome, Rollout, sign};

/// A single nats-server with JetStream on a free port (killed on drop); fails the test when
/// nats-server is not installed.
pub(super) fn nats_server(conf: &str) -> servers::Server {
    let binary = nats_cluster::require_nats_server().unwrap_or_else(|| {
        panic!("nats-server is needed by the spec channel's tests (apt-get install nats-server)")
    });
    let dir = tempfile::tempdir().unwrap();
    let port = servers::free_port();
    let conf = format!(
        "listen: 127.0.0.1:{port}\njetstream {{ store_dir: \"{}\" }}\n{conf}\n",
        dir.path().join("js").display()
    );
    servers::Server::start(&binary, &["-c"], dir, port, "nats.conf", &conf)
}

/// A spec folder, the operator's key (made by `spec keygen`) and a channel URL.
pub(super) struct Setup {
    pub(super) dir: tempfile::TempDir,
    pub(super) seed: PathBuf,
    pub(super) public: String,
}

impl Setup {
    pub(super) fn new() -> Setup {
        let dir = tempfile::tempdir().unwrap();
        let seed = dir.path().join("operator.seed");
        let out = spec(&["keygen", "--seed-file", seed.to_str().unwrap()], &[]);
        assert!(out.status.success(), "{}", child::text(&out.stderr));
        let text = child::text(&out.stdout);
        let public = text
            .lines()
            .find_map(|l| l.strip_prefix("public key: "))
            .unwrap_or_else(|| panic!("no public key in {text}"))
            .to_string();
        let seed_text = std::fs::read_to_string(&seed).unwrap();
        assert!(seed_text.starts_with("SO"), "a seed: {}", &seed_text[..2]);
        assert!(!text.contains(seed_text.trim()), "the seed is not printed");
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&seed).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o600);
        Setup { dir, seed, public }
    }

    /// `main.tessla` including `lib.tessla`, whose `def` is `body`.
    fn write_spec(&self, body: &str) -> PathBuf {
        child::write(
            self.dir.path(),
            "lib.tessla",
            &format!("def scaled(x: Events[Int]) = {body}\n"),
        );
        child::write(
            self.dir.path(),
            "main.tessla",
            "include \"lib.tessla\"\n@TelegrafIn(\"m\", \"x\")\nin x: Events[Int]\nout scaled(x) as y\n",
        )
    }

    /// `spec publish SPEC --channel URL --sign-key-file SEED ARGS...`.
    pub(super) fn publish(&self, url: &str, spec_file: &Path, args: &[&str]) -> Output {
        let mut all = vec![
            "publish",
            spec_file.to_str().unwrap(),
            "--channel",
            url,
            "--sign-key-file",
            self.seed.to_str().unwrap(),
        ];
        all.extend_from_slice(args);
        spec(&all, &[])
    }

    fn rollback(&self, url: &str, args: &[&str]) -> Output {
        let mut all = vec![
            "rollback",
            "--channel",
            url,
            "--sign-key-file",
            self.seed.to_str().unwrap(),
        ];
        all.extend_from_slice(args);
        spec(&all, &[])
    }
}

/// `tessla-telegraf spec ARGS` with `env`.
fn spec(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut all = vec!["spec"];
    all.extend_from_slice(args);
    let child = child::command(&all)
        .envs(env.iter().copied())
        .spawn()
        .expect("spawn the binary");
    child.wait_with_output().expect("wait for the binary")
}

/// The version id of a `rollout N: version ID ...` line.
pub(super) fn published(out: &Output, revision: u64) -> String {
    let text = child::text(&out.stdout);
    assert!(out.status.success(), "{text}{}", child::text(&out.stderr));
    let prefix = format!("rollout {revision}: version ");
    let rest = text
        .strip_prefix(&prefix)
        .unwrap_or_else(|| panic!("expected `{prefix}...`, got {text}"));
    rest.split(' ').next().unwrap_or_default().to_string()
}

fn until<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + Duration::from_secs(15);
    loop {
        if let Some(t) = f() {
            return t;
        }
        assert!(Instant::now() < deadline, "{what} within 15 s");
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn connect(url: &str, trust: &[String]) -> (NatsFeed, Vec<Arrival>) {
    let (feed, first) = NatsFeed::connect(&parse_url(url).unwrap(), trust)
        .unwrap_or_else(|e| panic!("connect to {url}: {}", e.message()));
    (feed, proposals(first))
}

/// The rollouts among a channel's events (the decisions left out).
fn proposals(events: Vec<Event>) -> Vec<Arrival> {
    events
        .into_iter()
        .filter_map(|e| match e {
            Event::Proposal(a) => Some(a),
            Event::Decision { .. } => None,
        })
        .collect()
}

fn outcome(r: &Rollout, accepted: bool, reason: &str) -> Outcome {
    Outcome {
        revision: r.revision,
        id: r.id.clone(),
        label: r.label.clone(),
        accepted,
        reason: reason.into(),
        reset_outputs: if accepted {
            vec!["y".into()]
        } else {
            Vec::new()
        },
        ..Outcome::default()
    }
}

fn json(out: &Output) -> serde_json::Value {
    assert!(out.status.success(), "{}", child::text(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn publish_list_status_and_a_process_following_the_channel() {
    let server = nats_server("");
    let url = format!("nats://127.0.0.1:{}", server.port);
    let s = Setup::new();
    let main = s.write_spec("x * 2");

    let v1 = published(&s.publish(&url, &main, &["--label", "double"]), 1);
    // A process connecting now reads it before its first record: verified, with its bundle.
    let (mut feed, first) = connect(&url, std::slice::from_ref(&s.public));
    assert_eq!(first.len(), 1);
    let a = &first[0];
    assert_eq!(
        (a.rollout.revision, a.rollout.label.as_str()),
        (1, "double")
    );
    assert!(a.rollout.selector.is_all());
    let bundle = a.bundle.as_ref().unwrap();
    assert_eq!((bundle.id(), bundle.files.len()), (v1.clone(), 2));
    assert!(proposals(feed.poll()).is_empty());

    // A publish after connect (the seed from the environment, a canary from a stated time):
    // `poll` hands it over.
    s.write_spec("x * 3");
    let seed = std::fs::read_to_string(&s.seed).unwrap();
    let out = spec(
        &[
            "publish",
            main.to_str().unwrap(),
            "--channel",
            &url,
            "--select",
            "robot=r1,r2",
            "--from",
            "2023-11-14T22:13:20Z",
        ],
        &[("TESSLA_SIGN_KEY", seed.trim())],
    );
    let v2 = published(&out, 2);
    assert_ne!(v1, v2);
    assert!(
        child::text(&out.stdout)
            .contains("in force from 2023-11-14T22:13:20.000000000Z for robot=r1,r2"),
        "{}",
        child::text(&out.stdout)
    );
    let got = until("the second rollout polled", || {
        let got = proposals(feed.poll());
        (!got.is_empty()).then_some(got)
    });
    assert_eq!(got.len(), 1);
    let r2 = &got[0].rollout;
    assert_eq!(
        (
            r2.revision,
            r2.id.as_str(),
            r2.from,
            r2.selector.to_string()
        ),
        (
            2,
            v2.as_str(),
            1_700_000_000_000_000_000,
            "robot=r1,r2".to_string()
        )
    );
    assert_eq!(got[0].bundle.as_ref().unwrap().id(), v2);
    assert!(proposals(feed.poll()).is_empty(), "each rollout once");

    // Two processes report; `spec status` shows both, per rollout.
    feed.report(
        "host-a",
        "p0",
        &[
            outcome(&a.rollout, true, ""),
            outcome(
                r2,
                false,
                "input `x` cannot read the metrics this process receives",
            ),
        ],
    );
    let (mut other, both) = connect(&url, std::slice::from_ref(&s.public));
    assert_eq!(
        both.iter().map(|a| a.rollout.revision).collect::<Vec<_>>(),
        [1, 2]
    );
    other.report(
        "host-b",
        "",
        &[
            outcome(&both[0].rollout, true, ""),
            outcome(&both[1].rollout, true, ""),
        ],
    );
    let status = until("both statuses", || {
        let v = json(&spec(&["status", "--channel", &url, "--json"], &[]));
        (v["processes"].as_array().map_or(0, Vec::len) == 2).then_some(v)
    });
    let rollouts = status["rollouts"].as_array().unwrap();
    assert_eq!(rollouts.len(), 2);
    assert_eq!(rollouts[0]["label"], "double");
    assert_eq!(rollouts[0]["signer"], s.public.as_str());
    assert_eq!(
        (
            rollouts[0]["accepted"].as_u64(),
            rollouts[0]["refused"].as_u64()
        ),
        (Some(2), Some(0))
    );
    assert_eq!(
        (
            rollouts[1]["accepted"].as_u64(),
            rollouts[1]["refused"].as_u64()
        ),
        (Some(1), Some(1))
    );
    let a_status = status["processes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["host"] == "host-a")
        .unwrap();
    assert_eq!(a_status["partition"], "p0");
    assert_eq!(
        a_status["key"],
        format!("status.vhost-a.vp0.pid{}", std::process::id())
    );
    assert_eq!(a_status["outcomes"][1]["accepted"], false);

    let table = child::text(&spec(&["status", "--channel", &url], &[]).stdout);
    for want in [
        "1 accepted, 1 refused",
        "2 accepted, 0 refused",
        "host-a",
        "refused",
        "input `x` cannot read the metrics",
        "outputs starting afresh: y",
        "robot=r1,r2",
    ] {
        assert!(table.contains(want), "`{want}` in\n{table}");
    }
    let list = child::text(&spec(&["list", "--channel", &url], &[]).stdout);
    assert!(
        list.starts_with("REV  VERSION ") && list.contains(&v1) && list.contains("double"),
        "{list}"
    );

    // Refused before anything is written: a spec that does not check (the full diagnostic,
    // exit 2), no signing key (exit 2).
    let bad = child::write(
        s.dir.path(),
        "bad.tessla",
        "in x: Events[Int]\nout x + true\n",
    );
    let out = s.publish(&url, &bad, &[]);
    let err = child::text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("bad.tessla:2:") && err.contains("was not published: it does not check"),
        "{err}"
    );
    let out = spec(&["publish", main.to_str().unwrap(), "--channel", &url], &[]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        child::text(&out.stderr)
            .contains("no signing key: give the operator's seed with --sign-key-file FILE"),
        "{}",
        child::text(&out.stderr)
    );
    let listed = json(&spec(&["list", "--channel", &url, "--json"], &[]));
    assert_eq!(listed["rollouts"].as_array().unwrap().len(), 2);

    // An unreachable channel: exit 3, saying so.
    drop(server);
    let out = spec(&["list", "--channel", &url], &[]);
    assert_eq!(out.status.code(), Some(3));
    assert!(
        child::text(&out.stderr).contains("no NATS server answered"),
        "{}",
        child::text(&out.stderr)
    );
}

#[test]
fn a_rollback_publishes_the_version_in_force_before() {
    let server = nats_server("");
    let url = format!("nats://127.0.0.1:{}/specs_a", server.port);
    let s = Setup::new();
    let main = s.write_spec("x * 2");

    // Nothing published: nothing to roll back (exit 2). A process started before the bucket
    // exists waits for it.
    let out = s.rollback(&url, &[]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        child::text(&out.stderr).contains("nothing to roll back"),
        "{}",
        child::text(&out.stderr)
    );
    let (mut feed, first) = connect(&url, std::slice::from_ref(&s.public));
    assert!(first.is_empty());

    let v1 = published(&s.publish(&url, &main, &[]), 1);
    let got = until("the first rollout, once the bucket exists", || {
        let got = proposals(feed.poll());
        (!got.is_empty()).then_some(got)
    });
    assert_eq!(got[0].rollout.id, v1);

    // One rollout: back to the spec each process started with (the base marker).
    let out = s.rollback(&url, &[]);
    assert_eq!(published(&out, 2), "base");
    assert!(
        child::text(&out.stdout).contains("(`rollback of ")
            && child::text(&out.stdout)
                .contains("rolls back rollout 1 to the spec each process started with"),
        "{}",
        child::text(&out.stdout)
    );
    let got = until("the base rollout", || {
        let got = proposals(feed.poll());
        (!got.is_empty()).then_some(got)
    });
    let base = &got[0];
    assert_eq!(
        (base.rollout.id.as_str(), base.rollout.digest.as_str()),
        ("base", "")
    );
    assert_eq!(base.rollout.label, format!("rollback of {v1}"));
    assert!(base.bundle.as_ref().unwrap().files.is_empty());

    // v2 for all, then a rollback: v1's version again (from a stated time).
    s.write_spec("x * 5");
    let v2 = published(&s.publish(&url, &main, &["--label", "five"]), 3);
    let out = s.rollback(&url, &["--from", "1700000000000000000"]);
    // Revision 2 (base) was in force before revision 3.
    assert_eq!(published(&out, 4), "base");
    // v2 again; a canary of v3 for r1; its rollback for r1 is v2 (the last for every robot).
    let again = s.publish(&url, &main, &[]);
    assert_eq!(published(&again, 5), v2);
    s.write_spec("x * 7");
    let v3 = published(&s.publish(&url, &main, &["--select", "robot=r1"]), 6);
    let out = s.rollback(&url, &["--select", "robot=r1"]);
    assert_eq!(published(&out, 7), v2);
    assert!(
        child::text(&out.stdout).contains(&format!("(`rollback of {v3}`)"))
            && child::text(&out.stdout)
                .contains("for robot=r1: rolls back rollout 6 to the version of rollout 5"),
        "{}",
        child::text(&out.stdout)
    );
    let mut got = Vec::new();
    until("rollouts 3 to 7", || {
        got.extend(proposals(feed.poll()));
        (got.len() >= 5).then_some(())
    });
    assert_eq!(
        got.iter().map(|a| a.rollout.revision).collect::<Vec<_>>(),
        [3, 4, 5, 6, 7]
    );
    assert!(got.iter().all(|a| a.bundle.is_ok()));
    assert_eq!(got[1].rollout.from, 1_700_000_000_000_000_000);

    // A selector no rollout covers entirely: nothing to roll back for it.
    let url_b = format!("nats://127.0.0.1:{}/specs_b", server.port);
    published(&s.publish(&url_b, &main, &["--select", "robot=r1"]), 1);
    let out = s.rollback(&url_b, &["--select", "robot=r1,r2"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        child::text(&out.stderr).contains("nothing to roll back for robot=r1,r2"),
        "{}",
        child::text(&out.stderr)
    );
}

/// Defect 4 of the issue "One fleet, one truth": a rollback skips aborted rollouts (it undoes
/// the last committed one); a rollout left undecided (its publisher died before counting the
/// votes) holds every later publish until `spec decide` counts the votes or `spec abort`
/// aborts it, and a decision is never changed.
#[test]
fn a_rollback_skips_aborted_rollouts_and_an_undecided_one_is_decided_first() {
    use crate::support::live_child::LiveChild;
    let server = nats_server("");
    let port = server.port;
    let url = format!("nats://127.0.0.1:{port}/specs_c");
    let s = Setup::new();
    let base = child::write(s.dir.path(), "base.tessla", BASE_SPEC);
    let new = child::write(s.dir.path(), "new.tessla", NEW_SPEC);
    let bad = child::write(s.dir.path(), "bad.tessla", "in x: Events[Bool]\nout x\n");
    // The bucket first, then a process that has seen an Int `x`.
    published(&s.publish(&url, &new, &["--select", "robot=none"]), 1);
    let mut p = LiveChild::spawn(&channel_run(&url, &s, &base));
    p.write(&format!("m,robot=r1 x=1i {}\n", ts(0)));
    p.wait_out("the first answer", |l| l.contains(" c=1i,y=2i "));
    let v_new = published(&s.publish(&url, &new, &[]), 2);
    let out = s.publish(&url, &bad, &[]);
    assert_eq!(out.status.code(), Some(5), "{}", child::text(&out.stdout));
    // The rollback undoes rollout 2 (the aborted 3 was never in force); rollout 1 picks only
    // robot=none, so what was in force before rollout 2 is the base.
    let out = s.rollback(&url, &[]);
    let text = child::text(&out.stdout);
    assert!(out.status.success(), "{text}{}", child::text(&out.stderr));
    assert!(
        text.starts_with("rollout 4: version base")
            && text.contains(&format!("(`rollback of {v_new}`)"))
            && text.contains("rolls back rollout 2 to the spec each process started with")
            && text.contains("committed: all 1 processes accepted it"),
        "{text}"
    );
    // A signed rollout whose publisher died before deciding: publishing waits for it.
    let operator =
        nkeys::KeyPair::from_seed(std::fs::read_to_string(&s.seed).unwrap().trim()).unwrap();
    let record = raw(port, "specs_c", async |kv| {
        kv.get("rollout.2").await.unwrap().unwrap()
    });
    let mut r5: Rollout = sign::Record::<Rollout>::parse(&record).body.unwrap();
    r5.revision = 5;
    r5.label = "orphan".into();
    let sealed = sign::seal(&r5, &operator).unwrap();
    raw(port, "specs_c", async |kv| {
        kv.create("rollout.5", sealed.into()).await.unwrap();
    });
    let out = s.publish(&url, &new, &[]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        child::text(&out.stderr).contains("rollout 5")
            && child::text(&out.stderr).contains("is undecided")
            && child::text(&out.stderr).contains("spec decide 5"),
        "{}",
        child::text(&out.stderr)
    );
    // The running process voted on it when it arrived: `spec decide` counts that vote.
    p.wait_out("the vote on the orphan", |l| {
        l.contains(",outcome=accepted,") && l.contains("revision=5i")
    });
    let decide = |args: &[&str]| {
        let mut all = vec![
            args[0],
            args[1],
            "--channel",
            url.as_str(),
            "--sign-key-file",
            s.seed.to_str().unwrap(),
        ];
        all.extend_from_slice(&args[2..]);
        spec(&all, &[])
    };
    let out = decide(&["decide", "5"]);
    let text = child::text(&out.stdout);
    assert!(
        out.status.success() && text.contains("committed: all 1 processes accepted it"),
        "{text}{}",
        child::text(&out.stderr)
    );
    p.wait_out("the orphan committed", |l| {
        l.contains(",outcome=committed,") && l.contains("revision=5i")
    });
    // Decided once: neither abort nor decide changes it.
    for args in [["abort", "5"], ["decide", "5"]] {
        let out = decide(&args);
        assert_eq!(out.status.code(), Some(2));
        assert!(
            child::text(&out.stderr).contains("is decided already (committed)"),
            "{}",
            child::text(&out.stderr)
        );
    }
    let status = child::text(&spec(&["status", "--channel", &url], &[]).stdout);
    for want in [
        "DECISION",
        "committed",
        "aborted",
        "voted accepted, committed",
    ] {
        assert!(status.contains(want), "`{want}` in\n{status}");
    }
    let (_, err, code) = p.finish();
    assert_eq!(code, 0, "{err}");
}

/// The bucket `bucket` on `port`, opened by a raw client (what someone with write access
/// could do without the operator's key).
fn raw<T>(
    port: u16,
    bucket: &str,
    f: impl AsyncFnOnce(async_nats::jetstream::kv::Store) -> T,
) -> T {
    kv::with_bucket(&format!("127.0.0.1:{port}"), bucket, f)
}

#[test]
fn tampered_unsigned_and_foreign_rollouts_are_refused_saying_why() {
    let server = nats_server("");
    let port = server.port;
    let url = format!("nats://127.0.0.1:{port}");
    let s = Setup::new();
    let main = s.write_spec("x * 2");
    let id = published(&s.publish(&url, &main, &["--label", "good"]), 1);
    let operator =
        nkeys::KeyPair::from_seed(std::fs::read_to_string(&s.seed).unwrap().trim()).unwrap();
    let foreign = nkeys::KeyPair::new_operator();
    let record = raw(port, "tessla_specs", async |kv| {
        kv.get("rollout.1").await.unwrap().unwrap()
    });
    let rec = sign::Record::<Rollout>::parse(&record);
    let good: Rollout = rec.body.clone().unwrap();
    let at = |revision: u64| Rollout {
        revision,
        label: format!("r{revision}"),
        ..good.clone()
    };
    // 2: unsigned.
    let mut unsigned: serde_json::Value = serde_json::from_slice(&record).unwrap();
    unsigned.as_object_mut().unwrap().remove("signature");
    unsigned["rollout"] = serde_json::to_value(at(2)).unwrap();
    // 3: signed by a key the processes do not trust.
    let untrusted = sign::seal(&at(3), &foreign).unwrap();
    // 4: signed by the operator, but as revision 2 (copied to another key).
    let copied = sign::seal(&at(2), &operator).unwrap();
    // 5: naming the operator as signer, signed by another key.
    let mut forged: serde_json::Value =
        serde_json::from_slice(&sign::seal(&at(5), &foreign).unwrap()).unwrap();
    forged["signer"] = serde_json::Value::String(s.public.clone());
    // And the good rollout's bundle changed after publishing.
    raw(port, "tessla_specs", async |kv| {
        let key = format!("bundle.{id}");
        let mut b: serde_json::Value =
            serde_json::from_slice(&kv.get(key.as_str()).await.unwrap().unwrap()).unwrap();
        let text = b["files"][1]["text"]
            .as_str()
            .unwrap()
            .replace("x * 2", "x * 200");
        b["files"][1]["text"] = serde_json::Value::String(text);
        kv.put(key.as_str(), serde_json::to_vec(&b).unwrap().into())
            .await
            .unwrap();
        for (k, v) in [
            ("rollout.2", serde_json::to_vec(&unsigned).unwrap()),
            ("rollout.3", untrusted),
            ("rollout.4", copied),
            ("rollout.5", serde_json::to_vec(&forged).unwrap()),
        ] {
            kv.create(k, v.into()).await.unwrap();
        }
    });

    let (mut feed, first) = connect(&url, std::slice::from_ref(&s.public));
    let why: Vec<(u64, String, String)> = first
        .iter()
        .map(|a| {
            (
                a.rollout.revision,
                a.rollout.label.clone(),
                a.bundle
                    .as_ref()
                    .map_or_else(ToString::to_string, |_| String::new()),
            )
        })
        .collect();
    let expect = [
        (
            1,
            "good",
            "does not hash to the digest the rollout was signed with",
        ),
        (2, "r2", "it is unsigned"),
        (3, "r3", "which this process does not trust (--spec-trust)"),
        (
            4,
            "r2",
            "it says it is revision 2 but is stored as rollout.4",
        ),
        (5, "r5", "its signature does not verify with key"),
    ];
    assert_eq!(why.len(), expect.len(), "{why:?}");
    for ((rev, label, reason), (r, l, want)) in why.iter().zip(expect) {
        assert_eq!((*rev, label.as_str()), (r, l), "{why:?}");
        assert!(
            reason.contains(want),
            "rollout {rev}: `{want}` in `{reason}`"
        );
    }
    // Trusting the foreign key too: rollout 3 passes the signature check (and its bundle is
    // the tampered one, refused by its digest).
    let (_, both) = connect(&url, &[s.public.clone(), foreign.public_key()]);
    assert!(
        both[2]
            .bundle
            .as_ref()
            .is_err_and(|e| e.to_string().contains("does not hash")),
        "{:?}",
        both[2].bundle
    );
    // One arriving later is refused the same way.
    raw(port, "tessla_specs", async |kv| {
        kv.create(
            "rollout.6",
            b"{\"format\":\"tessla-telegraf-rollout/1\",\"rollout\":{\"revision\":6}}"
                .to_vec()
                .into(),
        )
        .await
        .unwrap();
    });
    let got = until("rollout 6 polled", || {
        let got = proposals(feed.poll());
        (!got.is_empty()).then_some(got)
    });
    assert_eq!(got[0].rollout.revision, 6);
    assert!(
        got[0]
            .bundle
            .as_ref()
            .is_err_and(|e| e.to_string().contains("its rollout cannot be read")),
        "{:?}",
        got[0].bundle
    );
    // No trusted key: a configuration error.
    let e = NatsFeed::connect(&parse_url(&url).unwrap(), &[])
        .err()
        .unwrap();
    assert!(e.message().contains("--spec-trust"), "{}", e.message());
}

#[test]
fn with_the_shipped_accounts_only_admin_may_publish() {
    let cluster = Cluster::start_secured(&nats_cluster::shipped_mapping(), &[])
        .unwrap_or_else(|| panic!("nats-server is needed by the spec channel's tests"));
    let hosts = cluster.hosts();
    let ca = cluster.certs().join("ca.pem");
    let url = |user: &str| {
        format!(
            "nats://{hosts}/tessla_specs?user={user}&password-env=PW&tls-ca={}",
            ca.display()
        )
    };
    let secrets: Vec<String> = ["fleet-p0", "fleet-p1", "admin"]
        .iter()
        .map(|u| cluster.password(u))
        .collect();
    let as_user = |user: &str, args: &[&str]| {
        let pw = cluster.password(user);
        let out = spec(args, &[("PW", pw.as_str())]);
        let text = format!("{}{}", child::text(&out.stdout), child::text(&out.stderr));
        for s in &secrets {
            assert!(
                !text.contains(s.as_str()),
                "a password in the output:\n{text}"
            );
        }
        out
    };
    let s = Setup::new();
    let main = s.write_spec("x * 2");
    let seed = s.seed.to_str().unwrap();
    let admin = url("admin");
    let p0 = url("fleet-p0");
    let out = as_user(
        "admin",
        &[
            "publish",
            main.to_str().unwrap(),
            "--channel",
            &admin,
            "--sign-key-file",
            seed,
        ],
    );
    let id = published(&out, 1);

    // fleet-p0 may not publish: the server refuses the write, the command says so (exit 3).
    s.write_spec("x * 9");
    let out = as_user(
        "fleet-p0",
        &[
            "publish",
            main.to_str().unwrap(),
            "--channel",
            &p0,
            "--sign-key-file",
            seed,
        ],
    );
    let err = child::text(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{err}");
    assert!(
        err.contains("spec: not permitted at nats://fleet-p0:***@")
            && err.contains("to write bundle.")
            && err.contains("Permissions Violation")
            && err.contains("gives that right to admin alone"),
        "{err}"
    );
    // Nor take a revision with a bundle already there.
    let out = as_user(
        "fleet-p0",
        &["rollback", "--channel", &p0, "--sign-key-file", seed],
    );
    let err = child::text(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{err}");
    assert!(
        err.contains("not permitted") && err.contains("rollout.2"),
        "{err}"
    );
    // Nothing was written; fleet-p0 may read.
    let listed = json(&as_user("fleet-p0", &["list", "--channel", &p0, "--json"]));
    assert_eq!(listed["rollouts"].as_array().unwrap().len(), 1);

    // fleet-p0 follows the channel and writes its status.
    let p0_url = parse_url(&format!(
        "nats://{hosts}/tessla_specs?user=fleet-p0&password-file={}&tls-ca={}",
        {
            let f = s.dir.path().join("p0.password");
            std::fs::write(&f, cluster.password("fleet-p0")).unwrap();
            f.display().to_string()
        },
        ca.display()
    ))
    .unwrap();
    let (mut feed, first) = NatsFeed::connect(&p0_url, std::slice::from_ref(&s.public))
        .unwrap_or_else(|e| panic!("{}", e.message()));
    let first = proposals(first);
    assert_eq!(first.len(), 1);
    assert_eq!(first[0].bundle.as_ref().unwrap().id(), id);
    feed.report("robot-host", "p0", &[outcome(&first[0].rollout, true, "")]);
    let status = until("fleet-p0's status", || {
        let v = json(&as_user(
            "admin",
            &["status", "--channel", &admin, "--json"],
        ));
        (v["processes"].as_array().map_or(0, Vec::len) == 1).then_some(v)
    });
    assert_eq!(status["processes"][0]["partition"], "p0");
    assert_eq!(status["rollouts"][0]["accepted"], 1);
}

#[test]
fn a_login_without_the_channel_permissions_is_told_what_it_needs() {
    let server = nats_server(
        "authorization { users: [\n\
         { user: admin, password: adminpw }\n\
         { user: other, password: otherpw, permissions: { publish: [\"$JS.API.INFO\"], subscribe: [\"_INBOX.>\"] } }\n\
         ] }",
    );
    let port = server.port;
    let s = Setup::new();
    let main = s.write_spec("x * 2");
    published(
        &s.publish(
            &format!("nats://admin:adminpw@127.0.0.1:{port}"),
            &main,
            &[],
        ),
        1,
    );
    let url = parse_url(&format!("nats://other:otherpw@127.0.0.1:{port}")).unwrap();
    let e = NatsFeed::connect(&url, std::slice::from_ref(&s.public))
        .err()
        .unwrap_or_else(|| panic!("connected without the permissions"));
    let m = e.message();
    assert!(
        m.contains("not permitted at nats://other:***@127.0.0.1:")
            && m.contains("access to the spec channel's bucket tessla_specs")
            && m.contains("Permissions Violation")
            && !m.contains("otherpw"),
        "{m}"
    );
}

/// The base spec of the end-to-end tests: a count that a new version keeps, and `y`, which it
/// changes.
pub(super) const BASE_SPEC: &str =
    "in x: Events[Int]\ndef c = count(x)\ndef y = x + 1\nout c\nout y\n";
const NEW_SPEC: &str = "in x: Events[Int]\ndef c = count(x)\ndef y = x * 10\nout c\nout y\n";
/// Event time of step `k` of the end-to-end input (in the past: no `--max-ahead` refusal).
pub(super) fn ts(k: i64) -> i64 {
    1_700_000_000_000_000_000 + k * 100_000_000
}

/// Records `ks` of `robots`, interleaved by step.
fn records(robots: &[&str], ks: std::ops::Range<i64>) -> String {
    let mut out = String::new();
    for k in ks {
        for r in robots {
            out.push_str(&format!("m,robot={r} x={k}i {}\n", ts(k)));
        }
    }
    out
}

/// `run BASE` following the channel at `url`, one instance per robot, outputs tagged with their
/// version.
pub(super) fn channel_run<'a>(url: &'a str, s: &'a Setup, base: &'a Path) -> Vec<&'a str> {
    vec![
        "run",
        "--spec",
        base.to_str().unwrap(),
        "--no-passthrough",
        "--instance-by",
        "robot",
        "--version-tag",
        "spec_version",
        "--spec-channel",
        url,
        "--spec-trust",
        &s.public,
    ]
}

/// `run` on the channel with the state in `bucket`, fed `input`: its output lines without the
/// status metrics, and stderr.
fn run_on_channel(
    url: &str,
    s: &Setup,
    base: &Path,
    bucket: &str,
    input: &str,
) -> (Vec<String>, String) {
    let state = format!("{url}/{bucket}");
    let mut args = channel_run(url, s, base);
    args.extend(["--state", &state]);
    let (out, err, code) = child::run_text(&args, input);
    assert_eq!(code, 0, "{err}");
    let lines = out
        .lines()
        .filter(|l| !l.starts_with("tessla_spec,"))
        .map(String::from)
        .collect();
    (lines, err)
}

/// A canary for robots r1 and r2 from step 10 and a rollout to every robot from step 15: one
/// process judges every record by the version in force at its time (the count carried over);
/// the same fleet split over a takeover in the middle of the change (at step 12: r1 and r2
/// switched, r3 not yet), and a robot run by a process of its own, give the same lines.
#[test]
fn a_rollout_switches_at_its_event_time_the_same_in_every_process() {
    let server = nats_server("");
    let url = format!("nats://127.0.0.1:{}", server.port);
    let s = Setup::new();
    let base = child::write(s.dir.path(), "base.tessla", BASE_SPEC);
    let new = child::write(s.dir.path(), "new.tessla", NEW_SPEC);
    let v_new = published(
        &s.publish(
            &url,
            &new,
            &[
                "--label",
                "ten",
                "--select",
                "robot=r1,r2",
                "--from",
                &ts(10).to_string(),
            ],
        ),
        1,
    );
    published(&s.publish(&url, &new, &["--from", &ts(15).to_string()]), 2);
    let robots = ["r1", "r2", "r3"];

    let (single, err) = run_on_channel(&url, &s, &base, "state_single", &records(&robots, 0..20));
    assert!(err.contains("rollout 1 (version"), "{err}");
    assert_eq!(single.len(), 60, "one line per record: {single:#?}");
    let v_base = single[0]
        .split(',')
        .find_map(|t| t.split(' ').next()?.strip_prefix("spec_version="))
        .unwrap()
        .to_string();
    assert_ne!(v_base, v_new);
    for (k, r) in (0..20).flat_map(|k| robots.iter().map(move |r| (k, *r))) {
        let switched = k >= 15 || (k >= 10 && r != "r3");
        let (v, y) = if switched {
            (&v_new, k * 10)
        } else {
            (&v_base, k + 1)
        };
        let want = format!(
            "tessla,robot={r},spec_version={v} c={}i,y={y}i {}",
            k + 1,
            ts(k)
        );
        assert!(single.contains(&want), "missing {want} in {single:#?}");
    }

    // A takeover in the middle of the change: the first process stops after step 11 (its
    // state saved), the next restores each robot as it arrives.
    let (mut split, _) = run_on_channel(&url, &s, &base, "state_split", &records(&robots, 0..12));
    let (rest, err) = run_on_channel(&url, &s, &base, "state_split", &records(&robots, 12..20));
    assert!(err.contains("restored"), "{err}");
    split.extend(rest);
    assert_eq!(split, single);

    // A partition of its own for r3.
    let (alone, _) = run_on_channel(&url, &s, &base, "state_r3", &records(&["r3"], 0..20));
    let r3: Vec<String> = single
        .iter()
        .filter(|l| l.starts_with("tessla,robot=r3,"))
        .cloned()
        .collect();
    assert_eq!(alone, r3);
}

/// Two running processes (two partitions): a good publish reaches both (each writes an accepted
/// status line and switches at the version's time), a version that cannot read their metrics
/// is refused by both with the reason, and both go on with the versions in force.
#[test]
fn every_running_process_takes_a_publish_and_refuses_a_bad_one() {
    use crate::support::live_child::LiveChild;
    let server = nats_server("");
    let url = format!("nats://127.0.0.1:{}", server.port);
    let s = Setup::new();
    let base = child::write(s.dir.path(), "base.tessla", BASE_SPEC);
    let new = child::write(s.dir.path(), "new.tessla", NEW_SPEC);
    // Reads `x` as a Bool: the metrics carry an Int.
    let bad = child::write(s.dir.path(), "bad.tessla", "in x: Events[Bool]\nout x\n");
    let spawn = || LiveChild::spawn(&channel_run(&url, &s, &base));
    let mut procs = [spawn(), spawn()];
    for (i, p) in procs.iter_mut().enumerate() {
        p.write(&format!("m,robot=p{i} x=1i {}\n", ts(0)));
        p.wait_out("the first answer", |l| {
            l.contains(&format!(" c=1i,y=2i {}", ts(0)))
        });
    }
    let out = s.publish(&url, &new, &["--from", &ts(5).to_string()]);
    let v_new = published(&out, 1);
    // Both voted; the fleet's decision is printed with each vote.
    let text = child::text(&out.stdout);
    assert!(
        text.contains("committed: all 2 processes accepted it") && text.contains("PROCESS"),
        "{text}"
    );
    for p in procs.iter_mut() {
        p.wait_out("the committed status", |l| {
            l.starts_with("tessla_spec,") && l.contains(",outcome=committed,") && l.contains(&v_new)
        });
        assert!(
            p.out
                .iter()
                .any(|l| l.contains(",outcome=accepted,") && l.contains(&v_new)),
            "the vote before the decision: {:#?}",
            p.out
        );
    }
    // Refused by both: aborted for the fleet, exit 5, saying who refused and why.
    let out = s.publish(&url, &bad, &[]);
    let text = child::text(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(5),
        "{text}{}",
        child::text(&out.stderr)
    );
    assert!(
        text.starts_with("rollout 2: version ")
            && text.contains("refused")
            && text.contains("aborted: ")
            && text.contains("input `x`"),
        "{text}"
    );
    // One refusal decides (the publisher does not wait for the other vote), so a process that
    // hears the abort before it has checked the version writes no refusal of its own: at least
    // one process refused, each with the reason, and every process took the abort.
    let mut refused = [false; 2];
    for (i, p) in procs.iter_mut().enumerate() {
        p.wait_out("the aborted status", |l| {
            l.starts_with("tessla_spec,") && l.contains(",outcome=aborted,")
        });
        for line in p.out.iter().filter(|l| l.contains(",outcome=refused,")) {
            assert!(line.contains("input `x`"), "{line}");
            refused[i] = true;
        }
        // Undisturbed: before the version's time the base, from it the new version.
        p.write(&format!(
            "m,robot=p{i} x=2i {}\nm,robot=p{i} x=3i {}\n",
            ts(4),
            ts(6)
        ));
        let want = format!(
            "tessla,robot=p{i},spec_version={v_new} c=3i,y=30i {}",
            ts(6)
        );
        p.wait_out("the new version's answer", |l| l.trim_end() == want);
        assert!(
            p.out
                .iter()
                .any(|l| l.trim_end().ends_with(&format!(" c=2i,y=3i {}", ts(4)))),
            "{:#?}",
            p.out
        );
    }
    assert!(refused.contains(&true), "no process wrote its refusal");
    for (p, refused) in procs.into_iter().zip(refused) {
        let (_, err, code) = p.finish();
        assert_eq!(code, 0, "{err}");
        // A refusal is logged where it was made, and only there.
        assert_eq!(err.contains("refused here: input `x`"), refused, "{err}");
        assert!(err.contains("aborted by the fleet"), "{err}");
    }
}

/// Defect 2 of the issue "One fleet, one truth", through real processes: a rollout the running
/// process refuses is aborted for the fleet; a process restarted afterwards (it has seen no
/// metric, so alone it would have accepted it) follows the decision and keeps the base; a
/// good rollout committed later reaches it, and a process started after that commit runs it
/// from its start too. Every line equals what one process with the same records gives.
#[test]
fn a_restart_after_an_aborted_rollout_and_a_start_after_a_commit_follow_the_decisions() {
    use crate::support::live_child::LiveChild;
    let server = nats_server("");
    let url = format!("nats://127.0.0.1:{}", server.port);
    let s = Setup::new();
    let base = child::write(s.dir.path(), "base.tessla", BASE_SPEC);
    let new = child::write(s.dir.path(), "new.tessla", NEW_SPEC);
    let bad = child::write(s.dir.path(), "bad.tessla", "in x: Events[Bool]\nout x\n");
    let state = format!("{url}/state_restart");
    let run_args = || {
        let mut a = channel_run(&url, &s, &base);
        a.extend(["--state", state.as_str()]);
        a
    };
    let mut first = LiveChild::spawn(&run_args());
    first.write(&format!("m,robot=r1 x=1i {}\n", ts(0)));
    first.wait_out("the first answer", |l| l.contains(" c=1i,y=2i "));
    let out = s.publish(&url, &bad, &[]);
    assert_eq!(out.status.code(), Some(5), "{}", child::text(&out.stdout));
    first.wait_out("the abort", |l| l.contains(",outcome=aborted,"));
    let (_, err, code) = first.finish();
    assert_eq!(code, 0, "{err}");

    // Restarted: it reads the rollout and its abort before its first record, never votes.
    let mut second = LiveChild::spawn(&run_args());
    second.write(&format!("m,robot=r1 x=2i {}\n", ts(1)));
    second.wait_out("the restored answer", |l| l.contains(" c=2i,y=3i "));
    assert!(
        !second
            .out
            .iter()
            .any(|l| l.contains(",outcome=accepted,") || l.contains(",outcome=refused,")),
        "a decided rollout is never voted on: {:#?}",
        second.out
    );
    // A good rollout now: the running process votes, the fleet commits.
    let v_new = published(&s.publish(&url, &new, &["--from", &ts(5).to_string()]), 2);
    second.wait_out("the commit", |l| {
        l.contains(",outcome=committed,") && l.contains(&v_new)
    });
    second.write(&format!(
        "m,robot=r1 x=3i {}\nm,robot=r1 x=4i {}\n",
        ts(4),
        ts(6)
    ));
    second.wait_out("the new version", |l| {
        l.trim_end() == format!("tessla,robot=r1,spec_version={v_new} c=4i,y=40i {}", ts(6))
    });
    let (_, err, code) = second.finish();
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("aborted by the fleet"), "{err}");

    // Started after the commit, for another robot: the rollout is in force from its start.
    let (lines, err) = run_on_channel(
        &url,
        &s,
        &base,
        "state_late",
        &format!("m,robot=r9 x=1i {}\nm,robot=r9 x=2i {}\n", ts(4), ts(6)),
    );
    assert!(err.contains("committed by the fleet"), "{err}");
    let v_base = lines[0]
        .split(',')
        .find_map(|t| t.split(' ').next()?.strip_prefix("spec_version="))
        .unwrap()
        .to_string();
    assert_eq!(
        lines,
        [
            format!("tessla,robot=r9,spec_version={v_base} c=1i,y=2i {}", ts(4)),
            format!("tessla,robot=r9,spec_version={v_new} c=2i,y=20i {}", ts(6)),
        ]
    );
}

/// Several processes on one host (issue 47: four Telegrafs showed as two): the primary and the
/// standby of one partition and a process of another each keep a status key of their own, so
/// `spec status` lists all three, live, each with its pid; a key in the earlier format
/// (`status.<host>.<partition>`) is still read; a process that stopped reads as stopped. The
/// channel's bucket is made by `spec init` before any rollout.
#[test]
fn spec_status_lists_every_process_of_one_host_each_by_its_pid() {
    use crate::support::live_child::LiveChild;
    let server = nats_server("");
    let url = format!("nats://127.0.0.1:{}", server.port);
    let s = Setup::new();
    let base = child::write(s.dir.path(), "base.tessla", BASE_SPEC);
    let out = spec(&["init", "--channel", &url], &[]);
    assert!(
        child::text(&out.stdout).contains(": bucket created"),
        "{}{}",
        child::text(&out.stdout),
        child::text(&out.stderr)
    );
    let out = spec(&["init", "--channel", &url], &[]);
    assert!(
        child::text(&out.stdout).contains(": bucket exists already"),
        "{}",
        child::text(&out.stdout)
    );
    // A key an earlier version wrote, for a process that has stopped since.
    let old = serde_json::json!({
        "host": "old-host", "partition": "p0", "pid": 1, "time": 1, "outcomes": [], "stopped": true
    });
    raw(server.port, "tessla_specs", async |kv| {
        kv.put("status.vold-host.vp0", old.to_string().into())
            .await
            .unwrap()
    });

    let state = |p: &str| format!("{url}/tessla_state?lease={p}&ttl=3s");
    let (s0, s1) = (state("p0"), state("p1"));
    let spawn = |state: &str| {
        let mut args = channel_run(&url, &s, &base);
        args.extend(["--state", state]);
        LiveChild::spawn(&args)
    };
    let mut procs = vec![spawn(&s0), spawn(&s0), spawn(&s1)];
    let pids: Vec<u64> = procs.iter().map(|p| u64::from(p.pid())).collect();
    let live = |v: &serde_json::Value| {
        v["processes"]
            .as_array()
            .map(|a| a.iter().filter(|p| p["state"] == "live").count())
            .unwrap_or(0)
    };
    let listed = until("three live processes", || {
        let v = json(&spec(&["status", "--channel", &url, "--json"], &[]));
        (live(&v) == 3).then_some(v)
    });
    let processes = listed["processes"].as_array().unwrap();
    assert_eq!(processes.len(), 4, "{listed:#}");
    let old_listed = processes
        .iter()
        .find(|p| p["key"] == "status.vold-host.vp0")
        .unwrap_or_else(|| panic!("the earlier key is read: {listed:#}"));
    assert_eq!(old_listed["state"], "stopped");
    let mut ours: Vec<(String, u64)> = processes
        .iter()
        .filter(|p| p["state"] == "live")
        .map(|p| {
            let pid = p["pid"].as_u64().unwrap();
            let key = p["key"].as_str().unwrap().to_string();
            let partition = p["partition"].as_str().unwrap();
            assert!(
                key.ends_with(&format!(".v{partition}.pid{pid}")),
                "{key} names its partition and pid"
            );
            (partition.to_string(), pid)
        })
        .collect();
    ours.sort();
    let mut want = vec![
        ("p0".to_string(), pids[0]),
        ("p0".to_string(), pids[1]),
        ("p1".to_string(), pids[2]),
    ];
    want.sort();
    assert_eq!(ours, want);
    let table = child::text(&spec(&["status", "--channel", &url], &[]).stdout);
    assert!(
        table.contains("Processes (4: 3 live, 0 silent, 1 stopped)"),
        "{table}"
    );

    // The standby stops (stdin closed, as Telegraf stops it): its key says so.
    let (_, err, code) = procs.remove(1).finish();
    assert_eq!(code, 0, "{err}");
    until("the standby stopped", || {
        let v = json(&spec(&["status", "--channel", &url, "--json"], &[]));
        v["processes"]
            .as_array()
            .and_then(|a| a.iter().find(|p| p["pid"].as_u64() == Some(pids[1])))
            .is_some_and(|p| p["state"] == "stopped")
            .then_some(())
    });
    let table = child::text(&spec(&["status", "--channel", &url], &[]).stdout);
    assert!(
        table.contains("Processes (4: 2 live, 0 silent, 2 stopped)") && table.contains("stopped "),
        "{table}"
    );
    for p in procs {
        let (_, err, code) = p.finish();
        assert_eq!(code, 0, "{err}");
    }
}
