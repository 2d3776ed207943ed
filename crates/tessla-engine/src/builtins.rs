//! Every builtin name of the language, once: stream operators, value functions, constants,
//! `Operators.*` and the natives reached through `extern("name")`.
//!
//! The one door from the front end (`resolve`, `typeck`, `lower`) into the runtime:
//! the natives' function pointers are in the table, and the few other runtime entry points the
//! lowering needs (the semantics of primitives for constant folding, function values of
//! natives) are re-exported here.
//!
//! Owns: [`BUILTINS`], each entry with its name, [`Kind`] (what the lowering does with it),
//! TeSSLa signature (what the checker types a use with; `None`: any type, checked at lowering)
//! and which arguments are lazy (read from earlier steps, so they may refer forward). The
//! checker (`typeck`), the lowering (`lower`) and the unknown-name listing all read this table.
//! A new stream operator is one entry here plus its nodes in the lowering's `stream_builtin`; a
//! new value function is one entry here plus its native in `natives`.
//!
//! The table is open to an application: [`Natives`] holds natives it registers (name, signature,
//! function) and hands the loader in [`crate::LoadOptions::natives`]; a spec reaches them through
//! `extern("name")`, the checker holds the declaring `def` to the registered signature and the
//! lowering calls them as it calls the table's natives. Registered names never shadow the table.
//!
//! Signatures are written in TeSSLa's type notation: `(Events[A], Events[B]) => Events[A]`, a
//! plain type for a constant (`List[A]`). `A`/`K` and `B`/`V` are the only type variables.
//! `lift`, `slift`, `merge` (with or without an arity suffix) and `log` take a varying number
//! of arguments: their signature is a [`Sig::Variadic`] shape and the checker builds it per call.

use crate::runtime::collections;
use crate::runtime::natives::core;
use crate::runtime::ops;
use crate::value::{NativeFn, Value};
use std::collections::HashMap;
use std::sync::OnceLock;

/// The rest of the runtime the front end uses, besides the natives listed in [`BUILTINS`]: the
/// semantics of primitives (which the lowering hands the constant fold, `crate::ir::fold`) and
/// function values of natives. A pass imports runtime code through this table only.
pub use crate::runtime::exec::{native_value, prim};

/// A stream operator the lowering builds nodes for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StreamOp {
    /// `nil`: the stream without events.
    Nil,
    /// `unit`: one unit event at time 0.
    Unit,
    Time,
    Last,
    Prev,
    Delay,
    Default,
    DefaultFrom,
    Merge,
    Filter,
    Const,
    First,
    On,
    Count,
    Sum,
    Fold,
    Reduce,
    Maximum,
    Minimum,
    Lift,
    SLift,
    Pure,
    IsFirst,
    FirstEvent,
    Defined,
    ConstIf,
    UnitIf,
    Rising,
    Falling,
    Period,
    /// Named by TeSSLa's standard library but not implemented: a use is an "unsupported" error.
    Unsupported,
}

/// What a builtin is.
#[derive(Debug, Clone, Copy)]
pub enum Kind {
    /// A stream operator.
    Stream(StreamOp),
    /// A value function with a native implementation, by name or `extern("name")`.
    Value(NativeFn),
    /// `Operators.add` and friends: an operator as a function value.
    Operator(NativeFn),
    /// A constant value (`List.empty`).
    Constant(fn() -> Value),
    /// A native reached only through `extern("name")`; its signature is the declaring `def`'s.
    Extern(NativeFn),
}

/// How the checker types a use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sig {
    /// Any type (not checked before lowering).
    Any,
    /// A signature in TeSSLa's type notation.
    Fixed(&'static str),
    /// Built per call from the number of arguments (`lift3`, `merge`, `log`), by its shape.
    Variadic(Variadic),
}

/// The shape of a signature whose number of parameters a call decides: `count` repeated
/// parameters of type `each`, then (for the lifts) one function of them, and a `result`, in
/// TeSSLa's notation. `A` is a fresh variable per repeated parameter (one for all of them when
/// `shared`), `B` one variable per use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Variadic {
    /// How many repeated parameters: fixed by an arity suffix (`lift3`: 3), else as many as the
    /// call gives (the function not counted); within `min..=max` either way.
    pub count: Option<usize>,
    pub min: usize,
    pub max: usize,
    pub each: &'static str,
    pub shared: bool,
    /// The last parameter, a function: the type of its parameter per repeated parameter, and
    /// of its result.
    pub function: Option<(&'static str, &'static str)>,
    pub result: &'static str,
}

