//! Making a [`Plan`]: the kind (`Unit`, `Bool`, `Int`, `Float`, or another value only moved or
//! compared) of every node, inferred from the nodes' forms, and each node's instruction with its
//! operands' kinds checked. A program with a node the plan has no form for gets no plan; the
//! nodes without one are handed back (`check --ir` names them).

use super::{
    Block, CONST, CallMode, FArg, Fused, Instr, KArg, Keep, Kernel, Kind, LiftOp, NoPlan, Op1, Op2,
    Opnd, Plan, Ref, Src, Straight, need,
};
use crate::ir::{self, LiftFn, NO_SLOT, Node, NodeId, SArg};
use crate::value::Value;
use std::cell::RefCell;

/// The kind of a constant: a scalar's, else [`Kind::Val`].
fn const_kind(v: &Value) -> Kind {
    Kind::of_value(v).map_or(Kind::Val, |(k, _)| k)
}

/// The kind of each node, as far as the nodes' forms tell: inputs by their declared type,
/// constants by their value, operators by their result. `last` reads a node that may come
/// later in the order, so this runs until nothing changes.
fn kinds(
    p: &ir::Program,
    kernel: &impl Fn(NodeId) -> Option<Kernel>,
    forced: &[bool],
) -> Vec<Option<Kind>> {
    let mut kinds: Vec<Option<Kind>> = (0..p.nodes.len())
        .map(|i| forced.get(i).copied().unwrap_or(false).then_some(Kind::Val))
        .collect();
    loop {
        let mut changed = false;
        for &i in &p.order {
            if kinds.get(i).copied().flatten().is_some() {
                continue;
            }
            let k = |n: &NodeId| kinds.get(*n).copied().flatten();
            let sk = |a: &SArg| match a {
                SArg::Stream(n) => k(n),
                SArg::Const(v) => Some(const_kind(v)),
            };
            let kind = match p.nodes.get(i) {
                Some(Node::Input(j)) => p.inputs.get(*j).map(|inp| Kind::of_type(&inp.ty)),
                Some(Node::Const(v) | Node::Default { value: v, .. }) => Some(const_kind(v)),
                Some(Node::Fold { init, .. }) => Some(const_kind(init)),
                Some(Node::Alias(n)) | Some(Node::Last { value: n, .. }) => k(n),
                Some(Node::Reduce { stream: n, .. } | Node::Filter { stream: n, .. }) => k(n),
                Some(Node::DefaultFrom { stream, .. }) => k(stream),
                // `nil` never has an event: any kind (the first other argument's).
                Some(Node::Merge(args)) => args
                    .iter()
                    .find(|a| !matches!(p.nodes.get(**a), Some(Node::Nil)))
                    .and_then(k),
                Some(Node::Nil) => Some(Kind::Unit),
                Some(Node::Time(_)) => Some(Kind::Int),
                Some(Node::Delay { .. }) => Some(Kind::Unit),
                Some(Node::Lift { args, f }) => match lift_op(f, args.len()) {
                    Some(LiftOp::On) => args.get(1).and_then(k),
                    Some(LiftOp::First | LiftOp::Distinct | LiftOp::FirstOnly) => {
                        args.first().and_then(k)
                    }
                    Some(LiftOp::Edge(_)) => Some(Kind::Bool),
                    None => None,
                },
                Some(Node::Bin { op, .. }) => Some(Op2::of(*op).kinds().1),
                Some(Node::Ite { then, .. }) => sk(then),
                Some(Node::SLift { .. }) => match kernel(i) {
                    Some(Kernel::Op(op, ..)) => Some(Op2::of(op).kinds().1),
                    Some(Kernel::Int(..)) => Some(Kind::Int),
                    Some(Kernel::Eq { .. }) | Some(Kernel::Not(_)) => Some(Kind::Bool),
                    Some(Kernel::FNeg(_) | Kernel::IntToFloat(_)) => Some(Kind::Float),
                    Some(Kernel::Const(v)) => Some(const_kind(&v)),
                    Some(Kernel::Pick(a)) => match p.nodes.get(i) {
                        Some(Node::SLift { args, .. }) => args.get(usize::from(a)).and_then(sk),
                        _ => None,
                    },
                    None => None,
                },
                _ => None,
            };
            if let (Some(kind), Some(slot)) = (kind, kinds.get_mut(i)) {
                *slot = Some(kind);
                changed = true;
            }
        }
        if !changed {
            return kinds;
        }
    }
}

