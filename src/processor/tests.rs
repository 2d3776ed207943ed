//! The processor's unit tests: records through a whole processor (their way, the time policy,
//! wall-clock firings, instances, versions), and the helpers other modules' tests share
//! ([`program`]).

use super::*;
use crate::processor::versions::Selector;
use lineproto::{RecordSplitter, parse_record};
use std::time::Instant;
use tessla_syntax::include::MemResolver;

/// `c` counts `x`; `k` is a constant event at TeSSLa time 0.
const SPEC: &str = "in x: Events[Int]\n\
                    def c = count(x)\n\
                    def k: Events[Int] = const(7, ())\n\
                    out c\nout k\nout x\n";

fn processor(opts: Options) -> Processor {
    let resolver = MemResolver {
        files: [("t.tessla".to_string(), SPEC.to_string())].into(),
    };
    let loaded = tessla_engine::load_with("t.tessla", &resolver, &Default::default()).unwrap();
    Processor::new(loaded.program, opts).unwrap()
}

/// Feed `input` as one read (flushing at its end, as a transport does) and return the output.
fn feed(p: &mut Processor, input: &str) -> String {
    let mut s = RecordSplitter::default();
    s.push(input.as_bytes());
    let mut out = Vec::new();
    while let Some(r) = s.next_record() {
        p.record(&r, &mut out);
    }
    while let Some(r) = s.finish() {
        p.record(&r, &mut out);
    }
    p.end_of_read();
    String::from_utf8(out).unwrap()
}

#[test]
fn an_unbalanced_quote_costs_only_its_own_line() {
    let mut p = processor(Options::default());
    let out = feed(&mut p, "m x=1 100\nm s=\"open 150\nm x=2 200\nm x=3 300\n");
    assert!(out.contains("m x=2 200\ntessla c=2i,x=2i 200\n"), "{out}");
    assert!(out.contains("m x=3 300\ntessla c=3i,x=3i 300\n"), "{out}");
    assert!(!out.contains("open"), "{out}");
    assert_eq!(p.counters.records, 4);
    assert_eq!(p.counters.parse_errors, 1);
    // A string field that really spans lines stays one record.
    let out = feed(&mut p, "m x=4,s=\"two\nlines\" 400\n");
    assert_eq!(out, "m x=4,s=\"two\nlines\" 400\ntessla c=4i,x=4i 400\n");
}

#[test]
fn time_zero_events_carry_the_first_records_timestamp() {
    let mut p = processor(Options {
        passthrough: false,
        ..Options::default()
    });
    let out = feed(&mut p, "m x=5 1700000000000000000\n");
    assert_eq!(out, "tessla c=1i,k=7i,x=5i 1700000000000000000\n");
}

/// Every record is a step of its own, answered right after its pass-through; a record with
/// the timestamp of its instance's last step is stepped 1 ns after it (not late).
#[test]
fn records_with_one_timestamp_are_stepped_each_apart() {
    let mut p = processor(Options::default());
    let out = feed(&mut p, "m x=5 100\nm y=1 100\nm x=6 200\n");
    assert_eq!(
        out,
        "m x=5 100\ntessla c=1i,k=7i,x=5i 100\nm y=1 100\nm x=6 200\ntessla c=2i,x=6i 200\n"
    );
    assert_eq!(p.counters.records, 3);
    assert_eq!(p.counters.events, 2);
    assert_eq!(p.counters.late, 0);
    // Two values of one input at one timestamp: both evaluated, the second 1 ns later.
    let mut p = processor(Options {
        passthrough: false,
        ..Options::default()
    });
    assert_eq!(
        feed(&mut p, "m x=1 100\nm x=2 100\n"),
        "tessla c=1i,k=7i,x=1i 100\ntessla c=2i,x=2i 101\n"
    );
    assert_eq!(p.counters.dropped_values, 0);
    assert_eq!(p.counters.late, 0);
}

