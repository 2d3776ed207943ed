//! Types during inference and their unification: [`Ty`] (variables, constructors, functions,
//! records; a tuple is the record of `_1` to `_n`), generalised [`Scheme`]s, the substitution
//! (`fresh`, `shallow`, `resolve`), unification *modulo `Events`* (`unify`: a stream `Events[T]`
//! fits wherever a `T` is expected and the other way round, TeSSLa's signal lift, constants as
//! streams and macro expansion in one rule), the mismatch report with its fixes (`expect`),
//! the signal lift of a result (`lifted`), and a resolved type as an IR type for the lowering
//! (`element_type`, `ir_type_of`) or as text for messages (`show`).

use super::*;

/// A type during inference.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Ty {
    Var(u32),
    /// `Int`, `Float`, `Bool`, `String`, `Unit`, `Option[T]`, `List[T]`, `Set[T]`, `Map[K, V]`,
    /// `Events[T]`.
    Con(&'static str, Vec<Ty>),
    Fn(Vec<Ty>, Box<Ty>),
    /// Fields sorted by name.
    Record(Vec<(String, Ty)>),
}

pub(super) fn con(n: &'static str) -> Ty {
    Ty::Con(n, Vec::new())
}
pub(super) fn int() -> Ty {
    con("Int")
}
pub(super) fn float() -> Ty {
    con("Float")
}
pub(super) fn boolean() -> Ty {
    con("Bool")
}
pub(super) fn string() -> Ty {
    con("String")
}
pub(super) fn unit() -> Ty {
    con("Unit")
}
pub(super) fn ev(t: Ty) -> Ty {
    Ty::Con("Events", vec![t])
}
pub(super) fn opt(t: Ty) -> Ty {
    Ty::Con("Option", vec![t])
}
pub(super) fn list(t: Ty) -> Ty {
    Ty::Con("List", vec![t])
}
pub(super) fn set(t: Ty) -> Ty {
    Ty::Con("Set", vec![t])
}
pub(super) fn map(k: Ty, v: Ty) -> Ty {
    Ty::Con("Map", vec![k, v])
}
/// A tuple is the record with fields `_1` to `_n` (TeSSLa: `(a, b)` is `{_1 = a, _2 = b}`).
pub(super) fn tuple(ts: Vec<Ty>) -> Ty {
    let mut fs: Vec<(String, Ty)> = ts
        .into_iter()
        .enumerate()
        .map(|(i, t)| (format!("_{}", i + 1), t))
        .collect();
    fs.sort_by(|a, b| a.0.cmp(&b.0));
    Ty::Record(fs)
}

pub(super) fn func(ps: Vec<Ty>, r: Ty) -> Ty {
    Ty::Fn(ps, Box::new(r))
}

/// A generalised type: `vars` are instantiated afresh at each use.
#[derive(Clone, Debug)]
pub(super) struct Scheme {
    pub(super) vars: Vec<u32>,
    pub(super) ty: Ty,
}

/// The element type of a stream (`T` of `Events[T]`; a constant is its own) as an IR type.
pub(super) fn element_type(t: &Ty) -> Type {
    match t {
        Ty::Con("Events", args) => args.first().map_or(Type::Unknown, ir_type_of),
        other => ir_type_of(other),
    }
}

/// A resolved checker type as an IR type; what the IR cannot name (`Set`, `Map`, functions,
/// open variables) is [`Type::Unknown`]. A stream inside a value type (`List[Events[Int]]`) is
/// an artifact of unifying modulo `Events` (values never hold streams): its element type.
pub(super) fn ir_type_of(t: &Ty) -> Type {
    let inner = |args: &[Ty]| Box::new(args.first().map_or(Type::Unknown, element_type));
    match t {
        Ty::Con("Unit", _) => Type::Unit,
        Ty::Con("Bool", _) => Type::Bool,
        Ty::Con("Int", _) => Type::Int,
        Ty::Con("Float", _) => Type::Float,
        Ty::Con("String", _) => Type::String,
        Ty::Con("Option", args) => Type::Option(inner(args)),
        Ty::Con("List", args) => Type::List(inner(args)),
        Ty::Con("Events", args) => Type::Events(inner(args)),
        Ty::Record(fs)
            if !fs.is_empty()
                && fs
                    .iter()
                    .enumerate()
                    .all(|(i, (n, _))| n.strip_prefix('_') == Some(&(i + 1).to_string())) =>
        {
            Type::Tuple(fs.iter().map(|(_, t)| element_type(t)).collect())
        }
        Ty::Record(fs) if !fs.is_empty() => Type::Record(
            fs.iter()
                .map(|(n, t)| (n.clone(), element_type(t)))
                .collect(),
        ),
        _ => Type::Unknown,
    }
}

