//! The type rules of the operators, each once: operand and result types of every unary and
//! binary operator, `==`/`!=` on one type, and TeSSLa 1.2's error for an Int operator on a
//! Float (with the dotted operator as the fix). The lowering has no copy of these.

use super::*;

impl<'a> Checker<'a> {
    /// A unary operator: `!` takes a Bool, `-.` a Float, `-` and `~` an Int (`-` on a Float
    /// is TeSSLa 1.2's error, with `-.` as the fix); lifted over a stream operand.
    pub(super) fn unary(
        &mut self,
        op: UnaryOp,
        operand: &'a Expr,
        span: Span,
        scope: &Rc<Scope<'a>>,
    ) -> Ty {
        let t = self.infer(operand, scope);
        let (want, what) = match op {
            UnaryOp::Not => (boolean(), "`!` needs a Bool"),
            UnaryOp::FNeg => (float(), "`-.` needs a Float"),
            UnaryOp::Neg | UnaryOp::BitNot => (int(), "this operator needs an Int"),
        };
        if matches!(op, UnaryOp::Neg) && self.base_is(&t, "Float") {
            self.report(
                Diagnostic::error(
                    Category::Type,
                    Some(span),
                    "`-` is not defined for Float in TeSSLa 1.2",
                )
                .with_label("a Float operand")
                .with_help("use `-.` for Float"),
            );
            return self.lifted(&[t], float());
        }
        self.expect(&want, &t, operand.span, what);
        self.lifted(&[t], want)
    }

    pub(super) fn binary(
        &mut self,
        op: BinOp,
        lhs: &'a Expr,
        rhs: &'a Expr,
        span: Span,
        scope: &Rc<Scope<'a>>,
    ) -> Ty {
        use BinOp::*;
        let a = self.infer(lhs, scope);
        let b = self.infer(rhs, scope);
        let sym = op.symbol();
        let (operand, result) = match op {
            Add | Sub | Mul | Div | Mod | Shl | Shr | BitAnd | BitOr | BitXor => (int(), int()),
            Lt | Gt | Le | Ge => (int(), boolean()),
            FAdd | FSub | FMul | FDiv => (float(), float()),
            FLt | FGt | FLe | FGe => (float(), boolean()),
            And | Or => (boolean(), boolean()),
            Eq | Ne => {
                if self.unify(&a, &b).is_err() {
                    let (x, y) = (show(&self.resolve(&a)), show(&self.resolve(&b)));
                    self.report(
                        Diagnostic::error(
                            Category::Type,
                            Some(span),
                            format!("`{sym}` compares values of one type, found {x} and {y}"),
                        )
                        .with_label("different types"),
                    );
                }
                return self.lifted(&[a, b], boolean());
            }
        };
        let int_op = matches!(op, Add | Sub | Mul | Div | Mod | Lt | Gt | Le | Ge);
        if int_op && (self.base_is(&a, "Float") || self.base_is(&b, "Float")) {
            self.report(
                Diagnostic::error(
                    Category::Type,
                    Some(span),
                    format!("`{sym}` is not defined for Float in TeSSLa 1.2"),
                )
                .with_label("a Float operand")
                .with_help(format!("use `{sym}.` for Float")),
            );
            return self.lifted(&[a, b], result);
        }
        let what = format!("operand of `{sym}`");
        if self.expect(&operand, &a, lhs.span, &what) {
            self.expect(&operand, &b, rhs.span, &what);
        }
        self.lifted(&[a, b], result)
    }
}
