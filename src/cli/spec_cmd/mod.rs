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
//!
//! Split by concern: [`args`] (the clap structs, `--from`), [`publish`] (the subcommands that
//! write: publish, decide, abort, rollback), [`show`] (the ones that read: list, status),
//! [`table`] (the table renderer and the lines it prints), [`selector`] (the selector algebra a
//! rollback needs); `init` and `keygen` here.

pub mod args;
pub mod publish;
pub mod selector;
pub mod show;
pub mod table;

pub use args::*;

use crate::cli::error::{CliError, CliResult};
use crate::nats::conn::Failure;
use crate::spec_feed::nats::Operator;
use publish::*;
use show::*;
use std::io::Write;
use std::path::Path;

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

pub(super) fn init(a: InitArgs) -> CliResult {
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

/// A NATS failure of the `spec` command, its message led by `spec: `.
pub(super) fn failure(f: Failure) -> CliError {
    CliError::from(f).within("spec")
}

pub(super) fn print(text: &str) -> CliResult {
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())
        .and_then(|()| out.flush())
        .map_err(|e| CliError::io(format!("cannot write to stdout: {e}")))
}

pub(super) fn keygen(a: KeygenArgs) -> CliResult {
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
pub(super) fn write_secret(path: &Path, seed: &str) -> CliResult {
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
    use super::selector::{covers, rollback_plan};
    use super::show::{Liveness, liveness};
    use super::table::{short_key, table};
    use super::*;
    use crate::processor::versions::Selector;
    use crate::spec_feed::Rollout;
    use crate::spec_feed::nats::{Reported, Status};

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
            fleet: false,
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
        assert!(
            parse_time("yesterday")
                .unwrap_err()
                .to_string()
                .contains("RFC 3339")
        );
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
        assert!(
            parse_time("+soon")
                .unwrap_err()
                .to_string()
                .contains("+DURATION")
        );
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
