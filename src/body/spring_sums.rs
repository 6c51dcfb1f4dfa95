//! Per row (vertex) of the implicit system, the sums over its springs that the assembly needs:
//! the springs' share of the right side, the sum of their extensions' magnitudes (for the force
//! scale), and the springs' part `Σ alpha` and `Σ w wᵀ` of the diagonal block. The same pass
//! copies each spring's block into the row's lanes of the coupling slices.
//!
//! With AVX2, eight rows (a slice) at a time: each group of the slice gathers its eight springs'
//! terms (the lane's spring from the layout, [`CouplingSlices::springs`]), transposes them into
//! registers, adds them up and writes the eight blocks in one store per axis. One row at a time
//! this took about 115 instructions per (row, spring) pair, most of the assembly; eight rows at a
//! time the whole assembly went from 1.45G to 0.95G instructions (callgrind, issue-5 balloon,
//! 200 steps, one thread), the per-row rest (gas, inverse, contacts) now most of it. Both ways
//! add the same values in the same order with the same operations (no fused multiply-adds), so
//! the sums do not depend on the processor's features (tested).
//!
//! [`CouplingSlices::springs`]: super::coupling_slices::CouplingSlices::springs

use glam::{Vec3, Vec3A};

#[cfg(target_arch = "x86_64")]
use super::coupling_slices::MAX_ROWS;
#[cfg(target_arch = "x86_64")]
use super::coupling_slices::transpose_rows;
use super::coupling_slices::{CouplingGroup, PackedCoupling, RowMut, SLICE};
use super::spring_terms::SpringTerms;
use super::symmetric_block::SymmetricParts;
#[cfg(target_arch = "x86_64")]
use super::symmetric_block::add_outer_lanes;

/// One row's sums over its springs (see the module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct SpringSums {
    /// `Σ ± (h F + h² K v)` of the springs, signed for this end.
    pub rhs: Vec3A,
    /// `Σ |L - L0|`.
    pub extension: f32,
    /// `Σ w wᵀ`.
    pub outer: SymmetricParts,
    /// `Σ alpha`.
    pub alpha: f32,
}

/// Row `row`'s sums, one spring at a time (`around`: its (spring, other end) pairs in layout
/// order), writing each spring's block into the row's lanes and padding the rest.
#[inline(always)]
pub(crate) fn row_spring_sums(around: &[(u32, u32)], row: usize, terms: &[SpringTerms], lanes: RowMut) -> SpringSums {
    let mut lanes = lanes;
    let mut sums = SpringSums::default();
    for (k, &(spring, other)) in around.iter().enumerate() {
        let t = &terms[spring as usize];
        // `SpringTerms` are seen from the spring's first end, its lower vertex.
        let sign = if (row as u32) < other { 1.0 } else { -1.0 };
        sums.rhs += Vec3A::from(t.rhs) * sign;
        lanes.set(k, t.coupling, other);
        let coupling = t.coupling.unpacked();
        // `add_outer(w, 1)`: the products `w * w` and `w * w.yzx`, then the sums, as the
        // eight-lane version computes them.
        sums.outer.add_outer(coupling.w(), 1.0);
        sums.alpha += coupling.alpha();
        sums.extension += t.extension.abs();
    }
    lanes.finish(around.len());
    sums
}

/// The terms a padding lane reads: zero, so it adds nothing and writes a zero block.
static NO_TERMS: SpringTerms = SpringTerms { rhs: Vec3::ZERO, extension: 0.0, coupling: PackedCoupling([0; 4]) };

/// The sums of the eight rows `first_row..first_row + 8` of a slice (lane by lane, [`Self::lane`]).
#[derive(Clone, Copy, Default)]
pub(crate) struct SliceSums {
    pub(super) rhs: [[f32; SLICE]; 3],
    pub(super) extension: [f32; SLICE],
    pub(super) diagonal: [[f32; SLICE]; 3],
    pub(super) off: [[f32; SLICE]; 3],
    pub(super) alpha: [f32; SLICE],
}

impl SliceSums {
    /// The sums of the slice's row `lane`.
    #[inline(always)]
    pub fn lane(&self, lane: usize) -> SpringSums {
        let axes = |a: &[[f32; SLICE]; 3]| Vec3A::new(a[0][lane], a[1][lane], a[2][lane]);
        SpringSums {
            rhs: axes(&self.rhs),
            extension: self.extension[lane],
            outer: SymmetricParts { diagonal: axes(&self.diagonal), off: axes(&self.off) },
            alpha: self.alpha[lane],
        }
    }
}

