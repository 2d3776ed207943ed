//! The closure compiler: value code ([`Code`], data in the IR) compiled into Rust closures, once
//! per program, when its first monitor is created.
//!
//! Owns: [`Program`] (what monitors run: the IR with its compiled code, made once and shared;
//! its listing for `check --ir`, [`Listing`], which ends with how its step runs), [`Exec`] (compiled code: a context and a frame in, a value out), [`Ctx`] (the compiled
//! function table and node functions of one program), [`compile`], [`compile_program_with`], the
//! semantics of [`Prim`]itives and [`LiftFn`]s, function values ([`FnClosure`],
//! [`native_value`]), the [`Fast`] forms of node functions that are one operator or native on
//! the node's arguments (run by the monitor on its arguments by reference). The semantics of
//! primitives ([`prim`]) are also what the lowering's constant fold (`crate::ir::fold`) is
//! handed through the builtins table; nothing else here serves the lowering.
//!
//! Calls between program functions go through the context passed to every closure (an index
//! into [`Ctx`]'s table), so compiled functions never refer to each other and recursion makes
//! no reference cycle. A function value holds its context: strongly when made at run time with
//! captured slots, weakly for the one shared value of a function without captures (kept in the
//! context itself; a strong reference there would be a cycle). Code applying a callee to a
//! node's arguments as they come (`f(slot 0, slot 1)`) passes the argument slice through
//! without copying, so a step costs what a hand-written closure would.

use crate::ir::code::{Callee, Code, FnId, LiftFn, Prim};
use crate::ir::scalar_op;
use crate::ir::{self, Node, NodeId};
use crate::ir::{BinOp, UnaryOp};
use crate::runtime::collections;
use crate::runtime::flat::{IntOp, KArg, Kernel, Plan};
use crate::runtime::ops;
use crate::value::{
    Callable, NativeFn, RuntimeError, Value, call_function_value, call_native, nested_call,
};
use std::sync::{Arc, OnceLock, Weak};

/// Compiled code: evaluates over a frame, calling program functions through the context.
pub type Exec = Arc<dyn Fn(&Ctx, &[Value]) -> Value + Send + Sync>;

/// The compiled code of one program (or, during lowering, of the functions finished so far).
pub struct Ctx {
    /// Per function: its compiled body (a stub error for a function never finished).
    fns: Vec<Exec>,
    /// Per function: its value without captures, made on first use.
    values: Vec<OnceLock<Value>>,
    /// Per node: its compiled function (`slift`, `fold`, `reduce` and `lift` nodes).
    nodes: Vec<Option<Exec>>,
    /// Per node: its function as a [`Fast`] form, when it has one.
    fast: Vec<Option<Fast>>,
    /// The program's step as a flat plan, when it has one (see `runtime::flat`); without one,
    /// the nodes that have no form in it (empty: none to name, or the plan is not used).
    plan: Result<Plan, Vec<NodeId>>,
    me: Weak<Ctx>,
}

impl std::fmt::Debug for Ctx {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} compiled functions", self.fns.len())
    }
}

impl Ctx {
    /// The compiled function of node `n`, if it has one.
    #[inline]
    pub fn node(&self, n: usize) -> Option<&Exec> {
        self.nodes.get(n).and_then(Option::as_ref)
    }

    /// The [`Fast`] form of node `n`'s function, if it has one.
    #[inline]
    pub fn fast(&self, n: usize) -> Option<&Fast> {
        self.fast.get(n).and_then(Option::as_ref)
    }

    /// The program's flat plan, if it has one (with calls or without: [`Plan::has_calls`]).
    #[inline]
    pub fn plan(&self) -> Option<&Plan> {
        self.plan.as_ref().ok()
    }

    /// The nodes that have no form in the flat plan, when the program has none (they make every
    /// node run by the general step).
    pub fn slow_nodes(&self) -> Option<&[NodeId]> {
        self.plan.as_ref().err().map(Vec::as_slice)
    }

    /// Call function `id` with `frame`, nested in the calls running now ([`nested_call`]: a
    /// recursion too deep is an error value, never a stack overflow).
    #[inline]
    pub fn call(&self, id: FnId, frame: &[Value]) -> Value {
        match self.fns.get(id) {
            Some(f) => nested_call(|| f(self, frame)),
            None => not_compiled(),
        }
    }

