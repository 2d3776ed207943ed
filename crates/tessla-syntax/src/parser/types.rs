//! Types: names with type arguments (`Events[Map[String, Int]]`), tuples, records
//! (`{x: Int}`) and function types (`(Int, Int) => Bool`).

use super::*;

impl Parser<'_> {
    pub(super) fn ty(&mut self) -> PResult<Type> {
        self.nested(0, Self::ty_inner)
    }

    pub(super) fn ty_inner(&mut self) -> PResult<Type> {
        let start = self.span();
        if self.is_punct(Punct::LParen) {
            let after = self.after_matching(0);
            let is_fn = matches!(self.tok_at(after), Tok::Punct(Punct::FatArrow));
            self.advance();
            let (params, _) = self.comma_list(Punct::RParen, ListForm::NoTrailing, |p| {
                let ev = p.evaluation();
                Ok((ev, p.ty()?))
            })?;
            if is_fn {
                self.expect_punct(Punct::FatArrow)?;
                self.skip_nl();
                let result = Box::new(self.ty()?);
                return Ok(Type::Function {
                    params,
                    result,
                    span: start.to(self.prev_span()),
                });
            }
            let elems = params.into_iter().map(|(_, t)| t).collect();
            return Ok(Type::Tuple {
                elems,
                span: start.to(self.prev_span()),
            });
        }
        if self.eat_punct(Punct::LBrace) {
            let (fields, _) = self.comma_list(Punct::RBrace, ListForm::Open, |p| {
                let n = p.ident()?;
                p.expect_punct(Punct::Colon)?;
                p.skip_nl();
                Ok((n, p.ty()?))
            })?;
            return Ok(Type::Record {
                fields,
                span: start.to(self.prev_span()),
            });
        }
        let name = self.ident()?;
        if self.eat_punct(Punct::LBracket) {
            let (args, _) = self.comma_list(Punct::RBracket, ListForm::NonEmpty, Self::ty)?;
            return Ok(Type::App {
                name,
                args,
                span: start.to(self.prev_span()),
            });
        }
        Ok(Type::Name(name))
    }

    // ---- expressions ----
}
