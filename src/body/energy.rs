//! Energies for the error report and the divergence check (SPEC 2.2, 4), and the stable time
//! step estimate `2/ω_max` with `ω_max² ≈ max_i 2 w_i Σ_{springs at i} K_s` (Gershgorin).

use glam::Vec3;

use super::springs::{Springs, spring_energy, spring_strain};
use crate::parallel::WorkerPool;

/// Kinetic energy `Σ m v²/2`, J.
pub(crate) fn kinetic(mass: &[f32], v: &[Vec3]) -> f64 {
    mass.iter().zip(v).map(|(&m, v)| 0.5 * m as f64 * v.as_dvec3().length_squared()).sum()
}

/// Springs per parallel chunk (fixed, so the sums do not depend on the thread count).
const SPRING_CHUNK: usize = 4096;

/// Spring energy (J) and the largest spring strain (0 when none is stretched), in one pass: the
/// end-of-step stats need both (SPEC 2.5), and each needs every spring's length.
pub(crate) fn springs_and_max_strain(pool: &WorkerPool, springs: &Springs, x: &[Vec3], ks: f32) -> (f64, f32) {
    let chunks = springs.len().div_ceil(SPRING_CHUNK);
    let parts = pool.map_collect(chunks, |c| {
        let range = c * SPRING_CHUNK..((c + 1) * SPRING_CHUNK).min(springs.len());
        let (mut energy, mut strain) = (0.0f64, 0.0f32);
        for (&[i, j], &rest) in springs.ends[range.clone()].iter().zip(&springs.rest[range]) {
            let (xi, xj) = (x[i as usize], x[j as usize]);
            energy += spring_energy(xi, xj, rest, ks);
            strain = strain.max(spring_strain(xi, xj, rest));
        }
        (energy, strain)
    });
    parts.iter().fold((0.0, 0.0f32), |(e, s), &(pe, ps)| (e + pe, s.max(ps)))
}

/// Gravitational energy `-Σ m g·x`, J.
pub(crate) fn gravity(mass: &[f32], x: &[Vec3], g: Vec3) -> f64 {
    let g = g.as_dvec3();
    -mass.iter().zip(x).map(|(&m, x)| m as f64 * g.dot(x.as_dvec3())).sum::<f64>()
}

/// Total momentum `Σ m v`, kg m/s.
pub(crate) fn momentum(mass: &[f32], v: &[Vec3]) -> glam::DVec3 {
    mass.iter().zip(v).map(|(&m, v)| m as f64 * v.as_dvec3()).sum()
}

/// Largest angular frequency of the spring network, rad/s (upper bound).
pub(crate) fn omega_max(springs: &Springs, inv_mass: &[f32], ks: f32) -> f64 {
    let mut stiffness = vec![0.0f64; inv_mass.len()];
    for &[i, j] in &springs.ends {
        stiffness[i as usize] += ks as f64;
        stiffness[j as usize] += ks as f64;
    }
    stiffness.iter().zip(inv_mass).map(|(&k, &w)| 2.0 * k * w as f64).fold(0.0, f64::max).sqrt()
}
