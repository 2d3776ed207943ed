//! `tessla-telegraf run --state nats://...`: the run with a shared state bucket (and, with
//! `?lease=NAME`, a partition lease), driving [`crate::telegraf::fleet`] on stdin/stdout.

use super::{EXIT_IO, EXIT_OK, RunArgs};
use crate::log::{self, Level};
use crate::telegraf::fleet::{self, Fleet};
use crate::telegraf::processor::{Options, Processor};
use crate::telegraf::reload::{self, SpecSource};
use crate::telegraf::state::{self, Backend};
use crate::telegraf::state_nats::{NatsBackend, Url};
use crate::transport::Ending;
use std::time::Duration;

pub fn run(
    args: &RunArgs,
    url: &Url,
    mut proc: Processor,
    opts: Options,
    source: &SpecSource,
    ctx: &state::Context,
) -> i32 {
    if args.udp_listen.is_some() {
        log::log(
            Level::Error,
            "--state nats://... runs on stdin/stdout (Telegraf's execd); --udp-listen is not supported with it",
        );
        return super::EXIT_SPEC;
    }
    let mut backend = match NatsBackend::connect(url, &proc, ctx) {
        Ok(b) => b,
        Err(e) => {
            log::log(Level::Error, &format!("state: {e}"));
            return EXIT_IO;
        }
    };
    let lease = backend.lease();
    let program = proc.program().clone();
    let fresh = move || Processor::new(program.clone(), opts.clone()).ok();
    let mut on_hangup = |p: &mut Processor, out: &mut Vec<u8>| {
        reload::reload(source, p, out);
    };
    // A standby must keep at least what the holder may not have saved: two save intervals
    // (one minute without --state-interval) and two lease TTLs.
    let window = args.state_interval.unwrap_or(Duration::from_secs(30)) * 2 + url.ttl * 2;
    let rt = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            log::log(Level::Error, &format!("cannot start the runtime: {e}"));
            return EXIT_IO;
        }
    };
    let result = rt.block_on(fleet::run(
        &mut proc,
        Fleet {
            backend: &mut backend as &mut dyn Backend,
            lease,
            instance_by: ctx.instance_by.clone(),
            interval: args.state_interval,
            window,
            fresh: &fresh,
            on_hangup: &mut on_hangup,
        },
    ));
    let code = match result {
        Ok(ending) => {
            if ending == Ending::OutputClosed {
                log::log(Level::Info, "stdout was closed by its reader; stopping");
            }
            EXIT_OK
        }
        Err(e) => {
            log::log(Level::Error, &format!("I/O error: {e}"));
            EXIT_IO
        }
    };
    log::log(Level::Info, &proc.summary());
    rt.shutdown_background();
    code
}
