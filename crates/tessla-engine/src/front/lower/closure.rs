//! Value-level code: named functions and lambdas lowered once into the program's function
//! table, function values, and applying a value function to terms (constant folding when every
//! argument is known now, a signal lift when one is a stream, code over the frame inside
//! function bodies).
//!
//! Owns: `Compiler::compile_fn` (a named function, once per definition; a recursive call refers
//! to the function by its index, so nothing is closed through a cell), `func_value`,
//! `apply_value_fn`, `as_code`, `param_frame`, constant folding (`fold`, by `crate::ir::fold`
//! with the primitives' semantics the builtins table hands over) and the name of a native
//! callee.

use super::*;

impl Compiler<'_> {
    /// Turn a constant or code into code.
    pub(super) fn as_code(&self, t: Term) -> Code {
        match t {
            Term::Code(c) => c,
            Term::Const(v) => Code::Const(v),
            _ => Code::Const(Value::Error(RuntimeError::Other("not a value".into()))),
        }
    }

    /// Apply a strict value function to terms: fold what is known now, lift over streams, or
    /// build code over the frame inside function bodies.
    pub(super) fn apply_value_fn(&mut self, f: Callee, args: Vec<Term>, span: Span) -> R<Term> {
        if args.iter().any(|a| matches!(a, Term::Func(_))) {
            // Functions as arguments of value functions become function values.
            let mut conv = Vec::new();
            for a in args {
                conv.push(match a {
                    Term::Func(ft) => self.func_value(&ft, span)?,
                    other => other,
                });
            }
            return self.apply_value_fn(f, conv, span);
        }
        let known = args.iter().all(|a| match a {
            Term::Const(_) => true,
            Term::Code(c) => c.is_closed() && self.functions_done(c),
            _ => false,
        });
        let callee_done = || match &f {
            Callee::Fn(id) => self.functions_done(&Code::apply(Callee::Fn(*id), Vec::new())),
            _ => true,
        };
        if known && callee_done() {
            let code = Code::apply(f, args.into_iter().map(|a| self.as_code(a)).collect());
            return Ok(Term::Const(self.fold(&code)));
        }
        let has_stream = args.iter().any(|a| matches!(a, Term::Stream(_)));
        let has_frame = args
            .iter()
            .any(|a| matches!(a, Term::Code(c) if !c.is_closed()));
        if has_stream && !has_frame {
            let mut sargs = Vec::new();
            let mut codes = Vec::new();
            for a in args {
                match a {
                    Term::Stream(n) => {
                        codes.push(Code::Slot(sargs.len()));
                        sargs.push(SArg::Stream(n));
                    }
                    Term::Const(v) => {
                        codes.push(Code::Slot(sargs.len()));
                        sargs.push(SArg::Const(v));
                    }
                    other => codes.push(self.as_code(other)),
                }
            }
            return Ok(Term::Stream(self.slift_node(sargs, Code::apply(f, codes))));
        }
        if has_stream {
            return self.error(
                Category::Unsupported,
                span,
                "mixing streams and function parameters in one expression is not supported",
            );
        }
        let codes = args.into_iter().map(|a| self.as_code(a)).collect();
        Ok(Term::Code(Code::apply(f, codes)))
    }

    /// Whether every program function `code` can reach has its body (so it can run now).
    pub(super) fn functions_done(&self, code: &Code) -> bool {
        let mut todo = Vec::new();
        code.functions(&mut todo);
        let mut seen = HashSet::new();
        while let Some(f) = todo.pop() {
            if !seen.insert(f) {
                continue;
            }
            match self.table.functions.get(f).and_then(|x| x.body.as_ref()) {
                Some(b) => b.functions(&mut todo),
                None => return false,
            }
        }
        true
    }

    /// Evaluate closed code now (constant folding), with the functions finished so far.
    pub(super) fn fold(&mut self, code: &Code) -> Value {
        self.table.folder.fold(&self.table.functions, code)
    }

    /// A new entry of the function table, its body still to come.
    fn new_function(&mut self, name: &str, frame: usize) -> FnId {
        self.table.functions.push(Function {
            name: name.to_string(),
            frame,
            body: None,
        });
        self.table.functions.len() - 1
    }

    /// Give a function its body.
    fn finish_function(&mut self, id: FnId, body: Code) {
        if let Some(f) = self.table.functions.get_mut(id) {
            f.body = Some(body);
        }
        self.table.folder.function_finished();
    }

    /// A function term as a runtime value: a constant (natives) or closure code.
    pub(super) fn func_value(&mut self, ft: &Rc<FuncTerm>, span: Span) -> R<Term> {
        match &**ft {
            FuncTerm::Native { f, .. } => Ok(Term::Const(builtins::native_value(*f))),
            FuncTerm::User { def, env } => {
                let (fun, _) = self.compile_fn(def, env, span)?;
                // Defined inside a function body: the closure captures the enclosing frame.
                Ok(Term::Code(Code::Closure {
                    fun,
                    captured: env.frame,
                }))
            }
            FuncTerm::Lambda { params, body, env } => {
                let (names, frame) = self.param_frame(params, env.frame);
                let inner = env.child(names, frame);
                let fun = self.new_function("lambda", frame);
                let code = self.expr(body, &inner)?;
                let code = self.as_code(code);
                self.finish_function(fun, code);
                Ok(Term::Code(Code::Closure {
                    fun,
                    captured: env.frame,
                }))
            }
            FuncTerm::Builtin(b, _) => self.error(
                Category::Unsupported,
                span,
                format!("the stream function `{}` cannot be used as a value", b.name),
            ),
        }
    }

    pub(super) fn param_frame(
        &self,
        params: &[ast::Param],
        base: usize,
    ) -> (HashMap<String, Binding>, usize) {
        let mut names = HashMap::new();
        for (i, p) in params.iter().enumerate() {
            names.insert(
                p.name.name.clone(),
                Binding::Term(Term::Code(Code::Slot(base + i))),
            );
        }
        (names, base + params.len())
    }

    /// Lower a named value function once into the function table. Its frame is the enclosing
    /// function's frame (`env.frame` values, none at top level) followed by the arguments. The
    /// flag is false while the function is still being lowered (a recursive call), so such
    /// calls must not be folded now.
    pub(super) fn compile_fn(&mut self, def: &Rc<Def>, env: &Env, span: Span) -> R<(FnId, bool)> {
        let key = Rc::as_ptr(def);
        if let Some(&id) = self.table.compiled_fns.get(&key) {
            let done = self
                .table
                .functions
                .get(id)
                .is_some_and(|f| f.body.is_some());
            return Ok((id, done));
        }
        let params = def.params.clone().unwrap_or_default();
        let (names, frame) = self.param_frame(&params, env.frame);
        let id = self.new_function(&def.name.name, frame);
        self.table.compiled_fns.insert(key, id);
        let inner = env.child(names, frame);
        let Ok(body) = self.body(def, &inner) else {
            self.table.compiled_fns.remove(&key);
            return Err(Fail);
        };
        let code = match body {
            Term::Code(c) => c,
            Term::Const(v) => Code::Const(v),
            Term::Func(ft) => match &*ft {
                FuncTerm::Native { name, f } if matches!(def.body, Body::Extern { .. }) => {
                    Code::apply(native_callee(name, *f), Code::slots(frame))
                }
                // A function returning a function: the result is a function value.
                _ => match self.func_value(&ft, span)? {
                    Term::Const(v) => Code::Const(v),
                    Term::Code(c) => c,
                    _ => {
                        return self.error(
                            Category::Unsupported,
                            span,
                            "this function value is not supported",
                        );
                    }
                },
            },
            // Not a type rule: the lowering's signal that this function cannot be a value
            // function (`call` then expands it as a macro; kept when a liftable function
            // makes streams).
            Term::Stream(_) => {
                return self.error(
                    Category::Type,
                    span,
                    format!(
                        "`{}` makes a stream and cannot be called on values",
                        def.name.name
                    ),
                );
            }
        };
        self.finish_function(id, code);
        Ok((id, true))
    }
}

/// A native as a callee, named as the builtins table names it (for listings and identities);
/// a native the table lacks (one the application registered) by `name`.
pub(super) fn native_callee(name: &'static str, f: NativeFn) -> Callee {
    static NAMES: std::sync::OnceLock<HashMap<usize, &'static str>> = std::sync::OnceLock::new();
    let names = NAMES.get_or_init(|| {
        let mut m = HashMap::new();
        for b in builtins::BUILTINS {
            if let Kind::Value(g) | Kind::Operator(g) | Kind::Extern(g) = b.kind {
                m.entry(g as usize).or_insert(b.name);
            }
        }
        m.entry(unknown_extern as NativeFn as usize)
            .or_insert("unknown extern");
        m
    });
    let name = names.get(&(f as usize)).copied().unwrap_or(name);
    Callee::Native { name, f }
}

/// The native the builtins table lists as `name`, as a callee (the lowering's own uses of a
/// native: `maximum` and `minimum` reduce with `max` and `min`). A name the table lacks is an
/// error when evaluated (a test checks the names used are there).
pub(super) fn named_native(name: &str) -> Callee {
    match builtins::extern_named(name) {
        Some((name, f)) => native_callee(name, f),
        None => native_callee("unknown extern", unknown_extern),
    }
}
