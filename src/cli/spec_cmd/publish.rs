//! The `spec` subcommands that write to the channel: `publish` (check the spec, sign, wait for
//! the votes, write the fleet's decision), `decide`, `abort` and `rollback`.

use super::args::*;
use super::selector::*;
use super::table::*;
use super::{failure, print};
use crate::cli::error::{CliError, CliResult};
use crate::cli::spec_options::{load_options, require_outputs};
use crate::spec_feed::bundle::Bundle;
use crate::spec_feed::decide;
use crate::spec_feed::nats::{Decided, Operator};
use crate::spec_feed::sign::read_signing_key;
use crate::spec_feed::status::{now_ns, show_time};
use crate::spec_feed::{BASE, Decision, Rollout};
use std::io::Write;
use std::time::{Duration, Instant};

pub(super) fn publish(a: PublishArgs) -> CliResult {
    let mut spec_options = a.spec_options.clone();
    spec_options.set_from_env();
    let options = load_options(&spec_options)?;
    if let Some(fleet) = &a.fleet {
        return publish_fleet(&a, fleet, &options);
    }
    let (bundle, loaded) = Bundle::read(&a.spec, &options).map_err(|e| {
        CliError::spec(format!(
            "{}\nspec publish: {} was not published: it does not check",
            e.render().trim_end(),
            a.spec.display()
        ))
    })?;
    require_outputs(&loaded.program, &a.spec.display().to_string())?;
    if !loaded.warnings.is_empty() {
        let text = tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, false);
        let _ = std::io::stderr().lock().write_all(text.as_bytes());
    }
    sign_publish_settle(&a, &bundle, a.select.clone().unwrap_or_default(), false, "")
}

/// `spec publish ROBOT_SPEC --fleet FILE`: check the fleet spec against the robot spec (the
/// messages of `run --fleet-spec`), then publish it as a fleet rollout and settle it.
fn publish_fleet(
    a: &PublishArgs,
    fleet: &std::path::Path,
    options: &tessla_engine::LoadOptions,
) -> CliResult {
    let not_published = |why: &str| {
        format!(
            "spec publish: fleet spec {} was not published: {why}",
            fleet.display()
        )
    };
    let (_, robot) = Bundle::read(&a.spec, options).map_err(|e| {
        CliError::spec(format!(
            "{}\n{}",
            e.render().trim_end(),
            not_published(&format!(
                "the robot spec {} it is checked against does not check",
                a.spec.display()
            ))
        ))
    })?;
    let checked = crate::fleet::check(fleet, &robot.program, options).map_err(|e| {
        CliError::spec(format!(
            "{}\n{}",
            e.to_string().trim_end(),
            not_published(&format!("it does not check against {}", a.spec.display()))
        ))
    })?;
    let bundle = checked.bundle;
    sign_publish_settle(a, &bundle, Default::default(), true, " (fleet spec)")
}

/// Sign `bundle`'s rollout (a fleet spec's with `fleet`), publish it on the channel once no
/// earlier rollout is undecided, print its line (with `note`) and settle it: the tail `spec
/// publish` shares for robot and fleet specs.
fn sign_publish_settle(
    a: &PublishArgs,
    bundle: &Bundle,
    selector: crate::processor::versions::Selector,
    fleet: bool,
    note: &str,
) -> CliResult {
    let (key, op) = signed_operator("spec publish", &a.sign, &a.channel, true)?;
    if op.created() {
        // Processes started before the channel existed are looking for it: let them find it
        // and report, so their votes are waited for.
        let wait = Operator::settling();
        eprintln!(
            "spec: created the channel; waiting {} s for running processes to find it",
            wait.as_secs_f64()
        );
        std::thread::sleep(wait);
    }
    refuse_while_undecided(&op)?;
    let now = now_ns();
    let rollout = Rollout {
        revision: 0,
        id: bundle.id(),
        digest: bundle.digest(),
        label: a.label.clone().unwrap_or_default(),
        from: a.from.unwrap_or(now),
        selector,
        published: now,
        fleet,
    };
    let (r, proposed) = op.publish(Some(bundle), rollout, &key).map_err(failure)?;
    print(&format!("{}{note}\n", published_line(&r, "")))?;
    settle(&op, &r, proposed, &key, a.vote.vote_timeout)
}

/// The operator's signing key (`--sign-key-file` or TESSLA_SIGN_KEY) and the channel it signs
/// for (`create`: make its bucket when missing): what every command that writes a rollout or a
/// decision starts with; `cmd` names the command in a refusal.
fn signed_operator(
    cmd: &str,
    sign: &SignArgs,
    channel: &ChannelArgs,
    create: bool,
) -> Result<(nkeys::KeyPair, Operator), CliError> {
    let key = read_signing_key(sign.sign_key_file.as_deref())
        .map_err(|e| CliError::spec(format!("{cmd}: {e}")))?;
    let op = Operator::connect(&channel.channel, create).map_err(failure)?;
    Ok((key, op))
}

