//! `tessla-telegraf trace SPEC [TRACE]`: run a spec over a TeSSLa input trace (file or stdin,
//! read line by line) and print TeSSLa's output format as outputs are produced. Exit 1 on a
//! runtime or trace error (outputs before it are printed, the error goes to stderr), 2 on a
//! spec error, 3 when the trace cannot be read; 0 also when stdout is closed by the reader.

use super::{EXIT_IO, EXIT_OK, EXIT_RUNTIME, EXIT_SPEC, TraceArgs};
use crate::trace::{ErrorKind, run_stream};
use std::io::{BufReader, IsTerminal};

pub fn run(args: TraceArgs) -> i32 {
    let options = match super::load_options(&args.spec_options) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("error: {e}");
            return EXIT_SPEC;
        }
    };
    let loaded = match tessla_engine::load_file(&args.spec, &options) {
        Ok(l) => l,
        Err(e) => {
            eprint!("{}", e.render());
            return EXIT_SPEC;
        }
    };
    if !loaded.warnings.is_empty() {
        let color = std::io::stderr().is_terminal();
        eprint!(
            "{}",
            tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, color)
        );
    }
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let result = match &args.trace {
        Some(p) => match std::fs::File::open(p) {
            Ok(f) => run_stream(
                &loaded.program,
                &p.display().to_string(),
                BufReader::new(f),
                &mut out,
            ),
            Err(e) => {
                eprintln!("error: cannot read {}: {e}", p.display());
                return EXIT_IO;
            }
        },
        None => run_stream(
            &loaded.program,
            "<stdin>",
            std::io::stdin().lock(),
            &mut out,
        ),
    };
    match result {
        Ok(()) => EXIT_OK,
        Err(e) if e.kind == ErrorKind::OutputClosed => EXIT_OK,
        Err(e) if e.kind == ErrorKind::Io => {
            eprintln!("{e}");
            EXIT_IO
        }
        Err(e) => {
            eprintln!("{e}");
            EXIT_RUNTIME
        }
    }
}