/// The plan's form of an event lift's function over `n` arguments, if it has one (the arities
/// are the ones `runtime::exec::lift` gives an event for).
fn lift_op(f: &LiftFn, n: usize) -> Option<LiftOp> {
    Some(match (f, n) {
        (LiftFn::First, 1..=3) => LiftOp::First,
        (LiftFn::On, 3) => LiftOp::On,
        (LiftFn::Distinct, 2) => LiftOp::Distinct,
        (LiftFn::FirstOnly, 2) => LiftOp::FirstOnly,
        (LiftFn::Edge(want), 2) => LiftOp::Edge(*want),
        _ => return None,
    })
}

/// Node `n` as an operand (its event, else its kept value).
fn stream_src(b: &Builder<'_>, n: NodeId) -> Result<Src, NoPlan> {
    b.src(&SArg::Stream(n))
}

/// Makes a [`Plan`]: the checks that every operand has the kind its operator takes.
struct Builder<'a> {
    p: &'a ir::Program,
    kinds: Vec<Option<Kind>>,
    /// The slot that never has an event (after the nodes').
    never: u32,
    /// The constants of [`Kind::Val`] met so far ([`Plan::consts`]).
    consts: RefCell<Vec<Value>>,
    /// The nodes made [`Kind::Val`] whatever their values (their instructions compute on
    /// values: [`Builder::instr_val`]).
    forced: Vec<bool>,
}

