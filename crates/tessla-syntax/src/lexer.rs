//! Tokens of TeSSLa 1.2 source text.
//!
//! Owns: the keywords ([`Kw`]) and punctuation marks ([`Punct`]) of TeSSLa 1.2, and turning
//! text into [`Token`]s with spans: identifiers, numbers, operators, significant
//! newlines, and string literals (with `${expr}`/`$id` interpolation lexed into nested token lists,
//! and `f"..."` format specifiers). Comments (`#`, `--`, doc lines `---`/`##`) and escaped newlines
//! are skipped; the newline ending a comment is kept, since newlines end statements.
//!
//! Hand-written: string interpolation needs nested lexer modes, and newline significance depends
//! on the parser's context, which lexer generators such as logos do not express directly.

use crate::diag::{Category, Diagnostic};
use crate::source::{FileId, Span};

#[derive(Debug, Clone, PartialEq)]
/// A token of TeSSLa's source text.
pub enum Tok {
    /// A name: `x`, `Events`, `__root__`.
    Ident(String),
    /// An integer literal (decimal or `0x` hexadecimal), its value.
    Int(i128),
    /// A float literal: `1.5`, `2e-3`.
    Float(f64),
    /// A string literal, `"..."` or `f"..."`, split at its interpolations.
    Str {
        /// Its text and `${...}` parts, in order.
        parts: Vec<LexStrPart>,
        /// `f"..."`: a format string.
        format: bool,
    },
    /// An operator or punctuation, e.g. `+.`, `(`, `=>`.
    Punct(Punct),
    /// A line break (it ends a statement where one can end).
    Newline,
    /// The end of the text.
    Eof,
}

#[derive(Debug, Clone, PartialEq)]
/// A part of a string literal as the lexer splits it.
pub enum LexStrPart {
    /// Literal text, escapes resolved.
    Text(String),
    /// The tokens of `${ ... }` (without the braces) or of `$id`, then an optional format.
    Interp {
        /// The interpolation's tokens, for the parser.
        tokens: Vec<Token>,
        /// Where the interpolation is written.
        span: Span,
        /// The `%` format specifier after it, in a format string.
        format: Option<String>,
    },
}

#[derive(Debug, Clone, PartialEq)]
/// A token with its place in the source.
pub struct Token {
    /// What was read.
    pub tok: Tok,
    /// Where it was read.
    pub span: Span,
}

/// A reserved word of TeSSLa 1.2. The lexer reads words as [`Tok::Ident`] (a keyword may still
/// name a record field or a member); the parser asks [`Tok::is_kw`] where a keyword may stand
/// and refuses one where a name must.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kw {
    /// `def`
    Def,
    /// `liftable`
    Liftable,
    /// `in`
    In,
    /// `out`
    Out,
    /// `as`
    As,
    /// `if`
    If,
    /// `then`
    Then,
    /// `else`
    Else,
    /// `static`
    Static,
    /// `include`
    Include,
    /// `type`
    Type,
    /// `module`
    Module,
    /// `import`
    Import,
    /// `extern`
    Extern,
    /// `where`
    Where,
    /// `return`
    Return,
    /// `strict`
    Strict,
    /// `lazy`
    Lazy,
    /// `__root__`
    Root,
}

const KEYWORDS: &[(&str, Kw)] = &[
    ("def", Kw::Def),
    ("liftable", Kw::Liftable),
    ("in", Kw::In),
    ("out", Kw::Out),
    ("as", Kw::As),
    ("if", Kw::If),
    ("then", Kw::Then),
    ("else", Kw::Else),
    ("static", Kw::Static),
    ("include", Kw::Include),
    ("type", Kw::Type),
    ("module", Kw::Module),
    ("import", Kw::Import),
    ("extern", Kw::Extern),
    ("where", Kw::Where),
    ("return", Kw::Return),
    ("strict", Kw::Strict),
    ("lazy", Kw::Lazy),
    ("__root__", Kw::Root),
];

impl Kw {
    /// The keyword `word` is, if it is one.
    pub fn of(word: &str) -> Option<Kw> {
        KEYWORDS.iter().find(|(w, _)| *w == word).map(|(_, k)| *k)
    }

