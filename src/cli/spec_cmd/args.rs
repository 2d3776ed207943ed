//! The `spec` subcommand's clap structs (its eight actions and their options) and the `--from`
//! time syntax.

use crate::cli::spec_options::SpecOptions;
use crate::nats::url::Url;
use crate::processor::versions::Selector;
use crate::spec_feed::nats::parse_url;
use clap::{Args, Subcommand};
use std::path::PathBuf;
use std::time::Duration;

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
    /// The `.tessla` file; its includes are published with it. With `--fleet`: the robot spec
    /// the fleet spec is checked against (not published).
    pub spec: PathBuf,
    /// Publish a version of the fleet spec (`run --fleet-spec`) instead: FILE is checked
    /// against the robot spec as `--fleet-spec` is at start-up, and the fleet level of every
    /// process switches to it at its first step at or after `--from` (docs/fleet.md).
    #[arg(long, value_name = "FILE", conflicts_with = "select")]
    pub fleet: Option<PathBuf>,
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
pub fn parse_time(s: &str) -> Result<i64, TimeError> {
    let s = s.trim();
    if let Ok(ns) = s.parse::<i64>() {
        return Ok(ns);
    }
    let past_2262 = |_| TimeError::Past2262(s.to_string());
    if let Some(ahead) = s.strip_prefix('+') {
        let d = humantime::parse_duration(ahead.trim()).map_err(|why| TimeError::Ahead {
            given: s.to_string(),
            why,
        })?;
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_err(|_| TimeError::ClockBefore1970)?;
        return i64::try_from((now + d).as_nanos()).map_err(past_2262);
    }
    let t = humantime::parse_rfc3339_weak(s).map_err(|why| TimeError::At {
        given: s.to_string(),
        why,
    })?;
    let d = t
        .duration_since(std::time::UNIX_EPOCH)
        .map_err(|_| TimeError::Before1970(s.to_string()))?;
    i64::try_from(d.as_nanos()).map_err(past_2262)
}

/// Why a `--from` time is refused (the time as given).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TimeError {
    #[error("`{given}`: {why} (expected +DURATION, e.g. +2s)")]
    Ahead {
        given: String,
        why: humantime::DurationError,
    },
    #[error(
        "`{given}`: {why} (expected RFC 3339, e.g. 2025-06-01T12:00:00Z, or nanoseconds since the Unix epoch)"
    )]
    At {
        given: String,
        why: humantime::TimestampError,
    },
    #[error("the clock is before 1970")]
    ClockBefore1970,
    #[error("`{0}` is before 1970")]
    Before1970(String),
    #[error("`{0}` is past the year 2262")]
    Past2262(String),
}
