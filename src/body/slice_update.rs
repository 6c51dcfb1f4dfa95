//! The last pass of an implicit substep on eight rows at a time: `v += Δv`, `x += h v` (SPEC
//! 2.2) and the test whether any of the eight rows went into an obstacle, for slices whose rows
//! all move and touch nothing. One row at a time, with its checks and the obstacles' loop, this
//! took about 50 instructions a row (the pass about 5% of a step on two threads on the issue-5
//! balloon); the rows that need more (friction, a contact response, a pin) go one at a time as
//! before. The operations and their order are those of the row-by-row pass, so every row gets
//! the same bits either way (tested).

use glam::{Vec3, Vec3A};

#[cfg(target_arch = "x86_64")]
use super::coupling_slices::{SLICE, load_points_transposed};
use super::obstacles::Obstacle;

/// The obstacles as (point, unit normal) into `planes` (cleared first; a buffer kept from
/// substep to substep, so this allocates nothing once it has grown): true when they are all
/// planes (a slice's test then needs no square root).
pub(crate) fn planes_of(obstacles: &[Obstacle], planes: &mut Vec<(Vec3, Vec3)>) -> bool {
    planes.clear();
    for obstacle in obstacles {
        match *obstacle {
            Obstacle::Plane { point, normal } => planes.push((point, normal)),
            Obstacle::Sphere { .. } => return false,
        }
    }
    true
}

/// What [`update_slice_avx2`] found in its eight rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct SliceUpdate {
    /// Every position and velocity is finite.
    pub finite: bool,
    /// Some row is behind a plane (`Obstacle::distance` not at least 0, NaN included): the
    /// caller resolves the slice's contacts one row at a time.
    pub inside: bool,
}

/// Rows `first..first + 8` of `x` and `v`: `v += Δv` (`dv` indexed from the same first row as
/// `x` and `v`), then `x += v h`, each an addition and a multiplication per component as
/// `Vec3` computes them (no fused multiply-add), and whether a row is now behind one of the
/// `planes` (the signed distance `(x - point)·normal` as `Vec3::dot` sums it).
///
/// # Safety
/// The processor must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn update_slice_avx2(
    x: &mut [Vec3],
    v: &mut [Vec3],
    dv: &[Vec3A],
    first: usize,
    h: f32,
    planes: &[(Vec3, Vec3)],
) -> SliceUpdate {
    use std::arch::x86_64::*;
    let (x8, v8, dv8) = (&mut x[first..first + SLICE], &mut v[first..first + SLICE], &dv[first..first + SLICE]);
    // SAFETY: 24 f32 of x and of v, 32 of Δv (eight Vec3 and eight Vec3A), unaligned.
    unsafe {
        let (xp, vp, dp) = (x8.as_mut_ptr() as *mut f32, v8.as_mut_ptr() as *mut f32, dv8.as_ptr() as *const f32);
        // Δv's eight rows of four lanes packed into three registers of x y z triples.
        let (d01, d23, d45, d67) =
            (_mm256_loadu_ps(dp), _mm256_loadu_ps(dp.add(8)), _mm256_loadu_ps(dp.add(16)), _mm256_loadu_ps(dp.add(24)));
        let pick = |v: __m256, lanes: [i32; 8]| {
            _mm256_permutevar8x32_ps(
                v,
                _mm256_setr_epi32(lanes[0], lanes[1], lanes[2], lanes[3], lanes[4], lanes[5], lanes[6], lanes[7]),
            )
        };
        // x0 y0 z0 x1 y1 z1 x2 y2 | z2 x3 y3 z3 x4 y4 z4 x5 | y5 z5 x6 y6 z6 x7 y7 z7
        let packed = [
            _mm256_blend_ps::<0b1100_0000>(pick(d01, [0, 1, 2, 4, 5, 6, 0, 0]), pick(d23, [0, 0, 0, 0, 0, 0, 0, 1])),
            _mm256_blend_ps::<0b1111_0000>(pick(d23, [2, 4, 5, 6, 0, 0, 0, 0]), pick(d45, [0, 0, 0, 0, 0, 1, 2, 4])),
            _mm256_blend_ps::<0b1111_1100>(pick(d45, [5, 6, 0, 0, 0, 0, 0, 0]), pick(d67, [0, 0, 0, 1, 2, 4, 5, 6])),
        ];
        let hv = _mm256_set1_ps(h);
        let magnitude = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFF_FFFF));
        let infinity = _mm256_set1_ps(f32::INFINITY);
        let mut finite = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
        for (q, d) in packed.iter().enumerate() {
            let vq = _mm256_add_ps(_mm256_loadu_ps(vp.add(8 * q)), *d);
            _mm256_storeu_ps(vp.add(8 * q), vq);
            let xq = _mm256_add_ps(_mm256_loadu_ps(xp.add(8 * q)), _mm256_mul_ps(vq, hv));
            _mm256_storeu_ps(xp.add(8 * q), xq);
            // |value| < ∞: false for an infinity and for NaN.
            finite = _mm256_and_ps(finite, _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_and_ps(vq, magnitude), infinity));
            finite = _mm256_and_ps(finite, _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_and_ps(xq, magnitude), infinity));
        }
        let mut inside = false;
        if !planes.is_empty() {
            let (px, py, pz) = load_points_transposed(x, first);
            for &(point, normal) in planes {
                let depth = plane_distances((px, py, pz), point, normal);
                // Not `depth >= 0` (NaN included), as `resolve` tests it before it skips a plane.
                inside |= _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_NGE_UQ>(depth, _mm256_setzero_ps())) != 0;
            }
        }
        SliceUpdate { finite: _mm256_movemask_ps(finite) == 0xFF, inside }
    }
}

