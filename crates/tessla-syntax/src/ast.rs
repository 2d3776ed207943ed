//! The abstract syntax tree of a TeSSLa 1.2 specification, as produced by the parser.
//!
//! Owns: the shape of parsed specs and the source spans on every node. It knows nothing about
//! types, scopes or evaluation; the checker (`spec::check`) consumes it. Every node that can be
//! the subject of a diagnostic carries a [`Span`].

use crate::source::Span;

/// A parsed source file: its includes (already listed, not yet loaded) and its statements.
#[derive(Debug, Clone, PartialEq)]
pub struct File {
    /// Its `include "path"` lines, in order.
    pub includes: Vec<Include>,
    /// Everything else, in source order.
    pub statements: Vec<Statement>,
}

/// `include "path"`: the path is relative to the including file.
#[derive(Debug, Clone, PartialEq)]
pub struct Include {
    /// The quoted path, as written.
    pub path: String,
    /// The whole `include "path"`.
    pub span: Span,
}

/// An identifier with its place in the source.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Ident {
    /// The name as written (`x`, `Events`, `lidar_0`).
    pub name: String,
    /// Where it is written.
    pub span: Span,
}

/// A top-level (or module-level) statement of a TeSSLa file.
#[derive(Debug, Clone, PartialEq)]
pub enum Statement {
    /// `def name = expr`, `def f(x: Int): Int = expr`, `liftable def ...`.
    Def(Def),
    /// `def @Name(params)` (global = false) or `def @@Name(params)` (global = true).
    AnnotationDef {
        /// The annotation's name (without `@`).
        name: Ident,
        /// Its parameters, typed.
        params: Vec<Param>,
        /// `@@` (a global annotation) rather than `@`.
        global: bool,
        /// The whole definition.
        span: Span,
    },
    /// `type Name[T] = body`.
    TypeDef {
        /// The type's name.
        name: Ident,
        /// `[T, U]`: its type parameters.
        type_params: Vec<Ident>,
        /// What it stands for.
        body: TypeBody,
        /// The whole definition.
        span: Span,
    },
    /// `module Name { ... }`.
    Module {
        /// The module's name.
        name: Ident,
        /// The statements between the braces.
        statements: Vec<Statement>,
        /// The whole module.
        span: Span,
    },
    /// `import A.B`.
    Import {
        /// The module path's parts: `A`, `B`.
        path: Vec<Ident>,
        /// The whole `import`.
        span: Span,
    },
    /// `@A(..) in name: Type`.
    In {
        /// The `@A(..)` annotations before `in`.
        annotations: Vec<Annotation>,
        /// The input stream's name.
        name: Ident,
        /// Its declared type (`Events[Int]`).
        ty: Type,
        /// The whole declaration.
        span: Span,
    },
    /// `@A(..) out expr [as name]`; `name` is the text after `as`, or `None` (then the output is
    /// named by the expression's source text, see [`Out::source_text`]).
    Out(Out),
    /// `@A(..) out *`.
    OutAll {
        /// The `@A(..)` annotations before `out *`.
        annotations: Vec<Annotation>,
        /// The whole `out *`.
        span: Span,
    },
    /// `@@Name(args)`.
    GlobalAnnotation(Annotation),
}

/// `@A(..) out expr [as name]`: an output stream.
#[derive(Debug, Clone, PartialEq)]
pub struct Out {
    /// The `@A(..)` annotations before `out`.
    pub annotations: Vec<Annotation>,
    /// The stream written out.
    pub expr: Expr,
    /// The name after `as`, if any.
    pub alias: Option<Ident>,
    /// The exact source text of `expr` (TeSSLa names unnamed outputs by it: `out a+1` is "a+1").
    pub source_text: String,
    /// The whole `out`.
    pub span: Span,
}

/// `@Name(args)` applied to an `in` or `out`, or `@@Name(args)` at top level.
#[derive(Debug, Clone, PartialEq)]
pub struct Annotation {
    /// The annotation's name (without `@` or `@@`).
    pub name: Ident,
    /// `(args)`: its arguments (none without parentheses).
    pub args: Vec<Arg>,
    /// The whole annotation.
    pub span: Span,
}

