//! Per-robot monitor instances (`--instance-by`, `--max-instances`) with the real binary as a
//! child process: each robot's outputs are exactly those it gets when monitored alone, output
//! lines carry the instance tags, a fleet split across two processes gives the union of what one
//! process gives (partition invariance), and eviction is counted.

use crate::support::child::{self, run_text};

use std::io::Write;

const ROBOTS: usize = 3;
const PER_ROBOT: usize = 40;

/// The recorded run's records as robot `k` sends them: its own MQTT topic, and its clock
/// offset by `k` µs so that robots interleave without sharing timestamps... except robot 0 and
/// robot 2, which share every timestamp (one process must still keep them apart).
fn robot_lines(k: usize) -> Vec<String> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/robot/recorded_run.lp");
    let offset: i64 = if k == 2 { 0 } else { k as i64 * 1000 };
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        // Each robot starts at a different point of the run, so their states differ.
        .skip(k * 7)
        .take(PER_ROBOT)
        .map(|l| {
            let (head, ts) = l.rsplit_once(' ').unwrap();
            let ts: i64 = ts.parse().unwrap();
            let head = head.replacen("topic=tessla", &format!("topic=tessla/robot{k}"), 1);
            assert!(head.contains(&format!("topic=tessla/robot{k}")));
            format!("{head} {}\n", ts + offset)
        })
        .collect()
}

/// Robots' records interleaved round-robin, as one Telegraf would receive a fleet.
fn fleet(robots: &[usize]) -> String {
    let per: Vec<Vec<String>> = robots.iter().map(|&k| robot_lines(k)).collect();
    let mut s = String::new();
    for i in 0..PER_ROBOT {
        for lines in &per {
            s.push_str(&lines[i]);
        }
    }
    s
}

fn sorted_lines(s: &str) -> Vec<String> {
    let mut v: Vec<String> = s.lines().map(str::to_string).collect();
    v.sort();
    v
}

#[test]
fn each_instance_computes_what_its_robot_gets_alone() {
    let (out, err, code) = run_text(
        &["--no-passthrough", "--instance-by", "topic"],
        &fleet(&[0, 1, 2]),
    );
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("3 instances, 0 evicted"), "{err}");
    for k in 0..ROBOTS {
        let topic = format!("tessla/robot{k}");
        // Alone, without instances; the static tag stands in for the instance tag.
        let alone_input: String = robot_lines(k).concat();
        let (alone, err, code) = run_text(
            &["--no-passthrough", "--tag", &format!("topic={topic}")],
            &alone_input,
        );
        assert_eq!(code, 0, "{err}");
        assert!(err.contains("0 late records"), "{err}");
        let mine: Vec<String> = out
            .lines()
            .filter(|l| {
                let m = lineproto::parse_record(l.as_bytes()).unwrap().unwrap();
                m.tag("topic") == Some(topic.as_str())
            })
            .map(str::to_string)
            .collect();
        // Same lines in the same order: the instance's state is its own.
        assert_eq!(mine, alone.lines().collect::<Vec<_>>(), "robot {k}");
        assert_eq!(
            mine.iter().filter(|l| l.starts_with("action,")).count(),
            PER_ROBOT
        );
    }
    // Every output line carries its instance's tag.
    assert_eq!(
        out.lines().count(),
        out.lines()
            .filter(|l| l.contains(",topic=tessla/robot"))
            .count()
    );
}

#[test]
fn one_instance_mixes_robots_that_share_timestamps() {
    // Without --instance-by, robots 0 and 2 share one clock: robot 2 is 14 records ahead of
    // robot 0, so every record of robot 0 is late in the shared instance (stepped 1 ns after the
    // last step, its own time lost). This is what instances prevent.
    let (_, err, code) = run_text(&["--no-passthrough"], &fleet(&[0, 2]));
    assert_eq!(code, 0, "{err}");
    assert!(!err.contains(" 0 late records"), "{err}");
    let (_, err, _) = run_text(
        &["--no-passthrough", "--instance-by", "topic"],
        &fleet(&[0, 2]),
    );
    assert!(err.contains(" 0 late records"), "{err}");
    assert!(err.contains("0 dropped values"), "{err}");
}

#[test]
fn a_fleet_split_across_two_processes_gives_the_same_outputs() {
    let args = ["--no-passthrough", "--instance-by", "topic"];
    let (all, err, code) = run_text(&args, &fleet(&[0, 1, 2]));
    assert_eq!(code, 0, "{err}");
    let (part_a, err, code) = run_text(&args, &fleet(&[0, 2]));
    assert_eq!(code, 0, "{err}");
    let (part_b, err, code) = run_text(&args, &fleet(&[1]));
    assert_eq!(code, 0, "{err}");
    assert!(!part_a.is_empty() && !part_b.is_empty());
    let union = format!("{part_a}{part_b}");
    assert_eq!(sorted_lines(&all), sorted_lines(&union));
}

