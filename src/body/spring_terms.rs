//! Each spring's share of the implicit system (SPEC 2.1 force and damping, the stiffness block
//! of `springs`), computed once per spring before the per-vertex assembly gathers it; eight
//! springs at a time with AVX2 where the processor has it.

use glam::{Vec3, Vec3A};

use super::coupling_slices::Coupling;
use super::springs::{is_degenerate, spring_block_coefficients};

/// One spring's share of the assembly, seen from its first end (`Springs::ends[k][0]`): the
/// spring and damping force on it, its `h² K v` term and the coupling block, plus its extension
/// `L - L0` (for the force scale, and for the energy and strain of the state it was made at). The second end takes the vectors negated (`u` and the velocity
/// difference both flip sign, so they are exactly the negated values) and the same block, so
/// each spring is computed once, not once per end.
///
/// 48 bytes (the force unaligned beside the stretch): the assembly gathers these per vertex in
/// an order that jumps about the array, so their size is what that gather waits on.
#[derive(Clone, Copy, Default, Debug, PartialEq)]
pub(crate) struct SpringTerms {
    pub kv: Vec3A,
    pub coupling: Coupling,
    pub force: Vec3,
    pub extension: f32,
}

/// What the terms of every spring depend on.
#[derive(Clone, Copy)]
pub(crate) struct SpringInput<'a> {
    pub ends: &'a [[u32; 2]],
    pub rest: &'a [f32],
    pub x: &'a [Vec3],
    pub v: &'a [Vec3],
    /// `K_s`, `K_d` and the substep length.
    pub stiffness: f32,
    pub damping: f32,
    pub h: f32,
}

/// The terms of spring `k`.
pub(crate) fn spring_terms(input: &SpringInput, k: usize) -> SpringTerms {
    let (ks, kd) = (input.stiffness, input.damping);
    let (h, h2) = (input.h, input.h * input.h);
    let [i, j] = input.ends[k];
    let rest = input.rest[k];
    let d = Vec3A::from(input.x[j as usize]) - Vec3A::from(input.x[i as usize]);
    // The same operations as `Vec3::length`, so the extension is the same bits as the energy's.
    let len = (d.x * d.x + d.y * d.y + d.z * d.z).sqrt();
    if is_degenerate(len, rest) {
        return SpringTerms { extension: len - rest, ..SpringTerms::default() };
    }
    let u = d * (1.0 / len);
    let dvel = Vec3A::from(input.v[j as usize]) - Vec3A::from(input.v[i as usize]);
    let stretch = ks * (len - rest);
    let along = u.x * dvel.x + u.y * dvel.y + u.z * dvel.z;
    let (a, b) = spring_block_coefficients(len, rest, ks);
    let (alpha, beta) = (h2 * a, h2 * b + h * kd);
    SpringTerms {
        force: (u * (stretch + kd * along)).into(),
        kv: (dvel * a + u * (b * along)) * h2,
        coupling: Coupling::new(u, alpha, beta),
        extension: len - rest,
    }
}

/// The terms of springs `first..first + out.len()` into `out`: eight at a time with AVX2 when
/// the processor has it (checked at run time), with the same operations in the same order as
/// [`spring_terms`], so the results are the same bits either way (tested). On the issue-5
/// balloon this pass (30,720 springs) took about 11 ns per spring one at a time, most of it in
/// the two square roots and the division, which eight lanes share.
pub(crate) fn spring_terms_range(input: &SpringInput, first: usize, out: &mut [SpringTerms]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2 (checked just above).
        unsafe { spring_terms_avx2(input, first, out) };
        return;
    }
    for (k, t) in out.iter_mut().enumerate() {
        *t = spring_terms(input, first + k);
    }
}

