//! Names and written types: lookup of a name in the local scopes and the resolved globals, the
//! unknown-name report (with the nearest names), and a type written in the spec as a [`Ty`]
//! (`ast_type`): type names known, applied to as many type arguments as they take.

use super::*;

/// Type names every spec may use.
pub(super) const BUILTIN_TYPES: [&str; 10] = [
    "Int", "Float", "Bool", "String", "Unit", "Events", "Option", "List", "Set", "Map",
];

/// Does the syntax type `t` name the type `name` anywhere?
pub(super) fn mentions(t: &ast::Type, name: &str) -> bool {
    match t {
        ast::Type::Name(id) => id.name == name,
        ast::Type::App { name: n, args, .. } => {
            n.name == name || args.iter().any(|a| mentions(a, name))
        }
        ast::Type::Function { params, result, .. } => {
            params.iter().any(|(_, p)| mentions(p, name)) || mentions(result, name)
        }
        ast::Type::Record { fields, .. } => fields.iter().any(|(_, f)| mentions(f, name)),
        ast::Type::Tuple { elems, .. } => elems.iter().any(|e| mentions(e, name)),
    }
}

impl<'a> Checker<'a> {
    pub(super) fn find(&self, name: &str, scope: &Rc<Scope<'a>>) -> Option<Found<'a>> {
        let mut s = Some(scope.clone());
        while let Some(sc) = s {
            match sc.names.borrow().get(name) {
                Some(Local::Mono(t)) => return Some(Found::Mono(t.clone())),
                Some(Local::Def(d)) => return Some(Found::Def(d.clone())),
                None => {}
            }
            s = sc.parent.clone();
        }
        self.find_global(name, &scope.prefix)
    }

    /// A global by name as seen from module `prefix` ([`Resolved::global`]'s rule).
    pub(super) fn find_global(&self, name: &str, prefix: &str) -> Option<Found<'a>> {
        match self.resolved?.global(name, prefix)? {
            Global::Def(id) => self.globals.get(id).map(|d| Found::Def(d.clone())),
            Global::Input(i) => self.inputs.get(i).map(|t| Found::Mono(t.clone())),
        }
    }

    pub(super) fn lookup(&mut self, id: &ast::Ident, scope: &Rc<Scope<'a>>) -> Ty {
        let name = id.name.as_str();
        match self.find(name, scope) {
            Some(Found::Mono(t)) => t,
            Some(Found::Def(d)) => self.def_type(&d),
            None if !is_builtin_name(name) => {
                self.unknown_name(id, scope);
                self.fresh()
            }
            None => self.builtin(name).unwrap_or_else(|| self.fresh()),
        }
    }

    /// Report a name that is neither in scope, nor a builtin, nor in the prelude.
    pub(super) fn unknown_name(&mut self, id: &ast::Ident, scope: &Rc<Scope<'a>>) {
        let mut known: Vec<String> = Vec::new();
        let mut s = Some(scope.clone());
        while let Some(sc) = s {
            known.extend(sc.names.borrow().keys().cloned());
            s = sc.parent.clone();
        }
        if let Some(r) = self.resolved {
            known.extend(r.visible_names(&scope.prefix).map(str::to_string));
        }
        known.extend(builtins::names().map(str::to_string));
        known.extend(crate::front::prelude::names());
        self.report(tessla_syntax::diag::unknown_name(
            &id.name,
            id.span,
            known.iter().map(String::as_str),
        ));
    }

    /// Report a type name that is neither built in, a type parameter in scope, nor declared
    /// with `type` (a typo such as `Events[Integer]`). Dotted names (`M.T`) are not checked.
    pub(super) fn check_type_name(&mut self, id: &ast::Ident, tparams: &HashMap<String, Ty>) {
        let n = id.name.as_str();
        if n.contains('.')
            || BUILTIN_TYPES.contains(&n)
            || tparams.contains_key(n)
            || self.enclosing_tparams.iter().any(|tp| tp == n)
            || self.declared_type(n).is_some()
        {
            return;
        }
        let known: Vec<&str> = BUILTIN_TYPES
            .iter()
            .copied()
            .chain(
                self.resolved
                    .iter()
                    .flat_map(|r| r.declared_types.keys().map(String::as_str)),
            )
            .chain(tparams.keys().map(String::as_str))
            .collect();
        let mut near = tessla_syntax::diag::nearest(n, known.iter().copied());
        if near.is_empty() {
            // `Integer` for `Int`, `Boolean` for `Bool`: a known name that starts the unknown one.
            let lower = n.to_lowercase();
            near = known
                .iter()
                .copied()
                .filter(|k| k.len() >= 3 && lower.starts_with(&k.to_lowercase()))
                .take(3)
                .collect();
        }
        let help = if near.is_empty() {
            "declare it with `type` or use a built-in type (Int, Float, Bool, String, Unit, Option, List, Set, Map)".to_string()
        } else {
            format!(
                "did you mean {}?",
                near.iter()
                    .map(|k| format!("`{k}`"))
                    .collect::<Vec<_>>()
                    .join(" or ")
            )
        };
        let d = Diagnostic::error(Category::Type, Some(id.span), format!("unknown type `{n}`"))
            .with_label("not a known type")
            .with_help(help);
        self.report(d);
    }