/// Pass-through is unchanged with instances: with one thread the echo is the input in its
/// order; with the default threads (the machine's cores) every input line is echoed once and
/// each robot's lines keep their order (the README's ordering guarantee: per instance, not
/// across instances read together).
#[test]
fn pass_through_is_unchanged_with_instances() {
    let input = fleet(&[0, 1]);
    let echoed = |out: &str| -> String {
        out.split_inclusive('\n')
            .filter(|l| l.starts_with("mqtt_consumer"))
            .collect()
    };
    let (out, err, code) = run_text(&["--instance-by", "topic", "--threads", "1"], &input);
    assert_eq!(code, 0, "{err}");
    assert_eq!(echoed(&out), input);
    for threads in [None, Some("2")] {
        let mut args = vec!["--instance-by", "topic"];
        args.extend(threads.map(|t| ["--threads", t]).into_iter().flatten());
        let (out, err, code) = run_text(&args, &input);
        assert_eq!(code, 0, "{err}");
        let echo = echoed(&out);
        assert_eq!(sorted_lines(&echo), sorted_lines(&input), "{threads:?}");
        assert_eq!(
            child::per_instance(&echo, "topic"),
            child::per_instance(&input, "topic"),
            "{threads:?}"
        );
    }
}

#[test]
fn past_max_instances_the_least_recently_used_is_evicted() {
    // Two robots alternating with room for one instance: every record evicts the other robot.
    let input = fleet(&[0, 1]);
    let (out, err, code) = run_text(
        &[
            "--no-passthrough",
            "--instance-by",
            "topic",
            "--max-instances",
            "1",
        ],
        &input,
    );
    assert_eq!(code, 0, "{err}");
    let records = 2 * PER_ROBOT;
    assert!(
        err.contains(&format!("{records} instances, {} evicted", records - 1)),
        "{err}"
    );
    assert!(
        err.contains("W! monitor instance topic=tessla/robot0 evicted"),
        "{err}"
    );
    // Evicted instances still answer their record before they go.
    assert_eq!(
        out.lines().filter(|l| l.starts_with("action,")).count(),
        records
    );
    // And their state starts afresh: a fresh instance's MSE is that of its only sample, so the
    // outputs differ from the run with room for both.
    let (kept, _, _) = run_text(&["--no-passthrough", "--instance-by", "topic"], &input);
    assert_ne!(sorted_lines(&out), sorted_lines(&kept));
}

/// `--max-instances` is the total whatever `--threads`: three robots with room for two keep
/// evicting on 2 threads as on 1 (the shards split the room: were it per thread, 2 threads
/// would hold all three).
#[test]
fn max_instances_is_the_total_over_threads() {
    let input = fleet(&[0, 1, 2]);
    for threads in ["1", "2"] {
        let args = |max: &'static str| {
            [
                "--no-passthrough",
                "--instance-by",
                "topic",
                "--max-instances",
                max,
                "--threads",
                threads,
            ]
        };
        let (_, err, code) = run_text(&args("2"), &input);
        assert_eq!(code, 0, "{err}");
        assert!(!err.contains(" 0 evicted"), "{threads}: {err}");
    }
}

#[test]
fn max_instances_zero_is_refused() {
    let (_, err, code) = run_text(&["--instance-by", "topic", "--max-instances", "0"], "");
    assert_eq!(code, 2, "{err}");
}

/// Each robot is evicted by its own silence: with no other input, the wall clock evicts both
/// once idle past the limit (the test waits for the two warnings, not for a time); robot 1's
/// next record then starts a fresh instance.
#[test]
fn an_idle_instance_is_evicted() {
    use std::io::{BufRead, BufReader};
    let mut child = child::spawn(&[
        "--no-passthrough",
        "--instance-by",
        "topic",
        "--instance-idle",
        "200ms",
    ]);
    let mut stdin = child.stdin.take().unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut send_and_wait = |line: &str| {
        stdin.write_all(line.as_bytes()).unwrap();
        stdin.flush().unwrap();
        let mut got = String::new();
        while !got.starts_with("action,") {
            got.clear();
            assert!(stdout.read_line(&mut got).unwrap() > 0, "no answer");
        }
    };
    let r0 = robot_lines(0);
    let r1 = robot_lines(1);
    send_and_wait(&r0[0]);
    send_and_wait(&r1[0]);
    // Both fall silent: no record comes, yet each is evicted.
    let mut err = String::new();
    for robot in ["robot0", "robot1"] {
        let wanted = format!("topic=tessla/{robot} evicted (idle longer than --instance-idle)");
        while !err.contains(&wanted) {
            let mut line = String::new();
            assert!(stderr.read_line(&mut line).unwrap() > 0, "{err}");
            err.push_str(&line);
        }
    }
    send_and_wait(&r1[1]);
    drop(stdin);
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut stderr, &mut rest).unwrap();
    err.push_str(&rest);
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(0), "{err}");
    // The fresh instance may fall idle too before the input ends.
    assert!(
        err.contains("3 instances, 2 evicted") || err.contains("3 instances, 3 evicted"),
        "{err}"
    );
}

