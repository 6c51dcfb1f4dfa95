//! The naive O(n w^2) lattice shape matching, written straight from SPEC 3 with explicit loops
//! over each region's members and each particle's regions: the reference the fast passes are
//! tested against (test builds only).

use glam::{DMat3, DVec3};

use super::matching::rotation_from_columns;
use super::polar::polar_rotation;
use super::simulator::Lattice;

/// Every site's goal (world space; holes zero), by the definition.
pub(crate) fn naive_goals(lattice: &Lattice) -> Vec<[f64; 3]> {
    let layout = lattice.layout();
    let (columns, rows) = (layout.columns(), layout.rows());
    let w = lattice.params().region_half_width as usize;
    let n = layout.site_count();
    let x = lattice.site_positions();
    let rest0 = |s: usize| DVec3::from(layout.rest_position(s));
    let box_of = |s: usize| {
        let (c, r) = (s % columns, s / columns);
        let mut members = Vec::new();
        for rr in r.saturating_sub(w)..=(r + w).min(rows - 1) {
            for cc in c.saturating_sub(w)..=(c + w).min(columns - 1) {
                let t = rr * columns + cc;
                if layout.is_particle(t) {
                    members.push(t);
                }
            }
        }
        members
    };
    let mass = lattice.params().particle_mass as f64;
    // |R_s| and m~_s.
    let count: Vec<usize> = (0..n).map(|s| if layout.is_particle(s) { box_of(s).len() } else { 0 }).collect();
    let share = |s: usize| mass / count[s] as f64;
    // Each region's R and t.
    let mut fit = vec![(DMat3::IDENTITY, DVec3::ZERO); n];
    #[allow(clippy::needless_range_loop)] // r is a site number, used for more than indexing `fit`
    for r in 0..n {
        if !layout.is_particle(r) {
            continue;
        }
        let members = box_of(r);
        let m: f64 = members.iter().map(|&s| share(s)).sum();
        let c0 = members.iter().map(|&s| rest0(s) * share(s)).sum::<DVec3>() / m;
        let c = members.iter().map(|&s| DVec3::from(x[s]) * share(s)).sum::<DVec3>() / m;
        let mut a = DMat3::ZERO;
        for &s in &members {
            let d = DVec3::from(x[s]) - c;
            let d0 = rest0(s) - c0;
            a += DMat3::from_cols(d * d0.x, d * d0.y, d * d0.z) * share(s);
        }
        let spacing = layout.spacing();
        let rot = polar_rotation(a, rotation_from_columns(&lattice.rotation[r]), 1e-12 * m * spacing * spacing);
        fit[r] = (rot, c - rot * c0);
    }
    // Each particle's goal: the mean over the regions that contain it.
    (0..n)
        .map(|s| {
            if !layout.is_particle(s) {
                return [0.0; 3];
            }
            let regions = box_of(s);
            let sum: DVec3 = regions.iter().map(|&r| fit[r].0 * rest0(s) + fit[r].1).sum();
            (sum / regions.len() as f64).to_array()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::LatticeParams;

    fn params(columns: u32, rows: u32, w: u32) -> LatticeParams {
        LatticeParams { columns, rows, region_half_width: w, spacing: 0.1, ..LatticeParams::default() }
    }

    fn holey_mask(columns: usize, rows: usize) -> Vec<u8> {
        (0..columns * rows)
            .map(|s| {
                let (c, r) = (s % columns, s / columns);
                let in_hole = (4..8).contains(&c) && (3..6).contains(&r);
                let speck = (c * 7 + r * 3) % 11 == 0;
                u8::from(!(in_hole || speck))
            })
            .collect()
    }

    /// Bends and shears the sheet so that every region has its own rotation.
    fn deform(lattice: &mut Lattice) {
        let layout = lattice.layout().clone();
        let mut positions = vec![0.0f32; 3 * layout.particle_count()];
        for p in 0..layout.particle_count() {
            let [x, _, z] = layout.rest_position(layout.site_of_particle(p));
            let y = 0.3 * (2.0 * x).sin() * (1.5 * z).cos() + 0.1 * x * z;
            positions[3 * p..3 * p + 3].copy_from_slice(&[(x + 0.05 * z) as f32, y as f32, (z * 1.1) as f32]);
        }
        lattice.set_positions(&positions).unwrap();
    }

    fn max_difference(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
        a.iter().zip(b).flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs())).fold(0.0, f64::max)
    }

    #[test]
    fn fast_goals_agree_with_the_naive_definition_with_holes_and_several_w() {
        for (columns, rows) in [(17usize, 13usize), (40, 37)] {
            let mask = holey_mask(columns, rows);
            for w in [1, 2, 3, 5, 8] {
                for damping in [0.0, 0.3] {
                    let p = LatticeParams { damping, ..params(columns as u32, rows as u32, w) };
                    let mut lattice = Lattice::new(p, Some(&mask)).unwrap();
                    deform(&mut lattice);
                    let fast = lattice.goals();
                    let naive = naive_goals(&lattice);
                    let err = max_difference(&fast, &naive);
                    assert!(err < 1e-11, "{columns}x{rows} w={w}: fast and naive goals differ by {err}");
                    // And after steps (rotations warm-started, velocities nonzero).
                    for _ in 0..3 {
                        lattice.step().unwrap();
                    }
                    let err = max_difference(&lattice.goals(), &naive_goals(&lattice));
                    assert!(err < 1e-11, "{columns}x{rows} w={w} after steps: {err}");
                }
            }
        }
    }

    #[test]
    fn at_rest_it_stays_at_rest_and_a_rigid_rotation_is_reproduced() {
        let p = LatticeParams { gravity: [0.0; 3], ..params(12, 9, 2) };
        let mut lattice = Lattice::new(p, Some(&holey_mask(12, 9))).unwrap();
        let start = lattice.site_positions().to_vec();
        for _ in 0..10 {
            let stats = lattice.step().unwrap();
            assert!(stats.goal_distance < 1e-13, "{stats:?}");
        }
        assert!(max_difference(lattice.site_positions(), &start) < 1e-13);

        let q = DMat3::from_axis_angle(DVec3::new(0.3, -0.8, 0.5).normalize(), 2.2);
        let shift = DVec3::new(1.0, 2.0, -3.0);
        let count = lattice.particle_count();
        let mut positions = vec![0.0f32; 3 * count];
        for i in 0..count {
            let x = q * DVec3::from(lattice.layout().rest_position(lattice.layout().site_of_particle(i))) + shift;
            positions[3 * i..3 * i + 3].copy_from_slice(&x.as_vec3().to_array());
        }
        lattice.set_positions(&positions).unwrap();
        let moved = lattice.site_positions().to_vec();
        // f32 inputs are a rigid motion only to f32 rounding.
        for _ in 0..20 {
            let stats = lattice.step().unwrap();
            assert!(stats.goal_distance < 1e-6, "{stats:?}");
        }
        assert!(max_difference(lattice.site_positions(), &moved) < 1e-5);
    }

    #[test]
    fn results_do_not_depend_on_the_thread_count() {
        let run = |threads| {
            let p = LatticeParams { threads, damping: 0.2, ..params(70, 75, 3) };
            let mut lattice = Lattice::new(p, Some(&holey_mask(70, 75))).unwrap();
            lattice.pin(1, 0, true).unwrap();
            lattice.pin(69, 1, true).unwrap();
            for step in 0..15 {
                if step < 3 {
                    lattice.apply_force(35, 40, [0.0, 5.0, 1.0]).unwrap();
                }
                lattice.step().unwrap();
            }
            lattice.site_positions().to_vec()
        };
        let one = run(1);
        assert_eq!(one, run(2));
        assert_eq!(one, run(4));
    }

    #[test]
    fn divergence_rolls_back() {
        let mut lattice = Lattice::new(params(6, 5, 1), None).unwrap();
        lattice.step().unwrap();
        let before = lattice.site_positions().to_vec();
        lattice.apply_force(2, 2, [3e38, 0.0, 0.0]).unwrap();
        lattice.apply_force(2, 2, [3e38, 0.0, 0.0]).unwrap();
        let error = lattice.step().unwrap_err();
        assert_eq!(error.kind, crate::error::ErrorKind::Unstable);
        assert!(error.message.contains("column 2, row 2"), "{}", error.message);
        assert_eq!(lattice.site_positions(), &before[..]);
        assert_eq!(lattice.steps(), 1);
    }

    #[test]
    fn a_single_particle_falls_freely_and_a_rope_hangs() {
        // One particle: its region is itself (A = 0, the warm start keeps R), its goal is where
        // it is, so it falls exactly as symplectic Euler says.
        let p = LatticeParams { velocity_damping: 0.0, damping: 0.0, ..params(1, 1, 1) };
        let mut lattice = Lattice::new(p, None).unwrap();
        let h = p.time_step as f64;
        let g = p.gravity[1] as f64;
        let mut expected = 0.0;
        let mut speed = 0.0;
        for _ in 0..30 {
            lattice.step().unwrap();
            speed += g * h;
            expected += speed * h;
        }
        assert!((lattice.site_positions()[0][1] - expected).abs() < 1e-12);

        // A rope (one column): every region has rank 1, so the warm-started fallback turns it.
        let p = LatticeParams { damping: 0.2, velocity_damping: 2.0, ..params(1, 12, 2) };
        let mut rope = Lattice::new(p, None).unwrap();
        rope.pin(0, 0, true).unwrap();
        for _ in 0..3000 {
            rope.step().unwrap();
        }
        let x = rope.site_positions();
        assert!(x.iter().flatten().all(|v| v.is_finite()));
        let end = x[11];
        assert!(end[1] < -0.5 * 11.0 * 0.1, "the rope hangs down: end at {end:?}");
        assert!(end[0].abs() < 0.05 && end[2].abs() < 0.3 * 1.1, "{end:?}");
    }
}