/// `lift`: `(Events[A1], ..., Events[Ak], (Option[A1], ..., Option[Ak]) => Option[B]) => Events[B]`.
const fn lift_sig(count: Option<usize>) -> Sig {
    lifted_sig(count, ("Option[A]", "Option[B]"))
}

/// `slift`: `(Events[A1], ..., Events[Ak], (A1, ..., Ak) => B) => Events[B]`.
const fn slift_sig(count: Option<usize>) -> Sig {
    lifted_sig(count, ("A", "B"))
}

const fn lifted_sig(count: Option<usize>, function: (&'static str, &'static str)) -> Sig {
    Sig::Variadic(Variadic {
        count,
        min: 0,
        max: usize::MAX,
        each: "Events[A]",
        shared: false,
        function: Some(function),
        result: "Events[B]",
    })
}

/// `merge`: `(Events[A], ..., Events[A]) => Events[A]`.
const fn merge_sig(count: Option<usize>) -> Sig {
    Sig::Variadic(Variadic {
        count,
        min: 0,
        max: usize::MAX,
        each: "Events[A]",
        shared: true,
        function: None,
        result: "Events[A]",
    })
}

/// `log`: `(Float) => Float` or `(Float, Float) => Float`.
const LOG_SIG: Sig = Sig::Variadic(Variadic {
    count: None,
    min: 1,
    max: 2,
    each: "Float",
    shared: true,
    function: None,
    result: "Float",
});

/// One builtin.
#[derive(Debug, Clone, Copy)]
pub struct Builtin {
    pub name: &'static str,
    pub kind: Kind,
    pub sig: Sig,
    /// Indices of the lazy arguments.
    pub lazy: &'static [usize],
}

/// The builtin named `name`, if any.
pub fn get(name: &str) -> Option<&'static Builtin> {
    static INDEX: OnceLock<HashMap<&'static str, &'static Builtin>> = OnceLock::new();
    INDEX
        .get_or_init(|| BUILTINS.iter().map(|b| (b.name, b)).collect())
        .get(name)
        .copied()
}

/// The native `extern("name")` refers to, if any.
pub fn extern_native(name: &str) -> Option<NativeFn> {
    extern_named(name).map(|(_, f)| f)
}

/// The native `extern("name")` refers to, with its name in the table (the key natives are
/// looked up by afterwards, never their address: the linker may merge two natives of the
/// same body).
pub fn extern_named(name: &str) -> Option<(&'static str, NativeFn)> {
    get(name).and_then(|b| match b.kind {
        Kind::Value(f) | Kind::Extern(f) => Some((b.name, f)),
        _ => None,
    })
}

/// The names a spec can use without declaring them, for "did you mean" listings.
pub fn names() -> impl Iterator<Item = &'static str> {
    BUILTINS
        .iter()
        .filter(|b| !matches!(b.kind, Kind::Extern(_)))
        .map(|b| b.name)
}

const fn stream(name: &'static str, op: StreamOp, sig: &'static str) -> Builtin {
    Builtin {
        name,
        kind: Kind::Stream(op),
        sig: Sig::Fixed(sig),
        lazy: &[],
    }
}

const fn stream_any(name: &'static str, op: StreamOp, sig: Sig) -> Builtin {
    Builtin {
        name,
        kind: Kind::Stream(op),
        sig,
        lazy: &[],
    }
}

const fn value(name: &'static str, f: NativeFn, sig: &'static str) -> Builtin {
    Builtin {
        name,
        kind: Kind::Value(f),
        sig: Sig::Fixed(sig),
        lazy: &[],
    }
}

const fn value_any(name: &'static str, f: NativeFn) -> Builtin {
    Builtin {
        name,
        kind: Kind::Value(f),
        sig: Sig::Any,
        lazy: &[],
    }
}

const fn constant(name: &'static str, v: fn() -> Value, sig: &'static str) -> Builtin {
    Builtin {
        name,
        kind: Kind::Constant(v),
        sig: Sig::Fixed(sig),
        lazy: &[],
    }
}

