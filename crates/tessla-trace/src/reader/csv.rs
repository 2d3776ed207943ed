//! TeSSLa's CSV trace form: a header `time,a,b`, then `TS,value,value` lines, each cell a value
//! as in the line form (commas inside brackets, strings and braces do not split cells).

use super::*;

/// A CSV trace as TeSSLa's interpreter reads it (`--csv`): a header `time,a,b` (the first
/// column's name is not used) and then lines `TS,value,value` with one column per stream; an
/// empty column is no event. Columns are TeSSLa expressions, split at top-level commas (a
/// string, tuple or list may hold commas), so this is not RFC 4180 CSV: a quote opens a TeSSLa
/// string literal, not a quoted field.
#[derive(Debug, Default)]
pub struct CsvReader {
    header: Option<Vec<String>>,
}

impl CsvReader {
    /// The events of one line (none for the header, blank and comment lines).
    pub fn parse_line(
        &mut self,
        raw: &str,
        line: usize,
        program: &Program,
    ) -> Result<Vec<Read>, ReadError> {
        let l = strip_comment(raw).trim();
        if l.is_empty() {
            return Ok(Vec::new());
        }
        let columns = split_top_level_commas(l);
        let Some(header) = &self.header else {
            let names: Vec<String> = columns.iter().map(|c| c.trim().to_string()).collect();
            let ident = |n: &str| {
                n.chars()
                    .next()
                    .is_some_and(|c| c.is_alphabetic() || c == '_')
                    && n.chars().all(|c| c.is_alphanumeric() || c == '_')
            };
            if names.len() < 2 || !names.iter().all(|n| ident(n)) {
                return Err(ReadError::malformed(
                    line,
                    "No header row found: the first line of a CSV trace names the columns, \
                     `time,stream1,stream2,...`",
                ));
            }
            self.header = Some(names.into_iter().skip(1).collect());
            return Ok(Vec::new());
        };
        let mut columns = columns.into_iter();
        let ts = parse_ts(columns.next().unwrap_or(""), line)?;
        let mut out = Vec::new();
        for (k, text) in columns.enumerate() {
            let text = text.trim();
            if text.is_empty() {
                continue;
            }
            let Some(name) = header.get(k) else {
                return Err(ReadError::malformed(
                    line,
                    format!(
                        "{} value columns, but the header names {} streams",
                        k + 1,
                        header.len()
                    ),
                ));
            };
            out.push(event(ts, name, Some(text), line, program)?);
        }
        Ok(out)
    }
}

/// `text` split at the commas outside string literals and brackets.
fn split_top_level_commas(text: &str) -> Vec<&str> {
    let mut parts = Vec::new();
    let (mut depth, mut in_str, mut escape, mut start) = (0i32, false, false, 0);
    for (i, c) in text.char_indices() {
        if escape {
            escape = false;
            continue;
        }
        match c {
            '\\' if in_str => escape = true,
            '"' => in_str = !in_str,
            '(' | '[' | '{' if !in_str => depth += 1,
            ')' | ']' | '}' if !in_str => depth -= 1,
            ',' if !in_str && depth == 0 => {
                parts.push(&text[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&text[start..]);
    parts
}
