//! Calls: a function term applied to argument terms (macro expansion of user functions on
//! streams, builtins, natives, closures), named arguments, and the argument accessors the
//! stream operators use.
//!
//! Owns: `Compiler::call`, `call_compiled`, `order_named_args`,
//! `stream_arg`, `value_fn_arg`, `const_arg`.

use super::*;

impl Compiler<'_> {
    /// Put named arguments (`f(b = 1, a = x)`) in the order of the function's parameters, by
    /// TeSSLa's rule ([`crate::front::typeck::order_named`]).
    pub(super) fn order_named_args(
        &mut self,
        f: &Term,
        args: &[ast::Arg],
        terms: Vec<Term>,
        callee: &str,
        span: Span,
    ) -> R<Vec<Term>> {
        let params: Vec<String> = match f {
            Term::Func(ft) => match &**ft {
                FuncTerm::User { def, .. } => def
                    .params
                    .iter()
                    .flatten()
                    .map(|p| p.name.name.clone())
                    .collect(),
                FuncTerm::Lambda { params, .. } => {
                    params.iter().map(|p| p.name.name.clone()).collect()
                }
                // A builtin takes TeSSLa's parameter names, as the prelude declares them.
                FuncTerm::Builtin(b, _) if crate::front::prelude::param_names(b.name).is_some() => {
                    crate::front::prelude::param_names(b.name).unwrap_or_default()
                }
                FuncTerm::Native { name, .. }
                    if crate::front::prelude::native_param_names(name).is_some() =>
                {
                    crate::front::prelude::native_param_names(name).unwrap_or_default()
                }
                _ => {
                    return self.error(
                        Category::Unsupported,
                        span,
                        "named arguments need a function with named parameters",
                    );
                }
            },
            // The one place of this rule: the checker orders named arguments only for user
            // functions with parameters (`typeck::calls`) and leaves other callees open.
            _ => return self.error(Category::Type, span, "named arguments need a function"),
        };
        let names: Vec<&str> = params.iter().map(String::as_str).collect();
        let positions = match crate::front::typeck::order_named(args, &names, callee) {
            Ok(p) => p,
            Err(d) => {
                self.diags.push(d);
                return Err(Fail);
            }
        };
        // The one place of the rule that named arguments fill each parameter exactly once: the
        // checker leaves such calls open (a parameter without an argument could be a default
        // value, not modelled there), and builtins, natives and lambdas are resolved here only.
        let mut slots: Vec<Option<Term>> = vec![None; params.len()];
        for (idx, t) in positions.into_iter().zip(terms) {
            match slots.get_mut(idx) {
                Some(slot @ None) => *slot = Some(t),
                _ => {
                    return self.error(
                        Category::Type,
                        span,
                        "an argument is given twice or there are too many arguments",
                    );
                }
            }
        }
        slots
            .into_iter()
            .map(|s| s.ok_or(Fail))
            .collect::<R<Vec<_>>>()
            .or_else(|_| self.error(Category::Type, span, "missing arguments"))
    }

    pub(super) fn call(&mut self, f: Term, args: Vec<Term>, span: Span, env: &Env) -> R<Term> {
        let Term::Func(ft) = f else {
            // Calling a function value at runtime.
            if let Term::Code(_) | Term::Const(Value::Closure(_)) = f {
                let mut all = vec![f];
                all.extend(args);
                return self.apply_value_fn(Callee::Value, all, span);
            }
            return self.unchecked(span, "a call of something that is not a function");
        };
        match &*ft {
            FuncTerm::Builtin(b, op) => self.stream_builtin(b.name, *op, args, span),
            FuncTerm::Native { name, f } => {
                self.apply_value_fn(closure::native_callee(name, *f), args, span)
            }
            FuncTerm::User { def, env: denv } => {
                let params = def.params.clone().unwrap_or_default();
                if let Body::Extern { .. } = def.body {
                    let r = match self.body(def, denv)? {
                        Term::Func(inner) => self.call(Term::Func(inner), args, span, env)?,
                        other => other,
                    };
                    return Ok(r);
                }
                if params.len() != args.len() {
                    return self.unchecked(span, "a call with the wrong number of arguments");
                }
                let has_func = args.iter().any(|a| matches!(a, Term::Func(_)));
                let has_stream = args.iter().any(|a| matches!(a, Term::Stream(_)));
                let stream_params = def.params.as_ref().is_some_and(|ps| ps.iter().any(|p| matches!(&p.ty, Some(ast::Type::App { name, .. }) if name.name == "Events")));
                // `liftable` functions on streams are signal-lifted, not expanded.
                let lift = def.liftable && has_stream && !has_func && !stream_params;
                let mut expand = !lift
                    && (has_func
                        || has_stream
                        || stream_params
                        || self.table.not_value_fns.contains(&def.span));
                if !expand {
                    let saved = self.diags.len();
                    match self.call_compiled(def, denv, args.clone(), span) {
                        Ok(t) => return Ok(t),
                        // A body that makes streams from its parameters (`static if`, `const`
                        // ...) cannot be a value function: expand it like a macro instead.
                        // A name error (a named argument that is no parameter) is wrong in
                        // either form: expanding would only find it again, once per call site of every enclosing expansion
                        // (exponential in mutually recursive nested functions).
                        Err(Fail)
                            if !lift
                                && !self.diags[saved..]
                                    .iter()
                                    .any(|d| d.category == Category::Name) =>
                        {
                            self.diags.truncate(saved);
                            self.table.not_value_fns.insert(def.span);
                            expand = true;
                        }
                        Err(Fail) => return Err(Fail),
                    }
                }
                if expand {
                    self.depth.inline_depth += 1;
                    if self.depth.inline_depth > 200 {
                        self.depth.inline_depth -= 1;
                        return self.error(
                            Category::Recursion,
                            span,
                            format!("`{}` expands without end (recursive macro)", def.name.name),
                        );
                    }
                    let names: HashMap<String, Binding> = params
                        .iter()
                        .zip(args)
                        .map(|(p, a)| (p.name.name.clone(), Binding::Term(a)))
                        .collect();
                    // The expansion runs in the caller's runtime frame (its arguments read it):
                    // lambdas made inside capture that frame and put parameters after it.
                    let inner = denv.child(names, env.frame.max(denv.frame));
                    let r = self.body(def, &inner);
                    self.depth.inline_depth -= 1;
                    r
                } else {
                    self.call_compiled(def, denv, args, span)
                }
            }
            FuncTerm::Lambda {
                params,
                body,
                env: lenv,
            } => {
                if params.len() != args.len() {
                    return self.unchecked(span, "a call with the wrong number of arguments");
                }
                let names: HashMap<String, Binding> = params
                    .iter()
                    .zip(args)
                    .map(|(p, a)| (p.name.name.clone(), Binding::Term(a)))
                    .collect();
                // Inlined in the caller's runtime frame (see the expansion of user functions).
                let inner = lenv.child(names, env.frame.max(lenv.frame));
                self.expr(body, &inner)
            }
        }
    }

    /// Call a user function compiled to a value function (lifted over stream arguments).
    pub(super) fn call_compiled(
        &mut self,
        def: &Rc<Def>,
        denv: &Env,
        args: Vec<Term>,
        span: Span,
    ) -> R<Term> {
        let (f, ready) = self.compile_fn(def, denv, span)?;
        // A function defined inside a function body also gets the enclosing frame.
        let mut all: Vec<Term> = (0..denv.frame)
            .map(|slot| Term::Code(Code::Slot(slot)))
            .collect();
        all.extend(args);
        if !ready && all.iter().all(|a| matches!(a, Term::Const(_))) {
            // A recursive call with constant arguments: evaluated at run time.
            let vals = all.into_iter().map(|a| self.as_code(a)).collect();
            return Ok(Term::Code(Code::apply(Callee::Fn(f), vals)));
        }
        let r = self.apply_value_fn(Callee::Fn(f), all, span)?;
        Ok(r)
    }

    pub(super) fn stream_arg(&mut self, args: &[Term], i: usize, span: Span) -> R<NodeId> {
        match args.get(i) {
            Some(t) => self.stream_of(t.clone(), span),
            None => self.unchecked(span, "a call with the wrong number of arguments"),
        }
    }

    /// Argument `i`, a function, as code applying it to `arity` arguments (slots `0..arity`).
    pub(super) fn value_fn_arg(
        &mut self,
        args: &[Term],
        i: usize,
        arity: usize,
        span: Span,
    ) -> R<Code> {
        match args.get(i) {
            Some(Term::Func(ft)) => match &**ft {
                FuncTerm::Native { name, f } => Ok(Code::apply(
                    closure::native_callee(name, *f),
                    Code::slots(arity),
                )),
                _ => match self.func_value(ft, span)? {
                    Term::Const(Value::Closure(c)) => {
                        let mut all = vec![Code::Const(Value::Closure(c))];
                        all.extend(Code::slots(arity));
                        Ok(Code::apply(Callee::Value, all))
                    }
                    Term::Code(Code::Closure { fun, captured: 0 }) => {
                        Ok(Code::apply(Callee::Fn(fun), Code::slots(arity)))
                    }
                    _ => self.error(
                        Category::Unsupported,
                        span,
                        "this function cannot be compiled to a value",
                    ),
                },
            },
            Some(Term::Const(Value::Closure(c))) => {
                let mut all = vec![Code::Const(Value::Closure(c.clone()))];
                all.extend(Code::slots(arity));
                Ok(Code::apply(Callee::Value, all))
            }
            // The one place of this rule where the checker leaves the argument's type open
            // (`reduce(x, nil)`: `nil` and the other `Sig::Any` builtins of `crate::builtins`).
            _ => self.error(
                Category::Type,
                span,
                format!("argument {} must be a function", i + 1),
            ),
        }
    }

    pub(super) fn const_arg(&mut self, args: &[Term], i: usize, span: Span) -> R<Value> {
        match args.get(i) {
            Some(Term::Const(v)) => Ok(v.clone()),
            // The one place of this rule: the checker's types do not tell a constant from the
            // stream a signal lift makes of it (`default(x, x)`, `period(x)`). Also a signal
            // for `call` to expand a function as a macro instead of compiling it to a value.
            _ => self.error(
                Category::Type,
                span,
                format!("argument {} must be a constant", i + 1),
            ),
        }
    }
}
