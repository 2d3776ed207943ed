//! Compiling a spec frees everything it allocated except the program: scopes and definitions
//! refer to each other through `Rc`s, and each load used to leak its whole name table (found by
//! cargo fuzz's leak checker; it matters for reloading a spec in a long-running process).
//! Checked with a counting global allocator: loading the same spec again and again must not
//! grow the live heap.

use std::alloc::{GlobalAlloc, Layout, System};
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

/// Top-level defs, a function, a module, `where` defs and a block. (Recursive functions:
/// `no_leak_recursive.rs`.)
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