    /// A function value of `fun` over `captured`.
    fn closure(&self, fun: FnId, captured: &[Value]) -> Value {
        if captured.is_empty()
            && let Some(slot) = self.values.get(fun)
        {
            return slot
                .get_or_init(|| {
                    Value::Closure(Arc::new(FnClosure {
                        ctx: CtxRef::Weak(self.me.clone()),
                        fun,
                        captured: Vec::new(),
                    }))
                })
                .clone();
        }
        let ctx = match self.me.upgrade() {
            Some(c) if !captured.is_empty() => CtxRef::Strong(c),
            _ => CtxRef::Weak(self.me.clone()),
        };
        Value::Closure(Arc::new(FnClosure {
            ctx,
            fun,
            captured: captured.to_vec(),
        }))
    }
}

/// A context built from compiled functions (`None`: not finished, an error when called).
fn context(
    fns: Vec<Option<Exec>>,
    nodes: Vec<Option<Exec>>,
    fast: Vec<Option<Fast>>,
    plan: Result<Plan, Vec<NodeId>>,
) -> Arc<Ctx> {
    let n = fns.len();
    Arc::new_cyclic(|me| Ctx {
        fns: fns
            .into_iter()
            .map(|f| f.unwrap_or_else(|| Arc::new(|_: &Ctx, _: &[Value]| not_compiled())))
            .collect(),
        values: (0..n).map(|_| OnceLock::new()).collect(),
        fast,
        nodes,
        plan,
        me: me.clone(),
    })
}

/// A program ready to run, shared (in an `Arc`) by every monitor instance: the IR as the
/// lowering made it ([`ir::Program`], all data; this reads as it) and its code compiled into
/// closures, made once by the first monitor created and shared by every monitor of the program.
/// The compiled code lives here, not in the IR, so the IR never refers to the evaluator.
#[derive(Debug)]
pub struct Program {
    ir: ir::Program,
    exec: OnceLock<Arc<Ctx>>,
    /// Whether the program may run as a flat plan (`runtime::flat`) when it has one.
    flat: bool,
    /// Whether it runs a plan that calls compiled functions ([`Plan::has_calls`]); by default
    /// not (the general step costs less on them).
    calls: bool,
}

impl Program {
    /// The IR, its code not compiled yet.
    pub fn new(ir: ir::Program) -> Program {
        Program {
            ir,
            exec: OnceLock::new(),
            flat: true,
            calls: false,
        }
    }

    /// The IR, run as a flat plan whenever it has one, calls or not: what the plan's calls are
    /// tested and measured with.
    pub fn with_calls(ir: ir::Program) -> Program {
        Program {
            calls: true,
            ..Program::new(ir)
        }
    }

    /// The flat plan the monitor runs, if any: the program's, when it has no calls or runs them
    /// ([`Program::with_calls`]).
    #[inline]
    pub fn step_plan(&self) -> Option<&Plan> {
        self.exec().plan().filter(|p| self.calls || !p.has_calls())
    }

    /// The IR, always run by the general step, never as a flat plan: what the plan is tested
    /// and measured against.
    pub fn general_only(ir: ir::Program) -> Program {
        Program {
            flat: false,
            ..Program::new(ir)
        }
    }

    /// Take the IR back (to make another program of it).
    pub fn into_ir(self) -> ir::Program {
        self.ir
    }

    /// The program's code compiled into closures: built once, by the first monitor created,
    /// and shared by every monitor of the program.
    #[inline]
    pub fn exec(&self) -> &Arc<Ctx> {
        self.exec
            .get_or_init(|| compile_program_with(&self.ir, self.flat))
    }
}

/// The listing of a program (`check --ir`): the IR's ([`ir::Program::ir`]), then how its step
/// runs: as a flat plan, or by the general step, with the nodes that keep it from a plan.
pub struct Listing<'a>(&'a Program);

impl Program {
    /// A readable listing of the program and of how its step runs (implements `Display`).
    pub fn ir(&self) -> Listing<'_> {
        Listing(self)
    }
}