#[test]
fn late_records_shift_or_drop() {
    let mut p = processor(Options {
        passthrough: false,
        ..Options::default()
    });
    feed(&mut p, "m x=1 100\n");
    assert_eq!(feed(&mut p, "m x=2 50\n"), "tessla c=2i,x=2i 101\n");
    assert_eq!(p.counters.late, 1);
    // In one read: the late record is a step of its own after the last, never merged.
    let mut p = processor(Options {
        passthrough: false,
        ..Options::default()
    });
    assert_eq!(
        feed(&mut p, "m x=1 100\nm x=2 200\nm x=3 150\n"),
        "tessla c=1i,k=7i,x=1i 100\ntessla c=2i,x=2i 200\ntessla c=3i,x=3i 201\n"
    );
    let mut p = processor(Options {
        passthrough: false,
        late: LateMode::Drop,
        ..Options::default()
    });
    feed(&mut p, "m x=1 100\n");
    assert_eq!(feed(&mut p, "m x=2 50\n"), "");
    assert_eq!(feed(&mut p, "m x=3 300\n"), "tessla c=2i,x=3i 300\n");
    assert_eq!(p.counters.late, 1);
}

#[test]
fn a_record_without_timestamp_gets_the_wall_clock() {
    let mut p = processor(Options {
        passthrough: false,
        ..Options::default()
    });
    let before = clock::unix_ns();
    p.set_wall(Wall::now());
    let out = feed(&mut p, "m x=1\n");
    let after = clock::unix_ns();
    let m = parse_record(out.as_bytes()).unwrap().unwrap();
    let ts = m.timestamp.unwrap();
    assert!(before <= ts && ts <= after, "{before} <= {ts} <= {after}");
}

/// A record stamped beyond --max-ahead is echoed, not evaluated, and cannot move the clock.
#[test]
fn a_record_far_ahead_of_the_wall_clock_is_refused() {
    let mut p = processor(Options::default());
    let now = clock::unix_ns();
    let out = feed(&mut p, &format!("m x=1 {now}\nm x=2 9223372036854775807\n"));
    assert!(out.contains("m x=2 9223372036854775807\n"), "{out}");
    assert!(!out.contains("x=2i"), "{out}");
    assert_eq!(p.counters.ahead, 1);
    let later = now + 1_000;
    let out = feed(&mut p, &format!("m x=3 {later}\n"));
    assert!(
        out.ends_with(&format!("tessla c=2i,x=3i {later}\n")),
        "{out}"
    );
    assert_eq!(p.counters.late, 0);
    assert!(
        p.summary().contains(", 1 ahead of the clock,"),
        "{}",
        p.summary()
    );
    // Off: simulated data far in the future is evaluated.
    let mut p = processor(Options {
        passthrough: false,
        max_ahead: None,
        ..Options::default()
    });
    let out = feed(&mut p, "m x=2 9000000000000000000\n");
    assert_eq!(out, "tessla c=1i,k=7i,x=2i 9000000000000000000\n");
}

