//! TeSSLa's trace formats: running a monitor over an input trace (`TS: name = value` lines,
//! see [`reader`]) and printing TeSSLa's output format (see [`writer`]). Used by
//! `tessla-telegraf trace` and by the conformance test, so both take the same path. A crate of
//! its own: the execd plugin's record path never reads traces.
//!
//! Owns: the run semantics of TeSSLa's interpreter for traces. A bad trace line, decreasing
//! timestamps and two events on one stream at one timestamp are errors that stop the run: the
//! outputs of the steps before are kept, the pending step is dropped (as TeSSLa does). An error
//! value reaching an output stops the run at that step.
//!
#![doc = include_str!("../README.md")]
#![deny(missing_docs)]

pub mod ctf;
mod fast;
pub mod reader;
pub mod writer;

use std::fmt;
use std::io::{self, BufRead, Write};
use std::sync::Arc;
use tessla_engine::{InputError, Monitor, OutputEvent, Program, Value};

/// What kind of error stopped a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// A trace line that cannot be read or does not fit the spec's inputs.
    Input,
    /// Decreasing timestamps, multiple events, or an error value (division by zero ...).
    Runtime,
    /// A trace value this engine cannot represent.
    Unsupported,
    /// Reading the trace or writing the outputs failed.
    Io,
    /// The reader of the outputs went away (a closed pipe): not a failure of the run.
    OutputClosed,
    /// An option that does not fit the spec (`--stop-on` naming no output).
    Usage,
}

/// The error that stopped a run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunError {
    /// What kind of error it is (how `tessla-telegraf trace` exits).
    pub kind: ErrorKind,
    /// The message, as printed (a trace error names its line).
    pub message: String,
}

impl fmt::Display for RunError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for RunError {}

/// The format of an input trace.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Format {
    /// `TS: name = value` lines.
    #[default]
    Tessla,
    /// A header `time,a,b`, then `TS,value,value` lines (see [`reader::CsvReader`]).
    Csv,
}

/// How to run a trace: the options of TeSSLa's `interpreter` command.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// The trace's format (`--format`).
    pub format: Format,
    /// An event on a stream the spec does not declare is an error (`-r`); by default it is
    /// ignored, but time still advances to its timestamp.
    pub reject_undeclared: bool,
    /// Stop after the first event of this output stream (`-S`): the events of its step
    /// written before it are kept, the rest of the run is not evaluated.
    pub stop_on: Option<String>,
    /// Read no more than this many events plus one (`-a N`; TeSSLa's interpreter counts from
    /// 0, so `-a 2` reads 3 events), then end the run as at the end of the trace.
    pub abort_at: Option<u64>,
}

/// The result of running a trace held in memory: the printed output and the error, if any.
#[derive(Debug, Default)]
pub struct TraceRun {
    /// What the run printed: TeSSLa's output lines, up to the error.
    pub output: String,
    /// The error that stopped the run, if one did.
    pub error: Option<RunError>,
}

/// Run `program` over the trace text (named `input` in messages).
pub fn run(program: &Arc<Program>, trace: &str) -> TraceRun {
    run_named(program, "input", trace)
}

/// Run `program` over the trace text; `source` names the trace in error messages.
pub fn run_named(program: &Arc<Program>, source: &str, trace: &str) -> TraceRun {
    run_with(program, source, trace, &Options::default())
}

/// Run `program` over the trace text with `options`; `source` names the trace in messages.
pub fn run_with(program: &Arc<Program>, source: &str, trace: &str, options: &Options) -> TraceRun {
    let mut out = Vec::new();
    let error = run_stream_with(program, source, trace.as_bytes(), &mut out, options).err();
    TraceRun {
        output: String::from_utf8_lossy(&out).into_owned(),
        error,
    }
}

