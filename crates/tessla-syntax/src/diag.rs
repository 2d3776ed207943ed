//! Diagnostics for specifications: what went wrong, where, and how to fix it.
//!
//! Owns: the [`Diagnostic`] value every front-end phase (parse, include, check) reports, its
//! [`Category`] (syntax / type / name / ... errors, used by tests and the conformance runner to
//! match "an error of the right kind"), and rendering with `codespan-reporting` (file, line,
//! column, the source line with a caret, and a `help:` line when a fix is known).

use crate::source::{FileId, SourceMap, Span};
use codespan_reporting::diagnostic::{Diagnostic as CsDiagnostic, Label, Severity};
use codespan_reporting::files::{Error as FilesError, Files};
use codespan_reporting::term::{self, termcolor};
use std::ops::Range;

/// What kind of problem a diagnostic reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Category {
    /// The text does not parse.
    Syntax,
    /// An unknown name (stream, function, type, annotation, include file).
    Name,
    /// Types do not fit.
    Type,
    /// Recursion not through `last`/`delay`, include loops.
    Recursion,
    /// Time literals and base time.
    Time,
    /// A feature this engine does not implement (the message names it).
    Unsupported,
    /// Anything else found while checking (duplicate definitions, bad annotation arguments ...).
    Other,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
/// How serious a diagnostic is.
pub enum Level {
    /// The spec is refused.
    Error,
    /// The spec loads; something in it is probably not what was meant.
    Warning,
}

/// One message about a spec.
#[derive(Debug, Clone)]
pub struct Diagnostic {
    /// Error or warning.
    pub level: Level,
    /// Which phase found it (what `check` groups it under).
    pub category: Category,
    /// The one-line message.
    pub message: String,
    /// The primary place, with an optional label shown under the caret.
    pub span: Option<Span>,
    /// The text under the caret at `span` (empty: none).
    pub label: String,
    /// Secondary places (e.g. "first defined here").
    pub notes_at: Vec<(Span, String)>,
    /// How to fix it, when known ("use `+.` for Float", "did you mean `speed`?").
    pub help: Option<String>,
}

impl Diagnostic {
    /// An error of `category` at `span` (none: about the whole spec).
    pub fn error(category: Category, span: Option<Span>, message: impl Into<String>) -> Self {
        Diagnostic {
            level: Level::Error,
            category,
            message: message.into(),
            span,
            label: String::new(),
            notes_at: Vec::new(),
            help: None,
        }
    }

    /// A warning of `category` at `span`.
    pub fn warning(category: Category, span: Option<Span>, message: impl Into<String>) -> Self {
        Diagnostic {
            level: Level::Warning,
            ..Diagnostic::error(category, span, message)
        }
    }

    /// The same diagnostic with `label` under its caret.
    pub fn with_label(mut self, label: impl Into<String>) -> Self {
        self.label = label.into();
        self
    }

    /// The same diagnostic with a hint on how to fix it.
    pub fn with_help(mut self, help: impl Into<String>) -> Self {
        self.help = Some(help.into());
        self
    }

    /// The same diagnostic with a secondary place ("first defined here").
    pub fn with_note_at(mut self, span: Span, note: impl Into<String>) -> Self {
        self.notes_at.push((span, note.into()));
        self
    }

    /// Whether it refuses the spec.
    pub fn is_error(&self) -> bool {
        self.level == Level::Error
    }

    /// A one-line form: `file:line:col: error: message (help: ...)`.
    pub fn one_line(&self, sources: &SourceMap) -> String {
        let place = self
            .span
            .map(|s| format!("{}: ", sources.location(s)))
            .unwrap_or_default();
        let level = match self.level {
            Level::Error => "error",
            Level::Warning => "warning",
        };
        let help = self
            .help
            .as_ref()
            .map(|h| format!(" (help: {h})"))
            .unwrap_or_default();
        format!("{place}{level}: {}{help}", self.message)
    }
}

/// Adapter so codespan-reporting can read our [`SourceMap`].
struct CsFiles<'a>(&'a SourceMap);