/// A watchdog fires by the wall clock while the input is silent: at the instance's last
/// record plus the delay, once the allowed lateness has passed; its output carries its TeSSLa
/// time. Only the instance whose deadline is due is touched.
#[test]
fn delays_fire_by_the_wall_clock_while_the_input_is_silent() {
    let spec = "in x: Events[Int]\n\
                def quiet = delay(const(1000, x), x)\n\
                out quiet\nout x\n";
    let resolver = MemResolver {
        files: [("w.tessla".to_string(), spec.to_string())].into(),
    };
    let loaded = tessla_engine::load_with("w.tessla", &resolver, &Default::default()).unwrap();
    let lateness = Duration::from_micros(100);
    let mut p = Processor::new(
        loaded.program,
        Options {
            passthrough: false,
            instance_by: vec!["robot".into()],
            allowed_lateness: Some(lateness),
            ..Options::default()
        },
    )
    .unwrap();
    let t0 = Instant::now();
    p.set_wall(Wall { at: t0, ns: 0 });
    let out = feed(&mut p, "m,robot=a x=1i 5000\nm,robot=b x=1i 5000\n");
    assert_eq!(out.lines().count(), 2);
    // Due 1000 ns + lateness after the records arrived.
    assert_eq!(
        p.next_deadline(),
        Some(t0 + Duration::from_nanos(1000) + lateness)
    );
    // Robot b speaks again half-way; only a falls silent.
    p.set_wall(Wall {
        at: t0 + Duration::from_nanos(500),
        ns: 0,
    });
    feed(&mut p, "m,robot=b x=2i 5500\n");
    let mut out = Vec::new();
    p.advance_wall(t0 + Duration::from_nanos(900), &mut out);
    assert!(out.is_empty());
    p.advance_wall(t0 + Duration::from_nanos(1000) + lateness, &mut out);
    assert_eq!(
        String::from_utf8(out).unwrap(),
        "tessla,robot=a quiet=true 6000\n"
    );
    let mut out = Vec::new();
    p.advance_wall(t0 + Duration::from_nanos(1500) + lateness, &mut out);
    assert_eq!(
        String::from_utf8(out).unwrap(),
        "tessla,robot=b quiet=true 6500\n"
    );
    assert_eq!(p.next_deadline(), None);
    // A record after the firing but stamped before it is late: a step of its own after it.
    p.set_wall(Wall {
        at: t0 + Duration::from_millis(1),
        ns: 0,
    });
    let out = feed(&mut p, "m,robot=a x=3i 5900\n");
    assert_eq!(out, "tessla,robot=a x=3i 6001\n");
    assert_eq!(p.counters.late, 1);
}

#[test]
fn instances_keep_separate_state_and_tag_their_outputs() {
    let mut p = processor(Options {
        passthrough: false,
        instance_by: vec!["robot".into()],
        tags: vec![("site".into(), "lab".into())],
        ..Options::default()
    });
    let out = feed(
        &mut p,
        "m,robot=a x=1 100\nm,robot=b x=1 100\nm,robot=a x=1 200\nm x=9 300\n",
    );
    let mut lines: Vec<&str> = out.lines().collect();
    lines.sort();
    assert_eq!(
        lines,
        [
            "tessla,robot=a,site=lab c=1i,k=7i,x=1i 100",
            "tessla,robot=a,site=lab c=2i,x=1i 200",
            "tessla,robot=b,site=lab c=1i,k=7i,x=1i 100",
            // A metric without the tag is an instance of its own, without the tag.
            "tessla,site=lab c=1i,k=7i,x=9i 300",
        ]
    );
    assert_eq!(p.instance_count(), 3);
    assert!(p.summary().ends_with("3 instances, 0 evicted"));
}

/// A program compiled from `spec` (the processor's tests and its neighbours' use it).
pub(crate) fn program(spec: &str) -> Arc<Program> {
    let resolver = MemResolver {
        files: [("v.tessla".to_string(), spec.to_string())].into(),
    };
    tessla_engine::load_with("v.tessla", &resolver, &Default::default())
        .unwrap()
        .program
}

const OLD: &str = "in x: Events[Int]\ndef c = count(x)\ndef s = x + 1\nout c\nout s\n";
const NEW: &str = "in x: Events[Int]\ndef c = count(x)\ndef s = x * 10\nout c\nout s\n";

fn versioned() -> Processor {
    let mut p = Processor::new(
        program(OLD),
        Options {
            passthrough: false,
            instance_by: vec!["robot".into()],
            version_tag: Some("spec_version".into()),
            ..Options::default()
        },
    )
    .unwrap();
    p.name_base("old", "");
    p
}

