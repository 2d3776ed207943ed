//! Calls: application of a function type to arguments (arity, argument types, signal lift),
//! TeSSLa's named-argument rule ([`order_named`], the one place of it: the lowering calls it
//! for the callees only it resolves), type arguments of user functions, and the
//! library-function hints on a wrong argument.

use super::*;

/// TeSSLa's rules for named arguments: every name is a parameter, and once a named argument
/// stands elsewhere than at its parameter's position, no positional argument follows. Returns
/// the parameter position of each argument. The one place of this rule: the checker applies
/// it to user functions and annotations, the lowering to the callees only it resolves
/// (builtins, natives, lambdas).
pub fn order_named(
    args: &[ast::Arg],
    params: &[&str],
    callee: &str,
) -> Result<Vec<usize>, Diagnostic> {
    let mut out = Vec::with_capacity(args.len());
    let mut positional_ok = true;
    for (i, a) in args.iter().enumerate() {
        match &a.name {
            Some(n) => {
                let Some(pos) = params.iter().position(|p| *p == n.name) else {
                    return Err(Diagnostic::error(
                        Category::Name,
                        Some(n.span),
                        format!("`{}` is no parameter of `{callee}`", n.name),
                    )
                    .with_label("no such parameter")
                    .with_help(format!("its parameters are ({})", params.join(", "))));
                };
                positional_ok &= pos == i;
                out.push(pos);
            }
            None if !positional_ok => {
                return Err(Diagnostic::error(
                    Category::Type,
                    Some(a.value.span),
                    "a positional argument after a named one",
                )
                .with_label("positional")
                .with_help("name this argument too, or put the positional arguments first"));
            }
            None => out.push(i),
        }
    }
    Ok(out)
}

impl<'a> Checker<'a> {
    /// [`order_named`], reporting its error.
    pub(super) fn order_named(
        &mut self,
        args: &[ast::Arg],
        params: &[&str],
        callee: &str,
    ) -> Option<Vec<usize>> {
        order_named(args, params, callee)
            .map_err(|d| self.report(d))
            .ok()
    }