impl std::fmt::Display for Listing<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let p = self.0;
        write!(f, "{}", p.ir.ir())?;
        let cx = p.exec();
        match (cx.plan(), cx.slow_nodes()) {
            (Some(plan), _) if plan.has_calls() => {
                let names: Vec<String> = plan.calls().iter().map(|n| format!("n{n}")).collect();
                writeln!(
                    f,
                    "-- step: the general step, for all {} nodes: the flat plan would call {} compiled {} on values, which costs more than the general step: {}",
                    p.order.len(),
                    if names.len() == 1 {
                        "this node's"
                    } else {
                        "these nodes'"
                    },
                    if names.len() == 1 {
                        "function"
                    } else {
                        "functions"
                    },
                    names.join(", ")
                )
            }
            (Some(_), _) => writeln!(
                f,
                "-- step: the flat plan, one typed instruction per node (no node falls back to the general step)"
            ),
            (None, Some(slow)) if !slow.is_empty() => {
                let names: Vec<String> = slow.iter().map(|n| format!("n{n}")).collect();
                writeln!(
                    f,
                    "-- step: the general step, for all {} nodes (slower): no flat plan, since {} {} no form in it: {}",
                    p.order.len(),
                    if slow.len() == 1 {
                        "this node"
                    } else {
                        "these nodes"
                    },
                    if slow.len() == 1 { "has" } else { "have" },
                    names.join(", ")
                )
            }
            (None, _) => writeln!(
                f,
                "-- step: the general step, for all {} nodes",
                p.order.len()
            ),
        }
    }
}

impl From<ir::Program> for Program {
    fn from(ir: ir::Program) -> Program {
        Program::new(ir)
    }
}

impl std::ops::Deref for Program {
    type Target = ir::Program;

    #[inline]
    fn deref(&self) -> &ir::Program {
        &self.ir
    }
}

fn compile_program_with(p: &ir::Program, flat: bool) -> Arc<Ctx> {
    let fns = p
        .functions
        .iter()
        .map(|f| f.body.as_ref().map(compile))
        .collect();
    let nodes = p
        .nodes
        .iter()
        .map(|n| match n {
            Node::SLift { f, .. } | Node::Fold { f, .. } | Node::Reduce { f, .. } => {
                Some(compile(f))
            }
            Node::Lift { f, .. } => f.code().map(compile),
            _ => None,
        })
        .collect();
    let fast = p
        .nodes
        .iter()
        .map(|n| match n {
            Node::SLift { f, args } => Fast::of(f, args.len(), &p.functions),
            Node::Fold { f, .. } | Node::Reduce { f, .. } => Fast::of(f, 2, &p.functions),
            _ => None,
        })
        .collect::<Vec<_>>();
    let plan = if flat {
        Plan::build(p, |n| match (fast.get(n)?, p.nodes.get(n)?) {
            (Some(f), _) => f.kernel(),
            // `slift(a, b) { $0 }` has no fast form (no operator): the plan picks the argument.
            (None, Node::SLift { f, args }) => picked_arg(f, args.len(), &p.functions, 4)
                .and_then(|i| u8::try_from(i).ok())
                .map(Kernel::Pick),
            (None, _) => None,
        })
    } else {
        Err(Vec::new())
    };
    context(fns, nodes, fast, plan)
}

/// The argument a node function over `arity` arguments is (`$1`, or a function whose body is
/// one of its parameters applied to the arguments: `(a, v) => v`), if it is one.
fn picked_arg(
    code: &Code,
    arity: usize,
    functions: &[crate::ir::Function],
    depth: u8,
) -> Option<usize> {
    match code {
        Code::Slot(i) if *i < arity => Some(*i),
        Code::Apply(callee, args) if depth > 0 => {
            let Callee::Fn(id) = &**callee else {
                return None;
            };
            let fun = functions.get(*id)?;
            if fun.frame != args.len() {
                return None;
            }
            match args.get(picked_arg(
                fun.body.as_ref()?,
                args.len(),
                functions,
                depth - 1,
            )?)? {
                Code::Slot(j) if *j < arity => Some(*j),
                _ => None,
            }
        }
        _ => None,
    }
}

/// A node function that is one operator or native applied to the node's arguments and
/// constants (`$0 +. $1`, `$0 + 1`, `!$0`, `intToFloat($0)`, or a program function whose body
/// is one of these), or a constant (`slift(x) { () }`, what `unitIf` makes). The monitor runs it
/// on its arguments by reference: no frame of cloned values, no closure call. It computes
/// exactly what the compiled closure does.
#[derive(Debug, Clone)]
pub enum Fast {
    /// A constant, whatever the arguments.
    Const(Value),
    Binary(BinOp, Operand, Operand),
    Unary(UnaryOp, Operand),
    Native1(NativeFn, Operand),
    Native2(NativeFn, Operand, Operand),
    /// `intToFloat` (the native, for what is not an `Int`): a node every mean or ratio has.
    IntToFloat(NativeFn, Operand),
}

/// An operand of a [`Fast`] form: argument `i` of the node, or a constant.
#[derive(Debug, Clone)]
pub enum Operand {
    Arg(usize),
    Const(Value),
}