    /// The number of type parameters of the type `n` declared with `type`.
    pub(super) fn declared_type(&self, n: &str) -> Option<usize> {
        self.resolved?.declared_types.get(n).copied()
    }

    /// The number of type arguments the type named `n` takes (`None`: not known here, e.g. a
    /// dotted name or an unknown type, which [`Checker::check_type_name`] reports).
    pub(super) fn type_arity(&self, n: &str, tparams: &HashMap<String, Ty>) -> Option<usize> {
        if tparams.contains_key(n) || self.enclosing_tparams.iter().any(|tp| tp == n) {
            return Some(0);
        }
        match n {
            "Int" | "Float" | "Bool" | "String" | "Unit" => Some(0),
            "Events" | "Option" | "List" | "Set" => Some(1),
            "Map" => Some(2),
            _ => self.declared_type(n),
        }
    }

    /// Report a type applied to the wrong number of type arguments (TeSSLa: `Map[String]`,
    /// `Int[Bool]`, `Events[Int, Int]`, a bare `Events`); true when it is reported.
    pub(super) fn check_type_arity(
        &mut self,
        id: &ast::Ident,
        given: usize,
        tparams: &HashMap<String, Ty>,
    ) -> bool {
        let Some(want) = self.type_arity(&id.name, tparams) else {
            return false;
        };
        if want == given {
            return false;
        }
        let n = &id.name;
        let msg = match (want, given) {
            (0, _) => format!("`{n}` takes no type arguments, {given} given"),
            (1, 0) => format!("`{n}` takes a type argument: `{n}[T]`"),
            _ => format!(
                "`{n}` takes {want} type argument{}, {given} given",
                if want == 1 { "" } else { "s" }
            ),
        };
        let help = match n.as_str() {
            "Map" => "write `Map[K, V]`, the type of the keys and of the values".to_string(),
            _ if want == 0 => format!("write `{n}` alone"),
            _ => format!("write `{n}[{}]`", vec!["T"; want].join(", ")),
        };
        self.report(
            Diagnostic::error(Category::Type, Some(id.span), msg)
                .with_label("wrong number of type arguments")
                .with_help(help),
        );
        true
    }

    pub(super) fn ast_type(&mut self, t: &ast::Type, tparams: &HashMap<String, Ty>) -> Ty {
        if let ast::Type::Name(id) = t
            && self.check_type_arity(id, 0, tparams)
        {
            return self.fresh();
        }
        match t {
            ast::Type::Name(id) => match id.name.as_str() {
                "Int" => int(),
                "Float" => float(),
                "Bool" => boolean(),
                "String" => string(),
                "Unit" => unit(),
                n => match tparams.get(n) {
                    Some(t) => t.clone(),
                    None => {
                        self.check_type_name(id, tparams);
                        self.fresh()
                    }
                },
            },
            ast::Type::App { name, args, .. } => {
                let mut a: Vec<Ty> = args.iter().map(|x| self.ast_type(x, tparams)).collect();
                if self.check_type_arity(name, a.len(), tparams) {
                    return self.fresh();
                }
                match (name.name.as_str(), a.len()) {
                    ("Events", 1) => ev(a.remove(0)),
                    ("Option", 1) => opt(a.remove(0)),
                    ("List", 1) => list(a.remove(0)),
                    ("Set", 1) => set(a.remove(0)),
                    ("Map", 2) => {
                        let k = a.remove(0);
                        map(k, a.remove(0))
                    }
                    _ => {
                        self.check_type_name(name, tparams);
                        self.fresh()
                    }
                }
            }
            ast::Type::Function { params, result, .. } => {
                let ps = params
                    .iter()
                    .map(|(_, p)| self.ast_type(p, tparams))
                    .collect();
                let r = self.ast_type(result, tparams);
                func(ps, r)
            }
            ast::Type::Record { fields, .. } if fields.is_empty() => unit(),
            ast::Type::Record { fields, .. } => {
                let mut fs: Vec<(String, Ty)> = fields
                    .iter()
                    .map(|(n, t)| (n.name.clone(), self.ast_type(t, tparams)))
                    .collect();
                fs.sort_by(|a, b| a.0.cmp(&b.0));
                Ty::Record(fs)
            }
            ast::Type::Tuple { elems, .. } if elems.is_empty() => unit(),
            ast::Type::Tuple { elems, .. } => {
                tuple(elems.iter().map(|x| self.ast_type(x, tparams)).collect())
            }
        }
    }
}