    /// TeSSLa's rules for the type arguments of a call of a user function: as many as it has
    /// type parameters when given, and when none are given, each type parameter must occur in
    /// a parameter type so that the arguments determine it.
    pub(super) fn type_arguments(
        &mut self,
        d: &Def,
        given: &[ast::Type],
        called: bool,
        name_span: Span,
        span: Span,
    ) {
        let n = &d.name.name;
        let type_params = || {
            d.type_params
                .iter()
                .map(|t| t.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        };
        if !given.is_empty() && given.len() != d.type_params.len() {
            self.report(
                Diagnostic::error(
                    Category::Type,
                    Some(span),
                    format!(
                        "`{n}` takes {} type argument{}, {} given",
                        d.type_params.len(),
                        if d.type_params.len() == 1 { "" } else { "s" },
                        given.len()
                    ),
                )
                .with_help(format!("its type parameters are [{}]", type_params())),
            );
            return;
        }
        let Some(params) = &d.params else { return };
        if !given.is_empty() || !called {
            return;
        }
        for tp in &d.type_params {
            let inferable = params
                .iter()
                .any(|p| p.ty.as_ref().is_some_and(|t| mentions(t, &tp.name)));
            if !inferable {
                self.report(
                    Diagnostic::error(
                        Category::Type,
                        Some(name_span),
                        format!(
                            "the type argument `{}` of `{n}` cannot be inferred",
                            tp.name
                        ),
                    )
                    .with_label("type arguments needed")
                    .with_help(format!(
                        "`{}` occurs in no parameter type; give the type arguments: `{n}[{}](...)`",
                        tp.name,
                        type_params()
                    )),
                );
                return;
            }
        }
    }

    pub(super) fn call(
        &mut self,
        f: Ty,
        function: &'a Expr,
        args: &'a [ast::Arg],
        span: Span,
        scope: &Rc<Scope<'a>>,
    ) -> Ty {
        let mut ts: Vec<Ty> = args.iter().map(|a| self.infer(&a.value, scope)).collect();
        // Variadic builtins get their signature from the number of arguments.
        if let ExprKind::Var(id) = &function.kind
            && self.find(&id.name, scope).is_none()
            && let Some(Builtin {
                sig: Sig::Variadic(shape),
                ..
            }) = builtins::get(&id.name)
            && let Some(sig) = self.variadic(shape, ts.len())
        {
            return self.apply(sig, &ts, args, span, &id.name);
        }
        if args.iter().any(|a| a.name.is_some()) {
            // Named arguments: put them in parameter order when the callee is a user def.
            let params = match &function.kind {
                ExprKind::Var(id) => match self.find(&id.name, scope) {
                    Some(Found::Def(d)) => d.def.params.clone(),
                    _ => None,
                },
                _ => None,
            };
            let Some(params) = params else {
                return self.fresh();
            };
            let names: Vec<&str> = params.iter().map(|p| p.name.name.as_str()).collect();
            let callee = function
                .dotted_path()
                .unwrap_or_else(|| "the function".into());
            let Some(positions) = self.order_named(args, &names, &callee) else {
                return self.fresh();
            };
            let mut ordered: Vec<Option<Ty>> = vec![None; params.len()];
            for (pos, t) in positions.into_iter().zip(ts.iter()) {
                match ordered.get_mut(pos) {
                    Some(slot) => *slot = Some(t.clone()),
                    None => return self.fresh(),
                }
            }
            match ordered.into_iter().collect::<Option<Vec<Ty>>>() {
                Some(o) => ts = o,
                // A parameter without an argument (a default value): not modelled.
                None => return self.fresh(),
            }
        }
        let name = match &function.kind {
            ExprKind::Var(id) => id.name.clone(),
            _ => "the function".into(),
        };
        // A user function's parameters of value types, before the call binds anything.
        let value_params = match (function.dotted_path(), self.shallow(&f)) {
            (Some(path), Ty::Fn(ps, _)) => match self.find(&path, scope) {
                // A def without parameters (`def g = f`) names a function whose liftability
                // is its value's, not modelled: let through.
                Some(Found::Def(d)) if !d.def.liftable && d.def.params.is_some() => {
                    Some((d, self.value_params(&ps)))
                }
                _ => None,
            },
            _ => None,
        };
        let before = self.diags.len();
        let r = self.apply(f, &ts, args, span, &name);
        if self.diags.len() == before
            && let Some((d, value_params)) = value_params
        {
            self.check_not_lifted(d.def, &value_params, &ts, args, span);
        }
        if self.diags.len() > before
            && self.find(&name, scope).is_none()
            && let Some(h) = library_hint(&name)
            && let Some(d) = self.diags.last_mut()
        {
            d.help = Some(h.to_string());
        }
        r
    }

    /// Apply a function type to arguments.
    pub(super) fn apply(
        &mut self,
        f: Ty,
        ts: &[Ty],
        args: &[ast::Arg],
        span: Span,
        name: &str,
    ) -> Ty {
        match self.shallow(&f) {
            Ty::Fn(ps, r) => {
                if ps.len() != ts.len() {
                    self.report(Diagnostic::error(
                        Category::Type,
                        Some(span),
                        format!("`{name}` takes {} arguments, {} given", ps.len(), ts.len()),
                    ));
                    return self.fresh();
                }
                for (i, (p, t)) in ps.iter().zip(ts).enumerate() {
                    let sp = args.get(i).map_or(span, |a| a.value.span);
                    if !self.expect(p, t, sp, &format!("argument {} of `{name}`", i + 1)) {
                        return self.fresh();
                    }
                }
                self.lifted(ts, *r)
            }
            Ty::Var(_) => {
                let r = self.fresh();
                let _ = self.unify(&f, &func(ts.to_vec(), r.clone()));
                r
            }
            other => {
                self.report(Diagnostic::error(
                    Category::Type,
                    Some(span),
                    format!(
                        "`{name}` is {}, not a function",
                        show(&self.resolve(&other))
                    ),
                ));
                self.fresh()
            }
        }
    }
}