/// Writes output events and remembers the first error value or write failure.
struct Printer<'a, W: Write> {
    lines: writer::Lines<'a>,
    out: &'a mut W,
    error: Option<RunError>,
    /// The output index of `-S`'s stream.
    stop_on: Option<usize>,
    stopped: bool,
}

impl<'a, W: Write> Printer<'a, W> {
    /// A printer of `program`'s outputs to `out`, stopping at `-S`'s stream if one is given.
    fn new(program: &'a Program, out: &'a mut W, options: &Options) -> Result<Self, RunError> {
        Ok(Printer {
            lines: writer::Lines::new(&program.outputs),
            out,
            error: None,
            stop_on: stop_on_index(program, options)?,
            stopped: false,
        })
    }

    fn event(&mut self, e: OutputEvent<'_>) {
        if self.error.is_some() || self.stopped {
            return;
        }
        if Some(e.output) == self.stop_on {
            self.stopped = true;
        }
        if let Value::Error(err) = e.value {
            self.error = Some(RunError {
                kind: ErrorKind::Runtime,
                message: format!("Runtime error: {err} (t = {})", e.ts),
            });
            return;
        }
        if let Err(err) = self.lines.write(self.out, e.ts, e.output, e.value) {
            self.error = Some(io_error("writing the outputs", &err));
        }
    }
}

fn io_error(what: &str, err: &io::Error) -> RunError {
    RunError {
        kind: if err.kind() == io::ErrorKind::BrokenPipe {
            ErrorKind::OutputClosed
        } else {
            ErrorKind::Io
        },
        message: format!("error {what}: {err}"),
    }
}

/// The output index of `-S`'s stream; an output the spec lacks is a usage error.
pub(crate) fn stop_on_index(
    program: &Program,
    options: &Options,
) -> Result<Option<usize>, RunError> {
    Ok(match &options.stop_on {
        None => None,
        Some(name) => match program.outputs.iter().position(|o| o.name == *name) {
            Some(i) => Some(i),
            None => {
                let near = tessla_syntax::diag::nearest(
                    name,
                    program.outputs.iter().map(|o| o.name.as_str()),
                );
                let hint = if near.is_empty() {
                    String::new()
                } else {
                    format!(" (did you mean `{}`?)", near.join("` or `"))
                };
                return Err(RunError {
                    kind: ErrorKind::Usage,
                    message: format!(
                        "error: --stop-on {name}: the spec has no output stream `{name}`{hint}"
                    ),
                });
            }
        },
    })
}

/// Run `program` over a trace read line by line from `input`, writing outputs to `out` as they
/// are produced. Stops at the first error (see the module doc).
pub fn run_stream(
    program: &Arc<Program>,
    source: &str,
    input: impl BufRead,
    out: &mut impl Write,
) -> Result<(), RunError> {
    run_stream_with(program, source, input, out, &Options::default())
}

/// [`run_stream`] with `options`.
pub fn run_stream_with(
    program: &Arc<Program>,
    source: &str,
    input: impl BufRead,
    out: &mut impl Write,
    options: &Options,
) -> Result<(), RunError> {
    let mut feed = Feed {
        printer: Printer::new(program, out, options)?,
        monitor: Monitor::new(program.clone()),
        program,
        fast: fast::Inputs::new(program),
        source,
        options,
        csv: reader::CsvReader::default(),
        events_read: 0,
        line: 0,
    };
    let mut input = input;
    // The lines are read in the reader's own buffer; only a line that continues past its end
    // is copied (into `carry`), so there is no copy per line.
    let mut carry: Vec<u8> = Vec::new();
    let flow = 'read: loop {
        let buf = match input.fill_buf() {
            Ok(b) => b,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(io_error(&format!("reading {source}"), &e)),
        };
        if buf.is_empty() {
            break Flow::Go;
        }
        let mut at = 0;
        if !carry.is_empty() {
            // The rest of a line begun in the previous buffer.
            let Some(nl) = memchr::memchr(b'\n', buf) else {
                carry.extend_from_slice(buf);
                let n = buf.len();
                input.consume(n);
                continue;
            };
            carry.extend_from_slice(buf.get(..nl).unwrap_or_default());
            let flow = feed.line(&carry, true)?;
            carry.clear();
            if flow != Flow::Go {
                break flow;
            }
            at = nl + 1;
        }
        let rest = buf.get(at..).unwrap_or_default();
        let mut done = 0;
        for nl in memchr::memchr_iter(b'\n', rest) {
            let flow = feed.line(rest.get(done..nl).unwrap_or_default(), true)?;
            done = nl + 1;
            if flow != Flow::Go {
                break 'read flow;
            }
        }
        carry.extend_from_slice(rest.get(done..).unwrap_or_default());
        let n = buf.len();
        input.consume(n);
    };
    let flow = match flow {
        // The last line, without a line ending.
        Flow::Go if !carry.is_empty() => feed.line(&carry, false)?,
        flow => flow,
    };
    if flow != Flow::Stopped {
        feed.monitor.flush(&mut |e| feed.printer.event(e));
    }
    finish(feed.printer)
}