/// A rollout for robot a from time 300: a's records before 300 are judged by the old
/// version, from 300 by the new one, with `c` (unchanged) continuing; b stays on the old.
#[test]
fn a_rollout_switches_its_instances_at_their_first_step_from_its_start() {
    let mut p = versioned();
    let sel = Selector::parse("robot=a").unwrap();
    p.check_version("new", &program(NEW), &sel, p.samples())
        .unwrap();
    let acc = p
        .accept_version("new", "ten", program(NEW), 300, sel)
        .unwrap();
    assert_eq!(acc.reset_outputs, ["s"]);
    let out = feed(
        &mut p,
        "m,robot=a x=1i 100\nm,robot=b x=1i 100\nm,robot=a x=2i 299\nm,robot=a x=3i 300\nm,robot=b x=3i 300\nm,robot=a x=4i 400\n",
    );
    assert_eq!(
        out,
        "tessla,robot=a,spec_version=old c=1i,s=2i 100\n\
         tessla,robot=b,spec_version=old c=1i,s=2i 100\n\
         tessla,robot=a,spec_version=old c=2i,s=3i 299\n\
         tessla,robot=a,spec_version=new c=3i,s=30i 300\n\
         tessla,robot=b,spec_version=old c=2i,s=4i 300\n\
         tessla,robot=a,spec_version=new c=4i,s=40i 400\n"
    );
    assert_eq!(p.counters.switched, 1);
    // A robot first seen after the start begins in the new version, one that does not
    // match never.
    let out = feed(&mut p, "m,robot=c x=1i 500\n");
    assert_eq!(out, "tessla,robot=c,spec_version=old c=1i,s=2i 500\n");
    // A late record behind the start, after the switch: its instance's clock has passed
    // the start, so it is a step after its last one, in the version in force there.
    let out = feed(&mut p, "m,robot=a x=5i 250\n");
    assert_eq!(out, "tessla,robot=a,spec_version=new c=5i,s=50i 401\n");
}

/// A rollout back to the old version later: the instance switches back at its start.
/// Rules are kept in publish order; the newest that applies wins.
#[test]
fn a_later_rollout_wins_and_a_rollback_switches_back() {
    let mut p = versioned();
    p.accept_version("new", "", program(NEW), 200, Selector::all())
        .unwrap();
    p.accept_version("old", "rollback", program(OLD), 400, Selector::all())
        .unwrap();
    let out = feed(
        &mut p,
        "m,robot=a x=1i 100\nm,robot=a x=1i 250\nm,robot=a x=1i 450\n",
    );
    assert_eq!(
        out,
        "tessla,robot=a,spec_version=old c=1i,s=2i 100\n\
         tessla,robot=a,spec_version=new c=2i,s=10i 250\n\
         tessla,robot=a,spec_version=old c=3i,s=2i 450\n"
    );
    // Both starts passed in one step: ends in the newest.
    let out = feed(&mut p, "m,robot=b x=1i 100\nm,robot=b x=1i 500\n");
    assert!(
        out.ends_with("tessla,robot=b,spec_version=old c=2i,s=2i 500\n"),
        "{out}"
    );
    assert_eq!(p.versions().list.len(), 2);
}

/// Checks before a version counts: a selector naming a tag that chooses no instance, and
/// bindings that cannot read the metrics seen.
#[test]
fn a_version_that_does_not_fit_is_refused() {
    let mut p = versioned();
    let e = p
        .check_version(
            "new",
            &program(NEW),
            &Selector::parse("site=lab").unwrap(),
            &[],
        )
        .unwrap_err();
    assert!(matches!(e, super::Refusal::UnknownTags { .. }), "{e}");
    assert_eq!(
        e.to_string(),
        "its selector `site=lab` names tag(s) site that do not choose instances here (--instance-by robot)"
    );
    feed(&mut p, "m,robot=a x=1i 100\n");
    let strings = "in x: Events[Bool]\nout x\n";
    let e = p
        .check_version("b", &program(strings), &Selector::all(), p.samples())
        .unwrap_err();
    assert!(e.to_string().contains("input `x`"), "{e}");
    let other = "in y: Events[Int]\nout y\n";
    let e = p
        .check_version("o", &program(other), &Selector::all(), p.samples())
        .unwrap_err();
    assert!(
        matches!(
            e,
            super::Refusal::Unfit(super::versions::Unfit::Unfed { .. })
        ),
        "{e}"
    );
    assert!(e.to_string().contains("none of its inputs"), "{e}");
    p.check_version("new", &program(NEW), &Selector::all(), p.samples())
        .unwrap();
}

