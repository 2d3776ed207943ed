//! Expressions: every syntax form to a [`Term`] (literals, time literals, format strings,
//! operators with their inline scalar nodes, `if`, records, tuples, member access, lambdas,
//! blocks).
//!
//! Owns: `Compiler::expr`, the inline nodes of operators (`inline_op`, `slift_node`) and the one
//! mapping of the syntax's operators onto the IR's ([`BinOp`], [`UnaryOp`]: `From` the
//! `tessla_syntax::ast` ones, also what the trace reader converts with). Value operations become
//! [`Prim`]itive applications (semantics in `runtime::exec` and `runtime::ops`).

use super::*;

impl Compiler<'_> {
    /// Replace the signal lift just made for `t` by a node the evaluator runs inline (a typed
    /// fast path: no closure call, no argument copies).
    pub(super) fn inline_op(
        &mut self,
        t: &Term,
        make: impl FnOnce(&[SArg], &Code) -> Option<Node>,
    ) {
        if let Term::Stream(n) = t
            && let Some(Node::SLift { args, f }) = self.graph.nodes.get(*n)
            && let Some(node) = make(args, f)
            && let Some(slot) = self.graph.nodes.get_mut(*n)
        {
            *slot = node;
        }
    }

    pub(super) fn slift_node(&mut self, args: Vec<SArg>, f: Code) -> NodeId {
        self.node(Node::SLift { args, f })
    }

    /// Lower one expression. Specs nest expressions and expand calls to any depth (a recursive
    /// macro is stopped only after 200 expansions), so the stack grows on the heap instead of
    /// overflowing (a stack overflow aborts the process).
    pub(super) fn expr(&mut self, e: &Expr, env: &Env) -> R<Term> {
        stacker::maybe_grow(128 * 1024, 4 * 1024 * 1024, || self.expr_here(e, env))
    }

    fn expr_here(&mut self, e: &Expr, env: &Env) -> R<Term> {
        match &e.kind {
            ExprKind::Var(id) => self.lookup(&id.name, id.span, env),
            ExprKind::RootMember(id) => self.lookup(&id.name, id.span, env),
            ExprKind::Int { value, unit } => {
                let v = match unit {
                    None => *value,
                    Some(u) if !self.time.time_units => {
                        self.diags.push(
                            Diagnostic::error(
                                Category::Time,
                                Some(u.span),
                                format!("time unit `{}` used, but no base time is set", u.name),
                            )
                            .with_help("set the base time of the trace (`--base-time 1ms`)"),
                        );
                        return Err(Fail);
                    }
                    Some(u) => {
                        let f = unit_factor(&u.name).unwrap_or(1);
                        let fs = value.checked_mul(f).unwrap_or(i128::MAX);
                        // As TeSSLa does: the literal must be a whole number of the base
                        // time's unit; then it is divided by the base's count, truncating
                        // (100ms at 33333 µs is 3), but it must not become 0.
                        let unit_fs = self.time.base_unit.unwrap_or(self.time.base_ns);
                        if fs % unit_fs != 0 {
                            return self.error(
                                Category::Time,
                                e.span,
                                format!(
                                    "cannot convert {value} {} to the base time's unit",
                                    u.name
                                ),
                            );
                        }
                        let r = fs / unit_fs / (self.time.base_ns / unit_fs).max(1);
                        if r == 0 && *value != 0 {
                            return self.error(
                                Category::Time,
                                e.span,
                                format!(
                                    "cannot represent {value} {} in terms of the base time",
                                    u.name
                                ),
                            );
                        }
                        r
                    }
                };
                // The one place of this rule (the checker does not evaluate literals).
                match i64::try_from(v) {
                    Ok(i) => Ok(Term::Const(Value::Int(i))),
                    Err(_) => self.error(
                        Category::Type,
                        e.span,
                        "integer literal does not fit in 64 bits",
                    ),
                }
            }
            ExprKind::Float(f) => Ok(Term::Const(Value::Float(*f))),
            ExprKind::Str { parts, .. } => {
                let mut terms = Vec::new();
                for p in parts {
                    match p {
                        StrPart::Text(t) => terms.push(Term::Const(Value::Str(t.as_str().into()))),
                        StrPart::Interp { expr, format } => {
                            let t = self.expr(expr, env)?;
                            let f = Callee::Prim(Prim::Format(format.clone()));
                            terms.push(self.apply_value_fn(f, vec![t], e.span)?);
                        }
                    }
                }
                if terms.len() == 1 {
                    return Ok(terms.remove(0));
                }
                self.apply_value_fn(Callee::Prim(Prim::Concat), terms, e.span)
            }
            ExprKind::Tuple(es) if es.is_empty() => Ok(Term::Const(Value::Unit)),
            ExprKind::Tuple(es) => {
                let terms = es
                    .iter()
                    .map(|x| self.expr(x, env))
                    .collect::<R<Vec<_>>>()?;
                self.apply_value_fn(Callee::Prim(Prim::Tuple), terms, e.span)
            }
            ExprKind::Record(members) => {
                let mut sorted: Vec<_> = members.iter().collect();
                sorted.sort_by(|a, b| a.0.name.cmp(&b.0.name));
                let names: Vec<Arc<str>> = sorted
                    .iter()
                    .map(|(n, _)| Arc::from(n.name.as_str()))
                    .collect();
                let terms = sorted
                    .iter()
                    .map(|(_, x)| self.expr(x, env))
                    .collect::<R<Vec<_>>>()?;
                let f = Callee::Prim(Prim::Record(names.into()));
                self.apply_value_fn(f, terms, e.span)
            }
            ExprKind::Block { defs, result } => {
                let env = self.local_defs(defs, env);
                self.expr(result, &env)
            }
            ExprKind::Member { object, field } => {
                // `Foo.Bar.x` where `Foo` is not a value in scope: a module member.
                if let Some(path) = object.dotted_path()
                    && self
                        .binding(path.split('.').next().unwrap_or_default(), env)
                        .is_none()
                {
                    let q = format!("{path}.{}", field.name);
                    return self.lookup(&q, e.span, env);
                }
                if let Some(r) = self.literal_member(object, &field.name, env) {
                    return r;
                }
                let obj = self.expr(object, env)?;
                let f = Callee::Prim(Prim::Member(field.name.as_str().into()));
                self.apply_value_fn(f, vec![obj], e.span)
            }
            ExprKind::Unary { op, operand } => {
                let t = self.expr(operand, env)?;
                let op = UnaryOp::from(*op);
                let r = self.apply_value_fn(Callee::Prim(Prim::Unary(op)), vec![t], e.span)?;
                Ok(r)
            }
            ExprKind::Binary { op, lhs, rhs } => {
                let a = self.expr(lhs, env)?;
                let b = self.expr(rhs, env)?;
                let op = BinOp::from(*op);
                if matches!(op, BinOp::And | BinOp::Or) {
                    // Lazy: the right side is not evaluated when the left decides.
                    if let Term::Code(_) | Term::Const(_) = a
                        && let Term::Code(_) | Term::Const(_) = b
                        && !matches!((&a, &b), (Term::Const(_), Term::Const(_)))
                    {
                        let (fa, fb) = (self.as_code(a), self.as_code(b));
                        return Ok(Term::Code(Code::Logic {
                            and: op == BinOp::And,
                            args: Arc::new([fa, fb]),
                        }));
                    }
                }
                let r = self.apply_value_fn(Callee::Prim(Prim::Binary(op)), vec![a, b], e.span)?;
                if let Some(sop) = scalar_op(op) {
                    self.inline_op(&r, |args, _| match args {
                        [a, b] => Some(Node::Bin {
                            op: sop,
                            a: a.clone(),
                            b: b.clone(),
                            bop: op,
                        }),
                        _ => None,
                    });
                }
                Ok(r)
            }
            ExprKind::If {
                cond,
                then_branch,
                else_branch,
                ..
            } => {
                let c = self.expr(cond, env)?;
                if let Term::Const(v) = &c {
                    return match v {
                        Value::Bool(true) => self.expr(then_branch, env),
                        Value::Bool(false) => self.expr(else_branch, env),
                        // The checker owns "the condition is a Bool"; a constant of another
                        // value here is the value of an `extern` this engine does not know (an
                        // error value), whose declared type the checker trusts.
                        _ => self.error(
                            Category::Type,
                            cond.span,
                            "the condition of `if` must be a Bool",
                        ),
                    };
                }
                let t = self.expr(then_branch, env)?;
                let f = self.expr(else_branch, env)?;
                if let Term::Code(_) = c
                    && !matches!(t, Term::Stream(_) | Term::Func(_))
                    && !matches!(f, Term::Stream(_) | Term::Func(_))
                {
                    let (fc, ft, ff) = (self.as_code(c), self.as_code(t), self.as_code(f));
                    return Ok(Term::Code(Code::If(Arc::new([fc, ft, ff]))));
                }
                let ite = Callee::Prim(Prim::Ite);
                let r = self.apply_value_fn(ite, vec![c, t, f], e.span)?;
                self.inline_op(&r, |args, _| match args {
                    [c, t, f] => Some(Node::Ite {
                        cond: c.clone(),
                        then: t.clone(),
                        other: f.clone(),
                    }),
                    _ => None,
                });
                Ok(r)
            }
            ExprKind::Lambda { params, body } => Ok(Term::Func(Rc::new(FuncTerm::Lambda {
                params: params.clone(),
                body: Rc::new((**body).clone()),
                env: env.clone(),
            }))),
            ExprKind::Call { function, args, .. } => {
                let f = self.expr(function, env)?;
                let Some(args) = args else {
                    return Ok(f);
                };
                // `last` and `delay`: the first argument is lazy (may refer back recursively).
                let lazy_first = matches!(&f, Term::Func(ft) if matches!(&**ft, FuncTerm::Builtin(b, _) if b.lazy == [0]));
                let mut terms = Vec::with_capacity(args.len());
                for (i, a) in args.iter().enumerate() {
                    if lazy_first && i == 0 {
                        self.depth.lazy_depth += 1;
                        let r = self.expr(&a.value, env);
                        self.depth.lazy_depth -= 1;
                        terms.push(r?);
                    } else {
                        terms.push(self.expr(&a.value, env)?);
                    }
                }
                let terms = if args.iter().any(|a| a.name.is_some()) {
                    let callee = function
                        .dotted_path()
                        .unwrap_or_else(|| "the function".into());
                    self.order_named_args(&f, args, terms, &callee, e.span)?
                } else {
                    terms
                };
                self.call(f, terms, e.span, env)
            }
        }
    }
}

