//! `tessla-telegraf check SPEC`: parse and check a spec, print its inputs and outputs with types
//! and annotations; exit 0, or 2 with diagnostics.

use super::{CheckArgs, EXIT_OK, EXIT_SPEC};

pub fn run(args: CheckArgs) -> i32 {
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
        eprint!(
            "{}",
            tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, false)
        );
    }
    // The Telegraf binding reads the annotations: check them as `run` does.
    if let Err(e) = crate::telegraf::binding::bindings(&loaded.program) {
        eprintln!("error: {e}");
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
    for i in &p.inputs {
        println!("in  {}: Events[{}]{}", i.name, i.ty, ann(&i.annotations));
    }
    for o in &p.outputs {
        println!("out {}: Events[{}]{}", o.name, o.ty, ann(&o.annotations));
    }
    println!(
        "{} inputs, {} outputs, {} stream nodes",
        p.inputs.len(),
        p.outputs.len(),
        p.nodes.len()
    );
    EXIT_OK
}
