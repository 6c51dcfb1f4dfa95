//! A symmetric 3x3 block in its six distinct entries (24 bytes instead of a `Mat3A`'s 48): the
//! block-Jacobi preconditioner of the implicit integrator, which every conjugate-gradient
//! iteration reads for every vertex.
//!
//! On the issue-5 balloon (10,242 vertices) the inverted blocks took 492 KB as `Mat3A`, about a
//! quarter of what an iteration streams; on two threads each core's share of an iteration was
//! then just over its 1 MB L2 cache. Stored so, the preconditioner is also exactly symmetric
//! (the inverse of a symmetric block, computed by cofactors in f32, is so only up to rounding),
//! as conjugate gradients assume.

use glam::{Mat3A, Vec3A};

/// `[xx, yy, zz, xy, xz, yz]`.
#[derive(Clone, Copy, Default, Debug, PartialEq)]
#[repr(C)]
pub(crate) struct SymmetricBlock([f32; 6]);

impl SymmetricBlock {
    /// The symmetric part of `m` (`(m + mᵀ) / 2`).
    pub fn from_mat(m: Mat3A) -> Self {
        let pair = |a: f32, b: f32| 0.5 * (a + b);
        SymmetricBlock([
            m.x_axis.x,
            m.y_axis.y,
            m.z_axis.z,
            pair(m.y_axis.x, m.x_axis.y),
            pair(m.z_axis.x, m.x_axis.z),
            pair(m.z_axis.y, m.y_axis.z),
        ])
    }

    /// The block times `r`.
    #[inline(always)]
    pub fn apply(&self, r: Vec3A) -> Vec3A {
        #[cfg(target_arch = "x86_64")]
        {
            // `diag r + (xy, xy, xz) (r.y, r.x, r.x) + (xz, yz, yz) (r.z, r.z, r.y)` with SSE2
            // (part of x86-64): two unaligned loads inside the 24 bytes, `[xx yy zz xy]` and
            // `[zz xy xz yz]`, instead of nine scalar products (3.5% more instructions in a step).
            use std::arch::x86_64::*;
            // SAFETY: SSE2 is always present on x86-64; both loads read 16 of the 24 bytes.
            unsafe {
                let base = self.0.as_ptr();
                let (head, tail) = (_mm_loadu_ps(base), _mm_loadu_ps(base.add(2)));
                let r = __m128::from(r);
                let diagonal = _mm_mul_ps(head, r);
                let first =
                    _mm_mul_ps(_mm_shuffle_ps::<0b00_10_01_01>(tail, tail), _mm_shuffle_ps::<0b00_00_00_01>(r, r));
                let second =
                    _mm_mul_ps(_mm_shuffle_ps::<0b00_11_11_10>(tail, tail), _mm_shuffle_ps::<0b00_01_10_10>(r, r));
                let sum = _mm_add_ps(_mm_add_ps(diagonal, first), second);
                // The fourth lane (xy r.w + ...) is ignored by every Vec3A operation; cleared
                // anyway so that no NaN or infinity hides there.
                let xyz = _mm_castsi128_ps(_mm_set_epi32(0, -1, -1, -1));
                Vec3A::from(_mm_and_ps(sum, xyz))
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let [xx, yy, zz, xy, xz, yz] = self.0;
            Vec3A::new(xx * r.x + xy * r.y + xz * r.z, xy * r.x + yy * r.y + yz * r.z, xz * r.x + yz * r.y + zz * r.z)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The six entries hold a symmetric matrix exactly; an unsymmetric one becomes its
    /// symmetric part.
    #[test]
    fn applies_the_symmetric_part() {
        let mut unit = crate::body::test_randoms(0x5eed_0f_b10c);
        for _ in 0..200 {
            let a = Mat3A::from_cols_array(&std::array::from_fn(|_| unit()));
            let symmetric = a + a.transpose();
            let r = Vec3A::new(unit(), unit(), unit());
            let block = SymmetricBlock::from_mat(symmetric);
            let (got, want) = (block.apply(r), symmetric * r);
            assert!((got - want).length() <= 1e-6 * (1.0 + want.length()), "{got} vs {want}");
            let [xx, yy, zz, xy, xz, yz] = block.0;
            let scalar = Vec3A::new(
                xx * r.x + xy * r.y + xz * r.z,
                xy * r.x + yy * r.y + yz * r.z,
                xz * r.x + yz * r.y + zz * r.z,
            );
            assert!((got - scalar).length() <= 1e-6 * (1.0 + want.length()), "{got} vs {scalar}");
            let half = SymmetricBlock::from_mat(a).apply(r);
            let want = (a + a.transpose()) * r * 0.5;
            assert!((half - want).length() <= 1e-6 * (1.0 + want.length()), "{half} vs {want}");
        }
    }
}
