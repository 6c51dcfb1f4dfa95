//! Each spring's share of the implicit system (SPEC 2.1 force and damping, the stiffness block
//! of `springs`), computed once per spring before the per-vertex assembly gathers it; eight
//! springs at a time with AVX2 where the processor has it.

use glam::{Vec3, Vec3A};

#[cfg(target_arch = "x86_64")]
use super::coupling_slices::transpose_rows;
use super::coupling_slices::{Coupling, PackedCoupling};
use super::energy::{ENERGY_LANES, SpringEnergyLanes};
#[cfg(target_arch = "x86_64")]
use super::springs::MIN_LENGTH_RATIO;
use super::springs::{is_degenerate, spring_block_coefficients};

/// One spring's share of the assembly, seen from its first end (`Springs::ends[k][0]`): its
/// share `h F + h² K v` of the right side (spring and damping force F), its coupling block in
/// bfloat16 as the slices store it, and its extension `L - L0` (for the force scale, and for
/// the energy and strain of the state it was made at). The second end takes the right side
/// negated (`u` and the velocity difference both flip sign, so it is exactly the negated
/// value) and the same block, so each spring is computed once, not once per end.
///
/// 24 bytes: the assembly gathers these per vertex in an order that jumps about the array, so
/// their size is what that gather waits on. (At 48 bytes, with the force and `h² K v` apart
/// and the block in f32, the balloon's 30,720 springs took 1.5 MB, more than a core's L2
/// cache, and the assembly rounded each block twice.)
#[derive(Clone, Copy, Default, Debug, PartialEq)]
#[repr(C)]
pub(crate) struct SpringTerms {
    pub rhs: Vec3,
    pub extension: f32,
    pub coupling: PackedCoupling,
}

const _: () = assert!(std::mem::size_of::<SpringTerms>() == 24);

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
    let force = u * (stretch + kd * along);
    let kv = (dvel * a + u * (b * along)) * h2;
    SpringTerms {
        rhs: (force * h + kv).into(),
        extension: len - rest,
        coupling: Coupling::new(u, alpha, beta).packed(),
    }
}

/// The terms of springs `first..first + out.len()` into `out`: eight at a time with AVX2 when
/// the processor has it (checked at run time), with the same operations in the same order as
/// [`spring_terms`], so the results are the same bits either way (tested). On the issue-5
/// balloon this pass (30,720 springs) took about 11 ns per spring one at a time, most of it in
/// the two square roots and the division, which eight lanes share.
///
/// With `energy`, each spring's extension is also added to its lanes (spring `first + k` in
/// lane k mod 8, as `energy::springs_energy_strain` sums a chunk from `first`), eight at a
/// time while they are in registers. As a pass of its own over the terms, one spring at a time
/// (a division and a maximum each), it took 1.6-1.9% of a one-thread profile of the issue-5
/// balloon's drop, now about 0.4% (the terms' share grew by that), with the same bits.
pub(crate) fn spring_terms_range(
    input: &SpringInput,
    first: usize,
    out: &mut [SpringTerms],
    mut energy: Option<&mut SpringEnergyLanes>,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2 (checked just above).
        unsafe { spring_terms_avx2(input, first, out, energy) };
        return;
    }
    for (k, t) in out.iter_mut().enumerate() {
        *t = spring_terms(input, first + k);
        if let Some(lanes) = energy.as_deref_mut() {
            lanes.add(k % ENERGY_LANES, t.extension, input.rest[first + k]);
        }
    }
}