    /// The keyword as written.
    pub fn as_str(self) -> &'static str {
        KEYWORDS
            .iter()
            .find(|(_, k)| *k == self)
            .map_or("?", |(w, _)| w)
    }
}

impl std::fmt::Display for Kw {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl Tok {
    /// Whether this token is the keyword `k`.
    pub fn is_kw(&self, k: Kw) -> bool {
        matches!(self, Tok::Ident(s) if s == k.as_str())
    }

    /// Whether this token is the punctuation mark `p`.
    pub fn is_punct(&self, p: Punct) -> bool {
        *self == Tok::Punct(p)
    }
}

/// An operator or punctuation mark of TeSSLa 1.2.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Punct {
    /// `>=.`
    FGe,
    /// `<=.`
    FLe,
    /// `&&`
    AndAnd,
    /// `||`
    OrOr,
    /// `==`
    EqEq,
    /// `!=`
    NotEq,
    /// `<=`
    Le,
    /// `>=`
    Ge,
    /// `<<`
    Shl,
    /// `>>`
    Shr,
    /// `<.`
    FLt,
    /// `>.`
    FGt,
    /// `+.`
    FPlus,
    /// `-.`
    FMinus,
    /// `*.`
    FStar,
    /// `/.`
    FSlash,
    /// `:=`
    ColonEq,
    /// `=>`
    FatArrow,
    /// `@@`
    AtAt,
    /// `+`
    Plus,
    /// `-`
    Minus,
    /// `*`
    Star,
    /// `/`
    Slash,
    /// `%`
    Percent,
    /// `<`
    Lt,
    /// `>`
    Gt,
    /// `=`
    Eq,
    /// `!`
    Bang,
    /// `~`
    Tilde,
    /// `&`
    Amp,
    /// `|`
    Pipe,
    /// `^`
    Caret,
    /// `(`
    LParen,
    /// `)`
    RParen,
    /// `[`
    LBracket,
    /// `]`
    RBracket,
    /// `{`
    LBrace,
    /// `}`
    RBrace,
    /// `,`
    Comma,
    /// `;`
    Semi,
    /// `:`
    Colon,
    /// `.`
    Dot,
    /// `@`
    At,
}

/// Every punctuation mark with its text, longest first, so that `>=.` wins over `>=` and `>`.
const PUNCTS: &[(&str, Punct)] = &[
    (">=.", Punct::FGe),
    ("<=.", Punct::FLe),
    ("&&", Punct::AndAnd),
    ("||", Punct::OrOr),
    ("==", Punct::EqEq),
    ("!=", Punct::NotEq),
    ("<=", Punct::Le),
    (">=", Punct::Ge),
    ("<<", Punct::Shl),
    (">>", Punct::Shr),
    ("<.", Punct::FLt),
    (">.", Punct::FGt),
    ("+.", Punct::FPlus),
    ("-.", Punct::FMinus),
    ("*.", Punct::FStar),
    ("/.", Punct::FSlash),
    (":=", Punct::ColonEq),
    ("=>", Punct::FatArrow),
    ("@@", Punct::AtAt),
    ("+", Punct::Plus),
    ("-", Punct::Minus),
    ("*", Punct::Star),
    ("/", Punct::Slash),
    ("%", Punct::Percent),
    ("<", Punct::Lt),
    (">", Punct::Gt),
    ("=", Punct::Eq),
    ("!", Punct::Bang),
    ("~", Punct::Tilde),
    ("&", Punct::Amp),
    ("|", Punct::Pipe),
    ("^", Punct::Caret),
    ("(", Punct::LParen),
    (")", Punct::RParen),
    ("[", Punct::LBracket),
    ("]", Punct::RBracket),
    ("{", Punct::LBrace),
    ("}", Punct::RBrace),
    (",", Punct::Comma),
    (";", Punct::Semi),
    (":", Punct::Colon),
    (".", Punct::Dot),
    ("@", Punct::At),
];

