//! `tessla-telegraf [run]`: load the spec (or the bundled robot monitors), then process line
//! protocol from stdin (Telegraf's execd) or UDP (the connector's wiring) until EOF or a signal,
//! on the one step loop. With `--state`, instances are restored at start and saved at every
//! ending; SIGHUP reloads.

use super::args::RunArgs;
use super::config::{RunConfig, StateConfig};
use super::ending::{finish, runtime};
use super::error::{CliError, CliResult};
use super::spec_options::require_outputs;
use crate::fleet::{Feed, Level};
use crate::processor::Processor;
use crate::spec_feed::Updates;
use crate::spec_feed::nats::NatsFeed;
use crate::state::file::FileBackend;
use crate::state::nats::NatsBackend;
use crate::state::{Backend, Target};
use crate::step_loop::{Setup, SharedStore, Store};
use crate::transport;
use crate::watchdog::{self, Watch};
use std::sync::Arc;

pub fn run(args: RunArgs) -> CliResult {
    let fleet_args = (
        args.instances.fleet_spec.clone(),
        args.instances.fleet_silence,
        args.spec_options.clone(),
    );
    let config = RunConfig::from_args(args)?;
    let (loaded, bundle) = config.spec.load().map_err(|e| CliError::spec(e.render()))?;
    if !loaded.warnings.is_empty() {
        log_warn!(
            "{}",
            tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, false)
        );
    }
    require_outputs(&loaded.program, &config.spec_name())?;
    let fleet = match &fleet_args.0 {
        Some(path) => Some(fleet_level(path, &fleet_args, &loaded.program, &config)?),
        None => None,
    };
    let fleet_check = match &fleet {
        Some((_, names)) => Some(fleet_check(
            Arc::clone(&loaded.program),
            super::spec_options::load_options(&fleet_args.2)?,
            Arc::clone(names),
        )),
        None => None,
    };
    let mut proc = Processor::new(loaded.program, config.processor.clone())
        .map_err(|e| CliError::spec(format!("spec: {e}")))?;
    if let Some((_, names)) = &fleet {
        proc.tap_fleet(names.clone());
    }
    proc.name_base(&bundle.id(), "");
    let watch = Arc::new(Watch::default());
    proc.watch_with(watch.lane());
    watchdog::spawn(watch.clone(), Some(config.step_timeout))
        .map_err(|e| CliError::io(format!("cannot start the step watchdog: {e}")))?;
    let (mut backend, shared) = match &config.state {
        Some(s) => {
            let (b, shared) = open_store(s)?;
            (Some(b), shared)
        }
        None => (None, None),
    };
    let partition = match config.state.as_ref().map(|s| &s.target) {
        Some(Target::Nats(url)) => url.lease.clone().unwrap_or_default(),
        _ => String::new(),
    };
    // A partition of a NATS fleet sends to the fleet level, which one process of the fleet
    // writes (docs/fleet.md, "A fleet of NATS partitions"); otherwise the level runs here.
    let mut feed = match (fleet, config.state.as_ref().map(|s| &s.target)) {
        (Some((level, _)), Some(Target::Nats(url))) if url.lease.is_some() => {
            let silence = i64::try_from(fleet_args.1.as_nanos()).unwrap_or(i64::MAX);
            let n = crate::fleet::nats::FleetNats::connect(
                url,
                partition.clone(),
                level,
                silence,
                config.processor.tags.clone(),
            )
            .map_err(|e| CliError::from(e).within("fleet"))?;
            Some(Feed::Nats(Box::new(n)))
        }
        (Some((level, _)), _) => Some(Feed::Local(Box::new(level))),
        (None, _) => None,
    };
    let mut updates = Updates::new(config.spec.clone(), config.watch_spec, &partition);
    if let Some(check) = fleet_check {
        updates.with_fleet(check);
    }
    if let Some(ch) = &config.channel {
        let (feed, first) = NatsFeed::connect(&ch.url, &ch.trust)
            .map_err(|e| CliError::from(e).within("spec channel"))?;
        updates.with_channel(Box::new(feed), first);
    }
    let store = backend.as_deref_mut().map(|backend| Store {
        backend,
        interval: config.state.as_ref().and_then(|s| s.interval),
        shared,
    });
    let setup = Setup {
        threads: config.threads,
        updates: &mut updates,
        store,
        watch,
        fleet: feed.as_mut(),
    };
    let rt = runtime()?;
    let result = rt.block_on(transport::run(&config.transport, &mut proc, setup));
    proc.finish_wiring();
    finish(rt, result, &proc)
}

