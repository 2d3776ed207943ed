//! TeSSLa's trace formats: reading input traces (`TS: name = value`) and running a monitor over
//! them, printing TeSSLa's output format. Used by `tessla-telegraf trace` and the conformance test.
//!
//! Owns: the run semantics of TeSSLa's interpreter for traces: decreasing timestamps and two
//! events on one stream at one timestamp are runtime errors that stop the run (outputs before it
//! are kept); an error value reaching an output stops the run at that step.

pub mod reader;

use std::fmt::Write as _;
use std::sync::Arc;
use tessla_engine::{InputError, Monitor, OutputEvent, Program, Value};

/// The result of running a trace: the printed output lines and the runtime error, if any.
#[derive(Debug, Default)]
pub struct TraceRun {
    pub output: String,
    pub error: Option<String>,
}

/// Run `program` over the trace text.
pub fn run(program: &Arc<Program>, trace: &str) -> TraceRun {
    let mut monitor = Monitor::new(program.clone());
    let mut run = TraceRun::default();
    let failed: std::cell::RefCell<Option<String>> = std::cell::RefCell::new(None);
    let outputs = &program.outputs;
    let mut sink = |e: OutputEvent<'_>| {
        if failed.borrow().is_some() {
            return;
        }
        if let Value::Error(err) = e.value {
            *failed.borrow_mut() = Some(format!("Runtime error: {err} (t = {})", e.ts));
            return;
        }
        let Some(o) = outputs.get(e.output) else {
            return;
        };
        if o.raw {
            let _ = writeln!(run.output, "{}", e.value);
        } else {
            let _ = writeln!(run.output, "{}: {} = {}", e.ts, o.name, e.value);
        }
    };
    for item in reader::events(trace, program) {
        match item {
            Err(msg) => {
                failed.borrow_mut().get_or_insert(msg);
            }
            Ok(ev) => match monitor.push(ev.ts, ev.input, ev.value, &mut sink) {
                Ok(()) => {}
                Err(InputError::Decreasing { last, got }) => {
                    failed.borrow_mut().get_or_insert(format!(
                        "line {}: Decreasing time stamps: first = {last}, second = {got}",
                        ev.line
                    ));
                }
                Err(InputError::Multiple { input, ts }) => {
                    let name = program.inputs.get(input).map_or("?", |i| i.name.as_str());
                    failed.borrow_mut().get_or_insert(format!(
                        "line {}: Multiple events \"{name}\" at timestamp {ts}",
                        ev.line
                    ));
                }
                Err(InputError::UnknownInput(i)) => {
                    failed
                        .borrow_mut()
                        .get_or_insert(format!("line {}: unknown input {i}", ev.line));
                }
            },
        }
        if failed.borrow().is_some() {
            break;
        }
    }
    if failed.borrow().is_none() {
        monitor.flush(&mut sink);
    }
    run.error = failed.into_inner();
    run
}
