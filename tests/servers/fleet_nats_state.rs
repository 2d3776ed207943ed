//! `--state nats://...` against a real 3-node NATS cluster: a fleet's state
//! continues across processes exactly (two runs give one uninterrupted run's outputs), one entry
//! per robot under its sanitised key, and a corrupt or foreign entry is put aside with a
//! warning, never trusted; a restart with an edited spec keeps every unchanged stream; a holder
//! whose lease another process takes stops stepping and stands by. Also: an unreachable server
//! is a clear error (exit 3).

use crate::support::child;
use crate::support::kv;

use crate::support::nats_cluster;

use nats_cluster::Cluster;
use std::io::Write;

/// Robots `ids`' records (the recorded run, one topic per robot), interleaved, records `range`.
fn fleet(ids: &[&str], range: std::ops::Range<usize>) -> String {
    let text = std::fs::read_to_string(format!(
        "{}/tests/fixtures/robot/recorded_run.lp",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let mut out = String::new();
    for line in &lines[range] {
        for id in ids {
            let tag = id.replace(' ', "\\ ");
            out.push_str(&line.replacen("topic=tessla", &format!("topic={tag}"), 1));
            out.push('\n');
        }
    }
    out
}

fn run(args: &[&str], input: &str) -> (String, String, i32) {
    let args: Vec<&str> = ["run", "--no-passthrough", "--instance-by", "topic"]
        .into_iter()
        .chain(args.iter().copied())
        .collect();
    child::run_text(&args, input)
}

/// The bucket `name`: (key, value) of every live entry.
fn entries(cluster: &Cluster, name: &str) -> Vec<(String, Vec<u8>)> {
    kv::with_bucket(&cluster.url(0), name, async |kv| {
        let mut out = Vec::new();
        for k in kv::keys(&kv).await {
            if let Some(v) = kv.get(&k).await.unwrap() {
                out.push((k, v.to_vec()));
            }
        }
        out
    })
}

fn put(cluster: &Cluster, bucket: &str, key: &str, value: Vec<u8>) {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let client = async_nats::connect(cluster.url(1)).await.unwrap();
        let kv = async_nats::jetstream::new(client)
            .get_key_value(bucket)
            .await
            .unwrap();
        kv.put(key, value.into()).await.unwrap();
    });
}

