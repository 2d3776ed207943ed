//! The straight block compiled once: each [`Straight`] node made one [`Fused`] instruction whose
//! variant names its operator and its operands' shape (a node's event or a constant), so a node
//! costs one dispatch and its slot traffic, not a dispatch on its kind, then on its operator, then
//! on each operand.
//!
//! Owns: [`Fused`] (made from a [`Straight`] by [`Fused::of`] when the plan is made) and
//! [`Fused::run`], one node of the block as `Plan::straight` runs it.
//!
//! Why: the block's nodes are known when the plan is made (their kinds, operators and operands),
//! but `Straight` keeps them as data, looked at on every step: an `Op2` dispatched on its
//! operator after its kind, an `Opnd` tested for node or constant, an input's kind matched
//! against its value's. Here those choices are made once; what a variant runs is the same
//! computation (`Op2::run` of a known operator), so the block computes exactly what it did.

use super::{
    Cur, FArg, Kind, Op1, Op2, Opnd, Src, StepState, Straight, cur_of, kept_of, opnd, some,
};
use crate::value::Value;

/// Write node `dst`'s event `v`.
#[inline(always)]
fn set<S: Cur + ?Sized>(cur: &mut S, dst: u32, v: u64) -> Flow {
    cur.set(dst, some(v));
    Flow::Done
}

/// Node `n`'s bits this step.
#[inline(always)]
fn bits<S: Cur + ?Sized>(cur: &S, n: u32) -> u64 {
    cur_of(cur, n).bits
}

/// How one fused node ended: its event written, or what `Plan::straight` must do.
pub(super) enum Flow {
    /// Its event is in its slot.
    Done,
    /// The plan's loop instruction `i` runs this node.
    Other(u32),
    /// The block cannot run this step (an input without its event, a `fold` without a kept
    /// value): the loop runs it.
    Loop,
}

