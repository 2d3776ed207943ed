//! Recursive-descent parser: tokens -> [`File`] (AST with spans).
//!
//! Owns: TeSSLa 1.2's grammar (statements, types, expressions with TeSSLa's operator precedence,
//! where newlines end a statement and where they may continue one), and syntax-error recovery:
//! after an error the parser skips to the next statement, so one run reports every broken
//! statement. Precedence, tightest first: postfix (call, member, type application), unary
//! (`! ~ - -.`), `* / % *. /.`, `+ - +. -.`, `<< >>`, `&`, `| ^`, comparisons, `&&`, `||`,
//! then `if`/lambda.
//!
//! Here: the token cursor (peek, eat, expect with the unclosed bracket named), the nesting
//! bound, recovery, comma lists and the file loop. Statements are in `statement`, types in
//! `types`, expressions in `expr`; each adds its part of the one `Parser`.

mod expr;
mod statement;
mod types;

use crate::ast::*;
use crate::diag::{Category, Diagnostic};
use crate::lexer::{Kw, LexStrPart, Lexer, Punct, Tok, Token};
use crate::source::{FileId, Span};

/// Parse one source file. Always returns a (possibly partial) file; syntax errors are in the
/// diagnostics.
pub fn parse(text: &str, file: FileId) -> (File, Vec<Diagnostic>) {
    let (tokens, mut diags) = Lexer::new(text, file).tokenize();
    let mut p = Parser {
        toks: tokens,
        pos: 0,
        text,
        diags: Vec::new(),
        depth: 0,
        abandoned: false,
    };
    let f = p.file();
    diags.append(&mut p.diags);
    (f, diags)
}

/// Parse one expression spanning the whole text (newlines allowed around it), as TeSSLa's input
/// traces use for event values (`Some((1, "a"))`, `${x = 2}`, `2 + 40`). `None` with diagnostics
/// when the text is not exactly one expression.
pub fn parse_expr(text: &str, file: FileId) -> (Option<Expr>, Vec<Diagnostic>) {
    let (tokens, mut diags) = Lexer::new(text, file).tokenize();
    let mut p = Parser {
        toks: tokens,
        pos: 0,
        text,
        diags: Vec::new(),
        depth: 0,
        abandoned: false,
    };
    p.skip_nl();
    let e = p.expr().ok();
    p.skip_nl();
    let e = match e {
        Some(e) if *p.peek() == Tok::Eof => Some(e),
        Some(_) => {
            let _ = p.expected::<()>("the end of the value");
            None
        }
        None => None,
    };
    diags.append(&mut p.diags);
    (e, diags)
}

const TIME_UNITS: &[&str] = &["fs", "ps", "ns", "us", "µs", "ms", "s", "min", "h", "d"];

struct Fail;
type PResult<T> = Result<T, Fail>;

/// How a comma-separated list between brackets may be written (see [`Parser::comma_list`]).
#[derive(Clone, Copy, PartialEq, Eq)]
enum ListForm {
    /// May be empty and may end in a comma: call arguments, tuples, records.
    Open,
    /// May be empty, no trailing comma: parameters, tuple and function types.
    NoTrailing,
    /// At least one item, no trailing comma: type parameters and type arguments.
    NonEmpty,
}

struct Parser<'a> {
    toks: Vec<Token>,
    pos: usize,
    text: &'a str,
    diags: Vec<Diagnostic>,
    /// Nesting of statements, expressions and types being parsed (see [`MAX_DEPTH`]).
    depth: usize,
    /// Set when the nesting limit was hit: the rest of the file is skipped and no further
    /// errors are reported (each enclosing level would add one, each quoting a huge line).
    abandoned: bool,
}

/// Deepest nesting of statements, expressions (an operator chain counts one level per operator)
/// and types accepted. The parser, the checker and dropping the tree all recurse along it: a
/// spec nested 100k levels deep overflowed the stack (found writing the broken-spec corpus).
/// Hand-written specs stay far below this.
pub const MAX_DEPTH: usize = 200;

