//! The flat plan: a program whose streams carry scalars, and values that are only passed on or
//! compared (tuples, strings, constants), run as a list of typed instructions over plain slots.
//!
//! Owns: [`Plan`] (made once per program by `runtime::exec`, beside its compiled code, when
//! every node the program evaluates has a form here; `build` makes it), [`Kernel`] (a node
//! function that is one scalar operator on its arguments, handed over by `exec` from its fast
//! forms), [`Slot`] (this step's event of a node: its bits and whether there is one), the
//! instructions and the plan's step ([`Plan::step`]).
//!
//! Why: the general step (`runtime::monitor`) moves an `Option<Value>` of 24 bytes per node
//! through a match over every node kind, tests its operands' types per operation and drops it
//! at the end of the step. A spec like P2 is 22 nodes of `Float`, `Int` and `Bool`. Their types
//! are known when the plan is made, so here each node is one instruction of a known type on a
//! 64-bit slot, with nothing to test but presence and nothing to drop.
//!
//! A value that is not a scalar (`Kind::Val`: a tuple input, a string constant) is never
//! copied during the step: its slot holds a reference to where it already is (this step's input
//! event, a kept value, a constant), an output is sent by reference, and only a kept one is
//! cloned into the monitor's state (for a tuple, one reference count).
//!
//! A plan without calls, values or delays also has a straight block (`Block`, made by `build`'s
//! clock analysis): for the steps where every input has an event (after the first), the nodes
//! that then fire for certain (operators and signal lifts of such nodes and constants, `fold`s
//! and `reduce`s of them) run without presence tests or kept-value fallbacks; the rest run as
//! in the loop. On P2 every node but the `filter` is straight. The block is compiled once
//! (`fused`): each node one instruction whose variant names its operator and its operands'
//! shape, so a node costs one dispatch; after a step of the block, the kept nodes it fires for
//! certain are written back by kind, without a presence test.
//!
//! Every other node has a form too: `delay` (its target read in the step, armed after it), and
//! a call (`Instr::Call`) of the node's compiled function for what has no typed form (natives,
//! user functions, lifts of functions, folds over Maps): its value is kept for the step in
//! `Scratch::temps`. A plan with calls costs more than the general step (measured), so the
//! monitor runs it only when asked (`Program::with_calls`); `check --ir` names the calls.
//!
//! The plan computes exactly what the general step does. Whatever it has no scalar answer for
//! (an `Int` overflow, a kept value that is an error value or a big integer, an input value of
//! another type, `==` on an error value) makes it give up before it has sent or changed anything: [`Plan::step`]
//! returns `false` and the monitor runs the general step on the same state. The plan reads and
//! writes the monitor's state as the general step keeps it (`Option<Value>` per kept node), so
//! the two can take turns at any step.

use crate::ir::{self, ScalarOp};
use crate::value::Value;

/// The type of a node's values in a plan.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Unit,
    Bool,
    Int,
    Float,
    /// Any other value (a tuple, a string, an option, ...), only ever moved or compared with
    /// `==`/`!=`, never computed on: its bits are a reference ([`Ref`]) to an input event, a
    /// kept value or one of the plan's constants, which stay in place for the whole step.
    Val,
}

/// Where a [`Kind::Val`] value is: the tag in the high 32 bits of its slot's bits, the index in
/// the low 32.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Ref {
    /// This step's event of input `i` ([`StepState::inputs`]).
    Input(u32),
    /// The value kept in slot `i` of [`StepState::last`].
    Last(u32),
    /// The plan's constant `i` ([`Plan::consts`]).
    Const(u32),
    /// The value node `i` computed this step by a call (`Instr::Call`), in [`Scratch::temps`].
    Temp(u32),
}

impl Ref {
    const INPUT: u64 = 0;
    const LAST: u64 = 1;
    const CONST: u64 = 2;
    const TEMP: u64 = 3;

    #[inline(always)]
    fn bits(self) -> u64 {
        match self {
            Ref::Input(i) => (Ref::INPUT << 32) | u64::from(i),
            Ref::Last(i) => (Ref::LAST << 32) | u64::from(i),
            Ref::Const(i) => (Ref::CONST << 32) | u64::from(i),
            Ref::Temp(i) => (Ref::TEMP << 32) | u64::from(i),
        }
    }

    #[inline(always)]
    fn of(bits: u64) -> Ref {
        let i = bits as u32;
        match bits >> 32 {
            Ref::INPUT => Ref::Input(i),
            Ref::LAST => Ref::Last(i),
            Ref::CONST => Ref::Const(i),
            _ => Ref::Temp(i),
        }
    }
}

/// What a step's references ([`Ref`]) point into.
#[derive(Clone, Copy)]
struct Vals<'a> {
    inputs: &'a [Option<Value>],
    last: &'a [Option<Value>],
    consts: &'a [Value],
    temps: &'a [Option<Value>],
}

impl<'a> Vals<'a> {
    /// The value `bits` refers to (`None` only for a reference out of range or to an empty
    /// slot, which a plan never makes).
    #[inline(always)]
    fn get(self, bits: u64) -> Option<&'a Value> {
        match Ref::of(bits) {
            Ref::Input(i) => self.inputs.get(i as usize)?.as_ref(),
            Ref::Last(i) => self.last.get(i as usize)?.as_ref(),
            Ref::Const(i) => self.consts.get(i as usize),
            Ref::Temp(i) => self.temps.get(i as usize)?.as_ref(),
        }
    }
}

impl Kind {
    fn of_type(t: &ir::Type) -> Kind {
        match t {
            ir::Type::Unit => Kind::Unit,
            ir::Type::Bool => Kind::Bool,
            ir::Type::Int => Kind::Int,
            ir::Type::Float => Kind::Float,
            _ => Kind::Val,
        }
    }

    /// The kind and bits of a scalar value.
    fn of_value(v: &Value) -> Option<(Kind, u64)> {
        Some(match v {
            Value::Unit => (Kind::Unit, 0),
            Value::Bool(b) => (Kind::Bool, u64::from(*b)),
            Value::Int(i) => (Kind::Int, *i as u64),
            Value::Float(x) => (Kind::Float, x.to_bits()),
            _ => return None,
        })
    }

    /// The bits of `v`, if it is a value of this kind.
    #[inline(always)]
    fn bits(self, v: &Value) -> Option<u64> {
        match (self, v) {
            (Kind::Float, Value::Float(x)) => Some(x.to_bits()),
            (Kind::Int, Value::Int(i)) => Some(*i as u64),
            (Kind::Bool, Value::Bool(b)) => Some(u64::from(*b)),
            (Kind::Unit, Value::Unit) => Some(0),
            _ => None,
        }
    }
}

/// This step's event of a node: its bits (an `f64`'s, an `i64`'s, 0 or 1), when it has one.
#[derive(Clone, Copy, Debug, Default)]
pub struct Slot {
    bits: u64,
    has: bool,
}

