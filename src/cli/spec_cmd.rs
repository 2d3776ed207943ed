//! `tessla-telegraf spec publish|decide|abort|list|status|rollback|keygen|init`: the operator's
//! command for the fleet's spec channel (`spec_feed::nats`). It logs in with the URL, TLS and
//! credential options of `--state` (`--channel URL`) and signs what it publishes and decides
//! with the operator's seed (`--sign-key-file FILE` or `TESSLA_SIGN_KEY`, never on the command
//! line).
//!
//! Owns: checking a spec before it is published (a spec that does not check is refused here,
//! with the full diagnostic, exit 2), waiting for the processes' votes and writing the fleet's
//! decision (the rule is `spec_feed::decide`'s; exit 5 on an abort), the `--from` time and
//! `--select` syntax, which version a rollback publishes, and the tables and JSON it prints.

use super::error::{CliError, CliResult};
use super::spec_options::{SpecOptions, load_options, require_outputs};
use crate::nats::conn::Failure;
use crate::nats::url::Url;
use crate::processor::versions::Selector;
use crate::spec_feed::bundle::Bundle;
use crate::spec_feed::decide;
use crate::spec_feed::nats::{Decided, LIVE, Listed, Operator, Reported, Status, parse_url};
use crate::spec_feed::sign::read_signing_key;
use crate::spec_feed::status::{now_ns, show_time};
use crate::spec_feed::{BASE, Decision, Phase, Rollout};
use clap::{Args, Subcommand};
use serde_json::{Value, json};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

#[derive(Debug, Args, Clone)]
pub struct SpecArgs {
    #[command(subcommand)]
    pub action: SpecAction,
}

#[derive(Debug, Subcommand, Clone)]
pub enum SpecAction {
    /// Check a spec (with its includes), put it in the channel and propose a signed rollout of
    /// it; every live process following the channel checks it and votes, and the fleet's
    /// decision (commit when all accepted, else abort) is written once: exit 5 on an abort.
    Publish(PublishArgs),
    /// Decide a rollout left undecided (its publisher stopped before deciding): count the
    /// votes of the processes alive now and write the decision.
    Decide(DecideArgs),
    /// Abort an undecided rollout outright (no process acts on it).
    Abort(AbortArgs),
    /// Every rollout: revision, version, label, from, selector, published, signer.
    List(ListArgs),
    /// The rollouts and what every process made of each (accepted, or refused and why).
    Status(ListArgs),
    /// Publish again the version in force before the last rollout for --select's instances
    /// (without --select: the last rollout's), labelled `rollback of <id>`.
    Rollback(RollbackArgs),
    /// Make the operator's signing key: a seed (secret, for `spec publish`) and its public key
    /// (for every process's --spec-trust).
    Keygen(KeygenArgs),
    /// Create the channel's bucket (what the first `spec publish` does, `replicas=N` from the
    /// URL), so that the processes following it report their status before any rollout;
    /// nothing is changed when it exists.
    Init(InitArgs),
}

#[derive(Debug, Args, Clone)]
pub struct InitArgs {
    #[command(flatten)]
    pub channel: ChannelArgs,
}

/// The channel and how to log in to it.
#[derive(Debug, Args, Clone)]
pub struct ChannelArgs {
    /// The spec channel: `nats://HOST:PORT[,HOST:PORT...][/BUCKET][?options]`, bucket
    /// `tessla_specs` when none is named, with --state's login and TLS options
    /// (`user=NAME&password-env=VAR`, `nkey-file=`, `creds=`, `tls-ca=`, ...) and `replicas=N`
    /// (when publishing creates the bucket).
    #[arg(long, value_name = "nats://HOST:PORT[/BUCKET]", value_parser = parse_url)]
    pub channel: Url,
}

/// The signing seed.
#[derive(Debug, Args, Clone, Default)]
pub struct SignArgs {
    /// A file holding the operator's seed (`spec keygen --seed-file`); without it the
    /// environment variable TESSLA_SIGN_KEY holds the seed.
    #[arg(long, value_name = "FILE")]
    pub sign_key_file: Option<PathBuf>,
}

