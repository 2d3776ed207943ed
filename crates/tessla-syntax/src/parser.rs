//! Recursive-descent parser: tokens -> [`File`] (AST with spans).
//!
//! Owns: TeSSLa 1.2's grammar (statements, types, expressions with TeSSLa's operator precedence,
//! where newlines end a statement and where they may continue one), and syntax-error recovery:
//! after an error the parser skips to the next statement, so one run reports every broken
//! statement. Precedence, tightest first: postfix (call, member, type application), unary
//! (`! ~ - -.`), `* / % *. /.`, `+ - +. -.`, `<< >>`, `&`, `| ^`, comparisons, `&&`, `||`,
//! then `if`/lambda.

use crate::ast::*;
use crate::diag::{Category, Diagnostic};
use crate::lexer::{LexStrPart, Lexer, Tok, Token};
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

const KEYWORDS: &[&str] = &[
    "def", "liftable", "in", "out", "as", "if", "then", "else", "static", "include", "type",
    "module", "import", "extern", "where", "return", "strict", "lazy", "__root__",
];

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

    fn is_punct(&self, p: &str) -> bool {
        matches!(self.peek(), Tok::Punct(q) if *q == p)
    }

    fn is_kw(&self, k: &str) -> bool {
        matches!(self.peek(), Tok::Ident(s) if s == k)
    }

    fn eat_punct(&mut self, p: &str) -> bool {
        if self.is_punct(p) {
            self.advance();
            true
        } else {
            false
        }
    }

    fn eat_kw(&mut self, k: &str) -> bool {
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

    fn expect_punct(&mut self, p: &str) -> PResult<Span> {
        if self.is_punct(p) {
            return Ok(self.advance().span);
        }
        let r = self.expected(&format!("`{p}`"));
        let open = match p {
            ")" => Some("("),
            "]" => Some("["),
            "}" => Some("{"),
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
    fn unclosed(&self, open: &str, close: &str) -> Option<Span> {
        let mut depth = 0usize;
        let end = self.pos.min(self.toks.len());
        for t in self.toks.get(..end)?.iter().rev() {
            match &t.tok {
                Tok::Punct(q) if *q == close => depth += 1,
                Tok::Punct(q) if *q == open || (open == "{" && *q == "${") => {
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

    fn expect_kw(&mut self, k: &str) -> PResult<Span> {
        if self.is_kw(k) {
            Ok(self.advance().span)
        } else {
            self.expected(&format!("`{k}`"))
        }
    }

    fn ident(&mut self) -> PResult<Ident> {
        match self.peek().clone() {
            Tok::Ident(name) if !KEYWORDS.contains(&name.as_str()) => {
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
                Tok::Punct(";") if depth <= 0 => return,
                Tok::Punct("(" | "[" | "{") => depth += 1,
                Tok::Punct(")" | "]" | "}") => depth -= 1,
                _ => {}
            }
            self.advance();
        }
    }

    fn starts_statement(&self, n: usize) -> bool {
        match self.peek_n(n) {
            Tok::Ident(k) => matches!(
                k.as_str(),
                "def" | "liftable" | "in" | "out" | "include" | "type" | "module" | "import"
            ),
            Tok::Punct("@" | "@@") => true,
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
            Tok::Punct(";") => {
                self.advance();
                self.skip_nl();
                Ok(())
            }
            Tok::Eof | Tok::Punct("}") => Ok(()),
            Tok::Punct("=") => {
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
            if self.is_kw("include") {
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
                        if self.is_punct("}") {
                            let sp = self.span();
                            let _ = self.err::<()>(sp, "unmatched `}`");
                            self.advance();
                        } else if self.eos().is_err() {
                            self.recover();
                        }
                    }
                    Err(Fail) => {
                        self.recover();
                        if self.is_punct("}") {
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
        while matches!(self.peek(), Tok::Newline | Tok::Punct(";")) {
            self.advance();
        }
    }

    fn annotations(&mut self) -> PResult<Vec<Annotation>> {
        let mut out = Vec::new();
        while self.is_punct("@") {
            let start = self.advance().span;
            out.push(self.annotation_inner(start)?);
        }
        Ok(out)
    }

    fn annotation_inner(&mut self, start: Span) -> PResult<Annotation> {
        let name = self.ident()?;
        let mut args = Vec::new();
        if self.eat_punct("(") {
            args = self.args_until_close()?;
        }
        let span = start.to(self.prev_span());
        self.skip_nl();
        Ok(Annotation { name, args, span })
    }

    /// Items separated by commas after an opening bracket, up to and including `close`; newlines
    /// may stand around every item and comma. Returns the items and whether the list ended in a
    /// comma (only [`ListForm::Open`] accepts one).
    fn comma_list<T>(
        &mut self,
        close: &str,
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
            if self.eat_punct(",") {
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

    /// Arguments after `(`, up to and including `)`.
    fn args_until_close(&mut self) -> PResult<Vec<Arg>> {
        let (args, _) = self.comma_list(")", ListForm::Open, |p| {
            let name = match (p.peek(), p.peek_n(1)) {
                (Tok::Ident(n), Tok::Punct("=")) if !KEYWORDS.contains(&n.as_str()) => {
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

    fn statement(&mut self) -> PResult<Statement> {
        self.nested(0, Self::statement_inner)
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

    fn statement_inner(&mut self) -> PResult<Statement> {
        let start = self.span();
        if self.is_punct("@@") {
            self.advance();
            let name = self.ident()?;
            let mut args = Vec::new();
            if self.eat_punct("(") {
                args = self.args_until_close()?;
            }
            let span = start.to(self.prev_span());
            return Ok(Statement::GlobalAnnotation(Annotation { name, args, span }));
        }
        if self.is_kw("def") && matches!(self.peek_n(1), Tok::Punct("@" | "@@")) {
            self.advance();
            let global = self.advance().tok == Tok::Punct("@@");
            let name = self.ident()?;
            let mut params = Vec::new();
            if self.eat_punct("(") {
                params = self.params_until_close()?;
            }
            return Ok(Statement::AnnotationDef {
                name,
                params,
                global,
                span: start.to(self.prev_span()),
            });
        }
        if self.eat_kw("type") {
            self.skip_nl();
            let name = self.ident()?;
            let type_params = self.type_params()?;
            if !(self.eat_punct("=") || self.eat_punct(":=")) {
                return self.expected("`=` in the type definition");
            }
            self.skip_nl();
            let body = if self.is_kw("extern") {
                let es = self.advance().span;
                self.expect_punct("(")?;
                self.skip_nl();
                let name = self.string_text()?;
                self.skip_nl();
                self.expect_punct(")")?;
                TypeBody::Extern {
                    name,
                    span: es.to(self.prev_span()),
                }
            } else {
                TypeBody::Alias(self.ty()?)
            };
            return Ok(Statement::TypeDef {
                name,
                type_params,
                body,
                span: start.to(self.prev_span()),
            });
        }
        if self.eat_kw("module") {
            self.skip_nl();
            let name = self.ident()?;
            self.skip_nl();
            self.expect_punct("{")?;
            let mut statements = Vec::new();
            self.skip_nl_semis();
            while !self.is_punct("}") {
                if *self.peek() == Tok::Eof {
                    return self.expected("`}` closing the module");
                }
                if self.is_kw("include") {
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
            return Ok(Statement::Module {
                name,
                statements,
                span: start.to(self.prev_span()),
            });
        }
        if self.eat_kw("import") {
            let mut path = vec![self.ident()?];
            while self.eat_punct(".") {
                path.push(self.ident()?);
            }
            return Ok(Statement::Import {
                path,
                span: start.to(self.prev_span()),
            });
        }
        let annotations = self.annotations()?;
        if self.eat_kw("in") {
            self.skip_nl();
            let name = self.ident()?;
            if !self.is_punct(":") {
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
            return Ok(Statement::In {
                annotations,
                name,
                ty,
                span: start.to(self.prev_span()),
            });
        }
        if self.eat_kw("out") {
            self.skip_nl();
            if self.eat_punct("*") {
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
            let alias = if self.eat_kw("as") {
                self.skip_nl();
                Some(self.ident()?)
            } else {
                None
            };
            return Ok(Statement::Out(Out {
                annotations,
                expr,
                alias,
                source_text,
                span: start.to(self.prev_span()),
            }));
        }
        if !annotations.is_empty() && !self.is_kw("def") && !self.is_kw("liftable") {
            return self.expected("`in`, `out` or `def` after the annotation");
        }
        if self.is_kw("def") || self.is_kw("liftable") {
            return Ok(Statement::Def(self.def()?));
        }
        self.expected("a statement (`def`, `in`, `out`, `include`, `type`, ...)")
    }

    fn type_params(&mut self) -> PResult<Vec<Ident>> {
        if !self.eat_punct("[") {
            return Ok(Vec::new());
        }
        Ok(self.comma_list("]", ListForm::NonEmpty, Self::ident)?.0)
    }

    fn string_text(&mut self) -> PResult<String> {
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

    fn def(&mut self) -> PResult<Def> {
        let start = self.span();
        let liftable = self.eat_kw("liftable");
        self.skip_nl();
        self.expect_kw("def")?;
        self.skip_nl();
        let name = self.ident()?;
        let type_params = self.type_params()?;
        let params = if self.eat_punct("(") {
            Some(self.params_until_close()?)
        } else {
            None
        };
        let result_type = if self.eat_punct(":") {
            self.skip_nl();
            Some(self.ty()?)
        } else {
            None
        };
        if !(self.eat_punct("=") || self.eat_punct(":=")) {
            if self.is_punct("==") {
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
        let body = if self.is_kw("extern") {
            let es = self.advance().span;
            self.expect_punct("(")?;
            self.skip_nl();
            let ename = self.string_text()?;
            self.skip_nl();
            let arg = if self.eat_punct(",") {
                self.skip_nl();
                Some(self.expr()?)
            } else {
                None
            };
            self.skip_nl();
            self.expect_punct(")")?;
            Body::Extern {
                name: ename,
                arg,
                span: es.to(self.prev_span()),
            }
        } else {
            let expr = self.expr()?;
            self.skip_nl_if(|t| matches!(t, Tok::Ident(s) if s == "where"));
            let mut where_defs = Vec::new();
            if self.eat_kw("where") {
                self.skip_nl();
                self.expect_punct("{")?;
                self.skip_nl_semis();
                while !self.is_punct("}") {
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
    fn params_until_close(&mut self) -> PResult<Vec<Param>> {
        Ok(self.comma_list(")", ListForm::NoTrailing, Self::param)?.0)
    }

    fn evaluation(&mut self) -> Evaluation {
        if self.eat_kw("strict") {
            Evaluation::Strict
        } else if self.eat_kw("lazy") {
            Evaluation::Lazy
        } else {
            Evaluation::Default
        }
    }

    fn param(&mut self) -> PResult<Param> {
        let start = self.span();
        let name = self.ident()?;
        let (ty, evaluation) = if self.eat_punct(":") {
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

    /// Index of the token after the bracket matching the one at `self.pos + offset`.
    fn after_matching(&self, offset: usize) -> usize {
        let mut depth = 0i32;
        let mut i = self.pos + offset;
        while i < self.toks.len() {
            match &self.toks[i].tok {
                Tok::Punct("(" | "[" | "{") => depth += 1,
                Tok::Punct(")" | "]" | "}") => {
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

    fn ty(&mut self) -> PResult<Type> {
        self.nested(0, Self::ty_inner)
    }

    fn ty_inner(&mut self) -> PResult<Type> {
        let start = self.span();
        if self.is_punct("(") {
            let after = self.after_matching(0);
            let is_fn = matches!(self.tok_at(after), Tok::Punct("=>"));
            self.advance();
            let (params, _) = self.comma_list(")", ListForm::NoTrailing, |p| {
                let ev = p.evaluation();
                Ok((ev, p.ty()?))
            })?;
            if is_fn {
                self.expect_punct("=>")?;
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
        if self.eat_punct("{") {
            let (fields, _) = self.comma_list("}", ListForm::Open, |p| {
                let n = p.ident()?;
                p.expect_punct(":")?;
                p.skip_nl();
                Ok((n, p.ty()?))
            })?;
            return Ok(Type::Record {
                fields,
                span: start.to(self.prev_span()),
            });
        }
        let name = self.ident()?;
        if self.eat_punct("[") {
            let (args, _) = self.comma_list("]", ListForm::NonEmpty, Self::ty)?;
            return Ok(Type::App {
                name,
                args,
                span: start.to(self.prev_span()),
            });
        }
        Ok(Type::Name(name))
    }

    // ---- expressions ----

    pub fn expr(&mut self) -> PResult<Expr> {
        self.nested(0, Self::expr_inner)
    }

    fn expr_inner(&mut self) -> PResult<Expr> {
        let start = self.span();
        if self.is_kw("if")
            || (self.is_kw("static") && matches!(self.peek_n(1), Tok::Ident(s) if s == "if"))
        {
            let is_static = self.eat_kw("static");
            self.expect_kw("if")?;
            self.skip_nl();
            let cond = self.expr()?;
            self.skip_nl();
            self.expect_kw("then")?;
            self.skip_nl();
            let then_branch = self.expr()?;
            self.skip_nl_if(|t| matches!(t, Tok::Ident(s) if s == "else"));
            self.expect_kw("else")?;
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
        if self.is_punct("(") {
            let after = self.after_matching(0);
            if matches!(self.tok_at(after), Tok::Punct("=>")) {
                self.advance();
                let params = self.params_until_close()?;
                self.expect_punct("=>")?;
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

    fn binary(&mut self, level: usize) -> PResult<Expr> {
        const LEVELS: &[&[(&str, BinOp)]] = &[
            &[("||", BinOp::Or)],
            &[("&&", BinOp::And)],
            &[
                ("==", BinOp::Eq),
                ("!=", BinOp::Ne),
                ("<", BinOp::Lt),
                (">", BinOp::Gt),
                ("<=", BinOp::Le),
                (">=", BinOp::Ge),
                ("<.", BinOp::FLt),
                (">.", BinOp::FGt),
                ("<=.", BinOp::FLe),
                (">=.", BinOp::FGe),
            ],
            &[("|", BinOp::BitOr), ("^", BinOp::BitXor)],
            &[("&", BinOp::BitAnd)],
            &[("<<", BinOp::Shl), (">>", BinOp::Shr)],
            &[
                ("+", BinOp::Add),
                ("-", BinOp::Sub),
                ("+.", BinOp::FAdd),
                ("-.", BinOp::FSub),
            ],
            &[
                ("*", BinOp::Mul),
                ("/", BinOp::Div),
                ("%", BinOp::Mod),
                ("*.", BinOp::FMul),
                ("/.", BinOp::FDiv),
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
            let rhs = if self.is_kw("if") || self.is_kw("static") {
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

    fn unary(&mut self) -> PResult<Expr> {
        let start = self.span();
        let op = match self.peek() {
            Tok::Punct("!") => Some(UnaryOp::Not),
            Tok::Punct("~") => Some(UnaryOp::BitNot),
            Tok::Punct("-") => Some(UnaryOp::Neg),
            Tok::Punct("-.") => Some(UnaryOp::FNeg),
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

    fn postfix(&mut self) -> PResult<Expr> {
        let mut e = self.primary()?;
        loop {
            if self.is_punct("(") {
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
            } else if self.is_punct("[") {
                self.advance();
                let (type_args, _) = self.comma_list("]", ListForm::NonEmpty, Self::ty)?;
                let args = if self.eat_punct("(") {
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
            } else if self.is_punct(".") {
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

    fn primary(&mut self) -> PResult<Expr> {
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
            Tok::Ident(name) if name == "__root__" => {
                self.advance();
                self.expect_punct(".")?;
                self.skip_nl();
                let id = self.ident()?;
                Ok(Expr {
                    span: start.to(id.span),
                    kind: ExprKind::RootMember(id),
                })
            }
            Tok::Ident(k) if KEYWORDS.contains(&k.as_str()) => self.expected("an expression"),
            Tok::Ident(_) => {
                let id = self.ident()?;
                Ok(Expr {
                    span: id.span,
                    kind: ExprKind::Var(id),
                })
            }
            Tok::Punct("(") => {
                self.advance();
                let (mut elems, trailing) = self.comma_list(")", ListForm::Open, Self::expr)?;
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
            Tok::Punct("{") => self.brace(),
            _ => self.expected("an expression"),
        }
    }

    /// `{` starts a block (`{ def a = 1; a }`, `{ x + 1 }`) or an object literal (`{a = 1, b}`).
    fn brace(&mut self) -> PResult<Expr> {
        let start = self.advance().span;
        self.skip_nl();
        let is_record = match (self.peek(), self.peek_n(1)) {
            (Tok::Punct("}"), _) => true,
            (Tok::Ident(n), Tok::Punct("=" | ":" | ",")) => !KEYWORDS.contains(&n.as_str()),
            // `{a}` is a block whose value is `a`; `{a,\n b}` was handled above.
            (Tok::Ident(_), Tok::Newline | Tok::Punct("}")) => false,
            _ => false,
        };
        if is_record {
            let (members, _) = self.comma_list("}", ListForm::Open, |p| {
                let name = p.ident()?;
                let value = if p.eat_punct("=") || p.eat_punct(":") {
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
        while self.is_kw("def") || self.is_kw("liftable") {
            defs.push(self.def()?);
            self.eos()?;
            self.skip_nl_semis();
        }
        self.eat_kw("return");
        let result = self.expr()?;
        self.skip_nl_semis();
        self.expect_punct("}")?;
        Ok(Expr {
            span: start.to(self.prev_span()),
            kind: ExprKind::Block {
                defs,
                result: Box::new(result),
            },
        })
    }
}
