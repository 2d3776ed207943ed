//! Definitions: inference of a def on first use and its generalisation (let-polymorphism), its
//! declared parameter and result types, local (`where`, block) definitions, and TeSSLa's
//! rules on them: parameters have types, a recursive definition has its type written on its
//! cycle, an unused local definition is still checked.

use super::*;

impl<'a> Checker<'a> {
    /// The (instantiated) type of a def, inferring it on first use.
    pub(super) fn def_type(&mut self, d: &Rc<DefInfo<'a>>) -> Ty {
        let s = self.def_scheme(d);
        self.instantiate(&s)
    }

    pub(super) fn def_scheme(&mut self, d: &Rc<DefInfo<'a>>) -> Scheme {
        let state = std::mem::replace(&mut *d.state.borrow_mut(), State::Todo);
        match state {
            State::Done(s) => {
                *d.state.borrow_mut() = State::Done(s.clone());
                s
            }
            State::InProgress(t) => {
                *d.state.borrow_mut() = State::InProgress(t.clone());
                self.check_recursion(d);
                Scheme {
                    vars: Vec::new(),
                    ty: t,
                }
            }
            State::Todo => {
                let me = self.fresh();
                *d.state.borrow_mut() = State::InProgress(me.clone());
                let typed =
                    d.def.result_type.is_some() || matches!(d.def.body, Body::Extern { .. });
                self.inferring.push(Some((Rc::as_ptr(d) as usize, typed)));
                let t = self.infer_def(d.def, &d.scope);
                self.inferring.pop();
                self.unify(&me, &t).ok();
                self.report_untyped_recursion(d, &t);
                let s = self.generalize(&t);
                *d.state.borrow_mut() = State::Done(s.clone());
                s
            }
        }
    }

    /// The type of a def: a function type when it has parameters.
    pub(super) fn infer_def(&mut self, d: &'a Def, scope: &Rc<Scope<'a>>) -> Ty {
        let outer = self.enclosing_tparams.len();
        self.enclosing_tparams
            .extend(d.type_params.iter().map(|tp| tp.name.clone()));
        let t = self.infer_def_body(d, scope);
        self.enclosing_tparams.truncate(outer);
        t
    }

    pub(super) fn infer_def_body(&mut self, d: &'a Def, scope: &Rc<Scope<'a>>) -> Ty {
        self.check_liftable(d);
        let mut tparams: HashMap<String, Ty> = HashMap::new();
        for tp in &d.type_params {
            let v = self.fresh();
            tparams.insert(tp.name.clone(), v);
        }
        let inner = self.child_of(scope);
        let mut ptys = Vec::new();
        if let Some(ps) = &d.params {
            for p in ps {
                let t = match &p.ty {
                    Some(t) => self.ast_type(t, &tparams),
                    None => self.missing_parameter_type(p, Some(&d.name.name)),
                };
                inner
                    .names
                    .borrow_mut()
                    .insert(p.name.name.clone(), Local::Mono(t.clone()));
                ptys.push(t);
            }
        }
        let declared = d.result_type.as_ref().map(|t| self.ast_type(t, &tparams));
        let body = match &d.body {
            Body::Extern { .. } => declared.clone().unwrap_or_else(|| self.fresh()),
            Body::Expr { expr, where_defs } => {
                let scope = if where_defs.is_empty() {
                    inner
                } else {
                    self.local_defs(where_defs, &inner)
                };
                let t = self.infer(expr, &scope);
                self.check_unused(where_defs, &scope);
                if let Some(dt) = &declared {
                    self.expect(
                        dt,
                        &t,
                        expr.span,
                        &format!(
                            "the body of `{}` does not have its declared type",
                            d.name.name
                        ),
                    );
                }
                t
            }
        };
        let ret = declared.unwrap_or(body);
        let t = if d.params.is_some() {
            func(ptys, ret)
        } else {
            ret
        };
        if let Body::Extern { name, span, .. } = &d.body {
            self.check_registered_native(d, name, *span, &t);
        }
        t
    }

    /// An `extern` of a native the application registered must be declared with the native's
    /// signature (else the native would be handed values of other types).
    fn check_registered_native(&mut self, d: &Def, name: &str, span: Span, declared: &Ty) {
        let Some(native) = self.natives.and_then(|n| n.get(name)) else {
            return;
        };
        let vars = [self.fresh(), self.fresh()];
        match signatures::signature(native.sig, &vars) {
            Some(registered) => {
                self.expect(
                    &registered,
                    declared,
                    span,
                    &format!(
                        "`{}` is declared with another type than the native `{name}`",
                        d.name.name
                    ),
                );
            }
            None => self.report(Diagnostic::error(
                Category::Type,
                Some(span),
                format!(
                    "the native `{name}` was registered with a signature that does not parse: `{}`",
                    native.sig
                ),
            )),
        }
    }

