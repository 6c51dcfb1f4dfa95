//! A symmetric 3x3 block in its six distinct entries (24 bytes instead of a `Mat3A`'s 48): the
//! block-Jacobi preconditioner of the implicit integrator, which every conjugate-gradient
//! iteration reads for every vertex, and the diagonal block it is the inverse of.
//!
//! On the issue-5 balloon (10,242 vertices) the inverted blocks took 492 KB as `Mat3A`, about a
//! quarter of what an iteration streams; on two threads each core's share of an iteration was
//! then just over its 1 MB L2 cache. Stored so, the preconditioner is also exactly symmetric
//! (a general 3x3 inverse in f32 is so only up to rounding), as conjugate gradients assume.
//!
//! In registers a block is two `Vec3A`: its diagonal `(xx, yy, zz)` and its off-diagonal
//! `(xy, yz, zx)` (each lane's row and the next axis), so that `w wᵀ` adds `w * w` and
//! `w * w.yzx` (two products where a `Mat3A` took three columns of three) and the inverse's
//! cofactors are lane-wise products of shuffles.

use glam::{Vec3A, Vec3Swizzles};

/// `[xx, yy, zz, xy, yz, zx]`.
#[derive(Clone, Copy, Default, Debug, PartialEq)]
#[repr(C)]
pub(crate) struct SymmetricBlock([f32; 6]);

/// A symmetric block being built: diagonal `(xx, yy, zz)` and off-diagonal `(xy, yz, zx)`.
#[derive(Clone, Copy, Default, Debug, PartialEq)]
pub(crate) struct SymmetricParts {
    pub diagonal: Vec3A,
    pub off: Vec3A,
}

impl SymmetricParts {
    /// `s I`.
    #[cfg(test)]
    pub fn scalar(s: f32) -> Self {
        SymmetricParts { diagonal: Vec3A::splat(s), off: Vec3A::ZERO }
    }

    /// Adds `s a aᵀ`.
    #[inline(always)]
    pub fn add_outer(&mut self, a: Vec3A, s: f32) {
        let sa = a * s;
        self.diagonal += sa * a;
        self.off += sa * a.yzx();
    }

    /// The inverse (of a symmetric positive definite block: by cofactors); the inverse of its
    /// diagonal when it is (numerically) singular (a zero entry there gives 1 / f32::MIN_POSITIVE,
    /// finite).
    pub fn inverse(self) -> SymmetricBlock {
        let (d, o) = (self.diagonal, self.off);
        // Cofactors: (yy zz - yz², xx zz - zx², xx yy - xy²) and
        // (zx yz - xy zz, xy zx - yz xx, xy yz - zx yy).
        let cofactor_diagonal = d.yxx() * d.zzy() - o.yzx() * o.yzx();
        let cofactor_off = o.zxx() * o.yzy() - o * d.zxy();
        let det = d.x * cofactor_diagonal.x + o.x * cofactor_off.x + o.z * cofactor_off.z;
        let scale = d.x.abs() + d.y.abs() + d.z.abs();
        if det.is_finite() && det > 1e-12 * scale * scale * scale {
            let inv = 1.0 / det;
            SymmetricParts { diagonal: cofactor_diagonal * inv, off: cofactor_off * inv }.stored()
        } else {
            let diagonal = Vec3A::ONE / d.max(Vec3A::splat(f32::MIN_POSITIVE));
            SymmetricParts { diagonal, off: Vec3A::ZERO }.stored()
        }
    }

    /// The six entries as stored.
    pub fn stored(self) -> SymmetricBlock {
        let (d, o) = (self.diagonal, self.off);
        SymmetricBlock([d.x, d.y, d.z, o.x, o.y, o.z])
    }
}

impl SymmetricBlock {
    /// The block of the entries `[xx, yy, zz, xy, yz, zx]`.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    #[inline(always)]
    pub fn from_entries(entries: [f32; 6]) -> Self {
        SymmetricBlock(entries)
    }

    pub fn parts(self) -> SymmetricParts {
        let [xx, yy, zz, xy, yz, zx] = self.0;
        SymmetricParts { diagonal: Vec3A::new(xx, yy, zz), off: Vec3A::new(xy, yz, zx) }
    }

