//! Statements: `def` (with parameters, evaluation modes and `where` blocks), `in`, `out`,
//! `type`, `module`, `import`, annotations and their definitions.

use super::*;

impl Parser<'_> {
    pub(super) fn annotations(&mut self) -> PResult<Vec<Annotation>> {
        let mut out = Vec::new();
        while self.is_punct(Punct::At) {
            let start = self.advance().span;
            out.push(self.annotation_inner(start)?);
        }
        Ok(out)
    }

    pub(super) fn annotation_inner(&mut self, start: Span) -> PResult<Annotation> {
        let name = self.ident()?;
        let mut args = Vec::new();
        if self.eat_punct(Punct::LParen) {
            args = self.args_until_close()?;
        }
        let span = start.to(self.prev_span());
        self.skip_nl();
        Ok(Annotation { name, args, span })
    }

    /// Arguments after `(`, up to and including `)`.
    pub(super) fn args_until_close(&mut self) -> PResult<Vec<Arg>> {
        let (args, _) = self.comma_list(Punct::RParen, ListForm::Open, |p| {
            let name = match (p.peek(), p.peek_n(1)) {
                (Tok::Ident(n), Tok::Punct(Punct::Eq)) if Kw::of(n).is_none() => {
                    let id = p.ident()?;
                    p.advance();
                    p.skip_nl();
                    Some(id)
                }
                _ => None,
            };
            let value = p.expr()?;
            Ok(Arg { name, value })
        })?;
        Ok(args)
    }

    pub(super) fn statement(&mut self) -> PResult<Statement> {
        self.nested(0, Self::statement_inner)
    }

    pub(super) fn statement_inner(&mut self) -> PResult<Statement> {
        let start = self.span();
        if self.is_punct(Punct::AtAt) {
            return self.global_annotation(start);
        }
        if self.is_kw(Kw::Def) && matches!(self.peek_n(1), Tok::Punct(Punct::At | Punct::AtAt)) {
            return self.annotation_def(start);
        }
        if self.eat_kw(Kw::Type) {
            return self.type_def(start);
        }
        if self.eat_kw(Kw::Module) {
            return self.module(start);
        }
        if self.eat_kw(Kw::Import) {
            return self.import(start);
        }
        let annotations = self.annotations()?;
        if self.eat_kw(Kw::In) {
            return self.input(start, annotations);
        }
        if self.eat_kw(Kw::Out) {
            return self.output(start, annotations);
        }
        if !annotations.is_empty() && !self.is_kw(Kw::Def) && !self.is_kw(Kw::Liftable) {
            return self.expected("`in`, `out` or `def` after the annotation");
        }
        if self.is_kw(Kw::Def) || self.is_kw(Kw::Liftable) {
            return Ok(Statement::Def(self.def()?));
        }
        self.expected("a statement (`def`, `in`, `out`, `include`, `type`, ...)")
    }

    /// `@@name(args)`: an annotation of the whole spec.
    fn global_annotation(&mut self, start: Span) -> PResult<Statement> {
        self.advance();
        let name = self.ident()?;
        let mut args = Vec::new();
        if self.eat_punct(Punct::LParen) {
            args = self.args_until_close()?;
        }
        let span = start.to(self.prev_span());
        Ok(Statement::GlobalAnnotation(Annotation { name, args, span }))
    }

    /// `def @name(params)` or `def @@name(params)`: an annotation's definition.
    fn annotation_def(&mut self, start: Span) -> PResult<Statement> {
        self.advance();
        let global = self.advance().tok == Tok::Punct(Punct::AtAt);
        let name = self.ident()?;
        let mut params = Vec::new();
        if self.eat_punct(Punct::LParen) {
            params = self.params_until_close()?;
        }
        Ok(Statement::AnnotationDef {
            name,
            params,
            global,
            span: start.to(self.prev_span()),
        })
    }

    /// After `type`: `Name[T] = Type` or `Name = extern("name")`.
    fn type_def(&mut self, start: Span) -> PResult<Statement> {
        self.skip_nl();
        let name = self.ident()?;
        let type_params = self.type_params()?;
        if !(self.eat_punct(Punct::Eq) || self.eat_punct(Punct::ColonEq)) {
            return self.expected("`=` in the type definition");
        }
        self.skip_nl();
        let body = if self.is_kw(Kw::Extern) {
            let es = self.advance().span;
            self.expect_punct(Punct::LParen)?;
            self.skip_nl();
            let name = self.string_text()?;
            self.skip_nl();
            self.expect_punct(Punct::RParen)?;
            TypeBody::Extern {
                name,
                span: es.to(self.prev_span()),
            }
        } else {
            TypeBody::Alias(self.ty()?)
        };
        Ok(Statement::TypeDef {
            name,
            type_params,
            body,
            span: start.to(self.prev_span()),
        })
    }

    /// After `module`: `Name { statements }`.
    fn module(&mut self, start: Span) -> PResult<Statement> {
        self.skip_nl();
        let name = self.ident()?;
        self.skip_nl();
        self.expect_punct(Punct::LBrace)?;
        let mut statements = Vec::new();
        self.skip_nl_semis();
        while !self.is_punct(Punct::RBrace) {
            if *self.peek() == Tok::Eof {
                return self.expected("`}` closing the module");
            }
            if self.is_kw(Kw::Include) {
                let sp = self.span();
                let _ = self.err::<()>(
                    sp,
                    "`include` is allowed only at the top level of a file, not inside a module",
                );
                self.advance();
                self.recover();
                self.skip_nl_semis();
                continue;
            }
            let at = self.pos;
            match self.statement() {
                Ok(s) => {
                    statements.push(s);
                    if self.eos().is_err() {
                        self.recover();
                    }
                }
                Err(Fail) => self.recover(),
            }
            if self.pos == at {
                // Nothing consumed (e.g. an `include` inside a module, which `recover` keeps
                // as a statement start): skip the token, or this loop never ends.
                self.advance();
            }
            self.skip_nl_semis();
        }
        self.advance();
        Ok(Statement::Module {
            name,
            statements,
            span: start.to(self.prev_span()),
        })
    }

    /// After `import`: a module path `A.B`.
    fn import(&mut self, start: Span) -> PResult<Statement> {
        let mut path = vec![self.ident()?];
        while self.eat_punct(Punct::Dot) {
            path.push(self.ident()?);
        }
        Ok(Statement::Import {
            path,
            span: start.to(self.prev_span()),
        })
    }

    /// After `in`: `name: Type`, with the annotations read before it.
    fn input(&mut self, start: Span, annotations: Vec<Annotation>) -> PResult<Statement> {
        self.skip_nl();
        let name = self.ident()?;
        if !self.is_punct(Punct::Colon) {
            let _ = self.expected::<()>("`:`");
            if let Some(d) = self.diags.last_mut() {
                d.help = Some(format!(
                    "an input needs its type: `in {}: Events[Int]`",
                    name.name
                ));
            }
            return Err(Fail);
        }
        self.advance();
        self.skip_nl();
        let ty = self.ty()?;
        Ok(Statement::In {
            annotations,
            name,
            ty,
            span: start.to(self.prev_span()),
        })
    }

    /// After `out`: `*`, or an expression with an optional `as name`.
    fn output(&mut self, start: Span, annotations: Vec<Annotation>) -> PResult<Statement> {
        self.skip_nl();
        if self.eat_punct(Punct::Star) {
            return Ok(Statement::OutAll {
                annotations,
                span: start.to(self.prev_span()),
            });
        }
        let expr = self.expr()?;
        let source_text = self
            .text
            .get(expr.span.start as usize..expr.span.end as usize)
            .unwrap_or("")
            .to_string();
        let alias = if self.eat_kw(Kw::As) {
            self.skip_nl();
            Some(self.ident()?)
        } else {
            None
        };
        Ok(Statement::Out(Out {
            annotations,
            expr,
            alias,
            source_text,
            span: start.to(self.prev_span()),
        }))
    }

    pub(super) fn type_params(&mut self) -> PResult<Vec<Ident>> {
        if !self.eat_punct(Punct::LBracket) {
            return Ok(Vec::new());
        }
        Ok(self
            .comma_list(Punct::RBracket, ListForm::NonEmpty, Self::ident)?
            .0)
    }

    pub(super) fn string_text(&mut self) -> PResult<String> {
        match self.peek().clone() {
            Tok::Str { parts, .. } => {
                self.advance();
                Ok(parts
                    .iter()
                    .map(|p| match p {
                        LexStrPart::Text(t) => t.as_str(),
                        LexStrPart::Interp { .. } => "",
                    })
                    .collect())
            }
            _ => self.expected("a string"),
        }
    }

    pub(super) fn def(&mut self) -> PResult<Def> {
        let start = self.span();
        let liftable = self.eat_kw(Kw::Liftable);
        self.skip_nl();
        self.expect_kw(Kw::Def)?;
        self.skip_nl();
        let name = self.ident()?;
        let type_params = self.type_params()?;
        let params = if self.eat_punct(Punct::LParen) {
            Some(self.params_until_close()?)
        } else {
            None
        };
        let result_type = if self.eat_punct(Punct::Colon) {
            self.skip_nl();
            Some(self.ty()?)
        } else {
            None
        };
        if !(self.eat_punct(Punct::Eq) || self.eat_punct(Punct::ColonEq)) {
            if self.is_punct(Punct::EqEq) {
                let sp = self.span();
                self.diags.push(
                    Diagnostic::error(
                        Category::Syntax,
                        Some(sp),
                        "expected `=` in the definition, found `==`",
                    )
                    .with_help("a definition uses a single `=`: `def x = ...`"),
                );
                return Err(Fail);
            }
            return self.expected("`=` or `:=` in the definition");
        }
        self.skip_nl();
        let body = if self.is_kw(Kw::Extern) {
            let es = self.advance().span;
            self.expect_punct(Punct::LParen)?;
            self.skip_nl();
            let ename = self.string_text()?;
            self.skip_nl();
            let arg = if self.eat_punct(Punct::Comma) {
                self.skip_nl();
                Some(self.expr()?)
            } else {
                None
            };
            self.skip_nl();
            self.expect_punct(Punct::RParen)?;
            Body::Extern {
                name: ename,
                arg,
                span: es.to(self.prev_span()),
            }
        } else {
            let expr = self.expr()?;
            self.skip_nl_if(|t| t.is_kw(Kw::Where));
            let mut where_defs = Vec::new();
            if self.eat_kw(Kw::Where) {
                self.skip_nl();
                self.expect_punct(Punct::LBrace)?;
                self.skip_nl_semis();
                while !self.is_punct(Punct::RBrace) {
                    if *self.peek() == Tok::Eof {
                        return self.expected("`}` closing `where`");
                    }
                    where_defs.push(self.def()?);
                    self.eos()?;
                    self.skip_nl_semis();
                }
                self.advance();
            }
            Body::Expr { expr, where_defs }
        };
        Ok(Def {
            liftable,
            name,
            type_params,
            params,
            result_type,
            body,
            span: start.to(self.prev_span()),
        })
    }

    /// Parameters after `(`, up to and including `)`.
    pub(super) fn params_until_close(&mut self) -> PResult<Vec<Param>> {
        Ok(self
            .comma_list(Punct::RParen, ListForm::NoTrailing, Self::param)?
            .0)
    }

    pub(super) fn evaluation(&mut self) -> Evaluation {
        if self.eat_kw(Kw::Strict) {
            Evaluation::Strict
        } else if self.eat_kw(Kw::Lazy) {
            Evaluation::Lazy
        } else {
            Evaluation::Default
        }
    }

    pub(super) fn param(&mut self) -> PResult<Param> {
        let start = self.span();
        let name = self.ident()?;
        let (ty, evaluation) = if self.eat_punct(Punct::Colon) {
            self.skip_nl();
            let ev = self.evaluation();
            (Some(self.ty()?), ev)
        } else {
            (None, Evaluation::Default)
        };
        Ok(Param {
            name,
            ty,
            evaluation,
            span: start.to(self.prev_span()),
        })
    }
}
