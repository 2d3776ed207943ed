//! `tessla-telegraf trace --ctf SPEC DIR` on CTF 1.8 traces written here (TSDL metadata and
//! binary stream files, LTTng-style headers): events to streams by name, timestamps (compact
//! headers wrapping, two stream files merged), `CTF.getInt`/`CTF.getString` with TeSSLa's key
//! rules and errors, undeclared events, `-r`, `-a`, `-S`, bad traces. The reader is checked
//! against babeltrace2's own reading of the same trace when the `babeltrace2` command is present.

use crate::support::servers;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::support::BIN;

const METADATA: &str = r#"/* CTF 1.8 */
typealias integer { size = 8; align = 8; signed = false; } := uint8_t;
typealias integer { size = 16; align = 8; signed = false; byte_order = be; } := be16_t;
typealias integer { size = 32; align = 8; signed = false; } := uint32_t;
typealias integer { size = 64; align = 8; signed = false; } := uint64_t;
typealias integer { size = 64; align = 8; signed = true; } := int64_t;
typealias integer { size = 5; align = 1; signed = false; } := uint5_t;
typealias integer { size = 27; align = 1; signed = false; map = clock.monotonic.value; } := uint27_clock_t;
typealias integer { size = 64; align = 8; signed = false; map = clock.monotonic.value; } := uint64_clock_t;
typealias floating_point { exp_dig = 11; mant_dig = 53; align = 8; } := double;

trace {
    major = 1;
    minor = 8;
    byte_order = le;
    packet.header := struct { uint32_t magic; uint32_t stream_id; };
};

env { hostname = "test"; domain = "ust"; };

clock {
    name = "monotonic";
    freq = 1000000000;
    offset_s = 100;
    offset = 5;
};

stream {
    id = 0;
    packet.context := struct {
        uint64_clock_t timestamp_begin;
        uint64_clock_t timestamp_end;
        uint64_t content_size;
        uint64_t packet_size;
        uint64_t events_discarded;
        uint32_t cpu_id;
    };
    event.header := struct {
        enum : uint5_t { compact = 0 ... 30, extended = 31 } id;
        variant <id> {
            struct { uint27_clock_t timestamp; } compact;
            struct { uint32_t id; uint64_clock_t timestamp; } extended;
        } v;
    } align(8);
    event.context := struct { int64_t vtid; };
};

event {
    name = "temp";
    id = 0;
    stream_id = 0;
    fields := struct {
        int64_t value;
        string unit;
        struct { uint8_t a; be16_t b; } inner;
        double ratio;
        uint8_t n;
        uint8_t seq[n];
        enum : uint8_t { LOW, HIGH } level;
    };
};

event {
    name = "other";
    id = 1;
    stream_id = 0;
    fields := struct { uint8_t x; };
};
"#;

/// One event to write: compact header when the timestamp's low 27 bits follow the previous one
/// (`compact`), else the extended header with the full timestamp.
struct Ev {
    id: u32,
    /// The value written in the header's timestamp field (27 bits when compact).
    ts: u64,
    compact: bool,
    vtid: i64,
    /// The payload bytes.
    fields: Vec<u8>,
}

fn temp_fields(value: i64, unit: &str, b: u16, n: u8, level: u8) -> Vec<u8> {
    let mut f = Vec::new();
    f.extend(value.to_le_bytes());
    f.extend(unit.as_bytes());
    f.push(0);
    f.push(7); // inner.a
    f.extend(b.to_be_bytes()); // inner.b, big-endian
    f.extend(0.5f64.to_le_bytes());
    f.push(n);
    f.extend((0..n).map(|i| i * 10));
    f.push(level);
    f
}

/// A packet of stream 0 for `cpu` holding `events`, padded to a multiple of 64 bytes.
fn packet(cpu: u32, begin: u64, end: u64, events: &[Ev]) -> Vec<u8> {
    packet_lost(cpu, begin, end, 0, events)
}

