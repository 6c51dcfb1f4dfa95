//! Each handle's own worker threads.
//!
//! A handle owns a rayon pool sized by its def's `threads` (0 = all cores, 1 = none), so the
//! host's global rayon pool is never touched and two handles never contend for one pool. Work is
//! split in fixed chunks that do not depend on the thread count, and every reduction runs in a
//! fixed order, so results are bit-identical whatever `threads` is. Without the `parallel`
//! feature every pool is serial.
//!
//! A loop of many short passes (the iterations of a solver) runs as one parallel region on a
//! [`Team`] of threads ([`WorkerPool::team`]; called from outside the pool, the caller's thread
//! is its first member and the pool's workers the others): the members claim fixed chunks
//! ([`Team::claim`]), meet at barriers ([`Team::barrier`]: spinning, then asleep) and share the
//! arrays of the passes through [`SharedSlice`] (each member writes only the chunks it claimed in
//! a pass), so a pass costs a barrier (well under a microsecond on idle cores) instead of a fork
//! and join (tens of microseconds when a worker has to be woken). When another process holds a
//! core, a [`TeamSizer`] gives the runs of a team one member for a while.

use std::marker::PhantomData;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};

use crate::error::{Error, Result};

/// A handle's worker threads (none when serial).
pub struct WorkerPool {
    #[cfg(feature = "parallel")]
    pool: Option<rayon::ThreadPool>,
    /// The workers, spawned by us rather than by rayon so that freeing the handle waits for them
    /// to end: rayon's own threads outlive their pool for a moment, and a host that frees its
    /// handles and exits then showed their stacks as "possibly lost" under valgrind (a review of
    /// the C examples with `-t 2`).
    #[cfg(feature = "parallel")]
    workers: Vec<std::thread::JoinHandle<()>>,
    threads: usize,
}

#[cfg(feature = "parallel")]
impl Drop for WorkerPool {
    fn drop(&mut self) {
        // Dropping the pool tells its workers to finish; then wait for them. Not from a rayon
        // worker (the pool dropped inside some pool's task): a worker cannot wait for itself,
        // and the others end on their own as before.
        drop(self.pool.take());
        if rayon::current_thread_index().is_none() {
            for worker in self.workers.drain(..) {
                let _ = worker.join();
            }
        }
    }
}

impl std::fmt::Debug for WorkerPool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "WorkerPool({} threads)", self.threads)
    }
}

impl WorkerPool {
    /// A pool of `threads` workers: 0 means one per core, 1 means run on the caller's thread.
    /// Asking for more than 256 threads is an error. Without the `parallel` feature the pool is
    /// always serial.
    pub fn new(threads: u32) -> Result<Self> {
        if threads > 256 {
            return Err(Error::invalid_argument(format!("`threads` = {threads} is more than 256")));
        }
        #[cfg(feature = "parallel")]
        {
            let wanted = if threads == 0 {
                std::thread::available_parallelism().map_or(1, |n| n.get())
            } else {
                threads as usize
            };
            if wanted <= 1 {
                return Ok(Self { pool: None, workers: Vec::new(), threads: 1 });
            }
            let mut workers = Vec::with_capacity(wanted);
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(wanted)
                .thread_name(|i| format!("softshell-{i}"))
                .spawn_handler(|worker| {
                    let mut builder = std::thread::Builder::new();
                    if let Some(name) = worker.name() {
                        builder = builder.name(name.to_owned());
                    }
                    if let Some(size) = worker.stack_size() {
                        builder = builder.stack_size(size);
                    }
                    workers.push(builder.spawn(|| worker.run())?);
                    Ok(())
                })
                .build()
                .map_err(|e| {
                    Error::new(crate::error::ErrorKind::Internal, format!("cannot start {wanted} worker threads: {e}"))
                })?;
            Ok(Self { pool: Some(pool), workers, threads: wanted })
        }
        #[cfg(not(feature = "parallel"))]
        {
            let _ = threads;
            Ok(Self { threads: 1 })
        }
    }