impl Operand {
    /// The operand's value given the node's arguments.
    #[inline]
    pub fn get<'a>(&'a self, args: &[&'a Value]) -> Option<&'a Value> {
        match self {
            Operand::Arg(i) => args.get(*i).copied(),
            Operand::Const(v) => Some(v),
        }
    }
}

impl Fast {
    /// The fast form of `code` over a frame of `arity` arguments, if it has one.
    pub fn of(code: &Code, arity: usize, functions: &[crate::ir::Function]) -> Option<Fast> {
        Fast::within(code, arity, functions, 4)
    }

    fn within(
        code: &Code,
        arity: usize,
        functions: &[crate::ir::Function],
        depth: u8,
    ) -> Option<Fast> {
        let (callee, args) = match code {
            Code::Apply(callee, args) => (callee, args),
            Code::Const(v) => return Some(Fast::Const(v.clone())),
            _ => return None,
        };
        let operand = |c: &Code| match c {
            Code::Slot(i) if *i < arity => Some(Operand::Arg(*i)),
            Code::Const(v) => Some(Operand::Const(v.clone())),
            _ => None,
        };
        match (&**callee, &args[..]) {
            (Callee::Prim(Prim::Binary(op)), [a, b]) => {
                Some(Fast::Binary(*op, operand(a)?, operand(b)?))
            }
            (Callee::Prim(Prim::Unary(op)), [a]) => Some(Fast::Unary(*op, operand(a)?)),
            (
                Callee::Native {
                    name: "intToFloat",
                    f,
                },
                [a],
            ) => Some(Fast::IntToFloat(*f, operand(a)?)),
            (Callee::Native { f, .. }, [a]) => Some(Fast::Native1(*f, operand(a)?)),
            (Callee::Native { f, .. }, [a, b]) => Some(Fast::Native2(*f, operand(a)?, operand(b)?)),
            (Callee::Fn(id), _) if depth > 0 => {
                // The callee's frame is exactly the argument values: substitute them.
                let fun = functions.get(*id)?;
                if fun.frame != args.len() {
                    return None;
                }
                let inner = Fast::within(fun.body.as_ref()?, args.len(), functions, depth - 1)?;
                let ops: Vec<Operand> = args.iter().map(operand).collect::<Option<_>>()?;
                let sub = |o: Operand| match o {
                    Operand::Arg(j) => ops.get(j).cloned(),
                    c @ Operand::Const(_) => Some(c),
                };
                Some(match inner {
                    Fast::Const(v) => Fast::Const(v),
                    Fast::Binary(op, a, b) => Fast::Binary(op, sub(a)?, sub(b)?),
                    Fast::Unary(op, a) => Fast::Unary(op, sub(a)?),
                    Fast::Native1(f, a) => Fast::Native1(f, sub(a)?),
                    Fast::Native2(f, a, b) => Fast::Native2(f, sub(a)?, sub(b)?),
                    Fast::IntToFloat(f, a) => Fast::IntToFloat(f, sub(a)?),
                })
            }
            _ => None,
        }
    }

    /// The form as a flat plan's [`Kernel`], if it is one scalar operator (the kernel computes
    /// what [`Fast::run`] does on scalars and gives up on anything else).
    fn kernel(&self) -> Option<Kernel> {
        let arg = |o: &Operand| match o {
            Operand::Arg(i) => u8::try_from(*i).ok().map(KArg::Arg),
            Operand::Const(v) => Some(KArg::Const(v.clone())),
        };
        Some(match self {
            Fast::Const(v) => Kernel::Const(v.clone()),
            Fast::Binary(op, a, b) => match (scalar_op(*op), op) {
                (Some(sop), _) => Kernel::Op(sop, arg(a)?, arg(b)?),
                (None, BinOp::Mul) => Kernel::Int(IntOp::Mul, arg(a)?, arg(b)?),
                (None, BinOp::Div) => Kernel::Int(IntOp::Div, arg(a)?, arg(b)?),
                (None, BinOp::Mod) => Kernel::Int(IntOp::Mod, arg(a)?, arg(b)?),
                (None, BinOp::Eq | BinOp::Ne) => Kernel::Eq {
                    ne: *op == BinOp::Ne,
                    a: arg(a)?,
                    b: arg(b)?,
                },
                (None, _) => return None,
            },
            Fast::Unary(UnaryOp::Not, a) => Kernel::Not(arg(a)?),
            Fast::Unary(UnaryOp::FNeg, a) => Kernel::FNeg(arg(a)?),
            Fast::IntToFloat(_, a) => Kernel::IntToFloat(arg(a)?),
            Fast::Unary(..) | Fast::Native1(..) | Fast::Native2(..) => return None,
        })
    }