/// A rollout starting behind instances' clocks: they are counted (the status says how many
/// switched late), and each switches at its next step.
#[test]
fn instances_already_past_a_start_are_counted_and_switch_next() {
    let mut p = versioned();
    feed(&mut p, "m,robot=a x=1i 100\nm,robot=b x=1i 500\n");
    let sel = Selector::parse("robot=a,b").unwrap();
    assert_eq!(p.instances_past(300, &sel), (1, 200));
    assert_eq!(p.instances_past(600, &sel), (0, 0));
    p.accept_version("new", "", program(NEW), 300, sel).unwrap();
    let out = feed(&mut p, "m,robot=b x=2i 600\n");
    assert_eq!(out, "tessla,robot=b,spec_version=new c=2i,s=20i 600\n");
}

const AB: &str = "in x: Events[Int]\ndef a = x * 2\ndef b = x + 100\nout a\nout b\n";
const CD: &str = "in x: Events[Int]\ndef c = x * 3\ndef d = x + 1000\nout c\nout d\n";

fn renamed() -> Processor {
    let mut p = Processor::new(
        program(AB),
        Options {
            passthrough: false,
            instance_by: vec!["robot".into()],
            ..Options::default()
        },
    )
    .unwrap();
    p.name_base("v1", "");
    p
}

/// A canary whose outputs have other names than the base's (as many of them): each
/// instance's lines carry its own version's field names, whichever instance wrote last.
#[test]
fn a_canary_with_renamed_outputs_writes_its_own_field_names() {
    let mut p = renamed();
    p.accept_version(
        "v2",
        "",
        program(CD),
        300,
        Selector::parse("robot=r1").unwrap(),
    )
    .unwrap();
    let out = feed(
        &mut p,
        "m,robot=r1 x=5i 100\nm,robot=r2 x=5i 100\nm,robot=r1 x=5i 300\nm,robot=r2 x=5i 300\nm,robot=r1 x=6i 400\nm,robot=r2 x=6i 400\nm,robot=r1 x=7i 500\n",
    );
    assert_eq!(
        out,
        "tessla,robot=r1 a=10i,b=105i 100\n\
         tessla,robot=r2 a=10i,b=105i 100\n\
         tessla,robot=r1 c=15i,d=1005i 300\n\
         tessla,robot=r2 a=10i,b=105i 300\n\
         tessla,robot=r1 c=18i,d=1006i 400\n\
         tessla,robot=r2 a=12i,b=106i 400\n\
         tessla,robot=r1 c=21i,d=1007i 500\n"
    );
    // Without a rollout, the same bytes as ever.
    let mut q = renamed();
    let out = feed(&mut q, "m,robot=r1 x=5i 100\nm,robot=r2 x=6i 100\n");
    assert_eq!(
        out,
        "tessla,robot=r1 a=10i,b=105i 100\ntessla,robot=r2 a=12i,b=106i 100\n"
    );
}

/// One instance switching to a version with renamed outputs, back, and to it again: each
/// line carries the names of the version that computed it.
#[test]
fn an_instance_switching_back_and_forth_writes_each_versions_names() {
    let mut p = renamed();
    let r1 = || Selector::parse("robot=r1").unwrap();
    p.accept_version("v2", "", program(CD), 200, r1()).unwrap();
    p.accept_version("v1", "", program(AB), 300, r1()).unwrap();
    p.accept_version("v2", "", program(CD), 400, r1()).unwrap();
    let out = feed(
        &mut p,
        "m,robot=r1 x=1i 100\nm,robot=r1 x=1i 200\nm,robot=r1 x=1i 300\nm,robot=r1 x=1i 400\n",
    );
    assert_eq!(
        out,
        "tessla,robot=r1 a=2i,b=101i 100\n\
         tessla,robot=r1 c=3i,d=1001i 200\n\
         tessla,robot=r1 a=2i,b=101i 300\n\
         tessla,robot=r1 c=3i,d=1001i 400\n"
    );
    assert_eq!(p.counters.switched, 3);
}