fn describe(t: &Tok) -> String {
    match t {
        Tok::Ident(s) => format!("`{s}`"),
        Tok::Int(i) => format!("`{i}`"),
        Tok::Float(f) => format!("`{f}`"),
        Tok::Str { .. } => "a string".into(),
        Tok::Punct(p) => format!("`{p}`"),
        Tok::Newline => "end of line".into(),
        Tok::Eof => "end of file".into(),
    }
}

impl<'a> Parser<'a> {
    fn sub(&self, tokens: Vec<Token>) -> Parser<'a> {
        Parser {
            toks: tokens,
            pos: 0,
            text: self.text,
            diags: Vec::new(),
            depth: self.depth,
            abandoned: false,
        }
    }

    fn peek(&self) -> &Tok {
        self.peek_n(0)
    }

    fn peek_n(&self, n: usize) -> &Tok {
        self.toks
            .get(self.pos + n)
            .or_else(|| self.toks.last())
            .map_or(&Tok::Eof, |t| &t.tok)
    }

    fn span(&self) -> Span {
        self.toks
            .get(self.pos)
            .or_else(|| self.toks.last())
            .map_or_else(Span::default, |t| t.span)
    }

    fn prev_span(&self) -> Span {
        self.toks
            .get(self.pos.saturating_sub(1))
            .map_or_else(|| self.span(), |t| t.span)
    }

    fn advance(&mut self) -> Token {
        let t = self.toks.get(self.pos).cloned().unwrap_or_else(|| Token {
            tok: Tok::Eof,
            span: self.span(),
        });
        if self.pos < self.toks.len() && t.tok != Tok::Eof {
            self.pos += 1;
        }
        t
    }

    fn is_punct(&self, p: Punct) -> bool {
        self.peek().is_punct(p)
    }

    fn is_kw(&self, k: Kw) -> bool {
        self.peek().is_kw(k)
    }

    fn eat_punct(&mut self, p: Punct) -> bool {
        if self.is_punct(p) {
            self.advance();
            true
        } else {
            false
        }
    }

    fn eat_kw(&mut self, k: Kw) -> bool {
        if self.is_kw(k) {
            self.advance();
            true
        } else {
            false
        }
    }

    fn skip_nl(&mut self) {
        while *self.peek() == Tok::Newline {
            self.advance();
        }
    }

    /// Skip newlines only if the next token after them satisfies `f` (e.g. `else` on a new line).
    fn skip_nl_if(&mut self, f: impl Fn(&Tok) -> bool) {
        let mut n = 0;
        while *self.peek_n(n) == Tok::Newline {
            n += 1;
        }
        if n > 0 && f(self.peek_n(n)) {
            self.pos += n;
        }
    }

    fn err<T>(&mut self, span: Span, msg: impl Into<String>) -> PResult<T> {
        if self.abandoned {
            return Err(Fail);
        }
        self.diags
            .push(Diagnostic::error(Category::Syntax, Some(span), msg));
        Err(Fail)
    }

    fn expected<T>(&mut self, what: &str) -> PResult<T> {
        if self.abandoned {
            return Err(Fail);
        }
        let found = describe(self.peek());
        let mut span = self.span();
        if matches!(self.peek(), Tok::Newline | Tok::Eof) {
            // Point at the end of the line, not across the line break.
            span.end = span.start;
        }
        self.diags.push(
            Diagnostic::error(
                Category::Syntax,
                Some(span),
                format!("expected {what}, found {found}"),
            )
            .with_label(format!("expected {what} here")),
        );
        Err(Fail)
    }

    fn expect_punct(&mut self, p: Punct) -> PResult<Span> {
        if self.is_punct(p) {
            return Ok(self.advance().span);
        }
        let r = self.expected(&format!("`{p}`"));
        let open = match p {
            Punct::RParen => Some(Punct::LParen),
            Punct::RBracket => Some(Punct::LBracket),
            Punct::RBrace => Some(Punct::LBrace),
            _ => None,
        };
        if let Some(open) = open
            && let Some(at) = self.unclosed(open, p)
            && let Some(d) = self.diags.last_mut()
        {
            d.notes_at
                .push((at, format!("unclosed `{open}` opened here")));
            d.help = Some(format!("add the closing `{p}`"));
        }
        r
    }

    /// The span of the nearest `open` before the current token that has no matching `close`.
    fn unclosed(&self, open: Punct, close: Punct) -> Option<Span> {
        let mut depth = 0usize;
        let end = self.pos.min(self.toks.len());
        for t in self.toks.get(..end)?.iter().rev() {
            match &t.tok {
                Tok::Punct(q) if *q == close => depth += 1,
                Tok::Punct(q) if *q == open => {
                    if depth == 0 {
                        return Some(t.span);
                    }
                    depth -= 1;
                }
                _ => {}
            }
        }
        None
    }

    fn expect_kw(&mut self, k: Kw) -> PResult<Span> {
        if self.is_kw(k) {
            Ok(self.advance().span)
        } else {
            self.expected(&format!("`{k}`"))
        }
    }

    fn ident(&mut self) -> PResult<Ident> {
        match self.peek().clone() {
            Tok::Ident(name) if Kw::of(&name).is_none() => {
                let span = self.advance().span;
                Ok(Ident { name, span })
            }
            Tok::Ident(name) => {
                let span = self.span();
                self.diags.push(
                    Diagnostic::error(
                        Category::Syntax,
                        Some(span),
                        format!("`{name}` is a keyword and cannot be used as a name"),
                    )
                    .with_help("choose another name"),
                );
                Err(Fail)
            }
            _ => self.expected("a name"),
        }
    }

    /// Skip to the end of the current statement: a newline or `;` outside brackets, or a line
    /// that starts a new statement (so an unclosed bracket does not swallow the rest of the file).
    fn recover(&mut self) {
        let mut depth = 0i32;
        let mut first = true;
        loop {
            let at_line_start = first
                && self.pos > 0
                && matches!(
                    self.toks.get(self.pos - 1).map(|t| &t.tok),
                    Some(Tok::Newline)
                );
            if at_line_start && self.starts_statement(0) {
                return;
            }
            first = false;
            match self.peek() {
                Tok::Eof => return,
                Tok::Newline if depth <= 0 || self.starts_statement(1) => return,
                Tok::Punct(Punct::Semi) if depth <= 0 => return,
                Tok::Punct(Punct::LParen | Punct::LBracket | Punct::LBrace) => depth += 1,
                Tok::Punct(Punct::RParen | Punct::RBracket | Punct::RBrace) => depth -= 1,
                _ => {}
            }
            self.advance();
        }
    }

    fn starts_statement(&self, n: usize) -> bool {
        match self.peek_n(n) {
            Tok::Ident(k) => matches!(
                Kw::of(k),
                Some(
                    Kw::Def
                        | Kw::Liftable
                        | Kw::In
                        | Kw::Out
                        | Kw::Include
                        | Kw::Type
                        | Kw::Module
                        | Kw::Import
                )
            ),
            Tok::Punct(Punct::At | Punct::AtAt) => true,
            _ => false,
        }
    }

    /// End of statement: newline(s), `;`, or end of file (or a closing `}` of a module/where).
    fn eos(&mut self) -> PResult<()> {
        match self.peek() {
            Tok::Newline => {
                self.skip_nl();
                Ok(())
            }
            Tok::Punct(Punct::Semi) => {
                self.advance();
                self.skip_nl();
                Ok(())
            }
            Tok::Eof | Tok::Punct(Punct::RBrace) => Ok(()),
            Tok::Punct(Punct::Eq) => {
                let r = self.expected("the end of the statement (a new line or `;`)");
                if let Some(d) = self.diags.last_mut() {
                    d.help = Some("use `==` to compare values".into());
                }
                r
            }
            _ => self.expected("the end of the statement (a new line or `;`)"),
        }
    }

    fn file(&mut self) -> File {
        let mut includes = Vec::new();
        let mut statements = Vec::new();
        self.skip_nl_semis();
        while *self.peek() != Tok::Eof {
            if self.is_kw(Kw::Include) {
                let start = self.advance().span;
                match self.peek().clone() {
                    Tok::Str { parts, format } => {
                        let end = self.advance().span;
                        // TeSSLa's rule: an include names its file literally.
                        let interp = parts.iter().find_map(|p| match p {
                            LexStrPart::Interp { span, .. } => Some(*span),
                            LexStrPart::Text(_) => None,
                        });
                        if let Some(sp) = interp.or(format.then_some(end)) {
                            let _ = self.err::<()>(
                                sp,
                                "string interpolation and format specifiers are not allowed in \
                                 `include`: write the file name as it is",
                            );
                            if self.eos().is_err() {
                                self.recover();
                            }
                            continue;
                        }
                        let path = parts
                            .iter()
                            .map(|p| match p {
                                LexStrPart::Text(t) => t.as_str(),
                                LexStrPart::Interp { .. } => "",
                            })
                            .collect();
                        includes.push(Include {
                            path,
                            span: start.to(end),
                        });
                        if self.eos().is_err() {
                            self.recover();
                        }
                    }
                    _ => {
                        let _ = self.expected::<()>("a file name in quotes after `include`");
                        self.recover();
                    }
                }
            } else {
                match self.statement() {
                    Ok(s) => {
                        statements.push(s);
                        if self.is_punct(Punct::RBrace) {
                            let sp = self.span();
                            let _ = self.err::<()>(sp, "unmatched `}`");
                            self.advance();
                        } else if self.eos().is_err() {
                            self.recover();
                        }
                    }
                    Err(Fail) => {
                        self.recover();
                        if self.is_punct(Punct::RBrace) {
                            self.advance();
                        }
                    }
                }
            }
            self.skip_nl_semis();
        }
        File {
            includes,
            statements,
        }
    }

    fn skip_nl_semis(&mut self) {
        while matches!(self.peek(), Tok::Newline | Tok::Punct(Punct::Semi)) {
            self.advance();
        }
    }

    /// Items separated by commas after an opening bracket, up to and including `close`; newlines
    /// may stand around every item and comma. Returns the items and whether the list ended in a
    /// comma (only [`ListForm::Open`] accepts one).
    fn comma_list<T>(
        &mut self,
        close: Punct,
        form: ListForm,
        mut item: impl FnMut(&mut Self) -> PResult<T>,
    ) -> PResult<(Vec<T>, bool)> {
        let mut out = Vec::new();
        self.skip_nl();
        if form != ListForm::NonEmpty && self.eat_punct(close) {
            return Ok((out, false));
        }
        loop {
            out.push(item(self)?);
            self.skip_nl();
            if self.eat_punct(Punct::Comma) {
                self.skip_nl();
                if form == ListForm::Open && self.eat_punct(close) {
                    return Ok((out, true));
                }
                continue;
            }
            self.expect_punct(close)?;
            return Ok((out, false));
        }
    }

    /// Run `f` one level deeper (plus `extra` levels), or report the spec as nested too deeply.
    fn nested<T>(&mut self, extra: usize, f: impl FnOnce(&mut Self) -> PResult<T>) -> PResult<T> {
        if self.depth + extra >= MAX_DEPTH {
            let sp = self.span();
            if !self.abandoned {
                self.abandoned = true;
                self.diags.push(
                    Diagnostic::error(
                        Category::Syntax,
                        Some(sp),
                        format!("nested more than {MAX_DEPTH} levels deep"),
                    )
                    .with_help("split the expression into several `def`s"),
                );
            }
            self.pos = self.toks.len().saturating_sub(1);
            return Err(Fail);
        }
        self.depth += 1;
        let r = f(self);
        self.depth -= 1;
        r
    }

    /// Index of the token after the bracket matching the one at `self.pos + offset`.
    fn after_matching(&self, offset: usize) -> usize {
        let mut depth = 0i32;
        let mut i = self.pos + offset;
        while i < self.toks.len() {
            match &self.toks[i].tok {
                Tok::Punct(Punct::LParen | Punct::LBracket | Punct::LBrace) => depth += 1,
                Tok::Punct(Punct::RParen | Punct::RBracket | Punct::RBrace) => {
                    depth -= 1;
                    if depth == 0 {
                        return i + 1;
                    }
                }
                Tok::Eof => return i,
                _ => {}
            }
            i += 1;
        }
        i
    }

    fn tok_at(&self, i: usize) -> &Tok {
        self.toks.get(i).map_or(&Tok::Eof, |t| &t.tok)
    }
}