#[test]
fn shipped_fleet_conf_command_keeps_robots_apart() {
    let conf = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("telegraf/telegraf-fleet.conf"),
    )
    .unwrap();
    let v: toml::Value = toml::from_str(&conf).unwrap();
    let execd = &v["processors"]["execd"][0];
    let cmd: Vec<&str> = execd["command"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap())
        .collect();
    assert_eq!(cmd[0], "/usr/bin/tessla-telegraf");
    // The MQTT topic template reads the tag the instances are keyed by.
    let by = cmd[cmd.iter().position(|a| *a == "--instance-by").unwrap() + 1];
    let topic = v["outputs"]["mqtt"][0]["topic"].as_str().unwrap();
    assert!(
        topic.contains(&format!("{{{{ .Tag \"{by}\" }}}}")),
        "{topic}"
    );
    // The monitors' state is kept in the systemd drop-in's StateDirectory; here in a temp dir.
    let state = "/var/lib/tessla-telegraf/telegraf-fleet.state";
    assert!(cmd.contains(&state), "{cmd:?}");
    let dir = tempfile::tempdir().unwrap();
    let here = dir.path().join("telegraf-fleet.state");
    let args: Vec<&str> = cmd[1..]
        .iter()
        .map(|a| {
            if *a == state {
                here.to_str().unwrap()
            } else {
                a
            }
        })
        .collect();
    let (out, err, code) = run_text(&args, &fleet(&[0, 1, 2]));
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("3 instances"), "{err}");
    assert!(err.contains("state: saved 3 monitor instances"), "{err}");
    // Every action names its robot and the spec version that computed it (--version-tag).
    let tags_of = |l: &str| -> Vec<String> {
        l.split(' ')
            .next()
            .unwrap()
            .split(',')
            .skip(1)
            .map(String::from)
            .collect()
    };
    for k in 0..ROBOTS {
        let robot = format!("{by}=tessla/robot{k}");
        let actions: Vec<&str> = out
            .lines()
            .filter(|l| l.starts_with("action,") && tags_of(l).contains(&robot))
            .collect();
        assert_eq!(actions.len(), PER_ROBOT, "robot {k}");
        for a in actions {
            assert!(
                tags_of(a).iter().any(|t| t.starts_with("spec_version=")),
                "{a}"
            );
        }
    }
}

/// `--threads N` spreads the instances over N threads: the output set and every instance's
/// output order (pass-through included) are those of one thread.
#[test]
fn threads_keep_the_output_set_and_each_instances_order() {
    // The recorded robots, and 300 more robots sending P2 records round by round.
    let mut input = fleet(&[0, 1, 2]);
    for round in 0..6 {
        for r in 0..300 {
            input.push_str(&format!(
                "mqtt_consumer,host=h,topic=fleet/r{r} expectedSpeed=0.05,actualSpeed=\"0.0{}\" {}\n",
                (r + round) % 9 + 1,
                1_600_000_000_000_000_000i64 + round * 200_000_000 + r
            ));
        }
    }
    let (one, _) = threads_agree_with_one(&input, |_, err_many| {
        assert!(err_many.contains("303 instances"), "{err_many}");
    });
    assert!(one.lines().count() > input.lines().count());
}

/// Runs `input` with `--instance-by topic` on 1, 2 and 3 threads and asserts that 2 and 3 threads
/// write the same set of lines as one, each instance's lines in the same order; `check` gets the
/// one-thread and the many-thread stderr. Returns the one-thread stdout and stderr.
fn threads_agree_with_one(input: &str, check: impl Fn(&str, &str)) -> (String, String) {
    let (one, err, code) = run_text(&["--instance-by", "topic", "--threads", "1"], input);
    assert_eq!(code, 0, "{err}");
    for threads in ["2", "3"] {
        let (many, err_many, code) =
            run_text(&["--instance-by", "topic", "--threads", threads], input);
        assert_eq!(code, 0, "{err_many}");
        assert_eq!(
            sorted_lines(&one),
            sorted_lines(&many),
            "--threads {threads}"
        );
        assert_eq!(
            child::per_instance(&one, "topic"),
            child::per_instance(&many, "topic"),
            "--threads {threads}"
        );
        check(&err, &err_many);
    }
    (one, err)
}

