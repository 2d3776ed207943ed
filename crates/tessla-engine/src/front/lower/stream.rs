//! The stream operators of the builtins table (`last`, `merge`, `fold`, `lift` ...) as IR nodes.
//!
//! Owns: [`Compiler::stream_builtin`], one arm per [`StreamOp`]: what a stream operator's
//! arguments become. Names, signatures and lazy arguments are in `crate::builtins`.

use super::*;

impl Compiler<'_> {
    /// The nodes of a stream operator of the builtins table applied to `args`.
    pub(super) fn stream_builtin(
        &mut self,
        name: &str,
        op: StreamOp,
        args: Vec<Term>,
        span: Span,
    ) -> R<Term> {
        let n = args.len();
        let node = match op {
            StreamOp::Time => Node::Time(self.stream_arg(&args, 0, span)?),
            StreamOp::Last => Node::Last {
                value: self.stream_arg(&args, 0, span)?,
                trigger: self.stream_arg(&args, 1, span)?,
            },
            StreamOp::Prev => {
                let s = self.stream_arg(&args, 0, span)?;
                Node::Last {
                    value: s,
                    trigger: s,
                }
            }
            StreamOp::Delay => {
                let delay = self.stream_arg(&args, 0, span)?;
                let reset = self.stream_arg(&args, 1, span)?;
                self.graph.delays_at.push((delay, reset, span));
                Node::Delay { delay, reset }
            }
            StreamOp::Default => Node::Default {
                stream: self.stream_arg(&args, 0, span)?,
                value: self.const_arg(&args, 1, span)?,
            },
            StreamOp::DefaultFrom => Node::DefaultFrom {
                stream: self.stream_arg(&args, 0, span)?,
                from: self.stream_arg(&args, 1, span)?,
            },
            StreamOp::Merge => Node::Merge(
                (0..n)
                    .map(|i| self.stream_arg(&args, i, span))
                    .collect::<R<Vec<_>>>()?,
            ),
            StreamOp::Filter => Node::Filter {
                stream: self.stream_arg(&args, 0, span)?,
                cond: self.stream_arg(&args, 1, span)?,
            },
            StreamOp::Const => {
                let v = self.const_arg(&args, 0, span)?;
                let s = self.stream_arg(&args, 1, span)?;
                Node::SLift {
                    args: vec![SArg::Stream(s)],
                    f: Code::Const(v),
                }
            }
            StreamOp::First => {
                let a = self.stream_arg(&args, 0, span)?;
                let b = self.stream_arg(&args, 1, span)?;
                Node::SLift {
                    args: vec![SArg::Stream(a), SArg::Stream(b)],
                    f: Code::Slot(0),
                }
            }
            StreamOp::On => {
                // At each event of the trigger, the latest value of the stream (this step's or
                // an earlier one); nothing before the stream's first event.
                let t = self.stream_arg(&args, 0, span)?;
                let s = self.stream_arg(&args, 1, span)?;
                let before = self.node(Node::Last {
                    value: s,
                    trigger: t,
                });
                Node::Lift {
                    args: vec![t, s, before],
                    f: LiftFn::On,
                }
            }
            StreamOp::Count => Node::Fold {
                stream: self.stream_arg(&args, 0, span)?,
                init: Value::Int(0),
                f: add(Code::Slot(0), Code::Const(Value::Int(1))),
            },
            StreamOp::Sum => Node::Fold {
                stream: self.stream_arg(&args, 0, span)?,
                init: Value::Int(0),
                f: add(Code::Slot(0), Code::Slot(1)),
            },
            StreamOp::Fold => Node::Fold {
                stream: self.stream_arg(&args, 0, span)?,
                init: self.const_arg(&args, 1, span)?,
                f: self.value_fn_arg(&args, 2, 2, span)?,
            },
            StreamOp::Reduce => Node::Reduce {
                stream: self.stream_arg(&args, 0, span)?,
                f: self.value_fn_arg(&args, 1, 2, span)?,
            },
            StreamOp::Maximum => Node::Reduce {
                stream: self.stream_arg(&args, 0, span)?,
                f: Code::apply(closure::named_native("max"), Code::slots(2)),
            },
            StreamOp::Minimum => Node::Reduce {
                stream: self.stream_arg(&args, 0, span)?,
                f: Code::apply(closure::named_native("min"), Code::slots(2)),
            },
            StreamOp::Lift | StreamOp::SLift => {
                // The checker types `lift`/`slift` from their variadic signature: the function
                // comes last and takes one argument per stream.
                let Some(ft) = args.last().cloned() else {
                    return self.unchecked(span, "a call with the wrong number of arguments");
                };
                if fn_arity(&ft).is_some_and(|arity| arity != n - 1) {
                    return self.unchecked(span, "a function of the wrong arity");
                }
                let f = self.value_fn_arg(&[ft], 0, n - 1, span)?;
                let streams = (0..n - 1)
                    .map(|i| self.stream_arg(&args, i, span))
                    .collect::<R<Vec<_>>>()?;
                if op == StreamOp::SLift {
                    Node::SLift {
                        args: streams.into_iter().map(SArg::Stream).collect(),
                        f,
                    }
                } else {
                    Node::Lift {
                        args: streams,
                        f: LiftFn::Options(f),
                    }
                }
            }
            StreamOp::Pure => {
                let s = self.stream_arg(&args, 0, span)?;
                Node::Lift {
                    args: vec![s, self.node(Node::Nil)],
                    f: LiftFn::First,
                }
                .pipe_pure(self, s)
            }
            StreamOp::IsFirst => {
                let s = self.stream_arg(&args, 0, span)?;
                let cnt = self.node(Node::Fold {
                    stream: s,
                    init: Value::Int(0),
                    f: add(Code::Slot(0), Code::Const(Value::Int(1))),
                });
                let first = self.node(Node::SLift {
                    args: vec![SArg::Stream(s), SArg::Stream(cnt)],
                    f: Code::apply(Callee::Prim(Prim::IsOne), Code::slots(2)),
                });
                // TeSSLa merges in a constant `false`: `false` at 0 when `x` has no event there.
                Node::Default {
                    stream: first,
                    value: Value::Bool(false),
                }
            }
            StreamOp::FirstEvent => {
                let s = self.stream_arg(&args, 0, span)?;
                Node::Lift {
                    args: vec![s],
                    f: LiftFn::First,
                }
                .first_only(self)
            }
            StreamOp::Defined => {
                let s = self.stream_arg(&args, 0, span)?;
                let t = self.node(Node::SLift {
                    args: vec![SArg::Stream(s)],
                    f: Code::Const(Value::Bool(true)),
                });
                Node::Default {
                    stream: t,
                    value: Value::Bool(false),
                }
            }
            StreamOp::ConstIf => {
                let v = self.const_arg(&args, 0, span)?;
                let c = self.stream_arg(&args, 1, span)?;
                let k = self.node(Node::SLift {
                    args: vec![SArg::Stream(c)],
                    f: Code::Const(v),
                });
                Node::Filter { stream: k, cond: c }
            }
            StreamOp::UnitIf => {
                let c = self.stream_arg(&args, 0, span)?;
                let k = self.node(Node::SLift {
                    args: vec![SArg::Stream(c)],
                    f: Code::Const(Value::Unit),
                });
                Node::Filter { stream: k, cond: c }
            }
            StreamOp::Rising | StreamOp::Falling => {
                let c = self.stream_arg(&args, 0, span)?;
                let prev = self.node(Node::Last {
                    value: c,
                    trigger: c,
                });
                let edge = self.node(Node::Lift {
                    args: vec![c, prev],
                    f: LiftFn::Edge(op == StreamOp::Rising),
                });
                let k = self.node(Node::SLift {
                    args: vec![SArg::Stream(edge)],
                    f: Code::Const(Value::Unit),
                });
                Node::Filter {
                    stream: k,
                    cond: edge,
                }
            }
            StreamOp::Period => {
                let d = self.const_arg(&args, 0, span)?;
                let u = self.unit();
                let alias = self.node(Node::Alias(usize::MAX));
                let m = self.node(Node::Merge(vec![u, alias]));
                let dnode = self.node(Node::SLift {
                    args: vec![SArg::Stream(m)],
                    f: Code::Const(d.clone()),
                });
                let delay = self.node(Node::Delay {
                    delay: dnode,
                    reset: u,
                });
                self.graph.nodes[alias] = Node::Alias(delay);
                // The periodic events: the delay's firings, plus the start at t = 0.
                Node::Merge(vec![u, delay])
            }
            StreamOp::Unsupported | StreamOp::Nil | StreamOp::Unit => {
                return self.error(
                    Category::Unsupported,
                    span,
                    format!("`{name}` is not supported yet"),
                );
            }
        };
        Ok(Term::Stream(self.node(node)))
    }
}