/// The sums of a slice's eight rows from its groups (`groups`, with each lane's spring in
/// `springs`: [`super::coupling_slices::NO_SPRING`] or any spring past `terms` reads zero terms),
/// writing every lane's block into the groups. The other ends must be laid out (they give each
/// lane's sign); they are neither read for anything else nor written.
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn slice_spring_sums_avx2(
    groups: &mut [CouplingGroup],
    springs: &[[u32; SLICE]],
    terms: &[SpringTerms],
    first_row: usize,
) -> SliceSums {
    use std::arch::x86_64::*;
    assert!(groups.len() == springs.len(), "{} groups, {} lanes of springs", groups.len(), springs.len());
    // Each lane's row as an offset in f32, as the other ends are kept (4 × each row of a layout
    // and of the lanes past its last row fits an i32).
    assert!(first_row < MAX_ROWS);
    let rows = _mm256_slli_epi32::<2>(_mm256_add_epi32(
        _mm256_set1_epi32(first_row as i32),
        _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
    ));
    let sign_bit = _mm256_set1_epi32(i32::MIN);
    let high = _mm256_set1_epi32(0xFFFF_0000_u32 as i32);
    let zero = _mm256_setzero_ps();
    let (mut rx, mut ry, mut rz, mut extension) = (zero, zero, zero, zero);
    // `Σ w wᵀ` (xx, yy, zz, xy, yz, zx) and `Σ alpha`.
    let (mut outer, mut alpha) = ([zero; 6], zero);
    for (group, lanes) in groups.iter_mut().zip(springs) {
        let records: [*const u8; SLICE] = std::array::from_fn(|lane| {
            let spring = lanes[lane] as usize;
            let record = if spring < terms.len() { &terms[spring] } else { &NO_TERMS };
            record as *const SpringTerms as *const u8
        });
        // SAFETY: each pointer is a live `SpringTerms` (checked above).
        let ((tx, ty, tz, te), (xy, za)) = unsafe { (load_terms(&records), load_blocks(&records)) };
        // SAFETY: `other_offset` is 32 aligned bytes (offset 64 of a 32-byte aligned group).
        let other = unsafe { _mm256_load_si256(group.other_offset.as_ptr() as *const __m256i) };
        // The terms are seen from the spring's lower end: negated at the higher one.
        let sign = _mm256_castsi256_ps(_mm256_and_si256(_mm256_cmpgt_epi32(rows, other), sign_bit));
        rx = _mm256_add_ps(rx, _mm256_xor_ps(tx, sign));
        ry = _mm256_add_ps(ry, _mm256_xor_ps(ty, sign));
        rz = _mm256_add_ps(rz, _mm256_xor_ps(tz, sign));
        extension = _mm256_add_ps(extension, _mm256_andnot_ps(_mm256_castsi256_ps(sign_bit), te));
        // bfloat16 to f32: the upper halves of the blocks' 32-bit words.
        let wx = _mm256_castsi256_ps(_mm256_slli_epi32::<16>(xy));
        let wy = _mm256_castsi256_ps(_mm256_and_si256(xy, high));
        let wz = _mm256_castsi256_ps(_mm256_slli_epi32::<16>(za));
        let a = _mm256_castsi256_ps(_mm256_and_si256(za, high));
        add_outer_lanes(&mut outer, [wx, wy, wz], [wx, wy, wz]);
        alpha = _mm256_add_ps(alpha, a);
        // The blocks' words as the groups keep them.
        // SAFETY: `xy` and `za` are 32 aligned bytes (offsets 0 and 32 of a 32-byte aligned
        // group).
        unsafe {
            _mm256_store_si256(group.xy.as_mut_ptr() as *mut __m256i, xy);
            _mm256_store_si256(group.za.as_mut_ptr() as *mut __m256i, za);
        }
    }
    let mut sums = SliceSums::default();
    // (Stores written out: an intrinsic in a closure does not inherit the target feature and
    // becomes a call.)
    // SAFETY: eight f32 into each array of eight.
    unsafe {
        _mm256_storeu_ps(sums.rhs[0].as_mut_ptr(), rx);
        _mm256_storeu_ps(sums.rhs[1].as_mut_ptr(), ry);
        _mm256_storeu_ps(sums.rhs[2].as_mut_ptr(), rz);
        _mm256_storeu_ps(sums.diagonal[0].as_mut_ptr(), outer[0]);
        _mm256_storeu_ps(sums.diagonal[1].as_mut_ptr(), outer[1]);
        _mm256_storeu_ps(sums.diagonal[2].as_mut_ptr(), outer[2]);
        _mm256_storeu_ps(sums.off[0].as_mut_ptr(), outer[3]);
        _mm256_storeu_ps(sums.off[1].as_mut_ptr(), outer[4]);
        _mm256_storeu_ps(sums.off[2].as_mut_ptr(), outer[5]);
        _mm256_storeu_ps(sums.extension.as_mut_ptr(), extension);
        _mm256_storeu_ps(sums.alpha.as_mut_ptr(), alpha);
    }
    sums
}

