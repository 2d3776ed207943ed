//! `tessla-telegraf trace SPEC [TRACE]`: run a spec over a TeSSLa input trace (file or stdin)
//! and print TeSSLa's output format; exit 1 on a runtime error, 2 on a spec error.

use super::{EXIT_IO, EXIT_OK, EXIT_RUNTIME, EXIT_SPEC, TraceArgs};
use std::io::{Read, Write};

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
    let text = match &args.trace {
        Some(p) => {
            std::fs::read_to_string(p).map_err(|e| format!("cannot read {}: {e}", p.display()))
        }
        None => {
            let mut s = String::new();
            std::io::stdin()
                .read_to_string(&mut s)
                .map(|_| s)
                .map_err(|e| format!("cannot read stdin: {e}"))
        }
    };
    let text = match text {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            return EXIT_IO;
        }
    };
    let result = crate::trace::run(&loaded.program, &text);
    let _ = std::io::stdout().write_all(result.output.as_bytes());
    match result.error {
        Some(e) => {
            eprintln!("{e}");
            EXIT_RUNTIME
        }
        None => EXIT_OK,
    }
}