impl Punct {
    /// The mark as written in source text.
    pub fn as_str(self) -> &'static str {
        PUNCTS
            .iter()
            .find(|(_, p)| *p == self)
            .map_or("?", |(text, _)| text)
    }
}

impl std::fmt::Display for Punct {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Turns one file's text into [`Token`]s, collecting what it cannot read as diagnostics.
pub struct Lexer<'a> {
    text: &'a str,
    pos: usize,
    file: FileId,
    /// What could not be read (a bad character, an unterminated string), in order.
    pub diagnostics: Vec<Diagnostic>,
    /// `${` interpolations open around the current position (see [`MAX_INTERPOLATION`]).
    nesting: usize,
    /// Whether too deep an interpolation was reported (once per file).
    too_deep: bool,
}

/// Deepest nesting of `${ ... }` inside strings: lexing recurses along it (5000 levels
/// overflowed the stack; found while writing tests/fixtures/broken-specs).
pub const MAX_INTERPOLATION: usize = 32;

/// Letters, `_`, and (as TeSSLa allows emoji names) any other non-ASCII symbol.
fn is_ident_start(c: char) -> bool {
    c == '_' || c.is_alphabetic() || (!c.is_ascii() && !c.is_whitespace() && !c.is_numeric())
}

fn is_ident_char(c: char) -> bool {
    is_ident_start(c) || c.is_alphanumeric()
}

impl<'a> Lexer<'a> {
    /// A lexer at the start of `text`, the content of `file`.
    pub fn new(text: &'a str, file: FileId) -> Lexer<'a> {
        Lexer {
            text,
            pos: 0,
            file,
            diagnostics: Vec::new(),
            nesting: 0,
            too_deep: false,
        }
    }

    fn span(&self, start: usize) -> Span {
        Span::new(self.file, start, self.pos)
    }

    fn peek(&self) -> Option<char> {
        self.text.get(self.pos..).and_then(|s| s.chars().next())
    }

    fn peek_at(&self, n: usize) -> Option<char> {
        self.text.get(self.pos..).and_then(|s| s.chars().nth(n))
    }

    fn rest(&self) -> &'a str {
        self.text.get(self.pos..).unwrap_or("")
    }

    fn bump(&mut self) -> Option<char> {
        let c = self.peek()?;
        self.pos += c.len_utf8();
        Some(c)
    }

    fn error(&mut self, span: Span, msg: impl Into<String>) {
        self.diagnostics
            .push(Diagnostic::error(Category::Syntax, Some(span), msg));
    }

    /// Lex the whole text; the last token is [`Tok::Eof`].
    pub fn tokenize(mut self) -> (Vec<Token>, Vec<Diagnostic>) {
        let toks = self.tokens_until(None);
        (toks, self.diagnostics)
    }

    /// Lex tokens until EOF, or (inside `${ ... }`) until the `}` closing the interpolation,
    /// which is consumed but not returned.
    fn tokens_until(&mut self, close_brace: Option<usize>) -> Vec<Token> {
        let mut out = Vec::new();
        let mut depth = 0usize;
        loop {
            self.skip_space_and_comments();
            let start = self.pos;
            let Some(c) = self.peek() else {
                if let Some(open) = close_brace {
                    let sp = Span::new(self.file, open, open + 2);
                    self.error(sp, "unterminated `${` in a string: add the closing `}`");
                }
                out.push(Token {
                    tok: Tok::Eof,
                    span: self.span(start),
                });
                return out;
            };
            if c == '\n' || (c == '\r' && self.peek_at(1) == Some('\n')) {
                self.bump();
                if c == '\r' {
                    self.bump();
                }
                out.push(Token {
                    tok: Tok::Newline,
                    span: self.span(start),
                });
                continue;
            }
            if close_brace.is_some() && c == '}' && depth == 0 {
                self.bump();
                out.push(Token {
                    tok: Tok::Eof,
                    span: self.span(start),
                });
                return out;
            }
            let tok = if c == '"' {
                self.bump();
                self.string(start, false)
            } else if c == 'f' && self.peek_at(1) == Some('"') {
                self.bump();
                self.bump();
                self.string(start, true)
            } else if is_ident_start(c) {
                while self.peek().is_some_and(is_ident_char) {
                    self.bump();
                }
                Tok::Ident(self.text[start..self.pos].to_string())
            } else if c.is_ascii_digit() {
                self.number(start)
            } else if c == '$' && self.peek_at(1) == Some('{') {
                // `${` outside strings opens an object literal, like `{`.
                self.bump();
                self.bump();
                depth += 1;
                Tok::Punct(Punct::LBrace)
            } else if let Some(&(text, p)) =
                PUNCTS.iter().find(|(t, _)| self.rest().starts_with(*t))
            {
                self.pos += text.len();
                match p {
                    Punct::LBrace => depth += 1,
                    Punct::RBrace => depth = depth.saturating_sub(1),
                    _ => {}
                }
                Tok::Punct(p)
            } else {
                self.bump();
                let sp = self.span(start);
                self.error(sp, format!("unexpected character `{}`", c.escape_debug()));
                continue;
            };
            out.push(Token {
                tok,
                span: self.span(start),
            });
        }
    }

