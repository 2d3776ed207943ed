//! Warnings about specs that check but cannot do what they say (TeSSLa's documentation of
//! `delay`: the delay is armed only by an event of its first argument, at the time of that event;
//! an event of the second argument without one of the first cancels it; a delay must be
//! positive). Each warning names the place and what to write instead:
//!
//! - a `delay` whose delay stream has events at time 0 only (a constant such as
//!   `delay(max_silence, x)`, or a stream computed from constants alone) while its reset stream
//!   has events later: it is armed once, at 0, the first event of the reset stream cancels it, and
//!   it never fires again. The watchdog meant is `delay(const(max_silence, x), x)`;
//! - a `delay` whose delay is a constant that is not positive (every firing an error).

use super::*;

impl Compiler<'_> {
    /// Warn about each `delay` call of the program that is armed at time 0 only, or by a
    /// constant that is not positive.
    pub(super) fn warn_delay_traps(&mut self) {
        let mut seen: HashSet<Span> = HashSet::new();
        let calls = std::mem::take(&mut self.graph.delays_at);
        for (delay, reset, span) in calls {
            if !seen.insert(span) {
                continue;
            }
            let nodes = &self.graph.nodes;
            if let Some(Value::Int(d)) = constant(nodes, delay)
                && d <= 0
            {
                // Not a watchdog at all: said once, whatever the streams.
                self.diags.push(
                    Diagnostic::warning(
                        Category::Other,
                        Some(span),
                        format!(
                            "this `delay` waits {d} (a delay must be positive): its events are \
                             errors (`Delay must be positive`)"
                        ),
                    )
                    .with_help(
                        "give a positive delay, in the spec's time unit (Telegraf's: ns; \
                         `2 s` with a time literal)",
                    ),
                );
                continue;
            }
            if at_zero_only(nodes, delay) && !at_zero_only(nodes, reset) {
                let instead = match two_args(self.sources.text(span)) {
                    Some((d, r)) => format!("write `delay(const({d}, {r}), {r})`"),
                    None => "write `delay(const(D, r), r)`".to_string(),
                };
                self.diags.push(
                    Diagnostic::warning(
                        Category::Other,
                        Some(span),
                        "this `delay` is armed only at time 0: its delay stream is a constant \
                         (one event, at t = 0), so the first event of the reset stream \
                         cancels it and it never fires again"
                            .to_string(),
                    )
                    .with_help(format!(
                        "to wait after each event of the reset stream (a watchdog), arm it \
                         with an event of that stream: {instead}"
                    )),
                );
            }
        }
    }
}

/// The two arguments of a call `delay(a, b)` as written, when they can be told apart.
fn two_args(call: &str) -> Option<(&str, &str)> {
    let inner = call.trim().strip_prefix("delay")?.trim_start();
    let inner = inner.strip_prefix('(')?.strip_suffix(')')?;
    let mut depth = 0i32;
    let mut quoted = false;
    let mut comma = None;
    for (i, c) in inner.char_indices() {
        match c {
            '"' => quoted = !quoted,
            '(' | '[' | '{' if !quoted => depth += 1,
            ')' | ']' | '}' if !quoted => depth -= 1,
            ',' if !quoted && depth == 0 => {
                if comma.is_some() {
                    return None;
                }
                comma = Some(i);
            }
            _ => {}
        }
    }
    let (a, b) = inner.split_at(comma?);
    let (a, b) = (a.trim(), b.get(1..)?.trim());
    (!a.is_empty() && !b.is_empty() && !a.contains('\n') && !b.contains('\n')).then_some((a, b))
}

/// The constant `n` is, through aliases (also `const(c, s)`: every event `c`).
fn constant(nodes: &[Node], mut n: NodeId) -> Option<Value> {
    for _ in 0..nodes.len() {
        match nodes.get(n)? {
            Node::Const(v)
            | Node::SLift {
                f: Code::Const(v), ..
            } => return Some(v.clone()),
            Node::Alias(m) => n = *m,
            _ => return None,
        }
    }
    None
}

/// Whether node `n` has events at time 0 at most: constants and streams computed from them
/// alone (no input and no `delay` among the streams it is computed from).
fn at_zero_only(nodes: &[Node], n: NodeId) -> bool {
    let mut seen: HashSet<NodeId> = HashSet::new();
    let mut todo = vec![n];
    while let Some(n) = todo.pop() {
        if !seen.insert(n) {
            continue;
        }
        match nodes.get(n) {
            None | Some(Node::Input(_) | Node::Delay { .. }) => return false,
            // `last`'s value is read at its trigger's events: only the trigger says when.
            Some(Node::Last { trigger, .. }) => todo.push(*trigger),
            Some(node) => todo.extend(node.strict_deps()),
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::two_args;

    #[test]
    fn the_arguments_of_a_delay_as_written() {
        assert_eq!(
            two_args("delay(max_silence, battery)"),
            Some(("max_silence", "battery"))
        );
        assert_eq!(
            two_args("delay(f(a, b), merge(x, y))"),
            Some(("f(a, b)", "merge(x, y)"))
        );
        assert_eq!(two_args("delay(a)"), None);
        assert_eq!(two_args("slift(a, b)"), None);
    }
}