const fn operator(name: &'static str, f: NativeFn) -> Builtin {
    Builtin {
        name,
        kind: Kind::Operator(f),
        sig: Sig::Any,
        lazy: &[],
    }
}

const fn external(name: &'static str, f: NativeFn) -> Builtin {
    Builtin {
        name,
        kind: Kind::Extern(f),
        sig: Sig::Any,
        lazy: &[],
    }
}

use StreamOp as S;

/// Every builtin.
pub static BUILTINS: &[Builtin] = &[
    // Stream operators.
    stream_any("nil", S::Nil, Sig::Any),
    stream_any("unit", S::Unit, Sig::Any),
    stream("time", S::Time, "(Events[A]) => Events[Int]"),
    Builtin {
        lazy: &[0],
        ..stream("last", S::Last, "(Events[A], Events[B]) => Events[A]")
    },
    Builtin {
        lazy: &[0],
        ..stream(
            "delay",
            S::Delay,
            "(Events[Int], Events[A]) => Events[Unit]",
        )
    },
    stream("prev", S::Prev, "(Events[A]) => Events[A]"),
    stream("default", S::Default, "(Events[A], A) => Events[A]"),
    stream(
        "defaultFrom",
        S::DefaultFrom,
        "(Events[A], Events[A]) => Events[A]",
    ),
    stream_any("lift", S::Lift, lift_sig(None)),
    stream_any("lift1", S::Lift, lift_sig(Some(1))),
    stream_any("lift2", S::Lift, lift_sig(Some(2))),
    stream_any("lift3", S::Lift, lift_sig(Some(3))),
    stream_any("lift4", S::Lift, lift_sig(Some(4))),
    stream_any("lift5", S::Lift, lift_sig(Some(5))),
    stream_any("slift", S::SLift, slift_sig(None)),
    stream_any("slift1", S::SLift, slift_sig(Some(1))),
    stream_any("slift2", S::SLift, slift_sig(Some(2))),
    stream_any("slift3", S::SLift, slift_sig(Some(3))),
    stream_any("slift4", S::SLift, slift_sig(Some(4))),
    stream_any("slift5", S::SLift, slift_sig(Some(5))),
    stream_any("merge", S::Merge, merge_sig(None)),
    stream_any("merge2", S::Merge, merge_sig(Some(2))),
    stream_any("merge3", S::Merge, merge_sig(Some(3))),
    stream_any("merge4", S::Merge, merge_sig(Some(4))),
    stream_any("merge5", S::Merge, merge_sig(Some(5))),
    stream_any("merge6", S::Merge, merge_sig(Some(6))),
    stream_any("merge7", S::Merge, merge_sig(Some(7))),
    stream_any("merge8", S::Merge, merge_sig(Some(8))),
    stream("const", S::Const, "(A, Events[B]) => Events[A]"),
    stream("first", S::First, "(Events[A], Events[B]) => Events[A]"),
    stream(
        "filter",
        S::Filter,
        "(Events[A], Events[Bool]) => Events[A]",
    ),
    stream("count", S::Count, "(Events[A]) => Events[Int]"),
    stream_any("sum", S::Sum, Sig::Any),
    stream("fold", S::Fold, "(Events[A], B, (B, A) => B) => Events[B]"),
    stream("reduce", S::Reduce, "(Events[A], (A, A) => A) => Events[A]"),
    stream("pure", S::Pure, "(Events[A]) => Events[A]"),
    stream("isFirst", S::IsFirst, "(Events[A]) => Events[Bool]"),
    stream("firstEvent", S::FirstEvent, "(Events[A]) => Events[A]"),
    stream("defined", S::Defined, "(Events[A]) => Events[Bool]"),
    stream("on", S::On, "(Events[A], Events[B]) => Events[B]"),
    stream("constIf", S::ConstIf, "(A, Events[Bool]) => Events[A]"),
    stream("unitIf", S::UnitIf, "(Events[Bool]) => Events[Unit]"),
    stream("rising", S::Rising, "(Events[Bool]) => Events[B]"),
    stream("falling", S::Falling, "(Events[Bool]) => Events[B]"),
    stream(
        "noEvent",
        S::Unsupported,
        "(Events[A], Events[B]) => Events[Bool]",
    ),
    stream("period", S::Period, "(Int) => Events[Unit]"),
    stream_any("runtime", S::Unsupported, Sig::Any),
    stream_any("maximum", S::Maximum, Sig::Any),
    stream_any("minimum", S::Minimum, Sig::Any),
    stream_any("average", S::Unsupported, Sig::Any),
    // Value functions.
    value("intToFloat", core::int_to_float, "(Int) => Float"),
    value("floatToInt", core::float_to_int, "(Float) => Int"),
    value("pow", core::pow, "(Float, Float) => Float"),
    Builtin {
        sig: LOG_SIG,
        ..value_any("log", core::log)
    },
    value("sin", core::sin, "(Float) => Float"),
    value("cos", core::cos, "(Float) => Float"),
    value("tan", core::tan, "(Float) => Float"),
    value("atan", core::atan, "(Float) => Float"),
    value("sqrt", core::sqrt, "(Float) => Float"),
    value("abs", core::abs, "(A) => A"),
    value("max", core::max, "(A, A) => A"),
    value("min", core::min, "(A, A) => A"),
    value("toString", core::to_string, "(A) => String"),
    value("String.concat", core::concat, "(String, String) => String"),
    value(
        "String.format",
        core::string_format,
        "(String, A) => String",
    ),
    value("Some", core::some, "(A) => Option[A]"),
    value("isNone", core::is_none, "(Option[A]) => Bool"),
    value("isSome", core::is_some, "(Option[A]) => Bool"),
    value("getSome", core::get_some, "(Option[A]) => A"),
    value(
        "getSomeOrElse",
        core::get_some_or_else,
        "(Option[A], A) => A",
    ),
    value("ite", core::ite, "(Bool, A, A) => A"),
    value(
        "Option.map",
        core::option_map,
        "(Option[A], (A) => B) => Option[B]",
    ),
    value(
        "OptionUtils.map",
        core::option_map,
        "(Option[A], (A) => B) => Option[B]",
    ),
    value(
        "Option.flatMap",
        core::option_flat_map,
        "(Option[A], (A) => Option[B]) => Option[B]",
    ),
    value(
        "OptionUtils.flatMap",
        core::option_flat_map,
        "(Option[A], (A) => Option[B]) => Option[B]",
    ),
    value("List.size", core::list_size, "(List[A]) => Int"),
    value("List.append", core::list_append, "(List[A], A) => List[A]"),
    value(
        "List.prepend",
        core::list_prepend,
        "(A, List[A]) => List[A]",
    ),
    value("List.get", core::list_get, "(List[A], Int) => A"),
    value("List.set", core::list_set, "(List[A], Int, A) => List[A]"),
    value("List.head", core::list_head, "(List[A]) => A"),
    value("List.last", core::list_last, "(List[A]) => A"),
    value("List.tail", core::list_tail, "(List[A]) => List[A]"),
    value("List.init", core::list_init, "(List[A]) => List[A]"),
    value(
        "List.fold",
        core::list_fold,
        "(List[A], B, (B, A) => B) => B",
    ),
    value("List.map", core::list_map, "(List[A], (A) => B) => List[B]"),
    value(
        "List.isEmpty",
        collections::list_is_empty,
        "(List[A]) => Bool",
    ),
    value_any("List.zip", collections::list_zip),
    value_any("List.zipWithIndex", collections::list_zip_with_index),
    value("Set.add", collections::set_add, "(Set[A], A) => Set[A]"),
    value(
        "Set.remove",
        collections::set_remove,
        "(Set[A], A) => Set[A]",
    ),
    value(
        "Set.contains",
        collections::set_contains,
        "(Set[A], A) => Bool",
    ),
    value("Set.size", collections::set_size, "(Set[A]) => Int"),
    value(
        "Set.union",
        collections::set_union,
        "(Set[A], Set[A]) => Set[A]",
    ),
    value(
        "Set.intersection",
        collections::set_intersection,
        "(Set[A], Set[A]) => Set[A]",
    ),
    value(
        "Set.minus",
        collections::set_minus,
        "(Set[A], Set[A]) => Set[A]",
    ),
    value(
        "Set.fold",
        collections::set_fold,
        "(Set[A], B, (B, A) => B) => B",
    ),
    value(
        "Set.map",
        collections::set_map,
        "(Set[A], (A) => B) => Set[B]",
    ),
    value(
        "Map.add",
        collections::map_add,
        "(Map[K, V], K, V) => Map[K, V]",
    ),
    value(
        "Map.contains",
        collections::map_contains,
        "(Map[K, V], K) => Bool",
    ),
    value("Map.get", collections::map_get, "(Map[K, V], K) => V"),
    value(
        "Map.getOrElse",
        collections::map_get_or_else,
        "(Map[K, V], K, V) => V",
    ),
    value(
        "Map.remove",
        collections::map_remove,
        "(Map[K, V], K) => Map[K, V]",
    ),
    value("Map.size", collections::map_size, "(Map[K, V]) => Int"),
    value_any("Map.keys", collections::map_keys),
    value_any("Map.fold", collections::map_fold),
    value_any("Map.map", collections::map_map),
    // Constants.
    constant("List.empty", collections::empty_list, "List[A]"),
    constant("Set.empty", collections::empty_set, "Set[A]"),
    constant("Map.empty", collections::empty_map, "Map[K, V]"),
    // Operators as functions (`slift(x, y, Operators.add)`); semantics in `ops`.
    operator("Operators.add", ops::natives::add),
    operator("Operators.sub", ops::natives::sub),
    operator("Operators.mul", ops::natives::mul),
    operator("Operators.div", ops::natives::div),
    operator("Operators.mod", ops::natives::rem),
    operator("Operators.lt", ops::natives::lt),
    operator("Operators.gt", ops::natives::gt),
    operator("Operators.leq", ops::natives::le),
    operator("Operators.geq", ops::natives::ge),
    operator("Operators.eq", ops::natives::eq),
    operator("Operators.neq", ops::natives::ne),
    operator("Operators.fadd", ops::natives::fadd),
    operator("Operators.fsub", ops::natives::fsub),
    operator("Operators.fmul", ops::natives::fmul),
    operator("Operators.fdiv", ops::natives::fdiv),
    operator("Operators.flt", ops::natives::flt),
    operator("Operators.fgt", ops::natives::fgt),
    operator("Operators.fleq", ops::natives::fle),
    operator("Operators.fgeq", ops::natives::fge),
    operator("Operators.and", ops::natives::and),
    operator("Operators.or", ops::natives::or),
    operator("Operators.bitand", ops::natives::bitand),
    operator("Operators.bitor", ops::natives::bitor),
    operator("Operators.bitxor", ops::natives::bitxor),
    operator("Operators.leftshift", ops::natives::shl),
    operator("Operators.rightshift", ops::natives::shr),
    operator("Operators.not", ops::natives::not),
    operator("Operators.negate", ops::natives::neg),
    operator("Operators.fnegate", ops::natives::fneg),
    operator("Operators.bitflip", ops::natives::bitflip),
    // Natives reached only through `extern("name")` (declared in the bundled prelude and
    // TeSSLa's libraries); an application adds its own with [`Natives::register`].
    external("CTF.getInt", core::ctf_get_int),
    external("CTF.getString", core::ctf_get_string),
    external("List_size", core::list_size),
    external("List_get", core::list_get),
    external("List_fold", core::list_fold),
];