    /// Number of threads that run work (1 when serial).
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// Runs `f` inside the pool, so rayon calls in it use these workers (on the caller's thread
    /// when serial). A panic in a worker comes back out of this call.
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        #[cfg(feature = "parallel")]
        if let Some(pool) = &self.pool {
            return pool.install(f);
        }
        f()
    }

    /// Runs `a` and `b`, at the same time when the pool has workers; returns both results.
    pub fn join<A: Send, B: Send>(&self, a: impl FnOnce() -> A + Send, b: impl FnOnce() -> B + Send) -> (A, B) {
        #[cfg(feature = "parallel")]
        if self.pool.is_some() {
            return self.install(|| rayon::join(a, b));
        }
        (a(), b())
    }

    /// Calls `f(chunk_index, chunk)` for consecutive chunks of `chunk_len` elements of `data`, in
    /// parallel when the pool has workers. The chunking does not depend on the thread count.
    pub fn for_each_chunk_mut<T: Send>(
        &self,
        data: &mut [T],
        chunk_len: usize,
        f: impl Fn(usize, &mut [T]) + Sync + Send,
    ) {
        let chunk_len = chunk_len.max(1);
        #[cfg(feature = "parallel")]
        if self.pool.is_some() && data.len() > chunk_len {
            use rayon::prelude::*;
            return self.install(|| data.par_chunks_mut(chunk_len).enumerate().for_each(|(i, c)| f(i, c)));
        }
        data.chunks_mut(chunk_len).enumerate().for_each(|(i, c)| f(i, c));
    }

    /// Calls `f(task)` for every task, in parallel when the pool has workers. The tasks are made
    /// by the caller (for example disjoint sub-slices of several arrays), so how the work is split
    /// never depends on the thread count.
    pub fn for_each_task<T: Send>(&self, tasks: &mut [T], f: impl Fn(&mut T) + Sync + Send) {
        #[cfg(feature = "parallel")]
        if self.pool.is_some() && tasks.len() > 1 {
            use rayon::prelude::*;
            return self.install(|| tasks.par_iter_mut().for_each(&f));
        }
        tasks.iter_mut().for_each(f);
    }

    /// `(0..n).map(f).collect()`, in parallel when the pool has workers; the order of the result
    /// is always `0..n`.
    pub fn map_collect<R: Send>(&self, n: usize, f: impl Fn(usize) -> R + Sync + Send) -> Vec<R> {
        #[cfg(feature = "parallel")]
        if self.pool.is_some() {
            use rayon::prelude::*;
            return self.install(|| (0..n).into_par_iter().map(&f).collect());
        }
        (0..n).map(f).collect()
    }

    /// Runs `f` once on every thread of the pool at the same time (on the caller's thread alone
    /// when serial; called from a thread outside the pool, on that thread as member 0 and on
    /// workers of the pool as the others, one worker then idle), each call with its own [`Team`]
    /// member (index `0..size`), and returns member 0's result. Not from inside a team of the
    /// same pool (its members would wait for workers that are all in the outer team). The
    /// members share work by [`Team::share`] and meet at [`Team::barrier`], so a
    /// loop of many short parallel passes (the iterations of a solver) is one parallel region
    /// instead of a fork and join per pass. Every member must reach the same barriers. A panic in
    /// one member makes the others' barriers panic too (nobody waits forever), and comes back out
    /// of this call.
    pub fn team<R: Send>(&self, f: impl Fn(&Team) -> R + Sync) -> R {
        self.team_of(self.threads, f).0
    }

    /// [`WorkerPool::team`] with `members` members (at least one, at most the pool's threads;
    /// one runs on the caller's thread alone), and what its barriers saw ([`TeamStats`]).
    pub fn team_of<R: Send>(&self, members: usize, f: impl Fn(&Team) -> R + Sync) -> (R, TeamStats) {
        #[cfg(feature = "parallel")]
        if let (Some(pool), true) = (&self.pool, members > 1 && self.threads > 1) {
            let members = members.min(self.threads);
            let sync = TeamSync::new(members);
            let run = |index: usize| {
                let member = Team::new(index, members, &sync);
                match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| f(&member))) {
                    Ok(result) => {
                        // Each member's counts once, at the end (no shared counter per barrier).
                        if index == 0 {
                            sync.barriers.store(member.barriers.get(), Ordering::Relaxed);
                        }
                        sync.long_waits.fetch_add(member.long_waits.get(), Ordering::Relaxed);
                        result
                    }
                    Err(panic) => {
                        sync.poisoned.store(true, Ordering::SeqCst);
                        sync.wake_sleepers();
                        std::panic::resume_unwind(panic)
                    }
                }
            };
            let result = if pool.current_thread_index().is_none() {
                // Called from outside the pool: this thread is member 0 and the others are
                // spawned into the pool, instead of handing the whole region to a worker and
                // sleeping until it is over (woken at the end: see `Body::step`). It starts at
                // once; a member that a sleeping worker starts late leaves its share of the first
                // pass to the others (`Team::claim`).
                let done = AtomicUsize::new(0);
                let mut result = None;
                pool.in_place_scope(|scope| {
                    for index in 1..members {
                        let (run, done) = (&run, &done);
                        scope.spawn(move |_| {
                            let _ = run(index);
                            done.fetch_add(1, Ordering::Release);
                        });
                    }
                    result = Some(run(0));
                    // The others are a moment behind (their last pass): waiting here for them
                    // keeps the scope's own wait, which sleeps, from making this thread sleep and
                    // be woken again.
                    spin_until(std::time::Instant::now(), || done.load(Ordering::Acquire) + 1 >= members);
                });
                result.expect("member 0 ran")
            } else {
                // Threads past the team's members take no part (but the call returns only when
                // each has run its empty part).
                let mut results =
                    pool.install(|| pool.broadcast(|ctx| (ctx.index() < members).then(|| run(ctx.index()))));
                results.swap_remove(0).expect("member 0 runs")
            };
            let stats = TeamStats {
                members,
                barriers: sync.barriers.load(Ordering::Relaxed),
                long_waits: sync.long_waits.load(Ordering::Relaxed),
            };
            return (result, stats);
        }
        let _ = members;
        let sync = TeamSync::new(1);
        let result = f(&Team::new(0, 1, &sync));
        (result, TeamStats { members: 1, ..TeamStats::default() })
    }

    /// Heap bytes attributed to the pool (its threads' stacks are not counted).
    pub fn memory_bytes(&self) -> usize {
        #[cfg(feature = "parallel")]
        if self.pool.is_some() {
            return std::mem::size_of::<rayon::ThreadPool>();
        }
        0
    }
}

