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

/// `spec` is rejected with an error of category `cat` whose rendering contains every string of
/// `wanted`.
#[track_caller]
fn rejects_as(spec: &str, cat: Category, wanted: &[&str]) {
    match load(spec) {
        Ok(()) => panic!("accepted a spec TeSSLa rejects:\n{spec}"),
        Err((cats, text)) => {
            assert!(cats.contains(&cat), "{cats:?}: {text}");
            for w in wanted {
                assert!(text.contains(w), "missing {w:?} in:\n{text}");
            }
        }
    }
}

#[test]
fn every_expression_is_checked_in_nested_and_unused_definitions() {
    // A field of an Int parameter, inside a function nested in a function.
    rejects(
        "in s: Events[Int]\ndef f(x: Int) = {\n  def g(a: Int): Int = a + x.foo\n  g(1)\n}\n\
         out slift1(s, (v: Int) => f(v)) as y\n",
        &["Int has no field `foo`", "3:30"],
    );
    // A local definition nothing uses, in a block and in a `where` clause.
    rejects(
        "in x: Events[Int]\ndef y = {\n  def unused: Events[Float] = x -. 1.0\n  x\n}\nout y\n",
        &["operand of `-.`"],
    );
    rejects(
        "in x: Events[Int]\ndef y := x where {\n  def unused := x && true\n}\nout y\n",
        &["operand of `&&`"],
    );
    rejects_as(
        "in x: Events[Int]\ndef y = {\n  def unused = x + nope\n  x\n}\nout y\n",
        Category::Name,
        &["unknown name `nope`"],
    );
}

#[test]
fn recursion_needs_a_written_type_somewhere_on_its_cycle() {
    // No type on the cycle: TeSSLa cannot order the inference.
    rejects_as(
        "in x: Events[Int]\ndef c = default(last(c, x) + 1, 0)\nout c\n",
        Category::Recursion,
        &[
            "`c` is defined recursively and needs a type",
            "2:5",
            "def c: Events[Int] = ...",
        ],
    );
    rejects_as(
        "def fact(n: Int) = if n < 2 then 1 else n * fact(n - 1)\nout fact(5) as f\n",
        Category::Recursion,
        &["`fact` is defined recursively", "def fact(...): Int = ..."],
    );
    // One written type on the cycle is enough, wherever the inference starts.
    let ok = [
        "in x: Events[Int]\ndef a = default(last(b, x), 0) + x\ndef b: Events[Int] = a + 1\nout a\n",
        "in x: Events[Int]\ndef b: Events[Int] = a + 1\ndef a = default(last(b, x), 0) + x\nout b\n",
        "def fact(n: Int): Int = if n < 2 then 1 else n * fact(n - 1)\nout fact(5) as f\n",
        // A member of a tuple literal read inside the tuple itself is no recursion.
        "in v: Events[Int]\ndef p = (v, p._1 + 1)\nout p._2 as q\n",
    ];
    for spec in ok {
        if let Err((_, text)) = load(spec) {
            panic!("rejected a spec TeSSLa accepts:\n{spec}\n{text}");
        }
    }
}

#[test]
fn recursion_through_last_inside_function_bodies_loads() {
    let ok = [
        // The stream handed to `last` as a parameter of a helper.
        "in a: Events[Int]\ndef prev(s: Events[Int], t: Events[Int]): Events[Int] = last(s, t)\n\
         def st: Events[Int] = default(slift3(prev(st, a), a, a, (s: Int, p: Int, q: Int) => s + p - q), 0)\n\
         out st\n",
        // A nested helper in a monitor function, the step lifted with `slift3`.
        "in a: Events[Int]\ndef step(s: Int, p: Int, q: Int): Int = s + p + q\n\
         def mon(x: Events[Int]): Events[Int] = {\n\
           def before(v: Events[Int]): Events[Int] = last(v, x)\n\
           def n: Events[Int] = default(slift3(before(n), x, x, step), 0)\n\
           n\n}\nout mon(a) as m\n",
    ];
    for spec in ok {
        if let Err((_, text)) = load(spec) {
            panic!("rejected a spec TeSSLa accepts:\n{spec}\n{text}");
        }
    }
    // Through a helper that does not `last`: still a recursion without `last`.
    rejects_as(
        "in a: Events[Int]\ndef id(s: Events[Int]): Events[Int] = s\n\
         def st: Events[Int] = merge(id(st) + 1, a)\nout st\n",
        Category::Recursion,
        &["`st` is defined in terms of itself"],
    );
}