/// `reset_outputs` names what changes between the version each picked robot runs before the
/// start and the new one: r1 ran v2 (from 100), which v3 changes in `t` only, although v3
/// differs from the base in `s` too; a selector also picking r2 (on the base) adds `s`.
#[test]
fn reset_outputs_name_only_what_changes_from_the_version_the_robot_ran() {
    const V1: &str = "in x: Events[Int]\ndef s = x + 1\ndef t = x + 2\nout s\nout t\n";
    const V2: &str = "in x: Events[Int]\ndef s = x * 10\ndef t = x + 2\nout s\nout t\n";
    const V3: &str = "in x: Events[Int]\ndef s = x * 10\ndef t = x * 20\nout s\nout t\n";
    let base = || {
        let mut p = Processor::new(
            program(V1),
            Options {
                passthrough: false,
                instance_by: vec!["robot".into()],
                ..Options::default()
            },
        )
        .unwrap();
        let r1 = Selector::parse("robot=r1").unwrap();
        let acc = p.accept_version("v2", "", program(V2), 100, r1).unwrap();
        assert_eq!(acc.reset_outputs, ["s"]);
        p
    };
    let mut p = base();
    let r1 = Selector::parse("robot=r1").unwrap();
    let acc = p.accept_version("v3", "", program(V3), 200, r1).unwrap();
    assert_eq!(acc.reset_outputs, ["t"]);
    let mut p = base();
    let both = Selector::parse("robot=r1,r2").unwrap();
    let acc = p.accept_version("v3", "", program(V3), 200, both).unwrap();
    assert_eq!(acc.reset_outputs, ["s", "t"]);
    // Every robot but r1 runs the base at 199: all of them start `s` and `t` afresh.
    let mut p = base();
    let acc = p
        .accept_version("v3", "", program(V3), 200, Selector::all())
        .unwrap();
    assert_eq!(acc.reset_outputs, ["s", "t"]);
    // A rule starting after the new one does not count; one for r1 back to the base does.
    let mut p = base();
    let r1 = || Selector::parse("robot=r1").unwrap();
    p.accept_version("v3", "", program(V3), 300, r1()).unwrap();
    let acc = p.accept_version("v2", "", program(V2), 250, r1()).unwrap();
    assert_eq!(acc.reset_outputs, Vec::<String>::new());
}

const COUNT: &str = "in x: Events[Int]\ndef n = count(x)\nout n\n";

fn idle_processor(spec: &str, idle: Duration) -> Processor {
    Processor::new(
        program(spec),
        Options {
            passthrough: false,
            instance_by: vec!["robot".into()],
            instance_idle: Some(idle),
            max_ahead: None,
            ..Options::default()
        },
    )
    .unwrap()
}

/// Output lines sorted (instances on different processors interleave otherwise).
fn sorted(out: &str) -> Vec<String> {
    let mut v: Vec<String> = out.lines().map(String::from).collect();
    v.sort();
    v
}