/// [`packet`] after `discarded` events were discarded in this stream so far.
fn packet_lost(cpu: u32, begin: u64, end: u64, discarded: u64, events: &[Ev]) -> Vec<u8> {
    let mut body = Vec::new();
    for e in events {
        if e.compact {
            body.extend(((e.ts as u32) << 5 | e.id).to_le_bytes());
        } else {
            body.push(31);
            body.extend(e.id.to_le_bytes());
            body.extend(e.ts.to_le_bytes());
        }
        body.extend(e.vtid.to_le_bytes());
        body.extend(&e.fields);
    }
    let header_len = 8 + 5 * 8 + 4;
    let content = header_len + body.len();
    let size = content.div_ceil(64) * 64;
    let mut p = Vec::new();
    p.extend(0xC1FC_1FC1u32.to_le_bytes());
    p.extend(0u32.to_le_bytes());
    p.extend(begin.to_le_bytes());
    p.extend(end.to_le_bytes());
    p.extend((content as u64 * 8).to_le_bytes());
    p.extend((size as u64 * 8).to_le_bytes());
    p.extend(discarded.to_le_bytes());
    p.extend(cpu.to_le_bytes());
    p.extend(body);
    p.resize(size, 0);
    p
}

fn dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("tessla-ctf-{}", std::process::id()))
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The standard trace: CPU 0 with two packets (the second's compact timestamp wraps), CPU 1
/// with one event between them in time, and an `other` event.
fn write_trace(name: &str) -> PathBuf {
    let d = dir(name);
    std::fs::write(d.join("metadata"), METADATA).unwrap();
    let mut cpu0 = packet(
        0,
        1000,
        2000,
        &[
            Ev {
                id: 0,
                ts: 1005,
                compact: true,
                vtid: 11,
                fields: temp_fields(42, "C", 300, 2, 1),
            },
            Ev {
                id: 1,
                ts: 1010,
                compact: true,
                vtid: 11,
                fields: vec![9],
            },
            Ev {
                id: 0,
                ts: 2000,
                compact: false,
                vtid: 12,
                fields: temp_fields(-7, "K", 1, 0, 0),
            },
        ],
    );
    // Compact timestamp 10 after 2000: the 27-bit field wrapped once.
    cpu0.extend(packet(
        0,
        2000,
        (1 << 27) + 10,
        &[Ev {
            id: 0,
            ts: 10,
            compact: true,
            vtid: 13,
            fields: temp_fields(5, "F", 2, 1, 1),
        }],
    ));
    std::fs::write(d.join("chan_0"), cpu0).unwrap();
    let cpu1 = packet(
        1,
        1500,
        1500,
        &[Ev {
            id: 0,
            ts: 1500,
            compact: false,
            vtid: 21,
            fields: temp_fields(100, "C", 2, 0, 0),
        }],
    );
    std::fs::write(d.join("chan_1"), cpu1).unwrap();
    d
}

fn spec(name: &str, text: &str) -> PathBuf {
    let p = dir(&format!("spec-{name}")).join("spec.tessla");
    std::fs::write(&p, text).unwrap();
    p
}

fn run(spec: &Path, args: &[&str], trace: &Path) -> Output {
    Command::new(BIN)
        .arg("trace")
        .arg(spec)
        .arg("--ctf")
        .args(args)
        .arg(trace)
        .output()
        .unwrap()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

const MEMBERS: &str = r#"in temp: Events[CTF]
out CTF.getInt(temp, "value") as value
out CTF.getString(temp, "fields:unit") as unit
out CTF.getInt(temp, "inner.b") as b
out CTF.getInt(temp, "fields:inner.a") as a
out CTF.getInt(temp, "context:vtid") as vtid
out CTF.getInt(temp, "packetcontext:cpu_id") as cpu
"#;

#[test]
fn events_become_inputs_with_their_members() {
    let t = write_trace("members");
    let o = run(&spec("members", MEMBERS), &[], &t);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let mut want = Vec::new();
    for (ts, value, unit, b, vtid, cpu) in [
        (1005, 42, "C", 300, 11, 0),
        (1500, 100, "C", 2, 21, 1),
        (2000, -7, "K", 1, 12, 0),
        ((1 << 27) + 10, 5, "F", 2, 13, 0),
    ] {
        want.extend([
            format!("{ts}: value = {value}"),
            format!("{ts}: unit = {unit}"),
            format!("{ts}: b = {b}"),
            format!("{ts}: a = 7"),
            format!("{ts}: vtid = {vtid}"),
            format!("{ts}: cpu = {cpu}"),
        ]);
    }
    let mut got: Vec<String> = stdout(&o).lines().map(String::from).collect();
    // Within a timestamp the order of outputs is the spec's; compare as sets per line.
    got.sort();
    want.sort();
    assert_eq!(got, want);
}

#[test]
fn ctf_key_errors_are_teslas() {
    let t = write_trace("errors");
    for (call, message) in [
        (r#"CTF.getInt(temp, "nope")"#, r#"Key "nope" not found"#),
        (
            r#"CTF.getInt(temp, "inner.c")"#,
            r#"Key "inner.c" not found"#,
        ),
        (
            r#"CTF.getInt(temp, "value.x")"#,
            r#"Key "value.x" not found"#,
        ),
        // The stream's event context is in `context`, `eventcontext` is the event's own.
        (
            r#"CTF.getInt(temp, "eventcontext:vtid")"#,
            r#"Key "eventcontext:vtid" not found"#,
        ),
        (
            r#"CTF.getInt(temp, "unit")"#,
            r#"Value for key "unit" is not of type Int"#,
        ),
        (
            r#"CTF.getString(temp, "value")"#,
            r#"Value for key "value" is not of type String"#,
        ),
        (
            r#"CTF.getInt(temp, "ratio")"#,
            r#"Value for key "ratio" is not of type Int"#,
        ),
        (
            r#"CTF.getInt(temp, "level")"#,
            r#"Value for key "level" is not of type Int"#,
        ),
        (
            r#"CTF.getInt(temp, "seq")"#,
            r#"Value for key "seq" is not of type Int"#,
        ),
        (
            r#"CTF.getInt(temp, "eventheader:id")"#,
            r#"Value for key "eventheader:id" is not of type Int"#,
        ),
        (
            r#"CTF.getInt(temp, "bogus:value")"#,
            r#"Unknown prefix "bogus". Available prefixes are context, eventcontext, eventheader, packetcontext and fields"#,
        ),
    ] {
        let s = spec("err", &format!("in temp: Events[CTF]\nout {call} as v\n"));
        let o = run(&s, &[], &t);
        assert_eq!(o.status.code(), Some(1), "{call}: {}", stderr(&o));
        assert_eq!(stdout(&o), "", "{call}");
        assert!(
            stderr(&o).contains(&format!("Runtime error: {message} (t = 1005)")),
            "{call}: {}",
            stderr(&o)
        );
    }
}

#[test]
fn undeclared_events_advance_time_and_reject_undeclared_stops() {
    let t = write_trace("undeclared");
    // `other` at 1010 is not declared: ignored, but it opens a step at 1010, so the delay set
    // at 1005 fires there.
    let s = spec(
        "undeclared",
        "in temp: Events[CTF]\nout delay(const(5, temp), temp) as d\n",
    );
    let o = run(&s, &[], &t);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout(&o).starts_with("1010: d = ()\n"), "{}", stdout(&o));
    let o = run(&s, &["-r"], &t);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("event at 1010: Undeclared input stream other"),
        "{}",
        stderr(&o)
    );
    // The declared input `other` receives its event.
    let s = spec(
        "other",
        "in temp: Events[CTF]\nin other: Events[CTF]\nout CTF.getInt(other, \"x\") as x\n",
    );
    let o = run(&s, &["-r"], &t);
    assert_eq!(
        (stdout(&o).as_str(), o.status.code()),
        ("1010: x = 9\n", Some(0))
    );
}

#[test]
fn abort_at_and_stop_on() {
    let t = write_trace("abort");
    let s = spec(
        "abort",
        "in temp: Events[CTF]\nout CTF.getInt(temp, \"value\") as v\n",
    );
    // As TeSSLa's CTF reader: `-a 3` reads 3 events (temp, other, temp at 1500).
    let o = run(&s, &["-a", "3"], &t);
    assert_eq!(
        stdout(&o),
        "1005: v = 42\n1500: v = 100\n",
        "{}",
        stderr(&o)
    );
    let o = run(&s, &["-S", "v"], &t);
    assert_eq!(
        (stdout(&o).as_str(), o.status.code()),
        ("1005: v = 42\n", Some(0))
    );
}

#[test]
fn a_ctf_value_cannot_be_printed_and_a_typed_input_is_refused() {
    let t = write_trace("print");
    let o = run(&spec("print", "in temp: Events[CTF]\nout temp\n"), &[], &t);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("output `temp` at t = 1005: a CTF event object has no printed form"),
        "{}",
        stderr(&o)
    );
    let o = run(
        &spec("nested", "in temp: Events[CTF]\nout Some(temp) as p\n"),
        &[],
        &t,
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("output `p` at t = 1005: a CTF event object"),
        "{}",
        stderr(&o)
    );
    let o = run(&spec("typed", "in temp: Events[Int]\nout temp\n"), &[], &t);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("declare `in temp: Events[CTF]`"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_corrupted_trace_keeps_the_outputs_before_and_never_panics() {
    let good = write_trace("corrupt-src");
    let s = spec(
        "corrupt",
        "in temp: Events[CTF]\nout CTF.getInt(temp, \"value\") as v\n",
    );
    let chan0 = std::fs::read(good.join("chan_0")).unwrap();
    // The second packet of chan_0 cut in its event: the events before it are printed.
    let t = dir("corrupt");
    std::fs::write(t.join("metadata"), METADATA).unwrap();
    let second = (1..chan0.len())
        .find(|&i| chan0[i..].starts_with(&0xC1FC_1FC1u32.to_le_bytes()))
        .unwrap();
    std::fs::write(t.join("chan_0"), &chan0[..second + 60]).unwrap();
    let o = run(&s, &[], &t);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    // As for text traces: the steps before the error are kept, the pending one (2000) dropped.
    assert_eq!(stdout(&o), "1005: v = 42\n");
    assert!(
        stderr(&o).contains(&format!(
            "chan_0: packet at byte {second}: packet context: content size"
        )),
        "{}",
        stderr(&o)
    );
    // Every truncation and many garbled bytes: an error or a run, never a crash.
    for cut in (0..chan0.len()).step_by(7) {
        std::fs::write(t.join("chan_0"), &chan0[..cut]).unwrap();
        let o = run(&s, &[], &t);
        assert!(
            matches!(o.status.code(), Some(0 | 1)),
            "cut {cut}: {}",
            stderr(&o)
        );
        assert!(
            !stderr(&o).contains("panicked"),
            "cut {cut}: {}",
            stderr(&o)
        );
    }
    for k in (0..chan0.len()).step_by(5) {
        let mut bad = chan0.clone();
        bad[k] ^= 0xA5;
        std::fs::write(t.join("chan_0"), &bad).unwrap();
        let o = run(&s, &[], &t);
        assert!(
            o.status.code().is_some_and(|c| c <= 1),
            "byte {k}: {}",
            stderr(&o)
        );
        assert!(!stderr(&o).contains("panicked"), "byte {k}: {}", stderr(&o));
    }
    // Garbled metadata: exit 3 with the place.
    std::fs::write(t.join("chan_0"), &chan0).unwrap();
    std::fs::write(
        t.join("metadata"),
        METADATA.replace("uint8_t x;", "uint9_t x;"),
    )
    .unwrap();
    let o = run(&s, &[], &t);
    assert_eq!(o.status.code(), Some(3));
    assert!(
        stderr(&o).contains("metadata:67:24: unknown type `uint9_t`"),
        "{}",
        stderr(&o)
    );
    for cut in (0..METADATA.len()).step_by(13) {
        std::fs::write(t.join("metadata"), &METADATA[..cut]).unwrap();
        let o = run(&s, &[], &t);
        assert!(
            o.status.code().is_some_and(|c| c <= 3),
            "metadata cut {cut}: {}",
            stderr(&o)
        );
        assert!(
            !stderr(&o).contains("panicked"),
            "metadata cut {cut}: {}",
            stderr(&o)
        );
    }
}

#[test]
fn empty_trace_dirs() {
    let s = spec(
        "empty",
        "in temp: Events[CTF]\nout CTF.getInt(temp, \"value\") as v\n",
    );
    let t = dir("empty");
    let o = run(&s, &[], &t);
    assert_eq!(o.status.code(), Some(3));
    assert!(stderr(&o).contains("metadata"), "{}", stderr(&o));
    // Metadata and no stream file: a trace without events.
    std::fs::write(t.join("metadata"), METADATA).unwrap();
    let o = run(&s, &[], &t);
    assert_eq!((stdout(&o).as_str(), o.status.code()), ("", Some(0)));
}

/// babeltrace2 (the reference CTF reader) reads the same events at the same clock values.
#[test]
fn agrees_with_babeltrace2() {
    let Some(bt) = servers::require("babeltrace2", "babeltrace2") else {
        return;
    };
    let t = write_trace("babeltrace");
    let o = Command::new(bt)
        .arg("--clock-cycles")
        .arg(&t)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    // `[1005] (+?.?????????) test temp: { vtid = 11 }, { value = 42, ... }`
    let theirs: Vec<(u64, String)> = stdout(&o)
        .lines()
        .map(|l| {
            let ts = l[1..l.find(']').unwrap()].parse().unwrap();
            let name = l.split_whitespace().nth(3).unwrap().trim_end_matches(':');
            (ts, name.to_string())
        })
        .collect();
    assert_eq!(theirs.len(), 5, "{}", stdout(&o));
    let (ours, err) = tessla_telegraf::trace::ctf::read_dir(&t).unwrap();
    assert!(err.is_none());
    let ours: Vec<(u64, String)> = ours.into_iter().map(|e| (e.ts, e.name)).collect();
    assert_eq!(ours, theirs);
    assert!(
        stdout(&o).contains("value = 42, unit = \"C\", inner = { a = 7, b = 300 }"),
        "{}",
        stdout(&o)
    );
}

/// A packet whose `events_discarded` grew starts with a `Lost event` at its start time, as in
/// Trace Compass: it advances time, and `-r` stops at it.
#[test]
fn discarded_events_are_a_lost_event() {
    let t = dir("lost");
    std::fs::write(t.join("metadata"), METADATA).unwrap();
    let ev = |ts, value| Ev {
        id: 0,
        ts,
        compact: false,
        vtid: 1,
        fields: temp_fields(value, "C", 1, 0, 0),
    };
    let mut data = packet_lost(0, 1000, 2000, 0, &[ev(1005, 1)]);
    data.extend(packet_lost(0, 3000, 4000, 3, &[ev(3500, 2)]));
    // An empty packet: no lost event even though more were discarded.
    data.extend(packet_lost(0, 4000, 5000, 5, &[]));
    std::fs::write(t.join("chan_0"), data).unwrap();
    let (events, err) = tessla_telegraf::trace::ctf::read_dir(&t).unwrap();
    assert!(err.is_none());
    let got: Vec<(u64, &str)> = events.iter().map(|e| (e.ts, e.name.as_str())).collect();
    assert_eq!(got, [(1005, "temp"), (3000, "Lost event"), (3500, "temp")]);
    let s = spec(
        "lost",
        "in temp: Events[CTF]\nout CTF.getInt(temp, \"value\") as v\n",
    );
    let o = run(&s, &[], &t);
    assert_eq!(stdout(&o), "1005: v = 1\n3500: v = 2\n");
    // As for text traces, the pending step (1005) is dropped at the error.
    let o = run(&s, &["-r"], &t);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(stdout(&o), "");
    assert!(
        stderr(&o).contains("event at 3000: Undeclared input stream Lost event"),
        "{}",
        stderr(&o)
    );
}

/// Metadata in packets (as LTTng writes it): the same trace, the same outputs.
#[test]
fn packetized_metadata() {
    let t = write_trace("packetized");
    let mut md = Vec::new();
    // Packets of at most 900 bytes of text, each padded to 1024 bytes.
    for chunk in METADATA.as_bytes().chunks(900) {
        let content = 37 + chunk.len();
        let mut p = Vec::new();
        p.extend(0x75D1_1D57u32.to_le_bytes());
        p.extend([0u8; 16]); // uuid
        p.extend(0u32.to_le_bytes()); // checksum
        p.extend((content as u32 * 8).to_le_bytes());
        p.extend((1024u32 * 8).to_le_bytes());
        p.extend([0, 0, 0, 1, 8]); // compression, encryption, checksum scheme, major, minor
        p.extend(chunk);
        p.resize(1024, 0);
        md.extend(p);
    }
    std::fs::write(t.join("metadata"), md).unwrap();
    let o = run(&spec("packetized", MEMBERS), &[], &t);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(stdout(&o).lines().count(), 4 * 6);
    assert!(stdout(&o).contains("1500: value = 100\n"), "{}", stdout(&o));
}

/// A trace written by babeltrace2's own CTF writer (`sink.ctf.fs`, from dmesg-style lines):
/// read with its event names, clock values and string fields.
#[test]
fn reads_a_trace_written_by_babeltrace2() {
    let Some(bt) = servers::require("babeltrace2", "babeltrace2") else {
        return;
    };
    let d = dir("bt-written");
    let log = d.join("kernel.log");
    std::fs::write(
        &log,
        "[    0.000100] first line\n[    1.500000] second: thing\n[    2.000001] third\n",
    )
    .unwrap();
    let out = d.join("out");
    let o = Command::new(bt)
        .arg("--component=src.text.dmesg")
        .arg(format!("--params=path=\"{}\"", log.display()))
        .arg("--component=sink.ctf.fs")
        .arg(format!("--params=path=\"{}\"", out.display()))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let s = spec(
        "bt-written",
        "in string: Events[CTF]\nout CTF.getString(string, \"_str\") as s\n",
    );
    let o = run(&s, &[], &out.join("kernel.log"));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_eq!(
        stdout(&o),
        "100000: s = first line\n1500000000: s = second: thing\n2000001000: s = third\n"
    );
}
