//! `run`'s command line converted once into what the core takes ([`RunConfig`]): the spec to
//! load, the processor's options, the transport, the state store and the watchdog's bound,
//! with every rule that ties two options together checked here and nowhere else.
//!
//! The rules: without `--spec` the spec comes from `TESSLA_SPEC`, without `--set` the overrides
//! from `TESSLA_SET`; UDP mode never echoes input records (Telegraf already routes the robot
//! metric to its other outputs, and an echo sent back to Telegraf is one step from a feedback
//! loop); a shared NATS store runs on stdin/stdout only; the number of threads that step records
//! is decided here alone (`threads`); UDP addresses must resolve (a bad command line, exit 2)
//! and the listening one must be free (exit 3).

use super::args::{Bound, InstanceArgs, Late, OutputArgs, RunArgs, SPEC_ENV, TimeArgs};
use super::error::CliError;
use super::spec_options::{SET_ENV, load_options};
use crate::log;
use crate::processor::{self, LateMode};
use crate::spec_feed::reload::SpecSource;
use crate::state::{self, Target};
use crate::telegraf::binding::parse_tags;
use crate::transport::Transport;
use std::path::PathBuf;
use std::time::Duration;

/// Everything `run` needs, converted from the command line.
pub struct RunConfig {
    /// The spec, loaded at start and on every SIGHUP.
    pub spec: SpecSource,
    /// `--watch-spec`: reload when the spec file or an include changes.
    pub watch_spec: bool,
    /// `--spec-channel`: the fleet's spec channel and the keys its rollouts must be signed with.
    pub channel: Option<ChannelConfig>,
    pub processor: processor::Options,
    pub transport: Transport,
    /// How many threads step records (1: the calling thread only), final (`threads` below).
    pub threads: usize,
    pub state: Option<StateConfig>,
    /// `--step-timeout` (zero: no watchdog).
    pub step_timeout: Duration,
}

/// `--spec-channel` with its trusted keys (at least one).
pub struct ChannelConfig {
    pub url: crate::nats::url::Url,
    pub trust: Vec<String>,
}

/// `--state` and what decides whether saved state fits this run.
pub struct StateConfig {
    pub target: Target,
    pub context: state::Context,
    /// `--state-interval`.
    pub interval: Option<Duration>,
    /// How long a standby keeps records for replay (a shared store with a lease): at least what
    /// the holder may not have saved, two save intervals (one minute without
    /// `--state-interval`) and two lease TTLs.
    pub window: Duration,
}

impl RunConfig {
    /// Convert `args` (the environment read for what they leave out). Sets the log level first,
    /// so what is read from the environment is logged.
    pub fn from_args(mut args: RunArgs) -> Result<RunConfig, CliError> {
        log::set_level(args.output.log_level.level());
        from_env(&mut args);
        let options = load_options(&args.spec_options)?;
        let spec = SpecSource {
            path: args.spec.clone(),
            options,
        };
        let udp = args.transport.udp_listen.is_some();
        let channel = match args.spec_channel.spec_channel.clone() {
            None => None,
            Some(url) => Some(ChannelConfig {
                url,
                trust: crate::spec_feed::sign::trusted_keys(
                    &args.spec_channel.spec_trust,
                    args.spec_channel.spec_trust_file.as_deref(),
                )
                .map_err(|e| CliError::spec(format!("--spec-channel: {e}")))?,
            }),
        };
        let processor = processor_options(&args.time, &args.instances, &args.output, udp)?;
        let state = args.state.state.clone().map(|target| {
            let interval = args.state.state_interval;
            let ttl = match &target {
                Target::Nats(url) => url.ttl,
                Target::File(_) => Duration::ZERO,
            };
            StateConfig {
                target,
                context: state::Context {
                    set: args.spec_options.set.clone(),
                    base_time: args.spec_options.base_time_or_default(),
                    instance_by: processor.instance_by.clone(),
                },
                interval,
                window: interval.unwrap_or(Duration::from_secs(30)) * 2 + ttl * 2,
            }
        });
        let transport = match args.transport.udp_listen.clone() {
            Some(listen) => {
                if matches!(state.as_ref().map(|s| &s.target), Some(Target::Nats(_))) {
                    return Err(CliError::spec(
                        "--state nats://... runs on stdin/stdout (Telegraf's execd); --udp-listen is not supported with it",
                    ));
                }
                check_udp(&listen, &args.transport.udp_send)?;
                Transport::Udp {
                    listen,
                    send: args.transport.udp_send.clone(),
                    max_datagram: args.transport.udp_max_datagram,
                }
            }
            None => Transport::Stdio,
        };
        let threads = threads(args.instances.threads, &processor, state.is_some(), udp);
        Ok(RunConfig {
            spec,
            watch_spec: args.watch_spec,
            channel,
            processor,
            transport,
            threads,
            state,
            step_timeout: args.step_timeout,
        })
    }