#[test]
fn state_in_a_bucket_continues_across_processes_and_rejects_bad_entries() {
    let Some(cluster) = Cluster::start(&nats_cluster::mapping(1)) else {
        return;
    };
    let url = format!("nats://{}/robots?replicas=3", cluster.hosts());
    let ids = ["fleet/a.1", "fleet/b 2"];
    // One thread, as with `--state`: the lines of the two robots keep their input order.
    let (whole, _, code) = run(&["--threads", "1"], &fleet(&ids, 0..300));
    assert_eq!(code, 0);

    // Two processes one after the other: the second continues the first's monitors.
    let (first, err, code) = run(&["--state", &url], &fleet(&ids, 0..120));
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("state: saved 2 monitor instances"), "{err}");
    let (second, err, code) = run(&["--state", &url], &fleet(&ids, 120..300));
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        first + &second,
        whole,
        "split run differs from the whole run"
    );

    // One entry per robot, under keys NATS accepts; the format is the state file's.
    let saved = entries(&cluster, "robots");
    let keys: Vec<&str> = saved.iter().map(|(k, _)| k.as_str()).collect();
    assert_eq!(keys, ["i.vfleet_2fa_2e1", "i.vfleet_2fb_202"]);
    let entry: serde_json::Value = serde_json::from_slice(&saved[0].1).unwrap();
    assert_eq!(entry["magic"], "tessla-telegraf-state");
    assert_eq!(entry["version"], 3);
    assert_eq!(entry["key"], serde_json::json!(["fleet/a.1"]));
    // The program it ran: its fingerprint and the key of every evaluated stream.
    assert_eq!(entry["program"]["fingerprint"].as_str().unwrap().len(), 16);
    assert!(entry["program"]["keys"].as_array().unwrap().len() > 50);

    // A corrupt entry and a foreign one (another options fingerprint): put aside, the robot
    // starts fresh.
    put(
        &cluster,
        "robots",
        "i.vfleet_2fa_2e1",
        b"{not json".to_vec(),
    );
    let mut foreign = entry.clone();
    foreign["fingerprint"] = "0123456789abcdef".into();
    foreign["key"] = serde_json::json!(["fleet/b 2"]);
    put(
        &cluster,
        "robots",
        "i.vfleet_2fb_202",
        serde_json::to_vec(&foreign).unwrap(),
    );
    let (fresh, _, _) = run(&["--threads", "1"], &fleet(&ids, 120..300));
    let (out, err, code) = run(&["--state", &url], &fleet(&ids, 120..300));
    assert_eq!(code, 0, "{err}");
    assert_eq!(out, fresh, "a rejected entry must not be used");
    assert!(
        err.contains("W! state: i.vfleet_2fa_2e1 in nats://")
            && err.contains("not used: not a state entry (corrupt or truncated"),
        "{err}"
    );
    assert!(
        err.contains("W! state: i.vfleet_2fb_202 in nats://")
            && err.contains("written for other options"),
        "{err}"
    );
    assert!(
        err.contains("put aside as aside.i.vfleet_2fa_2e1."),
        "{err}"
    );
    let after = entries(&cluster, "robots");
    let aside: Vec<&(String, Vec<u8>)> = after
        .iter()
        .filter(|(k, _)| k.starts_with("aside."))
        .collect();
    assert_eq!(
        aside.len(),
        2,
        "{:?}",
        after.iter().map(|e| &e.0).collect::<Vec<_>>()
    );
    assert!(aside.iter().any(|(_, v)| v == b"{not json"));
    // The run saved the robots' new state over the rejected entries.
    for key in ["i.vfleet_2fa_2e1", "i.vfleet_2fb_202"] {
        let (_, v) = after.iter().find(|(k, _)| k == key).unwrap();
        let e: serde_json::Value = serde_json::from_slice(v).unwrap();
        assert_eq!(e["fingerprint"], entry["fingerprint"]);
    }
}

const SUM: &str = "in x: Events[Int]\ndef c = count(x)\n\
    def sum: Events[Int] = default(last(sum, x), 0) + x\nout c\nout sum\n";
/// [`SUM`] with `sum`'s definition changed; `c` unchanged.
const SUM_EDITED: &str = "in x: Events[Int]\ndef c = count(x)\n\
    def sum: Events[Int] = default(last(sum, x), 0) + 2 * x\nout c\nout sum\n";

/// Each robot's output lines as (timestamp, c, sum), by robot.
fn counts_and_sums(
    text: &str,
) -> std::collections::BTreeMap<String, Vec<(String, String, String)>> {
    let mut m = std::collections::BTreeMap::<String, Vec<_>>::new();
    for l in text.lines() {
        let mut parts = l.split(' ');
        let robot = parts.next().unwrap().strip_prefix("tessla,topic=").unwrap();
        let fields: std::collections::HashMap<&str, &str> = parts
            .next()
            .unwrap()
            .split(',')
            .map(|f| f.split_once('=').unwrap())
            .collect();
        let ts = parts.next().unwrap();
        m.entry(robot.to_string()).or_default().push((
            ts.to_string(),
            fields["c"].to_string(),
            fields["sum"].to_string(),
        ));
    }
    m
}

