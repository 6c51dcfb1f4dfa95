//! Self-collision of the shell through the C ABI (SPEC 1.6, issue 4): shells squeezed hard
//! (30 times the default pressure, no stop ratio) must never pass through themselves. After the
//! run, no two vertex-disjoint triangles may intersect, checked by an independent
//! triangle-triangle test (orientation determinants in f64 on the f32 positions) over the pairs a
//! uniform grid brings together.
//!
//! Meshes: a sphere (genus 0), the torus (genus 1), the eight (genus 2) and a dumbbell built here
//! whose two lobes are pressed together. At 30 times the default pressure every shell is crushed
//! to V/V0 of 0.01-0.03 within about 30 steps, after which every step is full of contacts
//! (thousands per step). Each runs the 300 steps, checked every 50 steps and at the end.
#![cfg(all(feature = "shell", feature = "body", feature = "lattice"))]

mod report_util;

use report_util::*;
use softshell::ffi::SoftshellShellDef;
use softshell::ffi::shell::softshell_shell_def_default;

type P = [f64; 3];

fn sub(a: P, b: P) -> P {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Orientation of d against the plane abc: det(b - a, c - a, d - a).
fn orient(a: P, b: P, c: P, d: P) -> f64 {
    let (u, v, w) = (sub(b, a), sub(c, a), sub(d, a));
    u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) + u[2] * (v[0] * w[1] - v[1] * w[0])
}

/// Does segment pq cross triangle abc (touching counts)? Coplanar segments are left to the other
/// edges (two non-coplanar triangles that intersect always have an edge of one through the other).
fn segment_crosses(p: P, q: P, a: P, b: P, c: P) -> bool {
    let (o1, o2) = (orient(a, b, c, p), orient(a, b, c, q));
    if (o1 > 0.0 && o2 > 0.0) || (o1 < 0.0 && o2 < 0.0) || (o1 == 0.0 && o2 == 0.0) {
        return false;
    }
    let (s1, s2, s3) = (orient(p, q, a, b), orient(p, q, b, c), orient(p, q, c, a));
    (s1 >= 0.0 && s2 >= 0.0 && s3 >= 0.0) || (s1 <= 0.0 && s2 <= 0.0 && s3 <= 0.0)
}

fn triangles_intersect(t: [P; 3], u: [P; 3]) -> bool {
    (0..3).any(|k| segment_crosses(t[k], t[(k + 1) % 3], u[0], u[1], u[2]))
        || (0..3).any(|k| segment_crosses(u[k], u[(k + 1) % 3], t[0], t[1], t[2]))
}

/// Pairs of vertex-disjoint triangles that intersect, found through a uniform grid of cells as
/// large as the largest triangle box (each pair is tested once, in the cell of the lowest corner
/// of the two boxes' overlap).
fn intersecting_pairs(positions: &[f32], triangles: &[u32]) -> Vec<(usize, usize)> {
    let x: Vec<P> = positions.chunks(3).map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]).collect();
    let tris: Vec<[u32; 3]> = triangles.chunks(3).map(|t| [t[0], t[1], t[2]]).collect();
    let boxes: Vec<(P, P)> = tris
        .iter()
        .map(|t| {
            let c = t.map(|v| x[v as usize]);
            (
                std::array::from_fn(|k| c[0][k].min(c[1][k]).min(c[2][k])),
                std::array::from_fn(|k| c[0][k].max(c[1][k]).max(c[2][k])),
            )
        })
        .collect();
    let cell = boxes.iter().flat_map(|(lo, hi)| (0..3).map(move |k| hi[k] - lo[k])).fold(1e-9, f64::max);
    let key = |p: &P| -> [i64; 3] { std::array::from_fn(|k| (p[k] / cell).floor() as i64) };
    let mut grid: std::collections::HashMap<[i64; 3], Vec<usize>> = std::collections::HashMap::new();
    for (i, (lo, hi)) in boxes.iter().enumerate() {
        let (a, b) = (key(lo), key(hi));
        for i0 in a[0]..=b[0] {
            for i1 in a[1]..=b[1] {
                for i2 in a[2]..=b[2] {
                    grid.entry([i0, i1, i2]).or_default().push(i);
                }
            }
        }
    }
    let mut found = Vec::new();
    for (cell_key, members) in &grid {
        for (k, &i) in members.iter().enumerate() {
            for &j in &members[k + 1..] {
                let (ti, tj) = (tris[i], tris[j]);
                if ti.iter().any(|v| tj.contains(v)) {
                    continue;
                }
                let ((lo_i, hi_i), (lo_j, hi_j)) = (boxes[i], boxes[j]);
                if (0..3).any(|a| lo_i[a] > hi_j[a] || lo_j[a] > hi_i[a]) {
                    continue;
                }
                let overlap_lo: P = std::array::from_fn(|a| lo_i[a].max(lo_j[a]));
                if key(&overlap_lo) != *cell_key {
                    continue;
                }
                if triangles_intersect(ti.map(|v| x[v as usize]), tj.map(|v| x[v as usize])) {
                    found.push((i.min(j), i.max(j)));
                }
            }
        }
    }
    found.sort_unstable();
    found
}

