//! An application's natives (`builtins::Natives`): registered with a name, a signature and a
//! function, reached from a spec through `extern("name")`, called like the table's natives,
//! the declaring `def` held to the registered signature; refused when they would shadow a
//! builtin, repeat a name or carry a signature that is not a function type.

use std::sync::Arc;
use tessla_engine::builtins::{self, Natives, RegisterError};
use tessla_engine::{LoadOptions, Monitor, OutputEvent, Value};
use tessla_syntax::include::MemResolver;

fn twice(a: &[Value]) -> Value {
    match a {
        [Value::Int(n)] => Value::Int(n.wrapping_mul(2)),
        _ => Value::None,
    }
}

fn pair_sum(a: &[Value]) -> Value {
    match a {
        [Value::Tuple(t)] => match &t[..] {
            [Value::Float(x), Value::Float(y)] => Value::Float(x + y),
            _ => Value::None,
        },
        _ => Value::None,
    }
}

fn natives() -> Natives {
    let mut n = Natives::new();
    let registered = n
        .register("app_twice", "(Int) => Int", twice)
        .and_then(|n| n.register("app_pair_sum", "((Float, Float)) => Float", pair_sum))
        .is_ok();
    assert!(registered);
    n
}

fn load(spec: &str, natives: Natives) -> Result<tessla_engine::Loaded, String> {
    let resolver = MemResolver {
        files: [("spec.tessla".to_string(), spec.to_string())].into(),
    };
    let options = LoadOptions {
        natives,
        ..LoadOptions::default()
    };
    tessla_engine::load_with("spec.tessla", &resolver, &options).map_err(|e| e.render())
}

/// The output lines `ts: name = value` of `spec` over `x` = 1, 2, 3 at times 1, 2, 3.
fn run(spec: &str, natives: Natives) -> Vec<String> {
    let loaded = load(spec, natives).unwrap_or_else(|e| panic!("{e}"));
    let program = Arc::clone(&loaded.program);
    let mut m = Monitor::new(Arc::clone(&program));
    let mut out = Vec::new();
    let mut sink = |e: OutputEvent<'_>| {
        out.push(format!(
            "{}: {} = {}",
            e.ts, program.outputs[e.output].name, e.value
        ));
    };
    let x = program.input_index("x").unwrap_or(0);
    for t in 1..=3 {
        m.push(t, x, Value::Int(t), &mut sink).unwrap();
    }
    m.flush(&mut sink);
    out
}

const TWICE: &str = "def twice(n: Int): Int = extern(\"app_twice\")\n\
                     in x: Events[Int]\n\
                     def y = slift(x, (v: Int) => twice(v))\n\
                     out y\n";

#[test]
fn a_registered_native_is_called_through_its_extern() {
    assert_eq!(run(TWICE, natives()), ["1: y = 2", "2: y = 4", "3: y = 6"]);
    // As a liftable def applied to a stream, and with a tuple in its signature.
    let spec = "liftable def twice(n: Int): Int = extern(\"app_twice\")\n\
                def sum(p: (Float, Float)): Float = extern(\"app_pair_sum\")\n\
                in x: Events[Int]\n\
                def y = twice(x)\n\
                def z = slift(x, (v: Int) => sum((intToFloat(v), 0.5)))\n\
                out y\nout z\n";
    assert_eq!(
        run(spec, natives()),
        [
            "1: y = 2",
            "1: z = 1.5",
            "2: y = 4",
            "2: z = 2.5",
            "3: y = 6",
            "3: z = 3.5"
        ]
    );
}

#[test]
fn without_registration_the_extern_is_unknown_as_before() {
    let lines = run(TWICE, Natives::new());
    assert_eq!(lines.len(), 3, "{lines:?}");
    assert!(
        lines.iter().all(|l| l.contains("unknown extern")),
        "{lines:?}"
    );
    // Said once at load, where the extern is declared, with the natives that are registered.
    let warnings = |natives: Natives| match load(TWICE, natives) {
        Ok(loaded) => tessla_syntax::diag::render(&loaded.warnings, &loaded.sources, false),
        Err(e) => panic!("{e}"),
    };
    let none = warnings(Natives::new());
    assert_eq!(none.matches("names no native").count(), 1, "{none}");
    assert!(none.contains("spec.tessla:1:"), "{none}");
    let mut other = Natives::new();
    other
        .register("app_pair_sum", "((Float, Float)) => Float", pair_sum)
        .unwrap();
    let listed = warnings(other);
    assert!(listed.contains("`extern(\"app_twice\")`"), "{listed}");
    assert!(
        listed.contains("this program's natives: app_pair_sum"),
        "{listed}"
    );
    // A registered native: no warning.
    assert!(!warnings(natives()).contains("names no native"));
}

#[test]
fn a_declaration_with_another_type_is_a_type_error() {
    for (decl, found) in [
        ("def twice(n: Float): Int", "(Float) => Int"),
        ("def twice(n: Int, m: Int): Int", "(Int, Int) => Int"),
        ("def twice(n: Int): String", "(Int) => String"),
    ] {
        let spec =
            format!("{decl} = extern(\"app_twice\")\nin x: Events[Int]\nout x\ndef u = twice\n");
        let err = load(&spec, natives()).err().unwrap_or_default();
        assert!(
            err.contains("`twice` is declared with another type than the native `app_twice`")
                && err.contains(found)
                && err.contains("spec.tessla:1:"),
            "{decl}: {err}"
        );
    }
}

#[test]
fn a_signature_that_does_not_parse_is_reported_where_the_native_is_declared() {
    let mut n = Natives::new();
    assert!(n.register("app_twice", "(Integer) => Int", twice).is_ok());
    let err = load(TWICE, n).err().unwrap_or_default();
    assert!(
        err.contains("the native `app_twice` was registered with a signature that does not parse"),
        "{err}"
    );
}

#[test]
fn registration_refuses_builtin_names_repeats_and_non_function_signatures() {
    let mut n = Natives::new();
    assert_eq!(
        n.register("max", "(Int, Int) => Int", twice).err(),
        Some(RegisterError::Builtin("max"))
    );
    assert_eq!(
        n.register("List_size", "(List[A]) => Int", twice).err(),
        Some(RegisterError::Builtin("List_size"))
    );
    assert!(n.register("app_twice", "(Int) => Int", twice).is_ok());
    assert_eq!(
        n.register("app_twice", "(Int) => Int", twice).err(),
        Some(RegisterError::Twice("app_twice"))
    );
    for sig in [
        "Int",
        "(Int)",
        "(Int) =>",
        "(Int => Int",
        "Int) => (Int",
        "(Int) => Int]",
        "(é => Int",
        "(Int) é=> Int",
    ] {
        assert_eq!(
            n.register("app_other", sig, twice).err(),
            Some(RegisterError::Signature {
                name: "app_other",
                sig
            }),
            "{sig}"
        );
    }
    assert_eq!(n.iter().map(|x| x.name).collect::<Vec<_>>(), ["app_twice"]);
    assert_eq!(
        RegisterError::Twice("app_twice").to_string(),
        "native `app_twice`: registered twice"
    );
}

#[test]
fn the_engine_itself_has_no_robot_or_fleet_natives() {
    for name in [
        "lidar_dropouts",
        "lidar_spikes",
        "lidar_sector_min",
        "lidar_sector_valid_fraction",
        "fleet_closest_pair",
    ] {
        assert!(builtins::get(name).is_none(), "{name}");
    }
}
