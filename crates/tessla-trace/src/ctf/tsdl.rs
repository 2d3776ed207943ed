//! The CTF 1.8 metadata: TSDL text (plain, or in metadata packets) parsed into the types the
//! binary decoder ([`super::decode`]) reads: the trace's byte order and packet header, the
//! clocks, each stream's packet context, event header and event context, and each event's
//! name, id, context and fields.
//!
//! The subset real traces use (LTTng, barectf, babeltrace's writers): `typealias`/`typedef`,
//! `integer`, `floating_point`, `string`, `enum`, `struct` (named, `align(N)`), `variant`
//! (tagged), arrays and sequences. `env` and `callsite` blocks are skipped. An error names the
//! line and column.

use std::collections::HashMap;
use std::sync::Arc;

/// A metadata error: 1-based line and column, and what was wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TsdlError {
    /// 1-based line of the metadata text.
    pub line: usize,
    /// 1-based column.
    pub col: usize,
    /// What was wrong there.
    pub message: String,
}

type R<T> = Result<T, TsdlError>;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
/// The byte order of an integer or float (`byte_order = native | le | be`).
pub enum Order {
    /// The trace's byte order.
    Native,
    /// Little endian (`le`).
    Le,
    /// Big endian (`be`).
    Be,
}

#[derive(Debug, Clone, PartialEq)]
/// An `integer { ... }` type.
pub struct IntType {
    /// In bits, 1 to 64.
    pub size: u32,
    /// In bits.
    pub align: u32,
    /// `signed = true`: two's complement.
    pub signed: bool,
    /// Its byte order.
    pub order: Order,
    /// The clock this integer holds a value of (`map = clock.NAME.value`).
    pub clock: Option<String>,
}

#[derive(Debug, Clone, PartialEq)]
/// The length of an array (`[N]`) or a sequence (`[field]`).
pub enum Len {
    /// A fixed number of elements.
    Fixed(u64),
    /// A sequence: the path of the integer field holding the length.
    Field(String),
}

#[derive(Debug, Clone, PartialEq)]
/// A field's type in the metadata.
pub enum Type {
    /// An integer.
    Int(IntType),
    /// Exponent and mantissa digits (8/24 or 11/53), alignment, byte order.
    Float {
        /// Exponent digits (`exp_dig`).
        exp: u32,
        /// Mantissa digits (`mant_dig`).
        mant: u32,
        /// Alignment in bits.
        align: u32,
        /// Byte order.
        order: Order,
    },
    /// A null-terminated UTF-8 string (`string`).
    Str,
    /// Labels with their value ranges (inclusive).
    Enum(IntType, Arc<Vec<(String, i128, i128)>>),
    /// A `struct { ... }` of named fields.
    Struct(Arc<StructType>),
    /// A `variant <tag> { ... }`: one of its options, chosen by the enum at `tag`.
    Variant {
        /// The path of the enum field whose label names the option.
        tag: String,
        /// The options by name, in declaration order.
        options: Arc<Vec<(String, Type)>>,
    },
    /// An array or sequence of elements of one type.
    Array(Box<Type>, Len),
}

#[derive(Debug, Clone, PartialEq, Default)]
/// A `struct { ... }` type.
pub struct StructType {
    /// Its fields by name, in declaration order.
    pub fields: Vec<(String, Type)>,
    /// `align(N)`, in bits as all CTF alignments (1 when absent).
    pub align: u32,
}

#[derive(Debug, Clone, PartialEq, Default)]
/// A `clock { ... }` block: what turns a timestamp field's cycles into time.
pub struct Clock {
    /// Its name (`clock.NAME.value` in an integer's `map`).
    pub name: String,
    /// Cycles per second (`freq`, 1 GHz when absent).
    pub freq: u64,
    /// Seconds since the Unix epoch at cycle 0 (`offset_s`).
    pub offset_s: i128,
    /// Cycles added to that (`offset`).
    pub offset: i128,
}

#[derive(Debug, Clone, PartialEq, Default)]
/// A `stream { ... }` block: the types every packet and event of the stream share.
pub struct Stream {
    /// The stream's id (`id`, 0 when absent).
    pub id: u64,
    /// The packet context (`packet.context`): sizes, timestamps, discarded events.
    pub packet_context: Option<Type>,
    /// The event header (`event.header`): the event's id and timestamp.
    pub event_header: Option<Type>,
    /// The context every event of the stream has (`event.context`).
    pub event_context: Option<Type>,
}

