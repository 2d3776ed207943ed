//! Annotations: each use checked against its definition (arity, named arguments, argument
//! types, constant arguments). That `@` stands on an `in`/`out` and `@@` on its own is a name
//! rule of `crate::front::resolve`.

use super::*;

/// The message when an annotation's argument is not a constant: the checker's for declared
/// annotations, the lowering's for those declared nowhere.
pub const ANNOTATION_ARGS_CONSTANT: &str = "annotation arguments must be constants";

impl<'a> Checker<'a> {
    /// Check one use of an annotation against its definition: declared with the same kind
    /// (`@` on an `in`/`out`, `@@` on its own), arity, argument types, constant arguments. An
    /// annotation declared nowhere is left to the compiler (a warning there).
    pub(super) fn annotation(&mut self, a: &'a ast::Annotation, global: bool) {
        let Some(defs) = self.resolved.map(|r| &r.annotations) else {
            return;
        };
        // Not declared (a warning of the lowering), or declared as the other kind (an error
        // of name resolution).
        let Some(params) = defs.get(&(a.name.name.clone(), global)).copied() else {
            return;
        };
        let name = at(&a.name, global);
        let names: Vec<&str> = params.iter().map(|p| p.name.name.as_str()).collect();
        let Some(positions) = self.order_named(&a.args, &names, &name) else {
            return;
        };
        if a.args.len() != params.len() {
            self.report(
                Diagnostic::error(
                    Category::Type,
                    Some(a.span),
                    match params.len() {
                        0 => format!("`{name}` takes no arguments, {} given", a.args.len()),
                        1 => format!("`{name}` takes 1 argument, {} given", a.args.len()),
                        n => format!("`{name}` takes {n} arguments, {} given", a.args.len()),
                    },
                )
                .with_help(format!("its parameters are ({})", names.join(", "))),
            );
            return;
        }
        let root = self.module_scope("");
        for (arg, pos) in a.args.iter().zip(positions) {
            let Some(p) = params.get(pos) else { continue };
            let t = self.infer(&arg.value, &root);
            if self.is_stream(&t) {
                self.report(
                    Diagnostic::error(
                        Category::Type,
                        Some(arg.value.span),
                        ANNOTATION_ARGS_CONSTANT,
                    )
                    .with_label("this is a stream")
                    .with_help("write a literal or a constant definition"),
                );
                continue;
            }
            let want = match &p.ty {
                Some(ty) => self.ast_type(ty, &HashMap::new()),
                None => self.fresh(),
            };
            self.expect(
                &want,
                &t,
                arg.value.span,
                &format!("argument `{}` of `{name}`", p.name.name),
            );
        }
    }
}
