//! Value-level code: named functions and lambdas compiled once into closures over a frame of
//! variables, function values, and applying a value function to terms (constant folding when
//! every argument is a constant, a signal lift when one is a stream).
//!
//! Owns: [`RtClosure`] and [`FnValue`] (functions as runtime values), `Compiler::compile_fn`
//! (a named function, cached, recursion through a cell), `func_value`, `apply_value_fn`,
//! `as_dyn`, `param_frame`.

use super::*;

impl Compiler<'_> {
    /// Turn a constant or frame code into frame code.
    pub(super) fn as_dyn(&self, t: Term) -> Dyn {
        match t {
            Term::Dyn(d) => d,
            Term::Const(v) => Arc::new(move |_: &[Value]| v.clone()),
            _ => Arc::new(|_: &[Value]| Value::Error(RuntimeError::Other("not a value".into()))),
        }
    }

    /// Apply a strict value function to terms: fold constants, lift over streams, or build frame
    /// code inside function bodies.
    pub(super) fn apply_value_fn(&mut self, f: Func, args: Vec<Term>, span: Span) -> R<Term> {
        if args.iter().all(|a| matches!(a, Term::Const(_))) {
            let vals: Vec<Value> = args
                .into_iter()
                .map(|a| match a {
                    Term::Const(v) => v,
                    _ => Value::Unit,
                })
                .collect();
            return Ok(Term::Const(f(&vals)));
        }
        let has_stream = args.iter().any(|a| matches!(a, Term::Stream(_)));
        let has_dyn = args.iter().any(|a| matches!(a, Term::Dyn(_)));
        if args.iter().any(|a| matches!(a, Term::Func(_))) {
            // Functions as arguments of value functions become closures.
            let mut conv = Vec::new();
            for a in args {
                conv.push(match a {
                    Term::Func(ft) => self.func_value(&ft, span)?,
                    other => other,
                });
            }
            return self.apply_value_fn(f, conv, span);
        }
        if has_stream && !has_dyn {
            let sargs = args
                .into_iter()
                .map(|a| match a {
                    Term::Stream(n) => SArg::Stream(n),
                    Term::Const(v) => SArg::Const(v),
                    _ => SArg::Const(Value::Unit),
                })
                .collect();
            return Ok(Term::Stream(self.slift_node(sargs, f)));
        }
        if has_stream {
            return self.error(
                Category::Unsupported,
                span,
                "mixing streams and function parameters in one expression is not supported",
            );
        }
        let ds: Vec<Dyn> = args.into_iter().map(|a| self.as_dyn(a)).collect();
        Ok(Term::Dyn(Arc::new(move |fr: &[Value]| {
            let vals: Vec<Value> = ds.iter().map(|d| d(fr)).collect();
            f(&vals)
        })))
    }

    /// A function term as a runtime value (`Value::Closure`), constant or frame code.
    pub(super) fn func_value(&mut self, ft: &Rc<FuncTerm>, span: Span) -> R<Term> {
        match &**ft {
            FuncTerm::Native(n) => {
                let n = *n;
                let f: Func = Arc::new(move |a: &[Value]| call_native(n, a));
                Ok(Term::Const(Value::Closure(Arc::new(FnValue(f)))))
            }
            FuncTerm::User { def, env } => {
                let (f, _) = self.compile_fn(def, env, span)?;
                let outer = env.frame;
                if outer == 0 {
                    return Ok(Term::Const(Value::Closure(Arc::new(FnValue(f)))));
                }
                // Defined inside a function body: the closure captures the enclosing frame.
                Ok(Term::Dyn(Arc::new(move |fr: &[Value]| {
                    Value::Closure(Arc::new(RtClosure {
                        captured: fr[..outer.min(fr.len())].to_vec(),
                        body: f.clone(),
                    }))
                })))
            }
            FuncTerm::Lambda { params, body, env } => {
                let (names, frame) = self.param_frame(params, env.frame);
                let inner = env.child(names, frame);
                let code = self.expr(body, &inner)?;
                let code = self.as_dyn(code);
                let outer = env.frame;
                if outer == 0 {
                    Ok(Term::Const(Value::Closure(Arc::new(RtClosure {
                        captured: Vec::new(),
                        body: code,
                    }))))
                } else {
                    Ok(Term::Dyn(Arc::new(move |fr: &[Value]| {
                        Value::Closure(Arc::new(RtClosure {
                            captured: fr[..outer.min(fr.len())].to_vec(),
                            body: code.clone(),
                        }))
                    })))
                }
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
            let slot = base + i;
            let d: Dyn = Arc::new(move |fr: &[Value]| fr.get(slot).cloned().unwrap_or(Value::Unit));
            names.insert(p.name.name.clone(), Binding::Term(Term::Dyn(d)));
        }
        (names, base + params.len())
    }

    /// Compile a named value function once into a closure (recursion through a cell). The
    /// closure takes the enclosing function's frame (`env.frame` values, none at top level)
    /// followed by the arguments. The flag is false while the function is still being compiled
    /// (a recursive call), so such calls must not be folded at compile time.
    pub(super) fn compile_fn(&mut self, def: &Rc<Def>, env: &Env, span: Span) -> R<(Func, bool)> {
        let key = Rc::as_ptr(def);
        if let Some(cell) = self.compiled_fns.get(&key) {
            if let Some(f) = cell.get() {
                return Ok((f.clone(), true));
            }
            // A recursive call inside the body being compiled refers to its cell weakly (the
            // body is in the cell: a strong reference would be a cycle that outlives the
            // program); the program holds the cell (`Program::functions`).
            self.recursive_cells.push(cell.clone());
            let cell = Arc::downgrade(cell);
            return Ok((
                Arc::new(move |a: &[Value]| match cell.upgrade() {
                    Some(c) => match c.get() {
                        Some(f) => f(a),
                        None => not_compiled(),
                    },
                    None => not_compiled(),
                }),
                false,
            ));
        }
        let cell: Arc<OnceLock<Func>> = Arc::new(OnceLock::new());
        self.compiled_fns.insert(key, cell.clone());
        let params = def.params.clone().unwrap_or_default();
        let (names, frame) = self.param_frame(&params, env.frame);
        let inner = Env {
            names: Rc::new(names),
            parent: Some(Rc::new(env.clone())),
            frame,
        };
        let Ok(body) = self.body(def, &inner) else {
            self.compiled_fns.remove(&key);
            return Err(Fail);
        };
        let f: Func = match body {
            Term::Dyn(d) => Arc::new(move |a: &[Value]| d(a)),
            Term::Const(v) => Arc::new(move |_: &[Value]| v.clone()),
            Term::Func(ft) => match &*ft {
                FuncTerm::Native(n) if matches!(def.body, Body::Extern { .. }) => {
                    let n = *n;
                    Arc::new(move |a: &[Value]| call_native(n, a))
                }
                // A function returning a function: the result is a closure value.
                _ => match self.func_value(&ft, span)? {
                    Term::Const(v) => Arc::new(move |_: &[Value]| v.clone()),
                    Term::Dyn(d) => Arc::new(move |a: &[Value]| d(a)),
                    _ => {
                        return self.error(
                            Category::Unsupported,
                            span,
                            "this function value is not supported",
                        );
                    }
                },
            },
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
        let _ = cell.set(f.clone());
        Ok((f, true))
    }
}

/// A runtime function value (closure over a captured frame).
pub(super) struct RtClosure {
    captured: Vec<Value>,
    body: Dyn,
}

impl std::fmt::Debug for RtClosure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("<function>")
    }
}

impl Callable for RtClosure {
    fn call(&self, args: &[Value]) -> Value {
        let mut frame = self.captured.clone();
        frame.extend_from_slice(args);
        (self.body)(&frame)
    }
}

/// A compiled named function called as a value.
pub(super) struct FnValue(Func);

impl std::fmt::Debug for FnValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("<function>")
    }
}

impl Callable for FnValue {
    fn call(&self, args: &[Value]) -> Value {
        (self.0)(args)
    }
}

fn not_compiled() -> Value {
    Value::Error(RuntimeError::Other("function not compiled".into()))
}