/// An operand of a [`Kernel`]: argument `i` of the node (for `fold` and `reduce`: 0 the
/// accumulator, 1 the event), or a constant.
#[derive(Clone, Debug)]
pub enum KArg {
    Arg(u8),
    Const(Value),
}

/// A node function the plan runs: one scalar operator on the node's arguments and constants.
#[derive(Clone, Debug)]
pub enum Kernel {
    /// A binary operator with an inline scalar path (`+.`, `<`, `&&`, ...).
    Op(ScalarOp, KArg, KArg),
    /// `*`, `/`, `%` on integers.
    Int(IntOp, KArg, KArg),
    /// `==` (`ne: false`) or `!=` on two scalars of one type.
    Eq {
        ne: bool,
        a: KArg,
        b: KArg,
    },
    Not(KArg),
    FNeg(KArg),
    IntToFloat(KArg),
    Const(Value),
    /// Argument `i` itself (`slift(a, b) { $0 }`: `a`'s value whenever either has an event).
    Pick(u8),
}

/// An integer operator without an inline scalar path in the IR (the general step computes it
/// with big integers past 64 bits, and division by zero as an error value).
#[derive(Clone, Copy, Debug)]
pub enum IntOp {
    Mul,
    Div,
    Mod,
}

/// A binary operator on typed bits: the IR's scalar operators ([`ScalarOp`], mapped one to one by
/// [`Op2::of`]) and the equalities, in one flat enum (a `Scalar(ScalarOp)` variant nests the
/// dispatch: P2 +1.3% instructions).
#[derive(Clone, Copy, Debug)]
enum Op2 {
    FAdd,
    FSub,
    FMul,
    FDiv,
    FLt,
    FGt,
    FLe,
    FGe,
    IAdd,
    ISub,
    ILt,
    IGt,
    ILe,
    IGe,
    /// `*`, `/`, `%` on integers (`None` on overflow or a zero divisor: the general step's).
    IMul,
    IDiv,
    IMod,
    And,
    Or,
    /// `==`, `!=` on floats.
    FEq,
    FNe,
    /// `==`, `!=` on integers or booleans (equal bits).
    BitsEq,
    BitsNe,
}

impl Op2 {
    fn of(op: ScalarOp) -> Op2 {
        match op {
            ScalarOp::FAdd => Op2::FAdd,
            ScalarOp::FSub => Op2::FSub,
            ScalarOp::FMul => Op2::FMul,
            ScalarOp::FDiv => Op2::FDiv,
            ScalarOp::FLt => Op2::FLt,
            ScalarOp::FGt => Op2::FGt,
            ScalarOp::FLe => Op2::FLe,
            ScalarOp::FGe => Op2::FGe,
            ScalarOp::IAdd => Op2::IAdd,
            ScalarOp::ISub => Op2::ISub,
            ScalarOp::ILt => Op2::ILt,
            ScalarOp::IGt => Op2::IGt,
            ScalarOp::ILe => Op2::ILe,
            ScalarOp::IGe => Op2::IGe,
            ScalarOp::And => Op2::And,
            ScalarOp::Or => Op2::Or,
        }
    }

    fn int(op: IntOp) -> Op2 {
        match op {
            IntOp::Mul => Op2::IMul,
            IntOp::Div => Op2::IDiv,
            IntOp::Mod => Op2::IMod,
        }
    }

    /// The operator `==`/`!=` is on operands of kind `k`.
    fn eq(ne: bool, k: Kind) -> Option<Op2> {
        Some(match (k, ne) {
            (Kind::Float, false) => Op2::FEq,
            (Kind::Float, true) => Op2::FNe,
            (Kind::Int | Kind::Bool, false) => Op2::BitsEq,
            (Kind::Int | Kind::Bool, true) => Op2::BitsNe,
            (Kind::Unit | Kind::Val, _) => return None,
        })
    }

    /// The kinds of its operands and of its result.
    fn kinds(self) -> (Option<Kind>, Kind) {
        use Op2::*;
        match self {
            FAdd | FSub | FMul | FDiv => (Some(Kind::Float), Kind::Float),
            FLt | FGt | FLe | FGe | FEq | FNe => (Some(Kind::Float), Kind::Bool),
            IAdd | ISub | IMul | IDiv | IMod => (Some(Kind::Int), Kind::Int),
            ILt | IGt | ILe | IGe => (Some(Kind::Int), Kind::Bool),
            And | Or => (Some(Kind::Bool), Kind::Bool),
            // Either, the same for both (checked where it is made).
            BitsEq | BitsNe => (None, Kind::Bool),
        }
    }

    /// The result, as `ScalarOp::eval` and the `==` of values compute it; `None` on `Int`
    /// overflow (a big integer: the general step's).
    #[inline(always)]
    fn run(self, a: u64, b: u64) -> Option<u64> {
        let (x, y) = (f64::from_bits(a), f64::from_bits(b));
        let (i, j) = (a as i64, b as i64);
        let t = |c: bool| u64::from(c);
        use Op2::*;
        Some(match self {
            FAdd => (x + y).to_bits(),
            FSub => (x - y).to_bits(),
            FMul => (x * y).to_bits(),
            FDiv => (x / y).to_bits(),
            FLt => t(x < y),
            FGt => t(x > y),
            FLe => t(x <= y),
            FGe => t(x >= y),
            IAdd => i.checked_add(j)? as u64,
            ISub => i.checked_sub(j)? as u64,
            IMul => i.checked_mul(j)? as u64,
            IDiv => i.checked_div(j)? as u64,
            IMod => i.checked_rem(j)? as u64,
            ILt => t(i < j),
            IGt => t(i > j),
            ILe => t(i <= j),
            IGe => t(i >= j),
            And => t(a != 0 && b != 0),
            Or => t(a != 0 || b != 0),
            FEq => t(x == y),
            FNe => t(x != y),
            BitsEq => t(a == b),
            BitsNe => t(a != b),
        })
    }
}

impl Op2 {
    /// A `fold`'s or `reduce`'s step: the operator on its operands from the accumulator and the
    /// event.
    #[inline(always)]
    fn fold(self, a: FArg, b: FArg, acc: u64, x: u64) -> Option<u64> {
        self.run(farg(a, acc, x), farg(b, acc, x))
    }
}

/// A unary operator on typed bits.
#[derive(Clone, Copy, Debug)]
enum Op1 {
    Not,
    FNeg,
    IntToFloat,
}

impl Op1 {
    #[inline(always)]
    fn run(self, a: u64) -> u64 {
        match self {
            Op1::Not => u64::from(a == 0),
            Op1::FNeg => (-f64::from_bits(a)).to_bits(),
            Op1::IntToFloat => ((a as i64) as f64).to_bits(),
        }
    }

    /// The kinds of its operand and of its result.
    fn kinds(self) -> (Kind, Kind) {
        match self {
            Op1::Not => (Kind::Bool, Kind::Bool),
            Op1::FNeg => (Kind::Float, Kind::Float),
            Op1::IntToFloat => (Kind::Int, Kind::Float),
        }
    }
}