    /// The spec's name in messages: its path, or the bundled default.
    pub fn spec_name(&self) -> String {
        self.spec.path.as_ref().map_or_else(
            || format!("<bundled>/{}", crate::bundled::DEFAULT),
            |p| p.display().to_string(),
        )
    }
}

/// Without `--spec`, the spec [`SPEC_ENV`] names (when set and not empty); without `--set`,
/// the assignments of [`SET_ENV`]. Each one taken is logged.
fn from_env(args: &mut RunArgs) {
    if args.spec.is_none()
        && let Some(path) = std::env::var_os(SPEC_ENV).filter(|p| !p.is_empty())
    {
        let path = PathBuf::from(path);
        log_info!("spec from {SPEC_ENV}: {}", path.display());
        args.spec = Some(path);
    }
    let had_set = !args.spec_options.set.is_empty();
    args.spec_options.set_from_env();
    if !had_set && !args.spec_options.set.is_empty() {
        log_info!("--set from {SET_ENV}: {}", args.spec_options.set.join(" "));
    }
}

/// How many threads step records, the one place this is decided: instances are spread over
/// threads only with `--instance-by`, on stdin, without `--state` (the state file holds one
/// processor's instances, and a shared store restores each instance as it arrives on the
/// calling thread; UDP answers datagram by datagram); then `--threads`, by default the machine's
/// cores, and never more than `--max-instances` (each thread keeps its even part of it).
fn threads(asked: Option<usize>, processor: &processor::Options, state: bool, udp: bool) -> usize {
    if processor.instance_by.is_empty() || state || udp {
        return 1;
    }
    let n = asked.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    n.clamp(1, processor.max_instances.max(1))
}

/// The processor's options from the time, instance and output groups.
fn processor_options(
    time: &TimeArgs,
    instances: &InstanceArgs,
    output: &OutputArgs,
    udp: bool,
) -> Result<processor::Options, CliError> {
    let tags = output
        .tags
        .iter()
        .map(|t| parse_tags(t).map_err(|e| CliError::spec(format!("--tag {t}: {e}"))))
        .collect::<Result<Vec<_>, _>>()?
        .into_iter()
        .flatten()
        .collect();
    let Bound(max_ahead) = time.max_ahead;
    let Bound(allowed_lateness) = time.allowed_lateness;
    Ok(processor::Options {
        passthrough: !output.no_passthrough && !udp,
        late: match time.late {
            Late::Shift => LateMode::Shift,
            Late::Drop => LateMode::Drop,
        },
        measurement: output.measurement.clone(),
        tags,
        instance_by: instances
            .instance_by
            .iter()
            .map(|t| t.trim().to_string())
            .filter(|t| !t.is_empty())
            .collect(),
        max_instances: instances.max_instances,
        instance_idle: instances.instance_idle,
        max_ahead,
        allowed_lateness,
        version_tag: output
            .version_tag
            .as_deref()
            .map(str::trim)
            .filter(|t| !t.is_empty())
            .map(str::to_string),
    })
}

/// UDP mode's addresses, checked before anything runs, so a mistake names its flag and address
/// (and no summary of a run that never started comes first): an address that does not resolve
/// is a bad command line (exit 2), one that cannot be bound an I/O error (exit 3).
fn check_udp(listen: &str, send: &str) -> Result<(), CliError> {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The thread count is final when it leaves here: one without `--instance-by`, with
    /// `--state` or on UDP; `--threads` otherwise, never above `--max-instances`, at least one.
    #[test]
    fn the_thread_count_is_decided_here() {
        let by = processor::Options {
            instance_by: vec!["robot".to_string()],
            max_instances: 3,
            ..processor::Options::default()
        };
        assert_eq!(threads(Some(2), &by, false, false), 2);
        assert_eq!(threads(Some(8), &by, false, false), 3);
        assert_eq!(threads(Some(0), &by, false, false), 1);
        assert_eq!(threads(Some(2), &by, true, false), 1);
        assert_eq!(threads(Some(2), &by, false, true), 1);
        assert_eq!(
            threads(Some(2), &processor::Options::default(), false, false),
            1
        );
        assert!((1..=3).contains(&threads(None, &by, false, false)));
    }
}