/// A fleet spec that does not check is a spec error (exit 2).
impl From<crate::fleet::CheckError> for CliError {
    fn from(e: crate::fleet::CheckError) -> Self {
        CliError::spec(e.to_string())
    }
}

/// The fleet level of `--fleet-spec` (checked against the robot spec `robot`) and the robot
/// outputs it reads; a fleet spec that does not check is a spec error (exit 2).
fn fleet_level(
    path: &std::path::Path,
    (_, silence, spec_options): &(
        Option<std::path::PathBuf>,
        std::time::Duration,
        super::spec_options::SpecOptions,
    ),
    robot: &tessla_engine::Program,
    config: &RunConfig,
) -> Result<(Level, Arc<[String]>), CliError> {
    let options = super::spec_options::load_options(spec_options)?;
    let crate::fleet::Checked {
        loaded,
        names,
        bundle,
    } = crate::fleet::check(path, robot, &options)?;
    if !loaded.warnings.is_empty() {
        log_warn!(
            "{}",
            tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, false)
        );
    }
    let silence = i64::try_from(silence.as_nanos()).unwrap_or(i64::MAX);
    let level = Level::new(
        loaded.program,
        &names,
        silence,
        crate::fleet::version_tags(
            &config.processor.tags,
            config.processor.version_tag.as_deref(),
            &bundle.id(),
        ),
        config.processor.instance_by.clone(),
    )
    .map_err(|e| CliError::spec(format!("{}: {e}", path.display())))?;
    let mut level = level;
    level.set_version_tag(config.processor.version_tag.clone());
    Ok((level, Arc::from(names)))
}

/// How this process checks a fleet rollout (`spec publish --fleet`): as `--fleet-spec` is
/// checked at start-up, against the robot spec it started with; and its inputs must be among
/// the robot outputs the fleet level collects (`names`: the start-up fleet spec's inputs).
fn fleet_check(
    robot: Arc<tessla_engine::Program>,
    options: tessla_engine::LoadOptions,
    names: Arc<[String]>,
) -> crate::spec_feed::FleetCheck {
    Box::new(move |bundle| {
        // The fleet level's check, as the spec channel's reason for refusing the version.
        let refused = |e: crate::fleet::CheckError| {
            crate::spec_feed::error::RolloutError::FleetCheck(e.to_string())
        };
        let checked =
            crate::fleet::check_bundle(bundle.clone(), &robot, &options).map_err(refused)?;
        if let Some(n) = checked.names.iter().find(|n| !names.contains(n)) {
            return Err(refused(crate::fleet::CheckError::NotCollected {
                input: n.clone(),
                collects: names.join(", "),
            }));
        }
        Ok(crate::spec_feed::FleetVersion {
            program: checked.loaded.program,
            names: checked.names,
        })
    })
}

/// The state store `--state` names, connected (a NATS bucket: a mistake in its URL's
/// credentials or TLS files is exit 2, a connection that fails exit 3), and for a shared one
/// its partition lease.
fn open_store(s: &StateConfig) -> Result<(Box<dyn Backend>, Option<SharedStore>), CliError> {
    match &s.target {
        Target::File(path) => {
            // A folder that is missing or not writable is said now, not at the first save.
            crate::state::file::check_writable(path)
                .map_err(|m| CliError::io(format!("state: {m}")))?;
            Ok((
                Box::new(FileBackend::new(path.clone(), s.context.clone())),
                None,
            ))
        }
        Target::Nats(url) => {
            let backend = NatsBackend::connect(url, &s.context)
                .map_err(|e| CliError::from(e).within("state"))?;
            let lease = backend.lease();
            Ok((
                Box::new(backend),
                Some(SharedStore {
                    lease,
                    window: s.window,
                }),
            ))
        }
    }
}
