//! Shared by the random-session tests (tests/ffi_*_random_sessions.rs and
//! tests/ffi_*_random_threads.rs): a small random number generator that gives the same sequence
//! on every platform, the seed and length settings read from the environment, and what the
//! thread sessions compare between thread counts.
#![allow(dead_code)]

use softshell::ffi::SoftshellStatus;

/// SplitMix64: small, and the same sequence on every platform.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    pub fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }
    pub fn uniform(&mut self, low: f64, high: f64) -> f32 {
        (low + (high - low) * self.unit()) as f32
    }
    /// 10^u, u uniform in [low, high).
    pub fn decades(&mut self, low: f64, high: f64) -> f32 {
        10f64.powf(low + (high - low) * self.unit()) as f32
    }
    /// `low` or `high` (the ends of a documented range) with probability 1/8 each, else None.
    pub fn end(&mut self, low: f32, high: f32) -> Option<f32> {
        match self.below(8) {
            0 => Some(low),
            1 => Some(high),
            _ => None,
        }
    }
}

/// The seeds `<first>..<end>` given in the environment variable `name`, else `default`.
pub fn seeds(name: &str, default: std::ops::Range<u64>) -> std::ops::Range<u64> {
    match std::env::var(name) {
        Ok(range) => {
            let (a, b) = range.split_once("..").unwrap_or_else(|| panic!("{name}=<first>..<end>"));
            a.parse().expect("first seed")..b.parse().expect("end seed")
        }
        Err(_) => default,
    }
}

/// The count in the environment variable `name`, else `default`.
pub fn count(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|n| n.parse().ok()).unwrap_or(default)
}

/// One call's outcome in a thread session, compared between the thread counts.
#[derive(Debug, PartialEq)]
pub struct Outcome {
    pub call: String,
    pub status: SoftshellStatus,
    /// The error message of a call that did not return OK (empty after OK): an UNSTABLE step
    /// names the value that blew up and advises settings, which must not depend on the threads
    /// either.
    pub message: String,
    /// Every stats field but the wall-clock time, floats as bits (a step's only).
    pub stats: Option<Vec<u64>>,
    /// Every buffer and count, floats as bits.
    pub state: Vec<u64>,
}

/// The first call whose outcome differs between `a` and `b`, described.
pub fn first_difference(a: &[Outcome], b: &[Outcome]) -> Option<String> {
    a.iter().zip(b).enumerate().find(|(_, (x, y))| x != y).map(|(k, (x, y))| {
        let what = if x.call != y.call {
            format!("the calls differ: {:?} against {:?}", x.call, y.call)
        } else if x.status != y.status {
            format!("status {:?} against {:?}", x.status, y.status)
        } else if x.message != y.message {
            format!("message {:?} against {:?}", x.message, y.message)
        } else if x.stats != y.stats {
            format!("stats {:?} against {:?}", x.stats, y.stats)
        } else {
            let at = x.state.iter().zip(&y.state).position(|(p, q)| p != q);
            format!("the state differs (lengths {} and {}, first at word {at:?})", x.state.len(), y.state.len())
        };
        format!("call {k} ({}): {what}", x.call)
    })
}

/// Runs each session of `seeds` on 1 thread, then again on 2 and on 3, and returns the
/// differences found, one line each (none: the same bits on every thread count). `run(seed,
/// threads, tally)` runs one session and returns its outcomes; `tally` counts what the 1-thread
/// runs did (the others make the same calls while the outcomes agree).
pub fn replay_on_threads<T: Default>(
    seeds: std::ops::Range<u64>,
    tally: &mut T,
    mut run: impl FnMut(u64, u32, &mut T) -> Vec<Outcome>,
) -> Vec<String> {
    let mut failures = Vec::new();
    for seed in seeds {
        let one = run(seed, 1, tally);
        for threads in [2, 3] {
            let other = run(seed, threads, &mut T::default());
            if let Some(d) = first_difference(&one, &other) {
                failures.push(format!("seed {seed}, 1 thread against {threads}: {d}"));
            }
        }
    }
    failures
}

/// Three calls a lattice of `columns` columns and `particles` particles must refuse, changing
/// nothing: a pin of a site outside it, a NaN force, positions one float short. Their statuses.
#[cfg(feature = "lattice")]
pub fn lattice_refused_calls(
    lattice: *mut softshell::ffi::SoftshellLattice,
    columns: u32,
    particles: usize,
) -> [SoftshellStatus; 3] {
    use softshell::ffi::lattice::*;
    let nan = [f32::NAN, 0.0, 0.0];
    let short = vec![0.0f32; 3 * particles - 1];
    // SAFETY: the caller's live lattice; float[3]; `short` holds its floats.
    unsafe {
        [
            softshell_lattice_pin(lattice, columns, 0),
            softshell_lattice_apply_force(lattice, 0, 0, nan.as_ptr()),
            softshell_lattice_set_positions(lattice, short.as_ptr(), short.len()),
        ]
    }
}
