//! `--set NAME=VALUE`: replace the body of a top-level constant (a global definition of the
//! resolve pass) before lowering.
//!
//! Owns: `Compiler::apply_overrides`, `const_type_of` (the type of a literal constant: a
//! `--set` value is parsed after checking, so its type is read here). Only top-level defs whose value is a literal constant can
//! be set; the new value must be a literal of the same type (`--set delta=-0.5` is the Float
//! -0.5, written `-.0.5` in a spec). Errors name the known constants.

use super::*;

impl Compiler<'_> {
    /// Apply `overrides` to the top-level definitions; errors go to the diagnostics.
    pub(super) fn apply_overrides(&mut self, overrides: &[(String, String)]) {
        let resolved = self.resolved;
        for (name, value) in overrides {
            // Parameters: top-level defs whose value is a constant literal.
            let known: Vec<String> = resolved
                .defs
                .iter()
                .filter(|g| {
                    g.prefix.is_empty() && g.def.params.is_none() && const_type_of(g.def).is_some()
                })
                .map(|g| g.def.name.name.clone())
                .collect();
            let Some((id, entry)) = resolved
                .def_id(name)
                .and_then(|id| Some((id, self.global_entry(id)?)))
            else {
                let mut k = known.clone();
                k.sort();
                self.diags.push(
                    Diagnostic::error(
                        Category::Name,
                        None,
                        format!("--set {name}: the spec has no top-level constant `{name}`"),
                    )
                    .with_help(if k.is_empty() {
                        "the spec has no top-level constants `--set` could change (a constant is a \
                         top-level `def NAME = literal` without parameters, e.g. `def delta = 0.02`)"
                            .to_string()
                    } else {
                        format!("known constants: {}", k.join(", "))
                    }),
                );
                continue;
            };
            let mut map = SourceMap::new();
            let fid = map.add("--set", None, format!("def {name} = {value}\n"));
            let (file, diags) = tessla_syntax::parse(&map.get(fid).text, fid);
            let new_def = match (diags.is_empty(), file.statements.first()) {
                (true, Some(Statement::Def(d))) => {
                    let mut d = d.clone();
                    // `--set delta=-0.5` means the Float -0.5 (in a spec it is written `-.0.5`).
                    if let Body::Expr { expr, .. } = &mut d.body
                        && let ExprKind::Unary { op, operand } = &mut expr.kind
                        && *op == ast::UnaryOp::Neg
                        && matches!(operand.kind, ExprKind::Float(_))
                    {
                        *op = ast::UnaryOp::FNeg;
                    }
                    d
                }
                _ => {
                    self.diags.push(Diagnostic::error(
                        Category::Syntax,
                        None,
                        format!("--set {name}={value}: not an expression"),
                    ));
                    continue;
                }
            };
            // Type check: the new value must be a constant of the old value's type. The one
            // place of this rule: `--set` values come from the command line, after the check.
            let old_ty = const_type_of(&entry.def);
            let new_ty = const_type_of(&new_def);
            if old_ty != new_ty || new_ty.is_none() {
                self.diags.push(Diagnostic::error(
                    Category::Type,
                    Some(entry.def.name.span),
                    format!(
                        "--set {name}={value}: expected a constant of type {}, found {}",
                        shown(old_ty.as_ref()),
                        shown(new_ty.as_ref())
                    ),
                ));
                continue;
            }
            let mut d = (*entry.def).clone();
            d.body = new_def.body;
            let state = self.new_state();
            if let Some(slot) = self.defs.globals.get_mut(id) {
                *slot = Some(Entry {
                    def: Rc::new(d),
                    env_cell: entry.env_cell.clone(),
                    state,
                });
            }
        }
    }
}

/// A constant's type for a message: `Float`, or what it is when it is not a literal constant.
fn shown(t: Option<&Type>) -> String {
    t.map_or_else(
        || "an expression that is not a literal".to_string(),
        ToString::to_string,
    )
}

/// The type of a parameterless def's constant value, if it is a literal constant.
fn const_type_of(d: &Def) -> Option<Type> {
    match &d.body {
        Body::Expr { expr, .. } => match &expr.kind {
            ExprKind::Int { .. } => Some(Type::Int),
            ExprKind::Float(_) => Some(Type::Float),
            ExprKind::Str { .. } => Some(Type::String),
            ExprKind::Var(v) if v.name == "true" || v.name == "false" => Some(Type::Bool),
            ExprKind::Unary { operand, .. } => match &operand.kind {
                ExprKind::Int { .. } => Some(Type::Int),
                ExprKind::Float(_) => Some(Type::Float),
                _ => None,
            },
            _ => None,
        },
        Body::Extern { .. } => None,
    }
}
