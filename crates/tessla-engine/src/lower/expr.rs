//! Expressions: every syntax form to a [`Term`] (literals, time literals, format strings,
//! operators with their inline scalar nodes, `if`, records, tuples, member access, lambdas,
//! blocks).
//!
//! Owns: `Compiler::expr`, the operator closures (`binop_fn`, semantics in `crate::ops`) and the
//! inline nodes of operators (`inline_op`, `slift_node`).

use super::*;

impl Compiler<'_> {
    /// Replace the signal lift just made for `t` by a node the evaluator runs inline (a typed
    /// fast path: no closure call, no argument copies).
    pub(super) fn inline_op(
        &mut self,
        t: &Term,
        make: impl FnOnce(&[SArg], &Func) -> Option<Node>,
    ) {
        if let Term::Stream(n) = t
            && let Some(Node::SLift { args, f }) = self.nodes.get(*n)
            && let Some(node) = make(args, f)
            && let Some(slot) = self.nodes.get_mut(*n)
        {
            *slot = node;
        }
    }

    pub(super) fn slift_node(&mut self, args: Vec<SArg>, f: Func) -> NodeId {
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
                    Some(u) if !self.time_units => {
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
                        let unit_fs = self.base_unit.unwrap_or(self.base_ns);
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
                        let r = fs / unit_fs / (self.base_ns / unit_fs).max(1);
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
                            let fmt = format.clone();
                            let f: Func = Arc::new(move |a: &[Value]| match (&fmt, a.first()) {
                                (Some(spec), Some(v)) => Value::Str(format_value(spec, v).into()),
                                (None, Some(v)) => Value::Str(v.to_string().into()),
                                _ => Value::Unit,
                            });
                            terms.push(self.apply_value_fn(f, vec![t], e.span)?);
                        }
                    }
                }
                if terms.len() == 1 {
                    return Ok(terms.remove(0));
                }
                let concat: Func = Arc::new(|a: &[Value]| {
                    if let Some(err) = a.iter().find_map(is_err) {
                        return err;
                    }
                    let mut s = String::new();
                    for v in a {
                        s.push_str(&v.to_string());
                    }
                    Value::Str(s.into())
                });
                self.apply_value_fn(concat, terms, e.span)
            }
            ExprKind::Tuple(es) if es.is_empty() => Ok(Term::Const(Value::Unit)),
            ExprKind::Tuple(es) => {
                let terms = es
                    .iter()
                    .map(|x| self.expr(x, env))
                    .collect::<R<Vec<_>>>()?;
                let f: Func = Arc::new(|a: &[Value]| Value::Tuple(a.to_vec().into()));
                self.apply_value_fn(f, terms, e.span)
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
                let f: Func = Arc::new(move |a: &[Value]| {
                    Value::Record(
                        names
                            .iter()
                            .cloned()
                            .zip(a.iter().cloned())
                            .collect::<Vec<_>>()
                            .into(),
                    )
                });
                self.apply_value_fn(f, terms, e.span)
            }
            ExprKind::Block { defs, result } => {
                let env = self.local_defs(defs, env);
                self.expr(result, &env)
            }
            ExprKind::Member { object, field } => {
                // `Foo.Bar.x` where `Foo` is not a value in scope: a module member.
                if let Some(path) = dotted_path(object)
                    && env
                        .lookup(path.split('.').next().unwrap_or_default())
                        .is_none()
                {
                    let q = format!("{path}.{}", field.name);
                    return self.lookup(&q, e.span, env);
                }
                if let Some(r) = self.literal_member(object, &field.name, env) {
                    return r;
                }
                let obj = self.expr(object, env)?;
                let fname: Arc<str> = field.name.as_str().into();
                let f: Func = Arc::new(move |a: &[Value]| match a.first() {
                    Some(Value::Record(r)) => r
                        .iter()
                        .find(|(k, _)| *k == fname)
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
                });
                self.apply_value_fn(f, vec![obj], e.span)
            }
            ExprKind::Unary { op, operand } => {
                let t = self.expr(operand, env)?;
                let op = *op;
                let ty = match op {
                    UnaryOp::Not => Type::Bool,
                    UnaryOp::FNeg => Type::Float,
                    UnaryOp::Neg | UnaryOp::BitNot => Type::Int,
                };
                let f: Func = Arc::new(move |a: &[Value]| unop(op, &a[0]));
                let r = self.apply_value_fn(f, vec![t], e.span)?;
                Ok(self.typed(r, ty))
            }
            ExprKind::Binary { op, lhs, rhs } => {
                let a = self.expr(lhs, env)?;
                let b = self.expr(rhs, env)?;
                let op = *op;
                let int_op = matches!(
                    op,
                    BinOp::Add
                        | BinOp::Sub
                        | BinOp::Mul
                        | BinOp::Div
                        | BinOp::Mod
                        | BinOp::Lt
                        | BinOp::Gt
                        | BinOp::Le
                        | BinOp::Ge
                );
                let is_float = |c: &Compiler<'_>, t: &Term| match t {
                    Term::Const(Value::Float(_)) => true,
                    Term::Stream(n) => c.stream_type(*n) == Type::Float,
                    _ => false,
                };
                if int_op && (is_float(self, &a) || is_float(self, &b)) {
                    self.diags.push(
                        Diagnostic::error(
                            Category::Type,
                            Some(e.span),
                            format!("`{}` is not defined for Float in TeSSLa 1.2", op.symbol()),
                        )
                        .with_label("a Float operand")
                        .with_help(format!("use `{}.` for Float", op.symbol())),
                    );
                    return Err(Fail);
                }
                if matches!(op, BinOp::And | BinOp::Or) {
                    // Lazy: the right side is not evaluated when the left decides.
                    if let Term::Dyn(_) | Term::Const(_) = a
                        && let Term::Dyn(_) | Term::Const(_) = b
                        && !matches!((&a, &b), (Term::Const(_), Term::Const(_)))
                    {
                        let (fa, fb) = (self.as_dyn(a), self.as_dyn(b));
                        let is_and = op == BinOp::And;
                        return Ok(Term::Dyn(Arc::new(move |fr: &[Value]| match fa(fr) {
                            Value::Bool(x) if x != is_and => Value::Bool(x),
                            Value::Bool(_) => fb(fr),
                            other => other,
                        })));
                    }
                }
                let ty = match op {
                    BinOp::FAdd | BinOp::FSub | BinOp::FMul | BinOp::FDiv => Type::Float,
                    BinOp::Add => match (&a, &b) {
                        (Term::Stream(n), _) | (_, Term::Stream(n)) => self.stream_type(*n),
                        _ => Type::Unknown,
                    },
                    BinOp::Sub
                    | BinOp::Mul
                    | BinOp::Div
                    | BinOp::Mod
                    | BinOp::Shl
                    | BinOp::Shr
                    | BinOp::BitAnd
                    | BinOp::BitOr
                    | BinOp::BitXor => Type::Int,
                    _ => Type::Bool,
                };
                let r = self.apply_value_fn(binop_fn(op), vec![a, b], e.span)?;
                if let Some(sop) = scalar_op(op) {
                    self.inline_op(&r, |args, f| match args {
                        [a, b] => Some(Node::Bin {
                            op: sop,
                            a: a.clone(),
                            b: b.clone(),
                            f: f.clone(),
                        }),
                        _ => None,
                    });
                }
                Ok(self.typed(r, ty))
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
                        _ => self.error(
                            Category::Type,
                            cond.span,
                            "the condition of `if` must be a Bool",
                        ),
                    };
                }
                let t = self.expr(then_branch, env)?;
                let f = self.expr(else_branch, env)?;
                if let Term::Dyn(_) = c
                    && !matches!(t, Term::Stream(_) | Term::Func(_))
                    && !matches!(f, Term::Stream(_) | Term::Func(_))
                {
                    let (fc, ft, ff) = (self.as_dyn(c), self.as_dyn(t), self.as_dyn(f));
                    return Ok(Term::Dyn(Arc::new(move |fr: &[Value]| match fc(fr) {
                        Value::Bool(true) => ft(fr),
                        Value::Bool(false) => ff(fr),
                        other => other,
                    })));
                }
                let ite: Func = Arc::new(|v: &[Value]| match &v[0] {
                    Value::Bool(true) => v[1].clone(),
                    Value::Bool(false) => v[2].clone(),
                    other => other.clone(),
                });
                let ty = match (&t, &f) {
                    (Term::Stream(n), _) | (_, Term::Stream(n)) => self.stream_type(*n),
                    (Term::Const(v), _) => value_type(v),
                    _ => Type::Unknown,
                };
                let r = self.apply_value_fn(ite, vec![c, t, f], e.span)?;
                self.inline_op(&r, |args, _| match args {
                    [c, t, f] => Some(Node::Ite {
                        cond: c.clone(),
                        then: t.clone(),
                        other: f.clone(),
                    }),
                    _ => None,
                });
                Ok(self.typed(r, ty))
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
                        self.lazy_depth += 1;
                        let r = self.expr(&a.value, env);
                        self.lazy_depth -= 1;
                        terms.push(r?);
                    } else {
                        terms.push(self.expr(&a.value, env)?);
                    }
                }
                let terms = self.order_named_args(&f, args, terms, e.span)?;
                self.call(f, terms, e.span, env)
            }
        }
    }
}