/// Declares [`Fused`] with a variant per (operator, shape) of the binary operators that cannot
/// fail (`NN`: two nodes, `NC`: a node and a constant, `CN`: a constant and a node), its
/// constructor from a [`Straight`] node and its step.
macro_rules! fused {
    ($($op:ident: $nn:ident $nc:ident $cn:ident),* $(,)?) => {
        /// One node of the straight block, compiled (see the module's documentation).
        #[derive(Clone, Debug)]
        pub(super) enum Fused {
            $(
                $nn { dst: u32, a: u32, b: u32 },
                $nc { dst: u32, a: u32, k: u64 },
                $cn { dst: u32, k: u64, b: u32 },
            )*
            /// Any other binary operator (those that may fail: `Int`'s).
            Op2 { dst: u32, op: Op2, a: Opnd, b: Opnd },
            InputFloat { dst: u32, input: u32 },
            InputInt { dst: u32, input: u32 },
            InputBool { dst: u32, input: u32 },
            Input { dst: u32, input: u32, kind: Kind },
            Not { dst: u32, a: u32 },
            FNeg { dst: u32, a: u32 },
            IntToFloat { dst: u32, a: u32 },
            /// `if` with a node as condition and each branch a node or a constant.
            IteNN { dst: u32, cond: u32, then: u32, other: u32 },
            IteNC { dst: u32, cond: u32, then: u32, k: u64 },
            IteCN { dst: u32, cond: u32, k: u64, other: u32 },
            Ite { dst: u32, cond: Opnd, then: Opnd, other: Opnd },
            Fold { dst: u32, stream: u32, acc: Src, op: Op2, a: FArg, b: FArg },
            Reduce { dst: u32, stream: u32, acc: Src, op: Op2, a: FArg, b: FArg },
            CopyNode { dst: u32, src: u32 },
            CopyConst { dst: u32, k: u64 },
            Time { dst: u32 },
            Other(u32),
        }

        impl Fused {
            /// A binary operator of the list on `a` and `b`, fused.
            fn op2(dst: u32, op: Op2, a: Opnd, b: Opnd) -> Fused {
                match (op, a, b) {
                    $(
                        (Op2::$op, Opnd::Node(a), Opnd::Node(b)) => Fused::$nn { dst, a, b },
                        (Op2::$op, Opnd::Node(a), Opnd::Const(k)) => Fused::$nc { dst, a, k },
                        (Op2::$op, Opnd::Const(k), Opnd::Node(b)) => Fused::$cn { dst, k, b },
                    )*
                    _ => Fused::Op2 { dst, op, a, b },
                }
            }

            /// Run this node on this step's slots: what `Straight` computes. `None`: no scalar
            /// answer (the plan gives the step to the general step).
            #[inline(always)]
            pub(super) fn run<S: Cur + ?Sized>(
                &self,
                st: &StepState<'_>,
                last: &[Option<Value>],
                cur: &mut S,
            ) -> Option<Flow> {
                let input = |i: u32| match st.inputs.get(i as usize) {
                    Some(Some(v)) => Some(v),
                    _ => None,
                };
                Some(match *self {
                    $(
                        Fused::$nn { dst, a, b } => {
                            let v = Op2::$op.run(bits(cur, a), bits(cur, b))?;
                            set(cur, dst, v)
                        }
                        Fused::$nc { dst, a, k } => {
                            let v = Op2::$op.run(bits(cur, a), k)?;
                            set(cur, dst, v)
                        }
                        Fused::$cn { dst, k, b } => {
                            let v = Op2::$op.run(k, bits(cur, b))?;
                            set(cur, dst, v)
                        }
                    )*
                    Fused::Op2 { dst, op, a, b } => {
                        let v = op.run(opnd(cur, a), opnd(cur, b))?;
                        set(cur, dst, v)
                    }
                    Fused::InputFloat { dst, input: i } => match input(i) {
                        Some(Value::Float(x)) => {
                            let v = x.to_bits();
                            set(cur, dst, v)
                        }
                        Some(_) => return None,
                        None => Flow::Loop,
                    },
                    Fused::InputInt { dst, input: i } => match input(i) {
                        Some(Value::Int(x)) => {
                            let v = *x as u64;
                            set(cur, dst, v)
                        }
                        Some(_) => return None,
                        None => Flow::Loop,
                    },
                    Fused::InputBool { dst, input: i } => match input(i) {
                        Some(Value::Bool(x)) => {
                            let v = u64::from(*x);
                            set(cur, dst, v)
                        }
                        Some(_) => return None,
                        None => Flow::Loop,
                    },
                    Fused::Input { dst, input: i, kind } => match input(i) {
                        Some(v) => {
                            let v = kind.bits(v)?;
                            set(cur, dst, v)
                        }
                        None => Flow::Loop,
                    },
                    Fused::Not { dst, a } => {
                        let v = Op1::Not.run(bits(cur, a));
                        set(cur, dst, v)
                    }
                    Fused::FNeg { dst, a } => {
                        let v = Op1::FNeg.run(bits(cur, a));
                        set(cur, dst, v)
                    }
                    Fused::IntToFloat { dst, a } => {
                        let v = Op1::IntToFloat.run(bits(cur, a));
                        set(cur, dst, v)
                    }
                    Fused::IteNN { dst, cond, then, other } => {
                        let v = if bits(cur, cond) != 0 {
                            bits(cur, then)
                        } else {
                            bits(cur, other)
                        };
                        set(cur, dst, v)
                    }
                    Fused::IteNC { dst, cond, then, k } => {
                        let v = if bits(cur, cond) != 0 { bits(cur, then) } else { k };
                        set(cur, dst, v)
                    }
                    Fused::IteCN { dst, cond, k, other } => {
                        let v = if bits(cur, cond) != 0 { k } else { bits(cur, other) };
                        set(cur, dst, v)
                    }
                    Fused::Ite { dst, cond, then, other } => {
                        let v = if opnd(cur, cond) != 0 {
                            opnd(cur, then)
                        } else {
                            opnd(cur, other)
                        };
                        set(cur, dst, v)
                    }
                    Fused::Fold { dst, stream, acc, op, a, b } => {
                        match kept_of(last, acc.slot, acc.kind)? {
                            Some(s) => {
                                let v = op.fold(a, b, s, bits(cur, stream))?;
                                set(cur, dst, v)
                            }
                            None => Flow::Loop,
                        }
                    }
                    Fused::Reduce { dst, stream, acc, op, a, b } => {
                        let x = bits(cur, stream);
                        match kept_of(last, acc.slot, acc.kind)? {
                            Some(s) => {
                                let v = op.fold(a, b, s, x)?;
                                set(cur, dst, v)
                            }
                            None => {
                                let v = x;
                                set(cur, dst, v)
                            }
                        }
                    }
                    Fused::CopyNode { dst, src } => {
                        let v = bits(cur, src);
                        set(cur, dst, v)
                    }
                    Fused::CopyConst { dst, k } => {
                        let v = k;
                        set(cur, dst, v)
                    }
                    Fused::Time { dst } => {
                        let v = st.ts as u64;
                        set(cur, dst, v)
                    }
                    Fused::Other(i) => Flow::Other(i),
                })
            }
        }
    };
}