    /// The blocks of two consecutive rows (`pair[0]` and `pair[1]`) times the two rows of `r`
    /// (row 0 in the low half of the register, row 1 in the high one; fourth lanes cleared): the
    /// operations of [`SymmetricBlock::apply`] on each half, so the same bits, with one
    /// register for both rows (the conjugate-gradient residual pass applies the blocks at every
    /// row of every iteration).
    ///
    /// # Safety
    /// The processor must have AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline]
    pub unsafe fn apply_pair(pair: &[SymmetricBlock; 2], r: std::arch::x86_64::__m256) -> std::arch::x86_64::__m256 {
        use std::arch::x86_64::*;
        // SAFETY: each load reads 16 of a block's 24 bytes (repr(C): the blocks are contiguous).
        unsafe {
            let (row0, row1) = (pair[0].0.as_ptr(), pair[1].0.as_ptr());
            let head = _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(_mm_loadu_ps(row0)), _mm_loadu_ps(row1));
            let tail =
                _mm256_insertf128_ps::<1>(_mm256_castps128_ps256(_mm_loadu_ps(row0.add(2))), _mm_loadu_ps(row1.add(2)));
            let diagonal = _mm256_mul_ps(head, r);
            let first =
                _mm256_mul_ps(_mm256_shuffle_ps::<0b00_11_01_01>(tail, tail), _mm256_shuffle_ps::<0b00_00_00_01>(r, r));
            let second =
                _mm256_mul_ps(_mm256_shuffle_ps::<0b00_10_10_11>(tail, tail), _mm256_shuffle_ps::<0b00_01_10_10>(r, r));
            let sum = _mm256_add_ps(_mm256_add_ps(diagonal, first), second);
            let xyz = _mm256_castsi256_ps(_mm256_setr_epi32(-1, -1, -1, 0, -1, -1, -1, 0));
            _mm256_and_ps(sum, xyz)
        }
    }

    /// The block times `r`.
    #[inline(always)]
    pub fn apply(&self, r: Vec3A) -> Vec3A {
        #[cfg(target_arch = "x86_64")]
        {
            // `diag r + (xy, xy, zx) (r.y, r.x, r.x) + (zx, yz, yz) (r.z, r.z, r.y)` with SSE2
            // (part of x86-64): two unaligned loads inside the 24 bytes, `[xx yy zz xy]` and
            // `[zz xy yz zx]`, instead of nine scalar products (3.5% more instructions in a step).
            use std::arch::x86_64::*;
            // SAFETY: SSE2 is always present on x86-64; both loads read 16 of the 24 bytes.
            unsafe {
                let base = self.0.as_ptr();
                let (head, tail) = (_mm_loadu_ps(base), _mm_loadu_ps(base.add(2)));
                let r = __m128::from(r);
                let diagonal = _mm_mul_ps(head, r);
                let first =
                    _mm_mul_ps(_mm_shuffle_ps::<0b00_11_01_01>(tail, tail), _mm_shuffle_ps::<0b00_00_00_01>(r, r));
                let second =
                    _mm_mul_ps(_mm_shuffle_ps::<0b00_10_10_11>(tail, tail), _mm_shuffle_ps::<0b00_01_10_10>(r, r));
                let sum = _mm_add_ps(_mm_add_ps(diagonal, first), second);
                // The fourth lane (xy r.w + ...) is ignored by every Vec3A operation; cleared
                // anyway so that no NaN or infinity hides there.
                let xyz = _mm_castsi128_ps(_mm_set_epi32(0, -1, -1, -1));
                Vec3A::from(_mm_and_ps(sum, xyz))
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let [xx, yy, zz, xy, yz, zx] = self.0;
            // The SSE2 path's sums in its order (the diagonal term, then the two others).
            Vec3A::new(xx * r.x + xy * r.y + zx * r.z, yy * r.y + xy * r.x + yz * r.z, zz * r.z + zx * r.x + yz * r.y)
        }
    }
}

