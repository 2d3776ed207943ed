//! CTF (Common Trace Format 1.8) traces as TeSSLa's interpreter reads them (`trace --ctf`): a
//! trace directory (a `metadata` file and one binary file per stream and CPU) is read, the
//! events of all stream files are merged by timestamp, and each becomes an event on the input
//! named after the event's declared name, at its timestamp, carrying the event as a `CTF` value
//! (read with `CTF.getInt`/`CTF.getString`).
//!
//! When a packet's `events_discarded` grew, the packet's events are preceded by one named
//! `Lost event` at the packet's start time (fields `Lost events` and `duration`), as in Trace
//! Compass: no spec can declare that name, so it only advances time (or stops `-r`).
//!
//! Timestamps are the clock values as the event headers hold them (clock cycles, a wrapping
//! compact timestamp extended over the previous one), without the clock's offset and frequency:
//! that is what TeSSLa's reader (Trace Compass's `ctf.core`, `IEventDefinition.getTimestamp`)
//! gives it.
//!
//! Why a reader of our own and not a crate: the Rust crates for CTF are `babeltrace2-sys` (a C
//! library and its large graph API for an input that is rarely used; the execd plugin would link
//! it too) and `barectf-parser` (reads barectf's YAML configuration, not the TSDL metadata that
//! LTTng and other writers produce). The subset real traces use is small: [`tsdl`] parses the
//! metadata, [`decode`] the binary streams; both return errors naming the file and the place,
//! and never panic on bad input.
//!
//! A `CTF` value is a record (see [`tessla_engine::ctf_get_int`] for the key
//! rules) with the marker field `$ctf` (the event name) and one field per TeSSLa key prefix:
//! `context` (stream event context and event context), `eventcontext`, `eventheader`,
//! `packetcontext` and `fields`. Nested structs are records, integers `Int`, strings `String`;
//! floats, enums (value and label), arrays and variants are kept in other forms so that
//! `CTF.getInt`/`CTF.getString` give TeSSLa's type error on them.

pub mod decode;
pub mod tsdl;

use crate::{ErrorKind, Options, Printer, RunError, finish};
use decode::{Field, RawEvent, StreamDecoder};
use std::io::Write;
use std::path::Path;
use std::sync::Arc;
use tessla_engine::{Monitor, Program, Value};

/// The marker field of a `CTF` value (no TeSSLa record can have it: not an identifier).
pub const CTF_MARKER: &str = tessla_engine::CTF_MARKER;

fn io(message: String) -> RunError {
    RunError {
        kind: ErrorKind::Io,
        message,
    }
}

/// A stream file of the trace and its bytes.
struct StreamFile {
    name: String,
    data: Vec<u8>,
}

/// The metadata and stream files of a trace directory.
fn open(dir: &Path) -> Result<(tsdl::Metadata, Vec<StreamFile>), RunError> {
    let shown = dir.display();
    let md_path = dir.join("metadata");
    if !dir.is_dir() {
        return Err(io(format!(
            "error: cannot read {shown}: a CTF trace is a directory (with a `metadata` file and stream files)"
        )));
    }
    let bytes = std::fs::read(&md_path).map_err(|e| {
        io(format!(
            "error: cannot read {}: {e} (a CTF trace directory holds a `metadata` file)",
            md_path.display()
        ))
    })?;
    let text = tsdl::metadata_text(&bytes)
        .map_err(|e| io(format!("error: {}: {e}", md_path.display())))?;
    let md = tsdl::parse(&text).map_err(|e| {
        io(format!(
            "error: {}:{}:{}: {}",
            md_path.display(),
            e.line,
            e.col,
            e.message
        ))
    })?;
    let entries =
        std::fs::read_dir(dir).map_err(|e| io(format!("error: cannot read {shown}: {e}")))?;
    let mut names = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| io(format!("error: cannot read {shown}: {e}")))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name == "metadata" || name.starts_with('.') || !entry.path().is_file() {
            continue;
        }
        names.push(name);
    }
    names.sort();
    let mut files = Vec::new();
    for name in names {
        let p = dir.join(&name);
        let data = std::fs::read(&p)
            .map_err(|e| io(format!("error: cannot read {}: {e}", p.display())))?;
        files.push(StreamFile {
            name: p.display().to_string(),
            data,
        });
    }
    Ok((md, files))
}

/// One event of the merged trace.
pub struct CtfEvent {
    /// The event's name as the metadata declares it (or [`decode::LOST_EVENT`]).
    pub name: String,
    /// Its timestamp: the clock value the event header holds (cycles, without the clock's
    /// offset and frequency), as TeSSLa's reader gives it.
    pub ts: u64,
    /// Its payload as a TeSSLa value: a record of its fields.
    pub value: Value,
}