/// A dumbbell: a surface of revolution about z with two round lobes and a short thin neck, so
/// that squeezing presses the lobes against each other. `rings` latitude rings, `segments` around.
fn dumbbell(rings: usize, segments: usize) -> (Vec<f32>, Vec<u32>) {
    let mut p = vec![0.0, 0.0, -1.0];
    for r in 1..=rings {
        let t = std::f32::consts::PI * r as f32 / (rings + 1) as f32;
        let z = -t.cos();
        // Lobes of radius ~0.5 around z = +-0.5, a neck of radius 0.15 at z = 0.
        let radius = t.sin() * (0.15 + 0.85 * (2.0 * t).sin().abs());
        for s in 0..segments {
            let a = 2.0 * std::f32::consts::PI * s as f32 / segments as f32;
            p.extend([radius * a.cos(), radius * a.sin(), z]);
        }
    }
    p.extend([0.0, 0.0, 1.0]);
    let ring = |r: usize, s: usize| (1 + r * segments + s % segments) as u32;
    let top = (1 + rings * segments) as u32;
    let mut t = Vec::new();
    for s in 0..segments {
        t.extend([0, ring(0, s + 1), ring(0, s)]);
        t.extend([top, ring(rings - 1, s), ring(rings - 1, s + 1)]);
    }
    for r in 0..rings - 1 {
        for s in 0..segments {
            t.extend([ring(r, s), ring(r, s + 1), ring(r + 1, s + 1)]);
            t.extend([ring(r, s), ring(r + 1, s + 1), ring(r + 1, s)]);
        }
    }
    normalise(&mut p, 1.0);
    (p, t)
}

