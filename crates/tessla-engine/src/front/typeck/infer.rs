//! Inference of an expression, form by form (`infer`): literals, strings, tuples, records,
//! blocks, member access, `if`, lambdas, calls (operators are in `operators`, calls in
//! `calls`), and TeSSLa's literal-member rule (`def x = (v, x._1)` reads the member).

use super::*;

impl<'a> Checker<'a> {
    /// The type of an expression. Definitions are inferred where they are first used, so a
    /// long chain of definitions recurses deeply: the stack grows on the heap instead of
    /// overflowing.
    pub(super) fn infer(&mut self, e: &'a Expr, scope: &Rc<Scope<'a>>) -> Ty {
        stacker::maybe_grow(128 * 1024, 4 * 1024 * 1024, || self.infer_here(e, scope))
    }

    pub(super) fn infer_here(&mut self, e: &'a Expr, scope: &Rc<Scope<'a>>) -> Ty {
        match &e.kind {
            ExprKind::Var(id) => match id.name.as_str() {
                n @ ("true" | "false" | "None" | "unit" | "nil")
                    if self.find(n, scope).is_none() =>
                {
                    match n {
                        "None" => {
                            let a = self.fresh();
                            opt(a)
                        }
                        "unit" => ev(unit()),
                        "nil" => {
                            let a = self.fresh();
                            ev(a)
                        }
                        _ => boolean(),
                    }
                }
                _ => self.lookup(id, scope),
            },
            ExprKind::RootMember(id) => match self.find_global(&id.name, "") {
                Some(Found::Mono(t)) => t,
                Some(Found::Def(d)) => self.def_type(&d),
                None => self.fresh(),
            },
            ExprKind::Int { .. } => int(),
            ExprKind::Float(_) => float(),
            ExprKind::Str { parts, .. } => {
                let mut ts = Vec::new();
                for p in parts {
                    if let StrPart::Interp { expr, .. } = p {
                        ts.push(self.infer(expr, scope));
                    }
                }
                self.lifted(&ts, string())
            }
            ExprKind::Tuple(es) if es.is_empty() => unit(),
            ExprKind::Tuple(es) => {
                let ts: Vec<Ty> = es.iter().map(|x| self.infer(x, scope)).collect();
                let r = tuple(ts.iter().map(|t| self.strip(t)).collect());
                self.lifted(&ts, r)
            }
            ExprKind::Record(members) if members.is_empty() => unit(),
            ExprKind::Record(members) => {
                let mut fs: Vec<(String, Ty)> = Vec::new();
                let mut ts = Vec::new();
                for (n, x) in members {
                    let t = self.infer(x, scope);
                    fs.push((n.name.clone(), self.strip(&t)));
                    ts.push(t);
                }
                fs.sort_by(|a, b| a.0.cmp(&b.0));
                fs.dedup_by(|a, b| a.0 == b.0);
                self.lifted(&ts, Ty::Record(fs))
            }
            ExprKind::Block { defs, result } => {
                let s = self.local_defs(defs, scope);
                let t = self.infer(result, &s);
                self.check_unused(defs, &s);
                t
            }
            ExprKind::Member { object, field } => {
                if let Some(path) = object.dotted_path() {
                    let head = path.split('.').next().unwrap_or_default();
                    if self.find(head, scope).is_none() {
                        let q = format!("{path}.{}", field.name);
                        return match self.find(&q, scope) {
                            Some(Found::Mono(t)) => t,
                            Some(Found::Def(d)) => self.def_type(&d),
                            // Neither a value, nor a builtin, nor a library alias of a
                            // literal (`Types.true`, `Option.None`): unknown (`Foo.bar`,
                            // `Operators.zzz`), as `lookup` finds for plain names.
                            None if !is_builtin_name(&q)
                                && !matches!(
                                    crate::front::prelude::builtin_alias(&q),
                                    Some("true" | "false" | "None")
                                ) =>
                            {
                                let id = ast::Ident {
                                    name: q,
                                    span: e.span,
                                };
                                self.unknown_name(&id, scope);
                                self.fresh()
                            }
                            None => self.builtin(&q).unwrap_or_else(|| self.fresh()),
                        };
                    }
                }
                if let Some(t) = self.literal_member(object, field, scope) {
                    return t;
                }
                let o = self.infer(object, scope);
                let base = self.resolve(&self.strip(&o));
                let r = match &base {
                    Ty::Record(fs) => match fs.iter().find(|(n, _)| *n == field.name) {
                        Some((_, t)) => t.clone(),
                        None => {
                            let known: Vec<String> =
                                fs.iter().map(|(n, _)| format!("`{n}`")).collect();
                            self.report(
                                Diagnostic::error(
                                    Category::Type,
                                    Some(field.span),
                                    format!("{} has no field `{}`", show(&base), field.name),
                                )
                                .with_help(format!("its fields are {}", known.join(", "))),
                            );
                            self.fresh()
                        }
                    },
                    other @ (Ty::Con(..) | Ty::Fn(..)) => {
                        self.report(
                            Diagnostic::error(
                                Category::Type,
                                Some(field.span),
                                format!("{} has no field `{}`", show(other), field.name),
                            )
                            .with_label("no such field")
                            .with_help("only records and tuples have fields"),
                        );
                        self.fresh()
                    }
                    _ => self.fresh(),
                };
                self.lifted(&[o], r)
            }
            ExprKind::Unary { op, operand } => self.unary(*op, operand, e.span, scope),
            ExprKind::Binary { op, lhs, rhs } => self.binary(*op, lhs, rhs, e.span, scope),
            ExprKind::If {
                is_static,
                cond,
                then_branch,
                else_branch,
            } => {
                let c = self.infer(cond, scope);
                self.expect(
                    &boolean(),
                    &c,
                    cond.span,
                    "the condition of `if` must be a Bool",
                );
                let t = self.infer(then_branch, scope);
                let f = self.infer(else_branch, scope);
                if *is_static {
                    // Only one branch is compiled; the other may have another type.
                    return self.fresh();
                }
                if self.unify(&t, &f).is_err() {
                    let (ts, fs) = (show(&self.resolve(&t)), show(&self.resolve(&f)));
                    self.report(
                        Diagnostic::error(
                            Category::Type,
                            Some(else_branch.span),
                            format!("the branches of `if` have different types: {ts} and {fs}"),
                        )
                        .with_label(format!("this is {fs}"))
                        .with_note_at(then_branch.span, format!("this is {ts}"))
                        .with_help("both branches must have the same type"),
                    );
                    return self.fresh();
                }
                let r = if self.is_stream(&f) { f } else { t };
                self.lifted(&[c], r)
            }
            ExprKind::Lambda { params, body } => {
                let inner = self.child_of(scope);
                let mut ps = Vec::new();
                for p in params {
                    let t = match &p.ty {
                        Some(t) => self.ast_type(t, &HashMap::new()),
                        None => self.missing_parameter_type(p, None),
                    };
                    inner
                        .names
                        .borrow_mut()
                        .insert(p.name.name.clone(), Local::Mono(t.clone()));
                    ps.push(t);
                }
                let r = self.infer(body, &inner);
                func(ps, r)
            }
            ExprKind::Call {
                function,
                args,
                type_args,
            } => {
                for t in type_args {
                    self.ast_type(t, &HashMap::new());
                }
                if let ExprKind::Var(id) = &function.kind {
                    match self.find(&id.name, scope) {
                        Some(Found::Def(d)) => self.type_arguments(
                            d.def,
                            type_args,
                            args.is_some(),
                            function.span,
                            e.span,
                        ),
                        // A builtin takes the type arguments its library declaration names.
                        None if !type_args.is_empty() => {
                            let name =
                                crate::front::prelude::builtin_alias(&id.name).unwrap_or(&id.name);
                            if let Some(d) = builtins::get(name)
                                .and_then(|b| crate::front::prelude::declaration(b.name))
                            {
                                self.type_arguments(d, type_args, false, function.span, e.span);
                            }
                        }
                        _ => {}
                    }
                }
                let f = self.infer(function, scope);
                let Some(args) = args else {
                    return f;
                };
                self.call(f, function, args, e.span, scope)
            }
        }
    }

