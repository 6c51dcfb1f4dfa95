//! Region damping (SPEC 3, after Müller et al. 2006): each region's velocities are pulled towards
//! the rigid motion (linear and angular momentum) of the region, which removes the wobble inside
//! regions and leaves their rigid motion alone. Like shape matching, every sum is a box sum.
//!
//! Particle channels (12): `[m~ v, m~ x' x v, m~ x'x'^T as xx yy zz xy xz yz]`.
//! Region: `v_cm = S_v / M`, `L = S_xv - M c x v_cm`, `I = tr(X) 1 - X` with
//! `X = S_xx - M c c^T`, `w = I^-1 L`; it hands back `[v_cm - w x c, w]` (6 values), so that a
//! particle's rigid velocity is `(sum a + (sum w) x x') / |R_s|`.

use glam::{DMat3, DVec3};

/// Channels of the particle moments for damping.
pub(crate) const DAMPING_MOMENT_CHANNELS: usize = 12;
/// Channels a region hands back for damping.
pub(crate) const DAMPING_FIT_CHANNELS: usize = 6;

/// Writes the damping moments of one particle (12 values).
#[inline]
pub(crate) fn damping_moments(share: f64, xp: [f64; 3], v: [f64; 3], out: &mut [f64]) {
    let x = DVec3::from(xp);
    let v = DVec3::from(v);
    out[0..3].copy_from_slice(&(v * share).to_array());
    out[3..6].copy_from_slice(&(x.cross(v) * share).to_array());
    out[6..12].copy_from_slice(&[
        share * x.x * x.x,
        share * x.y * x.y,
        share * x.z * x.z,
        share * x.x * x.y,
        share * x.x * x.z,
        share * x.y * x.z,
    ]);
}

/// The rigid motion of a region from its summed damping moments, its mass and centroid `c`:
/// writes `[v_cm - w x c, w]` into `out` (6 values).
#[inline]
pub(crate) fn region_rigid_motion(sums: &[f64], mass: f64, c: DVec3, out: &mut [f64]) {
    let v_cm = DVec3::new(sums[0], sums[1], sums[2]) / mass;
    let l = DVec3::new(sums[3], sums[4], sums[5]) - c.cross(v_cm) * mass;
    let xx = sums[6] - mass * c.x * c.x;
    let yy = sums[7] - mass * c.y * c.y;
    let zz = sums[8] - mass * c.z * c.z;
    let xy = sums[9] - mass * c.x * c.y;
    let xz = sums[10] - mass * c.x * c.z;
    let yz = sums[11] - mass * c.y * c.z;
    let tr = xx + yy + zz;
    let inertia =
        DMat3::from_cols(DVec3::new(tr - xx, -xy, -xz), DVec3::new(-xy, tr - yy, -yz), DVec3::new(-xz, -yz, tr - zz));
    // A region on a line (or a point) has no inertia about some axis: regularise, so that axis
    // just gets no spin. Degenerate guard: no rotation at all when the region has no extent.
    let reg = 1e-9 * tr.abs();
    let omega = if tr > 0.0 {
        let m = inertia + DMat3::from_diagonal(DVec3::splat(reg));
        let det = m.determinant();
        if det.is_finite() && det.abs() > 0.0 { m.inverse() * l } else { DVec3::ZERO }
    } else {
        DVec3::ZERO
    };
    out[0..3].copy_from_slice(&(v_cm - omega.cross(c)).to_array());
    out[3..6].copy_from_slice(&omega.to_array());
}

/// The rigid velocity of a particle at `xp` from the summed damping channels of its regions.
#[inline]
pub(crate) fn rigid_velocity(sums: &[f64], xp: [f64; 3], inv_count: f64) -> DVec3 {
    let a = DVec3::new(sums[0], sums[1], sums[2]);
    let w = DVec3::new(sums[3], sums[4], sums[5]);
    (a + w.cross(DVec3::from(xp))) * inv_count
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rigid_motion_is_its_own_rigid_velocity() {
        let omega = DVec3::new(0.3, -1.2, 0.5);
        let vel = DVec3::new(1.0, 2.0, -0.5);
        let mut sums = [0.0; 12];
        let mut one = [0.0; 12];
        let mut mass = 0.0;
        let mut c = DVec3::ZERO;
        let mut points = Vec::new();
        for i in 0..4 {
            for k in 0..3 {
                let x = DVec3::new(0.1 * i as f64 + 1.0, 0.02 * (i * k) as f64, 0.1 * k as f64 - 3.0);
                let v = vel + omega.cross(x);
                let share = 0.2 + 0.05 * k as f64;
                damping_moments(share, x.to_array(), v.to_array(), &mut one);
                sums.iter_mut().zip(&one).for_each(|(s, o)| *s += o);
                mass += share;
                c += x * share;
                points.push((x, v));
            }
        }
        let mut out = [0.0; 6];
        region_rigid_motion(&sums, mass, c / mass, &mut out);
        for (x, v) in points {
            assert!((rigid_velocity(&out, x.to_array(), 1.0) - v).length() < 1e-7, "{x}");
        }
    }
}