/// What a team's barriers saw ([`WorkerPool::team_of`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TeamStats {
    /// Members in the team.
    pub members: usize,
    /// Barriers passed (by all members).
    pub barriers: usize,
    /// Waits in a barrier of [`LONG_WAIT`] or more, over all members: another member's thread
    /// was off its core (the team's own uneven passes wait far less; on the issue-5 balloon
    /// with two members, 0.45 such waits a step of 49 barriers, and 21 with a busy loop on the
    /// second core).
    pub long_waits: usize,
}

/// Chooses the members of a sequence of team runs (the steps of a simulation): all the pool's
/// threads, unless a run had more [long waits](TeamStats::long_waits) than a quarter of its
/// barriers. Then another process holds one of the cores, and a team that meets there waits for
/// it again and again:
/// the issue-5 balloon with a busy loop on the second of two cores took 8.7 ms a step with two
/// members spinning at each barrier, 5.5 ms with them sleeping there, and 3.4 ms with one
/// member. The next 4 runs then get one member, and the one after probes with all again; each
/// probe that finds the core still busy doubles the wait (up to 64 runs). Results do not depend
/// on the members (see [`Team::claim`]), so only the time changes. On a busy shared machine
/// (another tenant's load, not a busy loop of ours) the issue-5 balloon's bodies without it (two
/// members whatever the waits) took 1-13% longer a step (four runs, two bodies stepped in turn).
#[derive(Clone, Copy, Debug, Default)]
pub struct TeamSizer {
    alone_left: u32,
    backoff: u32,
}

impl TeamSizer {
    const FIRST_BACKOFF: u32 = 4;
    const LONGEST_BACKOFF: u32 = 64;

    /// The members of the next run, with `threads` available.
    pub fn members(&mut self, threads: usize) -> usize {
        if self.alone_left > 0 {
            self.alone_left -= 1;
            1
        } else {
            threads
        }
    }

    /// The next `runs` runs with one member (as after a contended run).
    #[cfg(test)]
    pub fn alone_for(&mut self, runs: u32) {
        self.alone_left = runs;
    }

    /// What the last run's barriers saw.
    pub fn record(&mut self, stats: TeamStats) {
        if stats.members < 2 {
            return;
        }
        if 4 * stats.long_waits > stats.barriers {
            self.backoff = (2 * self.backoff).clamp(Self::FIRST_BACKOFF, Self::LONGEST_BACKOFF);
            self.alone_left = self.backoff;
        } else {
            self.backoff = 0;
        }
    }
}

/// The meeting point of a team: a sense-reversing barrier (a counter and a generation, and a
/// condition variable for members that stopped spinning), and per member the next unclaimed
/// item of its share in the current pass ([`Team::claim`]).
struct TeamSync {
    size: usize,
    arrived: Padded<AtomicUsize>,
    generation: Padded<AtomicUsize>,
    poisoned: AtomicBool,
    /// Members asleep in [`Team::barrier`] (the last to arrive wakes them only if there are).
    sleepers: Padded<AtomicUsize>,
    /// Barriers passed, and long waits in them ([`TeamStats`]), added by the members at the end
    /// (read only by a team of several threads).
    #[cfg_attr(not(feature = "parallel"), allow(dead_code))]
    barriers: AtomicUsize,
    #[cfg_attr(not(feature = "parallel"), allow(dead_code))]
    long_waits: AtomicUsize,
    park: std::sync::Mutex<()>,
    wake: std::sync::Condvar,
    /// Per member: `pass << 32 | next item`.
    claims: Claims,
}