/// The first 16 bytes of eight `SpringTerms` (`rhs` and `extension`), as their x, y, z and
/// extension lanes.
///
/// # Safety
/// The processor must have AVX2; every pointer must point at a `SpringTerms`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn load_terms(
    records: &[*const u8; SLICE],
) -> (std::arch::x86_64::__m256, std::arch::x86_64::__m256, std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
    use std::arch::x86_64::*;
    // SAFETY: `rhs` and `extension` are the first 16 bytes of each record (repr(C)).
    let (r04, r15, r26, r37) = unsafe {
        let row = |lane: usize| records[lane] as *const f32;
        (
            _mm256_set_m128(_mm_loadu_ps(row(4)), _mm_loadu_ps(row(0))),
            _mm256_set_m128(_mm_loadu_ps(row(5)), _mm_loadu_ps(row(1))),
            _mm256_set_m128(_mm_loadu_ps(row(6)), _mm_loadu_ps(row(2))),
            _mm256_set_m128(_mm_loadu_ps(row(7)), _mm_loadu_ps(row(3))),
        )
    };
    // The fourth lane of each record is its extension.
    transpose_rows(r04, r15, r26, r37)
}

/// The blocks of eight `SpringTerms` (bytes 16 to 24), as two words per lane: `x | y << 16` and
/// `z | alpha << 16` (the halves of [`PackedCoupling`] in memory order).
///
/// # Safety
/// The processor must have AVX2; every pointer must point at a `SpringTerms`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn load_blocks(records: &[*const u8; SLICE]) -> (std::arch::x86_64::__m256i, std::arch::x86_64::__m256i) {
    use std::arch::x86_64::*;
    // SAFETY: the block is bytes 16 to 24 of each record (repr(C)).
    let (c01, c23, c45, c67) = unsafe {
        let block = |lane: usize| records[lane].add(16) as *const __m128i;
        (
            _mm_unpacklo_epi64(_mm_loadl_epi64(block(0)), _mm_loadl_epi64(block(1))),
            _mm_unpacklo_epi64(_mm_loadl_epi64(block(2)), _mm_loadl_epi64(block(3))),
            _mm_unpacklo_epi64(_mm_loadl_epi64(block(4)), _mm_loadl_epi64(block(5))),
            _mm_unpacklo_epi64(_mm_loadl_epi64(block(6)), _mm_loadl_epi64(block(7))),
        )
    };
    // Words: xy0 za0 xy1 za1 | xy4 za4 xy5 za5, and lanes 2, 3 | 6, 7 alike.
    let (first, second) =
        (_mm256_castsi256_ps(_mm256_set_m128i(c45, c01)), _mm256_castsi256_ps(_mm256_set_m128i(c67, c23)));
    (
        _mm256_castps_si256(_mm256_shuffle_ps::<0b10_00_10_00>(first, second)),
        _mm256_castps_si256(_mm256_shuffle_ps::<0b11_01_11_01>(first, second)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::coupling_slices::{Coupling, CouplingSlices, NO_SPRING, SliceRowsMut};
    use crate::body::springs::Springs;

    /// Random springs on 61 vertices (rows of 0 to 10 springs, a last slice partly empty) with
    /// random terms: the eight-row sums are the row-by-row sums, lane by lane, and both write
    /// the same blocks into the slices.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn slice_sums_are_the_row_by_row_sums() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut unit = crate::body::test_randoms(0x0dd5_eed5_0f5a_11ce);
        let n = 61usize;
        let mut springs = Springs::default();
        for i in 0..n as u32 {
            for j in i + 1..n as u32 {
                // A fixed but irregular pattern: 4 to 15 springs a vertex, none at 20 and 40.
                let isolated = [i, j].iter().any(|&v| v == 20 || v == 40);
                if !isolated && ((i * 7 + j * 13) % 23 < 2 || (i % 9 == 0 && j % 5 == 1)) {
                    springs.ends.push([i, j]);
                    springs.rest.push(1.0);
                }
            }
        }
        springs.build_adjacency(n);
        let widths: Vec<usize> = (0..n).map(|i| springs.around(i).len()).collect();
        assert!(widths.contains(&0) && *widths.iter().max().unwrap() >= 8, "{widths:?}");
        let terms: Vec<SpringTerms> = (0..springs.len())
            .map(|_| SpringTerms {
                rhs: Vec3::new(unit(), unit(), unit()) * 50.0,
                extension: unit() * 0.1,
                coupling: Coupling::new(
                    Vec3A::new(unit(), unit(), unit()).normalize_or_zero(),
                    unit().abs() * 40.0,
                    unit().abs() * 900.0,
                )
                .packed(),
            })
            .collect();
        let mut by_rows = CouplingSlices::default();
        by_rows.layout_springs(&springs);
        let mut by_slices = CouplingSlices::default();
        by_slices.layout_springs(&springs);
        // Blocks left from an earlier step must be overwritten, padding included.
        for group in &mut by_slices.groups {
            group.xy = [0x4000_4000; SLICE];
            group.za = [0x3F80_4000; SLICE];
        }
        assert!(by_slices.springs.iter().flatten().any(|&s| s == NO_SPRING), "padding in the test");
        let mut rows = SliceRowsMut { offsets: &by_rows.offsets, groups: &mut by_rows.groups, first_row: 0 };
        let expected: Vec<SpringSums> =
            (0..n).map(|i| row_spring_sums(springs.around(i), i, &terms, rows.row(i))).collect();
        for first in (0..n).step_by(SLICE) {
            let slices = SliceRowsMut { offsets: &by_slices.offsets, groups: &mut by_slices.groups, first_row: 0 };
            let groups = slices.groups_of(first);
            // SAFETY: AVX2 (checked above).
            let sums = unsafe {
                slice_spring_sums_avx2(&mut by_slices.groups[groups.clone()], &by_slices.springs[groups], &terms, first)
            };
            for (lane, want) in expected[first..(first + SLICE).min(n)].iter().enumerate() {
                // `==` on floats: a zero's sign may differ (a padding lane adds +0).
                assert_eq!(sums.lane(lane), *want, "row {}", first + lane);
            }
        }
        for (g, (a, b)) in by_rows.groups.iter().zip(&by_slices.groups).enumerate() {
            assert_eq!((a.xy, a.za, a.other_offset), (b.xy, b.za, b.other_offset), "group {g}");
        }
        // Some sums are far from zero, so the comparison means something.
        assert!(expected.iter().filter(|s| s.rhs.length() > 10.0 && s.outer.diagonal.x > 1.0).count() > n / 2);
    }

    /// A spring index past the terms reads zero terms (and writes a zero block), never memory
    /// outside them.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn a_lane_past_the_terms_adds_nothing() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let terms = [SpringTerms {
            rhs: Vec3::new(1.0, 2.0, 3.0),
            extension: -0.5,
            coupling: Coupling::new(Vec3A::X, 2.0, 4.0).packed(),
        }];
        let mut groups = [CouplingGroup::default()];
        for lane in 0..SLICE {
            groups[0].set_other(lane, 1);
        }
        let springs = [[0, 1, NO_SPRING, 7, 0, 0, 0, 0]];
        // SAFETY: AVX2 (checked above).
        let sums = unsafe { slice_spring_sums_avx2(&mut groups, &springs, &terms, 0) };
        for lane in 1..4 {
            assert_eq!(sums.lane(lane), SpringSums::default(), "lane {lane}");
        }
        let first = sums.lane(0);
        assert_eq!(first.rhs, Vec3A::new(1.0, 2.0, 3.0));
        assert_eq!((first.extension, first.alpha, first.outer.diagonal.x), (0.5, 2.0, 4.0));
        // Lanes 8.. are rows 8..: above their other end 1, so they take the terms negated.
        // SAFETY: AVX2 (checked above).
        let second = unsafe { slice_spring_sums_avx2(&mut groups, &springs, &terms, 8) };
        assert_eq!(second.lane(0).rhs, Vec3A::new(-1.0, -2.0, -3.0));
        assert_eq!(groups[0].block(0), Coupling::new(Vec3A::X, 2.0, 4.0).packed());
        assert_eq!((groups[0].block(2), groups[0].block(3)), (PackedCoupling::default(), PackedCoupling::default()));
    }
}