/// `[liftable] def name[T, U](params): Result = body` or `... := body`.
#[derive(Debug, Clone, PartialEq)]
pub struct Def {
    /// `liftable def`: a function on values that may be applied to streams.
    pub liftable: bool,
    /// The defined name.
    pub name: Ident,
    /// `[T, U]`: its type parameters.
    pub type_params: Vec<Ident>,
    /// `None`: no parameter list at all (`def x = ...`); `Some(vec![])`: `def f() = ...`.
    pub params: Option<Vec<Param>>,
    /// `: Result`, when given.
    pub result_type: Option<Type>,
    /// What follows `=` (or `:=`).
    pub body: Body,
    /// The whole definition.
    pub span: Span,
}

/// The body of a `def`: an expression or `extern("name")`.
#[derive(Debug, Clone, PartialEq)]
pub enum Body {
    /// An expression, with the definitions of an optional `where { ... }` clause.
    Expr {
        /// The expression.
        expr: Expr,
        /// The `where { def ... }` definitions it may use (none without `where`).
        where_defs: Vec<Def>,
    },
    /// `extern("name")` (optionally `extern("name", expr)` as in TeSSLa's grammar).
    Extern {
        /// The built-in's (or native's) name.
        name: String,
        /// The optional second argument.
        arg: Option<Expr>,
        /// The whole `extern(...)`.
        span: Span,
    },
}

/// A parameter of a `def`, a lambda or an annotation: `[strict|lazy] name[: Type]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Param {
    /// The parameter's name.
    pub name: Ident,
    /// `: Type`, when given (a lambda's may be left out).
    pub ty: Option<Type>,
    /// `strict` or `lazy`, when written.
    pub evaluation: Evaluation,
    /// The whole parameter.
    pub span: Span,
}

/// Parameter evaluation modifiers (`strict` / `lazy`), kept for compatibility.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Evaluation {
    /// No modifier.
    #[default]
    Default,
    /// `strict`.
    Strict,
    /// `lazy`.
    Lazy,
}

/// What a `type Name[T] = ...` stands for.
#[derive(Debug, Clone, PartialEq)]
pub enum TypeBody {
    /// `type Name = Type`: another name for a type.
    Alias(Type),
    /// `type Name = extern("name")`: a type the engine provides.
    Extern {
        /// The built-in type's name.
        name: String,
        /// The whole `extern(...)`.
        span: Span,
    },
}

/// A type as written in TeSSLa: `Int`, `Events[Float]`, `(Int, Bool) => Int`, `{a: Int}`.
#[derive(Debug, Clone, PartialEq)]
pub enum Type {
    /// `Int`, `T`, `Events` (a bare name).
    Name(Ident),
    /// `Events[Int]`, `Option[T]`, `Map[K, V]`.
    App {
        /// The type constructor (`Events`, `Map`).
        name: Ident,
        /// Its arguments in brackets.
        args: Vec<Type>,
        /// The whole application.
        span: Span,
    },
    /// `(A, strict B) => R`.
    Function {
        /// The parameters' types, each with its `strict`/`lazy` modifier.
        params: Vec<(Evaluation, Type)>,
        /// The type after `=>`.
        result: Box<Type>,
        /// The whole function type.
        span: Span,
    },
    /// `{a: Int, b: Bool}`.
    Record {
        /// The fields' names and types, as written.
        fields: Vec<(Ident, Type)>,
        /// The whole record type.
        span: Span,
    },
    /// `(A, B)`; `()` is Unit.
    Tuple {
        /// The elements' types.
        elems: Vec<Type>,
        /// The whole tuple type.
        span: Span,
    },
}

impl Type {
    /// Where the type is written.
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
    /// `a` in `f(a = 1)`; `None` for a positional argument.
    pub name: Option<Ident>,
    /// The argument's expression.
    pub value: Expr,
}

/// An expression with its place in the source.
#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    /// What expression it is.
    pub kind: ExprKind,
    /// Where it is written (its whole text).
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

