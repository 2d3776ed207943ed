//! `tessla-telegraf replay`: publish a recorded robot run to MQTT as the robot's JSON messages.
//!
//! Reads the whole file (line protocol or CSV), reports skipped records on stderr, connects
//! (an unreachable broker is an error naming it, exit 3), then publishes each message when it is
//! due, with a progress bar on a terminal, and prints one summary line.

use super::error::{CliError, CliResult};
use crate::replay::message::{MessageOptions, to_json};
use crate::replay::mqtt::{Broker, BrokerError, Login, Publisher, parse_qos};
use crate::replay::{Recording, pacing, read_csv, read_lp};
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Default)]
pub enum InputFormat {
    /// `.csv` files are CSV, anything else line protocol.
    #[default]
    Auto,
    /// InfluxDB line protocol, as in tests/fixtures.
    Lp,
    /// CSV with a header row.
    Csv,
}

#[derive(Debug, Args, Clone)]
pub struct ReplayArgs {
    /// The recorded run: line protocol (as in our fixtures) or CSV with a header.
    pub file: PathBuf,
    /// The MQTT broker.
    #[arg(
        long,
        value_name = "mqtt://HOST:PORT",
        default_value = "mqtt://127.0.0.1:1883"
    )]
    pub broker: String,
    /// The topic the robot publishes on.
    #[arg(long, default_value = "tessla")]
    pub topic: String,
    /// Replay speed: 1 = recorded pacing, 2 = twice as fast, 0 = as fast as possible.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Input format.
    #[arg(long, value_enum, default_value_t = InputFormat::Auto)]
    pub format: InputFormat,
    /// Line protocol: replay only records of this measurement (e.g. `mqtt_consumer`).
    #[arg(long, value_name = "NAME")]
    pub measurement: Option<String>,
    /// Publish this field as a JSON string, as the paper's robot does with `actualSpeed` (repeatable).
    #[arg(long = "string-field", value_name = "NAME")]
    pub string_fields: Vec<String>,
    /// Add the recorded timestamp (integer ns) under this JSON key (Telegraf: `json_time_key`
    /// with `json_time_format = "unix_ns"`).
    #[arg(long, value_name = "KEY")]
    pub time_key: Option<String>,
    /// Pause between records that have no timestamp, in milliseconds (5 Hz scans: 200).
    #[arg(long, value_name = "MS", default_value_t = 200)]
    pub interval_ms: u64,
    /// Wait at most this long between two messages (`5s`, `1m`), however long the recording
    /// pauses there; every wait of 10 s or more, and every one shortened, is announced on stderr.
    #[arg(long, value_name = "DURATION", value_parser = humantime::parse_duration)]
    pub max_gap: Option<Duration>,
    /// MQTT quality of service: 0, 1 (default: every message acknowledged by the broker) or 2.
    #[arg(long, default_value_t = 1)]
    pub qos: u8,
    /// MQTT client id (default: `tessla-replay-<pid>`).
    #[arg(long)]
    pub client_id: Option<String>,
    /// Log in to the broker as this user (its password: --password-env).
    #[arg(long, value_name = "NAME")]
    pub username: Option<String>,
    /// The environment variable holding the password (so it appears neither on the command
    /// line nor in `ps`). Needs --username.
    #[arg(long, value_name = "VAR", requires = "username")]
    pub password_env: Option<String>,
    /// TLS (with an mqtts:// broker): the CA certificate (PEM) that signed the broker's.
    #[arg(long, value_name = "PATH")]
    pub tls_ca: Option<PathBuf>,
    /// TLS: a client certificate (PEM), for brokers that ask for one. Needs --tls-key.
    #[arg(long, value_name = "PATH", requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// TLS: the client certificate's private key (PEM). Needs --tls-cert.
    #[arg(long, value_name = "PATH", requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
}

/// The login from the command line: the password read from its variable, the TLS files read.
fn login(args: &ReplayArgs, broker: &Broker) -> Result<Login, CliError> {
    let password = match &args.password_env {
        None => None,
        Some(var) => Some(std::env::var(var).map_err(|_| {
            CliError::spec(format!(
                "--password-env {var}: the environment variable {var} is not set (or not UTF-8)"
            ))
        })?),
    };
    let read = |p: &PathBuf, what: &str| {
        std::fs::read(p).map_err(|e| CliError::spec(format!("{what} {}: {e}", p.display())))
    };
    let ca = args
        .tls_ca
        .as_ref()
        .map(|p| read(p, "--tls-ca"))
        .transpose()?;
    let client = match (&args.tls_cert, &args.tls_key) {
        (Some(c), Some(k)) => Some((read(c, "--tls-cert")?, read(k, "--tls-key")?)),
        _ => None,
    };
    if broker.tls && ca.is_none() {
        return Err(CliError::spec(format!(
            "{broker} is TLS: --tls-ca PATH must name the CA that signed its certificate"
        )));
    }
    if !broker.tls && (ca.is_some() || client.is_some()) {
        return Err(CliError::spec(format!(
            "--tls-ca/--tls-cert need a TLS broker: write mqtts://{}:{}",
            broker.host, broker.port
        )));
    }
    Ok(Login {
        username: args.username.clone(),
        password,
        ca,
        client,
    })
}

