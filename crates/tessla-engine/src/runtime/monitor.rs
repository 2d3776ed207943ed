//! Monitor instances: runs a compiled specification ([`Program`]) over timestamped input events.
//!
//! Owns: monitor state and the step semantics (synchronous steps per timestamp, the implicit step
//! at the origin, `last`/`delay` timing, error values). Data flows one way: `crate::front::lower`
//! lowers a checked spec into a [`Program`]; callers (the trace runner, the Telegraf binding)
//! create one [`Monitor`] per instance, push input events and receive output events through a
//! sink callback. The nodes' value code runs as closures compiled by `runtime::exec` when the
//! program's first monitor is created ([`Program::exec`], shared by every instance). This
//! module never parses text and never does I/O.
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
//! - [`Monitor::flush`] evaluates the pending step now (the Telegraf binding calls it after
//!   each record: every record is a step of its own). After it, only later timestamps may be
//!   pushed.
//! - [`Monitor::advance_to`] evaluates the pending step and the delay firings strictly before `ts`
//!   without adding input (the Telegraf binding calls it when an instance's input is silent and
//!   its next firing, [`Monitor::next_firing`], is due by the wall clock).
//! - Runtime errors (division by zero, overflow, `getSome(None)`) are values: an output whose value
//!   is [`Value::Error`] reaches the sink like any other event; the caller reports it.

use crate::ir::{NO_SLOT, Node, NodeId, SArg};
use crate::runtime::exec::{Ctx, Exec, Program};
use crate::runtime::flat::{self, StepState};
use crate::value::{RuntimeError, Value};

use std::cell::RefCell;
use std::sync::Arc;

/// One output event: output `output` (index into [`Program::outputs`]) has `value` at `ts`.
///
/// [`Program::outputs`]: crate::ir::Program::outputs
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

impl std::fmt::Display for InputError {
    /// The input is named by its index (callers holding the program name it).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            InputError::Decreasing { last, got } => {
                write!(f, "Decreasing time stamps: first = {last}, second = {got}")
            }
            InputError::Multiple { input, ts } => {
                write!(f, "Multiple events on input {input} at timestamp {ts}")
            }
            InputError::UnknownInput(i) => write!(f, "unknown input {i}"),
        }
    }
}

impl std::error::Error for InputError {}

/// The state of one program instance: only what must persist between steps. Cheap to clone
/// (the program is shared). Per-step scratch (this step's event of each node, argument buffers)
/// lives in a per-thread buffer shared by all instances, see `Scratch`.
///
/// Layout: `inputs` (one slot per input, filled between steps), `last` (one slot per node read
/// across steps, indexed by [`Program::last_slot`]), `targets` (one armed target per `delay`
/// node, in the order of [`Program::delays`]).
///
/// [`Program::last_slot`]: crate::ir::Program::last_slot
/// [`Program::delays`]: crate::ir::Program::delays
#[derive(Debug, Clone)]
pub struct Monitor {
    program: Arc<Program>,
    t0: i64,
    pending: Option<i64>,
    last_evaluated: Option<i64>,
    inputs: Box<[Option<Value>]>,
    /// The latest value from earlier steps of each node that is read across steps.
    last: Box<[Option<Value>]>,
    /// Armed target of each `Delay` node (parallel to [`Program::delays`]).
    ///
    /// [`Program::delays`]: crate::ir::Program::delays
    targets: Box<[Option<i64>]>,
}

/// Per-step working memory, reused by every monitor on a thread (thousands of instances share
/// one), so an instance holds only its persistent state.
#[derive(Default)]
struct Scratch {
    /// This step's event of each node.
    cur: Vec<Option<Value>>,
    /// Argument buffer of signal lifts with more than three arguments.
    args: Vec<Value>,
    /// The working memory of a program run as a flat plan.
    flat: flat::Scratch,
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// The latest value of node `n` from earlier steps, if it is kept and has had one.
#[inline]
fn last_of<'a>(last: &'a [Option<Value>], slots: &[u32], n: NodeId) -> Option<&'a Value> {
    match slots.get(n) {
        Some(&s) if s != NO_SLOT => last.get(s as usize).and_then(Option::as_ref),
        _ => None,
    }
}

