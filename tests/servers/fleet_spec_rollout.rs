//! Rollouts of the fleet spec through the spec channel (docs/fleet.md, "Rollouts of the fleet
//! spec"): a real nats-server, two partitions of the real binary running the fleet example with
//! `--spec-channel`, and `spec publish --fleet` in the middle of the run with a start ahead of
//! the records. The fleet lines the holder of the fleet level writes before and after the
//! switch equal, line for line, those of one process fed the same records and started after the
//! publish (the rollout known from its start); the lines after the switch carry the new fleet
//! spec's version. A fleet spec with a type error, and one reading an input that is no robot
//! output, are refused at publish with the messages of `--fleet-spec` and change nothing (the
//! good publish is still revision 1). A decision read after the fleet level passed the start
//! switches at the same step in every process (the one after the switch entry), also across a
//! takeover.

use super::fleet_level_nats::{base, example_args, fleet_lines, records};
use super::fleet_nats_specs::{Setup, nats_server, published};
use crate::support::child;
use crate::support::fleet_partitions::{
    TwoPartitions, hand_over, two_partitions, wait_fleet_line_from,
};
use crate::support::live_child::{LiveChild, run_all};
use crate::support::servers::Server;
use std::path::PathBuf;

const STEPS: i64 = 120;

/// The fleet example's fleet spec with zone A twice as long and its slow-down stricter.
const FLEET_V2: &str = "include \"fleet.tessla\"
in p2_violated: Events[Map[String, Bool]]
in position: Events[Map[String, (Float, Float)]]
def zone_a = fleetInZone(position, 0.0, 0.0, 4.0, 1.0)
def zone_a_count = Map.size(zone_a)
out fleetCountTrue(p2_violated) as fleet_p2_violations
out fleetClosestDistance(position) as closest_distance
out zone_a_count as zone_a_occupancy
@FleetAction(\"speed_limit\", 400000000)
out fleetAddress(filter(zone_a, zone_a_count >= 2), 0.02) as zone_a_slowdown
";

/// A type error in the fleet spec itself.
const FLEET_TYPE_ERROR: &str = "include \"fleet.tessla\"
in position: Events[Map[String, (Float, Float)]]
out fleetCountTrue(Map.size(position) > 1) as crowded
";

/// `position` read as a map of Floats: the robot output is a pair.
const FLEET_WRONG_INPUT: &str = "include \"fleet.tessla\"
in position: Events[Map[String, Float]]
out Map.size(position) as crowded
";

/// `speed` is no output of the robot spec.
const FLEET_NO_OUTPUT: &str = "include \"fleet.tessla\"
in speed: Events[Map[String, Float]]
out Map.size(speed) as moving
";

/// The example's arguments, following the channel, fleet lines tagged with their version.
fn args(url: &str, s: &Setup, extra: &[String]) -> Vec<String> {
    let mut a = example_args();
    a.extend(
        [
            "--spec-channel",
            url,
            "--spec-trust",
            &s.public,
            "--version-tag",
            "spec_version",
        ]
        .map(String::from),
    );
    a.extend(extra.iter().cloned());
    a
}

fn spawn(url: &str, s: &Setup, state: &str, lease: &str) -> LiveChild {
    let a = args(
        url,
        s,
        &[
            "--state".to_string(),
            format!("{state}?lease={lease}&ttl=1s"),
        ],
    );
    LiveChild::spawn(&a.iter().map(String::as_str).collect::<Vec<_>>())
}

/// What every test here starts with: a nats-server, the channel's URL and the state bucket
/// `bucket` on it, the operator's keys, the robot spec, the fleet spec's version 2 and the
/// records' base time.
struct Rollout {
    _server: Server,
    url: String,
    state: String,
    s: Setup,
    robot: PathBuf,
    v2: PathBuf,
    base: i64,
}

impl Rollout {
    fn new(bucket: &str) -> Rollout {
        let server = nats_server("");
        let url = format!("nats://127.0.0.1:{}", server.port);
        let state = format!("{url}/{bucket}");
        let s = Setup::new();
        let robot = child::root().join("specs/fleet/robot.tessla");
        let v2 = child::write(s.dir.path(), "fleet_v2.tessla", FLEET_V2);
        Rollout {
            _server: server,
            url,
            state,
            s,
            robot,
            v2,
            base: base(),
        }
    }

    /// A process of partition `lease` following the channel.
    fn spawn(&self, lease: &str) -> LiveChild {
        spawn(&self.url, &self.s, &self.state, lease)
    }

    /// Publish version 2 of the fleet spec from `from`: what `spec publish` said, and the
    /// version's id (revision 1).
    fn publish_v2(&self, from: i64) -> (std::process::Output, String) {
        let out = self.s.publish(
            &self.url,
            &self.robot,
            &[
                "--fleet",
                self.v2.to_str().unwrap(),
                "--from",
                &from.to_string(),
            ],
        );
        let id = published(&out, 1);
        (out, id)
    }
}

/// The `spec_version` tag of a line.
fn version(line: &str) -> Option<&str> {
    line.split(' ')
        .next()?
        .split(',')
        .find_map(|t| t.strip_prefix("spec_version="))
}

#[test]
fn a_fleet_spec_rollout_switches_at_its_start_in_every_partition_as_in_one_process() {
    let r = Rollout::new("fleet_rollout");
    let (url, s, robot, base) = (&r.url, &r.s, &r.robot, r.base);
    let bad_type = child::write(s.dir.path(), "fleet_type.tessla", FLEET_TYPE_ERROR);
    let bad_input = child::write(s.dir.path(), "fleet_input.tessla", FLEET_NO_OUTPUT);
    let wrong_input = child::write(s.dir.path(), "fleet_wrong.tessla", FLEET_WRONG_INPUT);
    // Ahead of every record written before the publish: step 70's time.
    let from = base + 70 * 200_000_000 - 500;

    let TwoPartitions {
        p0: mut a,
        p1: mut b,
        ..
    } = two_partitions(&|lease| r.spawn(lease), false);
    a.write(&records(base, Some(0), 0..50));
    b.write(&records(base, Some(1), 0..50));
    a.wait_out("a fleet line", |l| l.starts_with("tessla_fleet,"));

    // Refused at publish, with the start-up messages; nothing is written to the channel.
    let refused = s.publish(url, robot, &["--fleet", bad_type.to_str().unwrap()]);
    let err = child::text(&refused.stderr);
    assert!(!refused.status.success(), "{err}");
    assert!(
        err.contains("argument 1 of `fleetCountTrue`: expected Map[String, Bool]")
            && err.contains("fleet_type.tessla:3:20")
            && err.contains("was not published: it does not check"),
        "{err}"
    );
    let refused = s.publish(url, robot, &["--fleet", wrong_input.to_str().unwrap()]);
    let err = child::text(&refused.stderr);
    assert!(!refused.status.success(), "{err}");
    assert!(
        err.contains("fleet spec input `position` has type Events[Map[String, Float]]")
            && err.contains("was not published"),
        "{err}"
    );
    let refused = s.publish(url, robot, &["--fleet", bad_input.to_str().unwrap()]);
    let err = child::text(&refused.stderr);
    assert!(!refused.status.success(), "{err}");
    assert!(
        err.contains("fleet spec input `speed` is not an output of the robot spec")
            && err.contains("was not published"),
        "{err}"
    );

    // The good one: both partitions vote for it; revision 1 (the refusals wrote nothing).
    let (out, v_new) = r.publish_v2(from);
    assert!(
        child::text(&out.stdout).contains("all 2 processes accepted it"),
        "{}",
        child::text(&out.stdout)
    );
    // Both fleet levels have the switch before the records reach its start.
    for c in [&mut a, &mut b] {
        c.wait_err("the switch entry", 0, |l| {
            l.contains("switch entry for fleet rollout 1")
        });
    }
    a.write(&records(base, Some(0), 50..STEPS));
    b.write(&records(base, Some(1), 50..STEPS));
    let (b_out, b_err, code) = b.finish();
    assert_eq!(code, 0, "{b_err}");
    let (a_out, a_err, code) = a.finish();
    assert_eq!(code, 0, "{a_err}");
    assert!(fleet_lines(&b_out).is_empty(), "{b_out}");

    // One process started after the publish, fed every record.
    let one = args(url, s, &[]);
    let (one_out, one_err, code) = run_all(
        &one.iter().map(String::as_str).collect::<Vec<_>>(),
        &records(base, None, 0..STEPS),
    );
    assert_eq!(code, 0, "{one_err}");
    let want = fleet_lines(&one_out);
    let got = fleet_lines(&a_out);
    assert_eq!(
        got, want,
        "partitions:\n{a_out}\n{a_err}\none process:\n{one_err}"
    );

    // Before the start the fleet spec it started with, from the first step at or after it the
    // new one, with its own slow-down.
    let metrics: Vec<&String> = want
        .iter()
        .filter(|l| l.starts_with("tessla_fleet,"))
        .collect();
    let v_old = version(metrics[0]).unwrap().to_string();
    assert_ne!(v_old, v_new);
    for l in &metrics {
        let ts: i64 = l.rsplit(' ').next().unwrap().parse().unwrap();
        let want_v = if ts >= from { &v_new } else { &v_old };
        assert_eq!(version(l), Some(want_v.as_str()), "{l}");
    }
    assert!(metrics.iter().any(|l| version(l) == Some(v_new.as_str())));
    assert!(
        want.iter()
            .any(|l| l.starts_with("action,") && l.contains("speed_limit=0.02")),
        "the new version's slow-down: {want:#?}"
    );
    let switched = |out: &str| {
        out.lines()
            .find(|l| l.starts_with("tessla_fleet_status,") && l.contains("event=\"switched\""))
            .map(String::from)
    };
    let line = switched(&one_out).unwrap_or_else(|| panic!("{one_out}"));
    assert!(line.contains(&format!("version=\"{v_new}\"")) && line.contains("late=false"));
    assert_eq!(switched(&a_out), Some(line));
}

/// The step a process's fleet level switched at, from its log.
fn switch_step(err: &str) -> i64 {
    err.lines()
        .find_map(|l| {
            l.split_once("(fleet rollout 1) from its step at ")?
                .1
                .trim()
                .parse()
                .ok()
        })
        .unwrap_or_else(|| panic!("no switch in {err}"))
}

/// A decision the fleet level reads after it has stepped past the version's start: every
/// process (the holder, p0's standby, p1) switches at the same step, the first after the switch
/// entry, and says it was late; the standby that takes the fleet level over goes on with the
/// new version.
#[test]
fn a_late_fleet_rollout_switches_at_the_same_step_in_every_process_and_after_a_takeover() {
    let r = Rollout::new("fleet_rollout_late");
    let base = r.base;
    let TwoPartitions {
        p0: mut a,
        standby,
        p1: mut b,
    } = two_partitions(&|lease| r.spawn(lease), true);
    let mut a2 = standby.expect("p0's standby");
    for (c, p) in [(&mut a, 0), (&mut a2, 0), (&mut b, 1)] {
        c.write(&records(base, Some(p), 0..40));
    }
    let step_30 = base + 30 * 200_000_000;
    wait_fleet_line_from(&mut a, "a fleet line at step 30", step_30);
    // Its start (step 10) is behind the fleet level already.
    let from = base + 10 * 200_000_000;
    let (_, v_new) = r.publish_v2(from);
    for c in [&mut a, &mut a2, &mut b] {
        c.wait_err("the switch entry", 0, |l| {
            l.contains("switch entry for fleet rollout 1")
        });
    }
    for (c, p) in [(&mut a, 0), (&mut a2, 0), (&mut b, 1)] {
        c.write(&records(base, Some(p), 40..60));
    }
    for c in [&mut a, &mut a2, &mut b] {
        c.wait_err("the switch", 0, |l| {
            l.contains("(fleet rollout 1) from its step at")
        });
    }
    let steps: Vec<i64> = [&mut a, &mut a2, &mut b]
        .into_iter()
        .map(|c| {
            c.drain_err();
            switch_step(&c.err.concat())
        })
        .collect();
    assert!(steps[0] > from, "late: after its start ({steps:?})");
    assert_eq!(steps, [steps[0]; 3], "the same step in every process");
    let at = steps[0];
    a.wait_out("the switched line", |l| l.contains("event=\"switched\""));

    // The holder stops; p0's standby takes both leases over and goes on.
    let (a_out, a_err, _) = hand_over(a, "TERM", &mut a2, &mut b);
    let switched = a_out
        .lines()
        .find(|l| l.contains("event=\"switched\""))
        .unwrap_or_else(|| panic!("{a_out}\n{a_err}"));
    assert!(
        switched.contains("late=true") && switched.ends_with(&format!(" {at}")),
        "{switched}"
    );
    a2.write(&records(base, Some(0), 60..STEPS));
    b.write(&records(base, Some(1), 60..STEPS));
    let (b_out, b_err, code) = b.finish();
    assert_eq!(code, 0, "{b_err}");
    let (a2_out, a2_err, code) = a2.finish();
    assert_eq!(code, 0, "{a2_err}");
    let (holder_out, holder_err) = if a2_err.contains("fleet: holding the fleet level") {
        (a2_out, a2_err)
    } else {
        (b_out, b_err)
    };
    // Every fleet metric written from the switch on, by either holder, is the new version's.
    let all: Vec<String> = fleet_lines(&a_out)
        .into_iter()
        .chain(fleet_lines(&holder_out))
        .filter(|l| l.starts_with("tessla_fleet,"))
        .collect();
    let after: Vec<&String> = all
        .iter()
        .filter(|l| l.rsplit(' ').next().unwrap().parse::<i64>().unwrap() >= at)
        .collect();
    assert!(after.len() > 10, "{holder_out}\n{holder_err}");
    for l in &after {
        assert_eq!(version(l), Some(v_new.as_str()), "{l}");
    }
    for l in all.iter().filter(|l| !after.contains(l)) {
        assert_ne!(version(l), Some(v_new.as_str()), "{l}");
    }
}

/// A process that reads a switch entry but never the rollout's decision (here: it follows no
/// spec channel) holds the fleet entries after it: after a bounded wait it says so, a `W!` and
/// one `tessla_fleet_status` line `event="waiting"` naming the rollout, while the holder of the
/// fleet level, which read the decision, switches and goes on.
#[test]
fn a_process_holding_entries_behind_a_switch_entry_says_it_waits() {
    let r = Rollout::new("fleet_rollout_waiting");
    let base = r.base;
    // p1's process follows no spec channel.
    let mut lone = example_args();
    lone.extend([
        "--state".to_string(),
        format!("{}?lease=p1&ttl=1s", r.state),
        "--version-tag".to_string(),
        "spec_version".to_string(),
    ]);
    let TwoPartitions {
        p0: mut a,
        p1: mut b,
        ..
    } = two_partitions(
        &|lease| match lease {
            "p1" => LiveChild::spawn(&lone.iter().map(String::as_str).collect::<Vec<_>>()),
            _ => r.spawn(lease),
        },
        false,
    );
    a.write(&records(base, Some(0), 0..30));
    b.write(&records(base, Some(1), 0..30));
    a.wait_out("a fleet line", |l| l.starts_with("tessla_fleet,"));
    let from = base + 40 * 200_000_000;
    r.publish_v2(from);
    a.wait_err("the switch entry", 0, |l| {
        l.contains("switch entry for fleet rollout 1 (")
    });
    a.write(&records(base, Some(0), 30..60));
    b.write(&records(base, Some(1), 30..60));
    // The holder switches at step 40; p1's process holds every entry after the switch entry
    // and, after the bounded wait, says so.
    a.wait_out("the switched line", |l| l.contains("event=\"switched\""));
    let warn = b.wait_err("the waiting warning", 0, |l| {
        l.contains("has not read the rollout's decision")
    });
    assert!(
        warn.starts_with("W! ") && warn.contains("fleet rollout 1 "),
        "{warn}"
    );
    b.wait_out("the waiting line", |l| {
        l.starts_with("tessla_fleet_status,partition=p1")
            && l.contains("event=\"waiting\",revision=1i,")
    });
    let (b_out, b_err, code) = b.finish();
    assert_eq!(code, 0, "{b_err}");
    let (a_out, a_err, code) = a.finish();
    assert_eq!(code, 0, "{a_err}");
    // Said once; the holder never waited.
    assert_eq!(b_out.matches("event=\"waiting\"").count(), 1, "{b_out}");
    assert!(!a_out.contains("event=\"waiting\""), "{a_out}");
}
