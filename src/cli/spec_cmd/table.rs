//! The table renderer of `spec list` and `spec status`: columns padded to their widest cell,
//! the rollout table, and the one-line forms of a rollout, a selector, a time and a key.

use crate::processor::versions::Selector;
use crate::spec_feed::nats::{Decided, Listed, Status};
use crate::spec_feed::status::show_time;
use crate::spec_feed::{Phase, Rollout};

/// `rollout N: version ID (`label`) in force from T for S`.
pub(super) fn published_line(r: &Rollout, note: &str) -> String {
    let label = if r.label.is_empty() {
        String::new()
    } else {
        format!(" (`{}`)", r.label)
    };
    format!(
        "rollout {}: version {}{label} in force from {} for {}{note}",
        r.revision,
        r.id,
        show_time(r.from),
        who(&r.selector)
    )
}

pub(super) fn who(s: &Selector) -> String {
    if s.is_all() {
        "every instance".into()
    } else {
        s.to_string()
    }
}

pub(super) fn published_time(ns: i64) -> String {
    match u64::try_from(ns) {
        Ok(n) if n > 0 => humantime::format_rfc3339_seconds(
            std::time::UNIX_EPOCH + std::time::Duration::from_nanos(n),
        )
        .to_string(),
        _ => "-".into(),
    }
}

pub(super) fn short_key(k: &Option<String>) -> String {
    match k {
        // A signer is whatever the record says: cut by characters, never inside one.
        Some(k) if k.chars().count() > 12 => {
            let head: String = k.chars().take(6).collect();
            let tail: Vec<char> = k.chars().rev().take(4).collect();
            format!("{head}…{}", tail.iter().rev().collect::<String>())
        }
        Some(k) => k.clone(),
        None => "unsigned".into(),
    }
}

/// The rollouts as a table with the fleet's decision on each; with `statuses`, how many
/// processes voted to accept and to refuse each.
pub(super) fn rollout_table(
    listed: &[Listed],
    decided: &[Decided],
    statuses: Option<&[Status]>,
) -> String {
    if listed.is_empty() {
        return "no rollouts yet\n".into();
    }
    let mut head = vec![
        "REV",
        "VERSION",
        "LABEL",
        "FROM",
        "SELECTOR",
        "PUBLISHED",
        "SIGNER",
        "DECISION",
    ];
    if statuses.is_some() {
        head.push("VOTES");
    }
    let rows = listed
        .iter()
        .map(|l| {
            let mut row = match &l.rollout {
                Ok(r) => vec![
                    l.revision.to_string(),
                    r.id.clone(),
                    r.label.clone(),
                    show_time(r.from),
                    if r.selector.is_all() {
                        "all".into()
                    } else {
                        r.selector.to_string()
                    },
                    published_time(r.published),
                    short_key(&l.signer),
                    decision_word(l.revision, decided),
                ],
                Err(why) => vec![
                    l.revision.to_string(),
                    "?".into(),
                    format!("unreadable: {why}"),
                ],
            };
            if let Some(s) = statuses {
                while row.len() < 8 {
                    row.push(String::new());
                }
                let (a, r) = counts(l.revision, s);
                row.push(format!("{a} accepted, {r} refused"));
            }
            row
        })
        .collect::<Vec<_>>();
    table(&head, &rows)
}

/// Columns padded to their widest cell, two spaces apart.
pub(super) fn table(head: &[&str], rows: &[Vec<String>]) -> String {
    let mut width: Vec<usize> = head.iter().map(|h| h.chars().count()).collect();
    for row in rows {
        for (i, c) in row.iter().enumerate() {
            if let Some(w) = width.get_mut(i) {
                *w = (*w).max(c.chars().count());
            }
        }
    }
    let mut out = String::new();
    let mut line = |cells: Vec<&str>| {
        let n = cells.len();
        let mut l = String::new();
        for (i, c) in cells.into_iter().enumerate() {
            l.push_str(c);
            if i + 1 < n {
                let pad = width.get(i).copied().unwrap_or(0)
                    - c.chars().count().min(width.get(i).copied().unwrap_or(0));
                l.push_str(&" ".repeat(pad + 2));
            }
        }
        out.push_str(l.trim_end());
        out.push('\n');
    };
    line(head.to_vec());
    for row in rows {
        line(row.iter().map(String::as_str).collect());
    }
    out
}

pub(super) fn dash(s: &str) -> String {
    if s.is_empty() {
        "-".into()
    } else {
        s.to_string()
    }
}

/// A rollout's decision in a word: `committed`, `aborted`, `undecided` (or why its record
/// cannot be read).
pub(super) fn decision_word(revision: u64, decided: &[Decided]) -> String {
    match decided.iter().find(|d| d.revision == revision) {
        None => "undecided".into(),
        Some(d) => match &d.decision {
            Ok(x) if x.commit => "committed".into(),
            Ok(_) => "aborted".into(),
            Err(why) => format!("unreadable decision: {why}"),
        },
    }
}

/// How many processes voted to accept and to refuse rollout `revision` (each process's latest
/// check of it).
pub(super) fn counts(revision: u64, statuses: &[Status]) -> (usize, usize) {
    let mut acc = 0;
    let mut refd = 0;
    for s in statuses {
        let check = s
            .outcomes
            .iter()
            .rev()
            .find(|o| o.revision == revision && o.phase == Phase::Check);
        if let Some(o) = check {
            if o.accepted {
                acc += 1;
            } else {
                refd += 1;
            }
        }
    }
    (acc, refd)
}