impl Monitor {
    pub fn new(program: Arc<Program>) -> Monitor {
        Monitor::starting_at(program, 0)
    }

    pub fn starting_at(program: Arc<Program>, t0: i64) -> Monitor {
        // The program's code is compiled into closures by its first monitor.
        program.exec();
        Monitor {
            inputs: vec![None; program.inputs.len()].into_boxed_slice(),
            last: vec![None; program.n_last_slots].into_boxed_slice(),
            targets: vec![None; program.delays.len()].into_boxed_slice(),
            program,
            t0,
            pending: None,
            last_evaluated: None,
        }
    }

    /// Bytes one instance holds: the struct and its per-slot arrays (compound values such as
    /// lists share their payload and are not counted).
    pub fn state_bytes(&self) -> usize {
        std::mem::size_of::<Monitor>()
            + std::mem::size_of_val(&*self.inputs)
            + std::mem::size_of_val(&*self.last)
            + std::mem::size_of_val(&*self.targets)
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

    #[inline]
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
        self.open_step(ts, sink)?;
        if self.inputs[input].is_some() {
            return Err(InputError::Multiple { input, ts });
        }
        self.inputs[input] = Some(value);
        Ok(())
    }

    /// Open the step at `ts` without an input event (time advances to `ts`: the pending step
    /// before it and the delays firing before it are evaluated), as TeSSLa's interpreter does
    /// for an event on a stream the spec does not declare. The step at `ts` is evaluated when
    /// time passes it or at [`Monitor::flush`]; a `ts` before the open step is an error.
    pub fn open_step<S: FnMut(OutputEvent<'_>)>(
        &mut self,
        ts: i64,
        sink: &mut S,
    ) -> Result<(), InputError> {
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
        if self.pending != Some(ts) {
            self.advance_to(ts, sink);
            self.pending = Some(ts);
        }
        Ok(())
    }

    /// Evaluate the pending step now.
    #[inline]
    pub fn flush<S: FnMut(OutputEvent<'_>)>(&mut self, sink: &mut S) {
        if let Some(p) = self.pending.take() {
            self.step(p, sink);
        } else if self.last_evaluated.is_none() {
            self.step(self.t0, sink);
        }
    }

