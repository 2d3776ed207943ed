//! Bad input is normal input: parsing and rendering diagnostics never panic, whatever the text.
//! Seeds are sample specs (and the TeSSLa suite's specs when present), mutated with a fixed-seed
//! generator: deletions, duplications and insertions of characters that steer the lexer into its
//! corners (quotes, interpolation, escapes, comments, multibyte characters, brackets, numbers).

use std::path::{Path, PathBuf};
use tessla_syntax::diag::render;
use tessla_syntax::source::SourceMap;

const SAMPLES: &[&str] = &[
    "in x: Events[Int]\ndef y := x + 1\nout y as z\n",
    "def f(a: Int, b: Float): Float = if a > 0 then b +. 1.5 else -.b\nout f(1, 2.0e3)\n",
    "@raw out f\"v=${x}%05.2f $y\"\nin y: Events[String]\n",
    "def r = {a = 1, b: (2, \"s\\n\"), c = ${d = 3}}\nout r.b._1\n",
    "module M {\n  def x = 100 ms -- c\n}\nimport M\ndef g = (x: Int) => { def q = x; q } where { def w = 1 }\n",
    "def @TelegrafIn(m: String)\n@TelegrafIn(\"cpu\") in u: Events[Unit] # c\nout *\n",
    "liftable def h[T](o: Option[T]): Bool = static if true then isSome(o) else false\n",
];

const TRICKY: &[&str] = &[
    "\"", "$", "${", "{", "}", "(", ")", "[", "]", "\\", "\n", "-", "--", "#", "µ", "€", "1", "0x",
    ".", "e", "%", "f\"", "=>", ":", ",", ";", "@", " ", "ms", "-.", "\t", "\u{0}",
];

/// A fixed-seed generator (ChaCha), so failures reproduce.
struct Rng(rand_chacha::ChaCha8Rng);

impl Rng {
    fn seeded(seed: u64) -> Rng {
        Rng(rand::SeedableRng::seed_from_u64(seed))
    }

    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (rand::RngCore::next_u64(&mut self.0) % n as u64) as usize
        }
    }
}

/// A char boundary of `s` at or before `i`.
fn boundary(s: &str, mut i: usize) -> usize {
    i = i.min(s.len());
    while !s.is_char_boundary(i) {
        i -= 1;
    }
    i
}

fn mutate(rng: &mut Rng, s: &str) -> String {
    let mut s = s.to_string();
    for _ in 0..1 + rng.below(4) {
        let a = boundary(&s, rng.below(s.len() + 1));
        let b = boundary(&s, a + rng.below(8));
        let b = b.max(a);
        match rng.below(3) {
            0 => s.replace_range(a..b, ""),
            1 => {
                let piece = s[a..b].to_string();
                s.insert_str(b, &piece);
            }
            _ => s.insert_str(a, TRICKY[rng.below(TRICKY.len())]),
        }
    }
    s
}

fn suite_specs() -> Vec<PathBuf> {
    let dir = std::env::var_os("TESSLA_SUITE")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/tessla-suite")
        });
    let mut out = Vec::new();
    let mut stack = vec![dir];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "tessla") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

fn check(text: &str) {
    let mut map = SourceMap::new();
    let id = map.add("m.tessla", None, text.to_string());
    let result = std::panic::catch_unwind(|| {
        let (_, diags) = tessla_syntax::parse(&map.get(id).text, id);
        let _ = render(&diags, &map, false);
        for d in &diags {
            let _ = d.one_line(&map);
        }
        let (_, diags) = tessla_syntax::parse_expr(&map.get(id).text, id);
        let _ = render(&diags, &map, false);
    });
    assert!(result.is_ok(), "panicked on input {text:?}");
}

#[test]
fn mutated_specs_never_panic() {
    let mut seeds: Vec<String> = SAMPLES.iter().map(|s| s.to_string()).collect();
    for p in suite_specs() {
        if let Ok(t) = std::fs::read_to_string(p) {
            seeds.push(t);
        }
    }
    let mut rng = Rng::seeded(0x9e37_79b9);
    for seed in &seeds {
        check(seed);
        for _ in 0..60 {
            check(&mutate(&mut rng, seed));
        }
        // Every prefix: unterminated strings, brackets and interpolations at each place.
        let mut i = 0;
        while i < seed.len().min(400) {
            i = boundary(seed, i + 1 + rng.below(3)).max(i + 1);
            check(&seed[..boundary(seed, i)]);
        }
    }
}

/// Inputs the cargo-fuzz `spec` target found (fuzz/, docs/book/src/reliability-record.md): each parses, with an
/// error diagnostic, within a deadline (the first hung the parser: an `include` inside a module).
const FUZZ_FOUND: &[&str] = &[
    "module Foo {\n  ## c\ninclude \"empty\"\n}\n",
    "module Foo {\ninclude \"x\"\n",
];

/// Nesting far past `tessla_syntax::parser::MAX_DEPTH`: each overflowed the stack.
fn too_deep() -> Vec<String> {
    let n = 20_000;
    vec![
        format!("def a = {}1{}\nout a\n", "(".repeat(n), ")".repeat(n)),
        format!("def a = 1{}\nout a\n", " + 1".repeat(n)),
        format!("def a = {}1\nout a\n", "!".repeat(n)),
        format!("def a = {}1{}\n", "${def b = ".repeat(n), "; b}".repeat(n)),
        format!("in x: {}Int{}\n", "Events[".repeat(n), "]".repeat(n)),
        "module a {\n".repeat(n),
        format!("def s = \"{}\"\n", "${\"".repeat(2000)),
    ]
}

#[test]
fn inputs_found_by_fuzzing_terminate_with_a_diagnostic() {
    let texts: Vec<String> = FUZZ_FOUND
        .iter()
        .map(|s| s.to_string())
        .chain(too_deep())
        .collect();
    for text in texts {
        let head: String = text.chars().take(60).collect();
        let (tx, rx) = std::sync::mpsc::channel();
        // The main thread's stack size (8 MiB): the binary parses on its main thread.
        let spawned = std::thread::Builder::new()
            .stack_size(8 << 20)
            .spawn(move || {
                let mut map = SourceMap::new();
                let id = map.add("fuzz.tessla", None, text);
                let (_, diags) = tessla_syntax::parse(&map.get(id).text, id);
                let _ = tx.send((
                    diags.iter().any(|d| d.is_error()),
                    render(&diags, &map, false),
                ));
            });
        assert!(spawned.is_ok());
        let (error, rendered) = rx
            .recv_timeout(std::time::Duration::from_secs(120))
            .unwrap_or_else(|_| panic!("parsing {head:?}... did not finish"));
        assert!(error, "{head:?}");
        assert!(rendered.contains("fuzz.tessla:"), "{head:?}");
    }
}
