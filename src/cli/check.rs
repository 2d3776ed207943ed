//! `tessla-telegraf check SPEC`: parse and check a spec, print its inputs and outputs with types
//! and annotations; exit 0, or 2 with diagnostics.

use super::{CheckArgs, EXIT_IO, EXIT_OK, EXIT_SPEC};
use std::io::Write;

/// Write to stderr; a closed stderr is not worth a panic (the exit code still tells).
fn report(text: &str) {
    let _ = std::io::stderr().lock().write_all(text.as_bytes());
}

pub fn run(args: CheckArgs) -> i32 {
    let options = match super::load_options(&args.spec_options) {
        Ok(o) => o,
        Err(e) => {
            report(&format!("error: {e}\n"));
            return EXIT_SPEC;
        }
    };
    let loaded = match tessla_engine::load_file(&args.spec, &options) {
        Ok(l) => l,
        Err(e) => {
            report(&e.render());
            return EXIT_SPEC;
        }
    };
    if !loaded.warnings.is_empty() {
        report(&tessla_syntax::diag::render(
            &loaded.warnings,
            &loaded.sources,
            false,
        ));
    }
    // The Telegraf binding reads the annotations: check them as `run` does.
    if let Err(e) = crate::telegraf::binding::bindings(&loaded.program) {
        report(&format!("error: {e}\n"));
        return EXIT_SPEC;
    }
    let p = &loaded.program;
    let ann = |a: &[tessla_engine::Annotation]| {
        a.iter()
            .map(|a| {
                let args: Vec<String> = a
                    .args
                    .iter()
                    .map(|(k, v)| match v {
                        tessla_engine::Value::Str(s) => format!("{k} = {s:?}"),
                        other => format!("{k} = {other}"),
                    })
                    .collect();
                format!(" @{}({})", a.name, args.join(", "))
            })
            .collect::<String>()
    };
    let mut out = String::new();
    for i in &p.inputs {
        out.push_str(&format!(
            "in  {}: Events[{}]{}\n",
            i.name,
            i.ty,
            ann(&i.annotations)
        ));
    }
    for o in &p.outputs {
        out.push_str(&format!(
            "out {}: Events[{}]{}\n",
            o.name,
            o.ty,
            ann(&o.annotations)
        ));
    }
    out.push_str(&format!(
        "{} inputs, {} outputs, {} stream nodes\n",
        p.inputs.len(),
        p.outputs.len(),
        p.nodes.len()
    ));
    if args.ir {
        out.push_str(&p.ir().to_string());
    }
    let mut stdout = std::io::stdout().lock();
    match stdout
        .write_all(out.as_bytes())
        .and_then(|()| stdout.flush())
    {
        Ok(()) => EXIT_OK,
        Err(e) => {
            report(&format!("error: writing the result: {e}\n"));
            EXIT_IO
        }
    }
}
