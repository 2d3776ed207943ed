//! The specs of the speed yardsticks (BENCHMARKS.md) say what their references say, on the
//! references' own traces, read from `../shared/corpora` (public data kept beside the project,
//! never copied into it; see its README):
//! - `bench/auction.tessla`, the CRV 2016 "Auction" property, against the meaning of
//!   PRECISE/SMEDL's `auctionmonitor.smedl` (the state machine below, written from it) on the
//!   three traces its README describes (invalid1: sold below the reserve price; invalid2: sold
//!   after the auction ended; invalid3: sold twice);
//! - VAMOS `primes.tessla` against the output of the monitor TeSSLa's compiler generated for it.
//!
//! Without the corpora the tests skip with a note (tools/test-skips.sh prints it).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

fn corpora() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/corpora");
    if dir.is_dir() {
        return Some(dir);
    }
    let why = "the yardstick corpora are not at ../shared/corpora";
    eprintln!("yardsticks: SKIPPED: {why}");
    let notes = Path::new(env!("CARGO_TARGET_TMPDIR")).join("skipped-suites");
    let _ = std::fs::create_dir_all(&notes);
    let _ = std::fs::write(notes.join("yardsticks"), format!("{why}\n"));
    None
}

fn load(spec: &Path) -> Arc<tessla_engine::Program> {
    match tessla_engine::load_file(spec, &Default::default()) {
        Ok(l) => l.program,
        Err(e) => panic!("{}", e.render()),
    }
}

/// One event of an Auction trace (a CSV line).
enum Ev {
    Create(String, i64, i64),
    Bid(String, i64),
    Sold(String),
    EndOfDay,
}

fn events(csv: &str) -> Vec<Ev> {
    csv.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.trim().split(',').collect();
            let int = |i: usize| f[i].parse::<i64>().unwrap();
            match f[0] {
                "create_auction" => Ev::Create(f[1].into(), int(2), int(3)),
                "bid" => Ev::Bid(f[1].into(), int(2)),
                "sold" => Ev::Sold(f[1].into()),
                "endOfDay" => Ev::EndOfDay,
                other => panic!("unknown event {other}"),
            }
        })
        .collect()
}

/// The trace in TeSSLa's format, event n at time n (as bench/auction_trace.py writes it).
fn tessla_trace(evs: &[Ev]) -> String {
    let mut out = String::new();
    for (n, e) in evs.iter().enumerate() {
        let n = n + 1;
        out.push_str(&match e {
            Ev::Create(i, r, d) => format!("{n}: create_auction = (\"{i}\", {r}, {d})\n"),
            Ev::Bid(i, a) => format!("{n}: bid = (\"{i}\", {a})\n"),
            Ev::Sold(i) => format!("{n}: sold = \"{i}\"\n"),
            Ev::EndOfDay => format!("{n}: endOfDay\n"),
        });
    }
    out
}

#[derive(Clone, Copy, PartialEq)]
enum Phase {
    Bidding,
    AboveReserve,
    Done,
    Error,
}

struct Item {
    phase: Phase,
    reserve: i64,
    price: i64,
    duration: i64,
    days_passed: i64,
}

/// auctionmonitor.smedl, one instance per item, the days counted down at each end of day as
/// SMEDL does (the spec counts them lazily): the alarms as `TS: alarm = KIND ITEM` lines.
fn smedl(evs: &[Ev]) -> String {
    let mut items: HashMap<&str, Item> = HashMap::new();
    let mut out = String::new();
    let mut alarm = |n: usize, kind: &str, item: &str| {
        out.push_str(&format!("{n}: alarm = {kind} {item}\n"));
    };
    for (n, e) in evs.iter().enumerate() {
        let n = n + 1;
        match e {
            Ev::EndOfDay => {
                for it in items.values_mut() {
                    if matches!(it.phase, Phase::Bidding | Phase::AboveReserve) {
                        if it.days_passed < it.duration - 1 {
                            it.days_passed += 1;
                        } else {
                            it.phase = Phase::Done;
                        }
                    }
                }
            }
            Ev::Create(i, r, d) => match items.get_mut(i.as_str()) {
                None => {
                    items.insert(
                        i,
                        Item {
                            phase: Phase::Bidding,
                            reserve: *r,
                            price: 0,
                            duration: *d,
                            days_passed: 0,
                        },
                    );
                }
                Some(it) if it.phase != Phase::Error => {
                    alarm(n, "recreation", i);
                    it.phase = Phase::Error;
                }
                Some(_) => {}
            },
            Ev::Bid(i, a) => {
                let Some(it) = items.get_mut(i.as_str()) else {
                    continue;
                };
                match it.phase {
                    Phase::Bidding => {
                        it.price = *a;
                        it.phase = Phase::AboveReserve;
                    }
                    Phase::AboveReserve if *a > it.price => it.price = *a,
                    Phase::Done => {
                        alarm(n, "action_after_end", i);
                        it.phase = Phase::Error;
                    }
                    _ => {}
                }
            }
            Ev::Sold(i) => {
                let Some(it) = items.get_mut(i.as_str()) else {
                    continue;
                };
                match it.phase {
                    Phase::Bidding => {
                        alarm(n, "sold_early", i);
                        it.phase = Phase::Error;
                    }
                    Phase::AboveReserve if it.price < it.reserve => {
                        alarm(n, "low_bid", i);
                        it.phase = Phase::Error;
                    }
                    Phase::AboveReserve => it.phase = Phase::Done,
                    Phase::Done => {
                        alarm(n, "action_after_end", i);
                        it.phase = Phase::Error;
                    }
                    Phase::Error => {}
                }
            }
        }
    }
    out
}

