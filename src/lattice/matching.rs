//! Shape matching of one region and the goal of one particle (SPEC 3), as pure functions of the
//! box sums, so that the fast step and the naive reference share every formula except the sums.
//!
//! Particle moments (channels of the particles-to-regions sum), with `x' = x - o` (o a reference
//! point: positions relative to it cancel less) and `x0 = (x0x, 0, x0z)` the centred rest:
//! `[m~ x', m~ x' x0x, m~ x' x0z]` (9 values; the x0 y column of `x x0^T` is always zero).
//! Region fit from their sums: `c = S_x / M`, `A = [S_xx - M c c0x, 0, S_xz - M c c0z]`,
//! `R = polar(A)`, `t = c - R c0`; the region hands `[R e_x, R e_z, t]` back to its particles,
//! whose goal is the mean over their regions: `g = (sum R e_x x0x + sum R e_z x0z + sum t) / |R_s|`.

use glam::{DMat3, DVec3};

use super::polar::polar_rotation_flat;

/// Channels of the particle moments for shape matching.
pub(crate) const MOMENT_CHANNELS: usize = 9;
/// Channels a region hands back for the goals: `R e_x`, `R e_z`, `t`.
pub(crate) const FIT_CHANNELS: usize = 9;

/// Rest data of the region centred on a site (precomputed once).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct RegionRest {
    /// `m~_s = m_s / |R_s|`: the particle's mass share (0 for a hole).
    pub share: f64,
    /// `1 / |R_s|`, the number of regions containing the particle (0 for a hole).
    pub inv_count: f64,
    /// `M_r = sum m~` over the region.
    pub mass: f64,
    /// Rest centroid `c0_r` (x, z), centred coordinates.
    pub c0: [f64; 2],
}

/// The stored rotation of a region: its x and z columns (`R e_y = R e_z x R e_x`).
pub(crate) type RotationColumns = [f64; 6];

/// The identity rotation, stored.
pub(crate) const IDENTITY_COLUMNS: RotationColumns = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0];

/// Writes the shape-matching moments of one particle into `out` (9 values).
#[inline]
pub(crate) fn particle_moments(share: f64, xp: [f64; 3], x0: [f64; 2], out: &mut [f64]) {
    let m = [share * xp[0], share * xp[1], share * xp[2]];
    out[0..3].copy_from_slice(&m);
    out[3..6].copy_from_slice(&[m[0] * x0[0], m[1] * x0[0], m[2] * x0[0]]);
    out[6..9].copy_from_slice(&[m[0] * x0[1], m[1] * x0[1], m[2] * x0[1]]);
}

/// Expands stored columns into the full rotation.
#[inline]
pub(crate) fn rotation_from_columns(r: &RotationColumns) -> DMat3 {
    let rx = DVec3::new(r[0], r[1], r[2]);
    let rz = DVec3::new(r[3], r[4], r[5]);
    DMat3::from_cols(rx, rz.cross(rx), rz)
}

/// Fits a region to its particles from the summed moments `sums` (9 values): returns the new
/// stored rotation, the translation `t` and the centroid `c` (relative to o). `previous` is the
/// region's last rotation (the polar warm start); `tiny` the singular value that counts as zero.
#[inline]
pub(crate) fn fit_region(
    sums: &[f64],
    rest: &RegionRest,
    previous: &RotationColumns,
    tiny: f64,
) -> (RotationColumns, [f64; 3], DVec3) {
    let m = rest.mass;
    let c = DVec3::new(sums[0], sums[1], sums[2]) / m;
    // SPEC 3: A = sum m~ x x0^T - M c c0^T (the y column is zero for the flat rest).
    let ax = DVec3::new(sums[3], sums[4], sums[5]) - c * (m * rest.c0[0]);
    let az = DVec3::new(sums[6], sums[7], sums[8]) - c * (m * rest.c0[1]);
    let (rx, rz) = polar_rotation_flat(ax, az, rotation_from_columns(previous), tiny);
    // SPEC 3: t = c - R c0.
    let t = c - rx * rest.c0[0] - rz * rest.c0[1];
    let stored = [rx.x, rx.y, rx.z, rz.x, rz.y, rz.z];
    (stored, t.to_array(), c)
}

/// Writes what a region hands back to its particles: `[R e_x, R e_z, t]`.
#[inline]
pub(crate) fn fit_channels(rotation: &RotationColumns, t: [f64; 3], out: &mut [f64]) {
    out[0..6].copy_from_slice(rotation);
    out[6..9].copy_from_slice(&t);
}

/// The goal of a particle (relative to o) from the summed fit channels of its regions:
/// SPEC 3, `g_s = (1/|R_s|) sum_r (R_r x0_s + t_r)`.
#[inline]
pub(crate) fn goal(sums: &[f64], x0: [f64; 2], inv_count: f64) -> [f64; 3] {
    [
        (sums[0] * x0[0] + sums[3] * x0[1] + sums[6]) * inv_count,
        (sums[1] * x0[0] + sums[4] * x0[1] + sums[7]) * inv_count,
        (sums[2] * x0[0] + sums[5] * x0[1] + sums[8]) * inv_count,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rigidly_moved_region_fits_exactly() {
        // Nine particles of a 3x3 region, rest spacing 0.1, moved by a rotation and a shift.
        let q = DMat3::from_axis_angle(DVec3::new(0.4, 1.0, -0.3).normalize(), 1.1);
        let shift = DVec3::new(0.3, -2.0, 0.7);
        let mut sums = [0.0; 9];
        let mut rest = RegionRest { share: 1.0, inv_count: 1.0, mass: 0.0, c0: [0.0; 2] };
        let mut one = [0.0; 9];
        let mut points = Vec::new();
        for i in 0..3 {
            for k in 0..3 {
                let x0 = [0.1 * i as f64 + 0.05, 0.1 * k as f64 - 0.2];
                let x = q * DVec3::new(x0[0], 0.0, x0[1]) + shift;
                let share = 0.5 + 0.1 * (i + k) as f64;
                particle_moments(share, x.to_array(), x0, &mut one);
                sums.iter_mut().zip(&one).for_each(|(s, o)| *s += o);
                rest.mass += share;
                rest.c0[0] += share * x0[0];
                rest.c0[1] += share * x0[1];
                points.push((x0, x));
            }
        }
        rest.c0 = [rest.c0[0] / rest.mass, rest.c0[1] / rest.mass];
        let (rot, t, _c) = fit_region(&sums, &rest, &IDENTITY_COLUMNS, 1e-20);
        let r = rotation_from_columns(&rot);
        assert!((r - q).to_cols_array().iter().all(|d| d.abs() < 1e-12));
        let mut back = [0.0; 9];
        fit_channels(&rot, t, &mut back);
        for (x0, x) in points {
            let g = goal(&back, x0, 1.0);
            assert!((DVec3::from(g) - x).length() < 1e-12);
        }
    }
}
