//! Where the runner's memory comes from: the global allocator (the system's, with every
//! large block advised onto transparent huge pages, `madvise(MADV_HUGEPAGE)`; Linux only,
//! elsewhere the system's as it is) and glibc's parameters ([`tune_glibc`]).
//!
//! From about 100 k particles on, a step allocates its big buffers (neighbour lists, the
//! matrices, the solvers' vectors: about 1 GB a step at a million 2D particles) beyond
//! glibc's mmap threshold, so each step maps them afresh and faults them in 4 KiB at a time
//! (the 1 M-particle dam break: 9.9 M faults in 40 steps, 12 % of its CPU time in the
//! kernel). Advised, they fault in 2 MiB at a time and the solves' scattered reads miss the
//! TLB less (docs/performance.md, "What changed, and what did not help"). Only where memory
//! comes from changes, never a value: the same bits.

use std::alloc::{GlobalAlloc, Layout, System};

/// Sets glibc's allocator parameters; call before any worker thread exists.
///
/// The solver allocates and frees its per-step buffers every step; glibc's default then gives
/// the heap top back to the system and faults the pages in again each step (the 5 mm dam
/// break to 0.1 s: 23.8 k minor faults against 3.1 k, 10 % of its wall time;
/// docs/performance.md). A 64 MiB top pad keeps them. Blocks above glibc's mmap threshold
/// (grown at run time, not past 32 MiB) are mapped and unmapped every step; from 100 k
/// particles on many per-step buffers are that large (the 0.8 mm dam break: 1.6 M faults in
/// 40 steps, 10 % of its CPU time in the kernel). Fixed at its ceiling, with no trim below the
/// top pad's reach, they are kept too.
pub fn tune_glibc() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: sets allocator parameters; the caller runs it before any worker thread exists.
    unsafe {
        libc::mallopt(libc::M_TOP_PAD, 64 << 20);
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
    }
}

/// Blocks from this size on are advised: two huge pages, so that at least one aligned
/// 2 MiB page lies inside.
const ADVISE_FROM_BYTES: usize = 4 << 20;

/// See the module documentation.
pub struct HugePageAlloc;

// SAFETY: every call goes to `System` with the caller's arguments unchanged; the advice only
// flags pages inside the block just returned (madvise never moves or frees memory).
unsafe impl GlobalAlloc for HugePageAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract is `System`'s.
        let block = unsafe { System.alloc(layout) };
        advise(block, layout.size());
        block
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: as above.
        let block = unsafe { System.alloc_zeroed(layout) };
        advise(block, layout.size());
        block
    }

    unsafe fn dealloc(&self, block: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(block, layout) }
    }

    unsafe fn realloc(&self, block: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: as above.
        let moved = unsafe { System.realloc(block, layout, new_size) };
        advise(moved, new_size);
        moved
    }
}

/// Advises the whole pages inside `[block, block + size)` onto huge pages, when the block is
/// large; a refusal (THP off, an old kernel) leaves the block as it was.
fn advise(block: *mut u8, size: usize) {
    #[cfg(target_os = "linux")]
    if !block.is_null() && size >= ADVISE_FROM_BYTES {
        const PAGE: usize = 4096;
        let start = (block as usize).next_multiple_of(PAGE);
        let end = (block as usize + size) / PAGE * PAGE;
        // SAFETY: [start, end) lies inside the block just allocated for the caller, and
        // MADV_HUGEPAGE changes no contents.
        unsafe {
            libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (block, size);
}
