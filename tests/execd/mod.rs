//! The binary as Telegraf's `processors.execd` runs it: a child process on stdin/stdout (or UDP),
//! stopped by EOF or a signal, reloaded by SIGHUP, restarted with `--state`, fed hostile input.

#[allow(clippy::module_inception)]
mod execd;
mod execd_instances;
mod execd_reload;
mod execd_state;
mod fleet;
mod hostile_input;
mod last_lines;
mod live_time;
mod pipeline_duplicates;
mod robot_action;
mod robot_fixture;
mod step_watchdog;
mod unmatched_inputs;