    /// `x._1` or `x.a` inside the definition of `x` itself, where `x` is a tuple or record
    /// literal without a written type: as in TeSSLa, the access is the member's own expression
    /// (`def x = (v, x._1)` is not a recursion of `x`). `None`: not such an access.
    pub(super) fn literal_member(
        &mut self,
        object: &'a Expr,
        field: &ast::Ident,
        scope: &Rc<Scope<'a>>,
    ) -> Option<Ty> {
        let ExprKind::Var(id) = &object.kind else {
            return None;
        };
        let Some(Found::Def(d)) = self.find(&id.name, scope) else {
            return None;
        };
        if d.def.params.is_some() || !matches!(*d.state.borrow(), State::InProgress(_)) {
            return None;
        }
        let Body::Expr { expr, where_defs } = &d.def.body else {
            return None;
        };
        if !where_defs.is_empty() {
            return None;
        }
        let member = match &expr.kind {
            ExprKind::Tuple(es) => field
                .name
                .strip_prefix('_')
                .and_then(|k| k.parse::<usize>().ok())
                .and_then(|k| es.get(k.checked_sub(1)?)),
            ExprKind::Record(ms) => ms
                .iter()
                .find(|(n, _)| n.name == field.name)
                .map(|(_, e)| e),
            _ => None,
        }?;
        let key = (Rc::as_ptr(&d) as usize, field.name.clone());
        if self.literal_members.contains(&key) {
            return None;
        }
        self.literal_members.push(key);
        let t = self.infer(member, &d.scope);
        self.literal_members.pop();
        Some(t)
    }
}
