//! The engine and the command line: `check`, `trace`, `report`, `simulate`, the README's and the
//! book's commands run on files (or the engine in-process), the corpora of specs, the shipped files.

#[cfg(feature = "tools")]
mod book;
mod broken_specs;
mod check_cli;
mod combinations;
mod connector_include;
#[cfg(feature = "tools")]
mod first_hour;
mod pipeline_confs;
mod pipeline_dashboards;
#[cfg(feature = "tools")]
mod pipeline_report;
mod prelude;
#[cfg(feature = "tools")]
mod readme_commands;
#[cfg(feature = "tools")]
mod report_any_spec;
#[cfg(feature = "tools")]
mod report_chromium;
#[cfg(feature = "tools")]
mod simulate;
mod state_suite;
mod stdlib;
mod systemd_dropin;
mod trace_cli;
mod trace_ctf;
mod trace_run_differential;