/// An event lift's function (the IR's [`ir::LiftFn`] but for `Options` and `AddRemove`, whose
/// values are not scalars, and `ResetTag`, which only `resetCount` uses, beside a fold the plan
/// has no form for); what `runtime::exec::lift` computes.
#[derive(Clone, Copy, Debug)]
enum LiftOp {
    First,
    On,
    Distinct,
    FirstOnly,
    Edge(bool),
}

impl LiftOp {
    /// The events of the arguments in; the node's event out.
    #[inline(always)]
    fn run(self, a: [Slot; 3], kind: Kind, vals: Vals<'_>) -> Slot {
        let [x, y, z] = a;
        match self {
            LiftOp::First => x,
            LiftOp::On => match (x.has, y.has, z.has) {
                (true, true, _) => y,
                (true, false, true) => z,
                _ => NONE,
            },
            LiftOp::Distinct => {
                if x.has && y.has && same_value(kind, x.bits, y.bits, vals) {
                    NONE
                } else {
                    x
                }
            }
            LiftOp::FirstOnly => {
                if x.has && !y.has {
                    x
                } else {
                    NONE
                }
            }
            LiftOp::Edge(want) => match (x.has, y.has) {
                (true, true) => some(u64::from((x.bits != 0) == want && (y.bits != 0) != want)),
                (true, false) => some(0),
                _ => NONE,
            },
        }
    }
}

/// Whether two values of `kind` are equal as values compare (`==` on floats: NaN is not equal
/// to itself, 0.0 equals -0.0).
#[inline(always)]
fn same_value(kind: Kind, a: u64, b: u64, vals: Vals<'_>) -> bool {
    match kind {
        Kind::Float => f64::from_bits(a) == f64::from_bits(b),
        Kind::Val => vals.get(a) == vals.get(b),
        Kind::Unit | Kind::Bool | Kind::Int => a == b,
    }
}

/// `Src::slot` of a constant operand.
const CONST: u32 = u32::MAX - 1;

/// Where an operand's value comes from: node `n`'s event this step, else its latest value from
/// earlier steps (kept in `slot`, or [`NO_SLOT`]); or, with `slot` [`CONST`], the constant
/// `k` (its `n` is the plan's slot that never has an event). `kind` is the value's.
#[derive(Clone, Copy, Debug)]
struct Src {
    n: u32,
    slot: u32,
    kind: Kind,
    k: u64,
}

/// An operand of a `fold` or `reduce` node's operator.
#[derive(Clone, Copy, Debug)]
enum FArg {
    Acc,
    X,
    Const(u64),
}

/// How an `Instr::Call` node takes its operands: the general step's semantics of its form.
#[derive(Clone, Copy, Debug)]
enum CallMode {
    /// A signal lift (`slift`, an operator): fires when one argument has an event and every one
    /// has a value; the function gets their values.
    Signal,
    /// An event lift (`lift`): fires when one argument has an event; the function gets the
    /// events.
    Events,
    /// A `fold` (operands: its own kept value, the stream); `init` is its initial value (a
    /// reference to one of the plan's constants).
    Fold { init: u64 },
    /// A `reduce` (operands: its own kept value, the stream).
    Reduce,
}

/// One node's evaluation; `dst` is the node.
#[derive(Clone, Debug)]
enum Instr {
    Nil {
        dst: u32,
    },
    Input {
        dst: u32,
        input: u32,
        kind: Kind,
    },
    Const {
        dst: u32,
        bits: u64,
    },
    Alias {
        dst: u32,
        src: u32,
    },
    Time {
        dst: u32,
        src: u32,
    },
    /// `value`: the kept value read (its `n` never has an event).
    Last {
        dst: u32,
        value: Src,
        trigger: u32,
    },
    Default {
        dst: u32,
        stream: u32,
        bits: u64,
    },
    DefaultFrom {
        dst: u32,
        stream: Src,
        from: Src,
    },
    Op2 {
        dst: u32,
        op: Op2,
        a: Src,
        b: Src,
    },
    Op1 {
        dst: u32,
        op: Op1,
        a: Src,
    },
    /// `==` (`ne: false`) or `!=` on two values of [`Kind::Val`].
    EqVal {
        dst: u32,
        ne: bool,
        a: Src,
        b: Src,
    },
    /// A signal lift of a constant (`unitIf`'s `()`): fires like a lift of `args`.
    SConst {
        dst: u32,
        args: Box<[Src]>,
        bits: u64,
    },
    /// An event lift (`on`, `first`, `pure`, ...) of up to three arguments' events (`args[..n]`).
    Lift {
        dst: u32,
        f: LiftOp,
        args: [u32; 3],
        n: u8,
        /// The arguments' kind, for `pure`'s comparison.
        kind: Kind,
    },
    /// A signal lift whose value is its argument `pick`: fires like a lift of `args`.
    SPick {
        dst: u32,
        args: Box<[Src]>,
        pick: usize,
    },
    Ite {
        dst: u32,
        cond: Src,
        then: Src,
        other: Src,
    },
    Merge {
        dst: u32,
        args: Box<[u32]>,
    },
    Filter {
        dst: u32,
        stream: u32,
        cond: Src,
    },
    /// `acc`: the node's own kept value.
    Fold {
        dst: u32,
        stream: u32,
        init: u64,
        acc: Src,
        op: Op2,
        a: FArg,
        b: FArg,
    },
    Reduce {
        dst: u32,
        stream: u32,
        acc: Src,
        op: Op2,
        a: FArg,
        b: FArg,
    },
    /// A node whose function the plan has no typed form for (a native, a user function, a
    /// `lift` of a function, a `fold` over a Map, an operator on values that are not scalars):
    /// the monitor's code for node `node` computes its value (the caller handed to
    /// [`Plan::step`]), which goes to [`Scratch::temps`]; the node is of [`Kind::Val`].
    Call {
        dst: u32,
        node: u32,
        args: Box<[Src]>,
        mode: CallMode,
    },
    /// `time` of a node of [`Kind::Val`]: the timestamp as a value in [`Scratch::temps`].
    TimeVal {
        dst: u32,
        src: u32,
    },
    /// `delay`: an event (`bits`) when its target ([`StepState::targets`] `k`) is now; armed
    /// after the step from `amount`'s event when `reset` has one or it fired ([`Plan::arm`]).
    Delay {
        dst: u32,
        k: u32,
        bits: u64,
        amount: Src,
        reset: u32,
    },
}

/// An operand of a [`Straight`] instruction: a node's event, certain to be there, or a
/// constant.
#[derive(Clone, Copy, Debug)]
enum Opnd {
    Node(u32),
    Const(u64),
}