#[derive(Debug, Clone, PartialEq)]
/// An `event { ... }` block: one kind of event.
pub struct EventDecl {
    /// Its name (`name`).
    pub name: String,
    /// Its id in its stream (`id`), as the event header gives it.
    pub id: u64,
    /// The stream it belongs to (`stream_id`).
    pub stream_id: u64,
    /// Its own context (`context`).
    pub context: Option<Type>,
    /// Its payload (`fields`).
    pub fields: Option<Type>,
}

/// The parsed metadata.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Metadata {
    /// The trace's byte order (`Order::Le` when not given).
    pub big_endian: bool,
    /// The header every packet starts with (`trace.packet.header`).
    pub packet_header: Option<Type>,
    /// The clocks, in declaration order.
    pub clocks: Vec<Clock>,
    /// The streams, in declaration order.
    pub streams: Vec<Stream>,
    /// The event declarations, in declaration order.
    pub events: Vec<EventDecl>,
}

/// Why a `metadata` file holds no metadata text ([`metadata_text`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MetadataError {
    /// Plain text that is not UTF-8 (the first bad byte).
    #[error("metadata is not UTF-8 text (byte {0})")]
    NotUtf8(usize),
    /// Packets whose text is not UTF-8 (the first bad byte of the text).
    #[error("metadata is not UTF-8 text (byte {0} of its text)")]
    PacketsNotUtf8(usize),
    /// A packet without the magic number (its byte offset).
    #[error("metadata packet at byte {0}: bad magic number")]
    Magic(usize),
    /// A packet whose header is cut short.
    #[error("metadata packet at byte {0}: truncated header")]
    Truncated(usize),
    /// A compressed packet.
    #[error("metadata packet at byte {0}: compressed metadata is not supported")]
    Compressed(usize),
    /// A packet whose sizes do not fit the file.
    #[error(
        "metadata packet at byte {at}: sizes do not fit (content {content} bytes, packet {size} bytes, {left} left)"
    )]
    Sizes {
        /// The packet's byte offset.
        at: usize,
        /// Its content size (bytes).
        content: usize,
        /// Its packet size (bytes).
        size: usize,
        /// Bytes left in the file.
        left: usize,
    },
}

