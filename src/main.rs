//! The `tessla-telegraf` binary: parses the command line and hands over to `cli`.

fn main() {
    std::process::exit(tessla_telegraf::cli::main());
}