    /// Run on the node's argument values (`None`: an operand out of range, never for a form
    /// made by [`Fast::of`] with the node's arity). Inline in the evaluator's loop: the scalar
    /// cases of constants, operators and `intToFloat` (an operator on `Float`/`Int`/`Bool`
    /// operands as operator nodes compute it, `!`, `-.`, `intToFloat` of an `Int`); anything
    /// else (errors, strings, tuples, overflow, natives) goes out of line to the general
    /// semantics.
    #[inline(always)]
    pub fn run(&self, args: &[&Value]) -> Option<Value> {
        Some(match self {
            Fast::Binary(op, a, b) => {
                let (x, y) = (a.get(args)?, b.get(args)?);
                let inline = match scalar_op(*op) {
                    Some(sop) => sop.eval_values(x, y),
                    None => match (x, y) {
                        (
                            Value::Float(_) | Value::Int(_) | Value::Bool(_),
                            Value::Float(_) | Value::Int(_) | Value::Bool(_),
                        ) => ops::eq_values(*op, x, y),
                        _ => None,
                    },
                };
                match inline {
                    Some(r) => r,
                    None => binary_general(*op, x, y),
                }
            }
            Fast::Unary(op, a) => {
                let a = a.get(args)?;
                match ops::unary_fast(*op, a) {
                    Some(r) => r,
                    None => unary_general(*op, a),
                }
            }
            Fast::IntToFloat(f, a) => match a.get(args)? {
                Value::Int(i) => Value::Float(*i as f64),
                v => native_general(*f, v),
            },
            // `unitIf`'s `()`, and other constants.
            Fast::Const(Value::Unit) => Value::Unit,
            Fast::Const(v) => v.clone(),
            Fast::Native1(f, a) => native_general(*f, a.get(args)?),
            Fast::Native2(f, a, b) => native2_general(*f, a.get(args)?, b.get(args)?),
        })
    }
}

/// The general ways of [`Fast::run`], out of the evaluator's loop.
#[inline(never)]
fn binary_general(op: BinOp, a: &Value, b: &Value) -> Value {
    // What `binary` does after its scalar path, which `Fast::run` has already taken.
    ops::eq_values(op, a, b).unwrap_or_else(|| ops::binary_value(op, a, b))
}

#[inline(never)]
fn unary_general(op: UnaryOp, a: &Value) -> Value {
    ops::unary_value(op, a)
}

#[inline(never)]
fn native_general(f: NativeFn, a: &Value) -> Value {
    call_native(f, std::slice::from_ref(a))
}

#[inline(never)]
fn native2_general(f: NativeFn, a: &Value, b: &Value) -> Value {
    call_native(f, &[a.clone(), b.clone()])
}

enum CtxRef {
    Strong(Arc<Ctx>),
    Weak(Weak<Ctx>),
}

/// A program function as a value, with the captured slots of its enclosing frame.
pub struct FnClosure {
    ctx: CtxRef,
    fun: FnId,
    captured: Vec<Value>,
}

impl std::fmt::Debug for FnClosure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("<function>")
    }
}

impl Callable for FnClosure {
    fn call(&self, args: &[Value]) -> Value {
        let ctx = match &self.ctx {
            CtxRef::Strong(c) => c.clone(),
            CtxRef::Weak(w) => match w.upgrade() {
                Some(c) => c,
                None => return not_compiled(),
            },
        };
        if self.captured.is_empty() {
            return ctx.call(self.fun, args);
        }
        let mut frame = self.captured.clone();
        frame.extend_from_slice(args);
        ctx.call(self.fun, &frame)
    }
}

/// A native as a value.
pub struct NativeClosure(pub NativeFn);

impl std::fmt::Debug for NativeClosure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("<function>")
    }
}

impl Callable for NativeClosure {
    fn call(&self, args: &[Value]) -> Value {
        call_native(self.0, args)
    }
}

fn not_compiled() -> Value {
    Value::Error(RuntimeError::Other("function not compiled".into()))
}

fn is_err(v: &Value) -> Option<Value> {
    match v {
        Value::Error(_) => Some(v.clone()),
        _ => None,
    }
}

/// Apply a callee to argument values.
pub fn apply(cx: &Ctx, callee: &Callee, a: &[Value]) -> Value {
    match callee {
        Callee::Prim(p) => prim(p, a),
        Callee::Native { f, .. } => call_native(*f, a),
        Callee::Fn(id) => cx.call(*id, a),
        Callee::Value => call_function_value(a),
    }
}