/// The metadata text of a `metadata` file: plain TSDL, or metadata packets (each with a 37-byte
/// header: magic 0x75D11D57, uuid, checksum, content and packet size in bits, ...).
pub fn metadata_text(bytes: &[u8]) -> Result<String, MetadataError> {
    const MAGIC: u32 = 0x75D1_1D57;
    let magic_at = |b: &[u8]| -> Option<bool> {
        let m: [u8; 4] = b.get(..4)?.try_into().ok()?;
        if u32::from_le_bytes(m) == MAGIC {
            Some(false)
        } else if u32::from_be_bytes(m) == MAGIC {
            Some(true)
        } else {
            None
        }
    };
    if magic_at(bytes).is_none() {
        return String::from_utf8(bytes.to_vec())
            .map_err(|e| MetadataError::NotUtf8(e.utf8_error().valid_up_to()));
    }
    let mut text = Vec::new();
    let mut pos = 0usize;
    while pos < bytes.len() {
        let p = &bytes[pos..];
        let Some(be) = magic_at(p) else {
            return Err(MetadataError::Magic(pos));
        };
        let u32_at = |o: usize| -> Option<u32> {
            let b: [u8; 4] = p.get(o..o + 4)?.try_into().ok()?;
            Some(if be {
                u32::from_be_bytes(b)
            } else {
                u32::from_le_bytes(b)
            })
        };
        let (Some(content), Some(size)) = (u32_at(24), u32_at(28)) else {
            return Err(MetadataError::Truncated(pos));
        };
        let (content, size) = (content as usize / 8, size as usize / 8);
        if p.get(32).is_some_and(|&c| c != 0) {
            return Err(MetadataError::Compressed(pos));
        }
        if content < 37 || size < content || p.len() < content {
            return Err(MetadataError::Sizes {
                at: pos,
                content,
                size,
                left: p.len(),
            });
        }
        text.extend_from_slice(&p[37..content]);
        pos += size.max(1);
    }
    String::from_utf8(text).map_err(|e| MetadataError::PacketsNotUtf8(e.utf8_error().valid_up_to()))
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Ident(String),
    Num(i128),
    Str(String),
    /// Punctuation: `{ } ; : = := , [ ] < > ( ) . ... -` and `+`.
    P(&'static str),
}

struct Lexed {
    tok: Tok,
    line: usize,
    col: usize,
}

fn lex(text: &str) -> R<Vec<Lexed>> {
    let chars: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let (mut i, mut line, mut col) = (0usize, 1usize, 1usize);
    let err = |line, col, m: &str| TsdlError {
        line,
        col,
        message: m.to_string(),
    };
    while let Some(&c) = chars.get(i) {
        let (l0, c0) = (line, col);
        let mut adv = |i: &mut usize, n: usize| {
            for _ in 0..n {
                if chars.get(*i) == Some(&'\n') {
                    line += 1;
                    col = 1;
                } else {
                    col += 1;
                }
                *i += 1;
            }
        };
        if c.is_whitespace() {
            adv(&mut i, 1);
        } else if c == '/' && chars.get(i + 1) == Some(&'/') {
            while chars.get(i).is_some_and(|&c| c != '\n') {
                adv(&mut i, 1);
            }
        } else if c == '/' && chars.get(i + 1) == Some(&'*') {
            adv(&mut i, 2);
            loop {
                match chars.get(i) {
                    None => return Err(err(l0, c0, "unterminated comment")),
                    Some('*') if chars.get(i + 1) == Some(&'/') => {
                        adv(&mut i, 2);
                        break;
                    }
                    Some(_) => adv(&mut i, 1),
                }
            }
        } else if c.is_ascii_alphabetic() || c == '_' {
            let start = i;
            while chars
                .get(i)
                .is_some_and(|c| c.is_ascii_alphanumeric() || *c == '_')
            {
                adv(&mut i, 1);
            }
            out.push(Lexed {
                tok: Tok::Ident(chars[start..i].iter().collect()),
                line: l0,
                col: c0,
            });
        } else if c.is_ascii_digit() {
            let start = i;
            while chars.get(i).is_some_and(|c| c.is_ascii_alphanumeric()) {
                adv(&mut i, 1);
            }
            let s: String = chars[start..i].iter().collect();
            let t = s.trim_end_matches(['u', 'U', 'l', 'L']);
            let v = if let Some(h) = t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
                i128::from_str_radix(h, 16).ok()
            } else if t.len() > 1 && t.starts_with('0') {
                i128::from_str_radix(&t[1..], 8).ok()
            } else {
                t.parse().ok()
            };
            let Some(v) = v else {
                return Err(err(l0, c0, &format!("bad number `{s}`")));
            };
            out.push(Lexed {
                tok: Tok::Num(v),
                line: l0,
                col: c0,
            });
        } else if c == '"' {
            adv(&mut i, 1);
            let mut s = String::new();
            loop {
                match chars.get(i) {
                    None => return Err(err(l0, c0, "unterminated string")),
                    Some('"') => {
                        adv(&mut i, 1);
                        break;
                    }
                    Some('\\') => {
                        let e = chars.get(i + 1).copied().unwrap_or('\\');
                        s.push(match e {
                            'n' => '\n',
                            't' => '\t',
                            o => o,
                        });
                        adv(&mut i, 2);
                    }
                    Some(&o) => {
                        s.push(o);
                        adv(&mut i, 1);
                    }
                }
            }
            out.push(Lexed {
                tok: Tok::Str(s),
                line: l0,
                col: c0,
            });
        } else {
            let rest = |s: &str| {
                s.chars()
                    .enumerate()
                    .all(|(k, c)| chars.get(i + k) == Some(&c))
            };
            let p = [
                "...", ":=", "{", "}", ";", ":", "=", ",", "[", "]", "<", ">", "(", ")", ".", "-",
                "+",
            ]
            .into_iter()
            .find(|p| rest(p));
            let Some(p) = p else {
                return Err(err(l0, c0, &format!("unexpected character `{c}`")));
            };
            adv(&mut i, p.len());
            out.push(Lexed {
                tok: Tok::P(p),
                line: l0,
                col: c0,
            });
        }
    }
    Ok(out)
}

/// A value on the right of `=`.
#[derive(Debug, Clone)]
enum Val {
    Num(i128),
    Str(String),
    /// An identifier or a dotted path (`le`, `clock.monotonic.value`).
    Path(String),
}

