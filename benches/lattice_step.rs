//! FastLSM step cost (issue 6 goals): on a 256 x 256 lattice, the cost per step for
//! w = 1, 2, 4, 8 (goal: w = 8 costs at most 1.3x w = 1, SPEC 3's "cost O(n) whatever w"), and the
//! throughput in particle-steps per second on 1 and 2 threads (goal: >= 5 million on 2 threads).
//!
//! Run: `cargo bench --bench lattice_step` (optional argument: steps per sample, default 20).
//! The machine may be shared, so each figure is the best of several samples (the least
//! disturbed one); the median is printed beside it.

use std::time::Instant;

use softshell::lattice::{Lattice, LatticeParams};

const SIZE: u32 = 256;

/// Seconds per step: (best, median) over `samples` samples of `steps` steps each.
fn measure(w: u32, threads: u32, damping: f32, steps: usize, samples: usize) -> (f64, f64) {
    let params = LatticeParams {
        columns: SIZE,
        rows: SIZE,
        region_half_width: w,
        threads,
        damping,
        spacing: 0.01,
        ..LatticeParams::default()
    };
    let mut lattice = Lattice::new(params, None).expect("valid bench lattice");
    // Pinned along one edge and poked, so that regions really rotate and deform.
    for c in 0..SIZE {
        lattice.pin(c, 0, true).unwrap();
    }
    for _ in 0..5 {
        lattice.apply_force(SIZE / 2, SIZE / 2, [0.0, 50.0, 0.0]).unwrap();
        lattice.step().unwrap();
    }
    let mut times: Vec<f64> = (0..samples)
        .map(|_| {
            let start = Instant::now();
            for _ in 0..steps {
                lattice.step().unwrap();
            }
            start.elapsed().as_secs_f64() / steps as f64
        })
        .collect();
    times.sort_by(f64::total_cmp);
    (times[0], times[samples / 2])
}

fn main() {
    let steps: usize = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(20);
    let samples = 7;
    let particles = (SIZE * SIZE) as f64;
    println!("lattice_step: {SIZE} x {SIZE} = {particles} particles, {steps} steps per sample, best of {samples}");
    for damping in [0.2f32, 0.0] {
        println!("\nregion damping {damping} ({})", if damping > 0.0 { "the default" } else { "off" });
        println!("{:>3} {:>8} {:>12} {:>12} {:>16}", "w", "threads", "best ms", "median ms", "M particle-steps/s");
        let mut best = std::collections::BTreeMap::new();
        for threads in [1u32, 2] {
            for w in [1u32, 2, 4, 8] {
                let (b, m) = measure(w, threads, damping, steps, samples);
                best.insert((threads, w), b);
                println!("{w:>3} {threads:>8} {:>12.3} {:>12.3} {:>16.2}", b * 1e3, m * 1e3, particles / b / 1e6);
            }
        }
        for threads in [1u32, 2] {
            println!(
                "threads {threads}: cost ratio w=8 / w=1 = {:.3} (goal <= 1.3); w=2 / w=1 = {:.3}; w=4 / w=1 = {:.3}",
                best[&(threads, 8)] / best[&(threads, 1)],
                best[&(threads, 2)] / best[&(threads, 1)],
                best[&(threads, 4)] / best[&(threads, 1)]
            );
        }
        let worst_two = [1u32, 2, 4, 8].iter().map(|&w| best[&(2, w)]).fold(0.0, f64::max);
        println!("2 threads: {:.2} M particle-steps/s at the slowest w (goal >= 5)", particles / worst_two / 1e6);
    }
}