/// A native as a function value.
pub fn native_value(f: NativeFn) -> Value {
    Value::Closure(Arc::new(NativeClosure(f)))
}

/// A binary operator on two values: the inline scalar path first (as the evaluator's operator
/// nodes do), then the general one.
#[inline]
pub fn binary(op: BinOp, a: &Value, b: &Value) -> Value {
    if let Some(sop) = scalar_op(op)
        && let Some(r) = sop.eval_values(a, b)
    {
        return r;
    }
    if let Some(r) = ops::eq_values(op, a, b) {
        return r;
    }
    ops::binary_value(op, a, b)
}

/// The semantics of a primitive on argument values.
pub fn prim(p: &Prim, a: &[Value]) -> Value {
    match p {
        Prim::Binary(op) => match a {
            [x, y] => binary(*op, x, y),
            _ => Value::Error(RuntimeError::Other("an operator needs two operands".into())),
        },
        Prim::Unary(op) => ops::unary_value(*op, a.first().unwrap_or(&Value::Unit)),
        Prim::Tuple => Value::Tuple(a.to_vec().into()),
        Prim::Record(names) => Value::Record(
            names
                .iter()
                .cloned()
                .zip(a.iter().cloned())
                .collect::<Vec<_>>()
                .into(),
        ),
        Prim::Member(fname) => member(fname, a.first()),
        Prim::Format(spec) => match (spec, a.first()) {
            (Some(spec), Some(v)) => {
                Value::Str(crate::runtime::format::format_value(spec, v).into())
            }
            (None, Some(v)) => Value::Str(v.to_string().into()),
            _ => Value::Unit,
        },
        Prim::Concat => {
            if let Some(err) = a.iter().find_map(is_err) {
                return err;
            }
            let mut s = String::new();
            for v in a {
                s.push_str(&v.to_string());
            }
            Value::Str(s.into())
        }
        Prim::Ite => match a {
            [Value::Bool(true), t, _] => t.clone(),
            [Value::Bool(false), _, e] => e.clone(),
            [other, ..] => other.clone(),
            [] => Value::Unit,
        },
        Prim::IsOne => Value::Bool(a.get(1) == Some(&Value::Int(1))),
        Prim::ResetCount => match a {
            [acc, Value::Int(-1)] => ops::binary_value(BinOp::Add, acc, &Value::Int(1)),
            [_, tag] => tag.clone(),
            _ => Value::Unit,
        },
        Prim::SetAdd => collections::set_add(a),
        Prim::SetAddRemove => match a {
            [set, Value::Tuple(t)] => {
                let mut s = set.clone();
                if let Some(Value::Some(x)) = t.first() {
                    s = collections::set_add(&[s, (**x).clone()]);
                }
                if let Some(Value::Some(x)) = t.get(1) {
                    s = collections::set_remove(&[s, (**x).clone()]);
                }
                s
            }
            _ => Value::Unit,
        },
    }
}

fn member(fname: &Arc<str>, v: Option<&Value>) -> Value {
    match v {
        Some(Value::Record(r)) => r
            .iter()
            .find(|(k, _)| k == fname)
            .map(|(_, v)| v.clone())
            .unwrap_or_else(|| {
                Value::Error(RuntimeError::Other(format!("no field {fname}").into()))
            }),
        Some(Value::Tuple(t)) => fname
            .strip_prefix('_')
            .and_then(|i| i.parse::<usize>().ok())
            .and_then(|i| t.get(i.wrapping_sub(1)))
            .cloned()
            .unwrap_or_else(|| {
                Value::Error(RuntimeError::Other(format!("no member {fname}").into()))
            }),
        Some(err @ Value::Error(_)) => err.clone(),
        other => Value::Error(RuntimeError::Other(
            format!("no member {fname} in {other:?}").into(),
        )),
    }
}