/// Read all events of the trace in `dir`, merged by timestamp (ties in file name order).
/// Stops at the first bad event: the events before it and the error.
pub fn read_dir(dir: &Path) -> Result<(Vec<CtfEvent>, Option<RunError>), RunError> {
    let (md, files) = open(dir)?;
    let mut events = Vec::new();
    let error = merge(&md, &files, &mut |e| {
        events.push(e);
        true
    });
    Ok((events, error))
}

/// Merge the stream files' events by timestamp, passing each to `f` until it returns false.
/// The error that stopped the merge, if any: a stream's error comes at the time of its last
/// good event, after the events of other streams before it.
fn merge(
    md: &tsdl::Metadata,
    files: &[StreamFile],
    f: &mut dyn FnMut(CtfEvent) -> bool,
) -> Option<RunError> {
    let mut decoders: Vec<StreamDecoder<'_>> = files
        .iter()
        .map(|s| StreamDecoder::new(md, &s.data))
        .collect();
    let mut heads: Vec<Option<Result<RawEvent, decode::DecodeError>>> =
        decoders.iter_mut().map(|d| d.next_event()).collect();
    let mut last: Vec<u64> = vec![0; files.len()];
    loop {
        let key = |i: usize, h: &Option<Result<RawEvent, decode::DecodeError>>| match h {
            Some(Ok(e)) => Some((e.ts, 1u8, i)),
            Some(Err(_)) => Some((last[i], 0u8, i)),
            None => None,
        };
        let next = heads
            .iter()
            .enumerate()
            .filter_map(|(i, h)| key(i, h))
            .min();
        let (_, _, i) = next?;
        let head = heads.get_mut(i).and_then(Option::take);
        match head {
            Some(Ok(raw)) => {
                if let Some(l) = last.get_mut(i) {
                    *l = raw.ts;
                }
                let name = match raw.decl {
                    Some(d) => md
                        .events
                        .get(d)
                        .map_or_else(String::new, |d| d.name.clone()),
                    None => decode::LOST_EVENT.to_string(),
                };
                let ev = CtfEvent {
                    value: to_value(&name, &raw),
                    name,
                    ts: raw.ts,
                };
                if !f(ev) {
                    return None;
                }
                if let (Some(h), Some(d)) = (heads.get_mut(i), decoders.get_mut(i)) {
                    *h = d.next_event();
                }
            }
            Some(Err(e)) => {
                let (file, at) = (
                    files.get(i).map_or("?", |s| s.name.as_str()),
                    decoders.get(i).map_or(0, StreamDecoder::packet_offset),
                );
                return Some(RunError {
                    kind: ErrorKind::Input,
                    message: format!("{file}: packet at byte {at}: {e}"),
                });
            }
            None => return None,
        }
    }
}

/// A decoded field as a value (see the module doc).
fn field_value(f: &Field) -> Value {
    match f {
        Field::Int(i) => match i64::try_from(*i) {
            Ok(i) => Value::Int(i),
            Err(_) => Value::from_big((*i).into()),
        },
        Field::Float(x) => Value::Float(*x),
        Field::Str(s) => Value::Str(s.as_str().into()),
        Field::Enum(v, label) => Value::Tuple(Arc::from(vec![
            field_value(&Field::Int(*v)),
            label
                .as_deref()
                .map_or(Value::None, |l| Value::Str(l.into())),
        ])),
        Field::Struct(fs) => record(fs.iter().map(|(n, v)| (n.as_str(), field_value(v)))),
        Field::Array(items) => Value::List(Arc::new(items.iter().map(field_value).collect())),
        Field::Variant(_, v) => Value::Some(Arc::new(field_value(v))),
    }
}

/// A record of the fields, sorted by name (the first of two fields with one name is kept).
fn record<'a>(fields: impl Iterator<Item = (&'a str, Value)>) -> Value {
    let mut fs: Vec<(Arc<str>, Value)> = fields.map(|(n, v)| (Arc::from(n), v)).collect();
    fs.sort_by(|a, b| a.0.cmp(&b.0));
    fs.dedup_by(|a, b| a.0 == b.0);
    Value::Record(Arc::from(fs))
}

fn section(f: Option<&Field>) -> Value {
    f.map_or(Value::Unit, field_value)
}

/// The `CTF` value of an event.
fn to_value(name: &str, e: &RawEvent) -> Value {
    let context = match (&e.stream_context, &e.context) {
        (None, None) => Value::Unit,
        (a, b) => {
            let mut fs = Vec::new();
            for f in [a, b].into_iter().flatten() {
                if let Field::Struct(s) = f {
                    fs.extend(s.iter().cloned());
                }
            }
            field_value(&Field::Struct(fs))
        }
    };
    record(
        [
            (CTF_MARKER, Value::Str(name.into())),
            ("context", context),
            ("eventcontext", section(e.context.as_ref())),
            ("eventheader", section(e.header.as_ref())),
            ("packetcontext", section(e.packet_context.as_ref())),
            ("fields", section(e.fields.as_ref())),
        ]
        .into_iter(),
    )
}