impl Builder<'_> {
    fn idx(&self, n: NodeId) -> Result<u32, NoPlan> {
        need(u32::try_from(n).ok().filter(|_| n < self.p.nodes.len()))
    }

    fn kind(&self, n: NodeId) -> Result<Kind, NoPlan> {
        need(self.kinds.get(n).copied().flatten())
    }

    fn slot(&self, n: NodeId) -> Result<u32, NoPlan> {
        need(self.p.last_slot.get(n).copied())
    }

    /// A constant's kind and bits: a scalar's, or a reference to it among the plan's constants.
    fn const_bits(&self, v: &Value) -> Result<(Kind, u64), NoPlan> {
        match Kind::of_value(v) {
            Some(kb) => Ok(kb),
            None => {
                let mut consts = self.consts.borrow_mut();
                let i = need(u32::try_from(consts.len()).ok())?;
                consts.push(v.clone());
                Ok((Kind::Val, Ref::Const(i).bits()))
            }
        }
    }

    /// A constant as a value of [`Kind::Val`] (a reference among the plan's constants), even a
    /// scalar.
    fn val_const(&self, v: &Value) -> Result<u64, NoPlan> {
        let mut consts = self.consts.borrow_mut();
        let i = need(u32::try_from(consts.len()).ok())?;
        consts.push(v.clone());
        Ok(Ref::Const(i).bits())
    }

    /// An operand that must be of [`Kind::Val`]: a constant made one, a stream checked.
    fn vsrc(&self, a: &SArg) -> Result<Src, NoPlan> {
        let src = match a {
            SArg::Const(v) => Src {
                n: self.never,
                slot: CONST,
                kind: Kind::Val,
                k: self.val_const(v)?,
            },
            SArg::Stream(_) => self.src(a)?,
        };
        self.check(&src, Some(Kind::Val))?;
        Ok(src)
    }

    /// Node `n` as an operand that must be of [`Kind::Val`] (or `nil`, which has no event).
    fn vnode(&self, n: NodeId) -> Result<u32, NoPlan> {
        if self.kind(n)? == Kind::Val || matches!(self.p.nodes.get(n), Some(Node::Nil)) {
            self.idx(n)
        } else {
            Err(NoPlan)
        }
    }

    /// The instruction of node `i` made [`Kind::Val`]: operators, lifts and folds whose
    /// functions have no typed form are calls ([`Instr::Call`]); the forms that only move
    /// values take operands of [`Kind::Val`]. `delay` has none.
    fn instr_val(&self, i: NodeId) -> Result<Instr, NoPlan> {
        let dst = self.idx(i)?;
        let call = |args: Vec<Src>, mode: CallMode| -> Result<Instr, NoPlan> {
            Ok(Instr::Call {
                dst,
                node: dst,
                args: args.into_boxed_slice(),
                mode,
            })
        };
        let stream = |n: NodeId| self.src(&SArg::Stream(n));
        Ok(match need(self.p.nodes.get(i))? {
            Node::Input(k) => Instr::Input {
                dst,
                input: need(u32::try_from(*k).ok())?,
                kind: Kind::Val,
            },
            Node::Nil => Instr::Nil { dst },
            Node::Const(v) => Instr::Const {
                dst,
                bits: self.val_const(v)?,
            },
            Node::Alias(n) => Instr::Alias {
                dst,
                src: self.vnode(*n)?,
            },
            Node::Time(n) => Instr::TimeVal {
                dst,
                src: self.idx(*n)?,
            },
            Node::Last { value, trigger } => {
                self.vnode(*value)?;
                Instr::Last {
                    dst,
                    value: self.kept(*value)?,
                    trigger: self.idx(*trigger)?,
                }
            }
            Node::Default { stream, value } => Instr::Default {
                dst,
                stream: self.vnode(*stream)?,
                bits: self.val_const(value)?,
            },
            Node::DefaultFrom { stream, from } => {
                self.vnode(*stream)?;
                self.vnode(*from)?;
                Instr::DefaultFrom {
                    dst,
                    stream: stream_src(self, *stream)?,
                    from: stream_src(self, *from)?,
                }
            }
            Node::Bin { a, b, .. } => call(vec![self.src(a)?, self.src(b)?], CallMode::Signal)?,
            Node::SLift { args, .. } => {
                if args.is_empty() {
                    return Err(NoPlan);
                }
                call(
                    args.iter().map(|a| self.src(a)).collect::<Result<_, _>>()?,
                    CallMode::Signal,
                )?
            }
            Node::Ite { cond, then, other } => {
                let cond = self.src(cond)?;
                if !matches!(cond.kind, Kind::Bool | Kind::Val) {
                    return Err(NoPlan);
                }
                Instr::Ite {
                    dst,
                    cond,
                    then: self.vsrc(then)?,
                    other: self.vsrc(other)?,
                }
            }
            Node::Merge(args) => Instr::Merge {
                dst,
                args: args
                    .iter()
                    .map(|a| self.vnode(*a))
                    .collect::<Result<_, _>>()?,
            },
            Node::Filter { stream, cond } => {
                let cond = self.src(&SArg::Stream(*cond))?;
                if !matches!(cond.kind, Kind::Bool | Kind::Val) {
                    return Err(NoPlan);
                }
                Instr::Filter {
                    dst,
                    stream: self.vnode(*stream)?,
                    cond,
                }
            }
            Node::Fold {
                stream: x, init, ..
            } => call(
                vec![self.kept(i)?, stream(*x)?],
                CallMode::Fold {
                    init: self.val_const(init)?,
                },
            )?,
            Node::Reduce { stream: x, .. } => {
                self.vnode(*x)?;
                call(vec![self.kept(i)?, stream(*x)?], CallMode::Reduce)?
            }
            Node::Lift { args, .. } => {
                if args.is_empty() {
                    return Err(NoPlan);
                }
                call(
                    args.iter().map(|a| stream(*a)).collect::<Result<_, _>>()?,
                    CallMode::Events,
                )?
            }
            Node::Delay { delay, reset } => self.delay(dst, i, *delay, *reset, Value::Unit)?,
        })
    }

    /// A `delay` node's instruction: fires with `unit` (its bits: a scalar's, or a reference
    /// to the constant) when its armed target is now.
    fn delay(
        &self,
        dst: u32,
        i: NodeId,
        delay: NodeId,
        reset: NodeId,
        unit: Value,
    ) -> Result<Instr, NoPlan> {
        let k = need(self.p.delays.iter().position(|d| *d == i))?;
        let bits = if self.kind(i)? == Kind::Val {
            self.val_const(&unit)?
        } else {
            0
        };
        let amount = self.src(&SArg::Stream(delay))?;
        if !matches!(amount.kind, Kind::Int | Kind::Val) {
            return Err(NoPlan);
        }
        Ok(Instr::Delay {
            dst,
            k: need(u32::try_from(k).ok())?,
            bits,
            amount,
            reset: self.idx(reset)?,
        })
    }

    /// The nodes node `i` reads (made [`Kind::Val`] when its own instruction of that kind
    /// cannot take them as they are).
    fn reads(&self, i: NodeId) -> Vec<NodeId> {
        self.p.nodes.get(i).map(Node::all_deps).unwrap_or_default()
    }

    fn constant(&self, v: &Value) -> Result<Src, NoPlan> {
        let (kind, k) = self.const_bits(v)?;
        Ok(Src {
            n: self.never,
            slot: CONST,
            kind,
            k,
        })
    }

    fn src(&self, a: &SArg) -> Result<Src, NoPlan> {
        match a {
            SArg::Stream(n) => Ok(Src {
                n: self.idx(*n)?,
                slot: self.slot(*n)?,
                kind: self.kind(*n)?,
                k: 0,
            }),
            SArg::Const(v) => self.constant(v),
        }
    }

    /// Node `n`'s kept value, read without its event.
    fn kept(&self, n: NodeId) -> Result<Src, NoPlan> {
        Ok(Src {
            n: self.never,
            ..self.src(&SArg::Stream(n))?
        })
    }

    fn check(&self, src: &Src, kind: Option<Kind>) -> Result<(), NoPlan> {
        match kind {
            Some(k) if k != src.kind => Err(NoPlan),
            _ => Ok(()),
        }
    }

    /// The binary instruction of `op` on `a` and `b`, its kinds checked.
    fn op2(&self, dst: u32, op: Op2, a: Src, b: Src) -> Result<Instr, NoPlan> {
        let (operand, _) = op.kinds();
        self.check(&a, operand)?;
        self.check(&b, operand)?;
        if a.kind != b.kind {
            return Err(NoPlan);
        }
        Ok(Instr::Op2 { dst, op, a, b })
    }

    /// A signal lift's function as an instruction: only when its operands are its arguments,
    /// each used (a lift fires on its arguments, an operator on its operands).
    fn slift(&self, dst: u32, args: &[SArg], k: &Kernel) -> Result<Instr, NoPlan> {
        let srcs: Vec<Src> = args.iter().map(|a| self.src(a)).collect::<Result<_, _>>()?;
        let mut used = vec![false; srcs.len()];
        let mut operand = |a: &KArg| -> Result<Src, NoPlan> {
            match a {
                KArg::Arg(i) => {
                    let i = usize::from(*i);
                    *need(used.get_mut(i))? = true;
                    need(srcs.get(i).copied())
                }
                KArg::Const(v) => self.constant(v),
            }
        };
        let instr = match k {
            Kernel::Op(op, a, b) => {
                let (a, b) = (operand(a)?, operand(b)?);
                self.op2(dst, Op2::of(*op), a, b)?
            }
            Kernel::Int(op, a, b) => {
                let (a, b) = (operand(a)?, operand(b)?);
                self.op2(dst, Op2::int(*op), a, b)?
            }
            Kernel::Eq { ne, a, b } => {
                let (a, b) = (operand(a)?, operand(b)?);
                if a.kind == Kind::Val && b.kind == Kind::Val {
                    Instr::EqVal { dst, ne: *ne, a, b }
                } else {
                    self.op2(dst, need(Op2::eq(*ne, a.kind))?, a, b)?
                }
            }
            Kernel::Not(a) | Kernel::FNeg(a) | Kernel::IntToFloat(a) => {
                let op = match k {
                    Kernel::Not(_) => Op1::Not,
                    Kernel::FNeg(_) => Op1::FNeg,
                    _ => Op1::IntToFloat,
                };
                let a = operand(a)?;
                self.check(&a, Some(op.kinds().0))?;
                Instr::Op1 { dst, op, a }
            }
            Kernel::Const(v) => {
                used.iter_mut().for_each(|u| *u = true);
                Instr::SConst {
                    dst,
                    args: srcs.clone().into_boxed_slice(),
                    bits: self.const_bits(v)?.1,
                }
            }
            Kernel::Pick(a) => {
                used.iter_mut().for_each(|u| *u = true);
                let pick = usize::from(*a);
                need(srcs.get(pick))?;
                Instr::SPick {
                    dst,
                    args: srcs.clone().into_boxed_slice(),
                    pick,
                }
            }
        };
        if srcs.is_empty() || used.iter().any(|u| !u) {
            return Err(NoPlan);
        }
        Ok(instr)
    }

    /// A `fold`'s or `reduce`'s function on (accumulator, event) as an operator.
    fn step_fn(&self, k: &Kernel, acc: Kind, x: Kind) -> Result<(Op2, FArg, FArg), NoPlan> {
        let arg = |a: &KArg| -> Result<(FArg, Kind), NoPlan> {
            match a {
                KArg::Arg(0) => Ok((FArg::Acc, acc)),
                KArg::Arg(1) => Ok((FArg::X, x)),
                KArg::Arg(_) => Err(NoPlan),
                KArg::Const(v) => {
                    let (kind, bits) = self.const_bits(v)?;
                    Ok((FArg::Const(bits), kind))
                }
            }
        };
        let (op, a, b) = match k {
            Kernel::Op(op, a, b) => (Op2::of(*op), arg(a)?, arg(b)?),
            Kernel::Int(op, a, b) => (Op2::int(*op), arg(a)?, arg(b)?),
            Kernel::Eq { ne, a, b } => {
                let (a, b) = (arg(a)?, arg(b)?);
                (need(Op2::eq(*ne, a.1))?, a, b)
            }
            _ => return Err(NoPlan),
        };
        let (operand, result) = op.kinds();
        if a.1 != b.1 || operand.is_some_and(|k| k != a.1) || result != acc {
            return Err(NoPlan);
        }
        Ok((op, a.0, b.0))
    }

    fn instr(&self, i: NodeId, kernel: Option<Kernel>) -> Result<Instr, NoPlan> {
        if self.forced.get(i).copied().unwrap_or(false) {
            return self.instr_val(i);
        }
        let dst = self.idx(i)?;
        let kind = self.kind(i)?;
        let bits = |v: &Value| -> Result<u64, NoPlan> {
            match self.const_bits(v)? {
                (k, b) if k == kind => Ok(b),
                _ => Err(NoPlan),
            }
        };
        let same = |n: NodeId| -> Result<u32, NoPlan> {
            if self.kind(n)? == kind || matches!(self.p.nodes.get(n), Some(Node::Nil)) {
                self.idx(n)
            } else {
                Err(NoPlan)
            }
        };
        Ok(match need(self.p.nodes.get(i))? {
            Node::Input(k) => Instr::Input {
                dst,
                input: need(u32::try_from(*k).ok())?,
                kind,
            },
            Node::Nil => Instr::Nil { dst },
            Node::Const(v) => Instr::Const {
                dst,
                bits: bits(v)?,
            },
            Node::Alias(n) => Instr::Alias {
                dst,
                src: same(*n)?,
            },
            Node::Time(n) => Instr::Time {
                dst,
                src: self.idx(*n)?,
            },
            Node::Last { value, trigger } => Instr::Last {
                dst,
                value: self.kept(*value)?,
                trigger: self.idx(*trigger)?,
            },
            Node::Default { stream, value } => Instr::Default {
                dst,
                stream: same(*stream)?,
                bits: bits(value)?,
            },
            Node::DefaultFrom { stream, from } => {
                same(*stream)?;
                same(*from)?;
                Instr::DefaultFrom {
                    dst,
                    stream: self.src(&SArg::Stream(*stream))?,
                    from: self.src(&SArg::Stream(*from))?,
                }
            }
            Node::Bin { op, a, b, .. } => {
                self.op2(dst, Op2::of(*op), self.src(a)?, self.src(b)?)?
            }
            Node::SLift { args, .. } => self.slift(dst, args, &need(kernel)?)?,
            Node::Ite { cond, then, other } => {
                let (cond, then, other) = (self.src(cond)?, self.src(then)?, self.src(other)?);
                self.check(&cond, Some(Kind::Bool))?;
                self.check(&then, Some(kind))?;
                self.check(&other, Some(kind))?;
                Instr::Ite {
                    dst,
                    cond,
                    then,
                    other,
                }
            }
            Node::Merge(args) => Instr::Merge {
                dst,
                args: args.iter().map(|a| same(*a)).collect::<Result<_, _>>()?,
            },
            Node::Filter { stream, cond } => {
                let cond = self.src(&SArg::Stream(*cond))?;
                self.check(&cond, Some(Kind::Bool))?;
                Instr::Filter {
                    dst,
                    stream: same(*stream)?,
                    cond,
                }
            }
            Node::Fold { stream, init, .. } => {
                let (op, a, b) = self.step_fn(&need(kernel)?, kind, self.kind(*stream)?)?;
                Instr::Fold {
                    dst,
                    stream: self.idx(*stream)?,
                    init: bits(init)?,
                    acc: self.kept(i)?,
                    op,
                    a,
                    b,
                }
            }
            Node::Reduce { stream, .. } => {
                let (op, a, b) = self.step_fn(&need(kernel)?, kind, self.kind(*stream)?)?;
                Instr::Reduce {
                    dst,
                    stream: same(*stream)?,
                    acc: self.kept(i)?,
                    op,
                    a,
                    b,
                }
            }
            Node::Lift { args, f } => {
                let f = need(lift_op(f, args.len()))?;
                let mut a = [self.never; 3];
                for (d, n) in a.iter_mut().zip(args) {
                    *d = self.idx(*n)?;
                }
                let kinds: Vec<Kind> = args
                    .iter()
                    .map(|n| self.kind(*n))
                    .collect::<Result<_, _>>()?;
                let ok = match f {
                    LiftOp::On => kinds.get(1) == Some(&kind) && kinds.get(2) == Some(&kind),
                    LiftOp::First | LiftOp::FirstOnly => kinds.first() == Some(&kind),
                    LiftOp::Distinct => kinds.first() == Some(&kind) && kinds.get(1) == Some(&kind),
                    LiftOp::Edge(_) => kinds.iter().all(|k| *k == Kind::Bool),
                };
                if !ok {
                    return Err(NoPlan);
                }
                Instr::Lift {
                    dst,
                    f,
                    args: a,
                    n: need(u8::try_from(args.len()).ok())?,
                    kind,
                }
            }
            Node::Delay { delay, reset } => self.delay(dst, i, *delay, *reset, Value::Unit)?,
        })
    }
}