/// A block's `key = value;` and `key := type;` statements.
type Block = (Vec<(String, Val)>, Vec<(String, Type)>);

struct Parser {
    toks: Vec<Lexed>,
    pos: usize,
    aliases: HashMap<String, Type>,
    structs: HashMap<String, Type>,
    enums: HashMap<String, Type>,
    variants: HashMap<String, Arc<Vec<(String, Type)>>>,
    depth: usize,
}

const MAX_DEPTH: usize = 64;

impl Parser {
    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.pos).map(|l| &l.tok)
    }

    fn peek_at(&self, k: usize) -> Option<&Tok> {
        self.toks.get(self.pos + k).map(|l| &l.tok)
    }

    fn err<T>(&self, m: impl Into<String>) -> R<T> {
        let (line, col) = match self.toks.get(self.pos).or(self.toks.last()) {
            Some(l) => (l.line, l.col),
            None => (1, 1),
        };
        Err(TsdlError {
            line,
            col,
            message: m.into(),
        })
    }

    fn describe(&self) -> String {
        match self.peek() {
            None => "the end of the metadata".into(),
            Some(Tok::Ident(s)) => format!("`{s}`"),
            Some(Tok::Num(n)) => format!("`{n}`"),
            Some(Tok::Str(s)) => format!("\"{s}\""),
            Some(Tok::P(p)) => format!("`{p}`"),
        }
    }

    fn is(&self, p: &str) -> bool {
        matches!(self.peek(), Some(Tok::P(q)) if *q == p)
    }

    fn eat(&mut self, p: &str) -> bool {
        if self.is(p) {
            self.pos += 1;
            true
        } else {
            false
        }
    }

    fn expect(&mut self, p: &str) -> R<()> {
        if self.eat(p) {
            Ok(())
        } else {
            self.err(format!("expected `{p}`, found {}", self.describe()))
        }
    }

    fn is_kw(&self, kw: &str) -> bool {
        matches!(self.peek(), Some(Tok::Ident(s)) if s == kw)
    }

    fn ident(&mut self) -> R<String> {
        match self.peek() {
            Some(Tok::Ident(s)) => {
                let s = s.clone();
                self.pos += 1;
                Ok(s)
            }
            _ => self.err(format!("expected a name, found {}", self.describe())),
        }
    }

    fn number(&mut self) -> R<i128> {
        let neg = self.eat("-");
        match self.peek() {
            Some(Tok::Num(n)) => {
                let n = if neg { -*n } else { *n };
                self.pos += 1;
                Ok(n)
            }
            _ => self.err(format!("expected a number, found {}", self.describe())),
        }
    }

    /// `a.b.c`
    fn path(&mut self) -> R<String> {
        let mut s = self.ident()?;
        while self.is(".") && matches!(self.peek_at(1), Some(Tok::Ident(_))) {
            self.pos += 1;
            s.push('.');
            s.push_str(&self.ident()?);
        }
        Ok(s)
    }

    fn value(&mut self) -> R<Val> {
        match self.peek() {
            Some(Tok::Str(s)) => {
                let s = s.clone();
                self.pos += 1;
                Ok(Val::Str(s))
            }
            Some(Tok::Num(_)) | Some(Tok::P("-")) => Ok(Val::Num(self.number()?)),
            Some(Tok::Ident(_)) => Ok(Val::Path(self.path()?)),
            _ => self.err(format!("expected a value, found {}", self.describe())),
        }
    }

    /// The statements of a `{ ... }` block of `key = value;` and `key := type;` (the `{` read).
    fn block(&mut self) -> R<Block> {
        let (mut vals, mut types) = (Vec::new(), Vec::new());
        while !self.eat("}") {
            if self.peek().is_none() {
                return self.err("expected `}`, found the end of the metadata");
            }
            if self.is_kw("typealias") || self.is_kw("typedef") {
                self.alias()?;
                continue;
            }
            let key = self.path()?;
            if self.eat(":=") {
                types.push((key, self.type_spec(true)?));
            } else {
                self.expect("=")?;
                vals.push((key, self.value()?));
            }
            self.expect(";")?;
        }
        Ok((vals, types))
    }

    /// `typealias TYPE := NAME;` or `typedef TYPE NAME;` (the keyword not yet read).
    fn alias(&mut self) -> R<()> {
        if self.ident()? == "typealias" {
            let t = self.type_spec(true)?;
            self.expect(":=")?;
            let mut name = self.ident()?;
            while let Some(Tok::Ident(s)) = self.peek() {
                name = format!("{name} {s}");
                self.pos += 1;
            }
            self.expect(";")?;
            self.aliases.insert(name, t);
        } else {
            let t = self.type_spec(false)?;
            let (name, t) = self.declarator(t)?;
            self.expect(";")?;
            self.aliases.insert(name, t);
        }
        Ok(())
    }

    /// `name` followed by `[len]`s: the name and its (array) type.
    fn declarator(&mut self, t: Type) -> R<(String, Type)> {
        let name = self.ident()?;
        let mut dims = Vec::new();
        while self.eat("[") {
            let len = match self.peek() {
                Some(Tok::Num(n)) => {
                    let n = u64::try_from(*n).or_else(|_| self.err("negative array length"))?;
                    self.pos += 1;
                    Len::Fixed(n)
                }
                _ => Len::Field(self.path()?),
            };
            self.expect("]")?;
            dims.push(len);
        }
        // `int a[2][3]` is an array of 2 arrays of 3.
        let t = dims
            .into_iter()
            .rev()
            .fold(t, |t, len| Type::Array(Box::new(t), len));
        Ok((name, t))
    }

    /// The fields of a struct or variant body (the `{` read).
    fn fields(&mut self) -> R<Vec<(String, Type)>> {
        let mut fields = Vec::new();
        while !self.eat("}") {
            if self.peek().is_none() {
                return self.err("expected `}`, found the end of the metadata");
            }
            if self.is_kw("typealias") || self.is_kw("typedef") {
                self.alias()?;
                continue;
            }
            let t = self.type_spec(false)?;
            loop {
                fields.push(self.declarator(t.clone())?);
                if !self.eat(",") {
                    break;
                }
            }
            self.expect(";")?;
        }
        Ok(fields)
    }

    fn int_attrs(&mut self) -> R<IntType> {
        self.expect("{")?;
        let (vals, _) = self.block()?;
        let mut t = IntType {
            size: 0,
            align: 0,
            signed: false,
            order: Order::Native,
            clock: None,
        };
        for (k, v) in vals {
            match (k.as_str(), v) {
                ("size", Val::Num(n)) => t.size = u32::try_from(n).unwrap_or(0),
                ("align", Val::Num(n)) => t.align = u32::try_from(n).unwrap_or(0),
                ("signed", Val::Path(p)) => t.signed = p == "true" || p == "TRUE",
                ("signed", Val::Num(n)) => t.signed = n != 0,
                ("byte_order", Val::Path(p)) => t.order = order(&p),
                ("map", Val::Path(p)) => {
                    t.clock = p
                        .strip_prefix("clock.")
                        .and_then(|c| c.strip_suffix(".value"))
                        .map(str::to_string)
                }
                _ => {}
            }
        }
        if !(1..=64).contains(&t.size) {
            return self.err(format!(
                "integer size {} is not supported (1 to 64 bits)",
                t.size
            ));
        }
        if t.align == 0 {
            t.align = if t.size.is_multiple_of(8) { 8 } else { 1 };
        }
        if !t.align.is_power_of_two() {
            return self.err(format!("alignment {} is not a power of two", t.align));
        }
        Ok(t)
    }

    fn int_type(&mut self) -> R<IntType> {
        match self.type_spec(false)? {
            Type::Int(i) => Ok(i),
            _ => self.err("an enum's base type must be an integer"),
        }
    }

    /// A type specifier. `all_idents`: a name of several words runs to the next punctuation
    /// (after `:=`); in a field declaration the last word is the field's name.
    fn type_spec(&mut self, all_idents: bool) -> R<Type> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return self.err("types nested too deeply");
        }
        let t = self.type_spec_inner(all_idents);
        self.depth -= 1;
        t
    }

    fn type_spec_inner(&mut self, all_idents: bool) -> R<Type> {
        let start = self.pos;
        let kw = self.ident()?;
        match kw.as_str() {
            "integer" => Ok(Type::Int(self.int_attrs()?)),
            "floating_point" => {
                self.expect("{")?;
                let (vals, _) = self.block()?;
                let (mut exp, mut mant, mut align, mut ord) = (0, 0, 8, Order::Native);
                for (k, v) in vals {
                    match (k.as_str(), v) {
                        ("exp_dig", Val::Num(n)) => exp = u32::try_from(n).unwrap_or(0),
                        ("mant_dig", Val::Num(n)) => mant = u32::try_from(n).unwrap_or(0),
                        ("align", Val::Num(n)) => align = u32::try_from(n).unwrap_or(0),
                        ("byte_order", Val::Path(p)) => ord = order(&p),
                        _ => {}
                    }
                }
                if !matches!((exp, mant), (8, 24) | (11, 53)) {
                    return self.err(format!(
                        "floating point with exp_dig {exp}, mant_dig {mant} is not supported (8/24 or 11/53)"
                    ));
                }
                if !align.is_power_of_two() {
                    return self.err(format!("alignment {align} is not a power of two"));
                }
                Ok(Type::Float {
                    exp,
                    mant,
                    align,
                    order: ord,
                })
            }
            "string" => {
                if self.eat("{") {
                    self.block()?;
                }
                Ok(Type::Str)
            }
            "struct" => {
                let name = match self.peek() {
                    Some(Tok::Ident(_))
                        if !self.is_kw("align") || self.peek_at(1) != Some(&Tok::P("(")) =>
                    {
                        Some(self.ident()?)
                    }
                    _ => None,
                };
                if !self.eat("{") {
                    let Some(name) = name else {
                        return self.err(format!("expected `{{`, found {}", self.describe()));
                    };
                    return match self.structs.get(&name) {
                        Some(t) => Ok(t.clone()),
                        None => self.err(format!("unknown struct `{name}`")),
                    };
                }
                let fields = self.fields()?;
                let mut align = 1;
                if self.is_kw("align") && self.peek_at(1) == Some(&Tok::P("(")) {
                    self.pos += 2;
                    let n = self.number()?;
                    self.expect(")")?;
                    align = u32::try_from(n)
                        .ok()
                        .filter(|a| a.is_power_of_two())
                        .map_or_else(
                            || self.err(format!("alignment {n} is not a power of two")),
                            Ok,
                        )?;
                }
                let t = Type::Struct(Arc::new(StructType { fields, align }));
                if let Some(n) = name {
                    self.structs.insert(n, t.clone());
                }
                Ok(t)
            }
            "variant" => {
                let name = match self.peek() {
                    Some(Tok::Ident(_)) => Some(self.ident()?),
                    _ => None,
                };
                let tag = if self.eat("<") {
                    let t = self.path()?;
                    self.expect(">")?;
                    Some(t)
                } else {
                    None
                };
                let options = if self.eat("{") {
                    let o = Arc::new(self.fields()?);
                    if let Some(n) = &name {
                        self.variants.insert(n.clone(), o.clone());
                    }
                    o
                } else {
                    match name.as_ref().and_then(|n| self.variants.get(n)) {
                        Some(o) => o.clone(),
                        None => return self.err("unknown variant"),
                    }
                };
                match tag {
                    Some(tag) => Ok(Type::Variant { tag, options }),
                    // An untagged variant declared for later use with a tag.
                    None if name.is_some() => Ok(Type::Variant {
                        tag: String::new(),
                        options,
                    }),
                    None => self.err("a variant needs a tag (`variant <field> { ... }`)"),
                }
            }
            "enum" => {
                let name = match self.peek() {
                    Some(Tok::Ident(_)) => Some(self.ident()?),
                    _ => None,
                };
                let base = if self.eat(":") {
                    self.int_type()?
                } else if self.is("{") {
                    match self.aliases.get("int") {
                        Some(Type::Int(i)) => i.clone(),
                        _ => {
                            return self
                                .err("an enum needs a base type (`enum : uint8_t { ... }`)");
                        }
                    }
                } else {
                    let Some(name) = name else {
                        return self.err(format!("expected `{{`, found {}", self.describe()));
                    };
                    return match self.enums.get(&name) {
                        Some(t) => Ok(t.clone()),
                        None => self.err(format!("unknown enum `{name}`")),
                    };
                };
                self.expect("{")?;
                let mut labels = Vec::new();
                let mut next: i128 = 0;
                while !self.eat("}") {
                    let label = match self.peek() {
                        Some(Tok::Str(s)) => {
                            let s = s.clone();
                            self.pos += 1;
                            s
                        }
                        _ => self.ident()?,
                    };
                    let (lo, hi) = if self.eat("=") {
                        let lo = self.number()?;
                        let hi = if self.eat("...") { self.number()? } else { lo };
                        (lo, hi)
                    } else {
                        (next, next)
                    };
                    next = hi.saturating_add(1);
                    labels.push((label, lo, hi));
                    if !self.eat(",") {
                        self.expect("}")?;
                        break;
                    }
                }
                let t = Type::Enum(base, Arc::new(labels));
                if let Some(n) = name {
                    self.enums.insert(n, t.clone());
                }
                Ok(t)
            }
            _ => {
                let mut name = kw;
                loop {
                    let more = match (self.peek(), self.peek_at(1)) {
                        (Some(Tok::Ident(_)), Some(Tok::Ident(_))) => true,
                        (Some(Tok::Ident(_)), _) => all_idents,
                        _ => false,
                    };
                    if !more {
                        break;
                    }
                    name.push(' ');
                    name.push_str(&self.ident()?);
                }
                match self.aliases.get(&name) {
                    Some(t) => Ok(t.clone()),
                    None => {
                        self.pos = start;
                        self.err(format!("unknown type `{name}`"))
                    }
                }
            }
        }
    }

    fn top(&mut self, md: &mut Metadata) -> R<()> {
        while self.peek().is_some() {
            if self.eat(";") {
                continue;
            }
            if self.is_kw("typealias") || self.is_kw("typedef") {
                self.alias()?;
                continue;
            }
            let kw = match self.peek() {
                Some(Tok::Ident(s)) => s.clone(),
                _ => return self.err(format!("expected a declaration, found {}", self.describe())),
            };
            match kw.as_str() {
                "trace" | "stream" | "event" | "clock" | "env" | "callsite"
                    if self.peek_at(1) == Some(&Tok::P("{")) =>
                {
                    self.pos += 2;
                    let (vals, types) = self.block()?;
                    self.expect(";")?;
                    self.apply(md, &kw, vals, types)?;
                }
                "struct" | "enum" | "variant" => {
                    self.type_spec(false)?;
                    self.expect(";")?;
                }
                _ => return self.err(format!("expected a declaration, found `{kw}`")),
            }
        }
        Ok(())
    }

    fn apply(
        &self,
        md: &mut Metadata,
        kw: &str,
        vals: Vec<(String, Val)>,
        types: Vec<(String, Type)>,
    ) -> R<()> {
        let num = |k: &str| {
            vals.iter().find_map(|(n, v)| match v {
                Val::Num(x) if n == k => Some(*x),
                _ => None,
            })
        };
        let text = |k: &str| {
            vals.iter().find_map(|(n, v)| match v {
                Val::Str(s) | Val::Path(s) if n == k => Some(s.clone()),
                _ => None,
            })
        };
        let ty = |k: &str| types.iter().find(|(n, _)| n == k).map(|(_, t)| t.clone());
        let id = |k: &str| {
            u64::try_from(num(k).unwrap_or(0)).or_else(|_| self.err(format!("negative {k}")))
        };
        match kw {
            "trace" => {
                md.big_endian = matches!(text("byte_order").as_deref(), Some("be" | "network"));
                md.packet_header = ty("packet.header");
            }
            "clock" => md.clocks.push(Clock {
                name: text("name").unwrap_or_default(),
                freq: u64::try_from(num("freq").unwrap_or(1_000_000_000)).unwrap_or(1_000_000_000),
                offset_s: num("offset_s").unwrap_or(0),
                offset: num("offset").unwrap_or(0),
            }),
            "stream" => md.streams.push(Stream {
                id: id("id")?,
                packet_context: ty("packet.context"),
                event_header: ty("event.header"),
                event_context: ty("event.context"),
            }),
            "event" => md.events.push(EventDecl {
                name: text("name").unwrap_or_default(),
                id: id("id")?,
                stream_id: id("stream_id")?,
                context: ty("context"),
                fields: ty("fields"),
            }),
            _ => {}
        }
        Ok(())
    }
}

