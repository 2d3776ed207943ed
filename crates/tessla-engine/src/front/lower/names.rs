//! Names during lowering: a name is a local (a parameter, a block or `where` definition, a macro
//! argument: lowering's own scopes, [`Env`]) or else a global that `Resolved::global` finds from
//! the module the code stands in (a definition, by its `DefId`, or an input). Each global
//! definition has one lowering state, made on first use; definitions are compiled on first use;
//! also `extern` bodies. Unknown names are the checker's rule: here they are an internal
//! error. A stream definition used while it is compiled becomes an alias
//! filled in when it is done; a use outside the lazy argument of `last`/`delay` is then checked
//! for a strict cycle on the lowered graph, so recursion is allowed wherever TeSSLa allows it
//! (through `last`/`delay` inside function bodies, helpers and lifted calls too).
//!
//! Owns: `Compiler::binding` (local, else global), `global_entry`, `lookup`, `def_term`, `body`,
//! `local_defs`.

use super::*;
use crate::front::resolve::{DefId, Global};

impl Compiler<'_> {
    pub(super) fn def_term(&mut self, e: &Entry, span: Span) -> R<Term> {
        if e.def.params.is_some() {
            let env = e.env_cell.borrow().clone().unwrap_or_default();
            return Ok(Term::Func(Rc::new(FuncTerm::User {
                def: e.def.clone(),
                env,
            })));
        }
        let st = std::mem::replace(&mut *e.state.borrow_mut(), DefState::Todo);
        match st {
            DefState::Done(t) => {
                *e.state.borrow_mut() = DefState::Done(t.clone());
                Ok(t)
            }
            DefState::Failed => {
                *e.state.borrow_mut() = DefState::Failed;
                Err(Fail)
            }
            DefState::InProgress { alias, eager } => {
                // A use while the def is compiled: a stream alias filled in when it is done.
                // Whether the recursion goes through `last`/`delay` is decided then, on the
                // lowered graph, so a recursion through `last` inside a function body (a
                // parameter given to `last`, a lifted call) is allowed as in TeSSLa.
                let a = match alias {
                    Some(a) => a,
                    None => self.node(Node::Alias(usize::MAX)),
                };
                let eager = match eager {
                    None if self.depth.lazy_depth == 0 => Some(span),
                    e => e,
                };
                *e.state.borrow_mut() = DefState::InProgress {
                    alias: Some(a),
                    eager,
                };
                Ok(Term::Stream(a))
            }
            DefState::Todo => {
                *e.state.borrow_mut() = DefState::InProgress {
                    alias: None,
                    eager: None,
                };
                let env = e.env_cell.borrow().clone().unwrap_or_default();
                let saved = self.depth.lazy_depth;
                self.depth.lazy_depth = 0;
                let saved_owner = self.graph.owner;
                self.graph.owner = owner_key(self.sources.text(e.def.name.span));
                let r = self.body(&e.def, &env);
                self.graph.owner = saved_owner;
                self.depth.lazy_depth = saved;
                let (alias, eager) = match &*e.state.borrow() {
                    DefState::InProgress { alias, eager, .. } => (*alias, *eager),
                    _ => (None, None),
                };
                match r {
                    Ok(t) => {
                        if let Some(a) = alias {
                            match &t {
                                Term::Stream(n) => {
                                    self.graph.nodes[a] = Node::Alias(*n);
                                    if let Some(at) = eager
                                        && self.strictly_reaches(*n, a)
                                    {
                                        self.graph.nodes[a] = Node::Nil;
                                        *e.state.borrow_mut() = DefState::Failed;
                                        self.diags.push(
                                            Diagnostic::error(
                                                Category::Recursion,
                                                Some(at),
                                                format!(
                                                    "`{}` is defined in terms of itself",
                                                    e.def.name.name
                                                ),
                                            )
                                            .with_help("recursion is allowed only through the first argument of `last` or `delay`"),
                                        );
                                        return Err(Fail);
                                    }
                                }
                                Term::Const(v) => self.graph.nodes[a] = Node::Const(v.clone()),
                                _ => {
                                    *e.state.borrow_mut() = DefState::Todo;
                                    return self.error(
                                        Category::Recursion,
                                        span,
                                        "only streams may be defined recursively",
                                    );
                                }
                            }
                        }
                        *e.state.borrow_mut() = DefState::Done(t.clone());
                        Ok(t)
                    }
                    Err(Fail) => {
                        if let Some(a) = alias {
                            self.graph.nodes[a] = Node::Nil;
                        }
                        *e.state.borrow_mut() = DefState::Failed;
                        Err(Fail)
                    }
                }
            }
        }
    }

    /// Does node `from` depend on node `to` through strict dependencies only (not through the
    /// lazy argument of `last`/`delay`)?
    fn strictly_reaches(&self, from: NodeId, to: NodeId) -> bool {
        let mut seen = HashSet::new();
        let mut todo = vec![from];
        while let Some(x) = todo.pop() {
            if x == to {
                return true;
            }
            if !seen.insert(x) {
                continue;
            }
            if let Some(node) = self.graph.nodes.get(x) {
                todo.extend(node.strict_deps());
            }
        }
        false
    }

    /// A warning for an `extern` no builtin and no registered native provides (once per place),
    /// naming the natives this program registered.
    fn warn_unknown_extern(&mut self, name: &str, span: Span) {
        let message = format!(
            "`extern(\"{name}\")` names no native of this program: every call of it is an error \
             value (`call of an unknown extern`)"
        );
        if self
            .diags
            .iter()
            .any(|d| d.span == Some(span) && d.message == message)
        {
            return;
        }
        let mut registered: Vec<&str> = self.typed.natives().iter().map(|n| n.name).collect();
        registered.sort_unstable();
        let help = if registered.is_empty() {
            "check the name; a program embedding the engine registers its natives with \
             `Natives::register` in `LoadOptions::natives`"
                .to_string()
        } else {
            format!(
                "check the name; this program's natives: {}",
                registered.join(", ")
            )
        };
        self.diags
            .push(Diagnostic::warning(Category::Other, Some(span), message).with_help(help));
    }

    pub(super) fn body(&mut self, d: &Def, env: &Env) -> R<Term> {
        match &d.body {
            // The one place of this rule (the checker leaves an unannotated extern's type open).
            Body::Extern { span, .. } if d.result_type.is_none() => self.error(
                Category::Type,
                *span,
                format!(
                    "extern definition `{}` needs a type annotation",
                    d.name.name
                ),
            ),
            Body::Extern { name, span, .. } => match builtins::extern_named(name).or_else(|| {
                let n = self.typed.natives().get(name)?;
                Some((n.name, n.f))
            }) {
                Some((name, f)) => Ok(Term::Func(Rc::new(FuncTerm::Native { name, f }))),
                // As in TeSSLa, an unknown extern is an error when it is evaluated; said once
                // at load, so a misspelt or unregistered native is not found by its errors.
                None if d.params.is_some() => {
                    self.warn_unknown_extern(name, *span);
                    let f: NativeFn = unknown_extern;
                    let name = "unknown extern";
                    Ok(Term::Func(Rc::new(FuncTerm::Native { name, f })))
                }
                None => {
                    let msg: Arc<str> = format!("unknown extern `{name}`").into();
                    Ok(Term::Const(Value::Error(RuntimeError::Other(msg))))
                }
            },
            Body::Expr { expr, where_defs } => {
                if where_defs.is_empty() {
                    self.expr(expr, env)
                } else {
                    let env = self.local_defs(where_defs, env);
                    self.expr(expr, &env)
                }
            }
        }
    }

    pub(super) fn local_defs(&mut self, defs: &[Def], env: &Env) -> Env {
        let cell: Rc<RefCell<Option<Env>>> = self.new_scope();
        let mut names = HashMap::new();
        for d in defs {
            names.insert(
                d.name.name.clone(),
                Binding::Def(Entry {
                    def: Rc::new(d.clone()),
                    env_cell: cell.clone(),
                    state: self.new_state(),
                }),
            );
        }
        let child = env.child(names, env.frame);
        *cell.borrow_mut() = Some(child.clone());
        child
    }

    /// The lowering state of global definition `id`, made on first use.
    pub(super) fn global_entry(&mut self, id: DefId) -> Option<Entry> {
        if let Some(Some(e)) = self.defs.globals.get(id) {
            return Some(e.clone());
        }
        let g = self.resolved.defs.get(id)?;
        let e = Entry {
            def: Rc::new(g.def.clone()),
            // A global's body sees no local names: its scope cannot be part of a cycle.
            env_cell: Rc::new(RefCell::new(Some(Env::module(&g.prefix)))),
            state: self.new_state(),
        };
        *self.defs.globals.get_mut(id)? = Some(e.clone());
        Some(e)
    }

    /// What `name` means in `env`: a local name, else a global as the resolve pass finds it
    /// from `env`'s module (a definition or an input).
    pub(super) fn binding(&mut self, name: &str, env: &Env) -> Option<Binding> {
        if let Some(b) = env.local(name) {
            return Some(b);
        }
        match self.resolved.global(name, &env.prefix)? {
            Global::Def(id) => self.global_entry(id).map(Binding::Def),
            Global::Input(i) => self
                .graph
                .input_nodes
                .get(i)
                .map(|n| Binding::Term(Term::Stream(*n))),
        }
    }

    pub(super) fn lookup(&mut self, name: &str, span: Span, env: &Env) -> R<Term> {
        match self.binding(name, env) {
            Some(Binding::Term(t)) => Ok(t),
            Some(Binding::Def(e)) => self.def_term(&e, span),
            None => {
                let name = crate::front::prelude::builtin_alias(name).unwrap_or(name);
                if name == "true" {
                    return Ok(Term::Const(Value::Bool(true)));
                }
                if name == "false" {
                    return Ok(Term::Const(Value::Bool(false)));
                }
                if name == "None" {
                    return Ok(Term::Const(Value::None));
                }
                if let Some(b) = builtins::get(name) {
                    return Ok(match b.kind {
                        Kind::Stream(StreamOp::Nil) => Term::Stream(self.node(Node::Nil)),
                        Kind::Stream(StreamOp::Unit) => Term::Stream(self.unit()),
                        Kind::Stream(op) => Term::Func(Rc::new(FuncTerm::Builtin(b, op))),
                        Kind::Constant(v) => Term::Const(v()),
                        Kind::Value(f) | Kind::Operator(f) => {
                            Term::Func(Rc::new(FuncTerm::Native { name: b.name, f }))
                        }
                        // Only through `extern("name")`.
                        Kind::Extern(_) => return self.unchecked(span, "an unknown name"),
                    });
                }
                // Unknown names are the checker's (`crate::front::typeck`, its `unknown_name`).
                self.unchecked(span, "an unknown name")
            }
        }
    }
}
