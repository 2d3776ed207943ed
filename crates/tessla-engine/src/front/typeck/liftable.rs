//! `liftable`: TeSSLa's rules for declaring a function liftable (a function of value types)
//! and for applying a function to streams (only `liftable` ones are lifted; a stream for a
//! value parameter of another user function is a type mismatch).

use super::*;

/// TeSSLa's value types (what a liftable function may take and return): not a stream, and no
/// record or tuple holding one. A type name (an alias) counts as a value. TeSSLa also excludes
/// function types, but its library declares its liftable functions taking functions
/// (`List.map`) as `extern`, which the bundled prelude (and the corpus run with it) writes as
/// definitions: a function type is let through here.
pub(super) fn is_value_type(t: &ast::Type) -> bool {
    match t {
        ast::Type::Name(_) => true,
        ast::Type::App { name, args, .. } => {
            name.name != "Events" && args.iter().all(is_value_type)
        }
        ast::Type::Function { .. } => true,
        ast::Type::Record { fields, .. } => fields.iter().all(|(_, t)| is_value_type(t)),
        ast::Type::Tuple { elems, .. } => elems.iter().all(is_value_type),
    }
}

impl<'a> Checker<'a> {
    /// TeSSLa's rules for `liftable`: only a macro (a def with parameters or type parameters)
    /// can be liftable (`LiftableOnNonMacro`), and only when its parameter and result types
    /// are value types, not streams (`UnliftableMacroType`; see [`is_value_type`]).
    pub(super) fn check_liftable(&mut self, d: &Def) {
        if !d.liftable {
            return;
        }
        if d.params.is_none() && d.type_params.is_empty() {
            self.report(
                Diagnostic::error(
                    Category::Type,
                    Some(d.span),
                    format!(
                        "`{}` is not a function, so it cannot be `liftable`",
                        d.name.name
                    ),
                )
                .with_label("liftable without parameters")
                .with_help(format!(
                    "remove `liftable`: only functions with parameters are lifted to streams \
                     (TeSSLa: Non-macro \"{}\" can not be liftable)",
                    d.name.name
                )),
            );
            return;
        }
        let library = self.resolved.and_then(|r| r.library);
        if matches!(d.body, Body::Extern { .. }) || library == Some(d.span.file) {
            return;
        }
        let bad = d
            .params
            .iter()
            .flatten()
            .filter_map(|p| p.ty.as_ref())
            .chain(d.result_type.as_ref())
            .find(|t| !is_value_type(t));
        if let Some(t) = bad {
            self.report(
                Diagnostic::error(
                    Category::Type,
                    Some(d.span),
                    format!(
                        "`{}` is declared `liftable`, but its type does not allow being lifted",
                        d.name.name
                    ),
                )
                .with_note_at(t.span(), "a stream type")
                .with_help(
                    "a liftable function takes and returns plain values (Int, Float, records, \
                     ...), which TeSSLa lifts to streams; remove `liftable`, or the stream types",
                ),
            );
        }
    }

    /// Each parameter type that is a plain value type (`Int`, not a stream, not a type
    /// variable), as `Some(type)`.
    pub(super) fn value_params(&self, ps: &[Ty]) -> Vec<Option<Ty>> {
        ps.iter()
            .map(|p| match self.shallow(p) {
                Ty::Var(_) | Ty::Con("Events", _) => None,
                t @ (Ty::Con(..) | Ty::Fn(..) | Ty::Record(_)) => Some(t),
            })
            .collect()
    }

    /// TeSSLa lifts only `liftable` functions to streams: a stream given for a parameter of
    /// a plain value type (`Int`) of another function is a type mismatch. `ps` are the
    /// callee's value parameter types ([`Checker::value_params`]), `ts` the arguments'.
    pub(super) fn check_not_lifted(
        &mut self,
        d: &Def,
        ps: &[Option<Ty>],
        ts: &[Ty],
        args: &[ast::Arg],
        span: Span,
    ) {
        for (i, (p, t)) in ps.iter().zip(ts).enumerate() {
            if let Some(p) = p
                && self.is_stream(t)
            {
                let n = &d.name.name;
                let (ps, ts) = (show(&self.resolve(p)), show(&self.resolve(t)));
                let sp = args.get(i).map_or(span, |a| a.value.span);
                self.report(
                    Diagnostic::error(
                        Category::Type,
                        Some(sp),
                        format!("argument {} of `{n}`: expected {ps}, found {ts}", i + 1),
                    )
                    .with_label(format!("a stream, but `{n}` is not liftable"))
                    .with_help(format!(
                        "only `liftable` functions apply to streams event by event: declare \
                         `liftable def {n}(...)`, or give the parameter a stream type \
                         (`Events[...]`)"
                    )),
                );
                return;
            }
        }
    }
}
