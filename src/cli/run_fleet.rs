//! `tessla-telegraf run --state nats://...`: the run with a shared state bucket (and, with
//! `?lease=NAME`, a partition lease), driving [`crate::transport::nats_fleet`] on stdin/stdout.

use super::{CliError, CliResult, RunArgs};
use crate::processor::reload::{self, SpecSource};
use crate::processor::{Options, Processor};
use crate::state::nats::NatsBackend;
use crate::state::nats_conn::Failure;
use crate::state::url::Url;
use crate::state::{self, Backend};
use crate::transport::nats_fleet::{self, Fleet};
use std::time::Duration;

pub fn run(
    args: &RunArgs,
    url: &Url,
    mut proc: Processor,
    opts: Options,
    source: &SpecSource,
    ctx: &state::Context,
    watch: std::sync::Arc<crate::watchdog::Watch>,
) -> CliResult {
    if args.udp_listen.is_some() {
        return Err(CliError::spec(
            "--state nats://... runs on stdin/stdout (Telegraf's execd); --udp-listen is not supported with it",
        ));
    }
    let mut backend = NatsBackend::connect(url, &proc, ctx).map_err(|e| match e {
        Failure::Config(m) => CliError::spec(format!("state: {m}")),
        Failure::Io(m) => CliError::io(format!("state: {m}")),
    })?;
    let lease = backend.lease();
    let program = proc.program().clone();
    let fresh = move || Processor::new(program.clone(), opts.clone()).ok();
    let mut on_hangup = |p: &mut Processor, out: &mut Vec<u8>| {
        reload::reload(source, p, out);
    };
    // A standby must keep at least what the holder may not have saved: two save intervals
    // (one minute without --state-interval) and two lease TTLs.
    let window = args.state_interval.unwrap_or(Duration::from_secs(30)) * 2 + url.ttl * 2;
    let rt = super::run::runtime()?;
    let result = rt.block_on(nats_fleet::run(
        &mut proc,
        Fleet {
            backend: &mut backend as &mut dyn Backend,
            lease,
            instance_by: ctx.instance_by.clone(),
            interval: args.state_interval,
            window,
            fresh: &fresh,
            on_hangup: &mut on_hangup,
            watch,
        },
    ));
    super::run::finish(rt, result, &proc)
}
