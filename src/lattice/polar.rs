//! The rotation of a region: the polar decomposition `A = R S` by SVD (SPEC 3).
//!
//! The rest points of a lattice region are coplanar, so `A = sum m (x - c)(x0 - c0)^T` has rank
//! at most 2 and the polar decompositions that assume an invertible A (`R = A (A^T A)^-1/2`,
//! Newton iterations) fail on it. This one works from the SVD `A = U diag(s1, s2, s3) V^T`:
//! V from the eigenvectors of `A^T A` (cyclic Jacobi), `u_i = A v_i / s_i` for the two largest
//! singular values only, and the third column completed as `u3 = u1 x u2`, `v3 = v1 x v2`. That
//! is the reflection fix `R = U diag(1, 1, det(U V^T)) V^T` of a plain SVD: R is always a proper
//! rotation, and the best one (largest `tr(R^T A)`) even when A is flat or inverted.
//!
//! Warm start: each region keeps its previous rotation. Where A does not determine R (a region
//! squeezed onto a line, rank 1, or onto a point, rank 0) the previous rotation fills in what is
//! missing, so a region never flips at random. (The eigenbasis itself needs no warm start here:
//! a flat region's `A^T A` has a zero row and column, so a single exact Jacobi rotation
//! diagonalises it.)

use glam::{DMat3, DVec3};

/// Relative size below which the second singular value counts as zero (rank 1).
const RANK_TOLERANCE: f64 = 1e-6;

/// The rotation closest to `a` (largest `tr(R^T a)`), SPEC 3. `previous` is the region's rotation
/// from the last step (the warm start); `tiny` is the absolute singular value below which `a`
/// counts as zero (then `previous` is returned).
pub(crate) fn polar_rotation(a: DMat3, previous: DMat3, tiny: f64) -> DMat3 {
    let (sigma_sq, v) = symmetric_eigen(a.transpose() * a);
    // Order by decreasing eigenvalue.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| sigma_sq[j].total_cmp(&sigma_sq[i]));
    let s1 = sigma_sq[order[0]].max(0.0).sqrt();
    let s2 = sigma_sq[order[1]].max(0.0).sqrt();
    if !s1.is_finite() || s1 <= tiny {
        return previous;
    }
    let v1 = v.col(order[0]);
    let v2 = v.col(order[1]);
    let u1 = (a * v1) / s1;
    let u1 = u1.normalize_or_zero();
    if u1 == DVec3::ZERO {
        return previous;
    }
    if s2 > RANK_TOLERANCE * s1 && s2 > tiny {
        let u2 = a * v2;
        let u2 = (u2 - u1 * u1.dot(u2)).normalize_or_zero();
        if u2 != DVec3::ZERO {
            let v3 = v1.cross(v2);
            let u3 = u1.cross(u2);
            return outer(u1, v1) + outer(u2, v2) + outer(u3, v3);
        }
    }
    // Rank 1: only v1 -> u1 is known. Turn the previous rotation by the smallest rotation that
    // takes its image of v1 onto u1: R v1 = u1, and R stays as close to `previous` as it can.
    rotation_between((previous * v1).normalize_or_zero(), u1) * previous
}

/// [`polar_rotation`] for a flat region, `A = [ax, 0, az]` (the rest lies in the x-z plane, so
/// A's y column is zero): `A^T A` reduces to the 2x2 block of `ax`, `az`, whose eigenvectors one
/// exact Jacobi rotation gives, and R's x and z columns are `sum_i u_i v_i^T` over the two
/// nonzero singular values (`v3 = e_y` only reaches R's y column, which is `R e_z x R e_x`).
/// Returns R's x and z columns. Rank-deficient regions go to the general routine, which has the
/// warm-start fallback.
#[inline]
pub(crate) fn polar_rotation_flat(ax: DVec3, az: DVec3, previous: DMat3, tiny: f64) -> (DVec3, DVec3) {
    let (cxx, cxz, czz) = (ax.dot(ax), ax.dot(az), az.dot(az));
    // One Jacobi rotation diagonalises the symmetric 2x2 [[cxx, cxz], [cxz, czz]] exactly.
    let (c, s, lx, lz) = if cxz == 0.0 {
        (1.0, 0.0, cxx, czz)
    } else {
        let theta = (czz - cxx) / (2.0 * cxz);
        let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
        let c = 1.0 / (t * t + 1.0).sqrt();
        (c, t * c, cxx - t * cxz, czz + t * cxz)
    };
    // Eigenvectors in (x, z): (c, -s) for lx, (s, c) for lz.
    let ((v1, l1), (v2, l2)) = if lx >= lz { (((c, -s), lx), ((s, c), lz)) } else { (((s, c), lz), ((c, -s), lx)) };
    // Rank 2 (s2 > RANK_TOLERANCE s1, both above tiny), tested on the squares: no square roots.
    if l1 > tiny * tiny && l1.is_finite() && l2 > RANK_TOLERANCE * RANK_TOLERANCE * l1 && l2 > tiny * tiny {
        // u_i = A v_i / s_i, normalised anyway, so the division by s_i is left out.
        let u1 = (ax * v1.0 + az * v1.1).normalize_or_zero();
        let u2 = ax * v2.0 + az * v2.1;
        let u2 = (u2 - u1 * u1.dot(u2)).normalize_or_zero();
        if u1 != DVec3::ZERO && u2 != DVec3::ZERO {
            return (u1 * v1.0 + u2 * v2.0, u1 * v1.1 + u2 * v2.1);
        }
    }
    let r = polar_rotation(DMat3::from_cols(ax, DVec3::ZERO, az), previous, tiny);
    (r.x_axis, r.z_axis)
}

