//! Each handle's own worker threads.
//!
//! A handle owns a rayon pool sized by its def's `threads` (0 = all cores, 1 = none), so the
//! host's global rayon pool is never touched and two handles never contend for one pool. Work is
//! split in fixed chunks that do not depend on the thread count, and every reduction runs in a
//! fixed order, so results are bit-identical whatever `threads` is. Without the `parallel`
//! feature every pool is serial.

use crate::error::{Error, Result};

/// A handle's worker threads (none when serial).
pub struct WorkerPool {
    #[cfg(feature = "parallel")]
    pool: Option<rayon::ThreadPool>,
    threads: usize,
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
                return Ok(Self { pool: None, threads: 1 });
            }
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(wanted)
                .thread_name(|i| format!("softshell-{i}"))
                .build()
                .map_err(|e| {
                    Error::new(crate::error::ErrorKind::Internal, format!("cannot start {wanted} worker threads: {e}"))
                })?;
            Ok(Self { pool: Some(pool), threads: wanted })
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
        if self.pool.is_some() {
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

    /// Heap bytes attributed to the pool (its threads' stacks are not counted).
    pub fn memory_bytes(&self) -> usize {
        #[cfg(feature = "parallel")]
        if self.pool.is_some() {
            return std::mem::size_of::<rayon::ThreadPool>();
        }
        0
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

    #[test]
    fn worker_panics_come_back_to_the_caller() {
        let pool = WorkerPool::new(2).unwrap();
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            pool.map_collect(10, |i| if i == 7 { panic!("worker") } else { i })
        }));
        assert!(result.is_err());
    }
}