/// One node of the plan's straight block ([`Plan::block`]): its instruction as it runs when
/// the block's clock ticks (every input of the plan has an event, and it is not the first
/// step), where every operand it reads is certain to have its event or is a constant, so
/// nothing is tested for presence and nothing falls back to a kept value.
#[derive(Clone, Debug)]
enum Straight {
    /// An input of a scalar kind (its event is there: the block's condition).
    Input {
        dst: u32,
        input: u32,
        kind: Kind,
    },
    Op2 {
        dst: u32,
        op: Op2,
        a: Opnd,
        b: Opnd,
    },
    Op1 {
        dst: u32,
        op: Op1,
        a: u32,
    },
    Ite {
        dst: u32,
        cond: Opnd,
        then: Opnd,
        other: Opnd,
    },
    /// A `fold` of a stream with its event (`acc`: its own kept value; none kept: the block
    /// gives the step to the plan's loop).
    Fold {
        dst: u32,
        stream: u32,
        acc: Src,
        op: Op2,
        a: FArg,
        b: FArg,
    },
    Reduce {
        dst: u32,
        stream: u32,
        acc: Src,
        op: Op2,
        a: FArg,
        b: FArg,
    },
    /// An event that is its operand's (an alias, a `default` of a stream with its event, a
    /// signal lift picking an argument).
    Copy {
        dst: u32,
        src: Opnd,
    },
    /// `time` of a node with its event.
    Time {
        dst: u32,
    },
    /// Any other node: the plan's instruction, as the plan's loop runs it.
    Other(u32),
}

/// The plan's straight block: the same nodes as [`Plan::instrs`], for the steps where every
/// input has an event (see [`Straight`]). A clock analysis of the plan: a node that is a
/// function of such inputs and constants fires with them, so it needs neither a presence test
/// nor its kept value; what it cannot tell (a `filter`, a `merge`, `last`) runs as before.
#[derive(Debug)]
struct Block {
    /// The inputs that must all have an event (the plan's `Input` instructions').
    inputs: Vec<u32>,
    /// Its nodes, compiled ([`Fused::of`] of each [`Straight`]).
    code: Vec<Fused>,
    /// How many of the nodes run straight (not [`Straight::Other`]).
    straight: usize,
    /// The plan's kept nodes of a scalar kind, as a step of the block writes them back.
    keep: Keep,
}

/// The kept nodes of a scalar kind ([`Plan::kept`]) after a step of the straight block: those
/// it fires for certain, by kind (no presence test, no test of the kind), and the rest.
#[derive(Debug, Default)]
struct Keep {
    float: Vec<(u32, u32)>,
    int: Vec<(u32, u32)>,
    bool: Vec<(u32, u32)>,
    rest: Vec<(u32, u32, Kind)>,
}

impl Keep {
    /// Keep this step's events (the block ran it) in `last`.
    #[inline(always)]
    fn write<S: Cur + ?Sized>(&self, cur: &S, last: &mut [Option<Value>]) {
        for (list, kind) in [
            (&self.float, Kind::Float),
            (&self.int, Kind::Int),
            (&self.bool, Kind::Bool),
        ] {
            for &(n, slot) in list {
                if let Some(l) = last.get_mut(slot as usize) {
                    keep(l, kind, cur_of(cur, n).bits);
                }
            }
        }
        keep_some(&self.rest, cur, last);
    }
}

/// Keep the events of `kept` this step has in `last`.
#[inline(always)]
fn keep_some<S: Cur + ?Sized>(kept: &[(u32, u32, Kind)], cur: &S, last: &mut [Option<Value>]) {
    for &(n, slot, kind) in kept {
        let c = cur_of(cur, n);
        if c.has
            && let Some(l) = last.get_mut(slot as usize)
        {
            keep(l, kind, c.bits);
        }
    }
}

impl Block {
    /// Whether this step is one of the block's: not the first, and every input has an event.
    #[inline(always)]
    fn ticks(&self, st: &StepState<'_>) -> bool {
        !st.first
            && self
                .inputs
                .iter()
                .all(|&i| matches!(st.inputs.get(i as usize), Some(Some(_))))
    }
}

/// An operand's bits in the straight block.
#[inline(always)]
fn opnd<S: Cur + ?Sized>(cur: &S, a: Opnd) -> u64 {
    match a {
        Opnd::Node(n) => cur_of(cur, n).bits,
        Opnd::Const(k) => k,
    }
}

/// A program's step as flat instructions (see the module's documentation).
#[derive(Debug)]
pub struct Plan {
    instrs: Vec<Instr>,
    /// Number of slots: one per node and one that never has an event.
    slots: usize,
    /// (node, slot, kind) of each node of a scalar kind kept across steps.
    kept: Vec<(u32, u32, Kind)>,
    /// (node, slot) of each node of [`Kind::Val`] kept across steps.
    kept_vals: Vec<(u32, u32)>,
    /// The node of each output, with its kind.
    outputs: Vec<(u32, Kind)>,
    /// The values of [`Kind::Val`] constants, by index.
    consts: Vec<Value>,
    /// The nodes whose values go to [`Scratch::temps`] (emptied after each step).
    temp_nodes: Vec<u32>,
    /// (node, its target's index, its amount, its reset) of each `delay`.
    delays: Vec<(u32, u32, Src, u32)>,
    /// Whether the plan has calls, nodes made [`Kind::Val`] or delays (else the step runs a
    /// loop without their code: `eval`'s `FULL`).
    full: bool,
    /// Whether it has an `Instr::Call`.
    calls: bool,
    /// The straight block, for a plan without calls, values or delays whose nodes mostly fire
    /// with its inputs (none: every step runs the loop).
    block: Option<Block>,
}

/// A thread's working memory for plans, shared by every monitor on it.
#[derive(Default)]
pub struct Scratch {
    /// This step's event of each node.
    slots: Vec<Slot>,
    /// The values `Instr::Call` computed this step, by node (empty between steps).
    temps: Vec<Option<Value>>,
    /// Each `delay`'s new target, when this step changes it.
    arms: Vec<Option<Option<i64>>>,
}

/// An operand of a call, held for the call: none, a scalar made from its bits, or a reference
/// to a value where it is.
enum Held<'a> {
    No,
    Own(Value),
    Ref(&'a Value),
}

impl<'a> Held<'a> {
    /// `None`: a reference to nothing (a plan never makes one).
    #[inline(always)]
    fn of(kind: Kind, bits: Option<u64>, vals: Vals<'a>) -> Option<Held<'a>> {
        Some(match bits {
            None => Held::No,
            Some(b) if kind == Kind::Val => Held::Ref(vals.get(b)?),
            Some(b) => Held::Own(scalar(kind, b)),
        })
    }

    #[inline(always)]
    fn get(&self) -> Option<&Value> {
        match self {
            Held::No => None,
            Held::Own(v) => Some(v),
            Held::Ref(r) => Some(r),
        }
    }
}

/// Call node `node`'s function on its operands, each (kind, bits if it has a value); up to four
/// on the stack. `None`: an operand the plan cannot read.
fn call_node<'a, C>(
    call: &mut C,
    node: u32,
    ops: impl ExactSizeIterator<Item = Option<(Kind, Option<u64>)>>,
    vals: Vals<'a>,
) -> Option<Option<Value>>
where
    C: FnMut(usize, &[Option<&Value>]) -> Option<Value>,
{
    let n = ops.len();
    if n <= 4 {
        let mut held = [Held::No, Held::No, Held::No, Held::No];
        for (h, o) in held.iter_mut().zip(ops) {
            let (k, b) = o?;
            *h = Held::of(k, b, vals)?;
        }
        let refs = [held[0].get(), held[1].get(), held[2].get(), held[3].get()];
        Some(call(node as usize, refs.get(..n)?))
    } else {
        let held: Vec<Held<'a>> = ops
            .map(|o| o.and_then(|(k, b)| Held::of(k, b, vals)))
            .collect::<Option<_>>()?;
        let refs: Vec<Option<&Value>> = held.iter().map(Held::get).collect();
        Some(call(node as usize, &refs))
    }
}

