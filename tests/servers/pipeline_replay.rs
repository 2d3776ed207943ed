//! `tessla-telegraf replay` against a real Mosquitto: every record arrives as the robot's JSON
//! message, in order, paced by the recorded time; an unreachable broker is named and fails.

use crate::support::mqtt_client;
use crate::support::servers;

use serde_json::{Value, json};
use std::process::Command;
use std::time::Duration;

use crate::support::BIN;

const S: i64 = 1_000_000_000;
const T0: i64 = 1_700_000_000 * S;

fn replay(args: &[&str]) -> std::process::Output {
    Command::new(BIN).arg("replay").args(args).output().unwrap()
}

fn as_json(messages: &[(std::time::Instant, Vec<u8>)]) -> Vec<Value> {
    messages
        .iter()
        .map(|(_, payload)| serde_json::from_slice(payload).unwrap())
        .collect()
}

#[test]
fn line_protocol_records_arrive_as_robot_json_in_order() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("run.lp");
    // Shaped as Telegraf's mqtt_consumer makes the robot's messages: a string actualSpeed,
    // lidar flattened to lidar_<i> with beam 1 missing (it was NaN/null on the wire).
    std::fs::write(
        &file,
        format!(
            "mqtt_consumer,topic=tessla expectedSpeed=0.1,actualSpeed=\"0.05\",lidar_0=0.5,lidar_2=1.25 {}\n\
             mqtt_consumer,topic=tessla expectedSpeed=0.1,expectedAngular=0.2,actualAngular=-0.1 {}\n\
             not a record\n\
             mqtt_consumer,topic=tessla actualSpeed=0.08,lidar_0=0,lidar_1=3.5 {}\n",
            T0,
            T0 + S / 5,
            T0 + 2 * S / 5
        ),
    )
    .unwrap();
    let rx = mqtt_client::subscribe(broker.port, "tessla", "test-sub");
    let out = replay(&[
        file.to_str().unwrap(),
        "--broker",
        &broker.url(),
        "--topic",
        "tessla",
        "--speed",
        "0",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "replay failed: {stderr}");
    assert!(
        stderr.contains("line 3"),
        "the bad record is reported: {stderr}"
    );
    let got = as_json(&mqtt_client::collect(&rx, 3, Duration::from_secs(10)));
    assert_eq!(
        got,
        vec![
            json!({"expectedSpeed": 0.1, "actualSpeed": "0.05", "lidar": [0.5, null, 1.25]}),
            json!({"expectedSpeed": 0.1, "expectedAngular": 0.2, "actualAngular": -0.1}),
            json!({"actualSpeed": 0.08, "lidar": [0.0, 3.5]}),
        ]
    );
    // Nothing else was published.
    assert!(mqtt_client::collect(&rx, 1, Duration::from_millis(300)).is_empty());
}

