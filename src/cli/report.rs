//! `tessla-telegraf report`: render a run's line protocol (our output with pass-through) as an
//! HTML page with SVG plots, an MSE table and violation counts.

use crate::cli::{CliError, CliResult};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args, Clone)]
pub struct ReportArgs {
    /// Line protocol written by `tessla-telegraf run` (pass-through telemetry and verdicts);
    /// `-` reads stdin.
    pub file: PathBuf,
    /// Folder to write `index.html` and the SVG plots into (created when missing).
    #[arg(
        short = 'o',
        long = "output",
        value_name = "DIR",
        required_unless_present = "summary"
    )]
    pub output: Option<PathBuf>,
    /// Print a short summary to stdout (steps, violations per property, augmented actions and
    /// why, the final MSE); without `-o`, write no files.
    #[arg(long)]
    pub summary: bool,
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
    let Some(output) = &args.output else {
        let s = crate::report::summarize(&text);
        print!("{}", s.text(&name));
        return Ok(());
    };
    let written = crate::report::write_report(&text, &name, output)
        .map_err(|e| CliError::io(format!("report: {e}")))?;
    let s = &written.summary;
    if args.summary {
        print!("{}", s.text(&name));
    }
    println!("{}", written.html.display());
    for svg in &written.svgs {
        println!("{}", svg.display());
    }
    let mse = s
        .mse
        .map_or_else(|| "no data".to_string(), |v| format!("{v:.6e}"));
    eprintln!(
        "I! report: {} records; MSE expected/actual speed {mse}; P1 violated {} unknown {}; \
         P2 violated {}; P3 spikes {} dropouts {}",
        s.records, s.p1_violated, s.p1_unknown, s.p2_violations, s.p3_spikes, s.p3_dropouts
    );
    Ok(())
}
