//! The selector algebra a rollback needs: whether one selector covers another, and which rollout
//! a rollback undoes and which version it puts back.

use crate::processor::versions::Selector;
use crate::spec_feed::Rollout;

/// Whether every instance `s` picks is picked by `x` (each of `x`'s clauses is a clause of `s`
/// on the same tag with no value outside `x`'s; `x` picking every instance covers any).
pub(super) fn covers(x: &Selector, s: &Selector) -> bool {
    let xs = clauses(x);
    let ss = clauses(s);
    xs.iter().all(|(tag, values)| {
        ss.iter()
            .any(|(t, v)| t == tag && v.iter().all(|x| values.contains(x)))
    })
}

/// A selector's clauses, read back from its written form (`TAG=V1,V2;TAG=V`).
pub(super) fn clauses(s: &Selector) -> Vec<(String, Vec<String>)> {
    s.to_string()
        .split(';')
        .filter_map(|c| c.split_once('='))
        .map(|(t, v)| (t.to_string(), v.split(',').map(str::to_string).collect()))
        .collect()
}

/// Which rollout a rollback undoes and which version it publishes: the last readable rollout
/// covering `select` (the last one, without it) and the latest earlier one covering the same
/// instances (none: the base version). (undone, selector, previous)
pub(super) fn rollback_plan<'a>(
    rollouts: &'a [Rollout],
    select: Option<&Selector>,
) -> Option<(&'a Rollout, Selector, Option<&'a Rollout>)> {
    let last = match select {
        None => rollouts.len().checked_sub(1)?,
        Some(s) => rollouts.iter().rposition(|r| covers(&r.selector, s))?,
    };
    let undone = rollouts.get(last)?;
    let sel = select.cloned().unwrap_or_else(|| undone.selector.clone());
    let previous = rollouts
        .get(..last)?
        .iter()
        .rev()
        .find(|r| covers(&r.selector, &sel));
    Some((undone, sel, previous))
}
