//! `tessla-telegraf simulate`: a simulated TurtleBot3 in closed loop with the monitors.
//!
//! In-process (default) the run is made twice with the same seed, monitor off (the default
//! robot) and on (the augmented robot), and the summary compares them; the output file holds
//! the run `--monitor` chooses. With `--broker` the one chosen run drives the real pipeline.
//! With `--shared-floor N` it writes the records of N robots sharing one floor (the fleet
//! example's input, `crate::simulate::shared_floor`) and runs no monitor.

use super::error::{CliError, CliResult};
use super::spec_options::{SpecOptionError, SpecOptions, load_options};
use crate::log;
use crate::processor::{Options, Processor};
use crate::replay::mqtt::Broker;
use crate::simulate::closed_loop::{self, Outcome, Scenario};
use crate::simulate::in_process::InProcess;
use crate::simulate::mqtt_twin::MqttTwin;
use crate::simulate::program::Program;
use crate::simulate::scenario::{self, TerrainChoice};
use crate::simulate::summary::Summary;
use crate::simulate::terrain::Terrain;
use clap::Args;
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Default)]
pub enum Switch {
    #[default]
    On,
    Off,
}

#[derive(Debug, Args, Clone)]
pub struct SimulateArgs {
    /// Seed of every random choice (sensor noise, faults, `--terrain random`).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// `yoga-mat` (bundled), `random` (a random mat for the seed) or a terrain file.
    #[arg(long, value_name = "yoga-mat|random|FILE", default_value = "yoga-mat")]
    pub terrain: String,
    /// `paper` (bundled: steps between 0.015 and 0.1 m/s) or a program file.
    #[arg(long, value_name = "paper|FILE", default_value = "paper")]
    pub program: String,
    /// Whether the robot executes the twin's actions (on) or its own command (off).
    #[arg(long, value_enum, default_value_t)]
    pub monitor: Switch,
    /// Seconds between robot messages (the paper's actuation period).
    #[arg(long, value_name = "S", default_value_t = 0.5)]
    pub period: f64,
    /// Seconds from a message to its action taking effect (the twin's round trip).
    #[arg(long, value_name = "S", default_value_t = 0.2)]
    pub delay: f64,
    /// The robot's link drops at AT seconds for SECONDS (repeatable): its client holds its
    /// messages and sends them late, with their own times, when the link returns.
    #[arg(long, value_name = "AT:SECONDS")]
    pub link_drop: Vec<String>,
    /// Stop after this many seconds (default: the program's length).
    #[arg(long, value_name = "S")]
    pub duration: Option<f64>,
    /// The `.tessla` file; without it the bundled robot monitors.
    #[arg(long)]
    pub spec: Option<PathBuf>,
    #[command(flatten)]
    pub spec_options: SpecOptions,
    /// Write the run (robot messages, passed through, and the monitors' outputs) here.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Drive the real pipeline: publish to this broker, execute what arrives on `action`.
    #[arg(long, value_name = "mqtt://HOST:PORT")]
    pub broker: Option<String>,
    /// Broker mode: topic of the robot messages.
    #[arg(long, default_value = "tessla")]
    pub topic: String,
    /// Broker mode: topic of the actions.
    #[arg(long, default_value = "action")]
    pub action_topic: String,
    /// Broker mode: seconds to wait for an action before the robot keeps its own command.
    #[arg(long, value_name = "S", default_value_t = 5.0)]
    pub action_timeout: f64,
    /// Broker mode: add the message time (integer ns) under this JSON key.
    #[arg(long, value_name = "KEY")]
    pub time_key: Option<String>,
    /// Lidar: probability per beam and scan of a dust spike.
    #[arg(long, value_name = "P", default_value_t = 0.001)]
    pub spike_rate: f64,
    /// Lidar: probability per beam and scan of a dropout (no return, `0.0`).
    #[arg(long, value_name = "P", default_value_t = 0.01)]
    pub dropout_rate: f64,
    /// Print the summary as one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Write the records of N robots sharing one floor (positions x, y; two of them in zone A
    /// at times, lanes 0.4 m apart) to `--output` or stdout, for `run --fleet-spec
    /// specs/fleet/fleet.tessla` (docs/fleet.md); no monitor runs. `--duration` (default 60 s)
    /// and `--seed` apply.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub shared_floor: Option<u32>,
    /// Least severe messages written to stderr.
    #[arg(long, value_enum, default_value_t)]
    pub log_level: super::log_level::LogLevel,
}

fn bad(msg: &str) -> CliError {
    CliError::spec(format!("simulate: {msg}"))
}

/// A number option out of its range (`name` without the dashes).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
enum OutOfRange {
    #[error("--{0} {1}: must be a positive number")]
    NotPositive(&'static str, f64),
    #[error("--{0} {1}: must be between 0 and 1")]
    NotProbability(&'static str, f64),
}

fn positive(name: &'static str, v: f64) -> Result<f64, OutOfRange> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(OutOfRange::NotPositive(name, v))
    }
}

fn probability(name: &'static str, v: f64) -> Result<f64, OutOfRange> {
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(OutOfRange::NotProbability(name, v))
    }
}

