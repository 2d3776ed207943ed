//! Builtin signatures, from the builtins table (`crate::builtins`): a fixed signature in TeSSLa's
//! notation is parsed once (`template`), a variadic one is built per call from its shape
//! (`variadic`), and a builtin without one is typed by its declaration in the bundled prelude
//! (`declared_signature`). Also the hints for library functions given a wrong argument.

use super::*;

/// The help for a library function given an argument of the wrong type: how to write it for
/// the type at hand.
pub(super) fn library_hint(name: &str) -> Option<&'static str> {
    Some(match name {
        "sum" => {
            "`sum` is TeSSLa's `def sum(x: Events[Int]): Events[Int]`; for a Float stream \
             write it with `fold`: `fold(x, 0.0, (acc: Float, v: Float) => acc +. v)`"
        }
        "maximum" | "minimum" => {
            "`maximum` and `minimum` are declared for Events[Int]; for a Float stream use \
             `reduce(x, (a: Float, b: Float) => if a >. b then a else b)` (`<.` for the minimum)"
        }
        "average" => {
            "`average` is declared for Events[Int]; for a Float stream divide a `fold` sum \
             by `count(x)`"
        }
        _ => return None,
    })
}

/// Is `name` a builtin a spec may name (directly or by its prelude alias)? `extern`-only
/// natives are not.
pub(super) fn is_builtin_name(name: &str) -> bool {
    let name = crate::front::prelude::builtin_alias(name).unwrap_or(name);
    builtins::get(name).is_some_and(|b| !matches!(b.kind, builtins::Kind::Extern(_)))
}

/// Stand-ins for `A`/`K` and `B`/`V` in a parsed signature (never a checker variable: those
/// count up from 0).
pub(super) const TEMPLATE_VARS: [u32; 2] = [u32::MAX, u32::MAX - 1];

/// The parsed signature of a builtin with a fixed one, parsed once per process on first use.
pub(super) fn template(name: &'static str) -> Option<&'static Ty> {
    static TEMPLATES: OnceLock<HashMap<&'static str, OnceLock<Option<Ty>>>> = OnceLock::new();
    let cells = TEMPLATES.get_or_init(|| {
        builtins::BUILTINS
            .iter()
            .filter(|b| matches!(b.sig, Sig::Fixed(_)))
            .map(|b| (b.name, OnceLock::new()))
            .collect()
    });
    let Sig::Fixed(sig) = builtins::get(name)?.sig else {
        return None;
    };
    cells
        .get(name)?
        .get_or_init(|| signature(sig, &TEMPLATE_VARS.map(Ty::Var)))
        .as_ref()
}

/// `t` with the template variables replaced by `vars`.
pub(super) fn with_vars(t: &Ty, vars: &[Ty; 2]) -> Ty {
    let w = |x: &Ty| with_vars(x, vars);
    match t {
        Ty::Var(v) if *v == TEMPLATE_VARS[0] => vars[0].clone(),
        Ty::Var(v) if *v == TEMPLATE_VARS[1] => vars[1].clone(),
        Ty::Var(_) => t.clone(),
        Ty::Con(n, args) => Ty::Con(n, args.iter().map(w).collect()),
        Ty::Fn(ps, r) => Ty::Fn(ps.iter().map(w).collect(), Box::new(w(r))),
        Ty::Record(fs) => Ty::Record(fs.iter().map(|(n, t)| (n.clone(), w(t))).collect()),
    }
}

/// A type in TeSSLa's notation (`(Events[A], (B, A) => B) => Events[B]`) with `A`/`K` and
/// `B`/`V` standing for `vars`; `None` when it does not parse (a test parses every signature
/// of the builtins table).
pub(super) fn signature(sig: &'static str, vars: &[Ty; 2]) -> Option<Ty> {
    let mut p = SigParser { rest: sig, vars };
    let t = p.ty()?;
    p.rest.trim().is_empty().then_some(t)
}

pub(super) struct SigParser<'v> {
    rest: &'static str,
    vars: &'v [Ty; 2],
}

