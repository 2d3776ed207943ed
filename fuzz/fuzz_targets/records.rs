//! Fuzz target: the record reader and binding. Bytes in through the splitter (cut into chunks of
//! an input-chosen size, with a small record limit so oversized-record recovery is reached), the
//! parser and the Processor running the bundled robot monitors (optionally one instance per
//! `robot` tag with at most 3 instances, flushing after every chunk as a transport does), bytes
//! out. Checks: no panic, no hang, and without pass-through every output line parses back as line
//! protocol with at least one field and a timestamp.
#![no_main]

use libfuzzer_sys::fuzz_target;
use lineproto::{RecordSplitter, parse_record};
use std::sync::{Arc, OnceLock};
use tessla_engine::Program;
use tessla_telegraf::processor::{LateMode, Options, Processor};

fn program() -> Arc<Program> {
    static P: OnceLock<Arc<Program>> = OnceLock::new();
    P.get_or_init(|| {
        tessla_telegraf::log::set_level(tessla_telegraf::log::Level::Error);
        let options = match tessla_telegraf::natives::load_options() {
            Ok(o) => o,
            Err(e) => panic!("natives: {e}"),
        };
        match tessla_telegraf::bundled::load(&options) {
            Ok(l) => l.program,
            Err(e) => panic!("bundled spec does not load: {}", e.render()),
        }
    })
    .clone()
}

fuzz_target!(|data: &[u8]| {
    let Some((&flags, rest)) = data.split_first() else {
        return;
    };
    let Some((&chunk, input)) = rest.split_first() else {
        return;
    };
    let passthrough = flags & 1 != 0;
    let opts = Options {
        passthrough,
        late: if flags & 2 != 0 {
            LateMode::Drop
        } else {
            LateMode::Shift
        },
        instance_by: if flags & 4 != 0 {
            vec!["robot".into()]
        } else {
            Vec::new()
        },
        max_instances: 3,
        ..Options::default()
    };
    let Ok(mut p) = Processor::new(program(), opts) else {
        panic!("bundled spec has bad bindings");
    };
    let mut s = RecordSplitter::new(2048);
    let mut out = Vec::new();
    for c in input.chunks(usize::from(chunk).max(1)) {
        s.push(c);
        while let Some(r) = s.next_record() {
            p.record(&r, &mut out);
        }
        p.end_of_read();
    }
    while let Some(r) = s.finish() {
        p.record(&r, &mut out);
    }
    p.end_of_read();
    if !passthrough {
        for line in out.split(|&b| b == b'\n').filter(|l| !l.is_empty()) {
            match parse_record(line) {
                Ok(Some(m)) => {
                    assert!(!m.fields.is_empty());
                    assert!(m.timestamp.is_some(), "{:?}", String::from_utf8_lossy(line));
                }
                other => panic!(
                    "output line {:?} does not parse: {other:?}",
                    String::from_utf8_lossy(line)
                ),
            }
        }
    }
});