pub(super) fn binop(op: BinOp, a: &Value, b: &Value) -> Value {
    ops::binary_value(op, a, b)
}

/// The closure of a binary operator, with the inline scalar path for its usual operand types
/// ([`ScalarOp::eval`], as the evaluator's `Bin` nodes use it) before the general one.
pub(super) fn binop_fn(op: BinOp) -> Func {
    let two = || Value::Error(RuntimeError::Other("an operator needs two operands".into()));
    match scalar_op(op) {
        Some(sop) => Arc::new(move |v: &[Value]| match v {
            [a, b] => match (Scalar::of(a), Scalar::of(b)) {
                (Some(x), Some(y)) => match sop.eval(x, y) {
                    Some(r) => r.value(),
                    None => binop(op, a, b),
                },
                _ => binop(op, a, b),
            },
            _ => two(),
        }),
        None => Arc::new(move |v: &[Value]| match v {
            [a, b] => binop(op, a, b),
            _ => two(),
        }),
    }
}

pub(super) fn unop(op: UnaryOp, a: &Value) -> Value {
    ops::unary_value(op, a)
}

/// `a.b.c` as the string "a.b.c" when the expression is only names and member accesses.
pub(super) fn dotted_path(e: &Expr) -> Option<String> {
    match &e.kind {
        ExprKind::Var(id) => Some(id.name.clone()),
        ExprKind::Member { object, field } => {
            dotted_path(object).map(|p| format!("{p}.{}", field.name))
        }
        _ => None,
    }
}
