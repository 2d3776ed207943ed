//! `tessla-telegraf [run]`: load the spec (or the bundled robot monitors), then process line
//! protocol from stdin (Telegraf's execd) or UDP (the connector's wiring) until EOF or a signal.
//! With `--state`, instances are restored at start and saved at every ending; SIGHUP reloads.

use super::{CliError, CliResult, RunArgs};
use crate::log::{self, Level};
use crate::processor::reload::{self, SpecSource};
use crate::processor::{Options, Processor};
use crate::state;
use crate::telegraf::binding::parse_tags;
use crate::transport::{self, Ending};
use crate::watchdog::{self, Watch};
use std::sync::Arc;
use std::time::{Duration, Instant};

pub fn run(mut args: RunArgs) -> CliResult {
    log::set_level(args.log_level);
    let (had_spec, had_set) = (args.spec.is_some(), !args.spec_options.set.is_empty());
    args.from_env();
    if let Some(p) = args.spec.as_ref().filter(|_| !had_spec) {
        log::log(
            Level::Info,
            &format!("spec from {}: {}", super::SPEC_ENV, p.display()),
        );
    }
    if !had_set && !args.spec_options.set.is_empty() {
        log::log(
            Level::Info,
            &format!(
                "--set from {}: {}",
                super::SET_ENV,
                args.spec_options.set.join(" ")
            ),
        );
    }
    let options = super::load_options(&args.spec_options).map_err(CliError::spec)?;
    let source = SpecSource {
        path: args.spec.clone(),
        options,
    };
    let loaded = source.load().map_err(|e| CliError::spec(e.render()))?;
    if !loaded.warnings.is_empty() {
        log::log(
            Level::Warn,
            &tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, false),
        );
    }
    let spec_name = args.spec.as_ref().map_or_else(
        || format!("<bundled>/{}", crate::bundled::DEFAULT),
        |p| p.display().to_string(),
    );
    super::check::require_outputs(&loaded.program, &spec_name).map_err(CliError::spec)?;
    let tags = args
        .tags
        .iter()
        .map(|t| parse_tags(t).map_err(|e| CliError::spec(format!("--tag {t}: {e}"))))
        .collect::<Result<Vec<_>, _>>()?
        .into_iter()
        .flatten()
        .collect();
    let state_ctx = state::Context {
        set: args.spec_options.set.clone(),
        base_time: args.spec_options.base_time_or_default(),
        instance_by: Vec::new(),
    };
    let opts = Options {
        // UDP mode never echoes: Telegraf already routes the robot metric to its other outputs,
        // and an echo sent back to Telegraf is one step from a feedback loop.
        passthrough: !args.no_passthrough && args.udp_listen.is_none(),
        late: args.late,
        measurement: args.measurement.clone(),
        tags,
        instance_by: args
            .instance_by
            .iter()
            .map(|t| t.trim().to_string())
            .filter(|t| !t.is_empty())
            .collect(),
        max_instances: args.max_instances,
        instance_idle: args.instance_idle,
        max_ahead: args.max_ahead.0,
        allowed_lateness: args.allowed_lateness.0,
    };
    let state_ctx = state::Context {
        instance_by: opts.instance_by.clone(),
        ..state_ctx
    };
    let fleet_opts = opts.clone();
    let mut proc =
        Processor::new(loaded.program, opts).map_err(|e| CliError::spec(format!("spec: {e}")))?;
    let watch = Arc::new(Watch::default());
    proc.watch_with(watch.lane());
    watchdog::spawn(watch.clone(), Some(args.step_timeout))
        .map_err(|e| CliError::io(format!("cannot start the step watchdog: {e}")))?;
    if let Some(state::Target::Nats(url)) = &args.state {
        return super::run_fleet::run(&args, url, proc, fleet_opts, &source, &state_ctx, watch);
    }
    let state_file = match &args.state {
        Some(state::Target::File(path)) => Some(path.clone()),
        _ => None,
    };
    if let Some(path) = &state_file {
        state::file::load(path, &mut proc, &state_ctx);
    }
    let mut on_hangup = |p: &mut Processor, out: &mut Vec<u8>| {
        reload::reload(&source, p, out);
    };
    let mut save_now = |p: &Processor| {
        if let Some(path) = &state_file {
            save_state(path, p, &state_ctx, Level::Debug);
        }
    };
    let hooks = transport::Hooks {
        on_hangup: &mut on_hangup,
        periodic: args
            .state_interval
            .map(|d| (d, &mut save_now as &mut dyn FnMut(&Processor))),
        watch,
    };
    // Threads spread instances (default: the machine's cores). The state file holds one
    // processor's instances and UDP mode reads datagrams one at a time, so both keep one thread.
    let threads = match (&args.state, &args.udp_listen, args.threads) {
        (Some(_), _, _) | (_, Some(_), _) => 1,
        (None, None, Some(n)) => n,
        (None, None, None) => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    if let Some(listen) = &args.udp_listen {
        check_udp(listen, &args.udp_send)?;
    }
    let rt = runtime()?;
    let result = rt.block_on(async {
        match &args.udp_listen {
            Some(listen) => {
                transport::udp::run(
                    &mut proc,
                    listen,
                    &args.udp_send,
                    args.udp_max_datagram,
                    hooks,
                )
                .await
            }
            None => transport::stdio::run(&mut proc, hooks, threads).await,
        }
    });
    proc.finish_wiring();
    // Every ending (EOF, signal, closed stdout, I/O error) has evaluated what it could: save.
    if let Some(path) = &state_file {
        save_state(path, &proc, &state_ctx, Level::Info);
    }
    finish(rt, result, &proc)
}

