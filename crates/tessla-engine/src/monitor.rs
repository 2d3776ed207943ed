//! Monitor instances: runs a compiled specification ([`Program`]) over timestamped input events.
//!
//! Owns: monitor state and the step semantics (synchronous steps per timestamp, the implicit step
//! at the origin, `last`/`delay` timing, error values). Data flows one way: the front end
//! (`crate::check`) lowers a checked spec into a [`Program`]; callers (the trace runner, the Telegraf binding) create one [`Monitor`] per instance, push input events and receive output
//! events through a sink callback. This module never parses text and never does I/O.
//!
//! API contract (used by the trace runner and the Telegraf binding):
//! - [`Monitor::new`] starts at TeSSLa time 0; [`Monitor::starting_at`] puts the implicit first
//!   step (constants, `count`'s 0, `period`'s first tick) at `t0` instead, so a Telegraf run whose
//!   first record is at epoch-ns `t0` does not replay 1970..t0.
//! - [`Monitor::push`] adds one input event at `ts`. If `ts` is later than the pending step, the
//!   pending step and every `delay` firing strictly before `ts` are evaluated first, with their
//!   outputs sent to `sink`. Errors: `ts` earlier than the pending step (decreasing), or a second
//!   event on the same input at the same `ts` (multiple events), or `ts` not later than the last
//!   evaluated step (after a [`Monitor::flush`]).
//! - [`Monitor::flush`] evaluates the pending step now (the Telegraf binding calls it as soon as
//!   no more input is available). After it, only later timestamps may be pushed.
//! - [`Monitor::advance_to`] evaluates the pending step and the delay firings strictly before `ts`
//!   without adding input (used for idle time).
//! - Runtime errors (division by zero, overflow, `getSome(None)`) are values: an output whose value
//!   is [`Value::Error`] reaches the sink like any other event; the caller reports it.

use crate::ir::Program;
use crate::value::Value;

use std::sync::Arc;

/// One output event: output `output` (index into [`Program::outputs`]) has `value` at `ts`.
#[derive(Debug, Clone, Copy)]
pub struct OutputEvent<'a> {
    pub ts: i64,
    pub output: usize,
    pub value: &'a Value,
}

/// Why an input event was refused. The monitor state is unchanged by a refused event.
#[derive(Debug, Clone, PartialEq)]
pub enum InputError {
    /// `got` is earlier than the pending or last evaluated timestamp `last`.
    Decreasing { last: i64, got: i64 },
    /// A second event on input `input` at `ts`.
    Multiple { input: usize, ts: i64 },
    /// No input with that index.
    UnknownInput(usize),
}

/// The state of every stream of one program instance. Cheap to clone (the program is shared).
#[derive(Debug, Clone)]
pub struct Monitor {
    program: Arc<Program>,
}

impl Monitor {
    pub fn new(program: Arc<Program>) -> Monitor {
        Monitor::starting_at(program, 0)
    }

    pub fn starting_at(program: Arc<Program>, t0: i64) -> Monitor {
        let _ = (program, t0);
        todo!("engine: implemented by the core")
    }

    pub fn program(&self) -> &Arc<Program> {
        &self.program
    }

    /// Timestamp of the step collecting inputs, if one is open.
    pub fn pending(&self) -> Option<i64> {
        todo!()
    }

    /// Timestamp of the last evaluated step, if any.
    pub fn last_evaluated(&self) -> Option<i64> {
        todo!()
    }

    pub fn push<S: FnMut(OutputEvent<'_>)>(
        &mut self,
        ts: i64,
        input: usize,
        value: Value,
        sink: &mut S,
    ) -> Result<(), InputError> {
        let _ = (ts, input, value, sink);
        todo!()
    }

    pub fn flush<S: FnMut(OutputEvent<'_>)>(&mut self, sink: &mut S) {
        let _ = sink;
        todo!()
    }

    pub fn advance_to<S: FnMut(OutputEvent<'_>)>(&mut self, ts: i64, sink: &mut S) {
        let _ = (ts, sink);
        todo!()
    }
}