fn order(p: &str) -> Order {
    match p {
        "le" => Order::Le,
        "be" | "network" => Order::Be,
        _ => Order::Native,
    }
}

/// Parse TSDL metadata text.
pub fn parse(text: &str) -> Result<Metadata, TsdlError> {
    let mut p = Parser {
        toks: lex(text)?,
        pos: 0,
        aliases: HashMap::new(),
        structs: HashMap::new(),
        enums: HashMap::new(),
        variants: HashMap::new(),
        depth: 0,
    };
    let mut md = Metadata::default();
    p.top(&mut md)?;
    Ok(md)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_lttng_style_metadata() {
        let md = parse(
            r#"/* CTF 1.8 */
            typealias integer { size = 8; align = 8; signed = false; } := uint8_t;
            typealias integer { size = 32; align = 8; signed = false; } := unsigned long;
            typealias integer { size = 27; align = 1; signed = false; map = clock.mono.value; } := uint27_t;
            trace { major = 1; minor = 8; byte_order = be;
              packet.header := struct { uint8_t magic; unsigned long stream_id; }; };
            env { hostname = "h"; };
            clock { name = "mono"; freq = 1000; offset_s = 10; offset = -3; };
            stream { id = 0;
              event.header := struct {
                enum : uint8_t { compact = 0 ... 30, extended = 31 } id;
                variant <id> { struct { uint27_t timestamp; } compact; struct { unsigned long id; } extended; } v;
              } align(8); };
            event { name = "a:b"; id = 3; stream_id = 0;
              fields := struct { string s; uint8_t n; uint8_t arr[2][3]; uint8_t seq[n]; }; };
            "#,
        )
        .unwrap();
        assert!(md.big_endian);
        assert_eq!(md.clocks[0].offset, -3);
        assert_eq!(md.clocks[0].freq, 1000);
        assert_eq!(md.events[0].name, "a:b");
        assert_eq!(md.events[0].id, 3);
        let Some(Type::Struct(f)) = &md.events[0].fields else {
            panic!("fields")
        };
        assert_eq!(f.fields[0], ("s".to_string(), Type::Str));
        assert!(
            matches!(&f.fields[2].1, Type::Array(inner, Len::Fixed(2)) if matches!(**inner, Type::Array(_, Len::Fixed(3))))
        );
        assert!(matches!(&f.fields[3].1, Type::Array(_, Len::Field(n)) if n == "n"));
        let Some(Type::Struct(h)) = &md.streams[0].event_header else {
            panic!("header")
        };
        assert_eq!(h.align, 8);
    }

    /// LTTng declares its headers as named structs and refers to them by name; integers of
    /// several words (`unsigned long`); quoted enum labels; `callsite` blocks.
    #[test]
    fn named_structs_and_multi_word_types() {
        let md = parse(
            r#"typealias integer { size = 64; align = 8; signed = false; } := unsigned long;
            typealias integer { size = 8; align = 8; signed = 1; } := int8_t;
            struct packet_context { unsigned long content_size; unsigned long packet_size; } align(8);
            enum level : int8_t { "A b" = -1, C };
            callsite { name = "x"; func = "f"; ip = 0x1234; file = "a.c"; line = 3; };
            stream { id = 1; packet.context := struct packet_context; };
            event { name = "e"; stream_id = 1; fields := struct { enum level l; }; };"#,
        )
        .unwrap();
        let Some(Type::Struct(pc)) = &md.streams[0].packet_context else {
            panic!("packet context")
        };
        assert_eq!(pc.fields.len(), 2);
        assert_eq!(pc.fields[1].0, "packet_size");
        let Some(Type::Struct(f)) = &md.events[0].fields else {
            panic!("fields")
        };
        let Type::Enum(base, labels) = &f.fields[0].1 else {
            panic!("enum")
        };
        assert!(base.signed);
        assert_eq!(
            **labels,
            [("A b".to_string(), -1, -1), ("C".to_string(), 0, 0)]
        );
    }

    #[test]
    fn errors_name_line_and_column() {
        let e = parse("trace {\n  byte_order = le;\n  packet.header := struct { foo x; };\n};")
            .unwrap_err();
        assert_eq!((e.line, e.col), (3, 29));
        assert_eq!(e.message, "unknown type `foo`");
        let e = parse("typealias integer { size = 65; } := big;").unwrap_err();
        assert!(e.message.contains("65"), "{}", e.message);
        let deep = "typealias ".to_string() + &"struct { ".repeat(500);
        assert!(parse(&deep).is_err());
    }
}