    fn skip_space_and_comments(&mut self) {
        loop {
            match self.peek() {
                Some(' ' | '\t') => {
                    self.bump();
                }
                Some('\r') if self.peek_at(1) != Some('\n') => {
                    self.bump();
                }
                Some('\\') if self.peek_at(1) == Some('\n') => {
                    self.bump();
                    self.bump();
                }
                Some('#') => self.skip_line(),
                Some('-') if self.peek_at(1) == Some('-') => self.skip_line(),
                _ => return,
            }
        }
    }

    fn skip_line(&mut self) {
        while let Some(c) = self.peek() {
            if c == '\n' {
                return;
            }
            self.bump();
        }
    }

    fn number(&mut self, start: usize) -> Tok {
        if self.rest().starts_with("0x") && self.peek_at(2).is_some_and(|c| c.is_ascii_hexdigit()) {
            self.pos += 2;
            let ds = self.pos;
            while self.peek().is_some_and(|c| c.is_ascii_hexdigit()) {
                self.bump();
            }
            return match i128::from_str_radix(&self.text[ds..self.pos], 16) {
                Ok(v) => Tok::Int(v),
                Err(_) => {
                    let sp = self.span(start);
                    self.error(sp, "integer literal too large");
                    Tok::Int(0)
                }
            };
        }
        while self.peek().is_some_and(|c| c.is_ascii_digit()) {
            self.bump();
        }
        let mut is_float = false;
        if self.peek() == Some('.') && self.peek_at(1).is_some_and(|c| c.is_ascii_digit()) {
            is_float = true;
            self.bump();
            while self.peek().is_some_and(|c| c.is_ascii_digit()) {
                self.bump();
            }
        }
        if self.peek() == Some('e') {
            let sign = matches!(self.peek_at(1), Some('+' | '-'));
            let digit_at = if sign { 2 } else { 1 };
            if self.peek_at(digit_at).is_some_and(|c| c.is_ascii_digit()) {
                is_float = true;
                for _ in 0..digit_at {
                    self.bump();
                }
                while self.peek().is_some_and(|c| c.is_ascii_digit()) {
                    self.bump();
                }
            }
        }
        let text = &self.text[start..self.pos];
        if is_float {
            match text.parse::<f64>() {
                Ok(v) => Tok::Float(v),
                Err(_) => {
                    let sp = self.span(start);
                    self.error(sp, "malformed float literal");
                    Tok::Float(0.0)
                }
            }
        } else {
            match text.parse::<i128>() {
                Ok(v) => Tok::Int(v),
                Err(_) => {
                    let sp = self.span(start);
                    self.error(sp, "integer literal too large");
                    Tok::Int(0)
                }
            }
        }
    }

