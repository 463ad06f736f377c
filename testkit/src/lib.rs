//! Test support shared by fdd's crates (dev-dependency only).
//!
//! [`CountingAllocator`] is a global allocator that counts the heap allocations one thread
//! makes while it is armed. fdd promises that a filter, detector or monitor step allocates
//! nothing; tests prove it by installing the allocator in their test binary and measuring a
//! section of code with [`allocations_in`]:
//!
//! ```ignore
//! #[global_allocator]
//! static GLOBAL: fdd_testkit::CountingAllocator = fdd_testkit::CountingAllocator;
//!
//! assert_eq!(fdd_testkit::allocations_in(|| filter.predict(&u).map(|_| ())), 0);
//! ```
//!
//! Counting is per thread, so tests running in parallel do not see each other's allocations.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// Counts `alloc`, `alloc_zeroed` and `realloc` calls of the armed thread; delegates to the
/// system allocator.
pub struct CountingAllocator;

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<usize> = const { Cell::new(0) };
}

fn note_allocation() {
    // `try_with`: the allocator may be called while this thread's locals are being torn down.
    let _ = ARMED.try_with(|armed| {
        if armed.get() {
            let _ = COUNT.try_with(|c| c.set(c.get() + 1));
        }
    });
}

// SAFETY: every method forwards to `System` with the caller's arguments unchanged; the only
// extra work is a thread-local counter update, which does not allocate.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_allocation();
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

/// Number of heap allocations this thread makes inside `f`. Meaningful only in a test binary
/// whose global allocator is [`CountingAllocator`].
pub fn allocations_in(f: impl FnOnce()) -> usize {
    counted(f).1
}

/// Runs `f` armed and returns its result with the number of allocations it made.
pub fn counted<R>(f: impl FnOnce() -> R) -> (R, usize) {
    COUNT.with(|c| c.set(0));
    ARMED.with(|a| a.set(true));
    let r = f();
    ARMED.with(|a| a.set(false));
    (r, COUNT.with(Cell::get))
}

/// One edit of a byte string, for tests that mutate valid inputs into almost-valid ones:
/// `how` 1 deletes the byte at `at`, 2 inserts `byte` before it, 3 replaces it with `byte`,
/// 4 cuts the input at `at`; anything else (and an `at` past the end for 1 and 3) leaves it.
pub fn mutate(mut bytes: Vec<u8>, how: u8, at: usize, byte: u8) -> Vec<u8> {
    let at = at.min(bytes.len());
    match how {
        1 if at < bytes.len() => {
            bytes.remove(at);
        }
        2 => bytes.insert(at, byte),
        3 if at < bytes.len() => bytes[at] = byte,
        4 => bytes.truncate(at),
        _ => {}
    }
    bytes
}

/// Whether `python3` can import `modules` (e.g. `"mcap.reader, jsonschema"`), for the tests
/// that cross-check fdd's files with the official Python readers. Without them the caller
/// skips its check, except under CI (`CI` set), where their absence fails the test: CI
/// installs them (`.ci/run`), so a skip there would hide a missing check.
pub fn python_modules_available(modules: &str) -> bool {
    let found = std::process::Command::new("python3")
        .args(["-c", &format!("import {modules}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but python3 cannot import {modules} (pip install mcap jsonschema)"
        );
        eprintln!("skipped: python3 cannot import {modules} (pip install mcap jsonschema)");
    }
    found
}