impl<'a> Files<'a> for CsFiles<'a> {
    type FileId = FileId;
    type Name = &'a str;
    type Source = &'a str;

    fn name(&'a self, id: FileId) -> Result<&'a str, FilesError> {
        Ok(&self.0.get(id).name)
    }

    fn source(&'a self, id: FileId) -> Result<&'a str, FilesError> {
        Ok(&self.0.get(id).text)
    }

    fn line_index(&'a self, id: FileId, byte_index: usize) -> Result<usize, FilesError> {
        Ok(self.0.get(id).line_col(byte_index).0 - 1)
    }

    fn line_range(&'a self, id: FileId, line_index: usize) -> Result<Range<usize>, FilesError> {
        let text = &self.0.get(id).text;
        let mut start = 0;
        for _ in 0..line_index {
            match text[start..].find('\n') {
                Some(i) => start += i + 1,
                None => {
                    return Err(FilesError::LineTooLarge {
                        given: line_index,
                        max: line_index,
                    });
                }
            }
        }
        let end = text[start..]
            .find('\n')
            .map_or(text.len(), |i| start + i + 1);
        Ok(start..end)
    }
}

/// Render diagnostics as codespan-reporting does (caret under the place, help line), to a string.
/// `color` adds ANSI colours (used when stderr is a terminal).
pub fn render(diags: &[Diagnostic], sources: &SourceMap, color: bool) -> String {
    let files = CsFiles(sources);
    let config = term::Config::default();
    let mut out = String::new();
    for d in diags {
        let mut buf: Vec<u8> = Vec::new();
        let cs = to_codespan(d);
        let ok = if color {
            let mut w = termcolor::Ansi::new(&mut buf);
            term::emit_to_write_style(&mut w, &config, &files, &cs).is_ok()
        } else {
            let mut w = termcolor::NoColor::new(&mut buf);
            term::emit_to_write_style(&mut w, &config, &files, &cs).is_ok()
        };
        if ok {
            out.push_str(&String::from_utf8_lossy(&buf));
        } else {
            out.push_str(&d.one_line(sources));
            out.push('\n');
        }
    }
    out
}

fn to_codespan(d: &Diagnostic) -> CsDiagnostic<FileId> {
    let severity = match d.level {
        Level::Error => Severity::Error,
        Level::Warning => Severity::Warning,
    };
    let mut labels = Vec::new();
    if let Some(s) = d.span {
        labels
            .push(Label::primary(s.file, s.start as usize..s.end as usize).with_message(&d.label));
    }
    for (s, note) in &d.notes_at {
        labels.push(Label::secondary(s.file, s.start as usize..s.end as usize).with_message(note));
    }
    let mut cs = CsDiagnostic::new(severity)
        .with_message(&d.message)
        .with_labels(labels);
    if let Some(h) = &d.help {
        cs = cs.with_notes(vec![format!("help: {h}")]);
    }
    cs
}

/// Edit distance, for "did you mean" suggestions.
pub fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1; b.len() + 1];
        for (j, cb) in b.iter().enumerate() {
            let cost = usize::from(ca != *cb);
            cur[j + 1] = (prev[j] + cost).min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

/// "unknown name `name`" at `span`, with the nearest of `known` as "did you mean" help.
pub fn unknown_name<'a>(
    name: &str,
    span: Span,
    known: impl IntoIterator<Item = &'a str>,
) -> Diagnostic {
    let near = nearest(name, known);
    let d = Diagnostic::error(Category::Name, Some(span), format!("unknown name `{name}`"));
    if near.is_empty() {
        return d;
    }
    d.with_help(format!(
        "did you mean {}?",
        near.iter()
            .map(|n| format!("`{n}`"))
            .collect::<Vec<_>>()
            .join(" or ")
    ))
}

/// Up to three known names closest to `name`, for "did you mean" help.
pub fn nearest<'a>(name: &str, known: impl IntoIterator<Item = &'a str>) -> Vec<&'a str> {
    let limit = (name.chars().count() / 3).max(1) + 1;
    let mut scored: Vec<(usize, &str)> = known
        .into_iter()
        .map(|k| (edit_distance(&name.to_lowercase(), &k.to_lowercase()), k))
        .filter(|(d, _)| *d <= limit)
        .collect();
    scored.sort();
    scored.dedup_by(|a, b| a.1 == b.1);
    scored.into_iter().take(3).map(|(_, k)| k).collect()
}
