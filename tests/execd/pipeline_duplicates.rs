//! QoS 1 redelivery through the real binary: a robot message delivered twice (Telegraf parses it
//! again, so its fields come in another order) is dropped and counted, and the actions, verdicts
//! and late-record count are those of the run without the repeat, under both `--late` modes.

use crate::support::child;
use crate::support::recorded;

use std::time::Duration;

/// The record with its fields in reverse order (same metric, as Telegraf would write it after
/// parsing the same JSON again).
fn reordered(line: &str) -> String {
    let (series, rest) = line.split_once(' ').unwrap();
    let (fields, ts) = rest.rsplit_once(' ').unwrap();
    // The recorded run's field values hold no commas (numbers and plain strings).
    let mut f: Vec<&str> = fields.split(',').collect();
    f.reverse();
    format!("{series} {} {ts}", f.join(","))
}

fn outputs(stdout: &str) -> Vec<String> {
    stdout
        .lines()
        .filter(|l| !l.starts_with("mqtt_consumer"))
        .map(str::to_string)
        .collect()
}

#[test]
fn a_redelivered_message_is_dropped_and_counted() {
    let input = std::fs::read_to_string(recorded::recorded_run_path()).unwrap();
    let lines: Vec<&str> = input
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .collect();
    let n = lines.len().min(40);
    let clean: String = lines[..n].iter().map(|l| format!("{l}\n")).collect();
    // Records 10 and 11 come again after record 12, as after a reconnect.
    let mut dup = String::new();
    for (i, l) in lines[..n].iter().enumerate() {
        dup.push_str(l);
        dup.push('\n');
        if i == 12 {
            dup.push_str(&reordered(lines[10]));
            dup.push('\n');
            dup.push_str(&reordered(lines[11]));
            dup.push('\n');
        }
    }
    for late in ["shift", "drop"] {
        let args = ["run", "--late", late];
        let a = child::run_bytes(&args, clean.clone().into_bytes(), Duration::from_secs(60));
        let b = child::run_bytes(&args, dup.clone().into_bytes(), Duration::from_secs(60));
        assert_eq!(a.code, Some(0), "{}", a.stderr);
        assert_eq!(b.code, Some(0), "{}", b.stderr);
        assert_eq!(
            outputs(&a.stdout_text()),
            outputs(&b.stdout_text()),
            "--late {late}"
        );
        // The repeat is not passed through either.
        assert_eq!(a.stdout_text(), b.stdout_text(), "--late {late}");
        assert!(a.stderr.contains(", 0 late records,"), "{}", a.stderr);
        assert!(b.stderr.contains(", 0 late records,"), "{}", b.stderr);
        assert!(a.stderr.contains(", 0 duplicates"), "{}", a.stderr);
        assert!(b.stderr.contains(", 2 duplicates"), "{}", b.stderr);
        assert!(
            b.stderr.contains(&format!("{} records", n + 2)),
            "{}",
            b.stderr
        );
    }
}

#[test]
fn a_late_record_with_other_values_is_still_late() {
    let input = std::fs::read_to_string(recorded::recorded_run_path()).unwrap();
    let lines: Vec<&str> = input
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .collect();
    // Record 3's time with record 4's values: not a duplicate.
    let (_, ts3) = lines[3].rsplit_once(' ').unwrap();
    let (body4, _) = lines[4].rsplit_once(' ').unwrap();
    let text = format!(
        "{}\n{}\n{}\n{}\n{}\n{body4} {ts3}\n",
        lines[0], lines[1], lines[2], lines[3], lines[4]
    );
    let f = child::run_bytes(&["run"], text.into_bytes(), Duration::from_secs(60));
    assert_eq!(f.code, Some(0), "{}", f.stderr);
    assert!(f.stderr.contains(", 1 late records,"), "{}", f.stderr);
    assert!(f.stderr.contains(", 0 duplicates"), "{}", f.stderr);
}