    /// TeSSLa's rule: a parameter has a type, in a `def` as in a lambda. Reports and returns a
    /// fresh type so that checking goes on.
    pub(super) fn missing_parameter_type(&mut self, p: &ast::Param, function: Option<&str>) -> Ty {
        let n = &p.name.name;
        let msg = match function {
            Some(f) => format!("parameter `{n}` of `{f}` has no type"),
            None => format!("the lambda's parameter `{n}` has no type"),
        };
        self.report(
            Diagnostic::error(Category::Type, Some(p.name.span), msg)
                .with_label("type missing")
                .with_help(format!(
                    "TeSSLa needs the type of every parameter: write `{n}: Int` (or `{n}: Events[Int]` for a stream)"
                )),
        );
        self.fresh()
    }

    /// A def met again while its own type is inferred: TeSSLa infers types in dependency
    /// order and needs a written type somewhere on every cycle. The cycle is the defs being
    /// inferred from `d` up; one with a type (return type for a function) breaks it, and so
    /// does a def checked although unused (a barrier: nothing on the cycle refers to it).
    pub(super) fn check_recursion(&mut self, d: &Rc<DefInfo<'a>>) {
        let me = Rc::as_ptr(d) as usize;
        for entry in self.inferring.iter().rev() {
            match entry {
                // Checked although unused, or a def with a type: no cycle without types.
                None | Some((_, true)) => return,
                Some((ptr, false)) if *ptr == me => break,
                Some(_) => {}
            }
        }
        if !self.inferring.contains(&Some((me, false))) {
            return;
        }
        if !self.untyped_recursive.contains(&me) {
            self.untyped_recursive.push(me);
        }
    }

    /// Report a def found by [`Checker::check_recursion`], once its type is inferred, with
    /// that type in the fix.
    pub(super) fn report_untyped_recursion(&mut self, d: &Rc<DefInfo<'a>>, t: &Ty) {
        let me = Rc::as_ptr(d) as usize;
        let Some(k) = self.untyped_recursive.iter().position(|p| *p == me) else {
            return;
        };
        self.untyped_recursive.swap_remove(k);
        let n = &d.def.name.name;
        let written = |t: &Ty| {
            let mut vars = Vec::new();
            collect_vars(t, &mut vars);
            if vars.is_empty() {
                show(t)
            } else {
                "T".to_string()
            }
        };
        let help = match (&d.def.params, self.resolve(t)) {
            (Some(_), Ty::Fn(_, r)) => format!(
                "TeSSLa needs a written type on every recursion: `def {n}(...): {} = ...`",
                written(&r)
            ),
            (Some(_), _) => {
                format!("TeSSLa needs a written type on every recursion: `def {n}(...): T = ...`")
            }
            (None, t) => format!(
                "TeSSLa needs a written type on every recursion: `def {n}: {} = ...`",
                written(&t)
            ),
        };
        self.report(
            Diagnostic::error(
                Category::Recursion,
                Some(d.def.name.span),
                format!("`{n}` is defined recursively and needs a type"),
            )
            .with_label("recursive definition without a type")
            .with_help(help),
        );
    }

    /// Type-check the local defs that nothing used (TeSSLa checks every definition).
    pub(super) fn check_unused(&mut self, defs: &'a [Def], scope: &Rc<Scope<'a>>) {
        for d in defs {
            let info = match scope.names.borrow().get(&d.name.name) {
                Some(Local::Def(info)) if matches!(*info.state.borrow(), State::Todo) => {
                    info.clone()
                }
                _ => continue,
            };
            self.inferring.push(None);
            self.def_scheme(&info);
            self.inferring.pop();
        }
    }

    pub(super) fn local_defs(&mut self, defs: &'a [Def], scope: &Rc<Scope<'a>>) -> Rc<Scope<'a>> {
        let s = self.child_of(scope);
        for d in defs {
            s.names.borrow_mut().insert(
                d.name.name.clone(),
                Local::Def(Rc::new(DefInfo {
                    def: d,
                    scope: s.clone(),
                    state: RefCell::new(State::Todo),
                })),
            );
        }
        s
    }
}