#[derive(Debug, Args, Clone)]
pub struct PublishArgs {
    /// The `.tessla` file; its includes are published with it.
    pub spec: PathBuf,
    /// A label shown beside the version's id (`tight delta`).
    #[arg(long)]
    pub label: Option<String>,
    /// The event time from which it is in force: RFC 3339 (`2025-06-01T12:00:00Z`),
    /// nanoseconds since the Unix epoch, or `+DURATION` from now (`+2s`: every process has it
    /// before its records reach that time, so all switch at one point); default: now.
    #[arg(long, value_name = "TIME", value_parser = parse_time)]
    pub from: Option<i64>,
    /// Only the instances whose `--instance-by` tags match: `robot=r1,r2[;site=lab]`;
    /// default: every instance.
    #[arg(long, value_name = "TAG=V1,V2[;TAG=V]", value_parser = Selector::parse)]
    pub select: Option<Selector>,
    #[command(flatten)]
    pub vote: VoteArgs,
    #[command(flatten)]
    pub channel: ChannelArgs,
    #[command(flatten)]
    pub sign: SignArgs,
    #[command(flatten)]
    pub spec_options: SpecOptions,
}

/// How long to wait for the processes' votes.
#[derive(Debug, Args, Clone)]
pub struct VoteArgs {
    /// How long to wait for every live process's vote; a process that has not answered by
    /// then counts as a refusal (the rollout is aborted).
    #[arg(long, value_name = "DURATION", default_value = "10s", value_parser = humantime::parse_duration)]
    pub vote_timeout: Duration,
}

#[derive(Debug, Args, Clone)]
pub struct DecideArgs {
    /// The rollout's revision (`spec status` lists the undecided ones).
    pub revision: u64,
    #[command(flatten)]
    pub vote: VoteArgs,
    #[command(flatten)]
    pub channel: ChannelArgs,
    #[command(flatten)]
    pub sign: SignArgs,
}

#[derive(Debug, Args, Clone)]
pub struct AbortArgs {
    /// The rollout's revision.
    pub revision: u64,
    /// Why (recorded in the decision and shown by `spec status`).
    #[arg(long, default_value = "")]
    pub reason: String,
    #[command(flatten)]
    pub channel: ChannelArgs,
    #[command(flatten)]
    pub sign: SignArgs,
}

#[derive(Debug, Args, Clone)]
pub struct ListArgs {
    #[command(flatten)]
    pub channel: ChannelArgs,
    /// Print JSON instead of tables (for scripts).
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args, Clone)]
pub struct RollbackArgs {
    /// The instances to roll back: `robot=r1,r2[;site=lab]`; default: those of the last
    /// rollout.
    #[arg(long, value_name = "TAG=V1,V2[;TAG=V]", value_parser = Selector::parse)]
    pub select: Option<Selector>,
    /// The event time from which the rollback is in force (as publish's); default: now.
    #[arg(long, value_name = "TIME", value_parser = parse_time)]
    pub from: Option<i64>,
    #[command(flatten)]
    pub vote: VoteArgs,
    #[command(flatten)]
    pub channel: ChannelArgs,
    #[command(flatten)]
    pub sign: SignArgs,
}

#[derive(Debug, Args, Clone, Default)]
pub struct KeygenArgs {
    /// Write the seed to FILE (created, readable by its owner only; never overwritten) and
    /// print only the public key.
    #[arg(long, value_name = "FILE")]
    pub seed_file: Option<PathBuf>,
}

