//! `include` loading: order, each file once, loops, missing files, `.tessla` completion, and
//! file-system paths relative to the including file.

use tessla_syntax::diag::Category;
use tessla_syntax::include::{FsResolver, MemResolver, load_spec};
use tessla_syntax::source::SourceMap;

fn mem(files: &[(&str, &str)]) -> MemResolver {
    let mut r = MemResolver::default();
    for (n, t) in files {
        r.files.insert((*n).to_string(), (*t).to_string());
    }
    r
}

fn names(
    map: &SourceMap,
    files: &[(tessla_syntax::source::FileId, tessla_syntax::ast::File)],
) -> Vec<String> {
    files
        .iter()
        .map(|(id, _)| map.get(*id).name.clone())
        .collect()
}

#[test]
fn included_files_come_first_and_once() {
    let r = mem(&[
        ("main", "include \"a\"\ninclude \"b\"\nout 1"),
        ("a", "include \"c\"\ndef a = 1"),
        ("b", "include \"c\"\ndef b = 2"),
        ("c", "def c = 3"),
    ]);
    let mut map = SourceMap::new();
    let files = load_spec("main", &r, &mut map).unwrap();
    assert_eq!(names(&map, &files), ["c", "a", "b", "main"]);
}

#[test]
fn a_missing_name_is_tried_with_the_tessla_extension() {
    let r = mem(&[
        ("main", "include \"lib\"\nout 1"),
        ("lib.tessla", "def x = 1"),
    ]);
    let mut map = SourceMap::new();
    let files = load_spec("main", &r, &mut map).unwrap();
    assert_eq!(names(&map, &files), ["lib.tessla", "main"]);
}

#[test]
fn loops_and_missing_files_are_reported_at_the_include() {
    let r = mem(&[
        ("main", "include \"a\"\ninclude \"nothere\"\nout 1"),
        ("a", "include \"main\""),
    ]);
    let mut map = SourceMap::new();
    let diags = load_spec("main", &r, &mut map).unwrap_err();
    assert_eq!(diags.len(), 2, "{diags:?}");
    let looped = diags
        .iter()
        .find(|d| d.category == Category::Recursion)
        .unwrap();
    assert!(
        looped.message.contains("include loop"),
        "{}",
        looped.message
    );
    let span = looped.span.unwrap();
    assert_eq!(map.get(span.file).name, "a");
    let missing = diags.iter().find(|d| d.category == Category::Name).unwrap();
    assert!(missing.message.contains("nothere"), "{}", missing.message);
    let span = missing.span.unwrap();
    assert_eq!(map.get(span.file).name, "main");
    assert_eq!(
        &map.get(span.file).text[span.start as usize..span.end as usize],
        "include \"nothere\""
    );
}

#[test]
fn syntax_errors_of_included_files_are_returned() {
    let r = mem(&[("main", "include \"a\"\nout 1"), ("a", "def = 1")]);
    let mut map = SourceMap::new();
    let diags = load_spec("main", &r, &mut map).unwrap_err();
    assert!(diags.iter().any(|d| d.category == Category::Syntax));
}

#[test]
fn file_includes_are_relative_to_the_including_file() {
    let dir = std::env::temp_dir().join(format!("tessla-include-test-{}", std::process::id()));
    let sub = dir.join("sub");
    std::fs::create_dir_all(&sub).unwrap();
    std::fs::write(dir.join("main.tessla"), "include \"sub/lib.tessla\"\nout 1").unwrap();
    std::fs::write(sub.join("lib.tessla"), "include \"../common\"\ndef x = 1").unwrap();
    std::fs::write(dir.join("common.tessla"), "def y = 2").unwrap();
    // `./loop.tessla` names the file itself: a loop, not endless recursion.
    std::fs::write(dir.join("loop.tessla"), "include \"./loop.tessla\"\nout 1").unwrap();

    let mut map = SourceMap::new();
    let main = dir.join("main.tessla");
    let files = load_spec(&main.display().to_string(), &FsResolver, &mut map).unwrap();
    let got = names(&map, &files);
    assert_eq!(got.len(), 3);
    assert!(
        got[0].ends_with("common.tessla") && !got[0].contains(".."),
        "{got:?}"
    );
    assert!(got[1].ends_with("lib.tessla"), "{got:?}");

    let mut map = SourceMap::new();
    let looped = dir.join("loop.tessla");
    let diags = load_spec(&looped.display().to_string(), &FsResolver, &mut map).unwrap_err();
    assert!(
        diags.iter().any(|d| d.category == Category::Recursion),
        "{diags:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