/// A restart with an edited spec on the bucket: each robot's unchanged stream (`c`) continues
/// as in one uninterrupted run, the changed one (`sum`) starts afresh as in a fresh run of the
/// new spec, and one line (not one per robot) names the reset output. Needs nats-server: fails
/// without it.
#[test]
fn a_restart_with_an_edited_spec_keeps_every_unchanged_stream_in_the_bucket() {
    let cluster = Cluster::start(&nats_cluster::mapping(1))
        .expect("this test needs nats-server (it fails rather than skips without it)");
    let url = format!("nats://{}/edited?replicas=3", cluster.hosts());
    let dir = tempfile::tempdir().unwrap();
    let spec = dir.path().join("spec.tessla");
    let edited = dir.path().join("edited.tessla");
    std::fs::write(&spec, SUM).unwrap();
    std::fs::write(&edited, SUM_EDITED).unwrap();
    let lines: Vec<String> = (0..30i64)
        .map(|i| format!("m,topic=r{} x={}i {}\n", i % 3, (i * 7) % 5, 100 + i))
        .collect();
    let cut = 14;
    let args = |spec: &std::path::Path| {
        vec![
            "--spec".to_string(),
            spec.to_str().unwrap().to_string(),
            "--allowed-lateness".to_string(),
            "off".to_string(),
        ]
    };
    let run_spec = |spec: &std::path::Path, more: &[&str], input: &str| {
        let mut a = args(spec);
        a.extend(more.iter().map(|s| s.to_string()));
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        let (out, err, code) = run(&a, input);
        assert_eq!(code, 0, "{err}");
        (out, err)
    };
    let (whole, _) = run_spec(&spec, &["--threads", "1"], &lines.concat());
    let (fresh, _) = run_spec(&edited, &["--threads", "1"], &lines[cut..].concat());

    let (first, _) = run_spec(&spec, &["--state", &url], &lines[..cut].concat());
    let before = entries(&cluster, "edited");
    assert_eq!(before.len(), 3);
    std::fs::write(&spec, SUM_EDITED).unwrap();
    let (second, err) = run_spec(&spec, &["--state", &url], &lines[cut..].concat());
    let notes: Vec<&str> = err
        .lines()
        .filter(|l| l.contains("holds state saved by another program"))
        .collect();
    assert_eq!(notes.len(), 1, "one line for the three robots:\n{err}");
    assert!(
        notes[0].starts_with("I! state: nats://") && notes[0].contains("reset: outputs sum, "),
        "{}",
        notes[0]
    );
    assert!(
        !notes[0].contains("outputs c") && !err.contains("not used"),
        "{err}"
    );

    let got = counts_and_sums(&(first + &second));
    let whole = counts_and_sums(&whole);
    let fresh = counts_and_sums(&fresh);
    assert_eq!(got.len(), 3);
    for (robot, lines) in &got {
        let expected = &whole[robot];
        assert_eq!(lines.len(), expected.len(), "{robot}");
        // `c` (and the timestamps) as one uninterrupted run.
        let c = |v: &[(String, String, String)]| -> Vec<(String, String)> {
            v.iter().map(|(t, c, _)| (t.clone(), c.clone())).collect()
        };
        assert_eq!(c(lines), c(expected), "{robot}: `c` continues");
        // `sum` after the restart as a fresh run of the edited spec.
        let after = lines.len() - fresh[robot].len();
        assert_eq!(lines[..after], expected[..after], "{robot}");
        let sums = |v: &[(String, String, String)]| -> Vec<String> {
            v.iter().map(|(_, _, s)| s.clone()).collect()
        };
        assert_eq!(
            sums(&lines[after..]),
            sums(&fresh[robot]),
            "{robot}: `sum` starts afresh"
        );
    }
    // The entries now hold the edited spec's program.
    let after = entries(&cluster, "edited");
    for ((k, old), (k2, new)) in before.iter().zip(&after) {
        assert_eq!(k, k2);
        let old: serde_json::Value = serde_json::from_slice(old).unwrap();
        let new: serde_json::Value = serde_json::from_slice(new).unwrap();
        assert_eq!(new["version"], 3);
        assert_ne!(old["program"]["fingerprint"], new["program"]["fingerprint"]);
        assert_eq!(old["fingerprint"], new["fingerprint"], "the same options");
    }
}

