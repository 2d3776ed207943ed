//! The IR listing (`check --ir`): a loaded spec's nodes in evaluation order, its value code and
//! function table. (Here rather than beside `ir::print`, so the IR's unit tests do not load
//! specs through the front end: no module of the crate reaches back up the pipeline.)

fn listing(spec: &str) -> String {
    let loaded = tessla_engine::load_with(
        "spec.tessla",
        &tessla_syntax::include::MemResolver {
            files: [("spec.tessla".to_string(), spec.to_string())].into(),
        },
        &tessla_engine::LoadOptions::default(),
    );
    let Ok(loaded) = loaded else {
        panic!("spec does not load");
    };
    loaded.program.ir().to_string()
}

#[test]
fn a_program_lists_its_nodes_in_order() {
    let text = listing("in x: Events[Int]\ndef c = x + 1\ndef l = last(c, x)\nout c\nout l");
    assert!(text.starts_with("in  x: Events[Int]\n"), "{text}");
    assert!(text.contains("= input x"), "{text}");
    assert!(text.contains("last(n"), "{text}");
    assert!(text.contains("out c: Events[Int] = n"), "{text}");
}

#[test]
fn value_code_and_the_function_table_are_listed() {
    let text = listing(
        "in x: Events[Int]\ndef f(a: Int): Int = if a > 0 then f(a - 1) + 2 else 0\n\
         def y = slift1(x, f)\ndef s = fold(x, 0, (acc: Int, v: Int) => acc + v * 2)\nout y\nout s",
    );
    // The recursive function calls itself by index; the lambda is a function too.
    assert!(
        text.contains("f0 f/1 = (if ($0 > Int(0)) then (f0(($0 - Int(1))) + Int(2)) else Int(0))"),
        "{text}"
    );
    assert!(
        text.contains("f1 lambda/2 = ($0 + ($1 * Int(2)))"),
        "{text}"
    );
    assert!(text.contains("slift(n0) { f0($0) }"), "{text}");
    assert!(text.contains("fold(n0, Int(0)) { f1($0, $1) }"), "{text}");
    assert!(!text.contains("<fn>"), "{text}");
}

#[test]
fn the_listing_says_how_the_step_runs_and_names_the_calls() {
    let text = listing(
        "in x: Events[Int]\nin p: Events[(Int, Int)]\ndef c = x + 1\ndef e = p == p\nout c\nout e",
    );
    assert!(
        text.ends_with("-- step: the flat plan, one typed instruction per node (no node falls back to the general step)\n"),
        "{text}"
    );
    // `List.size` (a native) has a plan form only as a call, which the general step runs
    // faster, and `delay` has an instruction: the call is named, by node.
    let text = listing(
        "in x: Events[Int]\nin l: Events[List[Int]]\ndef n = List.size(l)\n\
         def d = delay(x, x)\ndef y = x + 1\nout n\nout d\nout y",
    );
    let last = text.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("-- step: the general step, for all 5 nodes: the flat plan would call this node's compiled function"),
        "{text}"
    );
    let named: Vec<&str> = last
        .rsplit_once(": ")
        .map(|(_, names)| names.split(", ").collect())
        .unwrap_or_default();
    assert_eq!(named.len(), 1, "{text}");
    for n in named {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("{n} = ")))
            .unwrap_or_else(|| panic!("{n} is not listed:\n{text}"));
        assert!(line.contains("size"), "{line}");
    }
}