/// The kinds of TeSSLa expression.
#[derive(Debug, Clone, PartialEq)]
pub enum ExprKind {
    /// A name: `x`, `count`.
    Var(Ident),
    /// `__root__.name`.
    RootMember(Ident),
    /// Integer literal; `unit` is the time unit suffix of a time literal (`100ms` -> Some("ms")).
    Int {
        /// The literal's value (`42`, `0x1F`).
        value: i128,
        /// The time unit after it (`ms`, `s`), if any.
        unit: Option<Ident>,
    },
    /// A float literal: `1.5`, `2e-3`.
    Float(f64),
    /// A string literal; plain strings have a single `Text` part.
    Str {
        /// The text and `${...}` parts, in order.
        parts: Vec<StrPart>,
        /// `f"..."`: a format string (its parts may carry `%` specifiers).
        format: bool,
    },
    /// `(a, b)`; `()` is Unit; `(a)` is parenthesised and the parser returns `a` itself, except
    /// with a trailing comma `(a,)`, which is a one-element tuple.
    Tuple(Vec<Expr>),
    /// `{ def a = 1; def b = 2; a + b }`.
    Block {
        /// The `def`s of the block, in order.
        defs: Vec<Def>,
        /// The expression the block ends with: its value.
        result: Box<Expr>,
    },
    /// `{a = 1, b: 2}`; a member without value (`{a}`) is `a = a`.
    Record(Vec<(Ident, Expr)>),
    /// `f[T](args)`, or `f[T]` alone (then `args` is `None`).
    Call {
        /// What is called (`f`, `String.concat`).
        function: Box<Expr>,
        /// `[T]`: explicit type arguments.
        type_args: Vec<Type>,
        /// `(args)`, or `None` without parentheses.
        args: Option<Vec<Arg>>,
    },
    /// `obj.field` (record field, tuple `._1`, or module member `String.concat`).
    Member {
        /// The expression before the dot.
        object: Box<Expr>,
        /// The name after it (`_1` for a tuple's first element).
        field: Ident,
    },
    /// `!a`, `~a`, `-a`, `-.a`.
    Unary {
        /// The operator.
        op: UnaryOp,
        /// What it applies to.
        operand: Box<Expr>,
    },
    /// `a + b`, `a && b`, `a <. b` (see [`BinOp`]).
    Binary {
        /// The operator.
        op: BinOp,
        /// The left operand.
        lhs: Box<Expr>,
        /// The right operand.
        rhs: Box<Expr>,
    },
    /// `if c then a else b`, or `static if c then a else b` (decided on the constant `c`).
    If {
        /// `static if`.
        is_static: bool,
        /// The condition.
        cond: Box<Expr>,
        /// After `then`.
        then_branch: Box<Expr>,
        /// After `else`.
        else_branch: Box<Expr>,
    },
    /// `(x: Int, y) => body`: an anonymous function.
    Lambda {
        /// Its parameters (types optional).
        params: Vec<Param>,
        /// The expression after `=>`.
        body: Box<Expr>,
    },
}

/// A part of a string literal.
#[derive(Debug, Clone, PartialEq)]
pub enum StrPart {
    /// Literal text, escapes resolved.
    Text(String),
    /// `${expr}` or `$id`, with an optional format specifier (`%.2f`) in format strings.
    Interp {
        /// The interpolated expression.
        expr: Expr,
        /// `%.2f` after it in a format string, if any.
        format: Option<String>,
    },
}

/// A prefix operator.
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

/// An infix operator; the `.` forms are TeSSLa's float operators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BinOp {
    /// `*`: integer multiplication.
    Mul,
    /// `/`: integer division.
    Div,
    /// `%`: integer remainder.
    Mod,
    /// `*.`: float multiplication.
    FMul,
    /// `/.`: float division.
    FDiv,
    /// `+`: integer addition.
    Add,
    /// `-`: integer subtraction.
    Sub,
    /// `+.`: float addition.
    FAdd,
    /// `-.`: float subtraction.
    FSub,
    /// `<<`: shift left.
    Shl,
    /// `>>`: shift right.
    Shr,
    /// `&`: bitwise and.
    BitAnd,
    /// `|`: bitwise or.
    BitOr,
    /// `^`: bitwise exclusive or.
    BitXor,
    /// `==`: equal.
    Eq,
    /// `!=`: not equal.
    Ne,
    /// `<`: integer less than.
    Lt,
    /// `>`: integer greater than.
    Gt,
    /// `<=`: integer at most.
    Le,
    /// `>=`: integer at least.
    Ge,
    /// `<.`: float less than.
    FLt,
    /// `>.`: float greater than.
    FGt,
    /// `<=.`: float at most.
    FLe,
    /// `>=.`: float at least.
    FGe,
    /// `&&`: logical and (lazy on its right).
    And,
    /// `||`: logical or (lazy on its right).
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