/// Whether a condition of `kind` holds: a `Bool`'s bits, or a value of [`Kind::Val`] that is a
/// `Bool`; `None` for any other value (an error value: the general step's to propagate).
#[inline(always)]
fn cond_of(kind: Kind, bits: u64, vals: Vals<'_>) -> Option<bool> {
    if kind == Kind::Val {
        match vals.get(bits)? {
            Value::Bool(b) => Some(*b),
            _ => None,
        }
    } else {
        Some(bits != 0)
    }
}

/// The program has no plan (some node or type has no form here).
struct NoPlan;

/// `Some` or no plan.
fn need<T>(o: Option<T>) -> Result<T, NoPlan> {
    o.ok_or(NoPlan)
}

mod build;
mod fused;

use fused::{Flow, Fused};

/// What one step of a plan reads and writes of a monitor.
pub struct StepState<'a> {
    pub ts: i64,
    /// No step has been evaluated yet (constants and `fold`'s initial value fire).
    pub first: bool,
    /// This step's input events.
    pub inputs: &'a [Option<Value>],
    /// The latest values of the kept nodes; updated when the step completes.
    pub last: &'a mut [Option<Value>],
    /// The armed target of each `delay` (`ir::Program::delays`); updated when the step
    /// completes.
    pub targets: &'a mut [Option<i64>],
}

/// Keep a node's scalar event in its slot of the monitor's state: written in place over one of
/// its kind (the usual case: the slot had the node's previous event).
#[inline(always)]
fn keep(l: &mut Option<Value>, kind: Kind, bits: u64) {
    match (kind, &mut *l) {
        (Kind::Float, Some(Value::Float(x))) => *x = f64::from_bits(bits),
        (Kind::Int, Some(Value::Int(x))) => *x = bits as i64,
        (Kind::Bool, Some(Value::Bool(x))) => *x = bits != 0,
        _ => replace(l, scalar(kind, bits)),
    }
}

/// Put `v` in a kept slot, dropping what was there only when it needs a drop.
#[inline(always)]
fn replace(l: &mut Option<Value>, v: Value) {
    replace_opt(l, Some(v));
}

/// Put `v` in a slot, dropping what was there only when it needs a drop.
#[inline(always)]
fn replace_opt(l: &mut Option<Value>, v: Option<Value>) {
    let old = std::mem::replace(l, v);
    match old {
        // Scalars need no drop.
        None | Some(Value::Unit | Value::Bool(_) | Value::Int(_) | Value::Float(_)) => {
            std::mem::forget(old)
        }
        old => drop(old),
    }
}

/// The value of scalar bits of `kind` (a [`Kind::Val`]'s are not: see [`Vals::get`]).
#[inline(always)]
fn scalar(kind: Kind, bits: u64) -> Value {
    match kind {
        Kind::Float => Value::Float(f64::from_bits(bits)),
        Kind::Int => Value::Int(bits as i64),
        Kind::Bool => Value::Bool(bits != 0),
        Kind::Unit | Kind::Val => Value::Unit,
    }
}

/// Plans of at most this many slots read them from a fixed array (see [`Cur`]).
const SMALL: usize = 256;

/// This step's slots as a plan reads and writes them: a slice (each index tested against its
/// length), or for a plan of at most [`SMALL`] slots a fixed array read by the index masked to
/// its length, which needs no test (every index of such a plan is below its slot count; the
/// slots past it are never read). The tests were a fifth of P2's step.
trait Cur {
    fn at(&self, n: u32) -> Slot;
    fn set(&mut self, n: u32, v: Slot);
}

impl Cur for [Slot] {
    #[inline(always)]
    fn at(&self, n: u32) -> Slot {
        self.get(n as usize).copied().unwrap_or_default()
    }

    #[inline(always)]
    fn set(&mut self, n: u32, v: Slot) {
        if let Some(c) = self.get_mut(n as usize) {
            *c = v;
        }
    }
}

impl Cur for [Slot; SMALL] {
    #[inline(always)]
    fn at(&self, n: u32) -> Slot {
        self[n as usize & (SMALL - 1)]
    }

    #[inline(always)]
    fn set(&mut self, n: u32, v: Slot) {
        self[n as usize & (SMALL - 1)] = v;
    }
}

/// Node `n`'s event this step.
#[inline(always)]
fn cur_of<S: Cur + ?Sized>(cur: &S, n: u32) -> Slot {
    cur.at(n)
}

/// The value kept in `slot` (`Some(None)` for none or [`NO_SLOT`]); `None`: not a scalar of
/// `kind` (an error value, a big integer).
#[inline(always)]
fn kept_of(last: &[Option<Value>], slot: u32, kind: Kind) -> Option<Option<u64>> {
    match last.get(slot as usize) {
        Some(Some(v)) => match kind.bits(v) {
            Some(b) => Some(Some(b)),
            None if kind == Kind::Val => Some(Some(Ref::Last(slot).bits())),
            None => None,
        },
        _ => Some(None),
    }
}

/// An operand's value: this step's event, else the latest one, or the constant.
#[inline(always)]
fn value_of<S: Cur + ?Sized>(cur: &S, last: &[Option<Value>], a: &Src) -> Option<Option<u64>> {
    let c = cur_of(cur, a.n);
    if c.has {
        Some(Some(c.bits))
    } else if a.slot == CONST {
        Some(Some(a.k))
    } else {
        kept_of(last, a.slot, a.kind)
    }
}

#[inline(always)]
fn has_event<S: Cur + ?Sized>(cur: &S, a: &Src) -> bool {
    cur_of(cur, a.n).has
}

/// Whether a signal lift of `args` fires: one has an event and every one has a value (`None`: a
/// kept value the plan cannot read).
#[inline(always)]
fn fires<S: Cur + ?Sized>(cur: &S, last: &[Option<Value>], args: &[Src]) -> Option<bool> {
    if !args.iter().any(|a| has_event(cur, a)) {
        return Some(false);
    }
    let mut all = true;
    for a in args {
        all &= value_of(cur, last, a)?.is_some();
    }
    Some(all)
}

#[inline(always)]
fn some(bits: u64) -> Slot {
    Slot { bits, has: true }
}

const NONE: Slot = Slot {
    bits: 0,
    has: false,
};

