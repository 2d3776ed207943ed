//! The abstract syntax tree of a TeSSLa 1.2 specification, as produced by the parser.
//!
//! Owns: the shape of parsed specs and the source spans on every node. It knows nothing about
//! types, scopes or evaluation; the checker (`spec::check`) consumes it. Every node that can be
//! the subject of a diagnostic carries a [`Span`].

use crate::source::Span;

/// A parsed source file: its includes (already listed, not yet loaded) and its statements.
#[derive(Debug, Clone, PartialEq)]
pub struct File {
    pub includes: Vec<Include>,
    pub statements: Vec<Statement>,
}

/// `include "path"`: the path is relative to the including file.
#[derive(Debug, Clone, PartialEq)]
pub struct Include {
    pub path: String,
    pub span: Span,
}

/// An identifier with its place in the source.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Ident {
    pub name: String,
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Statement {
    Def(Def),
    /// `def @Name(params)` (global = false) or `def @@Name(params)` (global = true).
    AnnotationDef {
        name: Ident,
        params: Vec<Param>,
        global: bool,
        span: Span,
    },
    /// `type Name[T] = body`.
    TypeDef {
        name: Ident,
        type_params: Vec<Ident>,
        body: TypeBody,
        span: Span,
    },
    /// `module Name { ... }`.
    Module {
        name: Ident,
        statements: Vec<Statement>,
        span: Span,
    },
    /// `import A.B`.
    Import {
        path: Vec<Ident>,
        span: Span,
    },
    /// `@A(..) in name: Type`.
    In {
        annotations: Vec<Annotation>,
        name: Ident,
        ty: Type,
        span: Span,
    },
    /// `@A(..) out expr [as name]`; `name` is the text after `as`, or `None` (then the output is
    /// named by the expression's source text, see [`Out::source_text`]).
    Out(Out),
    /// `@A(..) out *`.
    OutAll {
        annotations: Vec<Annotation>,
        span: Span,
    },
    /// `@@Name(args)`.
    GlobalAnnotation(Annotation),
}

#[derive(Debug, Clone, PartialEq)]
pub struct Out {
    pub annotations: Vec<Annotation>,
    pub expr: Expr,
    pub alias: Option<Ident>,
    /// The exact source text of `expr` (TeSSLa names unnamed outputs by it: `out a+1` is "a+1").
    pub source_text: String,
    pub span: Span,
}

/// `@Name(args)` applied to an `in` or `out`, or `@@Name(args)` at top level.
#[derive(Debug, Clone, PartialEq)]
pub struct Annotation {
    pub name: Ident,
    pub args: Vec<Arg>,
    pub span: Span,
}

/// `[liftable] def name[T, U](params): Result = body` or `... := body`.
#[derive(Debug, Clone, PartialEq)]
pub struct Def {
    pub liftable: bool,
    pub name: Ident,
    pub type_params: Vec<Ident>,
    /// `None`: no parameter list at all (`def x = ...`); `Some(vec![])`: `def f() = ...`.
    pub params: Option<Vec<Param>>,
    pub result_type: Option<Type>,
    pub body: Body,
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Body {
    /// An expression, with the definitions of an optional `where { ... }` clause.
    Expr { expr: Expr, where_defs: Vec<Def> },
    /// `extern("name")` (optionally `extern("name", expr)` as in TeSSLa's grammar).
    Extern {
        name: String,
        arg: Option<Expr>,
        span: Span,
    },
}

#[derive(Debug, Clone, PartialEq)]
pub struct Param {
    pub name: Ident,
    pub ty: Option<Type>,
    pub evaluation: Evaluation,
    pub span: Span,
}

/// Parameter evaluation modifiers (`strict` / `lazy`), kept for compatibility.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Evaluation {
    #[default]
    Default,
    Strict,
    Lazy,
}

#[derive(Debug, Clone, PartialEq)]
pub enum TypeBody {
    Alias(Type),
    Extern { name: String, span: Span },
}

#[derive(Debug, Clone, PartialEq)]
pub enum Type {
    /// `Int`, `T`, `Events` (a bare name).
    Name(Ident),
    /// `Events[Int]`, `Option[T]`, `Map[K, V]`.
    App {
        name: Ident,
        args: Vec<Type>,
        span: Span,
    },
    /// `(A, strict B) => R`.
    Function {
        params: Vec<(Evaluation, Type)>,
        result: Box<Type>,
        span: Span,
    },
    /// `{a: Int, b: Bool}`.
    Record {
        fields: Vec<(Ident, Type)>,
        span: Span,
    },
    /// `(A, B)`; `()` is Unit.
    Tuple { elems: Vec<Type>, span: Span },
}