impl From<ast::BinOp> for BinOp {
    /// The IR's operator for the syntax's (the same operator: one variant each).
    fn from(op: ast::BinOp) -> BinOp {
        use ast::BinOp as S;
        match op {
            S::Mul => BinOp::Mul,
            S::Div => BinOp::Div,
            S::Mod => BinOp::Mod,
            S::FMul => BinOp::FMul,
            S::FDiv => BinOp::FDiv,
            S::Add => BinOp::Add,
            S::Sub => BinOp::Sub,
            S::FAdd => BinOp::FAdd,
            S::FSub => BinOp::FSub,
            S::Shl => BinOp::Shl,
            S::Shr => BinOp::Shr,
            S::BitAnd => BinOp::BitAnd,
            S::BitOr => BinOp::BitOr,
            S::BitXor => BinOp::BitXor,
            S::Eq => BinOp::Eq,
            S::Ne => BinOp::Ne,
            S::Lt => BinOp::Lt,
            S::Gt => BinOp::Gt,
            S::Le => BinOp::Le,
            S::Ge => BinOp::Ge,
            S::FLt => BinOp::FLt,
            S::FGt => BinOp::FGt,
            S::FLe => BinOp::FLe,
            S::FGe => BinOp::FGe,
            S::And => BinOp::And,
            S::Or => BinOp::Or,
        }
    }
}

impl From<ast::UnaryOp> for UnaryOp {
    /// The IR's operator for the syntax's.
    fn from(op: ast::UnaryOp) -> UnaryOp {
        match op {
            ast::UnaryOp::Not => UnaryOp::Not,
            ast::UnaryOp::BitNot => UnaryOp::BitNot,
            ast::UnaryOp::Neg => UnaryOp::Neg,
            ast::UnaryOp::FNeg => UnaryOp::FNeg,
        }
    }
}
