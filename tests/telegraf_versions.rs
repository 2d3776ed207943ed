//! The Telegraf version floor (1.33.3) and the tag escapes Telegraf does not undo, with the real
//! binary and the stand-in's models of Telegraf's serializer, parser and execd stdout readers
//! (tests/support/telegraf_standin.rs).
//!
//! - Our output can hold lines longer than 256 KiB (the echo of a long record) and raw newlines
//!   inside string fields (the echo of what Telegraf's serializer writes: it escapes only `"` and
//!   `\` in string values, plugins/serializers/influx/escape.go). Telegraf 1.33.3 and later read
//!   both whole; 1.30.0 to 1.33.2 split the newline into two parse errors and stop reading at
//!   the long line. So the confs and the README require 1.33.3.
//! - Telegraf's serializer writes a tab, newline, form feed or return in a tag value as `\t`,
//!   `\n`, `\f`, `\r`; its parser (plugins/parsers/influx/escape.go) unescapes only `\,`, `\ `,
//!   `\=` and `\"`. We echo the bytes as they came and write instance tags the same way, so the
//!   metric Telegraf reads back has a backslash and a letter where the control character was.

#[path = "support/child.rs"]
mod child;
#[path = "support/mqtt_client.rs"]
mod mqtt_client;
#[path = "support/telegraf_standin.rs"]
mod telegraf_standin;

use std::collections::BTreeMap;
use std::time::Duration;
use telegraf_standin::*;

fn metric(topic: &str, t: i64, fields: Vec<(&str, Field)>) -> Metric {
    let mut tags = BTreeMap::new();
    tags.insert("host".to_string(), "robot-pc".to_string());
    tags.insert("topic".to_string(), topic.to_string());
    Metric {
        name: "mqtt_consumer".into(),
        tags,
        fields: fields
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
        time: t,
    }
}

fn robot(topic: &str, t: i64, extra: Option<(&str, Field)>) -> Metric {
    let mut fields = vec![
        ("expectedSpeed", Field::Float(0.2)),
        ("actualSpeed", Field::Str("0.19".into())),
    ];
    fields.extend(extra);
    metric(topic, t, fields)
}

const T0: i64 = 1_700_000_000_000_000_000;

#[test]
fn our_output_needs_the_streaming_reader_of_telegraf_1_33_3() {
    let long = "x".repeat(300 * 1024);
    let input = [
        robot(
            "tessla",
            T0,
            Some(("note", Field::Str("two\nlines".into()))),
        ),
        robot("tessla", T0 + 200_000_000, Some(("note", Field::Str(long)))),
        robot("tessla", T0 + 400_000_000, None),
    ];
    let text: String = input.iter().filter_map(to_line).collect();
    assert!(
        text.contains("two\nlines"),
        "Telegraf writes the newline raw"
    );
    let out = child::run_bytes(&["run"], text.into_bytes(), Duration::from_secs(60));
    assert_eq!(out.code, Some(0), "{}", out.stderr);
    assert!(out.stderr.contains(", 0 parse errors,"), "{}", out.stderr);

    // 1.33.3 and later: every echo whole, every action read.
    let (metrics, errors, stopped) = read_stdout(&out.stdout, StdoutReader::Streaming);
    assert_eq!((errors, stopped), (0, false));
    let echoes: Vec<&Metric> = metrics
        .iter()
        .filter(|m| m.name == "mqtt_consumer")
        .collect();
    assert_eq!(echoes.len(), 3);
    for (echo, sent) in echoes.iter().zip(&input) {
        let mut a = (*echo).clone();
        let mut b = sent.clone();
        a.fields.sort_by(|x, y| x.0.cmp(&y.0));
        b.fields.sort_by(|x, y| x.0.cmp(&y.0));
        assert_eq!(a, b);
    }
    assert_eq!(metrics.iter().filter(|m| m.name == "action").count(), 3);

    // 1.30.0 to 1.33.2: the newline splits the first echo into two parse errors, the long line
    // stops the reader, and the actions after it never reach Telegraf.
    let (metrics, errors, stopped) = read_stdout(&out.stdout, StdoutReader::Scanner);
    assert_eq!(errors, 2);
    assert!(stopped);
    assert_eq!(metrics.iter().filter(|m| m.name == "action").count(), 1);

    // So the floor is stated where a user looks.
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    for conf in ["telegraf/telegraf.conf", "telegraf/telegraf-fleet.conf"] {
        let text = std::fs::read_to_string(root.join(conf)).unwrap();
        assert!(text.contains("Needs Telegraf >= 1.33.3"), "{conf}");
    }
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    assert!(readme.contains("**Telegraf versions.** 1.33.3 or later"));
}

/// Telegraf's parser: `unescape` of plugins/parsers/influx/escape.go for tag values.
fn telegraf_unescape(v: &str) -> String {
    v.replace("\\,", ",")
        .replace("\\\"", "\"")
        .replace("\\ ", " ")
        .replace("\\=", "=")
}

#[test]
fn tag_escapes_telegraf_writes_but_does_not_read_back() {
    let topic = "robot\t1\n2\r3\x0c4";
    let input = [robot(topic, T0, None), robot(topic, T0 + 200_000_000, None)];
    let text: String = input.iter().filter_map(to_line).collect();
    let escaped = "robot\\t1\\n2\\r3\\f4";
    assert!(text.contains(&format!("topic={escaped} ")), "{text:?}");
    let out = child::run_bytes(
        &["run", "--instance-by", "topic"],
        text.clone().into_bytes(),
        Duration::from_secs(60),
    );
    assert_eq!(out.code, Some(0), "{}", out.stderr);
    let stdout = out.stdout_text();
    // The echo is the input, byte for byte.
    let echoes: String = stdout
        .lines()
        .filter(|l| l.starts_with("mqtt_consumer,"))
        .map(|l| format!("{l}\n"))
        .collect();
    assert_eq!(echoes, text);
    // Verdicts and actions carry the instance's tag written with the same bytes.
    let outputs: Vec<&str> = stdout
        .lines()
        .filter(|l| !l.starts_with("mqtt_consumer,"))
        .collect();
    assert!(!outputs.is_empty());
    for l in &outputs {
        assert!(l.contains(&format!(",topic={escaped} ")), "{l}");
    }
    // What Telegraf makes of it: a backslash and a letter, not the control character; so the
    // echo in InfluxDB, and the action's MQTT topic, differ from the robot's topic there.
    assert_eq!(telegraf_unescape(escaped), "robot\\t1\\n2\\r3\\f4");
    assert_ne!(telegraf_unescape(escaped), topic);
}