/// `--from`: RFC 3339, an integer count of nanoseconds since the Unix epoch, or `+DURATION`
/// from now (`+2s`: a start every process of the fleet receives before it comes).
pub fn parse_time(s: &str) -> Result<i64, String> {
    let s = s.trim();
    if let Ok(ns) = s.parse::<i64>() {
        return Ok(ns);
    }
    if let Some(ahead) = s.strip_prefix('+') {
        let d = humantime::parse_duration(ahead.trim())
            .map_err(|e| format!("`{s}`: {e} (expected +DURATION, e.g. +2s)"))?;
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_err(|_| "the clock is before 1970".to_string())?;
        return i64::try_from((now + d).as_nanos())
            .map_err(|_| format!("`{s}` is past the year 2262"));
    }
    let t = humantime::parse_rfc3339_weak(s).map_err(|e| {
        format!("`{s}`: {e} (expected RFC 3339, e.g. 2025-06-01T12:00:00Z, or nanoseconds since the Unix epoch)")
    })?;
    let d = t
        .duration_since(std::time::UNIX_EPOCH)
        .map_err(|_| format!("`{s}` is before 1970"))?;
    i64::try_from(d.as_nanos()).map_err(|_| format!("`{s}` is past the year 2262"))
}

pub fn run(args: SpecArgs) -> CliResult {
    match args.action {
        SpecAction::Publish(a) => publish(a),
        SpecAction::Decide(a) => decide_cmd(a),
        SpecAction::Abort(a) => abort_cmd(a),
        SpecAction::List(a) => list(a),
        SpecAction::Status(a) => status(a),
        SpecAction::Rollback(a) => rollback(a),
        SpecAction::Keygen(a) => keygen(a),
        SpecAction::Init(a) => init(a),
    }
}

fn init(a: InitArgs) -> CliResult {
    let op = Operator::connect(&a.channel.channel, true).map_err(failure)?;
    print(&format!(
        "spec channel {}: {}\n",
        op.url().shown(),
        if op.created() {
            "bucket created"
        } else {
            "bucket exists already"
        }
    ))
}

fn failure(f: Failure) -> CliError {
    match f {
        Failure::Config(m) => CliError::spec(format!("spec: {m}")),
        Failure::Io(m) => CliError::io(format!("spec: {m}")),
    }
}

fn print(text: &str) -> CliResult {
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .map_err(|e| CliError::io(format!("cannot write to stdout: {e}")))
}

fn publish(a: PublishArgs) -> CliResult {
    let mut spec_options = a.spec_options.clone();
    spec_options.set_from_env();
    let options = load_options(&spec_options).map_err(CliError::spec)?;
    let (bundle, loaded) = Bundle::read(&a.spec, &options).map_err(|e| {
        CliError::spec(format!(
            "{}\nspec publish: {} was not published: it does not check",
            e.render().trim_end(),
            a.spec.display()
        ))
    })?;
    require_outputs(&loaded.program, &a.spec.display().to_string()).map_err(CliError::spec)?;
    if !loaded.warnings.is_empty() {
        let text = tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, false);
        let _ = std::io::stderr().lock().write_all(text.as_bytes());
    }
    let key = read_signing_key(a.sign.sign_key_file.as_deref())
        .map_err(|e| CliError::spec(format!("spec publish: {e}")))?;
    let op = Operator::connect(&a.channel.channel, true).map_err(failure)?;
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
        selector: a.select.clone().unwrap_or_default(),
        published: now,
    };
    let (r, proposed) = op.publish(Some(&bundle), rollout, &key).map_err(failure)?;
    print(&format!("{}\n", published_line(&r, "")))?;
    settle(&op, &r, proposed, &key, a.vote.vote_timeout)
}

