//! Constant folding, an IR matter: closed value code ([`Code`] that reads no frame slot)
//! evaluated on constant [`Value`]s while the lowering builds the program, with the program
//! functions finished so far.
//!
//! Owns: [`Folder`] (the fold: walks the code, calls program functions by interpreting their
//! bodies, makes function values of closures) and its function values ([`FoldedFn`]). What a
//! primitive (an operator, a record, a format string ...) means is not written here: the
//! caller hands over the one definition the runtime evaluates with too ([`Semantics`], the
//! lowering passes the builtins table's), and natives and function values are called by their
//! calling conventions in `crate::value`. Nothing here compiles closures or reads the runtime.
//!
//! A fold gives exactly what the runtime's compiled code gives for the same code: the same
//! branches of `if`, `&&` and `||`, `()` for a slot beyond the frame, and a program function
//! without a body (still being lowered) an error value when called, and a recursion deeper
//! than [`crate::value::MAX_CALL_DEPTH`] the same error value.

use crate::ir::code::{Callee, Code, FnId, Function, Prim};
use crate::value::{Callable, RuntimeError, Value, call_function_value, call_native, nested_call};
use std::sync::Arc;

/// The semantics of a primitive on argument values (the runtime's, shared).
pub type Semantics = fn(&Prim, &[Value]) -> Value;

/// Folds closed code with the program functions finished so far.
pub struct Folder {
    prim: Semantics,
    /// The function table as of the last fold that made a function value, shared by the
    /// function values it made; dropped when a function is finished.
    table: Option<Arc<[Function]>>,
}

impl Folder {
    pub fn new(prim: Semantics) -> Folder {
        Folder { prim, table: None }
    }

    /// The value of closed code `code`, calling the functions of `functions` that have a body.
    pub fn fold(&mut self, functions: &[Function], code: &Code) -> Value {
        if self
            .table
            .as_ref()
            .is_none_or(|t| t.len() != functions.len())
        {
            self.table = Some(functions.into());
        }
        match &self.table {
            Some(table) => eval(self.prim, table, code, &[]),
            None => not_compiled(),
        }
    }

    /// A function got its body: the next fold sees it.
    pub fn function_finished(&mut self) {
        self.table = None;
    }
}

/// A program function as a value made by a fold, with the captured slots of its enclosing
/// frame.
pub struct FoldedFn {
    prim: Semantics,
    table: Arc<[Function]>,
    fun: FnId,
    captured: Vec<Value>,
}

impl std::fmt::Debug for FoldedFn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("<function>")
    }
}

impl Callable for FoldedFn {
    fn call(&self, args: &[Value]) -> Value {
        if self.captured.is_empty() {
            return call(self.prim, &self.table, self.fun, args);
        }
        let mut frame = self.captured.clone();
        frame.extend_from_slice(args);
        call(self.prim, &self.table, self.fun, &frame)
    }
}

fn not_compiled() -> Value {
    Value::Error(RuntimeError::Other("function not compiled".into()))
}

/// Call function `fun` of `table` with `frame`.
fn call(prim: Semantics, table: &Arc<[Function]>, fun: FnId, frame: &[Value]) -> Value {
    match table.get(fun).and_then(|f| f.body.as_ref()) {
        Some(body) => nested_call(|| eval(prim, table, body, frame)),
        None => not_compiled(),
    }
}

/// Evaluate `code` over `frame`. Macro expansion can nest code deeper than a thread's stack
/// allows recursion: the stack grows on the heap, as in lowering.
fn eval(prim: Semantics, table: &Arc<[Function]>, code: &Code, frame: &[Value]) -> Value {
    stacker::maybe_grow(64 * 1024, 1024 * 1024, || {
        eval_here(prim, table, code, frame)
    })
}

fn eval_here(prim: Semantics, table: &Arc<[Function]>, code: &Code, frame: &[Value]) -> Value {
    let ev = |c: &Code| eval(prim, table, c, frame);
    match code {
        Code::Const(v) => v.clone(),
        Code::Slot(i) => frame.get(*i).cloned().unwrap_or(Value::Unit),
        Code::If(parts) => {
            let [c, t, e] = &**parts;
            match ev(c) {
                Value::Bool(true) => ev(t),
                Value::Bool(false) => ev(e),
                other => other,
            }
        }
        Code::Logic { and, args } => {
            let [a, b] = &**args;
            match ev(a) {
                Value::Bool(x) if x != *and => Value::Bool(x),
                Value::Bool(_) => ev(b),
                other => other,
            }
        }
        Code::Closure { fun, captured } => Value::Closure(Arc::new(FoldedFn {
            prim,
            table: table.clone(),
            fun: *fun,
            captured: frame[..(*captured).min(frame.len())].to_vec(),
        })),
        Code::Apply(callee, args) => {
            let vals: Vec<Value> = args.iter().map(ev).collect();
            match &**callee {
                Callee::Prim(p) => prim(p, &vals),
                Callee::Native { f, .. } => call_native(*f, &vals),
                Callee::Fn(id) => call(prim, table, *id, &vals),
                Callee::Value => call_function_value(&vals),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ir::BinOp;

    /// A stand-in for the runtime's semantics: only `+` on Ints.
    fn add_only(p: &Prim, a: &[Value]) -> Value {
        match (p, a) {
            (Prim::Binary(BinOp::Add), [Value::Int(x), Value::Int(y)]) => Value::Int(x + y),
            _ => Value::Error(RuntimeError::Other("no".into())),
        }
    }

    #[test]
    fn functions_closures_and_unfinished_functions() {
        let add = |a, b| Code::apply(Callee::Prim(Prim::Binary(BinOp::Add)), vec![a, b]);
        // f0(x) = x + 1; f1 = the closure of f0; f2 not finished.
        let functions = vec![
            Function {
                name: "inc".into(),
                frame: 1,
                body: Some(add(Code::Slot(0), Code::Const(Value::Int(1)))),
            },
            Function {
                name: "lambda".into(),
                frame: 0,
                body: Some(Code::Closure {
                    fun: 0,
                    captured: 0,
                }),
            },
            Function {
                name: "later".into(),
                frame: 0,
                body: None,
            },
        ];
        let mut folder = Folder::new(add_only);
        let call = |f, args| Code::apply(Callee::Fn(f), args);
        assert_eq!(
            folder.fold(&functions, &call(0, vec![Code::Const(Value::Int(41))])),
            Value::Int(42)
        );
        let f = folder.fold(&functions, &call(1, vec![]));
        let applied = Code::apply(
            Callee::Value,
            vec![Code::Const(f), Code::Const(Value::Int(1))],
        );
        assert_eq!(folder.fold(&functions, &applied), Value::Int(2));
        assert_eq!(folder.fold(&functions, &call(2, vec![])), not_compiled());
    }
}
