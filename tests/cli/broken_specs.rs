//! The corpus of broken specs (tests/fixtures/broken-specs/): each gives exit 2 from `check` and
//! from `run --spec`, with a diagnostic naming the file, line and column of the problem, never
//! a panic, within a deadline. Every file of the folder must be listed below, so a new broken
//! spec comes with its expected place.

use crate::support::BIN;
use crate::support::child;

use std::path::PathBuf;
use std::time::Duration;

/// Spec file -> the place its first error must name (`file:line:column`).
const PLACED: &[(&str, &str)] = &[
    (
        "type_annotation_mismatch",
        "type_annotation_mismatch.tessla:3:25",
    ),
    ("type_if_branches", "type_if_branches.tessla:3:26"),
    (
        "type_int_float_operator",
        "type_int_float_operator.tessla:3:9",
    ),
    ("unknown_type", "unknown_type.tessla:2:14"),
    ("duplicate_definition", "duplicate_definition.tessla:3:5"),
    ("include_loop_a", "include_loop_b.tessla:2:1"),
    ("include_loop_b", "include_loop_a.tessla:2:1"),
    ("include_missing", "include_missing.tessla:2:1"),
    ("include_self", "include_self.tessla:2:1"),
    ("invalid_utf8", "invalid_utf8.tessla:2:10"),
    ("nul_byte", "nul_byte.tessla:2:10"),
    ("recursion_self", "recursion_self.tessla:3:28"),
    (
        "recursion_macro_mutual",
        "recursion_macro_mutual.tessla:5:55",
    ),
    (
        "unknown_name_in_mutual_recursion",
        "unknown_name_in_mutual_recursion.tessla:6:46",
    ),
    (
        "recursion_without_last",
        "recursion_without_last.tessla:5:9",
    ),
    ("syntax_bad_character", "syntax_bad_character.tessla:3:11"),
    (
        "syntax_include_in_module",
        "syntax_include_in_module.tessla:3:3",
    ),
    ("syntax_missing_paren", "syntax_missing_paren.tessla:4:1"),
    ("syntax_operator_twice", "syntax_operator_twice.tessla:3:13"),
    ("syntax_too_deep", "syntax_too_deep.tessla:2:208"),
    (
        "syntax_unclosed_module",
        "syntax_unclosed_module.tessla:4:1",
    ),
    (
        "syntax_unterminated_string",
        "syntax_unterminated_string.tessla:2:9",
    ),
    ("time_unit_unknown", "time_unit_unknown.tessla:3:17"),
    ("type_input_not_events", "type_input_not_events.tessla:2:7"),
    ("type_wrong_arity", "type_wrong_arity.tessla:3:9"),
    ("unknown_function", "unknown_function.tessla:3:9"),
    ("unknown_stream", "unknown_stream.tessla:3:5"),
    // TeSSLa's rules for definitions nothing uses, type applications, annotations, named
    // arguments, type arguments and written types (each case's first line names its place).
    (
        "annotation_argument_type",
        "annotation_argument_type.tessla:4:8",
    ),
    ("annotation_arity", "annotation_arity.tessla:4:1"),
    (
        "annotation_defined_twice",
        "annotation_defined_twice.tessla:4:6",
    ),
    (
        "annotation_global_arity",
        "annotation_global_arity.tessla:4:1",
    ),
    (
        "annotation_global_used_locally",
        "annotation_global_used_locally.tessla:5:2",
    ),
    ("annotation_in_module", "annotation_in_module.tessla:4:3"),
    (
        "annotation_local_used_globally",
        "annotation_local_used_globally.tessla:4:3",
    ),
    (
        "annotation_not_constant",
        "annotation_not_constant.tessla:5:8",
    ),
    (
        "missing_lambda_parameter_type",
        "missing_lambda_parameter_type.tessla:4:20",
    ),
    (
        "missing_parameter_type",
        "missing_parameter_type.tessla:4:11",
    ),
    (
        "missing_recursive_type",
        "missing_recursive_type.tessla:4:5",
    ),
    (
        "named_after_positional",
        "named_after_positional.tessla:5:19",
    ),
    (
        "named_unknown_parameter",
        "named_unknown_parameter.tessla:5:14",
    ),
    (
        "type_argument_not_inferable",
        "type_argument_not_inferable.tessla:5:9",
    ),
    (
        "type_arity_on_plain_type",
        "type_arity_on_plain_type.tessla:4:30",
    ),
    ("type_arity_too_few", "type_arity_too_few.tessla:4:8"),
    ("type_arity_too_many", "type_arity_too_many.tessla:3:7"),
    (
        "undefined_type_application",
        "undefined_type_application.tessla:4:13",
    ),
    ("undefined_type_nested", "undefined_type_nested.tessla:4:29"),
    (
        "unused_function_unknown_name",
        "unused_function_unknown_name.tessla:5:36",
    ),
    ("unused_type_error", "unused_type_error.tessla:5:28"),
    (
        "unused_unknown_module_member",
        "unused_unknown_module_member.tessla:7:17",
    ),
    ("unused_unknown_name", "unused_unknown_name.tessla:5:13"),
    (
        "annotation_wrong_arguments",
        "annotation_wrong_arguments.tessla:3:13",
    ),
    // TeSSLa's MultipleDefinitionsError (found by name resolution).
    ("duplicate_input", "duplicate_input.tessla:4:4"),
    ("input_and_definition", "input_and_definition.tessla:4:5"),
    ("duplicate_parameter", "duplicate_parameter.tessla:4:15"),
    (
        "duplicate_record_field",
        "duplicate_record_field.tessla:4:17",
    ),
    // TeSSLa's rules for `liftable`, library signatures and type arguments (type checking).
    (
        "not_liftable_on_stream",
        "not_liftable_on_stream.tessla:5:11",
    ),
    ("liftable_constant", "liftable_constant.tessla:3:1"),
    (
        "liftable_stream_parameter",
        "liftable_stream_parameter.tessla:3:1",
    ),
    ("sum_of_floats", "sum_of_floats.tessla:4:13"),
    (
        "type_arguments_too_many",
        "type_arguments_too_many.tessla:3:5",
    ),
    // TeSSLa's statement rules: `in`/`out` at the top level, imports, literal includes.
    ("in_out_in_module", "in_out_in_module.tessla:4:3"),
    ("import_ambiguous", "import_ambiguous.tessla:11:3"),
    ("include_interpolated", "include_interpolated.tessla:3:10"),
    // The rest of TeSSLa core's error tests, each in a spec of our own.
    (
        "function_argument_arity",
        "function_argument_arity.tessla:6:15",
    ),
    ("record_wrong_member", "record_wrong_member.tessla:6:11"),
    ("record_extra_member", "record_extra_member.tessla:4:32"),
    (
        "lambda_without_parameters",
        "lambda_without_parameters.tessla:4:5",
    ),
    ("call_of_a_constant", "call_of_a_constant.tessla:5:5"),
    ("record_unknown_member", "record_unknown_member.tessla:4:10"),
    (
        "recursion_delay_on_itself",
        "recursion_delay_on_itself.tessla:4:35",
    ),
    (
        "include_invalid_escape",
        "include_invalid_escape.tessla:3:13",
    ),
];

