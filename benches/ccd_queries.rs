//! Time per standalone CCD query on the public ground-truth set (tests/data/ccd), vertex-face
//! and edge-edge separately, through the C ABI with thickness 0: mean, median, max, false
//! positives and negatives, and which stage decided. Run with `cargo bench --bench ccd_queries`.
//!
//! If a Python virtual environment with the `ipctk` package (ipc-toolkit's bindings; never a
//! dependency of this crate) exists at $IPCTK_VENV (default /work/venv-ipctk), the same queries
//! are also run through its TightInclusionCCD in the same run and the ratio is printed. Its times
//! include the Python-to-C++ call; the time of a trivial call with the same arguments
//! (`point_triangle_aabb_ccd`/`edge_edge_aabb_ccd`) is printed beside it and subtracted.

#[path = "../tests/ccd_queries/mod.rs"]
mod ccd_queries;

use std::hint::black_box;
use std::time::Instant;

use ccd_queries::{Category, Kind, load_all};
use softshell::collision::{CcdSettings, Stage, edge_edge_with, vertex_triangle_with};
use softshell::ffi::ccd::{softshell_ccd_edge_edge, softshell_ccd_vertex_triangle};

/// Repetitions of one query inside one timed interval, and passes over the whole set (the
/// fastest pass counts for each query, which removes most scheduling noise).
const REPEAT: u32 = 16;
const PASSES: usize = 5;

fn call(kind: Kind, start: &[[f64; 3]; 4], end: &[[f64; 3]; 4]) -> bool {
    let f = match kind {
        Kind::VertexFace => softshell_ccd_vertex_triangle,
        Kind::EdgeEdge => softshell_ccd_edge_edge,
    };
    let mut hit = 0;
    let mut toi = 0.0;
    // SAFETY: every pointer is to a live local of the right size.
    let status = unsafe {
        f(
            start[0].as_ptr(),
            start[1].as_ptr(),
            start[2].as_ptr(),
            start[3].as_ptr(),
            end[0].as_ptr(),
            end[1].as_ptr(),
            end[2].as_ptr(),
            end[3].as_ptr(),
            black_box(0.0),
            &mut hit,
            &mut toi,
        )
    };
    assert_eq!(status as u32, 0);
    hit == 1
}

#[derive(Default)]
struct Summary {
    times_ns: Vec<f64>,
    false_positives: usize,
    false_negatives: usize,
    colliding: usize,
}

impl Summary {
    fn print(&mut self, label: &str) {
        self.times_ns.sort_by(f64::total_cmp);
        let n = self.times_ns.len();
        let mean = self.times_ns.iter().sum::<f64>() / n as f64;
        let median = self.times_ns[n / 2];
        let p99 = self.times_ns[(n * 99) / 100];
        let max = self.times_ns[n - 1];
        println!(
            "{label:<28} {n:>5} queries ({:>3} colliding): mean {:>8.3} us  median {:>7.3} us  p99 {:>8.3} us  max {:>9.3} us  false+ {:>3}  false- {}",
            self.colliding,
            mean / 1e3,
            median / 1e3,
            p99 / 1e3,
            max / 1e3,
            self.false_positives,
            self.false_negatives
        );
    }
}

fn kind_index(kind: Kind) -> usize {
    match kind {
        Kind::VertexFace => 0,
        Kind::EdgeEdge => 1,
    }
}

fn run_softshell(categories: &[Category]) -> [Summary; 2] {
    let mut best: Vec<Vec<f64>> = categories.iter().map(|c| vec![f64::INFINITY; c.queries.len()]).collect();
    for _ in 0..PASSES {
        for (c, category) in categories.iter().enumerate() {
            for (q, query) in category.queries.iter().enumerate() {
                let start = Instant::now();
                for _ in 0..REPEAT {
                    black_box(call(category.kind, black_box(&query.start), black_box(&query.end)));
                }
                let ns = start.elapsed().as_nanos() as f64 / REPEAT as f64;
                best[c][q] = best[c][q].min(ns);
            }
        }
    }
    let mut summaries = [Summary::default(), Summary::default()];
    for (c, category) in categories.iter().enumerate() {
        let summary = &mut summaries[kind_index(category.kind)];
        for (q, query) in category.queries.iter().enumerate() {
            let hit = call(category.kind, &query.start, &query.end);
            summary.times_ns.push(best[c][q]);
            summary.colliding += usize::from(query.collides);
            summary.false_positives += usize::from(hit && !query.collides);
            summary.false_negatives += usize::from(!hit && query.collides);
        }
    }
    summaries
}

fn print_stages(categories: &[Category]) {
    let settings = CcdSettings::default();
    for kind in [Kind::VertexFace, Kind::EdgeEdge] {
        let mut counts = std::collections::BTreeMap::new();
        let mut max_boxes = 0;
        let mut fp_exhausted = 0;
        for category in categories.iter().filter(|c| c.kind == kind) {
            for query in &category.queries {
                let outcome = match kind {
                    Kind::VertexFace => vertex_triangle_with(&query.start, &query.end, 0.0, &settings),
                    Kind::EdgeEdge => edge_edge_with(&query.start, &query.end, 0.0, &settings),
                };
                *counts.entry(format!("{:?}", outcome.stage)).or_insert(0usize) += 1;
                max_boxes = max_boxes.max(outcome.boxes);
                fp_exhausted += usize::from(outcome.stage == Stage::BudgetExhausted && !query.collides);
            }
        }
        println!(
            "  {kind:?} decided by: {counts:?}; most sub-domains in one query {max_boxes} (budget {}); false positives from the budget {fp_exhausted}",
            settings.max_boxes
        );
    }
}