    /// Evaluate the pending step (if before `ts`), the first step at t0 if none ran yet, and
    /// every delay firing strictly before `ts`.
    #[inline]
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
        self.targets.iter().filter_map(|t| *t).min()
    }

    /// When the next armed `delay` fires, if one is armed (the Telegraf binding fires it by the
    /// wall clock while the input is silent, through [`Monitor::advance_to`]).
    pub fn next_firing(&self) -> Option<i64> {
        self.next_delay()
    }

    /// The latest time this monitor has reached: its open step, its last evaluated step, or its
    /// origin.
    pub fn clock(&self) -> i64 {
        self.pending
            .into_iter()
            .chain(self.last_evaluated)
            .fold(self.t0, i64::max)
    }

    fn step<S: FnMut(OutputEvent<'_>)>(&mut self, ts: i64, sink: &mut S) {
        // The thread's scratch; a nested step (from a sink) gets a fresh one.
        SCRATCH.with(|cell| match cell.try_borrow_mut() {
            Ok(mut sc) => self.eval(ts, &mut sc, sink),
            Err(_) => self.eval(ts, &mut Scratch::default(), sink),
        });
    }

    /// One step: by the program's flat plan when it has one and it has an answer, else by the
    /// general step. Out of line, as the thread's scratch is borrowed around it.
    #[inline(never)]
    fn eval<S: FnMut(OutputEvent<'_>)>(&mut self, ts: i64, sc: &mut Scratch, sink: &mut S) {
        let program = &*self.program;
        let first = self.last_evaluated.is_none();
        if let Some(plan) = program.step_plan() {
            let st = StepState {
                ts,
                first,
                inputs: &self.inputs,
                last: &mut self.last,
                targets: &mut self.targets,
            };
            let mut send = |output, value: &Value| {
                sink(OutputEvent { ts, output, value });
            };
            let cx = &**program.exec();
            let mut call = |node: NodeId, a: &[Option<&Value>]| call_node(program, cx, node, a);
            if plan.step(st, &mut sc.flat, &mut call, &mut send) {
                for i in self.inputs.iter_mut() {
                    release(i.take());
                }
                self.last_evaluated = Some(ts);
                return;
            }
            // No scalar answer for this step: the general step runs it, from the same state.
        }
        self.general(ts, first, sc, sink);
    }

    /// The general step (every node's value as an `Option<Value>`), out of line: its code is
    /// not compiled with the plan's, so a change to one leaves the other's as it was.
    #[inline(never)]
    fn general<S: FnMut(OutputEvent<'_>)>(
        &mut self,
        ts: i64,
        first: bool,
        sc: &mut Scratch,
        sink: &mut S,
    ) {
        let program = &*self.program;
        let slots = &program.last_slot[..];
        let cur = &mut sc.cur;
        // Every entry is `None` between steps (the commit below empties it).
        if cur.len() != program.nodes.len() {
            cur.clear();
            cur.resize(program.nodes.len(), None);
        }
        let last = &mut self.last[..];
        let cx = &**program.exec();
        for &i in &program.order {
            let Some(node) = program.nodes.get(i) else {
                continue;
            };
            let v = match node {
                Node::Input(k) => {
                    // Move the event in place (the slot is empty between steps).
                    if let (Some(inp), Some(c)) = (self.inputs.get_mut(*k), cur.get_mut(i)) {
                        std::mem::swap(inp, c);
                    }
                    continue;
                }
                Node::Nil => None,
                Node::Const(v) => first.then(|| v.clone()),
                Node::Alias(n) => cur[*n].as_ref().map(clone_value),
                Node::Time(n) => cur[*n].as_ref().map(|_| Value::Int(ts)),
                Node::Last { value, trigger } => {
                    if cur[*trigger].is_some() {
                        last_of(last, slots, *value).map(clone_value)
                    } else {
                        None
                    }
                }
                Node::Delay { .. } => {
                    let k = program.delays.iter().position(|d| *d == i);
                    match k.and_then(|k| self.targets.get_mut(k)) {
                        Some(t) if *t == Some(ts) => {
                            *t = None;
                            Some(Value::Unit)
                        }
                        _ => None,
                    }
                }
                Node::Default { stream, value } => cur[*stream]
                    .as_ref()
                    .map(clone_value)
                    .or_else(|| first.then(|| value.clone())),
                Node::DefaultFrom { stream, from } => {
                    cur[*stream].as_ref().map(clone_value).or_else(|| {
                        let s_never = last_of(last, slots, *stream).is_none();
                        let d_first = last_of(last, slots, *from).is_none();
                        if s_never && d_first {
                            cur[*from].as_ref().map(clone_value)
                        } else {
                            None
                        }
                    })
                }
                Node::Lift { args, f } => {
                    if args.iter().any(|a| cur[*a].is_some()) {
                        let lift = |vals: &[Option<&Value>]| {
                            crate::runtime::exec::lift(cx, f, cx.node(i), vals)
                        };
                        // Up to three arguments on the stack, by reference.
                        match args[..] {
                            [a] => lift(&[cur[a].as_ref()]),
                            [a, b] => lift(&[cur[a].as_ref(), cur[b].as_ref()]),
                            [a, b, c] => lift(&[cur[a].as_ref(), cur[b].as_ref(), cur[c].as_ref()]),
                            _ => lift(&args.iter().map(|a| cur[*a].as_ref()).collect::<Vec<_>>()),
                        }
                    } else {
                        None
                    }
                }
                Node::SLift { args, .. } => slift(cur, last, slots, &mut sc.args, args, cx, i),
                Node::Bin { op, a, b, bop } => {
                    if !has_event(cur, a) && !has_event(cur, b) {
                        continue;
                    }
                    let (Some(x), Some(y)) = (arg(cur, last, slots, a), arg(cur, last, slots, b))
                    else {
                        continue;
                    };
                    // Fast path: compute on scalar operands, write the result in place.
                    if let Some(r) = op.eval_values(x, y) {
                        if let Some(c) = cur.get_mut(i) {
                            put(c, r);
                        }
                        continue;
                    }
                    Some(crate::runtime::exec::binary(*bop, x, y))
                }
                Node::Ite { cond, then, other } => {
                    if !has_event(cur, cond) && !has_event(cur, then) && !has_event(cur, other) {
                        continue;
                    }
                    let (Some(c), Some(t), Some(e)) = (
                        arg(cur, last, slots, cond),
                        arg(cur, last, slots, then),
                        arg(cur, last, slots, other),
                    ) else {
                        continue;
                    };
                    let chosen = match c {
                        Value::Bool(true) => t,
                        Value::Bool(false) => e,
                        // An error condition propagates.
                        _ => c,
                    };
                    Some(clone_value(chosen))
                }
                Node::Merge(args) => args.iter().find_map(|a| cur[*a].as_ref().map(clone_value)),
                Node::Filter { stream, cond } => match &cur[*stream] {
                    Some(v) => {
                        let c = cur[*cond].as_ref().or(last_of(last, slots, *cond));
                        match c {
                            Some(Value::Bool(true)) => Some(clone_value(v)),
                            Some(Value::Error(e)) => Some(Value::Error(e.clone())),
                            _ => None,
                        }
                    }
                    None => None,
                },
                Node::Fold { stream, init, .. } => {
                    if first {
                        // The initial value, folded with an event at t = 0 if there is one.
                        Some(match &cur[*stream] {
                            Some(x) => strict2(cx, i, init, x),
                            None => init.clone(),
                        })
                    } else {
                        match (&cur[*stream], last_of(last, slots, i)) {
                            (Some(x), Some(acc)) => Some(strict2(cx, i, acc, x)),
                            _ => None,
                        }
                    }
                }
                Node::Reduce { stream, .. } => match (&cur[*stream], last_of(last, slots, i)) {
                    (Some(x), Some(acc)) => Some(strict2(cx, i, acc, x)),
                    (Some(x), None) => Some(x.clone()),
                    _ => None,
                },
            };
            if let Some(v) = v
                && let Some(c) = cur.get_mut(i)
            {
                put(c, v);
            }
        }
        // Arm delays after the whole step: their delay argument is lazy and may come later.
        for (k, &i) in program.delays.iter().enumerate() {
            if let Some(Node::Delay { delay, reset }) = program.nodes.get(i) {
                let reset_now = cur[*reset].is_some();
                // A delay that fired this step has its unit event now.
                let fired_now = matches!(cur[i], Some(Value::Unit));
                let Some(target) = self.targets.get_mut(k) else {
                    continue;
                };
                if reset_now && !fired_now {
                    *target = None;
                }
                if reset_now || fired_now {
                    match &cur[*delay] {
                        Some(Value::Int(d)) if *d > 0 => *target = Some(ts.saturating_add(*d)),
                        Some(Value::Int(_)) => {
                            cur[i] = Some(Value::Error(RuntimeError::NonPositiveDelay));
                        }
                        _ => {}
                    }
                }
            }
        }
        for (out, &n) in program.output_nodes.iter().enumerate() {
            if let Some(v) = &cur[n] {
                sink(OutputEvent {
                    ts,
                    output: out,
                    value: v,
                });
            }
        }
        // Commit: keep the values read across steps, empty the scratch for the next step.
        for (&s, c) in slots.iter().zip(cur.iter_mut()) {
            if c.is_some() {
                if s != NO_SLOT
                    && let Some(l) = last.get_mut(s as usize)
                {
                    // Swap in place, then drop the previous value.
                    std::mem::swap(c, l);
                }
                release(c.take());
            }
        }
        for i in self.inputs.iter_mut() {
            *i = None;
        }
        self.last_evaluated = Some(ts);
    }
}