/// Adds the products of `a bᵀ` to eight symmetric blocks held lane by lane (`blocks`: xx, yy,
/// zz, xy, yz, zx, each a register of eight lanes): `a.x b.x`, `a.y b.y` and `a.z b.z` on the
/// diagonal, `a.x b.y`, `a.y b.z` and `a.z b.x` off it. With `a = s w` and `b = w` these are the
/// products of [`SymmetricParts::add_outer`] in its order, so each lane gets its bits.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
pub(crate) fn add_outer_lanes(
    blocks: &mut [std::arch::x86_64::__m256; 6],
    [ax, ay, az]: [std::arch::x86_64::__m256; 3],
    [bx, by, bz]: [std::arch::x86_64::__m256; 3],
) {
    use std::arch::x86_64::*;
    let products = [
        _mm256_mul_ps(ax, bx),
        _mm256_mul_ps(ay, by),
        _mm256_mul_ps(az, bz),
        _mm256_mul_ps(ax, by),
        _mm256_mul_ps(ay, bz),
        _mm256_mul_ps(az, bx),
    ];
    for (block, product) in blocks.iter_mut().zip(products) {
        *block = _mm256_add_ps(*block, product);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Mat3A;

    fn matrix(parts: SymmetricParts) -> Mat3A {
        let (d, o) = (parts.diagonal, parts.off);
        Mat3A::from_cols_array(&[d.x, o.x, o.z, o.x, d.y, o.y, o.z, o.y, d.z])
    }

    /// Sums of outer products (random, so positive definite with the scalar part): the parts
    /// hold the matrix, the stored block applies it, and its inverse applies the inverse.
    #[test]
    fn builds_applies_and_inverts_symmetric_blocks() {
        let mut unit = crate::body::test_randoms(0x5eed_0f_b10c);
        for _ in 0..300 {
            let mut parts = SymmetricParts::scalar(0.1 + unit().abs());
            let mut want = Mat3A::from_diagonal(glam::Vec3::splat(parts.diagonal.x));
            for _ in 0..6 {
                let (a, s) = (Vec3A::new(unit(), unit(), unit()) * 3.0, unit().abs() * 10.0);
                parts.add_outer(a, s);
                want += Mat3A::from_cols(a * (s * a.x), a * (s * a.y), a * (s * a.z));
            }
            let got = matrix(parts);
            for (g, w) in got.to_cols_array().iter().zip(want.to_cols_array()) {
                assert!((g - w).abs() <= 1e-5 * (1.0 + w.abs()), "{got} vs {want}");
            }
            let r = Vec3A::new(unit(), unit(), unit());
            let applied = parts.stored().apply(r);
            assert!((applied - want * r).length() <= 1e-5 * (1.0 + (want * r).length()));
            assert_eq!(parts.stored().parts(), parts);
            // A (A⁻¹ r) = r.
            let back = want * parts.inverse().apply(r);
            assert!((back - r).length() <= 1e-3 * r.length(), "{back} vs {r}");
        }
    }

    /// Two rows at once are each row's block times its row, to the bit (whatever the rows'
    /// fourth lanes hold).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn pairs_of_rows_are_each_row_alone() {
        use std::arch::x86_64::*;
        if !std::arch::is_x86_feature_detected!("avx") {
            eprintln!("skipped: this processor has no AVX");
            return;
        }
        let mut unit = crate::body::test_randoms(0x5eed_b10c);
        for round in 0..200 {
            let blocks: [SymmetricBlock; 2] =
                std::array::from_fn(|_| SymmetricBlock(std::array::from_fn(|_| unit() * 4.0)));
            let rows: [Vec3A; 2] = std::array::from_fn(|_| Vec3A::new(unit(), unit() * 1e3, unit() * 1e-3));
            let w = [f32::NAN, f32::INFINITY, 7.0][round % 3];
            // SAFETY: AVX (checked above); eight f32 in, eight out.
            let (got, want) = unsafe {
                let r = _mm256_setr_ps(rows[0].x, rows[0].y, rows[0].z, w, rows[1].x, rows[1].y, rows[1].z, w);
                let mut got = [0.0f32; 8];
                _mm256_storeu_ps(got.as_mut_ptr(), SymmetricBlock::apply_pair(&blocks, r));
                (got, [blocks[0].apply(rows[0]), blocks[1].apply(rows[1])])
            };
            let want: Vec<u32> = want.iter().flat_map(|v| [v.x, v.y, v.z, 0.0]).map(f32::to_bits).collect();
            assert_eq!(got.map(f32::to_bits).to_vec(), want, "round {round}");
        }
    }

    /// A singular block falls back to its diagonal's inverse, finite where that is zero.
    #[test]
    fn singular_blocks_invert_their_diagonal() {
        let mut parts = SymmetricParts::scalar(0.0);
        parts.add_outer(Vec3A::new(1.0, 2.0, 0.0), 1.0);
        let inverse = parts.inverse().parts();
        assert_eq!(inverse.off, Vec3A::ZERO);
        assert_eq!(inverse.diagonal.x, 1.0);
        assert_eq!(inverse.diagonal.y, 0.25);
        assert!(inverse.diagonal.z.is_finite() && inverse.diagonal.z > 0.0);
    }
}