/// `a + b` (as the `+` operator).
fn add(a: Code, b: Code) -> Code {
    Code::apply(Callee::Prim(Prim::Binary(BinOp::Add)), vec![a, b])
}

/// The number of parameters of a lambda or user function term, when known at compile time.
fn fn_arity(t: &Term) -> Option<usize> {
    match t {
        Term::Func(ft) => match &**ft {
            FuncTerm::Lambda { params, .. } => Some(params.len()),
            FuncTerm::User { def, .. } if !matches!(def.body, Body::Extern { .. }) => {
                def.params.as_ref().map(Vec::len)
            }
            _ => None,
        },
        _ => None,
    }
}

trait NodeExt {
    fn pipe_pure(self, c: &mut Compiler<'_>, s: NodeId) -> Node;
    fn first_only(self, c: &mut Compiler<'_>) -> Node;
}

impl NodeExt for Node {
    /// `pure(s)`: events of `s` whose value differs from the previous event's.
    fn pipe_pure(self, c: &mut Compiler<'_>, s: NodeId) -> Node {
        let prev = c.node(Node::Last {
            value: s,
            trigger: s,
        });
        Node::Lift {
            args: vec![s, prev],
            f: LiftFn::Distinct,
        }
    }

    /// Only the first event of the (single-argument) lift's stream.
    fn first_only(self, c: &mut Compiler<'_>) -> Node {
        let Node::Lift { args, .. } = &self else {
            return self;
        };
        let s = args[0];
        let seen = c.node(Node::Last {
            value: s,
            trigger: s,
        });
        Node::Lift {
            args: vec![s, seen],
            f: LiftFn::FirstOnly,
        }
    }
}
