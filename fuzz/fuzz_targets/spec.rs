//! Fuzz target: the spec front end. Text in (as `main.tessla`, which may include the bundled
//! robot specs or itself), through tessla-syntax and tessla-engine's checker and compiler,
//! diagnostics or a program out. Checks: no panic, no hang; an error always carries at least one
//! diagnostic and renders; a program's annotations give valid bindings and encodings.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tessla_syntax::include::MemResolver;
use tessla_telegraf::processor::{Options, Processor};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let mut files: std::collections::HashMap<String, String> = tessla_telegraf::bundled::FILES
        .iter()
        .map(|(n, t)| (n.to_string(), t.to_string()))
        .collect();
    files.insert("main.tessla".into(), text.to_string());
    let resolver = MemResolver { files };
    // The program's natives, as every command compiles with (the seeds declare the lidar's).
    let Ok(options) = tessla_telegraf::natives::load_options() else {
        return;
    };
    match tessla_engine::load_with("main.tessla", &resolver, &options) {
        Ok(loaded) => {
            let _ = tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, false);
            // Bad annotations are reported as a message, never a panic.
            let _ = Processor::new(loaded.program, Options::default());
        }
        Err(e) => {
            assert!(!e.diagnostics.is_empty(), "an error without a diagnostic");
            assert!(!e.render().is_empty());
        }
    }
});