/// Squeezes a shell with 30 times the default pressure for `steps` steps and checks that no two
/// vertex-disjoint triangles intersect at the end (and every 50 steps on the way), and that the
/// shell did touch itself (contacts reported by the stats).
fn squeeze(name: &str, positions: &[f32], triangles: &[u32], steps: usize) {
    assert!(intersecting_pairs(positions, triangles).is_empty(), "{name}: the input intersects itself");
    let base = softshell_shell_def_default();
    let def = SoftshellShellDef { pressure: 30.0 * base.pressure, stop_volume_ratio: 0.0, ..base };
    let shell = Shell::new(positions, triangles, &def).unwrap();
    let (mut contacts, mut tests, mut ratio, mut window) = (0u64, 0u64, 1.0, 0u64);
    for k in 1..=steps {
        let stats = match shell.step() {
            Ok(s) => s,
            Err((status, message)) => panic!("{name}: step {k} failed: {status:?}: {message}"),
        };
        contacts += stats.contacts;
        window += stats.contacts;
        tests += stats.ccd_tests;
        ratio = stats.volume_ratio;
        assert!(stats.ccd_tests <= stats.collision_candidates);
        if k % 50 == 0 || k == steps {
            // Crushed within the first 50 steps, the shell keeps pressing on itself after that.
            assert!(k <= 50 || window > 0, "{name}: no contact in the 50 steps before step {k} (V/V0 {ratio})");
            window = 0;
            let bad = intersecting_pairs(&shell.positions(), triangles);
            assert!(
                bad.is_empty(),
                "{name}: step {k}: {} intersecting triangle pairs, e.g. {:?}",
                bad.len(),
                &bad[..bad.len().min(5)]
            );
        }
    }
    println!("{name}: {steps} steps, V/V0 {ratio:.3}, {tests} exact tests, {contacts} contacts");
    assert!(contacts > 0, "{name}: squeezed this hard the shell must touch itself (V/V0 {ratio})");
    assert!(ratio < 0.5, "{name}: V/V0 {ratio}: not squeezed");
}

#[test]
fn the_checker_finds_crossings_and_accepts_neighbours() {
    let t = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    assert!(triangles_intersect(t, [[0.2, 0.2, -1.0], [0.2, 0.2, 1.0], [3.0, 3.0, 0.5]]));
    assert!(!triangles_intersect(t, [[0.2, 0.2, 0.1], [0.3, 0.2, 1.0], [3.0, 3.0, 0.5]]));
    assert!(!triangles_intersect(t, [[0.8, 0.8, -1.0], [0.8, 0.8, 1.0], [3.0, 3.0, 0.5]]));
    // A pierced sphere: move one vertex through the opposite side.
    let (mut p, tris) = unit_obj("sphere.obj", 1.0);
    assert!(intersecting_pairs(&p, &tris).is_empty());
    for k in 0..3 {
        p[k] = -p[k] * 1.5;
    }
    assert!(!intersecting_pairs(&p, &tris).is_empty());
    let (p, t) = dumbbell(20, 20);
    assert!(intersecting_pairs(&p, &t).is_empty());
    let m = Mesh::new(&p, &t).unwrap().report();
    assert!(m.is_closed && m.is_consistently_oriented && m.genus == 0 && m.volume > 0.0);
}

#[test]
fn a_squeezed_sphere_does_not_pass_through_itself() {
    let (p, t) = unit_obj("sphere.obj", 1.0);
    squeeze("sphere", &p, &t, 300);
}

#[test]
fn a_squeezed_dumbbell_keeps_its_lobes_apart() {
    let (p, t) = dumbbell(20, 20);
    squeeze("dumbbell", &p, &t, 300);
}

#[test]
fn a_squeezed_torus_genus_1_does_not_pass_through_itself() {
    let (p, t) = unit_obj("torus.obj", 1.0);
    squeeze("torus", &p, &t, 300);
}

#[test]
fn a_squeezed_eight_genus_2_does_not_pass_through_itself() {
    let (p, t) = unit_obj("eight.obj", 1.0);
    squeeze("eight", &p, &t, 300);
}

/// A host built with -ffast-math (gcc links crtfastmath.o, which sets FTZ and DAZ at start-up)
/// or an engine that sets them for speed: the shell must still keep its lobes apart. With DAZ
/// the BVH's key test (vertex indices once stored as the bits of f32 subnormals, compared with
/// an f32 compare) called every pair neighbours and skipped it: the dumbbell turned inside out
/// at step 8 (found in a review). The shell runs on this thread (`squeeze` keeps the default,
/// threads = 1).
#[cfg(target_arch = "x86_64")]
#[test]
fn a_squeezed_dumbbell_keeps_its_lobes_apart_with_denormals_are_zero() {
    let (p, t) = dumbbell(20, 20);
    with_denormals_are_zero(|| squeeze("dumbbell (DAZ/FTZ)", &p, &t, 100));
}
