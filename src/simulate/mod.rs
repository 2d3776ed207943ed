//! `tessla-telegraf simulate`: a simulated TurtleBot3 Burger in closed loop with the monitors.
//!
//! Owns the digital-twin simulation, one module per concern: [`robot`] (drive physics),
//! [`terrain`] (the ground along the path), [`program`] (the robot's expected-speed schedule),
//! [`lidar`] (the 2-D map and the sensor's faults), [`closed_loop`] (the clock, the message,
//! the measures), [`in_process`] and [`mqtt_twin`] (the two ways to reach the monitors),
//! [`summary`] (the table and JSON printed at the end), [`scenario`] (building a run from
//! the named bundled parts), and [`shared_floor`] (robots sharing one floor, for the fleet
//! example). The command line lives in `crate::cli::simulate`; the model and
//! where its parameters come from are documented in docs/book/src/simulation.md.

pub mod closed_loop;
pub mod gate;
pub mod in_process;
pub mod lidar;
pub mod mqtt_twin;
pub mod program;
pub mod robot;
pub mod scenario;
pub mod shared_floor;
pub mod summary;
pub mod terrain;

/// The data rows of the simulator's text formats (terrain, program): for each line that is not
/// blank or a `#` comment, its 1-based number and its columns (split at commas and white space).
/// Why a terrain or program file, or the points or steps it gives, is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    #[error("no points")]
    NoPoints,
    #[error("point {0}: not a finite number")]
    NotFinite(usize),
    #[error("point {0}: rolling coefficient {1} is negative")]
    NegativeRolling(usize, f64),
    #[error("point {0}: x = {1} is not after the previous point")]
    NotAfter(usize, f64),
    #[error("no steps")]
    NoSteps,
    #[error("step {0}: duration {1} is not a positive number of seconds")]
    BadDuration(usize, f64),
    #[error("step {0}: speed {1} is not a number")]
    BadSpeed(usize, f64),
    /// A line with the wrong number of columns (`expected`: the line's form).
    #[error("line {line}: expected `{expected}`, found {found} columns")]
    Columns {
        line: usize,
        expected: &'static str,
        found: usize,
    },
    #[error("line {0}: {1:?} is not a number")]
    NotANumber(usize, String),
    /// The points of a terrain file are refused.
    #[error("{0} (terrain file)")]
    TerrainFile(Box<InputError>),
    /// The steps of a program file are refused.
    #[error("{0} (program file)")]
    ProgramFile(Box<InputError>),
}

fn data_rows(text: &str) -> impl Iterator<Item = (usize, Vec<&str>)> {
    text.lines().enumerate().filter_map(|(n, raw)| {
        let line = raw.split('#').next().unwrap_or("").trim();
        let cols: Vec<&str> = line
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|c| !c.is_empty())
            .collect();
        (!cols.is_empty()).then_some((n + 1, cols))
    })
}