/// The signed distances `(x - point)·normal` of eight points (x, y and z lanes) from a plane,
/// as `Obstacle::distance` computes one (`Vec3::dot`'s order, no fused multiply-add).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) fn plane_distances(
    (px, py, pz): (std::arch::x86_64::__m256, std::arch::x86_64::__m256, std::arch::x86_64::__m256),
    point: Vec3,
    normal: Vec3,
) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    let dx = _mm256_sub_ps(px, _mm256_set1_ps(point.x));
    let dy = _mm256_sub_ps(py, _mm256_set1_ps(point.y));
    let dz = _mm256_sub_ps(pz, _mm256_set1_ps(point.z));
    _mm256_add_ps(
        _mm256_add_ps(_mm256_mul_ps(dx, _mm256_set1_ps(normal.x)), _mm256_mul_ps(dy, _mm256_set1_ps(normal.y))),
        _mm256_mul_ps(dz, _mm256_set1_ps(normal.z)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random rows, some behind the ground or a tilted plane, one with an infinite velocity:
    /// the eight rows at once are the rows one at a time, to the bit, and say which slices
    /// went inside and which are not finite.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn eight_rows_at_once_are_the_rows_one_at_a_time() {
        if !(std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")) {
            return;
        }
        let mut unit = crate::body::test_randoms(0x51ce_0dd5_7a7e_0042);
        // 41 rows: five slices and a row after them (the last slices' positions are read with
        // the row after them, the last one's without: `load_points_transposed`'s two ways).
        let n = 41;
        let x0: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), 0.3 + unit().abs(), unit())).collect();
        let mut v0: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), unit(), unit()) * 2.0).collect();
        let dv: Vec<Vec3A> = (0..n).map(|_| Vec3A::from_vec4(glam::Vec4::new(unit(), unit(), unit(), 7.0))).collect();
        // Slice 1 falls through the ground, slice 3 has an infinite velocity.
        for k in 8..16 {
            v0[k].y = -40.0;
        }
        v0[27].x = f32::INFINITY;
        let h = 1.0 / 60.0;
        let ground = (Vec3::ZERO, Vec3::Y);
        let tilted = (Vec3::new(0.0, 0.1, 0.0), Vec3::new(0.6, 0.8, 0.0));
        for planes in [vec![], vec![ground], vec![ground, tilted]] {
            let (mut x, mut v) = (x0.clone(), v0.clone());
            let mut found = Vec::new();
            for first in (0..n - 1).step_by(SLICE) {
                // The last slice as the last of a chunk (no row after it).
                let rows = if first + SLICE == n - 1 { n - 1 } else { n };
                // SAFETY: AVX2 and FMA (checked above).
                found
                    .push(unsafe { update_slice_avx2(&mut x[..rows], &mut v[..rows], &dv[..rows], first, h, &planes) });
            }
            for k in 0..n - 1 {
                let mut vk = v0[k];
                vk += Vec3::from(dv[k]);
                let xk = x0[k] + vk * h;
                assert_eq!(
                    (x[k].to_array().map(f32::to_bits), v[k].to_array().map(f32::to_bits)),
                    (xk.to_array().map(f32::to_bits), vk.to_array().map(f32::to_bits)),
                    "row {k}"
                );
            }
            assert_eq!((x[n - 1], v[n - 1]), (x0[n - 1], v0[n - 1]), "the row after the slices is untouched");
            for (s, update) in found.iter().enumerate() {
                let rows = s * SLICE..(s + 1) * SLICE;
                // (`resolve`'s test: a plane is skipped only at a depth of at least 0, not NaN.)
                let inside = rows.clone().any(|k| planes.iter().any(|&(p, nrm)| !((x[k] - p).dot(nrm) >= 0.0)));
                let finite = rows.clone().all(|k| x[k].is_finite() && v[k].is_finite());
                assert_eq!(*update, SliceUpdate { finite, inside }, "slice {s} with {} planes", planes.len());
            }
            assert!(found[1].inside == !planes.is_empty() && !found[3].finite);
            if planes.len() < 2 {
                // (The tilted plane cuts through most slices.)
                assert!(found.iter().filter(|u| u.finite && !u.inside).count() >= 3, "slices on the fast path");
            }
        }
    }
}
