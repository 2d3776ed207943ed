//! The `tessla-telegraf` binary: parses the command line and hands over to `cli`; the exit
//! code (README "Exit codes") is what the subcommand returns.

use std::process::ExitCode;

fn main() -> ExitCode {
    let code = tessla_telegraf::cli::main();
    // Codes are 0..=3 (cli's EXIT_*); anything else would be a bug, reported as 1.
    ExitCode::from(u8::try_from(code).unwrap_or(1))
}