/// Teams of up to this many members keep their claim counters inline (a team is made per
/// solve, and a vector was an allocation per step).
const INLINE_MEMBERS: usize = 4;

/// The members' claim counters ([`TeamSync::claims`]). (Its inline variant is the larger by
/// design: it lives on the stack of [`WorkerPool::team_of`] for one region.)
#[allow(clippy::large_enum_variant)]
enum Claims {
    Inline([Padded<AtomicU64>; INLINE_MEMBERS]),
    Heap(Vec<Padded<AtomicU64>>),
}

impl std::ops::Index<usize> for Claims {
    type Output = Padded<AtomicU64>;
    fn index(&self, member: usize) -> &Padded<AtomicU64> {
        match self {
            Claims::Inline(claims) => &claims[member],
            Claims::Heap(claims) => &claims[member],
        }
    }
}

/// A value alone on its cache lines (members spinning on one do not slow the others' writes).
#[repr(align(128))]
struct Padded<T>(T);

impl TeamSync {
    fn new(size: usize) -> Self {
        Self {
            size,
            arrived: Padded(AtomicUsize::new(0)),
            generation: Padded(AtomicUsize::new(0)),
            poisoned: AtomicBool::new(false),
            sleepers: Padded(AtomicUsize::new(0)),
            barriers: AtomicUsize::new(0),
            long_waits: AtomicUsize::new(0),
            park: std::sync::Mutex::new(()),
            wake: std::sync::Condvar::new(),
            claims: if size <= INLINE_MEMBERS {
                Claims::Inline(std::array::from_fn(|_| Padded(AtomicU64::new(0))))
            } else {
                Claims::Heap((0..size).map(|_| Padded(AtomicU64::new(0))).collect())
            },
        }
    }

    /// Wakes the members asleep in a barrier, if any (after the generation moved on or the
    /// team was poisoned: both are stored before this, sequentially consistent, and a sleeper
    /// counts itself before it looks at them, so one of the two sees the other).
    fn wake_sleepers(&self) {
        if self.sleepers.0.load(Ordering::SeqCst) > 0 {
            let _guard = self.park.lock().unwrap_or_else(|e| e.into_inner());
            self.wake.notify_all();
        }
    }
}

/// How long a waiting member spins before it sleeps: a barrier of a solver iteration is usually
/// passed within microseconds, but when another member's thread was descheduled (a shared
/// machine, or more members than cores) the waiting member must give its core away, so that
/// the scheduler can move the descheduled member there. Yielding the core instead kept it busy
/// (nothing else is queued on it) while the descheduled member waited for its own. On the
/// issue-5 balloon (benches/body_balloon.rs, 2 threads, a busy machine; one body, the spin
/// switched every other step) 5 µs took the step about 5% longer; 60, 100 and 200 µs were within
/// ±1% of this.
const SPIN_BEFORE_SLEEP: std::time::Duration = std::time::Duration::from_micros(20);

/// A wait in a barrier this long means another member's thread was off its core ([`TeamStats`]).
const LONG_WAIT: std::time::Duration = std::time::Duration::from_micros(100);

/// The longest a sleeping member waits before it looks again (a safety net: the last member
/// to arrive wakes the sleepers).
const SLEEP_LIMIT: std::time::Duration = std::time::Duration::from_millis(2);

/// One member of a team running a closure on threads of a pool ([`WorkerPool::team`],
/// [`WorkerPool::team_of`]).
pub struct Team<'a> {
    index: usize,
    size: usize,
    sync: &'a TeamSync,
    /// Passes of [`Team::claim`] so far (the same on every member).
    passes: std::cell::Cell<u32>,
    /// Barriers passed, and this member's long waits in them ([`TeamStats`]).
    barriers: std::cell::Cell<usize>,
    long_waits: std::cell::Cell<usize>,
}

impl<'a> Team<'a> {
    fn new(index: usize, size: usize, sync: &'a TeamSync) -> Self {
        use std::cell::Cell;
        Team { index, size, sync, passes: Cell::new(0), barriers: Cell::new(0), long_waits: Cell::new(0) }
    }
}