/// A native an application registers (see [`Natives`]): reached through `extern("name")`,
/// typed by its declaring `def`, which must have the registered signature.
#[derive(Debug, Clone, Copy)]
pub struct Native {
    pub name: &'static str,
    /// In TeSSLa's type notation, a function type: `(List[Float], Float) => Int`; `A`/`K` and
    /// `B`/`V` are type variables, as in [`BUILTINS`].
    pub sig: &'static str,
    pub f: NativeFn,
}

/// The natives an application adds to the builtins table, passed to the loader in
/// [`crate::LoadOptions::natives`]: a spec reaches each through `extern("name")` from a `def`
/// declared with the registered signature (checked when the spec is compiled; a different
/// declaration is a type error). Names are kept apart from the language's builtins and from each
/// other, so a registered native never changes what an existing spec means.
///
/// ```
/// use tessla_engine::{LoadOptions, Value, builtins::Natives};
/// fn twice(a: &[Value]) -> Value {
///     match a {
///         [Value::Int(n)] => Value::Int(n.wrapping_mul(2)),
///         _ => Value::None,
///     }
/// }
/// let mut natives = Natives::new();
/// natives.register("twice", "(Int) => Int", twice).unwrap();
/// let options = LoadOptions { natives, ..LoadOptions::default() };
/// # let _ = options;
/// ```
#[derive(Debug, Clone, Default)]
pub struct Natives {
    list: Vec<Native>,
}