/// How a run goes on after a line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Flow {
    /// On to the next line.
    Go,
    /// `-a`'s count is reached: the run ends as at the end of the trace.
    Aborted,
    /// `-S`'s stream had its event: the run ends now.
    Stopped,
}

/// One run over a trace, fed line by line.
struct Feed<'a, W: Write> {
    printer: Printer<'a, W>,
    monitor: Monitor,
    program: &'a Program,
    fast: fast::Inputs<'a>,
    source: &'a str,
    options: &'a Options,
    csv: reader::CsvReader,
    events_read: u64,
    /// The number of the current line, from 1.
    line: usize,
}

impl<W: Write> Feed<'_, W> {
    /// One line of the trace, without its `\n`; `ended` when it had one (then a `\r` before it
    /// is not part of the line either, as with `BufRead::lines`).
    fn line(&mut self, raw: &[u8], ended: bool) -> Result<Flow, RunError> {
        self.line += 1;
        let raw = match raw {
            [l @ .., b'\r'] if ended => l,
            l => l,
        };
        if self.options.format == Format::Tessla
            && let Some(ev) = self.fast.event(raw, self.line)
        {
            return self.read(reader::Read::Event(ev));
        }
        let Ok(text) = std::str::from_utf8(raw) else {
            // What `BufRead::read_line` says.
            let e = io::Error::new(
                io::ErrorKind::InvalidData,
                "stream did not contain valid UTF-8",
            );
            return Err(io_error(&format!("reading {}", self.source), &e));
        };
        match self.options.format {
            Format::Tessla => match reader::parse_line_any(text, self.line, self.program) {
                None => Ok(Flow::Go),
                Some(r) => {
                    let read = r.map_err(|e| self.read_error(e))?;
                    self.read(read)
                }
            },
            Format::Csv => {
                let reads = self
                    .csv
                    .parse_line(text, self.line, self.program)
                    .map_err(|e| self.read_error(e))?;
                for read in reads {
                    let flow = self.read(read)?;
                    if flow != Flow::Go {
                        return Ok(flow);
                    }
                }
                Ok(Flow::Go)
            }
        }
    }

    /// One event read from the current line, into the monitor.
    #[inline]
    fn read(&mut self, read: reader::Read) -> Result<Flow, RunError> {
        if self.options.abort_at.is_some_and(|n| self.events_read > n) {
            return Ok(Flow::Aborted);
        }
        self.events_read += 1;
        let pushed = match read {
            reader::Read::Event(ev) => {
                let printer = &mut self.printer;
                self.monitor
                    .push(ev.ts, ev.input, ev.value, &mut |e| printer.event(e))
            }
            reader::Read::Undeclared { line, ts, name } => {
                if self.options.reject_undeclared {
                    return Err(self.read_error(reader::undeclared(line, &name, self.program)));
                }
                let printer = &mut self.printer;
                self.monitor.open_step(ts, &mut |e| printer.event(e))
            }
        };
        if let Some(e) = self.printer.error.take() {
            return Err(e);
        }
        if self.printer.stopped {
            return Ok(Flow::Stopped);
        }
        match pushed {
            Ok(()) => Ok(Flow::Go),
            Err(e) => Err(RunError {
                kind: ErrorKind::Runtime,
                message: self.at(&input_error_message(self.program, &e)),
            }),
        }
    }

    /// `SOURCE:LINE: msg`, at the current line.
    fn at(&self, msg: &str) -> String {
        format!("{}:{}: {msg}", self.source, self.line)
    }

    fn read_error(&self, e: reader::ReadError) -> RunError {
        RunError {
            kind: match e.kind {
                reader::ReadErrorKind::Malformed => ErrorKind::Input,
                reader::ReadErrorKind::Unsupported => ErrorKind::Unsupported,
            },
            message: format!("{}:{}: {}", self.source, e.line, e.message),
        }
    }
}

