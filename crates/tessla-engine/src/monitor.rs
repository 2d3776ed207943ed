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

use crate::ir::{Node, Program, SArg};
use crate::value::{RuntimeError, Value};

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
    t0: i64,
    pending: Option<i64>,
    last_evaluated: Option<i64>,
    inputs: Vec<Option<Value>>,
    /// The latest value of each node from earlier steps.
    last: Vec<Option<Value>>,
    /// Scratch: this step's event of each node.
    cur: Vec<Option<Value>>,
    /// Armed delay target of each `Delay` node.
    targets: Vec<Option<i64>>,
    /// Reused argument buffer of signal lifts.
    scratch: Vec<Value>,
}

impl Monitor {
    pub fn new(program: Arc<Program>) -> Monitor {
        Monitor::starting_at(program, 0)
    }

    pub fn starting_at(program: Arc<Program>, t0: i64) -> Monitor {
        let n = program.nodes.len();
        Monitor {
            inputs: vec![None; program.inputs.len()],
            last: vec![None; n],
            cur: vec![None; n],
            targets: vec![None; n],
            scratch: Vec::new(),
            program,
            t0,
            pending: None,
            last_evaluated: None,
        }
    }

    pub fn program(&self) -> &Arc<Program> {
        &self.program
    }

    /// Timestamp of the step collecting inputs, if one is open.
    pub fn pending(&self) -> Option<i64> {
        self.pending
    }

    /// Timestamp of the last evaluated step, if any.
    pub fn last_evaluated(&self) -> Option<i64> {
        self.last_evaluated
    }

    pub fn push<S: FnMut(OutputEvent<'_>)>(
        &mut self,
        ts: i64,
        input: usize,
        value: Value,
        sink: &mut S,
    ) -> Result<(), InputError> {
        if input >= self.inputs.len() {
            return Err(InputError::UnknownInput(input));
        }
        if let Some(p) = self.pending {
            if ts < p {
                return Err(InputError::Decreasing { last: p, got: ts });
            }
        } else if let Some(l) = self.last_evaluated
            && ts <= l
        {
            return Err(InputError::Decreasing { last: l, got: ts });
        } else if self.last_evaluated.is_none() && ts < self.t0 {
            return Err(InputError::Decreasing {
                last: self.t0,
                got: ts,
            });
        }
        if self.pending == Some(ts) {
            if self.inputs[input].is_some() {
                return Err(InputError::Multiple { input, ts });
            }
        } else {
            self.advance_to(ts, sink);
            self.pending = Some(ts);
        }
        self.inputs[input] = Some(value);
        Ok(())
    }

    /// Evaluate the pending step now.
    pub fn flush<S: FnMut(OutputEvent<'_>)>(&mut self, sink: &mut S) {
        if let Some(p) = self.pending.take() {
            self.step(p, sink);
        } else if self.last_evaluated.is_none() {
            self.step(self.t0, sink);
        }
    }

    /// Evaluate the pending step (if before `ts`), the first step at t0 if none ran yet, and
    /// every delay firing strictly before `ts`.
    pub fn advance_to<S: FnMut(OutputEvent<'_>)>(&mut self, ts: i64, sink: &mut S) {
        if let Some(p) = self.pending
            && p < ts
        {
            self.pending = None;
            self.step(p, sink);
        }
        if self.pending.is_none() && self.last_evaluated.is_none() && self.t0 < ts {
            self.step(self.t0, sink);
        }
        if self.pending.is_some() {
            return;
        }
        while let Some(t) = self.next_delay().filter(|t| *t < ts) {
            self.step(t, sink);
        }
    }

    fn next_delay(&self) -> Option<i64> {
        self.program
            .delays
            .iter()
            .filter_map(|d| self.targets.get(*d).copied().flatten())
            .min()
    }