#[test]
fn an_unreachable_server_is_a_clear_error() {
    let port = nats_cluster::free_port();
    let (_, err, code) = run(
        &["--state", &format!("nats://127.0.0.1:{port}/b")],
        "m x=1 1\n",
    );
    assert_eq!(code, 3, "{err}");
    assert!(
        err.contains(&format!(
            "E! state: cannot connect to nats://127.0.0.1:{port}/b: no NATS server answered"
        )),
        "{err}"
    );
    let (_, err, code) = run(&["--state", "nats://127.0.0.1:1/bad.name"], "");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("bucket `bad.name` must be"), "{err}");
}

#[test]
fn a_holder_whose_lease_is_taken_stops_stepping_and_stands_by() {
    let Some(cluster) = Cluster::start(&nats_cluster::mapping(1)) else {
        return;
    };
    let url = format!("nats://{}/leases?lease=p0&ttl=1s", cluster.hosts());
    let mut child = child::spawn(&[
        "run",
        "--no-passthrough",
        "--instance-by",
        "topic",
        "--state",
        &url,
    ]);
    let mut stdin = child.stdin.take().unwrap();
    let stdout = child.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        use std::io::BufRead;
        std::io::BufReader::new(stdout)
            .lines()
            .map_while(Result::ok)
            .filter(|l| l.starts_with("action,"))
            .count()
    });
    stdin
        .write_all(fleet(&["robot"], 0..50).as_bytes())
        .unwrap();
    stdin.flush().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(500));
    // Another process takes the lease (and keeps renewing it): this one must stop stepping.
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let renewer = {
        let stop = std::sync::Arc::clone(&stop);
        let cluster_url = cluster.url(0);
        std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap();
            rt.block_on(async {
                let client = async_nats::connect(cluster_url).await.unwrap();
                let kv = async_nats::jetstream::new(client)
                    .get_key_value("leases")
                    .await
                    .unwrap();
                while !stop.load(std::sync::atomic::Ordering::SeqCst) {
                    kv.put("lease.vp0", "other:1".into()).await.unwrap();
                    tokio::time::sleep(std::time::Duration::from_millis(100)).await;
                }
            });
        })
    };
    std::thread::sleep(std::time::Duration::from_millis(800));
    stdin
        .write_all(fleet(&["robot"], 50..100).as_bytes())
        .unwrap();
    stdin.flush().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(300));
    drop(stdin);
    let out = child.wait_with_output().unwrap();
    stop.store(true, std::sync::atomic::Ordering::SeqCst);
    renewer.join().unwrap();
    let actions = reader.join().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("lease: lease.vp0 was taken over by another process; standing by"),
        "{err}"
    );
    assert_eq!(
        actions, 50,
        "only the records before the takeover are stepped:\n{err}"
    );
    assert!(
        err.contains("standing by at the end; nothing saved (50 records buffered"),
        "{err}"
    );
}

/// `replicas=3` on a single nats-server (issue 47): said at start, exit 2, naming the URL option
/// and the value that works; the same URL with `replicas=1` runs.
#[test]
fn replicas_a_single_server_cannot_keep_name_the_option_and_the_value_that_works() {
    let Some(nats) = nats_cluster::require_nats_server() else {
        return;
    };
    let port = nats_cluster::free_port();
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("js");
    let conf = format!(
        "listen: 127.0.0.1:{port}\njetstream {{ store_dir: \"{}\" }}\n",
        store.display()
    );
    let server =
        crate::support::servers::Server::start(&nats, &["-c"], dir, port, "nats.conf", &conf);
    let url = |replicas: u32| format!("nats://127.0.0.1:{port}/solo?replicas={replicas}");
    let (_, err, code) = run(&["--state", &url(3)], "m x=1 1\n");
    assert_eq!(code, 2, "{err}\n{}", server.log());
    assert!(
        err.contains(&format!(
            "E! state: the URL option replicas=3 of nats://127.0.0.1:{port}/solo asks for 3 copies"
        )) && err.contains("a single nats-server (not a cluster) takes replicas=1"),
        "{err}"
    );
    let (_, err, code) = run(&["--state", &url(1)], "m x=1 1\n");
    assert_eq!(code, 0, "{err}");
}