/// An event the monitor refused, in the words of TeSSLa's interpreter (text and CTF traces).
pub(crate) fn input_error_message(program: &Program, e: &InputError) -> String {
    match *e {
        InputError::Decreasing { last, got } => {
            format!("Decreasing time stamps: first = {last}, second = {got}")
        }
        InputError::Multiple { input, ts } => {
            let name = program.inputs.get(input).map_or("?", |i| i.name.as_str());
            format!("Multiple events \"{name}\" at timestamp {ts}")
        }
        InputError::UnknownInput(i) => format!("unknown input {i}"),
    }
}

fn finish<W: Write>(mut printer: Printer<'_, W>) -> Result<(), RunError> {
    if let Some(e) = printer.error.take() {
        return Err(e);
    }
    printer
        .out
        .flush()
        .map_err(|e| io_error("writing the outputs", &e))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use tessla_syntax::include::MemResolver;

    /// The spec text loaded as a program (the tests' specs are valid).
    pub(crate) fn program(spec: &str) -> Arc<Program> {
        let mut r = MemResolver::default();
        r.files.insert("main".into(), spec.into());
        match tessla_engine::load_with("main", &r, &Default::default()) {
            Ok(l) => l.program,
            Err(e) => panic!("{}", e.render()),
        }
    }

    #[test]
    fn outputs_in_tessla_format() {
        let p = program("in x: Events[Int]\nout x\nout x + 1 as y");
        let r = run(&p, "1: x = 2\n# comment\n\n3: x = 5\n");
        assert_eq!(r.error, None);
        let mut got: Vec<&str> = r.output.lines().collect();
        got.sort();
        assert_eq!(got, ["1: x = 2", "1: y = 3", "3: x = 5", "3: y = 6"]);
    }

    #[test]
    fn input_errors_keep_earlier_steps_and_drop_the_pending_one() {
        let p = program("in a: Events[Int]\nout a");
        for (trace, message) in [
            (
                "1: a = 1\n5: a = 1\n4: a = 1",
                "t:3: Decreasing time stamps: first = 5, second = 4",
            ),
            (
                "1: a = 1\n2: a = 1\n2: a = 1",
                "t:3: Multiple events \"a\" at timestamp 2",
            ),
            (
                "1: a = 1\n2: a = 1\n3: b = 1",
                "t:3: Undeclared input stream b (did you mean `a`?)",
            ),
        ] {
            let reject = Options {
                reject_undeclared: true,
                ..Options::default()
            };
            let r = run_with(&p, "t", trace, &reject);
            assert_eq!(r.output, "1: a = 1\n", "{trace}");
            let e = r.error.unwrap();
            assert_eq!(e.message, message);
            assert_ne!(e.kind, ErrorKind::Unsupported);
        }
    }

    #[test]
    fn undeclared_inputs_are_ignored_but_advance_time() {
        let p = program("in x: Events[Int]\nout delay(x, x) as d\nout x");
        // The delay set at 1 fires at 4: the event on `y` at 4 opens that step, so it is
        // evaluated at the end; without it the trace ends at 1 and the delay never fires.
        let r = run(&p, "1: x = 3\n4: y = \"ignored\"\n");
        assert_eq!(r.error, None);
        assert_eq!(r.output, "1: x = 3\n4: d = ()\n");
        let r = run(&p, "1: x = 3\n");
        assert_eq!(r.output, "1: x = 3\n");
        // An ignored event still takes part in the check of increasing timestamps.
        let r = run_named(&p, "t", "1: x = 3\n5: y = 1\n3: x = 1\n");
        assert_eq!(
            r.error.map(|e| e.message).as_deref(),
            Some("t:3: Decreasing time stamps: first = 5, second = 3")
        );
        // A value that cannot be read is an error on any stream.
        let r = run_named(&p, "t", "1: y = (1,\n");
        assert_eq!(r.error.map(|e| e.kind), Some(ErrorKind::Input));
    }

    #[test]
    fn csv_traces() {
        let p = program("in a: Events[Int]\nin b: Events[String]\nout a\nout b");
        let csv = Options {
            format: Format::Csv,
            ..Options::default()
        };
        let r = run_with(&p, "t", "time,a,b\n1,5,\"x,y\"\n2,,\"z\"\n3,7,\n", &csv);
        assert_eq!(r.error, None);
        let mut got: Vec<&str> = r.output.lines().collect();
        got.sort();
        assert_eq!(got, ["1: a = 5", "1: b = x,y", "2: b = z", "3: a = 7"]);
        for (trace, message) in [
            ("1,2,3\n", "t:1: No header row found"),
            (
                "t,a\n1,2,3\n",
                "t:2: 2 value columns, but the header names 1 streams",
            ),
            (
                "t,a\nx,2\n",
                "t:2: `x` is not a non-negative integer timestamp",
            ),
        ] {
            let e = run_with(&p, "t", trace, &csv).error.unwrap();
            assert!(e.message.starts_with(message), "{trace}: {}", e.message);
        }
    }

    #[test]
    fn stop_on_and_abort_at() {
        let p = program("in x: Events[Int]\nout x\nout x > 2 as big");
        let trace = "1: x = 1\n2: x = 3\n3: x = 4\n";
        let stop = |name: &str| Options {
            stop_on: Some(name.into()),
            ..Options::default()
        };
        let r = run_with(&p, "t", trace, &stop("x"));
        assert_eq!((r.output.as_str(), r.error), ("1: x = 1\n", None));
        let e = run_with(&p, "t", trace, &stop("bog")).error.unwrap();
        assert_eq!(e.kind, ErrorKind::Usage);
        assert!(e.message.contains("did you mean `big`?"), "{}", e.message);
        // TeSSLa counts from 0: `-a 1` reads two events.
        let abort = Options {
            abort_at: Some(1),
            ..Options::default()
        };
        let r = run_with(&p, "t", trace, &abort);
        let mut got: Vec<&str> = r.output.lines().collect();
        got.sort();
        assert_eq!(
            got,
            ["1: big = false", "1: x = 1", "2: big = true", "2: x = 3"]
        );
    }

    #[test]
    fn an_error_value_stops_the_run_at_its_step() {
        let p = program("in x: Events[Int]\nin y: Events[Int]\nout x / y as q");
        let r = run(&p, "1: x = 4\n1: y = 2\n2: y = 0\n3: y = 1\n");
        assert_eq!(r.output, "1: q = 2\n");
        let e = r.error.unwrap();
        assert_eq!(e.kind, ErrorKind::Runtime);
        assert_eq!(e.message, "Runtime error: Division by zero (t = 2)");
    }

    /// Lines cut by the reader's buffer anywhere (a line ending `\r\n` cut in two, the last line
    /// without its ending) read as whole lines, on the fast path and off it.
    #[test]
    fn lines_across_buffer_ends() {
        let p = program("in x: Events[Int]\nin u: Events[Unit]\nout x\nout u");
        let traces = [
            "1: x = 2\r\n# c\n\n2: u\n3: x = 1 + 4\r\n4: x = 77",
            "1: x = 2\n2: x = 3\r",
            "1: x = 2\n2: x = (1\n3: x = 4\n",
            "1: x = 2\n3: x = 1\n2: x = 4\n",
            "\n\n5: x = -5\n",
            "",
        ];
        for trace in traces {
            let want = run_named(&p, "t", trace);
            for cap in 1..12 {
                let mut out = Vec::new();
                let input = std::io::BufReader::with_capacity(cap, trace.as_bytes());
                let e = run_stream(&p, "t", input, &mut out).err();
                assert_eq!(
                    String::from_utf8_lossy(&out),
                    want.output,
                    "{trace:?} {cap}"
                );
                assert_eq!(e, want.error, "{trace:?} {cap}");
            }
        }
    }

    /// A line that is no UTF-8 stops the run with `read_line`'s message, as before the reader
    /// read its lines in place.
    #[test]
    fn a_line_that_is_no_utf8_is_a_read_error() {
        let p = program("in x: Events[Int]\nout x");
        let mut out = Vec::new();
        let trace: &[u8] = b"1: x = 2\n2: x = \xff\n3: x = 4\n";
        let e = run_stream(&p, "t", trace, &mut out).unwrap_err();
        assert_eq!(String::from_utf8_lossy(&out), "");
        assert_eq!(e.kind, ErrorKind::Io);
        let mut line = String::new();
        let std_error = BufRead::read_line(&mut &b"\xff"[..], &mut line).unwrap_err();
        assert_eq!(e.message, format!("error reading t: {std_error}"));
    }

    #[test]
    fn a_closed_output_is_reported_as_such() {
        struct Closed;
        impl Write for Closed {
            fn write(&mut self, _: &[u8]) -> io::Result<usize> {
                Err(io::ErrorKind::BrokenPipe.into())
            }
            fn flush(&mut self) -> io::Result<()> {
                Ok(())
            }
        }
        let p = program("in x: Events[Int]\nout x");
        let e = run_stream(&p, "t", "1: x = 1\n2: x = 2\n".as_bytes(), &mut Closed).unwrap_err();
        assert_eq!(e.kind, ErrorKind::OutputClosed);
    }

    /// The library errors are `std::error::Error`s, and their text is the message they carry.
    #[test]
    fn library_errors_are_std_errors_with_their_messages_as_text() {
        fn is_error<E: std::error::Error>() {}
        is_error::<RunError>();
        is_error::<reader::ReadError>();
        is_error::<tessla_engine::LoadError>();
        is_error::<tessla_engine::InputError>();
        is_error::<tessla_engine::RuntimeError>();
        is_error::<tessla_engine::ops::OpError>();
        is_error::<tessla_engine::snapshot::SError>();
        is_error::<tessla_engine::Cycle>();
        is_error::<tessla_engine::FormatError>();
        is_error::<tessla_engine::BaseTimeError>();
        is_error::<tessla_syntax::include::ResolveError>();

        let r = MemResolver::default();
        let e = tessla_syntax::include::Resolver::resolve(&r, None, "x").unwrap_err();
        assert_eq!(e.to_string(), "no bundled spec named `x`");
        let e = tessla_engine::parse_base_time("0 s").unwrap_err();
        assert_eq!(e.to_string(), "base time `0 s` must be positive");
        let e = tessla_engine::java_format("%", &Value::Int(1)).unwrap_err();
        assert_eq!(e.to_string(), "`%` lacks a conversion character");
    }
}