/// Drop a value, without a call into its drop glue for the scalars that make up most events
/// (nothing to free).
#[inline(always)]
fn release(v: Option<Value>) {
    match v {
        None | Some(Value::Unit | Value::Bool(_) | Value::Int(_) | Value::Float(_)) => {
            std::mem::forget(v)
        }
        v => drop(v),
    }
}

/// A copy of a value: scalars inline, without a call into `Value::clone`.
#[inline(always)]
fn clone_value(v: &Value) -> Value {
    match v {
        Value::Float(x) => Value::Float(*x),
        Value::Int(x) => Value::Int(*x),
        Value::Bool(x) => Value::Bool(*x),
        Value::Unit => Value::Unit,
        v => v.clone(),
    }
}

/// Put this step's event of a node in its slot (empty between steps, so nothing is dropped
/// but by [`release`]).
#[inline(always)]
fn put(slot: &mut Option<Value>, v: Value) {
    // A swap, not an assignment: moves the 24-byte value without a round trip through the
    // stack (which stalls store forwarding on x86).
    let mut v = Some(v);
    std::mem::swap(slot, &mut v);
    release(v);
}

/// Whether a signal-lift argument has an event in this step.
#[inline]
fn has_event(cur: &[Option<Value>], a: &SArg) -> bool {
    matches!(a, SArg::Stream(n) if cur.get(*n).is_some_and(Option::is_some))
}