impl Team<'_> {
    /// This member's index, `0..size()`.
    pub fn index(&self) -> usize {
        self.index
    }

    /// Members in the team (the pool's threads, or fewer with [`WorkerPool::team_of`]; 1 when
    /// serial).
    pub fn size(&self) -> usize {
        self.size
    }

    /// This member's share of `count` items (chunks): consecutive blocks in member order, fixed
    /// for a given team size, so each member keeps the same data in its cache from pass to pass.
    pub fn share(&self, count: usize) -> Range<usize> {
        Self::share_of(self.index, self.size, count)
    }

    fn share_of(member: usize, size: usize, count: usize) -> Range<usize> {
        (member * count / size)..((member + 1) * count / size)
    }

    /// Calls `f(item)` for the items `0..count` (chunks) this member claims in this pass: the
    /// items of its own share first ([`Team::share`], in order), then, once those are gone, the
    /// items left in the other members' shares. Every item is claimed by exactly one member, so
    /// a member slowed down (a busy core) leaves its work to the others instead of making them
    /// wait at the next barrier, while on an idle machine each member keeps its own share.
    ///
    /// Every member must call this the same number of times, and a barrier must separate two
    /// calls (a pass that claims from a member's share must be over everywhere before the next
    /// pass starts claiming from it).
    pub fn claim(&self, count: usize, mut f: impl FnMut(usize)) {
        let pass = self.passes.get().wrapping_add(1);
        self.passes.set(pass);
        for k in 0..self.size {
            let member = (self.index + k) % self.size;
            let range = Self::share_of(member, self.size, count);
            let counter = &self.sync.claims[member].0;
            loop {
                let current = counter.load(Ordering::Acquire);
                // A counter last used in an earlier pass starts at the share's first item.
                let next = if (current >> 32) as u32 == pass { current as u32 as usize } else { range.start };
                if next >= range.end {
                    break;
                }
                let claimed = (pass as u64) << 32 | (next + 1) as u64;
                if counter.compare_exchange_weak(current, claimed, Ordering::AcqRel, Ordering::Acquire).is_ok() {
                    f(next);
                }
            }
        }
    }

    /// Waits until every member has arrived here. Writes made before the barrier by any member
    /// are seen after it by all. Spins for [`SPIN_BEFORE_SLEEP`], then sleeps until the last
    /// member arrives; panics if another member panicked. (Not inlined: profiles then show the
    /// time spent waiting.)
    #[inline(never)]
    pub fn barrier(&self) {
        let sync = self.sync;
        if sync.size == 1 {
            return;
        }
        self.barriers.set(self.barriers.get() + 1);
        let generation = sync.generation.0.load(Ordering::Acquire);
        if sync.arrived.0.fetch_add(1, Ordering::AcqRel) + 1 == sync.size {
            sync.arrived.0.store(0, Ordering::Relaxed);
            sync.generation.0.store(generation.wrapping_add(1), Ordering::SeqCst);
            sync.wake_sleepers();
            return;
        }
        let passed = || sync.generation.0.load(Ordering::SeqCst) != generation;
        let poisoned = || {
            if sync.poisoned.load(Ordering::SeqCst) {
                panic!("another member of the worker team panicked");
            }
        };
        let start = std::time::Instant::now();
        if spin_until(start, || {
            poisoned();
            passed()
        }) {
            return;
        }
        let mut guard = sync.park.lock().unwrap_or_else(|e| e.into_inner());
        sync.sleepers.0.fetch_add(1, Ordering::SeqCst);
        while !passed() && !sync.poisoned.load(Ordering::SeqCst) {
            guard = sync.wake.wait_timeout(guard, SLEEP_LIMIT).unwrap_or_else(|e| e.into_inner()).0;
        }
        sync.sleepers.0.fetch_sub(1, Ordering::SeqCst);
        drop(guard);
        poisoned();
        if start.elapsed() >= LONG_WAIT {
            self.long_waits.set(self.long_waits.get() + 1);
        }
    }
}

/// Spins until `done()`, for at most [`SPIN_BEFORE_SLEEP`] from `start` (the clock read once
/// every 64 spins); returns whether `done()` became true.
#[inline(always)]
fn spin_until(start: std::time::Instant, mut done: impl FnMut() -> bool) -> bool {
    let mut spins = 0u32;
    while !done() {
        std::hint::spin_loop();
        spins = spins.wrapping_add(1);
        if spins % 64 == 0 && start.elapsed() >= SPIN_BEFORE_SLEEP {
            return false;
        }
    }
    true
}

/// A slice shared by the members of a [`Team`]: between two barriers each member writes only
/// its own parts of it, and reads the whole of it only in passes where nobody writes it.
pub struct SharedSlice<'a, T> {
    ptr: *mut T,
    len: usize,
    _borrow: PhantomData<&'a mut [T]>,
}

// SAFETY: the slice is borrowed mutably for 'a, so only the team uses it; the members' accesses
// follow the contract of `part` and `whole` (disjoint writes, reads only of what nobody writes).
unsafe impl<T: Send> Send for SharedSlice<'_, T> {}
// SAFETY: as above.
unsafe impl<T: Send + Sync> Sync for SharedSlice<'_, T> {}