/// A `fold`'s or `reduce`'s operand.
#[inline(always)]
fn farg(a: FArg, acc: u64, x: u64) -> u64 {
    match a {
        FArg::Acc => acc,
        FArg::X => x,
        FArg::Const(k) => k,
    }
}

impl Plan {
    /// Evaluate one step into `cur` (the thread's slots), send the outputs to `sink` and keep the
    /// values read across steps in `st.last`. `false`: the plan has no scalar answer for this
    /// step; nothing was sent or changed, and the general step must run it.
    /// `call(node, operands)` computes node `node`'s value the general step's way (its
    /// `Instr::Call`s): the operands of a signal lift, an operator, a `fold` or a `reduce` are
    /// all there; a `lift`'s are its arguments' events.
    #[inline(always)]
    pub fn step<F, C>(
        &self,
        st: StepState<'_>,
        sc: &mut Scratch,
        call: &mut C,
        sink: &mut F,
    ) -> bool
    where
        F: FnMut(usize, &Value),
        C: FnMut(usize, &[Option<&Value>]) -> Option<Value>,
    {
        let Scratch {
            slots: cur,
            temps,
            arms,
        } = sc;
        if self.slots <= SMALL {
            if cur.len() != SMALL {
                cur.clear();
                cur.resize(SMALL, NONE);
            }
            if let Ok(small) = <&mut [Slot; SMALL]>::try_from(cur.as_mut_slice()) {
                return self.run(st, small, temps, arms, call, sink);
            }
        }
        if cur.len() < self.slots {
            cur.clear();
            cur.resize(self.slots, NONE);
        }
        self.run(st, cur.as_mut_slice(), temps, arms, call, sink)
    }

    /// [`Plan::step`] on the thread's slots as `cur`.
    #[inline(always)]
    fn run<S, F, C>(
        &self,
        st: StepState<'_>,
        cur: &mut S,
        temps: &mut Vec<Option<Value>>,
        arms: &mut Vec<Option<Option<i64>>>,
        call: &mut C,
        sink: &mut F,
    ) -> bool
    where
        S: Cur + ?Sized,
        F: FnMut(usize, &Value),
        C: FnMut(usize, &[Option<&Value>]) -> Option<Value>,
    {
        if !self.temp_nodes.is_empty() && temps.len() != self.slots {
            temps.clear();
            temps.resize_with(self.slots, || None);
        }
        // The block that ran the step, if one did.
        let mut ran = None;
        let done = if self.full {
            self.eval::<S, C, true>(&st, cur, temps, call)
        } else if let Some(b) = self.block.as_ref().filter(|b| b.ticks(&st)) {
            match self.straight(b, &st, cur, temps, call) {
                Some(true) => {
                    ran = Some(b);
                    Some(())
                }
                // A kept value the block cannot read as it assumed: the loop runs the step.
                Some(false) => self.eval::<S, C, false>(&st, cur, temps, call),
                None => None,
            }
        } else {
            self.eval::<S, C, false>(&st, cur, temps, call)
        };
        if done.is_none() {
            self.clear_temps(temps);
            return false;
        }
        if !self.delays.is_empty() {
            arms.clear();
            arms.resize(self.delays.len(), None);
            let vals = Vals {
                inputs: st.inputs,
                last: st.last,
                consts: &self.consts,
                temps,
            };
            if self.arm(st.ts, cur, vals, arms).is_none() {
                self.clear_temps(temps);
                return false;
            }
        }
        let vals = Vals {
            inputs: st.inputs,
            last: st.last,
            consts: &self.consts,
            temps,
        };
        for (out, &(n, kind)) in self.outputs.iter().enumerate() {
            let c = cur_of(cur, n);
            if c.has {
                if kind == Kind::Val {
                    // Sent by reference: no copy of the value.
                    if let Some(v) = vals.get(c.bits) {
                        sink(out, v);
                    }
                } else {
                    let v = scalar(kind, c.bits);
                    sink(out, &v);
                    // A scalar: nothing to drop.
                    std::mem::forget(v);
                }
            }
        }
        match ran {
            Some(b) => b.keep.write(cur, st.last),
            None => keep_some(&self.kept, cur, st.last),
        }
        if !self.kept_vals.is_empty() {
            self.keep_values(cur, st.inputs, st.last, temps);
        }
        self.clear_temps(temps);
        if !self.delays.is_empty() {
            for (&(_, k, _, _), arm) in self.delays.iter().zip(arms.iter()) {
                if let (Some(t), Some(a)) = (st.targets.get_mut(k as usize), arm) {
                    *t = *a;
                }
            }
        }
        true
    }

    /// Each `delay`'s target after this step, as the general step arms it (`Some(target)`:
    /// changed; a target is cleared when the delay fires or is reset, and set `amount` after now
    /// when either happens with an amount): `None` when an amount is not positive (an error
    /// value the general step sends).
    fn arm<S: Cur + ?Sized>(
        &self,
        ts: i64,
        cur: &S,
        vals: Vals<'_>,
        arms: &mut [Option<Option<i64>>],
    ) -> Option<()> {
        for (&(dst, _, amount, reset), arm) in self.delays.iter().zip(arms.iter_mut()) {
            let fired = cur_of(cur, dst).has;
            let reset_now = cur_of(cur, reset).has;
            if !(fired || reset_now) {
                continue;
            }
            let mut target = None;
            let a = cur_of(cur, amount.n);
            if a.has {
                let d = match amount.kind {
                    Kind::Val => match vals.get(a.bits)? {
                        Value::Int(d) => Some(*d),
                        _ => None,
                    },
                    _ => Some(a.bits as i64),
                };
                match d {
                    Some(d) if d > 0 => target = Some(ts.saturating_add(d)),
                    Some(_) => return None,
                    None => {}
                }
            }
            *arm = Some(target);
        }
        Some(())
    }

    /// Whether the plan calls compiled functions (`Instr::Call`). Measured (BENCHMARKS.md,
    /// eleventh round): such a plan takes more instructions than the general step on the specs
    /// that have calls (the robot monitors, lidar, Auction: 7% to 12%), so the monitor runs it only
    /// without them.
    #[inline]
    pub fn has_calls(&self) -> bool {
        self.calls
    }

    /// The nodes the plan computes by calling their compiled functions (`Instr::Call`), in
    /// evaluation order (`check --ir` names them).
    pub fn calls(&self) -> Vec<usize> {
        self.instrs
            .iter()
            .filter_map(|i| match i {
                Instr::Call { dst, .. } => Some(*dst as usize),
                _ => None,
            })
            .collect()
    }

    /// How many nodes its straight block runs without presence tests (0: it has none).
    pub fn straight_nodes(&self) -> usize {
        self.block.as_ref().map_or(0, |b| b.straight)
    }

    /// Drop the values calls computed this step.
    #[inline(always)]
    fn clear_temps(&self, temps: &mut [Option<Value>]) {
        for &n in &self.temp_nodes {
            if let Some(t) = temps.get_mut(n as usize) {
                replace_opt(t, None);
            }
        }
    }