#[test]
fn csv_with_string_field_and_time_key() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("run.csv");
    std::fs::write(
        &file,
        "time,expectedSpeed,actualSpeed,lidar\n\
         10.0,0.1,0.05,0.5 nan 2\n\
         10.2,0.1,0.09,\n",
    )
    .unwrap();
    let rx = mqtt_client::subscribe(broker.port, "robot/in", "test-sub-csv");
    let out = replay(&[
        file.to_str().unwrap(),
        "--broker",
        &broker.url(),
        "--topic",
        "robot/in",
        "--speed",
        "0",
        "--string-field",
        "actualSpeed",
        "--time-key",
        "time",
        // QoS 0: nothing is acknowledged; replay must still deliver everything before it
        // disconnects.
        "--qos",
        "0",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got = as_json(&mqtt_client::collect(&rx, 2, Duration::from_secs(10)));
    assert_eq!(
        got,
        vec![
            json!({"expectedSpeed": 0.1, "actualSpeed": "0.05", "lidar": [0.5, null, 2.0],
                   "time": 10_000_000_000_i64}),
            json!({"expectedSpeed": 0.1, "actualSpeed": "0.09", "time": 10_200_000_000_i64}),
        ]
    );
}

#[test]
fn recorded_pacing_is_kept_and_scaled() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("paced.lp");
    // Four records 0.4 s apart: 1.2 s recorded.
    let text: String = (0..4)
        .map(|i| format!("mqtt_consumer expectedSpeed={i} {}\n", T0 + i * 2 * S / 5))
        .collect();
    std::fs::write(&file, text).unwrap();
    for (speed, recorded_s) in [("1", 1.2), ("2", 0.6)] {
        let rx = mqtt_client::subscribe(broker.port, "paced", &format!("sub-{speed}"));
        let out = replay(&[
            file.to_str().unwrap(),
            "--broker",
            &broker.url(),
            "--topic",
            "paced",
            "--speed",
            speed,
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let got = mqtt_client::collect(&rx, 4, Duration::from_secs(10));
        assert_eq!(got.len(), 4);
        let span = got[3].0.duration_since(got[0].0).as_secs_f64();
        assert!(
            span >= recorded_s * 0.9 && span < recorded_s + 0.5,
            "--speed {speed}: first to last took {span} s, recorded {recorded_s} s"
        );
        let values: Vec<Value> = as_json(&got)
            .into_iter()
            .map(|v| v["expectedSpeed"].clone())
            .collect();
        assert_eq!(values, vec![json!(0.0), json!(1.0), json!(2.0), json!(3.0)]);
    }
}

#[test]
fn unreachable_broker_is_named_and_fails() {
    let port = servers::free_port();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("one.lp");
    std::fs::write(&file, "mqtt_consumer expectedSpeed=1 1\n").unwrap();
    let url = format!("mqtt://127.0.0.1:{port}");
    let out = replay(&[file.to_str().unwrap(), "--broker", &url]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(3), "{stderr}");
    assert!(stderr.contains(&url), "names the broker: {stderr}");
}

#[test]
fn missing_file_and_bad_options_fail_clearly() {
    let out = replay(&["/nonexistent/run.lp", "--speed", "0"]);
    assert_eq!(out.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/run.lp"));
    let out = replay(&["x.lp", "--speed=-1"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--speed"));
}

#[test]
fn many_full_scans_all_arrive_even_with_qos_0() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("scans.lp");
    let mut text = String::new();
    for i in 0..300i64 {
        let beams: Vec<String> = (0..360)
            .map(|j| format!("lidar_{j}={}", 0.12 + ((i * 7 + j) % 300) as f64 / 100.0))
            .collect();
        text.push_str(&format!(
            "mqtt_consumer,topic=tessla expectedSpeed={i},{} {}\n",
            beams.join(","),
            T0 + i * S / 5
        ));
    }
    std::fs::write(&file, text).unwrap();
    let rx = mqtt_client::subscribe(broker.port, "tessla", "sub-scans");
    let out = replay(&[
        file.to_str().unwrap(),
        "--broker",
        &broker.url(),
        "--speed",
        "0",
        "--qos",
        "0",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got = as_json(&mqtt_client::collect(&rx, 300, Duration::from_secs(10)));
    assert_eq!(got.len(), 300, "every scan arrived");
    for (i, message) in got.iter().enumerate() {
        assert_eq!(message["expectedSpeed"], json!(i as f64), "in order");
        let lidar = message["lidar"].as_array().unwrap();
        assert_eq!(lidar.len(), 360);
        let expected_last = 0.12 + ((i as i64 * 7 + 359) % 300) as f64 / 100.0;
        assert_eq!(lidar[359], json!(expected_last));
    }
}

#[test]
fn a_line_that_is_not_utf8_is_skipped_and_a_long_gap_is_announced_and_capped() {
    let Some(broker) = servers::Mosquitto::start() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("gap.lp");
    // Line 2 is not UTF-8; an hour passes between lines 3 and 4.
    let mut bytes = format!("mqtt_consumer expectedSpeed=1 {T0}\n").into_bytes();
    bytes.extend_from_slice(b"mqtt_consumer note=\"\xc3\x28\" 1\n");
    bytes.extend(format!("mqtt_consumer expectedSpeed=2 {}\n", T0 + S / 5).into_bytes());
    bytes.extend(format!("mqtt_consumer expectedSpeed=3 {}\n", T0 + 3600 * S).into_bytes());
    std::fs::write(&file, bytes).unwrap();
    let rx = mqtt_client::subscribe(broker.port, "gap", "test-sub-gap");
    let start = std::time::Instant::now();
    let out = replay(&[
        file.to_str().unwrap(),
        "--broker",
        &broker.url(),
        "--topic",
        "gap",
        "--max-gap",
        "500ms",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "replay failed: {stderr}");
    assert!(
        start.elapsed() < Duration::from_secs(20),
        "the hour was capped: {:?}",
        start.elapsed()
    );
    assert!(
        stderr.contains("skipped line 2: not UTF-8 (a bad byte at column 21)"),
        "{stderr}"
    );
    assert!(
        stderr.contains("line 4: the recording pauses 3599.8 s here; waiting 0.5 s (--max-gap)"),
        "{stderr}"
    );
    assert!(stderr.contains("published 3 messages"), "{stderr}");
    let got = as_json(&mqtt_client::collect(&rx, 3, Duration::from_secs(10)));
    assert_eq!(
        got,
        vec![
            json!({"expectedSpeed": 1.0}),
            json!({"expectedSpeed": 2.0}),
            json!({"expectedSpeed": 3.0}),
        ]
    );
}