/// A `lift` node's function on its arguments' events this step.
pub fn lift(cx: &Ctx, f: &LiftFn, code: Option<&Exec>, a: &[Option<&Value>]) -> Option<Value> {
    match f {
        LiftFn::Options(_) => {
            let opts: Vec<Value> = a
                .iter()
                .map(|o| match o {
                    Some(v) => Value::Some(Arc::new((*v).clone())),
                    None => Value::None,
                })
                .collect();
            let r = match code {
                Some(c) => c(cx, &opts),
                None => not_compiled(),
            };
            match r {
                Value::Some(v) => Some((*v).clone()),
                Value::None => None,
                other => Some(other),
            }
        }
        LiftFn::First => a.first().copied().flatten().cloned(),
        LiftFn::On => match a {
            [Some(_), Some(now), _] => Some((*now).clone()),
            [Some(_), None, Some(prev)] => Some((*prev).clone()),
            _ => None,
        },
        LiftFn::Distinct => match a {
            [Some(x), Some(p)] if x == p => None,
            [x, ..] => x.cloned(),
            [] => None,
        },
        LiftFn::FirstOnly => match a {
            [Some(x), None] => Some((*x).clone()),
            _ => None,
        },
        LiftFn::Edge(want) => match a {
            [Some(Value::Bool(now)), Some(Value::Bool(before))]
                if *now == *want && *before != *want =>
            {
                Some(Value::Bool(true))
            }
            [Some(_), _] => Some(Value::Bool(false)),
            _ => None,
        },
        LiftFn::ResetTag => match a {
            [Some(_), Some(_)] => Some(Value::Int(1)),
            [None, Some(_)] => Some(Value::Int(0)),
            [Some(_), None] => Some(Value::Int(-1)),
            _ => None,
        },
        LiftFn::AddRemove => {
            let opt = |o: &Option<&Value>| match o {
                Some(v) => Value::Some(Arc::new((*v).clone())),
                None => Value::None,
            };
            Some(Value::Tuple(a.iter().map(opt).collect::<Vec<_>>().into()))
        }
    }
}

/// Compile code into a closure over a frame. Macro expansion can nest code deeper than a
/// thread's stack allows recursion: the stack grows on the heap as in lowering.
pub fn compile(code: &Code) -> Exec {
    stacker::maybe_grow(64 * 1024, 1024 * 1024, || compile_here(code))
}

fn compile_here(code: &Code) -> Exec {
    match code {
        Code::Const(v) => {
            let v = v.clone();
            Arc::new(move |_: &Ctx, _: &[Value]| v.clone())
        }
        Code::Slot(i) => {
            let i = *i;
            Arc::new(move |_: &Ctx, fr: &[Value]| fr.get(i).cloned().unwrap_or(Value::Unit))
        }
        Code::If(parts) => {
            let [c, t, e] = &**parts;
            let (c, t, e) = (compile(c), compile(t), compile(e));
            Arc::new(move |cx: &Ctx, fr: &[Value]| match c(cx, fr) {
                Value::Bool(true) => t(cx, fr),
                Value::Bool(false) => e(cx, fr),
                other => other,
            })
        }
        Code::Logic { and, args } => {
            let [a, b] = &**args;
            let (a, b, and) = (compile(a), compile(b), *and);
            Arc::new(move |cx: &Ctx, fr: &[Value]| match a(cx, fr) {
                Value::Bool(x) if x != and => Value::Bool(x),
                Value::Bool(_) => b(cx, fr),
                other => other,
            })
        }
        Code::Closure { fun, captured } => {
            let (fun, captured) = (*fun, *captured);
            Arc::new(move |cx: &Ctx, fr: &[Value]| cx.closure(fun, &fr[..captured.min(fr.len())]))
        }
        Code::Apply(callee, args) => compile_apply(callee, args),
    }
}

fn compile_apply(callee: &Callee, args: &[Code]) -> Exec {
    let n = args.len();
    if Code::applies_to_slots(args) {
        // The frame is the arguments: pass it through.
        let callee = callee.clone();
        return match callee {
            Callee::Prim(Prim::Binary(op)) if n == 2 => {
                Arc::new(move |_: &Ctx, fr: &[Value]| match fr {
                    [a, b, ..] => binary(op, a, b),
                    _ => with_args(fr, n, |a| prim(&Prim::Binary(op), a)),
                })
            }
            Callee::Native { f, .. } => {
                Arc::new(move |_: &Ctx, fr: &[Value]| with_args(fr, n, |a| call_native(f, a)))
            }
            Callee::Fn(id) => {
                Arc::new(move |cx: &Ctx, fr: &[Value]| with_args(fr, n, |a| cx.call(id, a)))
            }
            other => {
                Arc::new(move |cx: &Ctx, fr: &[Value]| with_args(fr, n, |a| apply(cx, &other, a)))
            }
        };
    }
    if let (Callee::Value, [Code::Const(Value::Closure(c)), rest @ ..]) = (callee, args)
        && Code::applies_to_slots(rest)
    {
        // A constant function value applied to the frame (`fold(x, 0, f)` with `f` a value).
        let (c, n) = (c.clone(), rest.len());
        return Arc::new(move |_: &Ctx, fr: &[Value]| with_args(fr, n, |a| c.call(a)));
    }
    let args: Vec<Exec> = args.iter().map(compile).collect();
    let callee = callee.clone();
    match (callee, &args[..]) {
        (Callee::Prim(Prim::Binary(op)), [a, b]) => {
            let (a, b) = (a.clone(), b.clone());
            Arc::new(move |cx: &Ctx, fr: &[Value]| binary(op, &a(cx, fr), &b(cx, fr)))
        }
        (callee, _) => Arc::new(move |cx: &Ctx, fr: &[Value]| {
            let vals: Vec<Value> = args.iter().map(|a| a(cx, fr)).collect();
            apply(cx, &callee, &vals)
        }),
    }
}

