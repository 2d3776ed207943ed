//! Value code as data: what the stream nodes compute from their arguments, and the program's
//! function table.
//!
//! Owns: [`Code`] (an expression over a frame of values: constants, frame slots, applications
//! of a [`Callee`], lazy `if`/`&&`/`||`, closures made from a function index and captured
//! slots), [`Callee`] (a [`Prim`]itive, a native by name, a program function by index into
//! [`crate::ir::Program::functions`], or a function value), [`LiftFn`] (the functions of `lift`
//! nodes, which see absent events) and [`Function`] (one entry of the function table). The
//! lowering builds these; `runtime::exec` compiles them into closures when a monitor is created;
//! `print` lists them and `runtime::snapshot` hashes them. Nothing here evaluates.

use crate::ir::op::{BinOp, UnaryOp};
use crate::value::{NativeFn, Value};
use std::sync::Arc;

/// Index of a function in [`crate::ir::Program::functions`].
pub type FnId = usize;

/// Value code over a frame: the arguments of a node's function, or a function's captured slots
/// followed by its parameters. Sub-expressions are shared (`Arc`), so cloning code is cheap
/// however deep macro expansion made it.
#[derive(Clone, Debug)]
pub enum Code {
    Const(Value),
    /// The frame's value at this index (`()` when the frame is shorter).
    Slot(usize),
    /// Evaluate every argument, then apply the callee to the values.
    Apply(Arc<Callee>, Arc<[Code]>),
    /// `if c then a else b`: only the chosen branch is evaluated; a condition that is not a
    /// Bool (an error) is the result.
    If(Arc<[Code; 3]>),
    /// `a && b` (`and`) or `a || b`: `b` is evaluated only when `a` does not decide.
    Logic {
        and: bool,
        args: Arc<[Code; 2]>,
    },
    /// A function value: function `fun` with the frame's first `captured` slots in front of
    /// its arguments.
    Closure {
        fun: FnId,
        captured: usize,
    },
}

/// What an [`Code::Apply`] applies.
#[derive(Clone, Debug)]
pub enum Callee {
    Prim(Prim),
    /// A native value function, strict: the first error argument is the result.
    Native {
        name: &'static str,
        f: NativeFn,
    },
    /// A program function; its frame is the argument values.
    Fn(FnId),
    /// The first argument is a function value, called with the others.
    Value,
}

/// Value operations built into the language (operators, tuples, records, format strings) and
/// the step functions of stream builtins. Semantics: `crate::runtime::exec`.
#[derive(Clone, Debug, PartialEq)]
pub enum Prim {
    Binary(BinOp),
    Unary(UnaryOp),
    Tuple,
    /// A record with these field names (sorted), one argument per field.
    Record(Arc<[Arc<str>]>),
    /// `.name` of a record, `._1` of a tuple.
    Member(Arc<str>),
    /// A string interpolation `${x}` or `%spec` of one value.
    Format(Option<String>),
    /// Concatenate the arguments' texts (a string with interpolations).
    Concat,
    /// `if` with every branch evaluated (a signal lift of `if`).
    Ite,
    /// `[_, count]`: `count == 1` (`isFirst`).
    IsOne,
    /// `resetCount`'s step: `[acc, -1]` counts, `[_, tag]` restarts at the tag.
    ResetCount,
    /// `Set.add`, not strict (`setCollect`'s step).
    SetAdd,
    /// `setCollectWithRemove`'s step: `[set, (Option add, Option remove)]`.
    SetAddRemove,
}

/// The function of a `lift` node: it sees which arguments have an event and may produce none.
#[derive(Clone, Debug)]
pub enum LiftFn {
    /// A spec's function over `Option` values (`Some(x)` for an event, `None` for none); a
    /// result `None` means no event.
    Options(Code),
    /// The first argument's event.
    First,
    /// `on(trigger, s, last(s, trigger))`: at the trigger, the stream's event or else its last.
    On,
    /// `pure`: `[x, previous]`, no event when `x` equals the previous value.
    Distinct,
    /// `[x, seen]`: `x` while nothing was seen before.
    FirstOnly,
    /// `rising` (true) or `falling` edges of `[c, previous c]`.
    Edge(bool),
    /// `resetCount`'s tag of `[x, reset]`: 1 both, 0 reset only, -1 `x` only.
    ResetTag,
    /// `setCollectWithRemove`'s step: `(Option add, Option remove)`.
    AddRemove,
}

/// One function of the program: a named function of the spec or a lambda.
#[derive(Clone, Debug)]
pub struct Function {
    /// The spec's name (`lambda` for a lambda).
    pub name: String,
    /// Slots of its frame: captured slots of the enclosing function, then its parameters.
    pub frame: usize,
    /// Its body over that frame; `None` while (or if) compiling it did not finish.
    pub body: Option<Code>,
}

impl Code {
    /// `callee(args)`.
    pub fn apply(callee: Callee, args: Vec<Code>) -> Code {
        Code::Apply(Arc::new(callee), args.into())
    }

    /// Slots `0..n`, for applying a callee to a node's arguments as they come.
    pub fn slots(n: usize) -> Vec<Code> {
        (0..n).map(Code::Slot).collect()
    }

    /// The direct sub-expressions.
    pub fn children(&self) -> &[Code] {
        match self {
            Code::Const(_) | Code::Slot(_) | Code::Closure { .. } => &[],
            Code::Apply(_, args) => args,
            Code::If(a) => &a[..],
            Code::Logic { args, .. } => &args[..],
        }
    }

    /// Whether the code reads no frame slot (it can be evaluated without a frame). Walks with
    /// its own stack: code can be deeper than the thread's stack allows recursion.
    pub fn is_closed(&self) -> bool {
        let mut todo = vec![self];
        while let Some(c) = todo.pop() {
            match c {
                Code::Slot(_) => return false,
                Code::Closure { captured, .. } if *captured > 0 => return false,
                _ => todo.extend(c.children()),
            }
        }
        true
    }

    /// The program functions this code refers to (calls and closures).
    pub fn functions(&self, out: &mut Vec<FnId>) {
        let mut todo = vec![self];
        while let Some(c) = todo.pop() {
            match c {
                Code::Closure { fun, .. } => out.push(*fun),
                Code::Apply(c, _) => {
                    if let Callee::Fn(fun) = **c {
                        out.push(fun);
                    }
                }
                _ => {}
            }
            todo.extend(c.children());
        }
    }

    /// Whether the code is `Apply(callee, [Slot(0), .., Slot(n - 1)])` for some callee.
    pub fn applies_to_slots(args: &[Code]) -> bool {
        args.iter()
            .enumerate()
            .all(|(i, a)| matches!(a, Code::Slot(s) if *s == i))
    }
}

impl LiftFn {
    /// The code inside, if the function has any.
    pub fn code(&self) -> Option<&Code> {
        match self {
            LiftFn::Options(c) => Some(c),
            _ => None,
        }
    }
}
