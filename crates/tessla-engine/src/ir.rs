//! The flat core IR: stream nodes in dependency order with typed value slots.
//!
//! Owns: [`Program`] (what the front end produces and the evaluator runs), the metadata the
//! bindings read ([`InputInfo`], [`OutputInfo`], [`Annotation`]) and value [`Type`]s.

use crate::value::Value;

/// A value type, as reported by `check` and used by bindings to convert inputs.
#[derive(Debug, Clone, PartialEq)]
pub enum Type {
    Unit,
    Bool,
    Int,
    Float,
    String,
    Option(Box<Type>),
    List(Box<Type>),
    Tuple(Vec<Type>),
    Record(Vec<(String, Type)>),
    Events(Box<Type>),
}

/// An annotation on an input or output (`@TelegrafIn("m", "", "f")`), with its arguments named by
/// the annotation declaration's parameters, in declaration order.
#[derive(Debug, Clone, PartialEq)]
pub struct Annotation {
    pub name: String,
    pub args: Vec<(String, Value)>,
}

#[derive(Debug, Clone)]
pub struct InputInfo {
    pub name: String,
    /// The element type (`Float` for `Events[Float]`).
    pub ty: Type,
    pub annotations: Vec<Annotation>,
}

#[derive(Debug, Clone)]
pub struct OutputInfo {
    pub name: String,
    /// The element type.
    pub ty: Type,
    pub annotations: Vec<Annotation>,
    /// `@raw out`: print the value only.
    pub raw: bool,
}

/// A compiled specification, shared (in an `Arc`) by every monitor instance.
#[derive(Debug)]
pub struct Program {
    pub inputs: Vec<InputInfo>,
    pub outputs: Vec<OutputInfo>,
    pub global_annotations: Vec<Annotation>,
}

impl Program {
    pub fn input_index(&self, name: &str) -> Option<usize> {
        self.inputs.iter().position(|i| i.name == name)
    }
}