/// Eight `Vec3` of `points` (`index[lane]`), as their x, y and z lanes; None when one of them is
/// the last point (its 16-byte load would read past the slice).
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn load_points(
    points: &[Vec3],
    index: [u32; 8],
) -> Option<(std::arch::x86_64::__m256, std::arch::x86_64::__m256, std::arch::x86_64::__m256)> {
    use std::arch::x86_64::*;
    if index.iter().any(|&i| i as usize + 1 >= points.len()) {
        return None;
    }
    let base = points.as_ptr() as *const f32;
    // SAFETY: point i is followed by point i + 1 (checked above), so the 16 bytes from its start
    // are inside the slice.
    let load = |lane: usize| unsafe { _mm_loadu_ps(base.add(3 * index[lane] as usize)) };
    let r04 = _mm256_set_m128(load(4), load(0));
    let r15 = _mm256_set_m128(load(5), load(1));
    let r26 = _mm256_set_m128(load(6), load(2));
    let r37 = _mm256_set_m128(load(7), load(3));
    let xy01 = _mm256_unpacklo_ps(r04, r15);
    let xy23 = _mm256_unpacklo_ps(r26, r37);
    let zw01 = _mm256_unpackhi_ps(r04, r15);
    let zw23 = _mm256_unpackhi_ps(r26, r37);
    Some((
        _mm256_shuffle_ps::<0x44>(xy01, xy23),
        _mm256_shuffle_ps::<0xEE>(xy01, xy23),
        _mm256_shuffle_ps::<0x44>(zw01, zw23),
    ))
}