/// The same over many reads: a fleet larger than one read (records cut by read boundaries), with
/// an unbalanced quote that swallows the lines after it (taken apart line by line, each line to
/// its own instance's thread), a record longer than the limit (skipped once, not once per
/// thread), a record without the instance tag, and a last record without a newline (it comes
/// out of the splitter when the input ends): the output set, each instance's order and the
/// summary's counts are those of one thread.
#[test]
fn threads_agree_with_one_thread_over_many_reads() {
    let mut input = String::new();
    for round in 0..40 {
        for r in 0..200 {
            input.push_str(&format!(
                "mqtt_consumer,host=h,topic=fleet/r{r} expectedSpeed=0.05,actualSpeed=\"0.0{}\" {}\n",
                (r + round) % 9 + 1,
                1_600_000_000_000_000_000i64 + round * 200_000_000 + r
            ));
            if round == 7 && r == 50 {
                input.push_str("mqtt_consumer,host=h,topic=fleet/r50 actualSpeed=\"0.01 1\n");
            }
            if round == 9 && r == 3 {
                input.push_str("mqtt_consumer,host=h expectedSpeed=0.05 1600000001800000000\n");
            }
        }
    }
    let huge = format!(
        "mqtt_consumer,topic=fleet/r9 note=\"{}\" 1600000001000000000\n",
        "x".repeat(16 * 1024 * 1024)
    );
    let cut = input.len() / 2;
    let cut = cut + input[cut..].find('\n').unwrap() + 1;
    input.insert_str(cut, &huge);
    input.pop();
    assert!(input.len() > 16 * 1024 * 1024 + 8 * 65536);
    let summary = |err: &str| {
        err.lines()
            .find(|l| l.contains("summary:"))
            .map(str::to_string)
    };
    let (_, err) = threads_agree_with_one(&input, |err, err_many| {
        assert_eq!(summary(err), summary(err_many));
    });
    assert!(err.contains("parse error"), "{err}");
}

/// The summary line counts the same on any thread count, every counter included: records,
/// events, outputs, parse errors, late records, records ahead of the clock, dropped values,
/// duplicates, instances and evictions.
#[test]
fn the_summary_is_the_same_on_any_thread_count() {
    let mut input = String::new();
    for round in 0..20i64 {
        for r in 0..100i64 {
            let ts = 1_600_000_000_000_000_000i64 + round * 200_000_000 + r;
            let line = format!(
                "mqtt_consumer,host=h,topic=fleet/r{r} expectedSpeed=0.05,actualSpeed=\"0.0{}\" {ts}\n",
                (r + round) % 9 + 1
            );
            input.push_str(&line);
            match (round + r) % 10 {
                // A redelivered message: an exact duplicate.
                0 => input.push_str(&line),
                // A late record, a value that does not convert, one far in the future.
                1 => input.push_str(&format!(
                    "mqtt_consumer,host=h,topic=fleet/r{r} expectedSpeed=0.04 {}\n",
                    ts - 100_000_000
                )),
                2 => input.push_str(&format!(
                    "mqtt_consumer,host=h,topic=fleet/r{r} actualSpeed=\"fast\" {}\n",
                    ts + 1
                )),
                3 => input.push_str(&format!(
                    "mqtt_consumer,host=h,topic=fleet/r{r} expectedSpeed=0.04 {}\n",
                    i64::MAX - 5
                )),
                4 => input.push_str(&format!("mqtt_consumer,topic=fleet/r{r} broken\n")),
                _ => {}
            }
        }
    }
    let summary = |threads: &str| {
        let (_, err, code) = run_text(
            &[
                "--no-passthrough",
                "--instance-by",
                "topic",
                "--max-instances",
                "80",
                "--threads",
                threads,
            ],
            &input,
        );
        assert_eq!(code, 0, "{err}");
        err.lines()
            .find(|l| l.starts_with("I! summary:"))
            .unwrap_or_else(|| panic!("no summary: {err}"))
            .to_string()
    };
    let one = summary("1");
    for c in [
        " 0 late records",
        " 0 ahead of the clock",
        " 0 duplicates",
        " 0 parse errors",
        " 0 evicted",
        " 0 dropped values",
    ] {
        assert!(!one.contains(c), "the workload has some: {one}");
    }
    assert_eq!(summary("2"), one);
    assert_eq!(summary("3"), one);
}