impl<'a, T> SharedSlice<'a, T> {
    /// Shares `slice` for as long as it is borrowed.
    pub fn new(slice: &'a mut [T]) -> Self {
        Self { ptr: slice.as_mut_ptr(), len: slice.len(), _borrow: PhantomData }
    }

    /// Elements in the slice.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when the slice has no elements.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The start of the slice, for code that hands disjoint rows of it to unsafe kernels of
    /// its own (which then keep the contract of [`SharedSlice::part`] themselves).
    pub fn as_mut_ptr(&self) -> *mut T {
        self.ptr
    }

    /// The elements `range`, to write.
    ///
    /// # Safety
    /// Until the next barrier, no other member reads or writes any element of `range`.
    #[allow(clippy::mut_from_ref)]
    pub unsafe fn part(&self, range: Range<usize>) -> &mut [T] {
        assert!(range.start <= range.end && range.end <= self.len, "part {range:?} of a slice of {}", self.len);
        // SAFETY: in bounds (checked above) of a live, mutably borrowed slice; no other member
        // touches these elements until the next barrier (the caller's contract).
        unsafe { std::slice::from_raw_parts_mut(self.ptr.add(range.start), range.end - range.start) }
    }

    /// The whole slice, to read.
    ///
    /// # Safety
    /// Until the next barrier, no member writes any element (through [`SharedSlice::part`]).
    pub unsafe fn whole(&self) -> &[T] {
        // SAFETY: a live slice that nobody writes until the next barrier (the caller's contract).
        unsafe { std::slice::from_raw_parts(self.ptr, self.len) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_do_not_depend_on_thread_count() {
        let run = |threads| {
            let pool = WorkerPool::new(threads).unwrap();
            let mut data: Vec<f32> = (0..1000).map(|i| i as f32).collect();
            pool.for_each_chunk_mut(&mut data, 64, |c, chunk| chunk.iter_mut().for_each(|x| *x = x.sqrt() + c as f32));
            // Tasks over disjoint sub-slices, each with its own partial sum, summed in task order.
            let mut tasks: Vec<(usize, &mut [f32], f32)> =
                data.chunks_mut(100).enumerate().map(|(c, chunk)| (c, chunk, 0.0)).collect();
            pool.for_each_task(&mut tasks, |(c, chunk, sum)| {
                chunk.iter_mut().for_each(|x| *x = (*x * 1.1).sin() + *c as f32);
                *sum = chunk.iter().sum();
            });
            let total: f32 = tasks.iter().map(|t| t.2).sum();
            (data, pool.map_collect(100, |i| (i as f32).sin()), total)
        };
        assert_eq!(run(1), run(2));
        assert_eq!(run(1), run(4));
        assert!(WorkerPool::new(1000).is_err());
    }

    /// `join` runs both closures (each writing its own buffer) and returns both results, with
    /// one thread or several, and a panic in either comes back to the caller.
    #[test]
    fn join_runs_both_and_returns_both_results() {
        for threads in [1, 2] {
            let pool = WorkerPool::new(threads).unwrap();
            let (mut left, mut right) = (vec![0u32; 1000], vec![0u32; 1000]);
            let (a, b) = pool.join(
                || {
                    left.iter_mut().enumerate().for_each(|(i, x)| *x = i as u32);
                    left.iter().sum::<u32>()
                },
                || {
                    right.iter_mut().enumerate().for_each(|(i, x)| *x = 2 * i as u32);
                    "right"
                },
            );
            assert_eq!((a, b), (499_500, "right"), "{threads} threads");
            assert_eq!(right[999], 1998);
            let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                pool.join(|| 1, || -> u32 { panic!("second") })
            }));
            assert!(result.is_err(), "{threads} threads");
        }
    }

    #[test]
    fn worker_panics_come_back_to_the_caller() {
        let pool = WorkerPool::new(2).unwrap();
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            pool.map_collect(10, |i| if i == 7 { panic!("worker") } else { i })
        }));
        assert!(result.is_err());
    }

    /// A barrier-synchronised reduction: every member writes its chunks' partial sums, then
    /// each adds all of them in chunk order, many times over. Same bits for 1, 2 and 3 threads
    /// (more members than cores: the barrier must yield, not starve), and every member agrees.
    #[test]
    fn team_reductions_do_not_depend_on_thread_count_and_never_deadlock() {
        use std::sync::atomic::AtomicU64;
        let run = |threads| {
            let pool = WorkerPool::new(threads).unwrap();
            let chunks = 13;
            let mut data: Vec<f32> = (0..chunks * 100).map(|i| (i as f32 * 0.37).sin()).collect();
            let partial: Vec<AtomicU64> = (0..chunks).map(|_| AtomicU64::new(0)).collect();
            let shared = SharedSlice::new(&mut data);
            let agreed = AtomicUsize::new(0);
            let total = pool.team(|team| {
                let mut total = 0.0f64;
                for round in 0..200 {
                    let mut claimed = Vec::new();
                    team.claim(chunks, |c| claimed.push(c));
                    for c in claimed {
                        // SAFETY: chunk c was claimed by this member alone in this pass.
                        let part = unsafe { shared.part(c * 100..(c + 1) * 100) };
                        let mut sum = 0.0f64;
                        for x in part.iter_mut() {
                            *x = (*x * 1.01 + round as f32 * 1e-3).sin();
                            sum += *x as f64;
                        }
                        partial[c].store(sum.to_bits(), Ordering::Relaxed);
                    }
                    team.barrier();
                    let sum: f64 = partial.iter().map(|p| f64::from_bits(p.load(Ordering::Relaxed))).sum();
                    // SAFETY: nobody writes `data` in this pass.
                    let first = unsafe { shared.whole()[0] };
                    total += sum + first as f64;
                    team.barrier();
                }
                if team.size() > 1 || threads <= 1 {
                    agreed.fetch_add(1, Ordering::Relaxed);
                }
                total
            });
            (total.to_bits(), data, agreed.into_inner())
        };
        let one = run(1);
        assert_eq!(one.2, 1);
        for threads in [2, 3] {
            let many = run(threads);
            assert_eq!(one.0, many.0);
            assert_eq!(one.1, many.1);
            #[cfg(feature = "parallel")]
            assert_eq!(many.2, threads as usize, "every member ran");
        }
    }

    /// A member that arrives late (its thread busy for milliseconds) finds the other asleep
    /// in the barrier and wakes it; the stats count the barriers and that long wait. A team of
    /// one member on a pool of two runs alone, with the same result.
    #[cfg(feature = "parallel")]
    #[test]
    fn a_late_member_wakes_the_one_asleep_in_the_barrier() {
        let pool = WorkerPool::new(2).unwrap();
        let run = |members| {
            pool.team_of(members, |team| {
                let mut seen = Vec::new();
                for round in 0..3 {
                    if team.index() == 1 && round == 1 {
                        std::thread::sleep(std::time::Duration::from_millis(5));
                    }
                    team.barrier();
                    seen.push((round, team.size()));
                }
                seen
            })
        };
        let (seen, stats) = run(2);
        assert_eq!(seen, [(0, 2), (1, 2), (2, 2)]);
        assert_eq!((stats.members, stats.barriers), (2, 3));
        assert!(stats.long_waits >= 1, "{stats:?}");
        let (alone, stats) = run(1);
        assert_eq!(alone, [(0, 1), (1, 1), (2, 1)]);
        assert_eq!(stats, TeamStats { members: 1, barriers: 0, long_waits: 0 });
    }

    /// Three members through 2,000 barriers, each arriving after its own short random delay
    /// (some past the spin, so members fall asleep and wake while others already wait at the
    /// next barrier): every member sees every other's write of the round before each barrier.
    #[test]
    fn many_barriers_with_uneven_arrivals_keep_every_round_apart() {
        let pool = WorkerPool::new(3).unwrap();
        let arrivals = AtomicUsize::new(0);
        let (_, stats) = pool.team_of(3, |team| {
            let mut state = 0x9e37_79b9u32.wrapping_mul(team.index() as u32 + 1);
            for round in 0..2000usize {
                state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let delay = (state >> 24) as u64 % 48;
                if delay > 40 {
                    std::thread::sleep(std::time::Duration::from_micros(delay));
                } else {
                    let start = std::time::Instant::now();
                    while start.elapsed() < std::time::Duration::from_micros(delay / 8) {
                        std::hint::spin_loop();
                    }
                }
                arrivals.fetch_add(1, Ordering::SeqCst);
                team.barrier();
                assert_eq!(arrivals.load(Ordering::SeqCst), team.size() * (round + 1), "round {round}");
                team.barrier();
            }
        });
        assert_eq!(arrivals.load(Ordering::SeqCst), stats.members * 2000);
        if stats.members > 1 {
            assert_eq!(stats.barriers, 4000);
        }
    }

    /// A member asleep in a barrier is woken by another member's panic, and panics too.
    #[cfg(feature = "parallel")]
    #[test]
    fn a_panic_wakes_a_member_asleep_in_a_barrier() {
        let pool = WorkerPool::new(2).unwrap();
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            pool.team(|team| {
                if team.index() == 1 {
                    std::thread::sleep(std::time::Duration::from_millis(5));
                    panic!("member");
                }
                team.barrier();
            })
        }));
        assert!(result.is_err());
    }

    /// One member for 4 runs after a run with long waits in more than a quarter of its
    /// barriers, then a probe with all; each contended probe doubles the wait (to 64 runs), and
    /// a quiet run ends it.
    #[test]
    fn a_contended_team_runs_alone_for_a_while() {
        let busy = TeamStats { members: 2, barriers: 40, long_waits: 11 };
        let quiet = TeamStats { members: 2, barriers: 40, long_waits: 10 };
        let mut sizer = TeamSizer::default();
        assert_eq!(sizer.members(2), 2);
        sizer.record(quiet);
        assert_eq!(sizer.members(2), 2);
        let mut alone_runs = Vec::new();
        for _ in 0..6 {
            sizer.record(busy);
            let mut alone = 0;
            while sizer.members(2) == 1 {
                // Runs alone report no barriers and change nothing.
                sizer.record(TeamStats { members: 1, ..TeamStats::default() });
                alone += 1;
            }
            alone_runs.push(alone);
        }
        assert_eq!(alone_runs, [4, 8, 16, 32, 64, 64]);
        sizer.record(quiet);
        assert_eq!(sizer.members(2), 2);
        sizer.record(busy);
        assert_eq!(sizer.members(2), 1, "the wait starts again at 4 runs");
        // A larger team whose members only wait briefly (uneven passes) keeps all its threads.
        let mut sizer = TeamSizer::default();
        sizer.record(TeamStats { members: 4, barriers: 40, long_waits: 0 });
        assert_eq!(sizer.members(4), 4);
    }

    #[test]
    fn a_panicking_member_does_not_leave_the_others_waiting() {
        let pool = WorkerPool::new(2).unwrap();
        // The last member (a worker), then the first (the caller's thread when called from
        // outside the pool, a worker from inside).
        for first in [false, true] {
            for inside in [false, true] {
                let team = || {
                    pool.team(|team| {
                        if team.index() == if first { 0 } else { team.size() - 1 } {
                            panic!("member");
                        }
                        team.barrier();
                        team.barrier();
                    })
                };
                let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    if inside { pool.install(team) } else { team() }
                }));
                assert!(result.is_err(), "first {first}, inside {inside}");
            }
        }
    }

    /// Called from outside the pool, the caller's thread is member 0 and the others run on the
    /// pool's workers; called from a worker (inside `install`), every member runs on a worker.
    /// Both give the same bits, and every member runs once.
    #[cfg(feature = "parallel")]
    #[test]
    fn the_callers_thread_is_member_0_from_outside_the_pool() {
        use std::sync::Mutex;
        let pool = WorkerPool::new(3).unwrap();
        let caller = std::thread::current().id();
        let run = |inside: bool| {
            let threads = Mutex::new(Vec::new());
            let mut data: Vec<f32> = (0..4000).map(|i| (i as f32 * 0.1).cos()).collect();
            let shared = SharedSlice::new(&mut data);
            let team = || {
                pool.team(|team| {
                    let name = std::thread::current().name().unwrap_or_default().to_owned();
                    threads.lock().unwrap().push((team.index(), std::thread::current().id(), name));
                    for _ in 0..50 {
                        team.claim(40, |c| {
                            // SAFETY: chunk c was claimed by this member alone in this pass.
                            let part = unsafe { shared.part(c * 100..(c + 1) * 100) };
                            part.iter_mut().for_each(|x| *x = (*x * 1.3).sin());
                        });
                        team.barrier();
                    }
                    team.index()
                })
            };
            let first = if inside { pool.install(team) } else { team() };
            assert_eq!(first, 0, "the result is member 0's");
            let mut threads = threads.into_inner().unwrap();
            threads.sort_by_key(|t| t.0);
            assert_eq!(threads.iter().map(|t| t.0).collect::<Vec<_>>(), [0, 1, 2], "inside {inside}");
            let on_caller: Vec<usize> = threads.iter().filter(|t| t.1 == caller).map(|t| t.0).collect();
            assert_eq!(on_caller, if inside { vec![] } else { vec![0] }, "inside {inside}");
            // The others on this pool's workers (not the host's global pool).
            let named: Vec<String> = threads.iter().filter(|t| t.1 != caller).map(|t| t.2.clone()).collect();
            assert_eq!(named.len(), if inside { 3 } else { 2 });
            assert!(named.iter().all(|name| name.starts_with("softshell-")), "{named:?}");
            data
        };
        let outside = run(false);
        assert_eq!(outside, run(true));
        let mut data: Vec<f32> = (0..4000).map(|i| (i as f32 * 0.1).cos()).collect();
        for _ in 0..50 {
            data.iter_mut().for_each(|x| *x = (*x * 1.3).sin());
        }
        assert_eq!(outside, data);
    }
}