/// The current or latest value of a signal-lift argument, by reference.
#[inline]
fn arg<'a>(
    cur: &'a [Option<Value>],
    last: &'a [Option<Value>],
    slots: &[u32],
    a: &'a SArg,
) -> Option<&'a Value> {
    match a {
        SArg::Const(v) => Some(v),
        SArg::Stream(n) => cur
            .get(*n)
            .and_then(Option::as_ref)
            .or_else(|| last_of(last, slots, *n)),
    }
}

/// Signal lift. Checks for an event first (most nodes have none in a step), then passes up to
/// three arguments in a stack array and more in a reused buffer, so a step allocates nothing for
/// scalar values.
#[inline(always)]
fn slift(
    cur: &[Option<Value>],
    last: &[Option<Value>],
    slots: &[u32],
    buf: &mut Vec<Value>,
    args: &[SArg],
    cx: &Ctx,
    node: NodeId,
) -> Option<Value> {
    let has_event = args
        .iter()
        .any(|a| matches!(a, SArg::Stream(n) if cur[*n].is_some()));
    if !has_event {
        return None;
    }
    if let Some(fast) = cx.fast(node) {
        // By reference: no frame of cloned values, no closure call.
        let arg = |a| arg(cur, last, slots, a);
        let r = match args {
            [a] => fast.run(&[arg(a)?]),
            [a, b] => fast.run(&[arg(a)?, arg(b)?]),
            [a, b, c] => fast.run(&[arg(a)?, arg(b)?, arg(c)?]),
            _ => None,
        };
        if r.is_some() {
            return r;
        }
    }
    let f = cx.node(node);
    let get = |a: &SArg| match a {
        SArg::Const(v) => Some(v.clone()),
        SArg::Stream(n) => cur[*n].as_ref().or(last_of(last, slots, *n)).cloned(),
    };
    match args {
        [a] => return Some(call(cx, f, &[get(a)?])),
        [a, b] => return Some(call(cx, f, &[get(a)?, get(b)?])),
        [a, b, c] => return Some(call(cx, f, &[get(a)?, get(b)?, get(c)?])),
        _ => {}
    }
    buf.clear();
    for a in args {
        buf.push(get(a)?);
    }
    let r = call(cx, f, buf);
    buf.clear();
    Some(r)
}

/// The evaluator's state fields, per node (`last`, `targets` indexed by node id) whatever the
/// monitor stores: what [`snapshot`](super::snapshot) saves and restores. Defined here, beside
/// the fields it mirrors, so the snapshot module reads the monitor and never the other way round.
pub(crate) struct RawState {
    pub t0: i64,
    pub pending: Option<i64>,
    pub last_evaluated: Option<i64>,
    pub inputs: Vec<Option<Value>>,
    pub last: Vec<Option<Value>>,
    pub targets: Vec<Option<i64>>,
}

/// State access for [`snapshot`](super::snapshot), the only code besides this file that depends
/// on the layout of the fields: this converts [`RawState`] from and to the slot layout
/// ([`Program::last_slot`], [`Program::delays`]).
///
/// [`Program::last_slot`]: crate::ir::Program::last_slot
/// [`Program::delays`]: crate::ir::Program::delays
impl Monitor {
    pub(crate) fn raw_state(&self) -> RawState {
        let program = &self.program;
        let n = program.nodes.len();
        let mut last = vec![None; n];
        for (node, &slot) in program.last_slot.iter().enumerate() {
            if slot != NO_SLOT
                && let (Some(dst), Some(v)) = (last.get_mut(node), self.last.get(slot as usize))
            {
                *dst = v.clone();
            }
        }
        let mut targets = vec![None; n];
        for (k, &node) in program.delays.iter().enumerate() {
            if let (Some(dst), Some(t)) = (targets.get_mut(node), self.targets.get(k)) {
                *dst = *t;
            }
        }
        RawState {
            t0: self.t0,
            pending: self.pending,
            last_evaluated: self.last_evaluated,
            inputs: self.inputs.to_vec(),
            last,
            targets,
        }
    }