/// The ipctk side, as a Python program reading the same CSV files. Prints one line per query:
/// kind (vf/ee), ccd ns, baseline ns, hit, truth.
const IPCTK_SCRIPT: &str = r#"
import sys, time, glob, os
from fractions import Fraction
import numpy as np
import ipctk
root, passes, repeat = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
ipctk.set_logger_level(ipctk.LoggerLevel.error)
ccd = ipctk.TightInclusionCCD()
def load(path):
    rows = []
    for line in open(path):
        c = line.strip().split(',')
        if len(c) < 7: continue
        p = np.array([float(Fraction(int(c[2*i]), int(c[2*i+1]))) for i in range(3)])
        rows.append((p, c[6].strip() == '1'))
    return [rows[i:i+8] for i in range(0, len(rows), 8)]
out = []
for scene in sorted(os.listdir(root)):
    for sub, kind in (('vertex-face', 'vf'), ('edge-edge', 'ee')):
        for path in sorted(glob.glob(os.path.join(root, scene, sub, '*.csv'))):
            for q in load(path):
                pts = [r[0] for r in q]
                truth = q[0][1]
                f = ccd.point_triangle_ccd if kind == 'vf' else ccd.edge_edge_ccd
                g = ipctk.point_triangle_aabb_ccd if kind == 'vf' else ipctk.edge_edge_aabb_ccd
                best = best0 = float('inf')
                for _ in range(passes):
                    t0 = time.perf_counter_ns()
                    for _ in range(repeat):
                        hit, toi = f(*pts)
                    best = min(best, (time.perf_counter_ns() - t0) / repeat)
                    t0 = time.perf_counter_ns()
                    for _ in range(repeat):
                        g(*pts, 0.0)
                    best0 = min(best0, (time.perf_counter_ns() - t0) / repeat)
                out.append('%s %.1f %.1f %d %d' % (kind, best, best0, hit, truth))
print('\n'.join(out))
"#;

fn run_ipctk(venv: &std::path::Path) -> Option<[(Summary, Vec<f64>); 2]> {
    let python = venv.join("bin/python");
    if !python.exists() {
        println!("ipctk: no virtual environment at {} (skipped)", venv.display());
        return None;
    }
    let data = ccd_queries::data_dir();
    let output =
        match std::process::Command::new(&python).arg("-c").arg(IPCTK_SCRIPT).arg(&data).args(["1", "3"]).output() {
            Ok(output) => output,
            Err(error) => {
                println!("ipctk: could not run {}: {error}", python.display());
                return None;
            }
        };
    if !output.status.success() {
        println!("ipctk: failed: {}", String::from_utf8_lossy(&output.stderr));
        return None;
    }
    let mut result = [(Summary::default(), Vec::new()), (Summary::default(), Vec::new())];
    for line in String::from_utf8_lossy(&output.stdout).lines() {
        let cols: Vec<&str> = line.split_whitespace().collect();
        if cols.len() != 5 || !(cols[0] == "vf" || cols[0] == "ee") {
            continue; // a log line of the library
        }
        let kind = if cols[0] == "vf" { 0 } else { 1 };
        let (Ok(ns), Ok(base)) = (cols[1].parse::<f64>(), cols[2].parse::<f64>()) else {
            println!("ipctk: unexpected output line {line:?}");
            return None;
        };
        let (hit, truth) = (cols[3] == "1", cols[4] == "1");
        let (summary, baseline) = &mut result[kind];
        summary.times_ns.push(ns);
        baseline.push(base);
        summary.colliding += usize::from(truth);
        summary.false_positives += usize::from(hit && !truth);
        summary.false_negatives += usize::from(!hit && truth);
    }
    Some(result)
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

fn main() {
    let categories = load_all();
    println!(
        "softshell CCD on {} public queries (thickness 0, through the C ABI):",
        categories.iter().map(|c| c.queries.len()).sum::<usize>()
    );
    let mut ours = run_softshell(&categories);
    ours[0].print("softshell vertex-face");
    ours[1].print("softshell edge-edge");
    print_stages(&categories);

    let venv = std::env::var_os("IPCTK_VENV").map_or_else(|| "/work/venv-ipctk".into(), std::path::PathBuf::from);
    if let Some(mut peer) = run_ipctk(&venv) {
        println!("ipc-toolkit (PyPI ipctk, TightInclusionCCD defaults) on the same queries, same run:");
        for (k, label) in [(0, "vertex-face"), (1, "edge-edge")] {
            let (summary, baseline) = &mut peer[k];
            let call_overhead = {
                let mut b = baseline.clone();
                b.sort_by(f64::total_cmp);
                b[b.len() / 2]
            };
            let raw_mean = mean(&summary.times_ns);
            summary.print(&format!("ipctk {label} (raw)"));
            let ours_mean = mean(&ours[k].times_ns);
            let net_mean = raw_mean - call_overhead;
            println!(
                "  Python call overhead (median of a trivial call) {:.3} us; ipctk mean without it {:.3} us; ratio ipctk/softshell (means, overhead removed) {:.1}x",
                call_overhead / 1e3,
                net_mean / 1e3,
                net_mean / ours_mean
            );
        }
    }
}