/// Whether an instance is evicted for idleness depends on its own silence only: robots r5
/// and r2 each silent 2.5 s past a 1 s limit both start afresh, on one processor (one
/// thread) as on two (two threads, one robot each).
#[test]
fn an_idle_instance_is_evicted_by_its_own_silence_alone() {
    let t0 = Instant::now();
    let first = "m,robot=r5 x=1i 1000\nm,robot=r2 x=1i 1000\n";
    let second = "m,robot=r5 x=1i 2000\nm,robot=r2 x=1i 2000\n";
    let run = |procs: &mut [Processor], text: &str, at: Instant| {
        let mut out = String::new();
        for line in text.lines() {
            let i = if procs.len() > 1 && line.contains("r2") {
                1
            } else {
                0
            };
            procs[i].set_wall(Wall { at, ns: 0 });
            out.push_str(&feed(&mut procs[i], &format!("{line}\n")));
        }
        out
    };
    let idle = Duration::from_secs(1);
    let mut one = [idle_processor(COUNT, idle)];
    let mut two = [idle_processor(COUNT, idle), idle_processor(COUNT, idle)];
    let later = t0 + Duration::from_millis(2500);
    let mut a = run(&mut one, first, t0);
    a.push_str(&run(&mut one, second, later));
    let mut b = run(&mut two, first, t0);
    b.push_str(&run(&mut two, second, later));
    assert_eq!(
        sorted(&a),
        [
            "tessla,robot=r2 n=1i 1000",
            "tessla,robot=r2 n=1i 2000",
            "tessla,robot=r5 n=1i 1000",
            "tessla,robot=r5 n=1i 2000",
        ]
    );
    assert_eq!(sorted(&a), sorted(&b));
    assert_eq!(one[0].counters.evicted, 2);
    assert_eq!(two[0].counters.evicted + two[1].counters.evicted, 2);
    // Within the limit, both keep their count.
    let mut p = idle_processor(COUNT, idle);
    p.set_wall(Wall { at: t0, ns: 0 });
    feed(&mut p, first);
    p.set_wall(Wall {
        at: t0 + Duration::from_millis(900),
        ns: 0,
    });
    assert_eq!(
        feed(&mut p, second),
        "tessla,robot=r5 n=2i 2000\ntessla,robot=r2 n=2i 2000\n"
    );
    assert_eq!(p.counters.evicted, 0);
}

/// A silent instance idle past the limit before its watchdog falls due is evicted, its
/// `delay` never fires; the wall clock wakes the loop for the eviction itself.
#[test]
fn a_watchdog_due_after_the_idle_limit_does_not_fire() {
    let spec = "in x: Events[Int]\n\
                def silent = delay(const(2000000000, x), x)\n\
                out silent\n";
    let t0 = Instant::now();
    let mut p = idle_processor(spec, Duration::from_secs(1));
    p.set_wall(Wall { at: t0, ns: 0 });
    feed(&mut p, "m,robot=r1 x=1i 1000000000\n");
    // Evicting it is due at the idle limit, before the watchdog.
    let next = p.next_deadline().unwrap();
    assert!(next <= t0 + Duration::from_millis(1001), "{next:?}");
    let mut out = Vec::new();
    p.advance_wall(t0 + Duration::from_millis(2260), &mut out);
    assert_eq!(String::from_utf8(out).unwrap(), "");
    assert_eq!(p.counters.evicted, 1);
    assert_eq!(p.instance_count(), 0);
    assert_eq!(p.next_deadline(), None);
    // With a longer limit, it fires.
    let mut p = idle_processor(spec, Duration::from_secs(5));
    p.set_wall(Wall { at: t0, ns: 0 });
    feed(&mut p, "m,robot=r1 x=1i 1000000000\n");
    let mut out = Vec::new();
    p.advance_wall(t0 + Duration::from_millis(2260), &mut out);
    assert_eq!(
        String::from_utf8(out).unwrap(),
        "tessla,robot=r1 silent=true 3000000000\n"
    );
    assert_eq!(p.counters.evicted, 0);
}

/// A spec over a list pattern and an exact field: the list's length, some elements and a
/// fold over all of them, so any element read differently changes an output.
const LIST_SPEC: &str = "@TelegrafIn(\"m\", \"\", \"lidar_*\")\n\
    in l: Events[List[Float]]\n\
    @TelegrafIn(\"m\", \"\", \"x\")\n\
    in x: Events[Float]\n\
    def n = List.size(l)\n\
    def a = List.get(l, 0)\n\
    def b = List.get(l, 3)\n\
    def s = List.fold(l, 0.0, (acc: Float, v: Float) => if v == v then acc +. v else acc +. 1000.0)\n\
    out n\nout a\nout b\nout s\nout x\n";