#[test]
fn auction_spec_raises_the_smedl_monitors_alarms() {
    let Some(corpora) = corpora() else { return };
    let dir = corpora.join("perf-anchors/PRECISE-SMEDL/b0096d1/tests/monitors/auction");
    let program = load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../bench/auction.tessla"));
    for (trace, expected) in [
        (
            "auction_trace_invalid1",
            "84683: alarm = low_bid item3790287\n",
        ),
        (
            "auction_trace_invalid2",
            "70417: alarm = action_after_end item3790287\n",
        ),
        (
            "auction_trace_invalid3",
            "84684: alarm = action_after_end item3790287\n",
        ),
    ] {
        let evs = events(&std::fs::read_to_string(dir.join(trace)).unwrap());
        assert_eq!(evs.len(), if trace.ends_with('3') { 84781 } else { 84780 });
        let reference = smedl(&evs);
        // The README's ground truth, as the state machine finds it.
        assert_eq!(reference, expected, "{trace}: the SMEDL state machine");
        let run = tessla_trace::run(&program, &tessla_trace(&evs));
        assert_eq!(run.error, None, "{trace}");
        assert_eq!(run.output, reference, "{trace}");
    }
    // Every kind of alarm, on a trace made for them: a bid after the days ran out, a sale with
    // no bid, a re-creation, a sale below the reserve, an item in error ignoring the rest, and
    // a bid that does not raise the price.
    let evs = events(
        "create_auction,a,10,1\ncreate_auction,b,10,2\ncreate_auction,c,5,3\n\
         create_auction,d,5,1\nbid,c,7,\nbid,c,6,\nendOfDay\nbid,a,3,\nsold,b,,\n\
         create_auction,c,1,1\nsold,c,,\nbid,d,1,\nsold,d,,\ncreate_auction,d,1,1\nsold,a,,\n\
         create_auction,e,5,2\nbid,e,9,\nbid,e,4,\nsold,e,,\nbid,e,10,\nsold,e,,\n\
         create_auction,f,20,2\nbid,f,3,\nsold,f,,\n",
    );
    let reference = smedl(&evs);
    for kind in ["recreation", "sold_early", "low_bid", "action_after_end"] {
        assert!(reference.contains(kind), "{kind} missing from\n{reference}");
    }
    let run = tessla_trace::run(&program, &tessla_trace(&evs));
    assert_eq!(run.error, None);
    assert_eq!(run.output, reference);
}

#[test]
fn primes_spec_prints_what_tesslas_compiled_monitor_prints() {
    let Some(corpora) = corpora() else { return };
    let dir = corpora.join("tessla-wild2/vamos-shamon/930b14d");
    let program = load(&dir.join("experiments/tessla_compare/primes.tessla"));
    let trace =
        std::fs::read_to_string(dir.join("experiments/tessla_compare/gen_tessla_input/primes.in"))
            .unwrap();
    let oracle = std::fs::read_to_string(dir.join("oracle-tessla-rust/primes.out")).unwrap();
    let run = tessla_trace::run(&program, &trace);
    assert_eq!(run.error, None);
    assert!(
        run.output == oracle,
        "primes: the output differs from TeSSLa's"
    );
}