    /// After the opening quote: text, escapes, interpolations, formats, up to the closing quote.
    fn string(&mut self, start: usize, format: bool) -> Tok {
        let mut parts = Vec::new();
        let mut text = String::new();
        loop {
            let Some(c) = self.peek() else {
                let sp = self.span(start);
                self.error(sp, "unterminated string literal: add the closing `\"`");
                break;
            };
            match c {
                '"' => {
                    self.bump();
                    break;
                }
                '\\' => {
                    let es = self.pos;
                    self.bump();
                    match self.bump() {
                        Some('n') => text.push('\n'),
                        Some('t') => text.push('\t'),
                        Some('r') => text.push('\r'),
                        Some('"') => text.push('"'),
                        Some('\\') => text.push('\\'),
                        Some('$') => text.push('$'),
                        Some('%') => text.push('%'),
                        Some('a') => text.push('\u{7}'),
                        Some(other) => {
                            // Reported here (TeSSLa reports it when translating the literal);
                            // the text is kept so the rest of the file still parses.
                            let sp = self.span(es);
                            self.diagnostics.push(
                                Diagnostic::error(
                                    Category::Syntax,
                                    Some(sp),
                                    format!("Invalid escape sequence '\\{other}' in string"),
                                )
                                .with_help(
                                    "valid escapes are \\n \\r \\t \\a \\\\ \\\" \\$ \\%; \
                                     write \\\\ for a backslash",
                                ),
                            );
                            text.push('\\');
                            text.push(other);
                        }
                        None => {}
                    }
                }
                '$' if self.peek_at(1) == Some('{') && self.nesting >= MAX_INTERPOLATION => {
                    let sp = Span::new(self.file, self.pos, self.pos + 2);
                    if !self.too_deep {
                        self.too_deep = true;
                        self.error(
                            sp,
                            format!(
                                "string interpolations nested more than {MAX_INTERPOLATION} deep"
                            ),
                        );
                    }
                    // Kept as text, so lexing goes on.
                    self.bump();
                    text.push('$');
                }
                '$' if self.peek_at(1) == Some('{') => {
                    let is = self.pos;
                    self.bump();
                    self.bump();
                    if !text.is_empty() {
                        parts.push(LexStrPart::Text(std::mem::take(&mut text)));
                    }
                    self.nesting += 1;
                    let tokens = self.tokens_until(Some(is));
                    self.nesting -= 1;
                    let span = self.span(is);
                    let fmt = if format { self.format_spec() } else { None };
                    parts.push(LexStrPart::Interp {
                        tokens,
                        span,
                        format: fmt,
                    });
                }
                '$' if self.peek_at(1).is_some_and(is_ident_start) => {
                    let is = self.pos;
                    self.bump();
                    let ids = self.pos;
                    while self.peek().is_some_and(is_ident_char) {
                        self.bump();
                    }
                    if !text.is_empty() {
                        parts.push(LexStrPart::Text(std::mem::take(&mut text)));
                    }
                    let span = self.span(is);
                    let id = Token {
                        tok: Tok::Ident(self.text[ids..self.pos].to_string()),
                        span: Span::new(self.file, ids, self.pos),
                    };
                    let eof = Token {
                        tok: Tok::Eof,
                        span: Span::new(self.file, self.pos, self.pos),
                    };
                    let fmt = if format { self.format_spec() } else { None };
                    parts.push(LexStrPart::Interp {
                        tokens: vec![id, eof],
                        span,
                        format: fmt,
                    });
                }
                _ => {
                    self.bump();
                    text.push(c);
                }
            }
        }
        if !text.is_empty() || parts.is_empty() {
            parts.push(LexStrPart::Text(text));
        }
        Tok::Str { parts, format }
    }

    /// A `%...` format specifier directly after an interpolation in an `f"..."` string.
    fn format_spec(&mut self) -> Option<String> {
        if self.peek() != Some('%') {
            return None;
        }
        let s = self.pos;
        self.bump();
        while self
            .peek()
            .is_some_and(|c| "-#+ 0,(".contains(c) || c.is_ascii_digit() || c == '.')
        {
            self.bump();
        }
        if self.peek().is_some_and(|c| !matches!(c, '\\' | '$' | '"')) {
            self.bump();
        }
        Some(self.text[s..self.pos].to_string())
    }
}