pub(super) fn collect_vars(t: &Ty, out: &mut Vec<u32>) {
    match t {
        Ty::Var(v) => {
            if !out.contains(v) {
                out.push(*v);
            }
        }
        Ty::Con(_, args) => args.iter().for_each(|a| collect_vars(a, out)),
        Ty::Fn(ps, r) => {
            ps.iter().for_each(|a| collect_vars(a, out));
            collect_vars(r, out);
        }
        Ty::Record(fs) => fs.iter().for_each(|(_, a)| collect_vars(a, out)),
    }
}

pub(super) fn substitute(t: &Ty, map: &HashMap<u32, Ty>) -> Ty {
    let s = |x: &Ty| substitute(x, map);
    match t {
        Ty::Var(v) => map.get(v).cloned().unwrap_or_else(|| t.clone()),
        Ty::Con(n, args) => Ty::Con(n, args.iter().map(s).collect()),
        Ty::Fn(ps, r) => Ty::Fn(ps.iter().map(s).collect(), Box::new(s(r))),
        Ty::Record(fs) => Ty::Record(fs.iter().map(|(n, t)| (n.clone(), s(t))).collect()),
    }
}

/// TeSSLa's notation of a type; unknown parts print as `?`.
pub(super) fn show(t: &Ty) -> String {
    match t {
        Ty::Var(_) => "?".into(),
        Ty::Con(n, args) if args.is_empty() => (*n).into(),
        Ty::Con(n, args) => format!(
            "{n}[{}]",
            args.iter().map(show).collect::<Vec<_>>().join(", ")
        ),
        Ty::Fn(ps, r) => format!(
            "({}) => {}",
            ps.iter().map(show).collect::<Vec<_>>().join(", "),
            show(r)
        ),
        Ty::Record(fs)
            if fs
                .iter()
                .enumerate()
                .all(|(i, (n, _))| n.strip_prefix('_') == Some(&(i + 1).to_string())) =>
        {
            format!(
                "({})",
                fs.iter()
                    .map(|(_, t)| show(t))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        }
        Ty::Record(fs) => format!(
            "{{{}}}",
            fs.iter()
                .map(|(n, t)| format!("{n}: {}", show(t)))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

impl<'a> Checker<'a> {
    pub(super) fn fresh(&mut self) -> Ty {
        self.subst.push(None);
        Ty::Var((self.subst.len() - 1) as u32)
    }

    /// Follow variable bindings at the top of `t`.
    pub(super) fn shallow(&self, t: &Ty) -> Ty {
        let mut t = t.clone();
        while let Ty::Var(v) = t {
            match self.subst.get(v as usize).and_then(Clone::clone) {
                Some(b) => t = b,
                None => break,
            }
        }
        t
    }

    /// `t` with every bound variable replaced (bounded depth: types are small).
    pub(super) fn resolve(&self, t: &Ty) -> Ty {
        self.resolve_depth(t, 0)
    }

    pub(super) fn resolve_depth(&self, t: &Ty, depth: u32) -> Ty {
        let t = self.shallow(t);
        if depth > 64 {
            return t;
        }
        let r = |x: &Ty| self.resolve_depth(x, depth + 1);
        match t {
            Ty::Var(_) => t,
            Ty::Con(n, args) => Ty::Con(n, args.iter().map(r).collect()),
            Ty::Fn(ps, ret) => Ty::Fn(ps.iter().map(r).collect(), Box::new(r(&ret))),
            Ty::Record(fs) => Ty::Record(fs.iter().map(|(n, t)| (n.clone(), r(t))).collect()),
        }
    }

    pub(super) fn occurs(&self, v: u32, t: &Ty) -> bool {
        match self.resolve(t) {
            Ty::Var(w) => v == w,
            Ty::Con(_, args) => args.iter().any(|a| self.occurs(v, a)),
            Ty::Fn(ps, r) => ps.iter().any(|a| self.occurs(v, a)) || self.occurs(v, &r),
            Ty::Record(fs) => fs.iter().any(|(_, a)| self.occurs(v, a)),
        }
    }

    /// Unify modulo `Events`: `Events[T]` and `T` fit each other (signal lift, constants as
    /// streams, macro expansion).
    pub(super) fn unify(&mut self, a: &Ty, b: &Ty) -> Result<(), ()> {
        let (a, b) = (self.shallow(a), self.shallow(b));
        match (&a, &b) {
            (Ty::Var(x), Ty::Var(y)) if x == y => Ok(()),
            (Ty::Var(x), t) | (t, Ty::Var(x)) => {
                // A cyclic type only comes from recursion through `last`; let it pass.
                if !self.occurs(*x, t)
                    && let Some(slot) = self.subst.get_mut(*x as usize)
                {
                    *slot = Some(t.clone());
                }
                Ok(())
            }
            (Ty::Con("Events", x), Ty::Con("Events", y)) => match (x.first(), y.first()) {
                (Some(x), Some(y)) => self.unify(x, y),
                _ => Ok(()),
            },
            (Ty::Con("Events", x), t) | (t, Ty::Con("Events", x)) => match x.first() {
                Some(x) => {
                    let x = x.clone();
                    self.unify(&x, t)
                }
                None => Ok(()),
            },
            (Ty::Con(n, xs), Ty::Con(m, ys)) => {
                if n != m || xs.len() != ys.len() {
                    return Err(());
                }
                for (x, y) in xs.iter().zip(ys) {
                    self.unify(x, y)?;
                }
                Ok(())
            }
            (Ty::Record(xs), Ty::Record(ys)) if xs.len() == ys.len() => {
                for ((n, x), (m, y)) in xs.iter().zip(ys) {
                    if n != m {
                        return Err(());
                    }
                    self.unify(x, y)?;
                }
                Ok(())
            }
            (Ty::Fn(ps, r), Ty::Fn(qs, s)) if ps.len() == qs.len() => {
                for (x, y) in ps.iter().zip(qs) {
                    self.unify(x, y)?;
                }
                self.unify(r, s)
            }
            _ => Err(()),
        }
    }

    /// Unify `found` (of the expression at `span`) with `expected`; report a mismatch with a fix
    /// where one is known.
    pub(super) fn expect(&mut self, expected: &Ty, found: &Ty, span: Span, what: &str) -> bool {
        if self.unify(expected, found).is_ok() {
            return true;
        }
        let (e, f) = (self.resolve(expected), self.resolve(found));
        let (es, fs) = (show(&e), show(&f));
        let mut d = Diagnostic::error(
            Category::Type,
            Some(span),
            format!("{what}: expected {es}, found {fs}"),
        )
        .with_label(format!("this is {fs}"));
        let base = |t: &Ty| match t {
            Ty::Con("Events", a) => a.first().cloned().unwrap_or(Ty::Var(0)),
            t => t.clone(),
        };
        match (base(&e), base(&f)) {
            (Ty::Con("Float", _), Ty::Con("Int", _)) => {
                d = d.with_help("write a Float literal (`1.0`) or convert with `intToFloat(...)`");
            }
            (Ty::Con("Int", _), Ty::Con("Float", _)) => {
                d = d
                    .with_help("convert with `floatToInt(...)`, or use the dotted Float operators");
            }
            (Ty::Fn(ps, _), Ty::Fn(qs, _)) if ps.len() != qs.len() => {
                d = d.with_help(format!(
                    "a function of {} arguments is expected; this one takes {} arguments",
                    ps.len(),
                    qs.len()
                ));
            }
            (Ty::Con("String", _), _) => {
                d = d.with_help("convert with `toString(...)`");
            }
            _ => {}
        }
        self.report(d);
        false
    }

    pub(super) fn generalize(&self, t: &Ty) -> Scheme {
        let ty = self.resolve(t);
        let mut vars = Vec::new();
        collect_vars(&ty, &mut vars);
        Scheme { vars, ty }
    }

    pub(super) fn instantiate(&mut self, s: &Scheme) -> Ty {
        if s.vars.is_empty() {
            return s.ty.clone();
        }
        let map: HashMap<u32, Ty> = s.vars.iter().map(|v| (*v, self.fresh())).collect();
        substitute(&s.ty, &map)
    }

    /// Is `t` (resolved) a stream?
    pub(super) fn is_stream(&self, t: &Ty) -> bool {
        matches!(self.shallow(t), Ty::Con("Events", _))
    }

    /// The result of an operator or lifted function: a stream if any argument is one.
    pub(super) fn lifted(&self, args: &[Ty], r: Ty) -> Ty {
        if args.iter().any(|a| self.is_stream(a)) && !self.is_stream(&r) {
            ev(r)
        } else {
            r
        }
    }

    /// The element type of a stream type, else the type itself.
    pub(super) fn strip(&self, t: &Ty) -> Ty {
        match self.shallow(t) {
            Ty::Con("Events", a) => a.first().cloned().unwrap_or_else(|| t.clone()),
            other => other,
        }
    }

    pub(super) fn base_is(&self, t: &Ty, name: &str) -> bool {
        matches!(self.shallow(&self.strip(t)), Ty::Con(n, _) if n == name)
    }
}
