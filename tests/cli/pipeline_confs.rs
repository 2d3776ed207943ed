//! What the shipped confs must set for the README's guarantees, read from the files (the
//! real Telegraf runs each of them in `servers::telegraf_real`, `servers::telegraf_real_nats`
//! and `servers::telegraf_real_failures`, and `telegraf --test` checks every key there): QoS 1, persistent
//! sessions with fixed client ids, millisecond action timestamps, an absolute command path,
//! the restart delay, a bounded instance count and the monitors' state kept.

#[test]
fn every_shipped_conf_is_read_whole_and_sets_the_guarantees() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("telegraf");
    let mut n = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "conf") {
            continue;
        }
        n += 1;
        let text = std::fs::read_to_string(&path).unwrap();
        let v: toml::Value = toml::from_str(&text).unwrap();
        let name = path.display();
        for c in v["inputs"]["mqtt_consumer"].as_array().unwrap() {
            assert_eq!(c["qos"].as_integer(), Some(1), "{name}");
            assert_eq!(c["persistent_session"].as_bool(), Some(true), "{name}");
            assert!(
                c["client_id"].as_str().is_some_and(|s| !s.is_empty()),
                "{name}"
            );
        }
        for o in v["outputs"]["mqtt"].as_array().unwrap() {
            // Actions at QoS 1, except the fleet's: one PUBACK round trip per action cannot
            // keep up with 1,000 robots (the conf's comment, BENCHMARKS.md).
            let qos = if name.to_string().ends_with("telegraf-fleet.conf") {
                0
            } else {
                1
            };
            assert_eq!(o["qos"].as_integer(), Some(qos), "{name}");
            assert_eq!(o["json_timestamp_units"].as_str(), Some("1ms"), "{name}");
        }
        if let Some(execd) = v.get("processors").and_then(|p| p.get("execd")) {
            check_execd(&execd[0], "1s", 50_000, &name.to_string());
        }
    }
    assert_eq!(n, 3);
}

/// An execd block as the README's guarantees need it: an absolute command path (systemd's
/// PATH), the restart_delay chosen for 5 Hz, and with --instance-by a --max-instances whose
/// save at a stop fits Telegraf's budget (README, "Restarts and reloads").
fn check_execd(execd: &toml::Value, delay: &str, max_instances: u64, name: &str) {
    let cmd: Vec<&str> = execd["command"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap())
        .collect();
    assert_eq!(cmd[0], "/usr/bin/tessla-telegraf", "{name}");
    assert_eq!(execd["restart_delay"].as_str(), Some(delay), "{name}");
    // The monitors' state survives a reload or restart: a file in the drop-in's
    // StateDirectory, or the fleet's bucket, saved periodically too.
    let state = cmd.iter().position(|a| *a == "--state").map(|i| cmd[i + 1]);
    assert!(
        state.is_some_and(|s| s.starts_with("/var/lib/tessla-telegraf/") || s.starts_with("nats://")),
        "{name}: --state {state:?}"
    );
    assert!(cmd.contains(&"--state-interval"), "{name}");
    if cmd.contains(&"--instance-by") {
        let at = cmd.iter().position(|a| *a == "--max-instances");
        let n: u64 = at
            .and_then(|i| cmd.get(i + 1))
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("{name}: --max-instances is set"));
        assert!(n <= max_instances, "{name}: {n}");
    }
}

#[test]
fn the_nats_confs_bound_what_a_stop_saves() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("telegraf/fleet-nats");
    let mut n = 0;
    for part in ["telegraf-p0.conf", "telegraf-p1.conf"] {
        let text = std::fs::read_to_string(dir.join(part)).unwrap();
        let v: toml::Value = toml::from_str(&text).unwrap();
        check_execd(&v["processors"]["execd"][0], "2s", 10_000, part);
        n += 1;
    }
    assert_eq!(n, 2);
}