    /// A monitor of `program` in state `raw` (per-node vectors of another length are cut or
    /// padded; values of nodes without a slot are not kept).
    pub(crate) fn from_raw_state(program: Arc<Program>, raw: RawState) -> Monitor {
        let mut m = Monitor::starting_at(program, raw.t0);
        m.pending = raw.pending;
        m.last_evaluated = raw.last_evaluated;
        for (slot, v) in m.inputs.iter_mut().zip(raw.inputs) {
            *slot = v;
        }
        let program = Arc::clone(&m.program);
        for (node, v) in raw.last.into_iter().enumerate() {
            if let Some(&slot) = program.last_slot.get(node)
                && slot != NO_SLOT
                && let Some(dst) = m.last.get_mut(slot as usize)
            {
                *dst = v;
            }
        }
        for (k, &node) in program.delays.iter().enumerate() {
            if let (Some(dst), Some(t)) = (m.targets.get_mut(k), raw.targets.get(node)) {
                *dst = *t;
            }
        }
        m
    }
}

/// `f(acc, x)` of a `fold` or `reduce` node, strict in the accumulator.
#[inline(always)]
fn strict2(cx: &Ctx, node: NodeId, a: &Value, b: &Value) -> Value {
    if let Value::Error(e) = a {
        return Value::Error(e.clone());
    }
    if let Some(r) = cx.fast(node).and_then(|f| f.run(&[a, b])) {
        return r;
    }
    call(cx, cx.node(node), &[a.clone(), b.clone()])
}

/// Node `node`'s value from its operands, for the flat plan's calls: what the general step
/// computes for a signal lift, an operator, a `fold` or `reduce` (operands: the kept value, the
/// event) and a `lift` (operands: the events).
fn call_node(program: &Program, cx: &Ctx, node: NodeId, a: &[Option<&Value>]) -> Option<Value> {
    match program.nodes.get(node)? {
        Node::Lift { f, .. } => crate::runtime::exec::lift(cx, f, cx.node(node), a),
        Node::Bin { op, bop, .. } => {
            let (x, y) = (a.first().copied()??, a.get(1).copied()??);
            Some(
                op.eval_values(x, y)
                    .unwrap_or_else(|| crate::runtime::exec::binary(*bop, x, y)),
            )
        }
        Node::Fold { .. } | Node::Reduce { .. } => {
            Some(strict2(cx, node, a.first().copied()??, a.get(1).copied()??))
        }
        Node::SLift { .. } => {
            if let Some(fast) = cx.fast(node) {
                let r = match a {
                    [Some(x)] => fast.run(&[x]),
                    [Some(x), Some(y)] => fast.run(&[x, y]),
                    [Some(x), Some(y), Some(z)] => fast.run(&[x, y, z]),
                    _ => None,
                };
                if r.is_some() {
                    return r;
                }
            }
            let f = cx.node(node);
            let g = |v: &Option<&Value>| v.map(clone_value);
            Some(match a {
                [x] => call(cx, f, &[g(x)?]),
                [x, y] => call(cx, f, &[g(x)?, g(y)?]),
                [x, y, z] => call(cx, f, &[g(x)?, g(y)?, g(z)?]),
                _ => call(cx, f, &a.iter().map(g).collect::<Option<Vec<_>>>()?),
            })
        }
        _ => None,
    }
}

/// Call a node's compiled function (every node that has code has one).
#[inline]
fn call(cx: &Ctx, f: Option<&Exec>, args: &[Value]) -> Value {
    match f {
        Some(f) => f(cx, args),
        None => Value::Error(RuntimeError::Other("function not compiled".into())),
    }
}
