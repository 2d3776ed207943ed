//! The type checker: ill-typed specs are compile errors (category Type, with the place and a fix
//! where one is known); well-typed specs with TeSSLa's implicit lift, constants as streams,
//! generic functions, macros and recursion through `last` load.

use tessla_engine::LoadOptions;
use tessla_syntax::diag::Category;
use tessla_syntax::include::MemResolver;

fn load(spec: &str) -> Result<(), (Vec<Category>, String)> {
    let resolver = MemResolver {
        files: [("spec.tessla".to_string(), spec.to_string())].into(),
    };
    let options = LoadOptions {
        base_time: Some("1 ms".into()),
        ..LoadOptions::default()
    };
    match tessla_engine::load_with("spec.tessla", &resolver, &options) {
        Ok(_) => Ok(()),
        Err(e) => Err((
            e.diagnostics.iter().map(|d| d.category).collect(),
            e.render(),
        )),
    }
}

/// `spec` is rejected with a type error whose rendering contains every string of `wanted`.
#[track_caller]
fn rejects(spec: &str, wanted: &[&str]) {
    match load(spec) {
        Ok(()) => panic!("accepted an ill-typed spec:\n{spec}"),
        Err((cats, text)) => {
            assert!(cats.contains(&Category::Type), "{cats:?}: {text}");
            for w in wanted {
                assert!(text.contains(w), "missing {w:?} in:\n{text}");
            }
        }
    }
}

const INPUTS: &str = "in x: Events[Int]\nin f: Events[Float]\nin s: Events[String]\n";

#[test]
fn if_condition_must_be_bool() {
    rejects(
        &format!("{INPUTS}def c = if x then 1 else 2\nout c\n"),
        &[
            "condition of `if`",
            "expected Bool",
            "spec.tessla:4:12",
            "^",
        ],
    );
}

#[test]
fn if_branches_must_agree() {
    rejects(
        &format!("{INPUTS}def c = if x > 0 then 1 else \"a\"\nout c\n"),
        &["branches of `if`", "Int and String"],
    );
}

#[test]
fn int_operators_take_ints() {
    rejects(
        &format!("{INPUTS}out x + s\n"),
        &["operand of `+`", "expected Int"],
    );
    rejects(
        &format!("{INPUTS}out f + 1.0\n"),
        &["not defined for Float", "use `+.`"],
    );
    rejects(&format!("{INPUTS}out x +. 1.0\n"), &["intToFloat"]);
}

#[test]
fn declared_parameter_types_are_checked() {
    rejects(
        &format!("{INPUTS}def g(a: Int): Int = a * 2\nout g(f)\n"),
        &[
            "argument 1 of `g`",
            "expected Int, found Events[Float]",
            "floatToInt",
        ],
    );
    rejects(
        &format!("{INPUTS}def g(a: Int, b: Int) = a\nout g(x)\n"),
        &["takes 2 arguments, 1 given"],
    );
}

#[test]
fn declared_def_types_are_checked() {
    rejects(
        &format!("{INPUTS}def b: Events[Bool] = x + 1\nout b\n"),
        &["declared type", "expected Events[Bool], found Events[Int]"],
    );
}

#[test]
fn functions_are_not_outputs() {
    rejects(
        &format!("{INPUTS}def h(a: Int) = a\nout h\n"),
        &["function cannot be an output"],
    );
}

#[test]
fn builtin_arguments_are_checked() {
    rejects(
        &format!("{INPUTS}out filter(x, x)\n"),
        &["argument 2 of `filter`"],
    );
    rejects(
        &format!("{INPUTS}out fold(x, 0.0, (a: Float, b: Int) => a +. b)\n"),
        &["operand of `+.`"],
    );
    rejects(
        &format!("{INPUTS}out last(x, s) +. 1.0\n"),
        &["expected Float"],
    );
    rejects(&format!("{INPUTS}out String.concat(s, x)\n"), &["toString"]);
    rejects(
        &format!("{INPUTS}out lift(x, (a: Option[Int], b: Option[Int]) => b)\n"),
        &["takes 2 arguments"],
    );
}

#[test]
fn records_and_tuples_are_checked() {
    rejects(
        &format!("{INPUTS}out {{a = x, b = 2}}.c\n"),
        &["no field `c`", "`a`, `b`"],
    );
    rejects(
        &format!("{INPUTS}out (x, s)._1 == s\n"),
        &["compares values of one type"],
    );
}

#[test]
fn unknown_type_names_are_reported_with_the_nearest_known() {
    rejects(
        "in x: Events[Integer]\nout x\n",
        &[
            "unknown type `Integer`",
            "spec.tessla:1:14",
            "did you mean `Int`?",
        ],
    );
    rejects(
        "type Pose = {x: Float, y: Float}\nin p: Events[Pos]\nout p\n",
        &["unknown type `Pos`", "did you mean `Pose`?"],
    );
    // Declared types (in modules too), type parameters and those of an enclosing def are known.
    let ok = "module Geo {\n  type Pose = {x: Float, y: Float}\n}\n\
              in p: Events[Pose]\n\
              def wrap[A](a: A): Option[A] = {\n  def inner(b: A): Option[A] = Some(b)\n  inner(a)\n}\n\
              def lam[T](t: T) = ((u: Option[T]) => u)(Some(t))\n\
              out p\nout wrap(1) as w\nout lam(2) as l\n";
    assert_eq!(load(ok).map_err(|e| e.1), Ok(()));
}

#[test]
fn well_typed_specs_load() {
    let ok = [
        // Signal lift of operators, constants as streams, if on streams.
        "in a: Events[Float]\nin b: Events[Float]\ndef d = a -. b\nout if d >. 0.1 then a else b\n",
        // A generic function used at two types; a liftable function on streams.
        "in x: Events[Int]\nin s: Events[String]\ndef id[T](v: T): T = v\n\
         liftable def twice(v: Int): Int = v * 2\nout id(x) + twice(x)\nout id(s)\n",
        // A macro with a stream parameter given a constant.
        "def m(e: Events[Int]) = last(e, e)\nout m(5)\n",
        // Recursion through `last`.
        "in a: Events[Int]\ndef x: Events[Int] := last(z, a)\ndef z := default(x, 0) + a\nout z\n",
        // Tuples are records `_1`, `_2`; fold with a lambda; Options; lists.
        "in a: Events[Int]\ndef p = (a, 1)\nout p._1 + p._2\n\
         out fold(a, 0, (acc: Int, v: Int) => acc + v)\n\
         out getSomeOrElse(Some(a), 0)\nout List.size(List.append(List.empty[Int], a))\n",
        // A parameterless function is called when output.
        "def foo() = 42\nout foo\n",
        // Time literals are Ints.
        "in a: Events[Int]\nout delay(const(100ms, a), a)\n",
    ];
    for spec in ok {
        if let Err((_, text)) = load(spec) {
            panic!("rejected a well-typed spec:\n{spec}\n{text}");
        }
    }
}