/// `a b^T`.
#[inline]
fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// The smallest rotation taking unit vector `from` to unit vector `to` (Rodrigues).
fn rotation_between(from: DVec3, to: DVec3) -> DMat3 {
    if from == DVec3::ZERO {
        return DMat3::IDENTITY;
    }
    let c = from.dot(to);
    if c < -1.0 + 1e-12 {
        // Opposite: half a turn about any axis perpendicular to `from`.
        let axis = from.any_orthonormal_vector();
        return DMat3::from_axis_angle(axis, std::f64::consts::PI);
    }
    let k = from.cross(to);
    let kx = DMat3::from_cols(DVec3::new(0.0, k.z, -k.y), DVec3::new(-k.z, 0.0, k.x), DVec3::new(k.y, -k.x, 0.0));
    DMat3::IDENTITY + kx + kx * kx * (1.0 / (1.0 + c))
}

/// Eigenvalues and eigenvectors (columns of the returned matrix, a proper rotation) of a
/// symmetric 3x3 matrix, by cyclic Jacobi rotations.
pub(crate) fn symmetric_eigen(m: DMat3) -> ([f64; 3], DMat3) {
    let mut a = m.to_cols_array_2d(); // a[col][row]; symmetric, so a[i][j] is entry (i, j) either way
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]; // v[col][row]
    let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
    for _sweep in 0..16 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        if off <= (1e-30 * scale) * scale || off == 0.0 {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            let apq = a[p][q];
            if apq == 0.0 {
                continue;
            }
            // Numerical Recipes' Jacobi rotation that zeroes a_pq.
            let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            a[p][p] -= t * apq;
            a[q][q] += t * apq;
            a[p][q] = 0.0;
            a[q][p] = 0.0;
            let r = 3 - p - q;
            let (arp, arq) = (a[r][p], a[r][q]);
            a[r][p] = c * arp - s * arq;
            a[p][r] = a[r][p];
            a[r][q] = s * arp + c * arq;
            a[q][r] = a[r][q];
            let (vp, vq) = (v[p], v[q]);
            for k in 0..3 {
                v[p][k] = c * vp[k] - s * vq[k];
                v[q][k] = s * vp[k] + c * vq[k];
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2]], DMat3::from_cols_array_2d(&v))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rotation(axis: DVec3, angle: f64) -> DMat3 {
        DMat3::from_axis_angle(axis.normalize(), angle)
    }

    fn close(a: DMat3, b: DMat3, tol: f64) -> bool {
        (a - b).to_cols_array().iter().all(|d| d.abs() <= tol)
    }

    fn is_rotation(r: DMat3) -> bool {
        close(r.transpose() * r, DMat3::IDENTITY, 1e-12) && (r.determinant() - 1.0).abs() < 1e-12
    }

    /// A flat region's A: the y column is zero, as for every lattice region.
    fn flat_stretch(sx: f64, sz: f64, shear: f64) -> DMat3 {
        DMat3::from_cols(DVec3::new(sx, 0.0, shear), DVec3::ZERO, DVec3::new(shear, 0.0, sz))
    }

    #[test]
    fn eigen_decomposition_reconstructs() {
        let m = DMat3::from_cols(DVec3::new(4.0, 1.0, -2.0), DVec3::new(1.0, 3.0, 0.5), DVec3::new(-2.0, 0.5, 5.0));
        let (l, v) = symmetric_eigen(m);
        let back = v * DMat3::from_diagonal(DVec3::from(l)) * v.transpose();
        assert!(close(back, m, 1e-12));
        assert!(is_rotation(v));
    }

    #[test]
    fn rank_two_flat_regions_give_the_rotation_back() {
        let prev = DMat3::IDENTITY;
        for (i, (axis, angle)) in
            [(DVec3::Y, 0.3), (DVec3::X, 2.9), (DVec3::new(1.0, 2.0, -0.5), -1.7), (DVec3::new(0.2, -1.0, 0.9), 3.1)]
                .into_iter()
                .enumerate()
        {
            let q = rotation(axis, angle);
            let s = flat_stretch(1.3 + i as f64 * 0.1, 0.7, 0.2);
            let r = polar_rotation(q * s, prev, 1e-30);
            assert!(is_rotation(r), "{r}");
            assert!(close(r, q, 1e-12), "case {i}: {r} vs {q}");
        }
    }

    #[test]
    fn the_flat_shortcut_matches_the_general_routine() {
        let prev = rotation(DVec3::new(0.1, 1.0, 0.3), 0.4);
        let mut seed = 11u64;
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64) / ((1u64 << 53) as f64) * 2.0 - 1.0
        };
        for _ in 0..200 {
            let ax = DVec3::new(next(), next(), next());
            let az = DVec3::new(next(), next(), next());
            let general = polar_rotation(DMat3::from_cols(ax, DVec3::ZERO, az), prev, 1e-30);
            let (rx, rz) = polar_rotation_flat(ax, az, prev, 1e-30);
            assert!((rx - general.x_axis).length() < 1e-9 && (rz - general.z_axis).length() < 1e-9);
        }
        // Rank 1 and 0 fall back to the general routine's warm start.
        let (rx, rz) = polar_rotation_flat(DVec3::ZERO, DVec3::ZERO, prev, 1e-9);
        assert_eq!((rx, rz), (prev.x_axis, prev.z_axis));
        let (rx, _) = polar_rotation_flat(DVec3::X * 2.0, DVec3::ZERO, prev, 1e-9);
        assert!((rx - DVec3::X).length() < 1e-12);
    }

    #[test]
    fn reflections_are_fixed_and_the_result_is_the_best_rotation() {
        // A mirrored full-rank A (det < 0) and a flat region folded over (in-plane mirror).
        let mirror = DMat3::from_diagonal(DVec3::new(1.0, 1.0, -1.0));
        let cases = [
            rotation(DVec3::new(1.0, 1.0, 0.0), 0.4) * mirror * DMat3::from_diagonal(DVec3::new(2.0, 1.0, 0.5)),
            rotation(DVec3::Z, 0.8) * DMat3::from_diagonal(DVec3::new(1.0, 0.0, -0.6)),
            DMat3::from_cols(DVec3::new(0.3, -1.2, 0.4), DVec3::new(0.9, 0.1, -0.2), DVec3::new(-0.5, 0.7, 1.1)),
        ];
        for a in cases {
            let r = polar_rotation(a, DMat3::IDENTITY, 1e-30);
            assert!(is_rotation(r), "{r}");
            let best = (r.transpose() * a).to_cols_array();
            let trace = best[0] + best[4] + best[8];
            // No nearby rotation does better.
            for axis in [DVec3::X, DVec3::Y, DVec3::Z, DVec3::new(1.0, -1.0, 2.0)] {
                for angle in [-0.05, -0.001, 0.001, 0.05] {
                    let other = rotation(axis, angle) * r;
                    let o = (other.transpose() * a).to_cols_array();
                    assert!(o[0] + o[4] + o[8] <= trace + 1e-12, "a rotation near R fits A better");
                }
            }
        }
    }

    #[test]
    fn degenerate_regions_keep_the_warm_start() {
        let prev = rotation(DVec3::new(0.3, 1.0, 0.2), 0.7);
        // Rank 0: nothing known, the previous rotation stays.
        assert_eq!(polar_rotation(DMat3::ZERO, prev, 1e-9), prev);
        // Rank 1: the region squeezed onto a line along prev's image of x, slightly turned.
        let q = rotation(DVec3::Z, 0.1);
        let line = outer(q * prev * DVec3::X, DVec3::X) * 2.0;
        let r = polar_rotation(line, prev, 1e-9);
        assert!(is_rotation(r));
        assert!((r * DVec3::X - q * prev * DVec3::X).length() < 1e-12);
        assert!(close(r, q * prev, 0.2), "stays near the warm start");
        // And with a line exactly along the previous image, R is the previous rotation.
        let r = polar_rotation(outer(prev * DVec3::X, DVec3::X), prev, 1e-9);
        assert!(close(r, prev, 1e-12));
    }
}