/// Run the subcommand; every error message starts with `replay: `.
pub fn run(args: ReplayArgs) -> CliResult {
    replay(&args).map_err(|e| CliError::new(e.code, format!("replay: {}", e.message)))
}

fn replay(args: &ReplayArgs) -> CliResult {
    let speed = pacing::check_speed(args.speed).map_err(|e| CliError::spec(e.to_string()))?;
    let qos = parse_qos(args.qos).map_err(|e| CliError::spec(e.to_string()))?;
    let broker: Broker = args
        .broker
        .parse()
        .map_err(|e: BrokerError| CliError::spec(e.to_string()))?;
    let login = login(args, &broker)?;
    let recording = read_recording(&args.file, args.format, args.measurement.as_deref())?;
    for skipped in &recording.skipped {
        eprintln!("W! replay: {}: skipped {skipped}", args.file.display());
    }
    if recording.samples.is_empty() {
        return Err(CliError::io(format!(
            "{}: no records to replay",
            args.file.display()
        )));
    }
    let options = MessageOptions {
        string_fields: args.string_fields.clone(),
        time_key: args.time_key.clone(),
    };
    let times: Vec<Option<i64>> = recording.samples.iter().map(|s| s.time_ns).collect();
    let (due, gaps) = pacing::offsets_capped(
        &times,
        speed,
        Duration::from_millis(args.interval_ms),
        args.max_gap,
    );
    let mut gaps = gaps.into_iter().peekable();

    let client_id = args
        .client_id
        .clone()
        .unwrap_or_else(|| format!("tessla-replay-{}", std::process::id()));
    let mut publisher =
        Publisher::connect_with(&broker, &client_id, qos, Duration::from_secs(10), &login)
            .map_err(|e| CliError::io(e.to_string()))?;

    let bar = progress_bar(recording.samples.len());
    let start = Instant::now();
    for (i, (sample, offset)) in recording.samples.iter().zip(&due).enumerate() {
        if let Some(gap) = gaps.next_if(|g| g.index == i) {
            bar.suspend(|| announce(&args.file, sample.line, &gap));
        }
        let wait = offset.saturating_sub(start.elapsed());
        if !wait.is_zero() {
            std::thread::sleep(wait);
        }
        let payload = to_json(sample, &options).to_string().into_bytes();
        publisher
            .publish(&args.topic, payload)
            .map_err(|e| CliError::io(e.to_string()))?;
        bar.inc(1);
    }
    let published = publisher
        .finish(Duration::from_secs(30))
        .map_err(|e| CliError::io(e.to_string()))?;
    bar.finish_and_clear();
    eprintln!(
        "I! replay: published {published} messages from {} to {broker} topic {:?} in {:.1} s ({} skipped)",
        args.file.display(),
        args.topic,
        start.elapsed().as_secs_f64(),
        recording.skipped.len()
    );
    Ok(())
}

/// Say that a long wait starts, or that `--max-gap` shortened one.
fn announce(file: &Path, line: usize, gap: &pacing::Gap) {
    let secs = |d: Duration| format!("{:.1} s", d.as_secs_f64());
    if gap.waited < gap.recorded {
        eprintln!(
            "I! replay: {}: line {line}: the recording pauses {} here; waiting {} (--max-gap)",
            file.display(),
            secs(gap.recorded),
            secs(gap.waited)
        );
    } else {
        eprintln!(
            "I! replay: {}: line {line}: the recording pauses {} here; waiting (--max-gap \
             DURATION shortens such waits)",
            file.display(),
            secs(gap.recorded)
        );
    }
}

fn read_recording(
    path: &Path,
    format: InputFormat,
    measurement: Option<&str>,
) -> Result<Recording, CliError> {
    let bytes = std::fs::read(path)
        .map_err(|e| CliError::io(format!("cannot read {}: {e}", path.display())))?;
    // A line that is not UTF-8 is skipped and reported, as `run` does, not the whole file.
    let (text, not_utf8) = read_lp::valid_lines(&bytes);
    let is_csv = match format {
        InputFormat::Csv => true,
        InputFormat::Lp => false,
        InputFormat::Auto => path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("csv")),
    };
    let mut recording = if is_csv {
        read_csv::read(&text).map_err(|e| CliError::io(format!("{}: {e}", path.display())))?
    } else {
        read_lp::read(&text, measurement)
    };
    recording.skipped.extend(not_utf8);
    recording.skipped.sort_by_key(|s| s.line);
    Ok(recording)
}

/// A progress bar on stderr when it is a terminal, hidden otherwise.
fn progress_bar(len: usize) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::with_draw_target(Some(len as u64), ProgressDrawTarget::hidden());
    }
    let bar = ProgressBar::new(len as u64);
    if let Ok(style) = ProgressStyle::with_template(
        "{spinner} [{elapsed_precise}] {wide_bar} {pos}/{len} msgs ({eta})",
    ) {
        bar.set_style(style);
    }
    bar
}