/// UDP mode's addresses, checked before anything runs, so a mistake names its flag and address
/// (and no summary of a run that never started comes first): an address that does not resolve
/// is a bad command line (exit 2), one that cannot be bound an I/O error (exit 3).
fn check_udp(listen: &str, send: &str) -> CliResult {
    use std::net::ToSocketAddrs;
    let form = "expected HOST:PORT, e.g. 127.0.0.1:1653 or [::1]:1653";
    for (flag, addr) in [("--udp-listen", listen), ("--udp-send", send)] {
        if let Err(e) = addr.to_socket_addrs() {
            return Err(CliError::spec(format!(
                "{flag} {addr}: not a UDP address ({e}); {form}"
            )));
        }
    }
    std::net::UdpSocket::bind(listen).map(drop).map_err(|e| {
        CliError::io(format!(
            "{flag} {listen}: cannot listen there: {e}",
            flag = "--udp-listen"
        ))
    })
}

/// The single-threaded runtime the transports run on.
pub(super) fn runtime() -> Result<tokio::runtime::Runtime, CliError> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::io(format!("cannot start the runtime: {e}")))
}

/// The end of a run: say why it stopped, log the summary, leave the runtime.
pub(super) fn finish(
    rt: tokio::runtime::Runtime,
    result: std::io::Result<Ending>,
    proc: &Processor,
) -> CliResult {
    if result.as_ref().is_ok_and(|e| *e == Ending::OutputClosed) {
        log::log(Level::Info, "stdout was closed by its reader; stopping");
    }
    log::log(Level::Info, &proc.summary());
    if matches!(result, Ok(Ending::Eof | Ending::Signal)) {
        wait_until_read(DRAIN_BOUND);
    }
    // The blocking stdin reader thread may still wait for input: leave without joining it.
    rt.shutdown_background();
    result
        .map(|_| ())
        .map_err(|e| CliError::io(format!("I/O error: {e}")))
}

/// The longest wait at the end for the reader of our stdout pipe ([`wait_until_read`]): well
/// inside the 5 s Telegraf waits after closing our stdin before it sends SIGTERM.
const DRAIN_BOUND: Duration = Duration::from_secs(2);