impl Plan {
    /// The plan of `p`, if every node it evaluates has a form here; `kernel(n)` is node `n`'s
    /// function as a [`Kernel`] (`slift`, `fold`, `reduce`). Without a plan: the nodes that have
    /// no form here, in evaluation order (empty when the program has none to name).
    pub fn build(
        p: &ir::Program,
        kernel: impl Fn(NodeId) -> Option<Kernel>,
    ) -> Result<Plan, Vec<NodeId>> {
        let n = p.nodes.len();
        let never = u32::try_from(n).map_err(|_| Vec::new())?;
        if p.last_slot.len() != n {
            return Err(Vec::new());
        }
        // Nodes without a typed form are made `Kind::Val` (a call, or a move of values), then
        // the nodes they read when that form cannot take them as they are; until every node
        // has an instruction or one has none of either kind.
        let mut forced = vec![false; n];
        loop {
            let b = Builder {
                p,
                kinds: kinds(p, &kernel, &forced),
                never,
                consts: RefCell::new(Vec::new()),
                forced: forced.clone(),
            };
            let mut evaluated = vec![false; n];
            let mut instrs = Vec::with_capacity(n);
            let mut slow = Vec::new();
            let mut more = false;
            for &i in &p.order {
                match (evaluated.get_mut(i), b.instr(i, kernel(i))) {
                    (Some(e), Ok(instr)) => {
                        *e = true;
                        instrs.push(instr);
                    }
                    (Some(_), Err(NoPlan)) if !forced[i] => {
                        forced[i] = true;
                        more = true;
                    }
                    (Some(_), Err(NoPlan)) => {
                        let mut any = false;
                        for r in b.reads(i) {
                            if let Some(f) = forced.get_mut(r).filter(|f| !**f) {
                                *f = true;
                                any = true;
                            }
                        }
                        if any {
                            more = true;
                        } else {
                            slow.push(i);
                        }
                    }
                    (None, _) => slow.push(i),
                }
            }
            if more {
                continue;
            }
            if !slow.is_empty() {
                return Err(slow);
            }
            return Plan::assemble(&b, instrs, &evaluated).map_err(|_| Vec::new());
        }
    }