/// The scenario from the command line; error messages start with `simulate: `.
fn scenario_of(args: &SimulateArgs) -> Result<Scenario, CliError> {
    let read = |what: &str, path: &str| {
        std::fs::read_to_string(path)
            .map_err(|e| CliError::io(format!("simulate: --{what} {path}: {e}")))
    };
    let terrain = match args.terrain.as_str() {
        "yoga-mat" => TerrainChoice::YogaMat,
        "random" => TerrainChoice::Random,
        path => TerrainChoice::Custom(
            Terrain::parse(&read("terrain", path)?)
                .map_err(|e| bad(&format!("--terrain {path}: {e}")))?,
        ),
    };
    let program = match args.program.as_str() {
        "paper" => Program::paper_steps(),
        path => Program::parse(&read("program", path)?)
            .map_err(|e| bad(&format!("--program {path}: {e}")))?,
    };
    let spec = |e: String| bad(&e);
    let mut s = scenario::build(terrain, program, args.seed);
    s.period = positive("period", args.period).map_err(|e| spec(e.to_string()))?;
    if s.period > 60.0 {
        return Err(spec(format!("--period {}: at most 60 s", args.period)));
    }
    if !(args.delay.is_finite() && args.delay >= 0.0) {
        return Err(spec(format!(
            "--delay {}: must be zero or positive",
            args.delay
        )));
    }
    s.delay = args.delay;
    if let Some(d) = args.duration {
        s.duration = positive("duration", d).map_err(|e| spec(e.to_string()))?;
    }
    for d in &args.link_drop {
        let parsed = d
            .split_once(':')
            .and_then(|(a, l)| Some((a.trim().parse::<f64>().ok()?, l.trim().parse::<f64>().ok()?)))
            .filter(|&(a, l)| a.is_finite() && l.is_finite() && a >= 0.0 && l > 0.0);
        let Some(drop) = parsed else {
            return Err(spec(format!(
                "--link-drop {d}: expected AT:SECONDS, two numbers (e.g. 12:1.5: the link drops 12 s into the run for 1.5 s)"
            )));
        };
        s.link_drops.push(drop);
    }
    s.lidar.spike_rate =
        probability("spike-rate", args.spike_rate).map_err(|e| spec(e.to_string()))?;
    s.lidar.dropout_rate =
        probability("dropout-rate", args.dropout_rate).map_err(|e| spec(e.to_string()))?;
    Ok(s)
}

/// `--shared-floor N`: the robots' records, to `--output` or stdout.
fn shared_floor(args: &SimulateArgs, robots: usize) -> CliResult {
    let seconds = match args.duration {
        Some(d) => positive("duration", d).map_err(|e| bad(&e.to_string()))?,
        None => 60.0,
    };
    let text = crate::simulate::shared_floor::records(
        robots,
        seconds,
        closed_loop::START_NS,
        args.seed,
        "sim",
    );
    let written = match &args.output {
        Some(path) => std::fs::write(path, text.as_bytes())
            .map_err(|e| format!("cannot write {}: {e}", path.display())),
        None => std::io::stdout()
            .lock()
            .write_all(text.as_bytes())
            .map_err(|e| format!("stdout: {e}")),
    };
    written.map_err(|e| CliError::io(format!("simulate: {e}")))
}