/// The rollouts that are readable, signed and undecided (each holds every later one in every
/// process until it is decided).
pub(super) fn undecided(op: &Operator) -> Result<Vec<u64>, CliError> {
    let decided: Vec<u64> = op
        .decisions()
        .map_err(failure)?
        .iter()
        .map(|d| d.revision)
        .collect();
    Ok(op
        .rollouts()
        .map_err(failure)?
        .iter()
        .filter(|l| l.rollout.is_ok() && l.signer.is_some() && !decided.contains(&l.revision))
        .map(|l| l.revision)
        .collect())
}

/// A new rollout waits for every earlier one in every process: refuse to propose one while an
/// earlier one is undecided.
pub(super) fn refuse_while_undecided(op: &Operator) -> CliResult {
    match undecided(op)?.first() {
        None => Ok(()),
        Some(n) => Err(CliError::spec(format!(
            "spec: rollout {n} in {} is undecided (its publisher stopped before the processes' votes were counted), and every later rollout would wait for it; decide it first: `tessla-telegraf spec decide {n} --channel ...` (counts the votes) or `tessla-telegraf spec abort {n} --channel ...`",
            op.url().shown()
        ))),
    }
}

/// Wait for the votes on `r` (proposed at server time `proposed`), write the fleet's decision
/// and print it with every vote; an abort is exit 5.
pub(super) fn settle(
    op: &Operator,
    r: &Rollout,
    proposed: i64,
    key: &nkeys::KeyPair,
    timeout: Duration,
) -> CliResult {
    let deadline = Instant::now() + timeout;
    let tally = loop {
        let statuses = op.statuses().map_err(failure)?;
        let t = decide::tally(r.revision, &statuses, proposed);
        if t.complete() || t.refused() || Instant::now() >= deadline {
            break t;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let mine = decide::decide(r, &tally, now_ns());
    let d = match op.decide(&mine, key).map_err(failure)? {
        None => mine,
        Some(Ok(first)) => first,
        Some(Err(why)) => {
            return Err(CliError::io(format!(
                "spec: rollout {} was decided by another command, but its decision cannot be read: {why}",
                r.revision
            )));
        }
    };
    print(&decision_report(&d, r))?;
    if d.commit {
        Ok(())
    } else {
        Err(CliError::aborted(format!(
            "spec: rollout {} aborted: {}; no process puts it in force",
            r.revision, d.reason
        )))
    }
}

/// Every vote, then the decision.
pub(super) fn decision_report(d: &Decision, r: &Rollout) -> String {
    let mut out = String::new();
    if !d.votes.is_empty() {
        let rows: Vec<Vec<String>> = d
            .votes
            .iter()
            .map(|v| {
                vec![
                    v.process.clone(),
                    match v.accepted {
                        Some(true) => "accepted",
                        Some(false) => "refused",
                        None => "no answer",
                    }
                    .to_string(),
                    v.reason.clone(),
                ]
            })
            .collect();
        out.push_str(&table(&["PROCESS", "VOTE", "REASON"], &rows));
    }
    if d.commit {
        out.push_str(&format!(
            "committed: {}; every process puts version {} in force from {} for {}\n",
            d.reason,
            r.id,
            show_time(r.from),
            who(&r.selector)
        ));
    } else {
        out.push_str(&format!("aborted: {}\n", d.reason));
    }
    out
}

/// The readable rollout `revision`, and when the server stored it.
pub(super) fn find_rollout(op: &Operator, revision: u64) -> Result<(Rollout, i64), CliError> {
    let listed = op.rollouts().map_err(failure)?;
    let l = listed
        .iter()
        .find(|l| l.revision == revision)
        .ok_or_else(|| {
            CliError::spec(format!(
                "spec: {} has no rollout {revision}",
                op.url().shown()
            ))
        })?;
    let r = l.rollout.clone().map_err(|why| {
        CliError::spec(format!(
            "spec: rollout {revision} cannot be read ({why}); it can only be aborted (`spec abort {revision}`)"
        ))
    })?;
    Ok((r, l.written))
}

/// The decision on `revision`, if there is one.
pub(super) fn decision_on(op: &Operator, revision: u64) -> Result<Option<Decided>, CliError> {
    Ok(op
        .decisions()
        .map_err(failure)?
        .into_iter()
        .find(|d| d.revision == revision))
}

pub(super) fn already_decided(d: &Decided) -> CliError {
    CliError::spec(format!(
        "spec: rollout {} is decided already ({}); a decision is never changed: publish a new rollout (or `spec rollback`)",
        d.revision,
        match &d.decision {
            Ok(x) if x.commit => "committed".to_string(),
            Ok(x) => format!("aborted: {}", x.reason),
            Err(why) => format!("its record cannot be read: {why}"),
        }
    ))
}

pub(super) fn decide_cmd(a: DecideArgs) -> CliResult {
    let (key, op) = signed_operator("spec decide", &a.sign, &a.channel, false)?;
    if let Some(d) = decision_on(&op, a.revision)? {
        return Err(already_decided(&d));
    }
    let (r, _) = find_rollout(&op, a.revision)?;
    // The voters are the processes alive now: the newest status key stands for the server's
    // "now" (every live process rewrites its key every few seconds).
    let now = op
        .statuses()
        .map_err(failure)?
        .iter()
        .map(|s| s.written)
        .max()
        .unwrap_or(0);
    settle(&op, &r, now, &key, a.vote.vote_timeout)
}

pub(super) fn abort_cmd(a: AbortArgs) -> CliResult {
    let (key, op) = signed_operator("spec abort", &a.sign, &a.channel, false)?;
    if let Some(d) = decision_on(&op, a.revision)? {
        return Err(already_decided(&d));
    }
    let listed = op.rollouts().map_err(failure)?;
    let Some(l) = listed.iter().find(|l| l.revision == a.revision) else {
        return Err(CliError::spec(format!(
            "spec abort: {} has no rollout {}",
            op.url().shown(),
            a.revision
        )));
    };
    let (id, digest) = match &l.rollout {
        Ok(r) => (r.id.clone(), r.digest.clone()),
        Err(_) => (String::new(), String::new()),
    };
    let d = Decision {
        revision: a.revision,
        id,
        digest,
        commit: false,
        reason: if a.reason.is_empty() {
            "aborted by the operator (spec abort)".into()
        } else {
            format!("aborted by the operator: {}", a.reason)
        },
        votes: Vec::new(),
        decided: now_ns(),
    };
    match op.decide(&d, &key).map_err(failure)? {
        None => print(&format!("rollout {}: aborted\n", a.revision)),
        Some(_) => Err(CliError::spec(format!(
            "spec abort: rollout {} was decided meanwhile by another command (`spec status` shows it)",
            a.revision
        ))),
    }
}

pub(super) fn rollback(a: RollbackArgs) -> CliResult {
    let (key, op) = signed_operator("spec rollback", &a.sign, &a.channel, false)?;
    refuse_while_undecided(&op)?;
    // Only committed rollouts were ever in force: aborted ones are skipped.
    let committed: Vec<u64> = op
        .decisions()
        .map_err(failure)?
        .iter()
        .filter(|d| d.decision.as_ref().is_ok_and(|x| x.commit))
        .map(|d| d.revision)
        .collect();
    let rollouts: Vec<Rollout> = op
        .rollouts()
        .map_err(failure)?
        .into_iter()
        .filter(|l| committed.contains(&l.revision))
        .filter_map(|l| l.rollout.ok())
        // A fleet spec is rolled back by publishing the earlier one with `--fleet`.
        .filter(|r| !r.fleet)
        .collect();
    let Some((undone, selector, previous)) = rollback_plan(&rollouts, a.select.as_ref()) else {
        return Err(CliError::spec(match &a.select {
            None => format!(
                "spec rollback: nothing to roll back: the spec channel {} has no rollout",
                op.url().shown()
            ),
            Some(s) => format!(
                "spec rollback: nothing to roll back for {s}: no rollout in {} is for all of those instances",
                op.url().shown()
            ),
        }));
    };
    let (id, digest) = match previous {
        Some(p) => {
            if p.id != BASE {
                op.check_bundle(p).map_err(|e| {
                    CliError::io(format!(
                        "spec rollback: version {} (rollout {}) cannot be published again: {e}",
                        p.id, p.revision
                    ))
                })?;
            }
            (p.id.clone(), p.digest.clone())
        }
        None => (BASE.to_string(), String::new()),
    };
    let now = now_ns();
    let rollout = Rollout {
        revision: 0,
        id,
        digest,
        label: format!("rollback of {}", undone.id),
        from: a.from.unwrap_or(now),
        selector,
        published: now,
        fleet: false,
    };
    let (r, proposed) = op.publish(None, rollout, &key).map_err(failure)?;
    let what = match previous {
        Some(p) => format!("the version of rollout {}", p.revision),
        None => "the spec each process started with".into(),
    };
    print(&format!(
        "{}: rolls back rollout {} to {what}\n",
        published_line(&r, ""),
        undone.revision
    ))?;
    settle(&op, &r, proposed, &key, a.vote.vote_timeout)
}