impl Type {
    pub fn span(&self) -> Span {
        match self {
            Type::Name(id) => id.span,
            Type::App { span, .. }
            | Type::Function { span, .. }
            | Type::Record { span, .. }
            | Type::Tuple { span, .. } => *span,
        }
    }
}

/// A call argument, positional or named (`f(a = 1)`).
#[derive(Debug, Clone, PartialEq)]
pub struct Arg {
    pub name: Option<Ident>,
    pub value: Expr,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    pub kind: ExprKind,
    pub span: Span,
}

impl Expr {
    /// `a.b.c` as the string "a.b.c" when the expression is only names and member accesses
    /// (a module path or a qualified name).
    pub fn dotted_path(&self) -> Option<String> {
        match &self.kind {
            ExprKind::Var(id) => Some(id.name.clone()),
            ExprKind::Member { object, field } => {
                Some(format!("{}.{}", object.dotted_path()?, field.name))
            }
            _ => None,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub enum ExprKind {
    Var(Ident),
    /// `__root__.name`.
    RootMember(Ident),
    /// Integer literal; `unit` is the time unit suffix of a time literal (`100ms` -> Some("ms")).
    Int {
        value: i128,
        unit: Option<Ident>,
    },
    Float(f64),
    /// A string literal; plain strings have a single `Text` part.
    Str {
        parts: Vec<StrPart>,
        format: bool,
    },
    /// `(a, b)`; `()` is Unit; `(a)` is parenthesised and the parser returns `a` itself, except
    /// with a trailing comma `(a,)`, which is a one-element tuple.
    Tuple(Vec<Expr>),
    /// `{ def a = 1; def b = 2; a + b }`.
    Block {
        defs: Vec<Def>,
        result: Box<Expr>,
    },
    /// `{a = 1, b: 2}`; a member without value (`{a}`) is `a = a`.
    Record(Vec<(Ident, Expr)>),
    /// `f[T](args)`, or `f[T]` alone (then `args` is `None`).
    Call {
        function: Box<Expr>,
        type_args: Vec<Type>,
        args: Option<Vec<Arg>>,
    },
    /// `obj.field` (record field, tuple `._1`, or module member `String.concat`).
    Member {
        object: Box<Expr>,
        field: Ident,
    },
    Unary {
        op: UnaryOp,
        operand: Box<Expr>,
    },
    Binary {
        op: BinOp,
        lhs: Box<Expr>,
        rhs: Box<Expr>,
    },
    If {
        is_static: bool,
        cond: Box<Expr>,
        then_branch: Box<Expr>,
        else_branch: Box<Expr>,
    },
    Lambda {
        params: Vec<Param>,
        body: Box<Expr>,
    },
}

#[derive(Debug, Clone, PartialEq)]
pub enum StrPart {
    Text(String),
    /// `${expr}` or `$id`, with an optional format specifier (`%.2f`) in format strings.
    Interp {
        expr: Expr,
        format: Option<String>,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnaryOp {
    /// `!`
    Not,
    /// `~`
    BitNot,
    /// `-`
    Neg,
    /// `-.`
    FNeg,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinOp {
    Mul,
    Div,
    Mod,
    FMul,
    FDiv,
    Add,
    Sub,
    FAdd,
    FSub,
    Shl,
    Shr,
    BitAnd,
    BitOr,
    BitXor,
    Eq,
    Ne,
    Lt,
    Gt,
    Le,
    Ge,
    FLt,
    FGt,
    FLe,
    FGe,
    And,
    Or,
}

impl BinOp {
    /// The operator as written in source.
    pub fn symbol(self) -> &'static str {
        use BinOp::*;
        match self {
            Mul => "*",
            Div => "/",
            Mod => "%",
            FMul => "*.",
            FDiv => "/.",
            Add => "+",
            Sub => "-",
            FAdd => "+.",
            FSub => "-.",
            Shl => "<<",
            Shr => ">>",
            BitAnd => "&",
            BitOr => "|",
            BitXor => "^",
            Eq => "==",
            Ne => "!=",
            Lt => "<",
            Gt => ">",
            Le => "<=",
            Ge => ">=",
            FLt => "<.",
            FGt => ">.",
            FLe => "<=.",
            FGe => ">=.",
            And => "&&",
            Or => "||",
        }
    }
}