// TeSSLa core's error tests (core/src/test/resources/.../core/errors in TeSSLa's repository)
// and the spec here that has each one's rule (its first error; TeSSLa's files are not copied):
// annotationdef-in-module: annotation_in_module; annotations-arity-mismatch: annotation_arity;
// annotations-type-mismatch: annotation_argument_type; global-annotations-arity-mismatch:
// annotation_global_arity; global-annotations-as-annotation: annotation_global_used_locally;
// non-literal-annotation: annotation_not_constant; arity-mismatch: type_wrong_arity;
// cycle-detection-in-delay: recursion_delay_on_itself; cycle-detection-in-last,
// infinite/*: recursion_self, recursion_macro_mutual; duplicate-definitions:
// duplicate_definition, duplicate_input, duplicate_record_field; hof-arity-mismatch 1-3:
// function_argument_arity; imports-ambiguous: import_ambiguous; include-invalid-escape,
// include-test: include_invalid_escape; inout-in-modules: in_out_in_module;
// interpolated-include: include_interpolated; multiple-definitions-annotation 1-2:
// annotation_defined_twice; namedarg-after-posarg: named_after_positional; object-type-error:
// record_wrong_member; parameterless-lambda: lambda_without_parameters;
// parameterless-without-parens: call_of_a_constant; type-arg-not-inferred:
// type_argument_not_inferable; type-arity-mismatch: type_arguments_too_many;
// types/input-non-stream: type_input_not_events; types/missing-parameter-type:
// missing_parameter_type; types/missing-return-type: missing_recursive_type;
// types/no-subtyping: record_extra_member; types/type-mismatch: type_annotation_mismatch;
// types/unliftable-macro-type: liftable_stream_parameter; undefined-members:
// record_unknown_member; undefined-named-arg: named_unknown_parameter; undefined-type:
// unknown_type; undefined-variable: unknown_stream; unknown-timeunit (a base time of an
// unknown unit): tests/cli/check_cli.rs. annotation-constant-folding is accepted, as by TeSSLa.

