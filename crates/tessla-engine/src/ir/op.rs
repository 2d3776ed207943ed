//! The IR's operators: what a [`Prim::Binary`](crate::ir::Prim::Binary) or
//! [`Prim::Unary`](crate::ir::Prim::Unary) applies and a [`Node::Bin`](crate::ir::Node::Bin)
//! falls back to.
//!
//! Owns: [`BinOp`] and [`UnaryOp`] with their symbols (for listings and messages). The lowering
//! maps the syntax's operators onto these (`front::lower`); their semantics are
//! `runtime::ops`. The IR and the runtime name operators only through these, never through the
//! syntax tree.

/// A binary operator.
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

/// A unary operator.
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

impl BinOp {
    /// The operator as TeSSLa writes it.
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

impl UnaryOp {
    /// The operator as TeSSLa writes it.
    pub fn symbol(self) -> &'static str {
        match self {
            UnaryOp::Not => "!",
            UnaryOp::BitNot => "~",
            UnaryOp::Neg => "-",
            UnaryOp::FNeg => "-.",
        }
    }
}
