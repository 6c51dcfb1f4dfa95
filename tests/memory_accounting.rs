//! `softshell_*_memory_bytes` against the heap a handle really holds, measured with a counting
//! global allocator (this test binary's own): a review found the shell's bending stencils held
//! 20 bytes each that the figure left out.
#![cfg(all(feature = "shell", feature = "body", feature = "lattice"))]

mod report_util;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::Mutex;
use std::sync::atomic::{AtomicIsize, Ordering};

use report_util::*;
use softshell::ffi::body::*;
use softshell::ffi::shell::*;
use softshell::ffi::{SoftshellBodyDef, SoftshellShellDef};

/// Counts the bytes allocated and not yet freed, by the whole process.
struct Counting;
static LIVE: AtomicIsize = AtomicIsize::new(0);

// SAFETY: forwards every call to the system allocator unchanged; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        LIVE.fetch_add(l.size() as isize, Ordering::SeqCst);
        // SAFETY: the caller's layout, as GlobalAlloc requires.
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        LIVE.fetch_sub(l.size() as isize, Ordering::SeqCst);
        // SAFETY: allocated by `System` through this allocator with layout `l`.
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        LIVE.fetch_add(l.size() as isize, Ordering::SeqCst);
        // SAFETY: as `alloc`.
        unsafe { System.alloc_zeroed(l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        LIVE.fetch_add(n as isize - l.size() as isize, Ordering::SeqCst);
        // SAFETY: as `dealloc`, with the caller's new size.
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static COUNTING: Counting = Counting;

/// The tests run one at a time: the count is the whole process's.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

#[test]
fn the_shell_reports_every_array_it_holds() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (p, t) = unit_obj("sphere.obj", 1.0);
    // One thread (no worker pool) and no collisions (the BVH's size is estimated): every byte
    // the shell holds is then in arrays its figure counts.
    let base = SoftshellShellDef { collisions: false, threads: 1, ..softshell_shell_def_default() };
    for bending in [SOFTSHELL_BENDING_NONE, SOFTSHELL_BENDING_ISOMETRIC, SOFTSHELL_BENDING_ISOMETRIC_REST] {
        let before = LIVE.load(Ordering::SeqCst);
        let shell = Shell::new(&p, &t, &SoftshellShellDef { bending, ..base }).unwrap();
        let held = LIVE.load(Ordering::SeqCst) - before;
        let reported = shell.memory() as isize;
        assert!((held - reported).abs() <= 64, "bending {bending}: holds {held} bytes, reports {reported}");
    }
}

#[test]
fn the_body_reports_what_it_holds_while_stepping() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (p, t) = unit_obj("sphere.obj", 1.0);
    let plain = SoftshellBodyDef { gravity: [0.0; 3], threads: 1, ..softshell_body_def_default() };
    for def in [plain, SoftshellBodyDef { gas_amount: 1.0, ..plain }] {
        let before = LIVE.load(Ordering::SeqCst);
        let body = Body::new(&p, &t, &def).unwrap();
        for step in 0..4 {
            let (reported, held) = (body.memory() as isize, LIVE.load(Ordering::SeqCst) - before);
            assert!(
                (reported - held).abs() <= 1024,
                "gas {} after {step} steps: reports {reported}, holds {held}",
                def.gas_amount
            );
            body.step().unwrap();
        }
    }
}
