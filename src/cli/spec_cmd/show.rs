//! The `spec` subcommands that read the channel: `list` (rollouts and decisions, as a table or
//! JSON) and `status` (each process's votes and whether its status key is live).

use super::args::*;
use super::table::*;
use super::{failure, print};
use crate::cli::error::CliResult;
use crate::spec_feed::Phase;
use crate::spec_feed::nats::{Decided, LIVE, Listed, Operator, Reported, Status};
use crate::spec_feed::status::now_ns;
use serde_json::{Value, json};

pub(super) fn list(a: ListArgs) -> CliResult {
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

pub(super) fn no_bucket(op: &Operator) -> String {
    format!(
        "no rollouts: the spec channel {} has no bucket yet (the first `tessla-telegraf spec publish` creates it)\n",
        op.url().shown()
    )
}

pub(super) fn rollout_json(l: &Listed, decided: &[Decided], statuses: &[Status]) -> Value {
    let decision = match decided.iter().find(|d| d.revision == l.revision) {
        None => Value::Null,
        Some(d) => match &d.decision {
            Ok(x) => serde_json::to_value(x).unwrap_or(Value::Null),
            Err(why) => json!({ "problem": why.to_string() }),
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
        Err(why) => json!({ "revision": l.revision, "problem": why.to_string() }),
    }
}

/// What a status key says of its process: renewed within [`LIVE`] (by the server's clock),
/// marked stopped as it ended, or neither (a crash, a lost connection, or a key of a process
/// restarted since under a new pid): silent, and no voter on a new rollout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Liveness {
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

pub(super) fn liveness(r: &Reported, s: &Status, now: i64) -> Liveness {
    let live = i64::try_from(LIVE.as_nanos()).unwrap_or(i64::MAX);
    if s.stopped {
        Liveness::Stopped
    } else if now.saturating_sub(r.written) > live {
        Liveness::Silent
    } else {
        Liveness::Live
    }
}

pub(super) fn status(a: ListArgs) -> CliResult {
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
                Err(why) => json!({ "key": r.key, "problem": why.to_string() }),
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
                    why.to_string(),
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