fused! {
    FAdd: FAddNN FAddNC FAddCN,
    FSub: FSubNN FSubNC FSubCN,
    FMul: FMulNN FMulNC FMulCN,
    FDiv: FDivNN FDivNC FDivCN,
    FLt: FLtNN FLtNC FLtCN,
    FGt: FGtNN FGtNC FGtCN,
    FLe: FLeNN FLeNC FLeCN,
    FGe: FGeNN FGeNC FGeCN,
    FEq: FEqNN FEqNC FEqCN,
    FNe: FNeNN FNeNC FNeCN,
    ILt: ILtNN ILtNC ILtCN,
    IGt: IGtNN IGtNC IGtCN,
    ILe: ILeNN ILeNC ILeCN,
    IGe: IGeNN IGeNC IGeCN,
    BitsEq: BitsEqNN BitsEqNC BitsEqCN,
    BitsNe: BitsNeNN BitsNeNC BitsNeCN,
    And: AndNN AndNC AndCN,
    Or: OrNN OrNC OrCN,
}

impl Fused {
    /// The compiled form of a straight block's node.
    pub(super) fn of(s: &Straight) -> Fused {
        match *s {
            Straight::Input { dst, input, kind } => match kind {
                Kind::Float => Fused::InputFloat { dst, input },
                Kind::Int => Fused::InputInt { dst, input },
                Kind::Bool => Fused::InputBool { dst, input },
                Kind::Unit | Kind::Val => Fused::Input { dst, input, kind },
            },
            Straight::Op2 { dst, op, a, b } => Fused::op2(dst, op, a, b),
            Straight::Op1 { dst, op, a } => match op {
                Op1::Not => Fused::Not { dst, a },
                Op1::FNeg => Fused::FNeg { dst, a },
                Op1::IntToFloat => Fused::IntToFloat { dst, a },
            },
            Straight::Ite {
                dst,
                cond,
                then,
                other,
            } => match (cond, then, other) {
                (Opnd::Node(cond), Opnd::Node(then), Opnd::Node(other)) => Fused::IteNN {
                    dst,
                    cond,
                    then,
                    other,
                },
                (Opnd::Node(cond), Opnd::Node(then), Opnd::Const(k)) => {
                    Fused::IteNC { dst, cond, then, k }
                }
                (Opnd::Node(cond), Opnd::Const(k), Opnd::Node(other)) => Fused::IteCN {
                    dst,
                    cond,
                    k,
                    other,
                },
                _ => Fused::Ite {
                    dst,
                    cond,
                    then,
                    other,
                },
            },
            Straight::Fold {
                dst,
                stream,
                acc,
                op,
                a,
                b,
            } => Fused::Fold {
                dst,
                stream,
                acc,
                op,
                a,
                b,
            },
            Straight::Reduce {
                dst,
                stream,
                acc,
                op,
                a,
                b,
            } => Fused::Reduce {
                dst,
                stream,
                acc,
                op,
                a,
                b,
            },
            Straight::Copy {
                dst,
                src: Opnd::Node(src),
            } => Fused::CopyNode { dst, src },
            Straight::Copy {
                dst,
                src: Opnd::Const(k),
            } => Fused::CopyConst { dst, k },
            Straight::Time { dst } => Fused::Time { dst },
            Straight::Other(i) => Fused::Other(i),
        }
    }
}