/// Why [`Natives::register`] refused a native.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RegisterError {
    #[error("native `{0}`: the name is a builtin of the language")]
    Builtin(&'static str),
    #[error("native `{0}`: registered twice")]
    Twice(&'static str),
    #[error("native `{name}`: signature `{sig}` is not a function type in TeSSLa's notation")]
    Signature {
        name: &'static str,
        sig: &'static str,
    },
}

impl Natives {
    /// No natives beyond the language's.
    pub const fn new() -> Natives {
        Natives { list: Vec::new() }
    }

    /// Add the native `name` with its signature and implementation. Refused: a name the
    /// language's table has, a name registered before, a signature that is not a function type
    /// (`(T1, ..., Tn) => R`, its parentheses balanced).
    pub fn register(
        &mut self,
        name: &'static str,
        sig: &'static str,
        f: NativeFn,
    ) -> Result<&mut Natives, RegisterError> {
        if get(name).is_some() {
            return Err(RegisterError::Builtin(name));
        }
        if self.get(name).is_some() {
            return Err(RegisterError::Twice(name));
        }
        if !looks_like_function_type(sig) {
            return Err(RegisterError::Signature { name, sig });
        }
        self.list.push(Native { name, sig, f });
        Ok(self)
    }

    /// The native registered as `name`, if any.
    pub fn get(&self, name: &str) -> Option<&Native> {
        self.list.iter().find(|n| n.name == name)
    }

    /// The registered natives, in the order registered.
    pub fn iter(&self) -> impl Iterator<Item = &Native> {
        self.list.iter()
    }
}

/// `(...) => R` with balanced brackets: the shape [`Natives::register`] accepts (the checker
/// parses the types when a spec uses the native, and reports a signature it cannot read).
fn looks_like_function_type(sig: &str) -> bool {
    /// The depth after each character, `None` once a bracket closes that was not opened.
    fn depths(s: &str) -> impl Iterator<Item = Option<usize>> + '_ {
        s.chars().scan(Some(0usize), |d, c| {
            *d = match c {
                '(' | '[' => d.map(|d| d + 1),
                ')' | ']' => d.and_then(|d| d.checked_sub(1)),
                _ => *d,
            };
            Some(*d)
        })
    }
    let s = sig.trim();
    if !s.starts_with('(') {
        return false;
    }
    // The parameters' closing parenthesis: the first character back at depth 0.
    let Some(((close, _), _)) = s.char_indices().zip(depths(s)).find(|(_, d)| *d == Some(0)) else {
        return false;
    };
    // `close` is the byte offset of a `)` or `]`, one byte long.
    let Some(result) = s[close + 1..].trim_start().strip_prefix("=>") else {
        return false;
    };
    !result.trim().is_empty()
        && depths(result).all(|d| d.is_some())
        && depths(result).last() == Some(Some(0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_name_once() {
        let mut names: Vec<&str> = BUILTINS.iter().map(|b| b.name).collect();
        names.sort_unstable();
        let n = names.len();
        names.dedup();
        assert_eq!(n, names.len(), "a builtin name is listed twice");
    }

    #[test]
    fn the_natives_the_lowering_names_are_listed() {
        // `maximum` and `minimum` reduce with these (`lower::closure::named_native`).
        let args = [Value::Int(1), Value::Int(3)];
        assert_eq!(extern_native("max").map(|f| f(&args)), Some(Value::Int(3)));
        assert_eq!(extern_native("min").map(|f| f(&args)), Some(Value::Int(1)));
    }

    #[test]
    fn lazy_arguments_exist() {
        for b in BUILTINS {
            if let Sig::Fixed(s) = b.sig {
                let params = s.matches(',').count() + 1;
                assert!(b.lazy.iter().all(|&i| i < params), "{}", b.name);
            }
        }
    }
}