/// Why the monitors' program could not be loaded (exit 2).
#[derive(Debug, thiserror::Error)]
enum LoadError {
    /// `--set` or `--base-time` is wrong.
    #[error("{0}")]
    Options(#[from] SpecOptionError),
    /// The spec does not compile (its diagnostics rendered).
    #[error("{0}")]
    Spec(#[from] tessla_engine::LoadError),
}

impl From<LoadError> for CliError {
    fn from(e: LoadError) -> Self {
        CliError::spec(e.to_string())
    }
}

/// Why a simulated run stopped (exit 3, the message led by `simulate: `).
#[derive(Debug, thiserror::Error)]
enum RunFailure {
    /// A processor could not be made for the program.
    #[error("spec: {0}")]
    Processor(#[from] crate::telegraf::binding::BindingError),
    /// The closed loop stopped.
    #[error("{0}")]
    Run(#[from] closed_loop::RunError),
    /// The MQTT twin could not finish publishing.
    #[error("{0}")]
    Mqtt(#[from] crate::replay::mqtt::MqttError),
    /// Neither a broker nor in-process monitors.
    #[error("no monitors loaded")]
    NoMonitors,
}

impl From<RunFailure> for CliError {
    fn from(e: RunFailure) -> Self {
        CliError::io(format!("simulate: {e}"))
    }
}

/// The monitors' program from `--spec` (or the bundled one) and `--set`/`--base-time`.
fn load(args: &SimulateArgs) -> Result<Arc<tessla_engine::Program>, LoadError> {
    let options = load_options(&args.spec_options)?;
    let loaded = match &args.spec {
        Some(path) => tessla_engine::load_file(path, &options),
        None => crate::bundled::load(&options),
    }?;
    if !loaded.warnings.is_empty() {
        log_warn!(
            "{}",
            tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, false)
        );
    }
    Ok(loaded.program)
}

pub fn run(args: SimulateArgs) -> CliResult {
    log::set_level(args.log_level.level());
    if let Some(robots) = args.shared_floor {
        return shared_floor(&args, robots as usize);
    }
    let scenario = scenario_of(&args)?;
    let broker = match args.broker.as_deref().map(str::parse::<Broker>) {
        None => None,
        // The twin speaks plain MQTT to a local broker (no login or TLS options).
        Some(Ok(b)) if b.tls => {
            return Err(bad(&format!(
                "--broker {b}: TLS is not supported by simulate (a local broker: mqtt://HOST:PORT)"
            )));
        }
        Some(Ok(_)) if !scenario.link_drops.is_empty() => {
            return Err(bad(
                "--link-drop runs in-process only: the MQTT twin waits for each answer in lock \
                 step (tests/servers/telegraf_real_failures.rs drops a real robot's link)",
            ));
        }
        Some(Ok(b)) => Some(b),
        Some(Err(e)) => return Err(bad(&e.to_string())),
    };
    let timeout = match positive("action-timeout", args.action_timeout) {
        Ok(t) => Duration::from_secs_f64(t),
        Err(e) => return Err(bad(&e.to_string())),
    };
    let program = match broker {
        Some(_) => {
            if args.spec.is_some() || !args.spec_options.set.is_empty() {
                log_warn!(
                    "simulate: --spec and --set configure the in-process monitors; with --broker \
                     the pipeline's own processor answers"
                );
            }
            None
        }
        None => Some(load(&args)?),
    };
    let mut file: Box<dyn Write> = match &args.output {
        Some(path) => match std::fs::File::create(path) {
            Ok(f) => Box::new(std::io::BufWriter::new(f)),
            Err(e) => {
                return Err(CliError::io(format!(
                    "simulate: cannot create {}: {e}",
                    path.display()
                )));
            }
        },
        None => Box::new(std::io::sink()),
    };
    let chosen_on = args.monitor == Switch::On;
    let mut summary = Summary {
        terrain: args.terrain.clone(),
        program: args.program.clone(),
        seed: args.seed,
        period_s: scenario.period,
        delay_s: scenario.delay,
        default: None,
        augmented: None,
    };
    let result = match (&broker, program) {
        (Some(broker), _) => {
            let twin = MqttTwin::connect(
                broker,
                &args.topic,
                &args.action_topic,
                timeout,
                args.time_key.clone(),
            );
            let mut twin = twin.map_err(|e| CliError::io(format!("simulate: {e}")))?;
            let outcome = closed_loop::run(&scenario, chosen_on, &mut twin, &mut file);
            if twin.unanswered > 0 {
                log_warn!(
                    "simulate: {} messages got no action from {broker}",
                    twin.unanswered
                );
            }
            let finished = twin.finish();
            match (outcome, finished) {
                (Err(e), _) => Err(RunFailure::from(e)),
                (Ok(_), Err(e)) => Err(RunFailure::from(e)),
                (Ok(o), Ok(_)) => Ok(vec![(chosen_on, o)]),
            }
        }
        (None, Some(program)) => in_process(&scenario, &program, chosen_on, &mut file),
        (None, None) => Err(RunFailure::NoMonitors),
    };
    let outcomes = result?;
    file.flush()
        .map_err(|e| CliError::io(format!("simulate: cannot write the output: {e}")))?;
    for (on, o) in outcomes {
        if on {
            summary.augmented = Some(o);
        } else {
            summary.default = Some(o);
        }
    }
    let text = if args.json {
        format!("{}\n", summary.to_json())
    } else {
        summary.to_table()
    };
    let mut stdout = std::io::stdout();
    stdout
        .write_all(text.as_bytes())
        .and_then(|_| stdout.flush())
        .map_err(|e| CliError::io(format!("simulate: cannot write the summary: {e}")))
}

/// Both runs in-process: the chosen one writes to `file`, the other only counts.
fn in_process(
    scenario: &Scenario,
    program: &Arc<tessla_engine::Program>,
    chosen_on: bool,
    file: &mut dyn Write,
) -> Result<Vec<(bool, Outcome)>, RunFailure> {
    let mut outcomes = Vec::new();
    for on in [false, true] {
        let processor = Processor::new(Arc::clone(program), Options::default())?;
        let mut twin = InProcess::new(processor);
        if !scenario.link_drops.is_empty() {
            // A held message is late only if the silence moved the monitor's clock meanwhile.
            twin = twin.live(scenario.start_ns);
        }
        let outcome = if on == chosen_on {
            closed_loop::run(scenario, on, &mut twin, file)
        } else {
            closed_loop::run(scenario, on, &mut twin, &mut std::io::sink())
        }?;
        log_debug!(
            "monitor {}: {}",
            if on { "on" } else { "off" },
            twin.summary()
        );
        outcomes.push((on, outcome));
    }
    Ok(outcomes)
}