/// Records with lists as Telegraf writes them and everything unusual a list's fields can
/// be: missing, repeated and non-Float elements, other index forms, keys of the prefix that
/// are no index, escapes, redelivered and late records.
fn list_records(n: usize) -> String {
    let mut rng = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(0x9e37_79b9);
    let mut next = move |m: u64| rand::RngCore::next_u64(&mut rng) % m;
    let mut text = String::new();
    let mut last = String::new();
    for r in 0..n {
        if r > 0 && next(40) == 0 {
            // A redelivered message (another field order would do: the digest is the same).
            text.push_str(&last);
            continue;
        }
        let beams = 4 + next(6) as usize;
        let mut fields: Vec<String> = Vec::new();
        for i in 0..beams {
            if next(15) == 0 {
                continue;
            }
            let v = match next(12) {
                0 => "0".to_string(),
                1 => "2.4749999046325684".to_string(),
                2 => format!("{}i", next(5)),
                3 if next(4) == 0 => "\"x\"".to_string(),
                4 => "1e3".to_string(),
                5 => "-0.5".to_string(),
                _ => format!("{}.{}", next(4), next(1000)),
            };
            fields.push(format!("lidar_{i}={v}"));
        }
        match next(30) {
            0 => fields.push("lidar_2=7.5".into()),
            1 => fields.push("lidar_02=7.5".into()),
            2 => fields.push("lidar_+1=7.5".into()),
            3 => fields.push("lidar_count=5i".into()),
            4 => fields.push("lidar_=1".into()),
            5 => fields.push("lidar_99999=1".into()),
            6 => fields.push("lidar\\ 1=2".into()),
            7 => fields.push("lidar_1x=2".into()),
            _ => {}
        }
        fields.push(format!("x={}", next(100)));
        for i in (1..fields.len()).rev() {
            fields.swap(i, next(i as u64 + 1) as usize);
        }
        let ts = if next(50) == 0 {
            r * 1000 - 1500
        } else {
            r * 1000 + 1000
        };
        last = format!("m,robot=r{} {} {ts}\n", next(2), fields.join(","));
        text.push_str(&last);
    }
    text
}

/// Reading a list's elements apart (after the wiring window) changes no output and no
/// counter: the same records through a processor that never captures give the same bytes.
#[test]
fn a_list_read_apart_gives_what_the_fields_give() {
    let resolver = MemResolver {
        files: [("t.tessla".to_string(), LIST_SPEC.to_string())].into(),
    };
    let loaded = tessla_engine::load_with("t.tessla", &resolver, &Default::default()).unwrap();
    let opts = || Options {
        instance_by: vec!["robot".into()],
        ..Options::default()
    };
    let mut fast = Processor::new(loaded.program.clone(), opts()).unwrap();
    let mut plain = Processor::new(loaded.program, opts()).unwrap();
    assert_eq!(fast.capture.as_deref(), Some("lidar_"));
    plain.capture = None;
    let input = list_records(3000);
    let (mut a, mut b) = (String::new(), String::new());
    for chunk in input.split_inclusive('\n').collect::<Vec<_>>().chunks(100) {
        a.push_str(&feed(&mut fast, &chunk.concat()));
        b.push_str(&feed(&mut plain, &chunk.concat()));
    }
    assert!(
        fast.wiring.is_done(),
        "the window ended: records were captured"
    );
    assert_eq!(a, b);
    assert_eq!(
        format!("{:?}", fast.counters),
        format!("{:?}", plain.counters)
    );
    assert!(fast.counters.duplicates > 10, "{:?}", fast.counters);
    assert!(fast.counters.late > 10, "{:?}", fast.counters);
    assert!(fast.counters.dropped_values > 10, "{:?}", fast.counters);
}