/// Is this a `CTF` value?
pub fn is_ctf(v: &Value) -> bool {
    matches!(v, Value::Record(fs) if fs.first().is_some_and(|(n, _)| &**n == CTF_MARKER))
}

/// Is this a `CTF` value or one holding one (in an option, tuple, list, record, set, map)?
pub fn holds_ctf(v: &Value) -> bool {
    is_ctf(v)
        || match v {
            Value::Some(x) => holds_ctf(x),
            Value::List(xs) => xs.iter().any(holds_ctf),
            Value::Tuple(xs) => xs.iter().any(holds_ctf),
            Value::Record(fs) => fs.iter().any(|(_, x)| holds_ctf(x)),
            Value::Set(xs) => xs.iter().any(holds_ctf),
            Value::Map(kv) => kv.iter().any(|(k, x)| holds_ctf(k) || holds_ctf(x)),
            _ => false,
        }
}

/// Run `program` over the CTF trace in `dir`, writing outputs to `out` as they are produced.
/// The options are those of text traces, except that `-a N` reads N events, as TeSSLa's CTF
/// reader counts. A bad event stops the run after the outputs of the steps before it.
pub fn run_dir(
    program: &Arc<Program>,
    dir: &Path,
    out: &mut impl Write,
    options: &Options,
) -> Result<(), RunError> {
    let mut printer = Printer::new(program, out, options)?;
    let (md, files) = open(dir)?;
    let mut monitor = Monitor::new(program.clone());
    let mut failure: Option<RunError> = None;
    let mut events_read: u64 = 0;
    let source = dir.display().to_string();
    let mut step = |ev: CtfEvent| -> bool {
        if options.abort_at.is_some_and(|n| events_read >= n) {
            return false;
        }
        events_read += 1;
        let Ok(ts) = i64::try_from(ev.ts) else {
            failure = Some(RunError {
                kind: ErrorKind::Unsupported,
                message: format!(
                    "{source}: event `{}`: timestamp {} is beyond 2^63",
                    ev.name, ev.ts
                ),
            });
            return false;
        };
        let mut print = |e: tessla_engine::OutputEvent<'_>| {
            if printer.error.is_none() && holds_ctf(e.value) {
                let name = program
                    .outputs
                    .get(e.output)
                    .map_or("?", |o| o.name.as_str());
                printer.error = Some(RunError {
                    kind: ErrorKind::Unsupported,
                    message: format!(
                        "output `{name}` at t = {}: a CTF event object has no printed form here; \
                         print its members with CTF.getInt or CTF.getString",
                        e.ts
                    ),
                });
            }
            printer.event(e)
        };
        let pushed = match program.inputs.iter().position(|i| i.name == ev.name) {
            Some(input) => {
                let ty = program.inputs.get(input).map(|i| &i.ty);
                if let Some(ty) = ty.filter(|t| **t != tessla_engine::Type::Unknown) {
                    failure = Some(RunError {
                        kind: ErrorKind::Input,
                        message: format!(
                            "{source}: event `{}` at {ts}: input `{}` is declared Events[{ty}], but a CTF event carries a CTF object: declare `in {}: Events[CTF]`",
                            ev.name, ev.name, ev.name
                        ),
                    });
                    return false;
                }
                monitor.push(ts, input, ev.value, &mut print)
            }
            None if options.reject_undeclared => {
                let e = crate::reader::undeclared(0, &ev.name, program);
                failure = Some(RunError {
                    kind: ErrorKind::Input,
                    message: format!("{source}: event at {ts}: {}", e.message),
                });
                return false;
            }
            None => monitor.open_step(ts, &mut print),
        };
        if printer.error.is_some() || printer.stopped {
            return false;
        }
        let message = match pushed {
            Ok(()) => return true,
            Err(e) => crate::input_error_message(program, &e),
        };
        failure = Some(RunError {
            kind: ErrorKind::Runtime,
            message: format!("{source}: {message}"),
        });
        false
    };
    let bad = merge(&md, &files, &mut step);
    if let Some(e) = printer.error.take() {
        return Err(e);
    }
    if printer.stopped {
        return finish(printer);
    }
    if let Some(e) = failure.or(bad) {
        // The outputs of the steps before are kept (written and flushed).
        let _ = printer.out.flush();
        return Err(e);
    }
    monitor.flush(&mut |e| printer.event(e));
    finish(printer)
}
