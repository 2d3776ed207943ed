//! Expressions, with TeSSLa's operator precedence (see the parent module): `if`, lambdas,
//! binary and unary operators, calls, members, type applications, literals, blocks and objects.

use super::*;

impl Parser<'_> {
    pub(super) fn expr(&mut self) -> PResult<Expr> {
        self.nested(0, Self::expr_inner)
    }

    pub(super) fn expr_inner(&mut self) -> PResult<Expr> {
        let start = self.span();
        if self.is_kw(Kw::If) || (self.is_kw(Kw::Static) && self.peek_n(1).is_kw(Kw::If)) {
            let is_static = self.eat_kw(Kw::Static);
            self.expect_kw(Kw::If)?;
            self.skip_nl();
            let cond = self.expr()?;
            self.skip_nl();
            self.expect_kw(Kw::Then)?;
            self.skip_nl();
            let then_branch = self.expr()?;
            self.skip_nl_if(|t| t.is_kw(Kw::Else));
            self.expect_kw(Kw::Else)?;
            self.skip_nl();
            let else_branch = self.expr()?;
            return Ok(Expr {
                span: start.to(else_branch.span),
                kind: ExprKind::If {
                    is_static,
                    cond: Box::new(cond),
                    then_branch: Box::new(then_branch),
                    else_branch: Box::new(else_branch),
                },
            });
        }
        if self.is_punct(Punct::LParen) {
            let after = self.after_matching(0);
            if matches!(self.tok_at(after), Tok::Punct(Punct::FatArrow)) {
                self.advance();
                let params = self.params_until_close()?;
                self.expect_punct(Punct::FatArrow)?;
                self.skip_nl();
                let body = self.expr()?;
                return Ok(Expr {
                    span: start.to(body.span),
                    kind: ExprKind::Lambda {
                        params,
                        body: Box::new(body),
                    },
                });
            }
        }
        self.binary(0)
    }

    pub(super) fn binary(&mut self, level: usize) -> PResult<Expr> {
        const LEVELS: &[&[(Punct, BinOp)]] = &[
            &[(Punct::OrOr, BinOp::Or)],
            &[(Punct::AndAnd, BinOp::And)],
            &[
                (Punct::EqEq, BinOp::Eq),
                (Punct::NotEq, BinOp::Ne),
                (Punct::Lt, BinOp::Lt),
                (Punct::Gt, BinOp::Gt),
                (Punct::Le, BinOp::Le),
                (Punct::Ge, BinOp::Ge),
                (Punct::FLt, BinOp::FLt),
                (Punct::FGt, BinOp::FGt),
                (Punct::FLe, BinOp::FLe),
                (Punct::FGe, BinOp::FGe),
            ],
            &[(Punct::Pipe, BinOp::BitOr), (Punct::Caret, BinOp::BitXor)],
            &[(Punct::Amp, BinOp::BitAnd)],
            &[(Punct::Shl, BinOp::Shl), (Punct::Shr, BinOp::Shr)],
            &[
                (Punct::Plus, BinOp::Add),
                (Punct::Minus, BinOp::Sub),
                (Punct::FPlus, BinOp::FAdd),
                (Punct::FMinus, BinOp::FSub),
            ],
            &[
                (Punct::Star, BinOp::Mul),
                (Punct::Slash, BinOp::Div),
                (Punct::Percent, BinOp::Mod),
                (Punct::FStar, BinOp::FMul),
                (Punct::FSlash, BinOp::FDiv),
            ],
        ];
        let Some(ops) = LEVELS.get(level) else {
            return self.unary();
        };
        let mut lhs = self.binary(level + 1)?;
        // Each operator applied deepens the tree by one level.
        let mut chain = 0;
        loop {
            let op = match self.peek() {
                Tok::Punct(p) => ops.iter().find(|(s, _)| s == p).map(|(_, o)| *o),
                _ => None,
            };
            let Some(op) = op else { break };
            chain += 1;
            self.nested(chain, |_| Ok(()))?;
            self.advance();
            self.skip_nl();
            // `if` and lambdas may appear as the right operand (`a + if c then 1 else 2`).
            let rhs = if self.is_kw(Kw::If) || self.is_kw(Kw::Static) {
                self.expr()?
            } else {
                self.binary(level + 1)?
            };
            lhs = Expr {
                span: lhs.span.to(rhs.span),
                kind: ExprKind::Binary {
                    op,
                    lhs: Box::new(lhs),
                    rhs: Box::new(rhs),
                },
            };
        }
        Ok(lhs)
    }

    pub(super) fn unary(&mut self) -> PResult<Expr> {
        let start = self.span();
        let op = match self.peek() {
            Tok::Punct(Punct::Bang) => Some(UnaryOp::Not),
            Tok::Punct(Punct::Tilde) => Some(UnaryOp::BitNot),
            Tok::Punct(Punct::Minus) => Some(UnaryOp::Neg),
            Tok::Punct(Punct::FMinus) => Some(UnaryOp::FNeg),
            _ => None,
        };
        if let Some(op) = op {
            self.advance();
            self.skip_nl();
            let operand = self.nested(0, Self::unary)?;
            return Ok(Expr {
                span: start.to(operand.span),
                kind: ExprKind::Unary {
                    op,
                    operand: Box::new(operand),
                },
            });
        }
        self.postfix()
    }

    pub(super) fn postfix(&mut self) -> PResult<Expr> {
        let mut e = self.primary()?;
        loop {
            if self.is_punct(Punct::LParen) {
                self.advance();
                let args = self.args_until_close()?;
                e = Expr {
                    span: e.span.to(self.prev_span()),
                    kind: ExprKind::Call {
                        function: Box::new(e),
                        type_args: Vec::new(),
                        args: Some(args),
                    },
                };
            } else if self.is_punct(Punct::LBracket) {
                self.advance();
                let (type_args, _) =
                    self.comma_list(Punct::RBracket, ListForm::NonEmpty, Self::ty)?;
                let args = if self.eat_punct(Punct::LParen) {
                    Some(self.args_until_close()?)
                } else {
                    None
                };
                e = Expr {
                    span: e.span.to(self.prev_span()),
                    kind: ExprKind::Call {
                        function: Box::new(e),
                        type_args,
                        args,
                    },
                };
            } else if self.is_punct(Punct::Dot) {
                self.advance();
                self.skip_nl();
                let field = match self.peek().clone() {
                    // Tuple access `t._1` lexes as an identifier; `t.1` is not TeSSLa.
                    Tok::Ident(name) => {
                        let span = self.advance().span;
                        Ident { name, span }
                    }
                    _ => return self.expected("a member name after `.`"),
                };
                e = Expr {
                    span: e.span.to(field.span),
                    kind: ExprKind::Member {
                        object: Box::new(e),
                        field,
                    },
                };
            } else {
                return Ok(e);
            }
        }
    }

    pub(super) fn primary(&mut self) -> PResult<Expr> {
        let start = self.span();
        match self.peek().clone() {
            Tok::Int(value) => {
                self.advance();
                let unit = match self.peek() {
                    Tok::Ident(u) if TIME_UNITS.contains(&u.as_str()) => {
                        let name = u.clone();
                        let span = self.advance().span;
                        Some(Ident { name, span })
                    }
                    _ => None,
                };
                Ok(Expr {
                    span: start.to(self.prev_span()),
                    kind: ExprKind::Int { value, unit },
                })
            }
            Tok::Float(f) => {
                self.advance();
                Ok(Expr {
                    span: start,
                    kind: ExprKind::Float(f),
                })
            }
            Tok::Str { parts, format } => {
                self.advance();
                let mut out = Vec::new();
                for p in parts {
                    match p {
                        LexStrPart::Text(t) => out.push(StrPart::Text(t)),
                        LexStrPart::Interp { tokens, format, .. } => {
                            let mut sub = self.sub(tokens);
                            sub.skip_nl();
                            let r = sub.expr();
                            sub.skip_nl();
                            if r.is_ok() && *sub.peek() != Tok::Eof {
                                let _ = sub.expected::<()>("`}` ending the interpolation");
                            }
                            let failed = r.is_err() || !sub.diags.is_empty();
                            self.diags.append(&mut sub.diags);
                            match r {
                                Ok(expr) if !failed => out.push(StrPart::Interp { expr, format }),
                                _ => return Err(Fail),
                            }
                        }
                    }
                }
                Ok(Expr {
                    span: start,
                    kind: ExprKind::Str { parts: out, format },
                })
            }
            Tok::Ident(name) if Kw::of(&name) == Some(Kw::Root) => {
                self.advance();
                self.expect_punct(Punct::Dot)?;
                self.skip_nl();
                let id = self.ident()?;
                Ok(Expr {
                    span: start.to(id.span),
                    kind: ExprKind::RootMember(id),
                })
            }
            Tok::Ident(k) if Kw::of(&k).is_some() => self.expected("an expression"),
            Tok::Ident(_) => {
                let id = self.ident()?;
                Ok(Expr {
                    span: id.span,
                    kind: ExprKind::Var(id),
                })
            }
            Tok::Punct(Punct::LParen) => {
                self.advance();
                let (mut elems, trailing) =
                    self.comma_list(Punct::RParen, ListForm::Open, Self::expr)?;
                let span = start.to(self.prev_span());
                if elems.len() == 1 && !trailing {
                    let mut e = elems.pop().ok_or(Fail)?;
                    // Keep the parenthesised span so outputs named by source text include it.
                    e.span = span;
                    return Ok(e);
                }
                Ok(Expr {
                    span,
                    kind: ExprKind::Tuple(elems),
                })
            }
            Tok::Punct(Punct::LBrace) => self.brace(),
            _ => self.expected("an expression"),
        }
    }

    /// `{` starts a block (`{ def a = 1; a }`, `{ x + 1 }`) or an object literal (`{a = 1, b}`).
    pub(super) fn brace(&mut self) -> PResult<Expr> {
        let start = self.advance().span;
        self.skip_nl();
        let is_record = match (self.peek(), self.peek_n(1)) {
            (Tok::Punct(Punct::RBrace), _) => true,
            (Tok::Ident(n), Tok::Punct(Punct::Eq | Punct::Colon | Punct::Comma)) => {
                Kw::of(n).is_none()
            }
            // `{a}` is a block whose value is `a`; `{a,\n b}` was handled above.
            (Tok::Ident(_), Tok::Newline | Tok::Punct(Punct::RBrace)) => false,
            _ => false,
        };
        if is_record {
            let (members, _) = self.comma_list(Punct::RBrace, ListForm::Open, |p| {
                let name = p.ident()?;
                let value = if p.eat_punct(Punct::Eq) || p.eat_punct(Punct::Colon) {
                    p.skip_nl();
                    p.expr()?
                } else {
                    Expr {
                        span: name.span,
                        kind: ExprKind::Var(name.clone()),
                    }
                };
                Ok((name, value))
            })?;
            return Ok(Expr {
                span: start.to(self.prev_span()),
                kind: ExprKind::Record(members),
            });
        }
        let mut defs = Vec::new();
        while self.is_kw(Kw::Def) || self.is_kw(Kw::Liftable) {
            defs.push(self.def()?);
            self.eos()?;
            self.skip_nl_semis();
        }
        self.eat_kw(Kw::Return);
        let result = self.expr()?;
        self.skip_nl_semis();
        self.expect_punct(Punct::RBrace)?;
        Ok(Expr {
            span: start.to(self.prev_span()),
            kind: ExprKind::Block {
                defs,
                result: Box::new(result),
            },
        })
    }
}