/// At a normal end, wait (at most `bound`) until the reader has read everything we wrote to
/// the pipes on stdout and stderr. Telegraf's `processors.execd` closes its ends of the pipes
/// once the child has exited (`Cmd.Wait`), so lines still unread when we exit would be lost:
/// the last outputs, and the summary on stderr. Polls the bytes unread in each pipe
/// (`FIONREAD`), first every 0.2 ms, backing off to every 10 ms; a stream that is no pipe, or
/// whose count cannot be read, is not waited for. Once both are read, [`hand_over_pipes`].
pub(super) fn wait_until_read(bound: Duration) {
    use rustix::fs::FileType;
    let is_pipe = |fd: &dyn std::os::fd::AsFd| {
        rustix::fs::fstat(fd).is_ok_and(|st| FileType::from_raw_mode(st.st_mode) == FileType::Fifo)
    };
    let stdout = std::io::stdout();
    let stderr = std::io::stderr();
    let (out_pipe, err_pipe) = (is_pipe(&stdout), is_pipe(&stderr));
    if !out_pipe && !err_pipe {
        return;
    }
    let unread = |fd: &dyn std::os::fd::AsFd, pipe: bool| {
        if pipe {
            rustix::io::ioctl_fionread(fd).unwrap_or(0)
        } else {
            0
        }
    };
    let start = Instant::now();
    let mut pause = Duration::from_micros(200);
    loop {
        let (out_left, err_left) = (unread(&stdout, out_pipe), unread(&stderr, err_pipe));
        if out_left + err_left == 0 {
            hand_over_pipes(out_pipe, err_pipe);
            return;
        }
        if start.elapsed() >= bound {
            log::log(
                Level::Warn,
                &format!(
                    "{}: {} bytes still unread by the reader after {} s; exiting anyway",
                    if out_left > 0 { "stdout" } else { "stderr" },
                    if out_left > 0 { out_left } else { err_left },
                    bound.as_secs_f64()
                ),
            );
            return;
        }
        std::thread::sleep(pause);
        pause = (pause * 2).min(Duration::from_millis(10));
    }
}

/// How long [`hand_over_pipes`] waits after closing them: Telegraf's readers parse the last
/// chunk they read, read again and see the end of the pipe.
const READER_GRACE: Duration = Duration::from_millis(50);

/// Close our ends of the stdout and stderr pipes (each replaced by `/dev/null`, so a late
/// write goes nowhere instead of failing) while we still run, then wait [`READER_GRACE`]:
/// Telegraf's readers see the end of each pipe and finish before we exit. Exiting with the
/// pipes open makes the end of the pipe and `Cmd.Wait`'s close race, and a reader that loses
/// logs "read |0: file already closed" (measured at about one stop in three on 1.33.3 and
/// 1.39.3 before this).
fn hand_over_pipes(out_pipe: bool, err_pipe: bool) {
    use std::io::Write;
    let _ = std::io::stdout().flush();
    let _ = std::io::stderr().flush();
    let Ok(null) = std::fs::OpenOptions::new().write(true).open("/dev/null") else {
        return;
    };
    if out_pipe {
        let _ = rustix::stdio::dup2_stdout(&null);
    }
    if err_pipe {
        let _ = rustix::stdio::dup2_stderr(&null);
    }
    std::thread::sleep(READER_GRACE);
}

/// Save the state, logging success at `level` and failure as an error (never fatal).
fn save_state(path: &std::path::Path, proc: &Processor, ctx: &state::Context, level: Level) {
    let start = std::time::Instant::now();
    match state::file::save(path, proc, ctx) {
        Ok(n) => log::log(
            level,
            &format!(
                "state: saved {n} monitor instances to {} in {} ms",
                path.display(),
                start.elapsed().as_millis()
            ),
        ),
        Err(e) => log::log(
            Level::Error,
            &format!("state: cannot save to {}: {e}", path.display()),
        ),
    }
}