    fn step<S: FnMut(OutputEvent<'_>)>(&mut self, ts: i64, sink: &mut S) {
        let program = Arc::clone(&self.program);
        let first = self.last_evaluated.is_none();
        for c in self.cur.iter_mut() {
            *c = None;
        }
        let mut fired = Vec::new();
        for &i in &program.order {
            let v = match &program.nodes[i] {
                Node::Input(k) => self.inputs.get_mut(*k).and_then(Option::take),
                Node::Nil => None,
                Node::Const(v) => first.then(|| v.clone()),
                Node::Alias(n) => self.cur[*n].clone(),
                Node::Time(n) => self.cur[*n].as_ref().map(|_| Value::Int(ts)),
                Node::Last { value, trigger } => {
                    if self.cur[*trigger].is_some() {
                        self.last[*value].clone()
                    } else {
                        None
                    }
                }
                Node::Delay { .. } => {
                    if self.targets[i] == Some(ts) {
                        self.targets[i] = None;
                        fired.push(i);
                        Some(Value::Unit)
                    } else {
                        None
                    }
                }
                Node::Default { stream, value } => self.cur[*stream]
                    .clone()
                    .or_else(|| first.then(|| value.clone())),
                Node::DefaultFrom { stream, from } => self.cur[*stream].clone().or_else(|| {
                    let s_never = self.last[*stream].is_none();
                    let d_first = self.last[*from].is_none();
                    if s_never && d_first {
                        self.cur[*from].clone()
                    } else {
                        None
                    }
                }),
                Node::Lift { args, f } => {
                    if args.iter().any(|a| self.cur[*a].is_some()) {
                        let vals: Vec<Option<Value>> =
                            args.iter().map(|a| self.cur[*a].clone()).collect();
                        f(&vals)
                    } else {
                        None
                    }
                }
                Node::SLift { args, f } => self.slift(args, f),
                Node::Merge(args) => args.iter().find_map(|a| self.cur[*a].clone()),
                Node::Filter { stream, cond } => match &self.cur[*stream] {
                    Some(v) => {
                        let c = self.cur[*cond].as_ref().or(self.last[*cond].as_ref());
                        match c {
                            Some(Value::Bool(true)) => Some(v.clone()),
                            Some(Value::Error(e)) => Some(Value::Error(e.clone())),
                            _ => None,
                        }
                    }
                    None => None,
                },
                Node::Fold { stream, init, f } => {
                    if first {
                        // The initial value, folded with an event at t = 0 if there is one.
                        Some(match &self.cur[*stream] {
                            Some(x) => strict2(f, init, x),
                            None => init.clone(),
                        })
                    } else {
                        match (&self.cur[*stream], &self.last[i]) {
                            (Some(x), Some(acc)) => Some(strict2(f, acc, x)),
                            _ => None,
                        }
                    }
                }
                Node::Reduce { stream, f } => match (&self.cur[*stream], &self.last[i]) {
                    (Some(x), Some(acc)) => Some(strict2(f, acc, x)),
                    (Some(x), None) => Some(x.clone()),
                    _ => None,
                },
            };
            self.cur[i] = v;
        }
        // Arm delays after the whole step: their delay argument is lazy and may come later.
        for &i in &program.delays {
            if let Some(Node::Delay { delay, reset }) = program.nodes.get(i) {
                let reset_now = self.cur[*reset].is_some();
                let fired_now = fired.contains(&i);
                if reset_now && !fired_now {
                    self.targets[i] = None;
                }
                if reset_now || fired_now {
                    match &self.cur[*delay] {
                        Some(Value::Int(d)) if *d > 0 => {
                            self.targets[i] = Some(ts.saturating_add(*d))
                        }
                        Some(Value::Int(_)) => {
                            self.cur[i] = Some(Value::Error(RuntimeError::NonPositiveDelay));
                        }
                        _ => {}
                    }
                }
            }
        }
        for (out, &n) in program.output_nodes.iter().enumerate() {
            if let Some(v) = &self.cur[n] {
                sink(OutputEvent {
                    ts,
                    output: out,
                    value: v,
                });
            }
        }
        for (l, c) in self.last.iter_mut().zip(self.cur.iter_mut()) {
            if let Some(v) = c.take() {
                *l = Some(v);
            }
        }
        for i in self.inputs.iter_mut() {
            *i = None;
        }
        self.last_evaluated = Some(ts);
    }

    /// Signal lift. Checks for an event first (most nodes have none in a step), then fills a
    /// reused argument buffer, so a step allocates nothing for scalar values.
    fn slift(&mut self, args: &[SArg], f: &crate::ir::Func) -> Option<Value> {
        let has_event = args
            .iter()
            .any(|a| matches!(a, SArg::Stream(n) if self.cur[*n].is_some()));
        if !has_event {
            return None;
        }
        // Up to three arguments (nearly every operator) are passed in a stack array.
        let get = |a: &SArg| match a {
            SArg::Const(v) => Some(v.clone()),
            SArg::Stream(n) => self.cur[*n].as_ref().or(self.last[*n].as_ref()).cloned(),
        };
        match args {
            [a] => return Some(f(&[get(a)?])),
            [a, b] => return Some(f(&[get(a)?, get(b)?])),
            [a, b, c] => return Some(f(&[get(a)?, get(b)?, get(c)?])),
            _ => {}
        }
        let mut vals = std::mem::take(&mut self.scratch);
        vals.clear();
        for a in args {
            match a {
                SArg::Const(v) => vals.push(v.clone()),
                SArg::Stream(n) => match self.cur[*n].as_ref().or(self.last[*n].as_ref()) {
                    Some(v) => vals.push(v.clone()),
                    None => {
                        self.scratch = vals;
                        return None;
                    }
                },
            }
        }
        let r = f(&vals);
        self.scratch = vals;
        Some(r)
    }
}

/// State access for [`crate::snapshot`], the only code that depends on the layout of the fields.
impl Monitor {
    pub(crate) fn raw_state(&self) -> crate::snapshot::RawState {
        crate::snapshot::RawState {
            t0: self.t0,
            pending: self.pending,
            last_evaluated: self.last_evaluated,
            inputs: self.inputs.clone(),
            last: self.last.clone(),
            targets: self.targets.clone(),
        }
    }

    /// A monitor of `program` in state `raw` (vectors of another length are cut or padded).
    pub(crate) fn from_raw_state(program: Arc<Program>, raw: crate::snapshot::RawState) -> Monitor {
        let mut m = Monitor::starting_at(program, raw.t0);
        m.pending = raw.pending;
        m.last_evaluated = raw.last_evaluated;
        for (slot, v) in m.inputs.iter_mut().zip(raw.inputs) {
            *slot = v;
        }
        for (slot, v) in m.last.iter_mut().zip(raw.last) {
            *slot = v;
        }
        for (slot, v) in m.targets.iter_mut().zip(raw.targets) {
            *slot = v;
        }
        m
    }
}

fn strict2(f: &crate::ir::Func, a: &Value, b: &Value) -> Value {
    if let Value::Error(e) = a {
        return Value::Error(e.clone());
    }
    f(&[a.clone(), b.clone()])
}
