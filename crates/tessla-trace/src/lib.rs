//! TeSSLa's trace formats: running a monitor over an input trace (`TS: name = value` lines,
//! see [`reader`]) and printing TeSSLa's output format (see [`writer`]). Used by
//! `tessla-telegraf trace` and by the conformance test, so both take the same path. A crate of
//! its own: the execd plugin's record path never reads traces.
//!
//! Owns: the run semantics of TeSSLa's interpreter for traces. A bad trace line, decreasing
//! timestamps and two events on one stream at one timestamp are errors that stop the run: the
//! outputs of the steps before are kept, the pending step is dropped (as TeSSLa does). An error
//! value reaching an output stops the run at that step.

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
}

/// The error that stopped a run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunError {
    pub kind: ErrorKind,
    pub message: String,
}

impl fmt::Display for RunError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

/// The result of running a trace held in memory: the printed output and the error, if any.
#[derive(Debug, Default)]
pub struct TraceRun {
    pub output: String,
    pub error: Option<RunError>,
}

/// Run `program` over the trace text (named `input` in messages).
pub fn run(program: &Arc<Program>, trace: &str) -> TraceRun {
    run_named(program, "input", trace)
}

/// Run `program` over the trace text; `source` names the trace in error messages.
pub fn run_named(program: &Arc<Program>, source: &str, trace: &str) -> TraceRun {
    let mut out = Vec::new();
    let error = run_stream(program, source, trace.as_bytes(), &mut out).err();
    TraceRun {
        output: String::from_utf8_lossy(&out).into_owned(),
        error,
    }
}

/// Writes output events and remembers the first error value or write failure.
struct Printer<'a, W: Write> {
    program: &'a Program,
    out: &'a mut W,
    error: Option<RunError>,
}

impl<W: Write> Printer<'_, W> {
    fn event(&mut self, e: OutputEvent<'_>) {
        if self.error.is_some() {
            return;
        }
        if let Value::Error(err) = e.value {
            self.error = Some(RunError {
                kind: ErrorKind::Runtime,
                message: format!("Runtime error: {err} (t = {})", e.ts),
            });
            return;
        }
        let Some(o) = self.program.outputs.get(e.output) else {
            return;
        };
        if let Err(err) = writer::write_event(self.out, e.ts, o, e.value) {
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

/// Run `program` over a trace read line by line from `input`, writing outputs to `out` as they
/// are produced. Stops at the first error (see the module doc).
pub fn run_stream(
    program: &Arc<Program>,
    source: &str,
    input: impl BufRead,
    out: &mut impl Write,
) -> Result<(), RunError> {
    let mut monitor = Monitor::new(program.clone());
    let mut printer = Printer {
        program,
        out,
        error: None,
    };
    let at = |line: usize, msg: &str| format!("{source}:{line}: {msg}");
    for (i, raw) in input.lines().enumerate() {
        let line = i + 1;
        let raw = raw.map_err(|e| io_error(&format!("reading {source}"), &e))?;
        let ev = match reader::parse_line(&raw, line, program) {
            None => continue,
            Some(Ok(ev)) => ev,
            Some(Err(e)) => {
                return Err(RunError {
                    kind: match e.kind {
                        reader::ReadErrorKind::Malformed => ErrorKind::Input,
                        reader::ReadErrorKind::Unsupported => ErrorKind::Unsupported,
                    },
                    message: at(e.line, &e.message),
                });
            }
        };
        let pushed = monitor.push(ev.ts, ev.input, ev.value, &mut |e| printer.event(e));
        if let Some(e) = printer.error.take() {
            return Err(e);
        }
        let message = match pushed {
            Ok(()) => continue,
            Err(InputError::Decreasing { last, got }) => {
                format!("Decreasing time stamps: first = {last}, second = {got}")
            }
            Err(InputError::Multiple { input, ts }) => {
                let name = program.inputs.get(input).map_or("?", |i| i.name.as_str());
                format!("Multiple events \"{name}\" at timestamp {ts}")
            }
            Err(InputError::UnknownInput(i)) => format!("unknown input {i}"),
        };
        return Err(RunError {
            kind: ErrorKind::Runtime,
            message: at(line, &message),
        });
    }
    monitor.flush(&mut |e| printer.event(e));
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
                "t:3: Undeclared input stream b",
            ),
        ] {
            let r = run_named(&p, "t", trace);
            assert_eq!(r.output, "1: a = 1\n", "{trace}");
            let e = r.error.unwrap();
            assert_eq!(e.message, message);
            assert_ne!(e.kind, ErrorKind::Unsupported);
        }
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
}
