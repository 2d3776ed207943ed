//! Compiling a spec frees everything it allocated except the program: scopes and definitions
//! refer to each other through `Rc`s, and each load used to leak its whole name table (found by
//! cargo fuzz's leak checker; it matters for reloading a spec in a long-running process).
//! Checked with a counting global allocator: loading the same spec again and again must not
//! grow the live heap.
//!
//! Recursive functions (and two that call each other) free all they allocated when the program
//! is dropped: a recursive call is a call by index into the program's function table
//! (`Program::functions`), and the compiled closures (`exec`) reach each other only through the
//! context passed to each call, so no reference cycle outlives a load.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::Mutex;
use std::sync::atomic::{AtomicIsize, Ordering};
use tessla_syntax::include::MemResolver;

struct Counting;

static LIVE: AtomicIsize = AtomicIsize::new(0);

// SAFETY: forwards to the system allocator, only counting bytes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LIVE.fetch_add(layout.size() as isize, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size() as isize, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// The tests measure one shared counter: they take turns.
static TURN: Mutex<()> = Mutex::new(());

/// Top-level defs, a function, a module, `where` defs and a block.
const SPEC: &str = "in x: Events[Int]\n\
    def f(n: Int): Int = ${def m = n + 1; m}\n\
    module M {\n  def k = 3\n  def twice(a: Int) = a * k\n}\n\
    def y = x + w where { def w = f(4) }\n\
    def z = ${def q = M.twice(2); q}\n\
    def c = count(x)\n\
    out y\nout z\nout c\n";

fn load() {
    let resolver = MemResolver {
        files: [("s.tessla".to_string(), SPEC.to_string())].into(),
    };
    let loaded = tessla_engine::load_with("s.tessla", &resolver, &Default::default());
    assert!(loaded.is_ok(), "{:?}", loaded.err().map(|e| e.render()));
}

#[test]
fn loading_a_spec_again_and_again_does_not_grow_the_heap() {
    let _turn = TURN.lock().unwrap_or_else(|e| e.into_inner());
    load();
    let before = LIVE.load(Ordering::Relaxed);
    for _ in 0..200 {
        load();
    }
    let grown = LIVE.load(Ordering::Relaxed) - before;
    // Other test threads of this binary may allocate meanwhile: allow a little slack, far
    // below the ~1 KB per load that leaked (200 KB here).
    assert!(
        grown < 16 * 1024,
        "the heap grew by {grown} bytes over 200 loads"
    );
}

const RECURSIVE_SPEC: &str = "in x: Events[Int]\n\
    def fact(n: Int): Int = if n <= 1 then 1 else n * fact(n - 1)\n\
    def even(n: Int): Bool = if n == 0 then true else odd(n - 1)\n\
    def odd(n: Int): Bool = if n == 0 then false else even(n - 1)\n\
    def f = slift1(x, fact)\n\
    def e = slift1(x, even)\n\
    out f\nout e\n";

/// Load the spec, run one step and check the outputs: 5! and whether 5 is even.
fn load_and_run() {
    let resolver = MemResolver {
        files: [("s.tessla".to_string(), RECURSIVE_SPEC.to_string())].into(),
    };
    let loaded = tessla_engine::load_with("s.tessla", &resolver, &Default::default());
    let Ok(loaded) = loaded else {
        panic!("{:?}", loaded.err().map(|e| e.render()));
    };
    let mut m = tessla_engine::Monitor::new(loaded.program);
    let mut outs = Vec::new();
    let mut sink = |e: tessla_engine::OutputEvent<'_>| outs.push(format!("{:?}", e.value));
    assert!(
        m.push(1, 0, tessla_engine::Value::Int(5), &mut sink)
            .is_ok()
    );
    m.flush(&mut sink);
    drop(m);
    assert_eq!(outs, ["Int(120)", "Bool(false)"]);
}

#[test]
fn recursive_functions_do_not_leak() {
    let _turn = TURN.lock().unwrap_or_else(|e| e.into_inner());
    load_and_run();
    let before = LIVE.load(Ordering::Relaxed);
    for _ in 0..200 {
        load_and_run();
    }
    let grown = LIVE.load(Ordering::Relaxed) - before;
    // About 850 bytes per load leaked before (170 KB here).
    assert!(
        grown < 16 * 1024,
        "the heap grew by {grown} bytes over 200 loads"
    );
}
