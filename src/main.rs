//! The `tessla-telegraf` binary: hands over to `cli`, whose exit code (the book, "Exit codes")
//! is the process's.

use std::process::ExitCode;

fn main() -> ExitCode {
    tessla_telegraf::cli::main()
}