impl SigParser<'_> {
    fn eat(&mut self, tok: &str) -> bool {
        let r = self.rest.trim_start();
        match r.strip_prefix(tok) {
            Some(after) => {
                self.rest = after;
                true
            }
            None => {
                self.rest = r;
                false
            }
        }
    }

    /// Types separated by commas up to `close`.
    fn list(&mut self, close: &str) -> Option<Vec<Ty>> {
        let mut out = Vec::new();
        if self.eat(close) {
            return Some(out);
        }
        loop {
            out.push(self.ty()?);
            if self.eat(close) {
                return Some(out);
            }
            if !self.eat(",") {
                return None;
            }
        }
    }

    fn ty(&mut self) -> Option<Ty> {
        if self.eat("(") {
            let params = self.list(")")?;
            if !self.eat("=>") {
                // A tuple (`(String, Float)`) as a spec writes it; `()` is Unit, `(T)` is T.
                let mut params = params;
                return Some(match params.len() {
                    0 => unit(),
                    1 => params.pop()?,
                    _ => tuple(params),
                });
            }
            return Some(func(params, self.ty()?));
        }
        let r = self.rest.trim_start();
        let end = r
            .find(|c: char| !c.is_ascii_alphanumeric())
            .unwrap_or(r.len());
        let (name, after) = r.split_at(end);
        self.rest = after;
        let args = if self.eat("[") {
            self.list("]")?
        } else {
            Vec::new()
        };
        let mut args = args.into_iter();
        let mut arg = || args.next();
        Some(match name {
            "A" | "K" => self.vars[0].clone(),
            "B" | "V" => self.vars[1].clone(),
            "Int" => int(),
            "Float" => float(),
            "Bool" => boolean(),
            "String" => string(),
            "Unit" => unit(),
            "Events" => ev(arg()?),
            "Option" => opt(arg()?),
            "List" => list(arg()?),
            "Set" => set(arg()?),
            "Map" => map(arg()?, arg()?),
            _ => return None,
        })
    }
}

impl<'a> Checker<'a> {
    /// The signature of a variadic builtin (`lift3`, `merge`, `log`) for a call with `n`
    /// arguments, built from its shape in the builtins table.
    pub(super) fn variadic(&mut self, shape: &Variadic, n: usize) -> Option<Ty> {
        let k = match (shape.count, shape.function) {
            (Some(k), Some(_)) => k.min(n.saturating_sub(1)),
            (None, Some(_)) => n.saturating_sub(1),
            (Some(k), None) => k,
            (None, None) => n,
        }
        .clamp(shape.min, shape.max);
        let shared = self.fresh();
        let r = self.fresh();
        let mut ps = Vec::with_capacity(k + 1);
        let mut fps = Vec::new();
        for _ in 0..k {
            let a = if shape.shared {
                shared.clone()
            } else {
                self.fresh()
            };
            let vars = [a, r.clone()];
            ps.push(signature(shape.each, &vars)?);
            if let Some((p, _)) = shape.function {
                fps.push(signature(p, &vars)?);
            }
        }
        let vars = [shared, r];
        if let Some((_, fr)) = shape.function {
            ps.push(func(fps, signature(fr, &vars)?));
        }
        Some(func(ps, signature(shape.result, &vars)?))
    }

    /// The type of a builtin name, from its signature in the builtins table (`None`: not a
    /// builtin or one without a fixed signature).
    pub(super) fn builtin(&mut self, name: &str) -> Option<Ty> {
        // Two variables per use, `A`/`K` and `B`/`V`, whether the signature uses them or not.
        let vars = [self.fresh(), self.fresh()];
        let name = crate::front::prelude::builtin_alias(name).unwrap_or(name);
        let b = builtins::get(name)?;
        // A builtin without a signature of its own has the one its library function declares
        // (`sum(x: Events[Int]): Events[Int]`).
        if b.sig == Sig::Any
            && let Some(d) = crate::front::prelude::declaration(b.name)
        {
            return Some(self.declared_signature(d));
        }
        let template = template(b.name)?;
        Some(with_vars(template, &vars))
    }

    /// The type a library declaration gives (fresh variables for its type parameters). Its
    /// types are TeSSLa's own: a name this checker does not model becomes a fresh variable,
    /// and nothing is reported (the declaration's spans are not in the spec's files).
    pub(super) fn declared_signature(&mut self, d: &Def) -> Ty {
        let quiet = self.diags.len();
        let tparams: HashMap<String, Ty> = d
            .type_params
            .iter()
            .map(|tp| (tp.name.clone(), self.fresh()))
            .collect();
        let r = match &d.result_type {
            Some(t) => self.ast_type(t, &tparams),
            None => self.fresh(),
        };
        let t = match &d.params {
            Some(ps) => {
                let ps = ps
                    .iter()
                    .map(|p| match &p.ty {
                        Some(t) => self.ast_type(t, &tparams),
                        None => self.fresh(),
                    })
                    .collect();
                func(ps, r)
            }
            None => r,
        };
        self.diags.truncate(quiet);
        t
    }
}