    /// Keep the events of the kept nodes of [`Kind::Val`]: one kept from another kept slot is
    /// copied before any of them is written (the slot it refers to may be written here; the
    /// scalars' slots are never referred to), one from an input or a constant is cloned.
    fn keep_values<S: Cur + ?Sized>(
        &self,
        cur: &S,
        inputs: &[Option<Value>],
        last: &mut [Option<Value>],
        temps: &[Option<Value>],
    ) {
        let mut moved: Vec<(u32, Value)> = Vec::new();
        for &(n, slot) in &self.kept_vals {
            let c = cur_of(cur, n);
            if c.has
                && let Ref::Last(from) = Ref::of(c.bits)
                && from != slot
                && let Some(Some(v)) = last.get(from as usize)
            {
                moved.push((slot, v.clone()));
            }
        }
        for &(n, slot) in &self.kept_vals {
            let c = cur_of(cur, n);
            if !c.has {
                continue;
            }
            let v = match Ref::of(c.bits) {
                // Its own slot, or copied above.
                Ref::Last(_) => continue,
                Ref::Input(i) => inputs.get(i as usize).and_then(Option::as_ref),
                Ref::Const(i) => self.consts.get(i as usize),
                Ref::Temp(i) => temps.get(i as usize).and_then(Option::as_ref),
            };
            if let (Some(v), Some(l)) = (v, last.get_mut(slot as usize)) {
                replace(l, v.clone());
            }
        }
        for (slot, v) in moved {
            if let Some(l) = last.get_mut(slot as usize) {
                replace(l, v);
            }
        }
    }

    /// An `Instr::Call`'s event (out of line: the typed instructions' loop stays small).
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn call<S: Cur + ?Sized, C>(
        &self,
        st: &StepState<'_>,
        cur: &mut S,
        temps: &mut [Option<Value>],
        call: &mut C,
        dst: u32,
        node: u32,
        args: &[Src],
        mode: CallMode,
    ) -> Option<Slot>
    where
        C: FnMut(usize, &[Option<&Value>]) -> Option<Value>,
    {
        let last = &*st.last;
        macro_rules! vals {
            () => {
                Vals {
                    inputs: st.inputs,
                    last,
                    consts: &self.consts,
                    temps: &*temps,
                }
            };
        }
        let r = match mode {
            CallMode::Signal => {
                if fires(cur, last, args)? {
                    let ops = args.iter().map(|a| Some((a.kind, value_of(cur, last, a)?)));
                    call_node(call, node, ops, vals!())?
                } else {
                    None
                }
            }
            CallMode::Events => {
                if args.iter().any(|a| has_event(cur, a)) {
                    let ops = args.iter().map(|a| {
                        let c = cur_of(cur, a.n);
                        Some((a.kind, c.has.then_some(c.bits)))
                    });
                    call_node(call, node, ops, vals!())?
                } else {
                    None
                }
            }
            CallMode::Fold { init } => {
                let (acc, x) = (args.first()?, args.get(1)?);
                let xs = cur_of(cur, x.n);
                let acc = if st.first {
                    Some(init)
                } else if xs.has {
                    kept_of(last, acc.slot, Kind::Val)?
                } else {
                    None
                };
                match acc {
                    Some(a) if xs.has => {
                        let ops = [Some((Kind::Val, Some(a))), Some((x.kind, Some(xs.bits)))];
                        call_node(call, node, ops.into_iter(), vals!())?
                    }
                    // The first step without an event: the initial value itself.
                    Some(a) => return Some(some(a)),
                    None => None,
                }
            }
            CallMode::Reduce => {
                let (acc, x) = (args.first()?, args.get(1)?);
                let xs = cur_of(cur, x.n);
                if !xs.has {
                    None
                } else if let Some(a) = kept_of(last, acc.slot, Kind::Val)? {
                    let ops = [Some((Kind::Val, Some(a))), Some((x.kind, Some(xs.bits)))];
                    call_node(call, node, ops.into_iter(), vals!())?
                } else {
                    // The first event: itself (of the node's kind, checked).
                    return Some(xs);
                }
            }
        };
        Some(match r {
            Some(v) => {
                *temps.get_mut(dst as usize)? = Some(v);
                some(Ref::Temp(dst).bits())
            }
            None => NONE,
        })
    }

    /// The step's events into `cur`; `None` as soon as one has no scalar answer.
    #[inline(always)]
    ///
    /// `FULL`: the plan has calls, values made [`Kind::Val`] or delays ([`Plan::full`]);
    /// without, their instructions are never met and their code is left out of the loop.
    fn eval<S: Cur + ?Sized, C, const FULL: bool>(
        &self,
        st: &StepState<'_>,
        cur: &mut S,
        temps: &mut [Option<Value>],
        call: &mut C,
    ) -> Option<()>
    where
        C: FnMut(usize, &[Option<&Value>]) -> Option<Value>,
    {
        for instr in &self.instrs {
            self.one::<S, C, FULL>(instr, st, cur, temps, call)?;
        }
        Some(())
    }

    /// Evaluate one step by the straight block `b` (its clock ticks: [`Block::ticks`]) into
    /// `cur`: `Some(true)` done; `Some(false)` the loop must run it (a `fold` without a kept
    /// value, as on no step after the first unless restored so); `None` no scalar answer (the
    /// loop's answer too). The plan has no calls, values or delays.
    #[inline(always)]
    fn straight<S: Cur + ?Sized, C>(
        &self,
        b: &Block,
        st: &StepState<'_>,
        cur: &mut S,
        temps: &mut [Option<Value>],
        call: &mut C,
    ) -> Option<bool>
    where
        C: FnMut(usize, &[Option<&Value>]) -> Option<Value>,
    {
        let last = &*st.last;
        for f in &b.code {
            match f.run(st, last, cur)? {
                Flow::Done => {}
                Flow::Other(i) => {
                    self.one::<S, C, false>(self.instrs.get(i as usize)?, st, cur, temps, call)?
                }
                Flow::Loop => return Some(false),
            }
        }
        Some(true)
    }

