//! The run report (`tessla-telegraf report`): the paper's plots and tables from line protocol.
//!
//! Data flows one way: the line protocol our binary printed (pass-through telemetry and
//! verdicts) is read into [`data::Run`], [`series`] picks the quantities out of it wherever the
//! output binding put them, [`stats`] computes the MSE table and violation counts, [`plots`]
//! draws SVG charts with plotters, and [`html`] writes the page. The command line lives in
//! `crate::cli::report`.

pub mod data;
pub mod html;
pub mod outputs;
pub mod plots;
pub mod series;
pub mod stats;
pub mod text;

use std::path::{Path, PathBuf};

/// Files written by [`write_report`].
#[derive(Debug, Clone)]
pub struct Written {
    pub html: PathBuf,
    pub svgs: Vec<PathBuf>,
    pub summary: stats::Summary,
}

/// The run in `text`; `telemetry` (when not empty) replaces the default telemetry measurement.
fn parse(text: &str, telemetry: &[String]) -> data::Run {
    let mut run = data::Run::parse(text);
    if !telemetry.is_empty() {
        run.telemetry = telemetry.to_vec();
    }
    run
}

/// The summary of `text` (line protocol) alone, without plots or files.
pub fn summarize(text: &str, telemetry: &[String]) -> stats::Summary {
    let run = parse(text, telemetry);
    let picked = series::Picked::from_run(&run);
    stats::Summary::compute(&run, &picked)
}

/// The terminal view of `text` (line protocol): verdict changes, runs of augmented actions.
pub fn timeline(text: &str, source: &str, width: usize, telemetry: &[String]) -> String {
    let run = parse(text, telemetry);
    let picked = series::Picked::from_run(&run);
    let outputs = outputs::Outputs::from_run(&run);
    let lines = outputs::timeline(&picked, &outputs, width);
    if lines.is_empty() {
        return format!("{source}: no verdicts and no augmented actions\n");
    }
    let start = run
        .start_ns
        .and_then(|ns| u64::try_from(ns).ok())
        .map(|ns| {
            let at = std::time::UNIX_EPOCH + std::time::Duration::from_nanos(ns);
            format!(", {}", humantime::format_rfc3339_seconds(at))
        })
        .unwrap_or_default();
    let actions = if picked.augmented.is_empty() {
        ""
    } else {
        "; the augmented actions"
    };
    format!(
        "{source}: when each verdict changed{actions}\n\
         (seconds from the first record{start})\n{lines}"
    )
}

/// Why a report could not be written: a file or folder, or a chart.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The output folder cannot be created.
    #[error("cannot create {}: {error}", .path.display())]
    Create {
        path: PathBuf,
        error: std::io::Error,
    },
    /// An earlier report's chart cannot be removed.
    #[error("cannot remove {}: {error}", .path.display())]
    Remove {
        path: PathBuf,
        error: std::io::Error,
    },
    /// A chart or the page cannot be written.
    #[error("cannot write {}: {error}", .path.display())]
    Write {
        path: PathBuf,
        error: std::io::Error,
    },
    /// A chart cannot be drawn.
    #[error(transparent)]
    Plot(#[from] plots::PlotError),
}

/// Read `text` (line protocol) and write `index.html` and the SVG plots into `dir`.
pub fn write_report(
    text: &str,
    source_name: &str,
    dir: &Path,
    telemetry: &[String],
) -> Result<Written, ReportError> {
    let run = parse(text, telemetry);
    let picked = series::Picked::from_run(&run);
    let summary = stats::Summary::compute(&run, &picked);
    std::fs::create_dir_all(dir).map_err(|error| ReportError::Create {
        path: dir.to_path_buf(),
        error,
    })?;
    let mut svgs = Vec::new();
    let outputs = outputs::Outputs::from_run(&run);
    let rendered = plots::render_all(&picked, &outputs)?;
    let titles: Vec<(&str, &str)> = rendered.iter().map(|p| (p.file_name, p.title)).collect();
    // A chart this run has no data for is not drawn: remove an earlier report's copy, so the
    // folder holds what the page shows.
    for (file, _) in plots::FILES {
        if !titles.iter().any(|(f, _)| *f == file) {
            let stale = dir.join(file);
            match std::fs::remove_file(&stale) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(ReportError::Remove {
                        path: stale,
                        error: e,
                    });
                }
                _ => {}
            }
        }
    }
    for plot in &rendered {
        let path = dir.join(plot.file_name);
        std::fs::write(&path, &plot.svg).map_err(|error| ReportError::Write {
            path: path.clone(),
            error,
        })?;
        svgs.push(path);
    }
    let page = html::page(source_name, &summary, &titles, &run, &outputs);
    let html_path = dir.join("index.html");
    std::fs::write(&html_path, page).map_err(|error| ReportError::Write {
        path: html_path.clone(),
        error,
    })?;
    Ok(Written {
        html: html_path,
        svgs,
        summary,
    })
}
