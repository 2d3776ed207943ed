//! TeSSLa's objects as outputs: `out o` where `o` is a record or tuple literal (or a definition
//! whose body is one) with a stream among its members prints one output per member, named by its
//! path (`o.a.b`, `o.e`), as TeSSLa's interpreter does; constant members print once, at 0, and a
//! member record of constants (`{d = 34}`) prints as one value.
//!
//! Owns: `Compiler::object_output`. Records are otherwise lowered as streams of records (the
//! fields signal-lifted), which is what every other use of such a record sees.

use super::*;

/// A member: an object (its members by path) or one term.
enum Part {
    Fields(Vec<(String, Term)>),
    One(Term),
}

/// How deep definitions and nested records are followed.
const MAX_DEPTH: usize = 32;

impl Compiler<'_> {
    /// The members of the object `e` stands for, by path; `None` when `e` is not an object
    /// (not a record literal, or one of constants only); `Some(Err)` when lowering a member
    /// failed (reported).
    pub(super) fn object_output(&mut self, e: &Expr, env: &Env) -> Option<R<Vec<(String, Term)>>> {
        let (members, menv) = self.record_literal(e, env, 0)?;
        match self.object_parts((e, env), &members, &menv, 0) {
            Ok(Part::Fields(fs)) => Some(Ok(fs)),
            Ok(Part::One(_)) => None,
            Err(f) => Some(Err(f)),
        }
    }

    /// The parts of the record literal `whole` (read in its scope) with `members` (read in `env`).
    fn object_parts(
        &mut self,
        whole: (&Expr, &Env),
        members: &[(String, Expr)],
        env: &Env,
        depth: usize,
    ) -> R<Part> {
        let mut parts: Vec<(String, Term)> = Vec::new();
        let mut object = false;
        for (name, x) in members {
            let part = match self.record_literal(x, env, 0).filter(|_| depth < MAX_DEPTH) {
                Some((inner, ienv)) => self.object_parts((x, env), &inner, &ienv, depth + 1)?,
                None => Part::One(self.expr(x, env)?),
            };
            match part {
                Part::Fields(fs) => {
                    object = true;
                    parts.extend(fs.into_iter().map(|(p, t)| (format!("{name}.{p}"), t)));
                }
                Part::One(t) => {
                    object |= matches!(t, Term::Stream(_));
                    parts.push((name.clone(), t));
                }
            }
        }
        if object {
            return Ok(Part::Fields(parts));
        }
        // Constants only: one value (a tuple's members in order; a record's fields sorted by
        // name, as `Value::Record` keeps them).
        if matches!(whole.0.kind, ExprKind::Tuple(_)) {
            let mut items = Vec::with_capacity(parts.len());
            for (_, t) in parts {
                match t {
                    Term::Const(v) => items.push(v),
                    _ => return Ok(Part::One(self.expr(whole.0, whole.1)?)),
                }
            }
            return Ok(Part::One(Term::Const(Value::Tuple(items.into()))));
        }
        let mut fields: Vec<(Arc<str>, Value)> = Vec::with_capacity(parts.len());
        for (name, t) in parts {
            match t {
                Term::Const(v) => fields.push((Arc::from(name.as_str()), v)),
                // Not a plain value (a function member ...): lowered as usual.
                _ => return Ok(Part::One(self.expr(whole.0, whole.1)?)),
            }
        }
        fields.sort_by(|a, b| a.0.cmp(&b.0));
        Ok(Part::One(Term::Const(Value::Record(fields.into()))))
    }
}

impl Compiler<'_> {
    /// The members of the record literal `e` is, directly or as the body of a definition without
    /// parameters, with the scope they are read in.
    fn record_literal(
        &mut self,
        e: &Expr,
        env: &Env,
        depth: usize,
    ) -> Option<(Vec<(String, Expr)>, Env)> {
        if depth > MAX_DEPTH {
            return None;
        }
        match &e.kind {
            ExprKind::Record(ms) => Some((
                ms.iter()
                    .map(|(n, x)| (n.name.clone(), x.clone()))
                    .collect(),
                env.clone(),
            )),
            // A tuple is the record of its members `_1`, `_2`, ...
            ExprKind::Tuple(xs) if xs.len() > 1 => Some((
                xs.iter()
                    .enumerate()
                    .map(|(i, x)| (format!("_{}", i + 1), x.clone()))
                    .collect(),
                env.clone(),
            )),
            // A member of a literal that is itself a literal (`o.a` with `o = {a = {b = x}}`).
            ExprKind::Member { object, field } => {
                let (members, menv) = self.record_literal(object, env, depth + 1)?;
                let (_, x) = members.into_iter().find(|(n, _)| *n == field.name)?;
                self.record_literal(&x, &menv, depth + 1)
            }
            ExprKind::Var(id) => match self.binding(&id.name, env) {
                Some(Binding::Def(entry)) if entry.def.params.is_none() => match &entry.def.body {
                    Body::Expr { expr, where_defs } if where_defs.is_empty() => {
                        let denv = entry.env_cell.borrow().clone()?;
                        self.record_literal(expr, &denv, depth + 1)
                    }
                    _ => None,
                },
                _ => None,
            },
            _ => None,
        }
    }
}

thread_local! {
    /// How many member projections are being lowered inside each other (a guard against
    /// `def x = (x._2, x._1)`, which then takes the ordinary path and its recursion error).
    static PROJECTING: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

impl Compiler<'_> {
    /// `o.f` where `o` is a record or tuple literal, or a definition whose body is one: the
    /// member's own expression, lowered in its scope (TeSSLa's objects: the member is that
    /// stream, and `def x = (v, x._1)` is well-founded). `None`: not such a member.
    pub(super) fn literal_member(
        &mut self,
        object: &Expr,
        field: &str,
        env: &Env,
    ) -> Option<R<Term>> {
        let (members, menv) = self.record_literal(object, env, 0)?;
        let (_, x) = members.into_iter().find(|(n, _)| n == field)?;
        let depth = PROJECTING.with(|p| p.get());
        if depth >= MAX_DEPTH {
            return None;
        }
        PROJECTING.with(|p| p.set(depth + 1));
        let r = self.expr(&x, &menv);
        PROJECTING.with(|p| p.set(depth));
        Some(r)
    }
}
