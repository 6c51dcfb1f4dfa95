//! How the shell runs loops on its own worker pool: independent index ranges (one colour of
//! constraints, one block of vertices) and fixed-chunk reductions, so that results never depend
//! on the thread count.

/// Below this many items a loop runs serially: a rayon split costs more than the work.
pub(crate) const MIN_PARALLEL: usize = 256;
/// Items per chunk of a reduction (fixed: the summation order must not depend on threads).
pub(crate) const REDUCE_CHUNK: usize = 2048;

/// A raw view of a slice that several threads write at disjoint indices.
#[derive(Clone, Copy)]
pub(crate) struct Shared<T> {
    ptr: *mut T,
    len: usize,
}

// SAFETY: `Shared` is only handed to loops whose iterations touch disjoint indices (one colour of
// a graph colouring, or one index per iteration); T itself is sent between threads.
unsafe impl<T: Send> Send for Shared<T> {}
// SAFETY: as above.
unsafe impl<T: Send> Sync for Shared<T> {}

impl<T: Copy> Shared<T> {
    pub(crate) fn new(slice: &mut [T]) -> Self {
        Self { ptr: slice.as_mut_ptr(), len: slice.len() }
    }

    /// Reads element `i`.
    ///
    /// # Safety
    /// No other thread may write element `i` during this loop.
    #[inline(always)]
    pub(crate) unsafe fn get(&self, i: usize) -> T {
        debug_assert!(i < self.len);
        // SAFETY: in bounds (checked in debug builds; indices come from validated meshes) and
        // not written concurrently (the caller's promise).
        unsafe { *self.ptr.add(i) }
    }

    /// Writes element `i`.
    ///
    /// # Safety
    /// No other thread may read or write element `i` during this loop.
    #[inline(always)]
    pub(crate) unsafe fn set(&self, i: usize, value: T) {
        debug_assert!(i < self.len);
        // SAFETY: as in `get`.
        unsafe { *self.ptr.add(i) = value }
    }
}

/// Writes `old + corr` (old = the current `p[i]`) to `p[i]` and adds what the f32 rounding lost
/// to `lo[i]` (Fast2Sum: exact when |old| >= |corr| per component). With many substeps a
/// correction can be smaller than half an ulp of the position; kept in `lo`, it still reaches
/// the velocity and the position (see `State::update_velocities`).
///
/// # Safety
/// No other thread may access element `i` of `p` or `lo` during this loop.
#[inline(always)]
pub(crate) unsafe fn add_compensated(
    p: &Shared<glam::Vec3>,
    lo: &Shared<glam::Vec3>,
    i: usize,
    old: glam::Vec3,
    corr: glam::Vec3,
) {
    let new = old + corr;
    // SAFETY: the caller's promise.
    unsafe {
        p.set(i, new);
        lo.set(i, lo.get(i) + (corr - (new - old)));
    }
}

/// Calls `f(i)` for every `i` in `start..end`, on the current rayon pool when `parallel`.
/// The calls must be independent (they may run in any order).
#[inline]
pub(crate) fn for_range(parallel: bool, start: usize, end: usize, f: impl Fn(usize) + Sync + Send) {
    for_range_min(parallel, start, end, MIN_PARALLEL, f)
}

/// [`for_range`] where each task gets at least `min_len` indices (fewer for indices that each
/// stand for several items, such as a group of four constraints).
#[inline]
pub(crate) fn for_range_min(parallel: bool, start: usize, end: usize, min_len: usize, f: impl Fn(usize) + Sync + Send) {
    #[cfg(feature = "parallel")]
    if parallel && end - start >= 2 * min_len {
        use rayon::prelude::*;
        (start..end).into_par_iter().with_min_len(min_len).for_each(f);
        return;
    }
    let _ = (parallel, min_len);
    for i in start..end {
        f(i);
    }
}

/// Fills `partials[c]` with `f(c·REDUCE_CHUNK .. min(n, (c+1)·REDUCE_CHUNK))` for every chunk c;
/// `partials` must hold `n.div_ceil(REDUCE_CHUNK)` elements. The caller then combines them in
/// index order, so sums are the same for any thread count.
pub(crate) fn chunk_partials<T: Send>(
    parallel: bool,
    n: usize,
    partials: &mut [T],
    f: impl Fn(usize, usize) -> T + Sync + Send,
) {
    debug_assert_eq!(partials.len(), n.div_ceil(REDUCE_CHUNK));
    let run = |c: usize, slot: &mut T| *slot = f(c * REDUCE_CHUNK, ((c + 1) * REDUCE_CHUNK).min(n));
    #[cfg(feature = "parallel")]
    if parallel && partials.len() > 1 {
        use rayon::prelude::*;
        partials.par_iter_mut().enumerate().for_each(|(c, slot)| run(c, slot));
        return;
    }
    let _ = parallel;
    partials.iter_mut().enumerate().for_each(|(c, slot)| run(c, slot));
}