/// [`spring_terms_range`] with AVX2 (no fused multiply-adds: the same roundings as the scalar
/// code). Groups of springs that touch the last vertex, and the tail, go one at a time.
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn spring_terms_avx2(input: &SpringInput, first: usize, out: &mut [SpringTerms]) {
    use std::arch::x86_64::*;
    let (ks, kd, h) = (input.stiffness, input.damping, input.h);
    let h2 = h * h;
    let hkd = h * kd;
    let mut k = 0;
    while k < out.len() {
        let s = first + k;
        let loaded = if k + 8 <= out.len() {
            let ends = &input.ends[s..s + 8];
            let i: [u32; 8] = std::array::from_fn(|l| ends[l][0]);
            let j: [u32; 8] = std::array::from_fn(|l| ends[l][1]);
            // SAFETY: AVX2 (this function's contract).
            unsafe {
                match (
                    load_points(input.x, i),
                    load_points(input.x, j),
                    load_points(input.v, i),
                    load_points(input.v, j),
                ) {
                    (Some(xi), Some(xj), Some(vi), Some(vj)) => Some((xi, xj, vi, vj)),
                    _ => None,
                }
            }
        } else {
            None
        };
        let Some((xi, xj, vi, vj)) = loaded else {
            // The tail, or a group touching the last vertex: one at a time.
            let end = (k + 8).min(out.len());
            for (m, t) in out[k..end].iter_mut().enumerate() {
                *t = spring_terms(input, s + m);
            }
            k = end;
            continue;
        };
        // SAFETY: eight f32 of a slice (bounds-checked by the indexing).
        let rest = unsafe { _mm256_loadu_ps(input.rest[s..s + 8].as_ptr()) };
        let (dx, dy, dz) = (_mm256_sub_ps(xj.0, xi.0), _mm256_sub_ps(xj.1, xi.1), _mm256_sub_ps(xj.2, xi.2));
        let len = _mm256_sqrt_ps(_mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
            _mm256_mul_ps(dz, dz),
        ));
        let inv = _mm256_div_ps(_mm256_set1_ps(1.0), len);
        let (ux, uy, uz) = (_mm256_mul_ps(dx, inv), _mm256_mul_ps(dy, inv), _mm256_mul_ps(dz, inv));
        let (wx, wy, wz) = (_mm256_sub_ps(vj.0, vi.0), _mm256_sub_ps(vj.1, vi.1), _mm256_sub_ps(vj.2, vi.2));
        let ksv = _mm256_set1_ps(ks);
        let stretch = _mm256_mul_ps(ksv, _mm256_sub_ps(len, rest));
        let along = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(ux, wx), _mm256_mul_ps(uy, wy)), _mm256_mul_ps(uz, wz));
        // a = K_s max(1 - L0/L, 0), b = K_s - a (`spring_block_coefficients`).
        let a = _mm256_mul_ps(
            ksv,
            _mm256_max_ps(_mm256_sub_ps(_mm256_set1_ps(1.0), _mm256_div_ps(rest, len)), _mm256_setzero_ps()),
        );
        let b = _mm256_sub_ps(ksv, a);
        let h2v = _mm256_set1_ps(h2);
        let alpha = _mm256_mul_ps(h2v, a);
        let beta = _mm256_add_ps(_mm256_mul_ps(h2v, b), _mm256_set1_ps(hkd));
        let root = _mm256_sqrt_ps(_mm256_max_ps(beta, _mm256_setzero_ps()));
        let push = _mm256_add_ps(stretch, _mm256_mul_ps(_mm256_set1_ps(kd), along));
        let b_along = _mm256_mul_ps(b, along);
        let kv =
            |w: __m256, u: __m256| _mm256_mul_ps(_mm256_add_ps(_mm256_mul_ps(w, a), _mm256_mul_ps(u, b_along)), h2v);
        let lanes = [
            _mm256_mul_ps(ux, push),
            _mm256_mul_ps(uy, push),
            _mm256_mul_ps(uz, push),
            kv(wx, ux),
            kv(wy, uy),
            kv(wz, uz),
            _mm256_mul_ps(ux, root),
            _mm256_mul_ps(uy, root),
            _mm256_mul_ps(uz, root),
            alpha,
            _mm256_sub_ps(len, rest),
            len,
        ];
        let mut v = [[0f32; 8]; 12];
        for (to, from) in v.iter_mut().zip(lanes) {
            // SAFETY: an unaligned store into eight local f32.
            unsafe { _mm256_storeu_ps(to.as_mut_ptr(), from) };
        }
        for (l, t) in out[k..k + 8].iter_mut().enumerate() {
            *t = if is_degenerate(v[11][l], input.rest[s + l]) {
                SpringTerms { extension: v[10][l], ..SpringTerms::default() }
            } else {
                SpringTerms {
                    force: Vec3::new(v[0][l], v[1][l], v[2][l]),
                    kv: Vec3A::new(v[3][l], v[4][l], v[5][l]),
                    coupling: Coupling(glam::Vec4::new(v[6][l], v[7][l], v[8][l], v[9][l])),
                    extension: v[10][l],
                }
            };
        }
        k += 8;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random springs (some of them degenerate, some compressed, some touching the last vertex,
    /// and a count that leaves a tail): the eight-at-a-time terms are the same bits as one at a
    /// time, from any first spring.
    #[test]
    fn eight_at_a_time_is_bitwise_one_at_a_time() {
        let mut unit = crate::body::test_randoms(0x9e37_79b9_7f4a_7c15);
        let n = 50;
        let x: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), unit(), unit())).collect();
        let v: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), unit(), unit()) * 3.0).collect();
        let mut ends = Vec::new();
        let mut rest = Vec::new();
        for k in 0..203u32 {
            let i = (k * 7) % n as u32;
            let j = match k % 17 {
                0 => i,            // degenerate: both ends at one point
                1 => n as u32 - 1, // the last vertex
                _ => (k * 13 + 1) % n as u32,
            };
            ends.push([i.min(j), i.max(j)]);
            let length = (x[j as usize] - x[i as usize]).length();
            rest.push(length * (0.5 + unit().abs()));
        }
        let input =
            SpringInput { ends: &ends, rest: &rest, x: &x, v: &v, stiffness: 1234.5, damping: 6.7, h: 1.0 / 60.0 };
        let expected: Vec<SpringTerms> = (0..ends.len()).map(|k| spring_terms(&input, k)).collect();
        assert!(expected.iter().any(|t| t.coupling == Coupling::default()), "a degenerate spring is in the test");
        assert!(expected.iter().filter(|t| t.coupling.w().length() > 0.0).count() > 150);
        for first in [0, 3, 8] {
            let mut out = vec![SpringTerms::default(); ends.len() - first];
            spring_terms_range(&input, first, &mut out);
            for (k, (got, want)) in out.iter().zip(&expected[first..]).enumerate() {
                let bits = |t: &SpringTerms| {
                    let mut all = Vec::new();
                    all.extend(t.kv.to_array().map(f32::to_bits));
                    all.extend(t.coupling.0.to_array().map(f32::to_bits));
                    all.extend(t.force.to_array().map(f32::to_bits));
                    all.push(t.extension.to_bits());
                    all
                };
                assert_eq!(bits(got), bits(want), "spring {}", first + k);
            }
        }
    }
}