    /// The plan of the nodes' instructions: a `nil` for each node never evaluated, the slots
    /// kept across steps, the outputs.
    fn assemble(b: &Builder<'_>, instrs: Vec<Instr>, evaluated: &[bool]) -> Result<Plan, NoPlan> {
        let p = b.p;
        let n = p.nodes.len();
        // A node never evaluated has no event (no step reads one; the slots are shared by every
        // program on a thread, so they are emptied anyway).
        let mut all: Vec<Instr> = (0..n)
            .filter(|i| !evaluated[*i])
            .map(|i| b.idx(i).map(|dst| Instr::Nil { dst }))
            .collect::<Result<_, _>>()?;
        all.push(Instr::Nil { dst: b.never });
        all.extend(instrs);
        let mut kept = Vec::new();
        for (i, &s) in p.last_slot.iter().enumerate() {
            if s != NO_SLOT && evaluated[i] {
                kept.push((b.idx(i)?, s, b.kind(i)?));
            }
        }
        let outputs = p
            .output_nodes
            .iter()
            .map(|o| Ok((b.idx(*o)?, b.kind(*o)?)))
            .collect::<Result<_, NoPlan>>()?;
        let (vals, kept): (Vec<_>, Vec<_>) = kept.into_iter().partition(|k| k.2 == Kind::Val);
        let temp_nodes: Vec<u32> = all
            .iter()
            .filter_map(|i| match i {
                Instr::Call { dst, .. } | Instr::TimeVal { dst, .. } => Some(*dst),
                _ => None,
            })
            .collect();
        let calls = all.iter().any(|i| matches!(i, Instr::Call { .. }));
        let delays: Vec<_> = all
            .iter()
            .filter_map(|i| match i {
                Instr::Delay {
                    dst,
                    k,
                    amount,
                    reset,
                    ..
                } => Some((*dst, *k, *amount, *reset)),
                _ => None,
            })
            .collect();
        let full = !temp_nodes.is_empty() || !delays.is_empty() || b.forced.iter().any(|f| *f);
        let block = if full {
            None
        } else {
            block(&all, n + 1, &kept)
        };
        Ok(Plan {
            block,
            instrs: all,
            slots: n + 1,
            kept_vals: vals.into_iter().map(|(n, s, _)| (n, s)).collect(),
            kept,
            outputs,
            consts: b.consts.take(),
            calls,
            full,
            temp_nodes,
            delays,
        })
    }
}