/// The rollouts that are readable, signed and undecided (each holds every later one in every
/// process until it is decided).
fn undecided(op: &Operator) -> Result<Vec<u64>, CliError> {
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
fn refuse_while_undecided(op: &Operator) -> CliResult {
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
fn settle(
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
fn decision_report(d: &Decision, r: &Rollout) -> String {
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
fn find_rollout(op: &Operator, revision: u64) -> Result<(Rollout, i64), CliError> {
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
fn decision_on(op: &Operator, revision: u64) -> Result<Option<Decided>, CliError> {
    Ok(op
        .decisions()
        .map_err(failure)?
        .into_iter()
        .find(|d| d.revision == revision))
}

fn already_decided(d: &Decided) -> CliError {
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

fn decide_cmd(a: DecideArgs) -> CliResult {
    let key = read_signing_key(a.sign.sign_key_file.as_deref())
        .map_err(|e| CliError::spec(format!("spec decide: {e}")))?;
    let op = Operator::connect(&a.channel.channel, false).map_err(failure)?;
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

fn abort_cmd(a: AbortArgs) -> CliResult {
    let key = read_signing_key(a.sign.sign_key_file.as_deref())
        .map_err(|e| CliError::spec(format!("spec abort: {e}")))?;
    let op = Operator::connect(&a.channel.channel, false).map_err(failure)?;
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

/// `rollout N: version ID (`label`) in force from T for S`.
fn published_line(r: &Rollout, note: &str) -> String {
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

fn who(s: &Selector) -> String {
    if s.is_all() {
        "every instance".into()
    } else {
        s.to_string()
    }
}

fn list(a: ListArgs) -> CliResult {
    let op = Operator::connect(&a.channel.channel, false).map_err(failure)?;
    let listed = op.rollouts().map_err(failure)?;
    let decided = op.decisions().map_err(failure)?;
    if a.json {
        let v = json!({
            "channel": op.url().shown(),
            "rollouts": listed.iter().map(|l| rollout_json(l, &decided, &[])).collect::<Vec<_>>(),
        });
        return print(&format!("{v:#}\n"));
    }
    if !op.exists() {
        return print(&no_bucket(&op));
    }
    print(&rollout_table(&listed, &decided, None))
}

/// A rollout's decision in a word: `committed`, `aborted`, `undecided` (or why its record
/// cannot be read).
fn decision_word(revision: u64, decided: &[Decided]) -> String {
    match decided.iter().find(|d| d.revision == revision) {
        None => "undecided".into(),
        Some(d) => match &d.decision {
            Ok(x) if x.commit => "committed".into(),
            Ok(_) => "aborted".into(),
            Err(why) => format!("unreadable decision: {why}"),
        },
    }
}

fn no_bucket(op: &Operator) -> String {
    format!(
        "no rollouts: the spec channel {} has no bucket yet (the first `tessla-telegraf spec publish` creates it)\n",
        op.url().shown()
    )
}

fn rollout_json(l: &Listed, decided: &[Decided], statuses: &[Status]) -> Value {
    let decision = match decided.iter().find(|d| d.revision == l.revision) {
        None => Value::Null,
        Some(d) => match &d.decision {
            Ok(x) => serde_json::to_value(x).unwrap_or(Value::Null),
            Err(why) => json!({ "problem": why }),
        },
    };
    match &l.rollout {
        Ok(r) => {
            let (acc, refd) = counts(l.revision, statuses);
            let mut v = json!({
                "revision": l.revision,
                "id": r.id,
                "digest": r.digest,
                "label": r.label,
                "from": r.from,
                "selector": r.selector.to_string(),
                "published": r.published,
                "signer": l.signer,
                "state": decision_word(l.revision, decided),
                "decision": decision,
            });
            if !statuses.is_empty() {
                v["accepted"] = json!(acc);
                v["refused"] = json!(refd);
            }
            v
        }
        Err(why) => json!({ "revision": l.revision, "problem": why }),
    }
}

/// How many processes voted to accept and to refuse rollout `revision` (each process's latest
/// check of it).
fn counts(revision: u64, statuses: &[Status]) -> (usize, usize) {
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

fn published_time(ns: i64) -> String {
    match u64::try_from(ns) {
        Ok(n) if n > 0 => humantime::format_rfc3339_seconds(
            std::time::UNIX_EPOCH + std::time::Duration::from_nanos(n),
        )
        .to_string(),
        _ => "-".into(),
    }
}

fn short_key(k: &Option<String>) -> String {
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
fn rollout_table(listed: &[Listed], decided: &[Decided], statuses: Option<&[Status]>) -> String {
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
fn table(head: &[&str], rows: &[Vec<String>]) -> String {
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

/// What a status key says of its process: renewed within [`LIVE`] (by the server's clock),
/// marked stopped as it ended, or neither (a crash, a lost connection, or a key of a process
/// restarted since under a new pid): silent, and no voter on a new rollout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Liveness {
    Live = 0,
    Silent = 1,
    Stopped = 2,
}

impl Liveness {
    fn word(self) -> &'static str {
        match self {
            Liveness::Live => "live",
            Liveness::Silent => "silent",
            Liveness::Stopped => "stopped",
        }
    }
}

fn liveness(r: &Reported, s: &Status, now: i64) -> Liveness {
    let live = i64::try_from(LIVE.as_nanos()).unwrap_or(i64::MAX);
    if s.stopped {
        Liveness::Stopped
    } else if now.saturating_sub(r.written) > live {
        Liveness::Silent
    } else {
        Liveness::Live
    }
}

fn status(a: ListArgs) -> CliResult {
    let op = Operator::connect(&a.channel.channel, false).map_err(failure)?;
    let listed = op.rollouts().map_err(failure)?;
    let decided = op.decisions().map_err(failure)?;
    let keyed = op.statuses().map_err(failure)?;
    let statuses: Vec<Status> = keyed
        .iter()
        .filter_map(|r| r.status.as_ref().ok().cloned())
        .collect();
    let now = now_ns();
    if a.json {
        let processes: Vec<Value> = keyed
            .iter()
            .map(|r| match &r.status {
                Ok(s) => {
                    let mut v = serde_json::to_value(s).unwrap_or(Value::Null);
                    v["key"] = json!(r.key);
                    v["state"] = json!(liveness(r, s, now).word());
                    v
                }
                Err(why) => json!({ "key": r.key, "problem": why }),
            })
            .collect();
        let v = json!({
            "channel": op.url().shown(),
            "rollouts": listed.iter().map(|l| rollout_json(l, &decided, &statuses)).collect::<Vec<_>>(),
            "processes": processes,
        });
        return print(&format!("{v:#}\n"));
    }
    if !op.exists() {
        return print(&no_bucket(&op));
    }
    let mut out = format!("Rollouts in {}\n", op.url().shown());
    out.push_str(&rollout_table(&listed, &decided, Some(&statuses)));
    let mut live = [0usize; 3];
    for r in &keyed {
        if let Ok(s) = &r.status {
            live[liveness(r, s, now) as usize] += 1;
        }
    }
    out.push_str(&format!(
        "\nProcesses ({}: {} live, {} silent, {} stopped)\n",
        keyed.len(),
        live[Liveness::Live as usize],
        live[Liveness::Silent as usize],
        live[Liveness::Stopped as usize]
    ));
    if keyed.is_empty() {
        out.push_str("no process has reported yet\n");
        return print(&out);
    }
    let mut rows = Vec::new();
    for r in &keyed {
        let k = &r.key;
        let s = match &r.status {
            Ok(s) => s,
            Err(why) => {
                rows.push(vec![
                    k.clone(),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                    "?".into(),
                    why.clone(),
                ]);
                continue;
            }
        };
        let secs = (now - r.written).max(0) / 1_000_000_000;
        let ago = match liveness(r, s, now) {
            Liveness::Live => format!("{secs}s ago"),
            Liveness::Silent => format!("{secs}s ago, silent"),
            Liveness::Stopped => format!("stopped {secs}s ago"),
        };
        // Each rollout's latest outcome in this process, in revision order.
        let mut latest: Vec<&crate::spec_feed::Outcome> = Vec::new();
        for o in &s.outcomes {
            match latest.iter_mut().find(|x| x.revision == o.revision) {
                Some(x) => *x = o,
                None => latest.push(o),
            }
        }
        latest.sort_by_key(|o| o.revision);
        if latest.is_empty() {
            rows.push(vec![
                s.host.clone(),
                dash(&s.partition),
                s.pid.to_string(),
                ago.clone(),
                String::new(),
                String::new(),
                "no outcome yet".into(),
                String::new(),
            ]);
        }
        for o in latest {
            rows.push(vec![
                s.host.clone(),
                dash(&s.partition),
                s.pid.to_string(),
                ago.clone(),
                if o.revision == 0 {
                    "local".into()
                } else {
                    o.revision.to_string()
                },
                o.id.clone(),
                // The vote, then what the decision did here.
                match s
                    .outcomes
                    .iter()
                    .rev()
                    .find(|v| v.revision == o.revision && v.phase == Phase::Check)
                {
                    Some(v) if o.revision != 0 && o.phase != Phase::Check => {
                        format!("voted {}, {}", v.word(), o.word())
                    }
                    _ => o.word().to_string(),
                },
                if o.accepted && !o.reset_outputs.is_empty() {
                    format!("outputs starting afresh: {}", o.reset_outputs.join(", "))
                } else {
                    o.reason.clone()
                },
            ]);
        }
    }
    out.push_str(&table(
        &[
            "HOST",
            "PARTITION",
            "PID",
            "REPORTED",
            "REV",
            "VERSION",
            "OUTCOME",
            "REASON",
        ],
        &rows,
    ));
    print(&out)
}

fn dash(s: &str) -> String {
    if s.is_empty() {
        "-".into()
    } else {
        s.to_string()
    }
}

/// Whether every instance `s` picks is picked by `x` (each of `x`'s clauses is a clause of `s`
/// on the same tag with no value outside `x`'s; `x` picking every instance covers any).
fn covers(x: &Selector, s: &Selector) -> bool {
    let xs = clauses(x);
    let ss = clauses(s);
    xs.iter().all(|(tag, values)| {
        ss.iter()
            .any(|(t, v)| t == tag && v.iter().all(|x| values.contains(x)))
    })
}

/// A selector's clauses, read back from its written form (`TAG=V1,V2;TAG=V`).
fn clauses(s: &Selector) -> Vec<(String, Vec<String>)> {
    s.to_string()
        .split(';')
        .filter_map(|c| c.split_once('='))
        .map(|(t, v)| (t.to_string(), v.split(',').map(str::to_string).collect()))
        .collect()
}

/// Which rollout a rollback undoes and which version it publishes: the last readable rollout
/// covering `select` (the last one, without it) and the latest earlier one covering the same
/// instances (none: the base version). (undone, selector, previous)
fn rollback_plan<'a>(
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

fn rollback(a: RollbackArgs) -> CliResult {
    let key = read_signing_key(a.sign.sign_key_file.as_deref())
        .map_err(|e| CliError::spec(format!("spec rollback: {e}")))?;
    let op = Operator::connect(&a.channel.channel, false).map_err(failure)?;
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

fn keygen(a: KeygenArgs) -> CliResult {
    let key = nkeys::KeyPair::new_operator();
    let seed = key
        .seed()
        .map_err(|e| CliError::io(format!("spec keygen: {e}")))?;
    match &a.seed_file {
        Some(path) => {
            write_secret(path, &seed)?;
            print(&format!(
                "seed written to {} (keep it secret: spec publish --sign-key-file {})\npublic key: {}\n",
                path.display(),
                path.display(),
                key.public_key()
            ))
        }
        None => print(&format!("seed: {seed}\npublic key: {}\n", key.public_key())),
    }
}

/// Create `path` readable by its owner only and write `seed` to it; an existing file is kept.
fn write_secret(path: &Path, seed: &str) -> CliResult {
    use std::os::unix::fs::OpenOptionsExt;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)
        .map_err(|e| {
            CliError::io(format!(
                "spec keygen: cannot create {}: {e} (an existing seed file is never overwritten)",
                path.display()
            ))
        })?;
    f.write_all(format!("{seed}\n").as_bytes())
        .and_then(|()| f.sync_all())
        .map_err(|e| CliError::io(format!("spec keygen: cannot write {}: {e}", path.display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_status_key_reads_live_silent_or_stopped() {
        const S: i64 = 1_000_000_000;
        let now = 100 * S;
        let at = |written: i64, stopped: bool| {
            let s = Status {
                host: "h".into(),
                partition: "p0".into(),
                pid: 7,
                time: written,
                outcomes: Vec::new(),
                stopped,
            };
            let r = Reported {
                key: "status.vh.vp0.pid7".into(),
                status: Ok(s.clone()),
                written,
            };
            liveness(&r, &s, now)
        };
        assert_eq!(at(now - 2 * S, false), Liveness::Live);
        // No heartbeat for longer than LIVE: a crash, or a process restarted under a new pid.
        assert_eq!(at(now - 11 * S, false), Liveness::Silent);
        assert_eq!(at(now - 2 * S, true), Liveness::Stopped);
        assert_eq!(at(now - 600 * S, true), Liveness::Stopped);
    }

    fn r(revision: u64, id: &str, sel: &str) -> Rollout {
        Rollout {
            revision,
            id: id.into(),
            digest: String::new(),
            label: String::new(),
            from: 0,
            selector: Selector::parse(sel).unwrap(),
            published: 0,
        }
    }

    #[test]
    fn times_are_rfc3339_or_nanoseconds() {
        assert_eq!(
            parse_time("1700000000000000000"),
            Ok(1_700_000_000_000_000_000)
        );
        assert_eq!(parse_time("1970-01-01T00:00:01Z"), Ok(1_000_000_000));
        assert_eq!(
            parse_time("2023-11-14T22:13:20.5Z"),
            Ok(1_700_000_000_500_000_000)
        );
        assert!(parse_time("yesterday").unwrap_err().contains("RFC 3339"));
        // `+DURATION`: that far from now.
        let before = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos() as i64;
        let t = parse_time("+2s").unwrap();
        assert!(
            t >= before + 2_000_000_000 && t < before + 3_000_000_000,
            "{t}"
        );
        assert!(parse_time("+soon").unwrap_err().contains("+DURATION"));
    }

    #[test]
    fn a_rollback_publishes_the_version_in_force_before_the_last_rollout() {
        let all = [r(1, "a", ""), r(2, "b", "robot=r1"), r(3, "c", "")];
        // The whole fleet: the previous rollout's version.
        let (undone, sel, prev) = rollback_plan(&all, None).unwrap();
        assert_eq!(
            (undone.revision, sel.is_all(), prev.map(|p| p.revision)),
            (3, true, Some(1))
        );
        // A canary: the last rollout for r1 is 3 (for all), before it 2 (r1).
        let s = Selector::parse("robot=r1").unwrap();
        let (undone, _, prev) = rollback_plan(&all, Some(&s)).unwrap();
        assert_eq!((undone.revision, prev.map(|p| p.revision)), (3, Some(2)));
        // The last rollout a canary: undone for its own robots, back to 1.
        let canary = [r(1, "a", ""), r(2, "b", "robot=r1,r2")];
        let (undone, sel, prev) = rollback_plan(&canary, None).unwrap();
        assert_eq!(
            (undone.revision, sel.to_string(), prev.map(|p| p.revision)),
            (2, "robot=r1,r2".into(), Some(1))
        );
        // Only one rollout: back to the base.
        let (_, _, prev) = rollback_plan(&canary[..1], None).unwrap();
        assert!(prev.is_none());
        // A wider rollout covers a narrower selector; a narrower one does not cover a wider.
        assert!(covers(&Selector::parse("robot=r1,r2").unwrap(), &s));
        assert!(!covers(&s, &Selector::parse("robot=r1,r2").unwrap()));
        assert!(rollback_plan(&[r(1, "a", "robot=r9")], Some(&s)).is_none());
        assert!(rollback_plan(&[], None).is_none());
    }

    #[test]
    fn a_signer_is_shortened_by_characters() {
        assert_eq!(short_key(&Some("OABCDEFGHIJKLMNOP".into())), "OABCDE…MNOP");
        assert_eq!(short_key(&Some("ééééééééééééééé".into())), "éééééé…éééé");
        assert_eq!(short_key(&None), "unsigned");
    }

    #[test]
    fn tables_line_up() {
        let t = table(
            &["A", "BB"],
            &[
                vec!["xyz".into(), "1".into()],
                vec!["q".into(), String::new()],
            ],
        );
        assert_eq!(t, "A    BB\nxyz  1\nq\n");
    }
}
