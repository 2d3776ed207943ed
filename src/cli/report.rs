//! `tessla-telegraf report`: render a run's line protocol (our output with pass-through) as an
//! HTML page with SVG plots, an MSE table and violation counts.

use super::error::{CliError, CliResult};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args, Clone)]
pub struct ReportArgs {
    /// Line protocol written by `tessla-telegraf run` (pass-through telemetry and verdicts);
    /// `-` reads stdin.
    pub file: PathBuf,
    /// Folder to write `index.html` and the SVG plots into (created when missing); without it,
    /// `report` (in the current folder), unless `--summary` or `--timeline` alone is asked for.
    #[arg(short = 'o', long = "output", value_name = "DIR")]
    pub output: Option<PathBuf>,
    /// Print a short summary to stdout (steps, violations per property, augmented actions and
    /// why, the final MSE); without `-o`, write no files.
    #[arg(long)]
    pub summary: bool,
    /// Print to stdout, before any summary, when each verdict changed and each run of augmented
    /// actions with its reason and speeds (one line per time, at most 80 characters wide);
    /// without `-o`, write no files.
    #[arg(long)]
    pub timeline: bool,
    /// A measurement that holds telemetry passed through rather than the spec's outputs
    /// (repeatable; default `mqtt_consumer`, Telegraf's MQTT input).
    #[arg(long, value_name = "MEASUREMENT")]
    pub telemetry: Vec<String>,
}

/// Run the subcommand.
pub fn run(args: ReportArgs) -> CliResult {
    let (text, name) = if args.file.as_os_str() == "-" {
        let mut text = String::new();
        std::io::Read::read_to_string(&mut std::io::stdin(), &mut text)
            .map_err(|e| CliError::io(format!("report: cannot read stdin: {e}")))?;
        (text, "stdin".to_string())
    } else {
        let text = std::fs::read_to_string(&args.file).map_err(|e| {
            CliError::io(format!("report: cannot read {}: {e}", args.file.display()))
        })?;
        (text, args.file.display().to_string())
    };
    if args.timeline && !say(&crate::report::timeline(&text, &name, 80, &args.telemetry))? {
        return Ok(());
    }
    let output = match (&args.output, args.summary || args.timeline) {
        (Some(dir), _) => dir.clone(),
        (None, false) => PathBuf::from("report"),
        (None, true) => {
            let s = crate::report::summarize(&text, &args.telemetry);
            warn_missing(&s, &name);
            if args.summary {
                say(&s.text(&name))?;
            }
            return Ok(());
        }
    };
    let output = &output;
    let written = crate::report::write_report(&text, &name, output, &args.telemetry)
        .map_err(|e| CliError::io(format!("report: {e}")))?;
    let s = &written.summary;
    warn_missing(s, &name);
    let mut files = format!("{}\n", written.html.display());
    for svg in &written.svgs {
        files.push_str(&format!("{}\n", svg.display()));
    }
    if args.summary && !say(&s.text(&name))? || !say(&files)? {
        return Ok(());
    }
    let mse = s
        .mse
        .map_or_else(|| "no data".to_string(), |v| format!("{v:.6e}"));
    let mut line = format!("I! report: {} records", s.records);
    if s.robot {
        line.push_str(&format!(
            "; MSE expected/actual speed {mse}; P1 violated {} unknown {}; P2 violated {}; \
             P3 spikes {} dropouts {}",
            s.p1_violated,
            s.p1_unknown,
            s.p2_violations,
            crate::report::outputs::short(s.p3_spikes),
            crate::report::outputs::short(s.p3_dropouts)
        ));
    }
    if let Some(silence) = &s.silence {
        line.push_str(&format!(
            "; robot silent {} times, {} s",
            silence.periods.len(),
            crate::report::outputs::short(silence.total())
        ));
    }
    eprintln!("{line}");
    Ok(())
}

/// Write `text` to stdout: `Ok(false)` when the reader closed it (`report … | head`), which ends
/// the command quietly, as other command-line tools do.
fn say(text: &str) -> Result<bool, CliError> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(false),
        Err(e) => Err(CliError::io(format!("report: cannot write to stdout: {e}"))),
    }
}

/// One warning naming the robot spec's outputs a run of the robot spec lacks (the report then
/// leaves their lines and plots out); none for another spec's run.
fn warn_missing(s: &crate::report::stats::Summary, source: &str) {
    if s.missing_robot.is_empty() {
        return;
    }
    eprintln!(
        "W! report: {source} lacks the robot spec's outputs {}: their counts and plots \
         are left out; the spec's own outputs and verdicts are shown",
        s.missing_robot.join(", ")
    );
}
