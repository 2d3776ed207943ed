//! Embedding the engine: load a spec, feed events, read the outputs.
//!
//! `cargo run -p tessla-engine --example embed` prints one line per output event;
//! `cargo test` runs the example's test below (the manifest builds it with `test = true`).

use std::io::Write;
use std::sync::Arc;
use tessla_engine::{LoadOptions, Monitor, OutputEvent, Value, load_with};
use tessla_syntax::include::MemResolver;

const SPEC: &str = "
in speed: Events[Float]
def too_fast = speed >. 0.22
out too_fast
";

fn run(out: &mut dyn Write) -> Result<(), Box<dyn std::error::Error>> {
    // Load from memory; `tessla_engine::load_file` reads a spec and its includes from disk.
    let mut specs = MemResolver::default();
    specs.files.insert("speed.tessla".into(), SPEC.into());
    // A spec that does not check comes back with diagnostics: file, line, column and a hint.
    let loaded =
        load_with("speed.tessla", &specs, &LoadOptions::default()).map_err(|e| e.render())?;
    let program = Arc::clone(&loaded.program);
    let speed = program
        .input_index("speed")
        .ok_or("the spec has no input `speed`")?;

    let mut monitor = Monitor::new(Arc::clone(&program));
    let mut lines = Vec::new();
    let mut sink = |e: OutputEvent<'_>| {
        lines.push(format!(
            "{}: {} = {}",
            e.ts, program.outputs[e.output].name, e.value
        ));
    };
    for (ts, v) in [(1, 0.10), (2, 0.25), (3, 0.20)] {
        // Events at one timestamp form one step; a step is evaluated once time passes it.
        monitor.push(ts, speed, Value::Float(v), &mut sink)?;
    }
    monitor.flush(&mut sink); // the end of the input: evaluate the last step
    Ok(writeln!(out, "{}", lines.join("\n"))?)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    run(&mut std::io::stdout())
}

#[test]
fn the_example_prints_each_steps_verdict() {
    let mut out = Vec::new();
    run(&mut out).map_err(|e| e.to_string()).unwrap();
    let expected = "1: too_fast = false\n2: too_fast = true\n3: too_fast = false\n";
    assert_eq!(String::from_utf8_lossy(&out), expected);
}