    /// Run one instruction of the plan's loop: node `dst`'s event into `cur`.
    #[inline(always)]
    fn one<S: Cur + ?Sized, C, const FULL: bool>(
        &self,
        instr: &Instr,
        st: &StepState<'_>,
        cur: &mut S,
        temps: &mut [Option<Value>],
        call: &mut C,
    ) -> Option<()>
    where
        C: FnMut(usize, &[Option<&Value>]) -> Option<Value>,
    {
        let last = &*st.last;
        // What references point into; `temps` as it is when read (calls write it).
        macro_rules! vals {
            () => {
                Vals {
                    inputs: st.inputs,
                    last,
                    consts: &self.consts,
                    temps: &*temps,
                }
            };
        }
        {
            let (dst, v) = match instr {
                Instr::Nil { dst } => (dst, NONE),
                Instr::Input { dst, input, kind } => (
                    dst,
                    match st.inputs.get(*input as usize) {
                        Some(Some(v)) => match kind.bits(v) {
                            Some(b) => some(b),
                            None if *kind == Kind::Val => some(Ref::Input(*input).bits()),
                            None => return None,
                        },
                        _ => NONE,
                    },
                ),
                Instr::EqVal { dst, ne, a, b } => {
                    if !has_event(cur, a) && !has_event(cur, b) {
                        (dst, NONE)
                    } else {
                        match (value_of(cur, last, a)?, value_of(cur, last, b)?) {
                            (Some(x), Some(y)) => {
                                let vals = vals!();
                                let (x, y) = (vals.get(x)?, vals.get(y)?);
                                // An error value propagates: the general step's.
                                if matches!(x, Value::Error(_)) || matches!(y, Value::Error(_)) {
                                    return None;
                                }
                                (dst, some(u64::from((x == y) != *ne)))
                            }
                            _ => (dst, NONE),
                        }
                    }
                }
                Instr::Op2 { dst, op, a, b } => {
                    if !has_event(cur, a) && !has_event(cur, b) {
                        (dst, NONE)
                    } else {
                        match (value_of(cur, last, a)?, value_of(cur, last, b)?) {
                            (Some(x), Some(y)) => (dst, some(op.run(x, y)?)),
                            _ => (dst, NONE),
                        }
                    }
                }
                Instr::Op1 { dst, op, a } => (
                    dst,
                    match (has_event(cur, a), value_of(cur, last, a)?) {
                        (true, Some(x)) => some(op.run(x)),
                        _ => NONE,
                    },
                ),
                Instr::Ite {
                    dst,
                    cond,
                    then,
                    other,
                } => {
                    if !has_event(cur, cond) && !has_event(cur, then) && !has_event(cur, other) {
                        (dst, NONE)
                    } else {
                        match (
                            value_of(cur, last, cond)?,
                            value_of(cur, last, then)?,
                            value_of(cur, last, other)?,
                        ) {
                            (Some(c), Some(t), Some(e)) => {
                                let c = if FULL {
                                    cond_of(cond.kind, c, vals!())?
                                } else {
                                    c != 0
                                };
                                (dst, some(if c { t } else { e }))
                            }
                            _ => (dst, NONE),
                        }
                    }
                }
                Instr::Fold {
                    dst,
                    stream,
                    init,
                    acc,
                    op,
                    a,
                    b,
                } => {
                    let x = cur_of(cur, *stream);
                    let v = if st.first {
                        if x.has {
                            some(op.fold(*a, *b, *init, x.bits)?)
                        } else {
                            some(*init)
                        }
                    } else if x.has {
                        match kept_of(last, acc.slot, acc.kind)? {
                            Some(s) => some(op.fold(*a, *b, s, x.bits)?),
                            None => NONE,
                        }
                    } else {
                        NONE
                    };
                    (dst, v)
                }
                Instr::Reduce {
                    dst,
                    stream,
                    acc,
                    op,
                    a,
                    b,
                } => {
                    let x = cur_of(cur, *stream);
                    let v = if x.has {
                        match kept_of(last, acc.slot, acc.kind)? {
                            Some(s) => some(op.fold(*a, *b, s, x.bits)?),
                            None => x,
                        }
                    } else {
                        NONE
                    };
                    (dst, v)
                }
                Instr::Const { dst, bits } => (dst, if st.first { some(*bits) } else { NONE }),
                Instr::Alias { dst, src } => (dst, cur_of(cur, *src)),
                Instr::Time { dst, src } => (
                    dst,
                    if cur_of(cur, *src).has {
                        some(st.ts as u64)
                    } else {
                        NONE
                    },
                ),
                Instr::Last {
                    dst,
                    value,
                    trigger,
                } => (
                    dst,
                    if cur_of(cur, *trigger).has {
                        match kept_of(last, value.slot, value.kind)? {
                            Some(v) => some(v),
                            None => NONE,
                        }
                    } else {
                        NONE
                    },
                ),
                Instr::Default { dst, stream, bits } => {
                    let s = cur_of(cur, *stream);
                    (dst, if !s.has && st.first { some(*bits) } else { s })
                }
                Instr::DefaultFrom { dst, stream, from } => {
                    let s = cur_of(cur, stream.n);
                    let v = if s.has {
                        s
                    } else {
                        let s_never = kept_of(last, stream.slot, stream.kind)?.is_none();
                        let d_first = kept_of(last, from.slot, from.kind)?.is_none();
                        if s_never && d_first {
                            cur_of(cur, from.n)
                        } else {
                            NONE
                        }
                    };
                    (dst, v)
                }
                Instr::SConst { dst, args, bits } => (
                    dst,
                    if fires(cur, last, args)? {
                        some(*bits)
                    } else {
                        NONE
                    },
                ),
                Instr::Lift {
                    dst,
                    f,
                    args,
                    n,
                    kind,
                } => {
                    let mut a = [NONE; 3];
                    for (v, arg) in a.iter_mut().zip(args.iter().take(usize::from(*n))) {
                        *v = cur_of(cur, *arg);
                    }
                    if !(a[0].has || a[1].has || a[2].has) {
                        (dst, NONE)
                    } else {
                        (dst, f.run(a, *kind, vals!()))
                    }
                }
                Instr::SPick { dst, args, pick } => {
                    let v = match args.get(*pick) {
                        Some(a) if fires(cur, last, args)? => value_of(cur, last, a)?,
                        _ => None,
                    };
                    (dst, v.map_or(NONE, some))
                }
                Instr::Call {
                    dst,
                    node,
                    args,
                    mode,
                } => (
                    dst,
                    if FULL {
                        self.call(st, cur, temps, call, *dst, *node, args, *mode)?
                    } else {
                        return None;
                    },
                ),
                Instr::TimeVal { dst, src } => {
                    let v = if !FULL {
                        return None;
                    } else if cur_of(cur, *src).has {
                        *temps.get_mut(*dst as usize)? = Some(Value::Int(st.ts));
                        some(Ref::Temp(*dst).bits())
                    } else {
                        NONE
                    };
                    (dst, v)
                }
                Instr::Delay { dst, k, bits, .. } => (
                    dst,
                    if !FULL {
                        return None;
                    } else if st.targets.get(*k as usize).copied().flatten() == Some(st.ts) {
                        some(*bits)
                    } else {
                        NONE
                    },
                ),
                Instr::Merge { dst, args } => (
                    dst,
                    args.iter()
                        .map(|a| cur_of(cur, *a))
                        .find(|v| v.has)
                        .unwrap_or(NONE),
                ),
                Instr::Filter { dst, stream, cond } => {
                    let s = cur_of(cur, *stream);
                    let v = if s.has {
                        match value_of(cur, last, cond)? {
                            Some(c) if FULL && cond_of(cond.kind, c, vals!())? => s,
                            Some(1) if !FULL => s,
                            _ => NONE,
                        }
                    } else {
                        NONE
                    };
                    (dst, v)
                }
            };
            cur.set(*dst, v);
        }
        Some(())
    }
}