/// Specs whose diagnostic must say how to fix them: (spec, text of the help).
const HELPED: &[(&str, &str)] = &[
    (
        "sum_of_floats",
        "help: `sum` is TeSSLa's `def sum(x: Events[Int]): Events[Int]`; for a Float stream \
         write it with `fold`",
    ),
    ("not_liftable_on_stream", "declare `liftable def f(...)`"),
];

/// Bad Telegraf annotations, found by the binding: exit 2 and a message naming the input (the
/// checked program keeps no source position for inputs, so no line and column yet).
const BINDING: &[(&str, &str)] = &[
    ("annotation_bad_tags", "input `speed`: @TelegrafIn tags"),
    (
        "annotation_indexed_not_list",
        "input `lidar`: a `_*` field pattern",
    ),
];

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/broken-specs")
}

fn spec(name: &str) -> String {
    dir().join(format!("{name}.tessla")).display().to_string()
}

/// `check SPEC` and `run --spec SPEC` (empty input): (exit code, stdout + stderr) of each.
fn both(name: &str) -> Vec<(&'static str, Option<i32>, String)> {
    let path = spec(name);
    [
        ("check", vec!["check", path.as_str()]),
        ("run", vec!["run", "--spec", path.as_str()]),
    ]
    .into_iter()
    .map(|(what, args)| {
        let f = child::run_bytes(&args, Vec::new(), Duration::from_secs(60));
        let text = format!("{}{}", f.stdout_text(), f.stderr);
        assert!(!text.contains("panicked"), "{what} {name}: {text}");
        (what, f.code, text)
    })
    .collect()
}

#[test]
fn every_broken_spec_is_listed() {
    let mut listed: Vec<&str> = PLACED.iter().chain(BINDING).map(|(n, _)| *n).collect();
    listed.sort_unstable();
    let mut found: Vec<String> = std::fs::read_dir(dir())
        .unwrap()
        .filter_map(|e| {
            let name = e.unwrap().file_name().into_string().unwrap();
            name.strip_suffix(".tessla").map(str::to_string)
        })
        .collect();
    found.sort_unstable();
    assert_eq!(found, listed);
}

#[test]
fn broken_specs_exit_2_naming_the_place() {
    for (name, place) in PLACED {
        for (what, code, text) in both(name) {
            assert_eq!(code, Some(2), "{what} {name}: {text}");
            assert!(
                text.contains(&format!("broken-specs/{place}")),
                "{what} {name}: no `{place}` in:\n{text}"
            );
            assert!(text.contains("error"), "{what} {name}: {text}");
        }
    }
}

#[test]
fn broken_specs_say_how_to_fix_them() {
    for (name, help) in HELPED {
        for (what, code, text) in both(name) {
            assert_eq!(code, Some(2), "{what} {name}: {text}");
            assert!(
                text.contains(help),
                "{what} {name}: no `{help}` in:\n{text}"
            );
        }
    }
}

#[test]
fn bad_telegraf_annotations_exit_2_naming_the_input() {
    for (name, message) in BINDING {
        for (what, code, text) in both(name) {
            assert_eq!(code, Some(2), "{what} {name}: {text}");
            assert!(text.contains(message), "{what} {name}: {text}");
        }
    }
}

#[test]
fn closed_output_streams_give_an_exit_code_not_a_panic() {
    // Diagnostics (and check's listing) written to pipes nobody reads: `check | head` must not
    // panic (exit 101) when the reader has gone.
    for (name, want) in [("syntax_too_deep", 2), ("../../../specs/robot", 3)] {
        let mut c = std::process::Command::new(BIN)
            .args(["check", &spec(name)])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        drop(c.stdout.take());
        drop(c.stderr.take());
        let start = std::time::Instant::now();
        let status = loop {
            if let Some(s) = c.try_wait().unwrap() {
                break s;
            }
            assert!(start.elapsed() < Duration::from_secs(60), "{name}: no exit");
            std::thread::sleep(Duration::from_millis(10));
        };
        assert_eq!(status.code(), Some(want), "{name}");
    }
}