/// The straight block of a plan's instructions (`instrs`, over `slots` slots; a plan without
/// calls, values or delays), if any node runs straight in it: a clock analysis for the steps
/// where every input has an event, after the first. An input then has its event; a node fires
/// for certain when its operands are nodes that do and constants, at least one a node (a signal
/// lift or an operator of them: every operand has a value and one has an event; a `fold`, a
/// `reduce`, `time`, an alias or a `default` of one). What depends on values or on kept values
/// (`filter`, `merge`, `last`, an event lift, a lift reading a node that may be silent) stays
/// the loop's instruction.
fn block(instrs: &[Instr], slots: usize, kept: &[(u32, u32, Kind)]) -> Option<Block> {
    let mut sure = vec![false; slots];
    let is = |sure: &[bool], n: u32| sure.get(n as usize).copied().unwrap_or(false);
    let opnd = |sure: &[bool], a: &Src| -> Option<Opnd> {
        if a.slot == CONST {
            Some(Opnd::Const(a.k))
        } else if is(sure, a.n) {
            Some(Opnd::Node(a.n))
        } else {
            None
        }
    };
    // Operands all certain or constant, one a node: they fire.
    let fire = |ops: &[Option<Opnd>]| -> bool {
        ops.iter().all(Option::is_some) && ops.iter().any(|o| matches!(o, Some(Opnd::Node(_))))
    };
    let mut inputs = Vec::new();
    let mut code = Vec::with_capacity(instrs.len());
    let mut straight = 0;
    for (i, instr) in instrs.iter().enumerate() {
        let s = match instr {
            Instr::Input { dst, input, kind } if *kind != Kind::Val => {
                inputs.push(*input);
                Some(Straight::Input {
                    dst: *dst,
                    input: *input,
                    kind: *kind,
                })
            }
            Instr::Op2 { dst, op, a, b } => {
                let (x, y) = (opnd(&sure, a), opnd(&sure, b));
                match (x, y) {
                    (Some(a), Some(b)) if fire(&[x, y]) => Some(Straight::Op2 {
                        dst: *dst,
                        op: *op,
                        a,
                        b,
                    }),
                    _ => None,
                }
            }
            Instr::Op1 { dst, op, a } if is(&sure, a.n) && a.slot != CONST => Some(Straight::Op1 {
                dst: *dst,
                op: *op,
                a: a.n,
            }),
            Instr::Ite {
                dst,
                cond,
                then,
                other,
            } => {
                let ops = [opnd(&sure, cond), opnd(&sure, then), opnd(&sure, other)];
                match ops {
                    [Some(cond), Some(then), Some(other)] if fire(&ops) => Some(Straight::Ite {
                        dst: *dst,
                        cond,
                        then,
                        other,
                    }),
                    _ => None,
                }
            }
            Instr::Fold {
                dst,
                stream,
                acc,
                op,
                a,
                b,
                ..
            } if is(&sure, *stream) => Some(Straight::Fold {
                dst: *dst,
                stream: *stream,
                acc: *acc,
                op: *op,
                a: *a,
                b: *b,
            }),
            Instr::Reduce {
                dst,
                stream,
                acc,
                op,
                a,
                b,
            } if is(&sure, *stream) => Some(Straight::Reduce {
                dst: *dst,
                stream: *stream,
                acc: *acc,
                op: *op,
                a: *a,
                b: *b,
            }),
            Instr::Alias { dst, src }
            | Instr::Default {
                dst, stream: src, ..
            } if is(&sure, *src) => Some(Straight::Copy {
                dst: *dst,
                src: Opnd::Node(*src),
            }),
            Instr::Time { dst, src } if is(&sure, *src) => Some(Straight::Time { dst: *dst }),
            Instr::SConst { dst, args, bits } => {
                let ops: Vec<_> = args.iter().map(|a| opnd(&sure, a)).collect();
                fire(&ops).then_some(Straight::Copy {
                    dst: *dst,
                    src: Opnd::Const(*bits),
                })
            }
            Instr::SPick { dst, args, pick } => {
                let ops: Vec<_> = args.iter().map(|a| opnd(&sure, a)).collect();
                match ops.get(*pick) {
                    Some(&Some(src)) if fire(&ops) => Some(Straight::Copy { dst: *dst, src }),
                    _ => None,
                }
            }
            _ => None,
        };
        match s {
            Some(s) => {
                let dst = match &s {
                    Straight::Input { dst, .. }
                    | Straight::Op2 { dst, .. }
                    | Straight::Op1 { dst, .. }
                    | Straight::Ite { dst, .. }
                    | Straight::Fold { dst, .. }
                    | Straight::Reduce { dst, .. }
                    | Straight::Copy { dst, .. }
                    | Straight::Time { dst } => *dst,
                    Straight::Other(_) => u32::MAX,
                };
                if let Some(f) = sure.get_mut(dst as usize) {
                    *f = true;
                }
                straight += 1;
                code.push(s);
            }
            None => code.push(Straight::Other(u32::try_from(i).ok()?)),
        }
    }
    // The kept nodes the block fires for certain: written back without a presence test, by kind.
    let mut keep = Keep::default();
    for &(n, slot, kind) in kept {
        match kind {
            Kind::Float if is(&sure, n) => keep.float.push((n, slot)),
            Kind::Int if is(&sure, n) => keep.int.push((n, slot)),
            Kind::Bool if is(&sure, n) => keep.bool.push((n, slot)),
            _ => keep.rest.push((n, slot, kind)),
        }
    }
    (!inputs.is_empty() && straight > inputs.len()).then_some(Block {
        inputs,
        keep,
        code: code.iter().map(Fused::of).collect(),
        straight,
    })
}