/// Eight points of `x` and `v` (four arrays of `Vec3` as x, y and z lanes: the first ends'
/// positions, the second ends', the first ends' velocities, the second ends'), at the ends of
/// springs `first..first + 8`; None when one of those ends is the last point of `x` or `v` (its
/// 16-byte load would read past the slice).
///
/// The ends are loaded, checked and scaled to offsets in f32 (3 × the point) eight lanes at a
/// time, each point's offset then serving its position and its velocity. Per end and array,
/// spelled one at a time (an index from the pair, a bounds check of its own, `3 ×` in an
/// address), this took about half the instructions of the spring pass (objdump: 155 moves, 62
/// address computations and 46 compares in the kernel).
///
/// # Safety
/// The processor must have AVX2; `first + 8 <= ends.len()`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
#[allow(clippy::type_complexity)]
unsafe fn load_spring_ends(
    input: &SpringInput,
    first: usize,
) -> Option<[(std::arch::x86_64::__m256, std::arch::x86_64::__m256, std::arch::x86_64::__m256); 4]> {
    use std::arch::x86_64::*;
    let points = input.x.len().min(input.v.len());
    // Every end must be followed by another point (`end <= points - 2`), and 3 × an end must
    // be an i32 (the offsets and the comparison below).
    if points < 2 || points > i32::MAX as usize / 3 {
        return None;
    }
    let ends = &input.ends[first..first + 8];
    // SAFETY: sixteen u32 (eight pairs) read as two unaligned 32-byte vectors.
    let (low, high) = unsafe {
        let p = ends.as_ptr() as *const __m256i;
        (_mm256_loadu_si256(p), _mm256_loadu_si256(p.add(1)))
    };
    let last = _mm256_set1_epi32((points - 2) as i32);
    let largest = _mm256_max_epu32(_mm256_max_epu32(low, high), last);
    if _mm256_movemask_epi8(_mm256_cmpeq_epi32(largest, last)) != -1 {
        return None;
    }
    // Offsets in f32: i0 j0 i1 j1 ... i7 j7.
    let mut offset = [0u32; 16];
    // SAFETY: sixteen u32 into an array of sixteen.
    unsafe {
        let p = offset.as_mut_ptr() as *mut __m256i;
        _mm256_storeu_si256(p, _mm256_add_epi32(low, _mm256_slli_epi32::<1>(low)));
        _mm256_storeu_si256(p.add(1), _mm256_add_epi32(high, _mm256_slli_epi32::<1>(high)));
    }
    let (x, v) = (input.x.as_ptr() as *const f32, input.v.as_ptr() as *const f32);
    // SAFETY: each offset is that of a point followed by another (checked above), so the 16 bytes
    // from its start are inside the slice.
    let lanes = |base: *const f32, end: usize| {
        let load = |spring: usize| unsafe { _mm_loadu_ps(base.add(offset[2 * spring + end] as usize)) };
        let (x, y, z, _) = transpose_rows(
            _mm256_set_m128(load(4), load(0)),
            _mm256_set_m128(load(5), load(1)),
            _mm256_set_m128(load(6), load(2)),
            _mm256_set_m128(load(7), load(3)),
        );
        (x, y, z)
    };
    Some([lanes(x, 0), lanes(x, 1), lanes(v, 0), lanes(v, 1)])
}

/// Eight f32 rounded to bfloat16 as `coupling_slices::to_bf16` rounds one (ties to even, a NaN
/// to 0x7FC0), each in the low half of its 32-bit lane.
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn bf16_lanes(v: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256i {
    use std::arch::x86_64::*;
    let bits = _mm256_castps_si256(v);
    let odd = _mm256_and_si256(_mm256_srli_epi32::<16>(bits), _mm256_set1_epi32(1));
    let rounded = _mm256_srli_epi32::<16>(_mm256_add_epi32(bits, _mm256_add_epi32(_mm256_set1_epi32(0x7FFF), odd)));
    let nan = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_UNORD_Q>(v, v));
    _mm256_or_si256(_mm256_and_si256(nan, _mm256_set1_epi32(0x7FC0)), _mm256_andnot_si256(nan, rounded))
}