/// The first `n` values of the frame (padded with `()` when it is shorter).
#[inline]
fn with_args(fr: &[Value], n: usize, f: impl FnOnce(&[Value]) -> Value) -> Value {
    match fr.get(..n) {
        Some(a) => f(a),
        None => {
            let mut vals = fr.to_vec();
            vals.resize(n, Value::Unit);
            f(&vals)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ir::Function;
    use crate::value::RuntimeError;

    /// Every fast form computes what the compiled closure of its code does, errors and
    /// overflow included.
    #[test]
    fn fast_forms_agree_with_the_compiled_code() {
        let bin = |op, a, b| Code::apply(Callee::Prim(Prim::Binary(op)), vec![a, b]);
        let add = Function {
            name: "lambda".into(),
            frame: 2,
            body: Some(bin(BinOp::FAdd, Code::Slot(0), Code::Slot(1))),
        };
        let functions = vec![add];
        let cx = context(
            functions
                .iter()
                .map(|f| f.body.as_ref().map(compile))
                .collect(),
            Vec::new(),
            Vec::new(),
            Err(Vec::new()),
        );
        let codes = [
            bin(BinOp::FAdd, Code::Slot(0), Code::Slot(1)),
            bin(BinOp::Add, Code::Slot(0), Code::Const(Value::Int(1))),
            bin(BinOp::Ne, Code::Slot(1), Code::Slot(0)),
            bin(BinOp::FDiv, Code::Const(Value::Float(1.0)), Code::Slot(0)),
            Code::apply(Callee::Prim(Prim::Unary(UnaryOp::Not)), vec![Code::Slot(0)]),
            Code::apply(Callee::Fn(0), vec![Code::Slot(1), Code::Slot(0)]),
            Code::apply(
                Callee::Native {
                    name: "intToFloat",
                    f: crate::runtime::natives::core::int_to_float,
                },
                vec![Code::Slot(0)],
            ),
            Code::Const(Value::Unit),
            Code::Const(Value::Int(7)),
            bin(BinOp::Eq, Code::Slot(0), Code::Slot(1)),
            bin(BinOp::Or, Code::Slot(0), Code::Slot(1)),
            bin(BinOp::Lt, Code::Slot(0), Code::Slot(1)),
            bin(BinOp::Sub, Code::Slot(0), Code::Slot(1)),
            Code::apply(
                Callee::Prim(Prim::Unary(UnaryOp::FNeg)),
                vec![Code::Slot(1)],
            ),
        ];
        let values = [
            Value::Float(1.5),
            Value::Float(-0.25),
            Value::Int(i64::MAX),
            Value::Int(3),
            Value::Float(f64::NAN),
            Value::from_big(num_bigint::BigInt::from(i64::MAX) * 4),
            Value::Bool(true),
            Value::Bool(false),
            Value::Str("x".into()),
            Value::Tuple(vec![Value::Int(1), Value::Str("x".into())].into()),
            Value::Error(RuntimeError::DivisionByZero),
        ];
        for code in &codes {
            let fast = Fast::of(code, 2, &functions);
            let Some(fast) = fast else {
                panic!("no fast form for {code:?}");
            };
            let exec = compile(code);
            for a in &values {
                for b in &values {
                    let want = exec(&cx, &[a.clone(), b.clone()]);
                    // Compared as printed: NaN is not equal to itself.
                    let want = format!("{:?}", Some(want));
                    let got = fast.run(&[a, b]);
                    assert_eq!(format!("{got:?}"), want, "{code:?} on {a:?}, {b:?}");
                }
            }
        }
        // Slots outside the node's arguments, and other code, have none.
        assert!(
            Fast::of(
                &bin(BinOp::Add, Code::Slot(2), Code::Slot(0)),
                2,
                &functions
            )
            .is_none()
        );
        assert!(Fast::of(&Code::Slot(0), 2, &functions).is_none());
    }
}