/// [`spring_terms_range`] with AVX2 (no fused multiply-adds: the same roundings as the scalar
/// code). Groups of springs that touch the last vertex, and the tail, go one at a time.
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn spring_terms_avx2(
    input: &SpringInput,
    first: usize,
    out: &mut [SpringTerms],
    mut energy: Option<&mut SpringEnergyLanes>,
) {
    use std::arch::x86_64::*;
    let (ks, kd, h) = (input.stiffness, input.damping, input.h);
    let h2 = h * h;
    let hkd = h * kd;
    let mut k = 0;
    while k < out.len() {
        let s = first + k;
        let loaded = if k + 8 <= out.len() {
            // SAFETY: AVX2 (this function's contract); s + 8 <= first + out.len(), the springs
            // of the call.
            unsafe { load_spring_ends(input, s) }
        } else {
            None
        };
        let Some([xi, xj, vi, vj]) = loaded else {
            // The tail, or a group touching the last vertex: one at a time.
            let end = (k + 8).min(out.len());
            for (m, t) in out[k..end].iter_mut().enumerate() {
                *t = spring_terms(input, s + m);
                if let Some(lanes) = energy.as_deref_mut() {
                    lanes.add((k + m) % ENERGY_LANES, t.extension, input.rest[s + m]);
                }
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
        let hv = _mm256_set1_ps(h);
        // `force * h + kv` per axis, as `spring_terms` computes it.
        let rhs = |w: __m256, u: __m256| {
            let kv = _mm256_mul_ps(_mm256_add_ps(_mm256_mul_ps(w, a), _mm256_mul_ps(u, b_along)), h2v);
            _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(u, push), hv), kv)
        };
        // A degenerate spring (`is_degenerate`: `len <= ratio rest`, false for NaN) keeps only
        // its extension.
        let degenerate = _mm256_cmp_ps::<_CMP_LE_OQ>(len, _mm256_mul_ps(_mm256_set1_ps(MIN_LENGTH_RATIO), rest));
        let keep = |v: __m256| _mm256_andnot_ps(degenerate, v);
        let (rx, ry, rz, extension) =
            (keep(rhs(wx, ux)), keep(rhs(wy, uy)), keep(rhs(wz, uz)), _mm256_sub_ps(len, rest));
        if let Some(lanes) = energy.as_deref_mut() {
            // SAFETY: AVX2 (this function's contract); k is a multiple of eight here, so lane l
            // holds spring first + k + l of lane l.
            unsafe { lanes.add_lanes(extension, rest) };
        }
        // SAFETY: AVX2 (this function's contract).
        let [cx, cy, cz, ca] = unsafe {
            [
                bf16_lanes(_mm256_mul_ps(ux, root)),
                bf16_lanes(_mm256_mul_ps(uy, root)),
                bf16_lanes(_mm256_mul_ps(uz, root)),
                bf16_lanes(alpha),
            ]
        };
        // Each spring's 24 bytes: (rhs, extension) transposed four lanes at a time into 16-byte
        // rows, then the block's four halves as one u64 (x, y in its low u32, z, alpha in its
        // high one, little-endian: the order of `PackedCoupling`).
        let t0 = _mm256_unpacklo_ps(rx, ry); // x0 y0 x1 y1 | x4 y4 x5 y5
        let t1 = _mm256_unpackhi_ps(rx, ry); // x2 y2 x3 y3 | x6 y6 x7 y7
        let t2 = _mm256_unpacklo_ps(rz, extension);
        let t3 = _mm256_unpackhi_ps(rz, extension);
        let rows = [
            _mm256_shuffle_ps::<0x44>(t0, t2), // spring 0 | spring 4
            _mm256_shuffle_ps::<0xEE>(t0, t2), // 1 | 5
            _mm256_shuffle_ps::<0x44>(t1, t3), // 2 | 6
            _mm256_shuffle_ps::<0xEE>(t1, t3), // 3 | 7
        ];
        let drop = _mm256_castps_si256(degenerate);
        let xy = _mm256_andnot_si256(drop, _mm256_or_si256(cx, _mm256_slli_epi32::<16>(cy)));
        let za = _mm256_andnot_si256(drop, _mm256_or_si256(cz, _mm256_slli_epi32::<16>(ca)));
        let (low, high) = (_mm256_unpacklo_epi32(xy, za), _mm256_unpackhi_epi32(xy, za)); // 0 1 | 4 5, 2 3 | 6 7
        let blocks = [
            _mm256_extract_epi64::<0>(low),
            _mm256_extract_epi64::<1>(low),
            _mm256_extract_epi64::<0>(high),
            _mm256_extract_epi64::<1>(high),
            _mm256_extract_epi64::<2>(low),
            _mm256_extract_epi64::<3>(low),
            _mm256_extract_epi64::<2>(high),
            _mm256_extract_epi64::<3>(high),
        ];
        let records = out[k..k + 8].as_mut_ptr();
        for (lane, &block) in blocks.iter().enumerate() {
            let row =
                if lane < 4 { _mm256_castps256_ps128(rows[lane]) } else { _mm256_extractf128_ps::<1>(rows[lane - 4]) };
            // SAFETY: `records` points at eight 24-byte `SpringTerms` (repr(C): rhs, extension
            // in the first 16 bytes, the block in the last 8), written unaligned.
            unsafe {
                let record = records.add(lane) as *mut u8;
                _mm_storeu_ps(record as *mut f32, row);
                std::ptr::write_unaligned(record.add(16) as *mut i64, block);
            }
        }
        k += 8;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eight lanes at a time round as `to_bf16` rounds one: ties to even, subnormals, infinities,
    /// signed zeros and NaN.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn eight_lane_bfloat16_is_the_scalar_rounding() {
        use super::super::coupling_slices::to_bf16;
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut unit = crate::body::test_randoms(0x1234_5678_9abc_def1);
        let mut values = vec![
            f32::NAN,
            -f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            -0.0,
            f32::MAX,
            f32::MIN_POSITIVE / 3.0,
            1.0 + 2f32.powi(-8),
            1.0 + 3.0 * 2f32.powi(-8),
            -(1.0 + 2f32.powi(-8)),
        ];
        values.extend((0..3000).map(|k| unit() * 10f32.powi(k % 30 - 15)));
        while values.len() % 8 != 0 {
            values.push(1.5);
        }
        for lanes in values.chunks_exact(8) {
            let mut got = [0u32; 8];
            // SAFETY: AVX2 (checked above); eight f32 loaded, eight u32 stored.
            unsafe {
                use std::arch::x86_64::*;
                let v = _mm256_loadu_ps(lanes.as_ptr());
                _mm256_storeu_si256(got.as_mut_ptr() as *mut __m256i, bf16_lanes(v));
            }
            for (value, got) in lanes.iter().zip(got) {
                assert_eq!(got, to_bf16(*value) as u32, "{value:e}");
            }
        }
    }

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
        assert!(expected.iter().any(|t| t.coupling == PackedCoupling::default()), "a degenerate spring is in the test");
        assert!(expected.iter().filter(|t| t.coupling.unpacked().w().length() > 0.0).count() > 150);
        for first in [0, 3, 8] {
            let mut out = vec![SpringTerms::default(); ends.len() - first];
            spring_terms_range(&input, first, &mut out, None);
            // With the energy lanes: the same terms, and the energy and strain (to the bit) of
            // `springs_energy_strain` over the springs from `first`.
            let mut with_energy = vec![SpringTerms::default(); ends.len() - first];
            let mut lanes = SpringEnergyLanes::new(input.stiffness);
            spring_terms_range(&input, first, &mut with_energy, Some(&mut lanes));
            assert_eq!(with_energy, out);
            let (energy, strain) = lanes.finish();
            let (want_energy, want_strain) = crate::body::energy::springs_energy_strain(
                |k| expected[first + k].extension,
                &rest[first..],
                input.stiffness,
            );
            assert_eq!((energy.to_bits(), strain.to_bits()), (want_energy.to_bits(), want_strain.to_bits()));
            assert!(energy > 0.0 && strain > 0.0, "first {first}: {energy} J, strain {strain}");
            for (k, (got, want)) in out.iter().zip(&expected[first..]).enumerate() {
                let bits = |t: &SpringTerms| {
                    let mut all = Vec::new();
                    all.extend(t.rhs.to_array().map(f32::to_bits));
                    all.extend(t.coupling.0.map(u32::from));
                    all.push(t.extension.to_bits());
                    all
                };
                assert_eq!(bits(got), bits(want), "spring {}", first + k);
            }
        }
    }
}
