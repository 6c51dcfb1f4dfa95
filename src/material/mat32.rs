//! The small matrices of membrane mechanics: 3x2 (a deformation gradient, a stress) and
//! symmetric 2x2 (a right Cauchy-Green tensor, a second Piola-Kirchhoff stress).

// `add`/`sub`/`scale` are plain methods rather than operator traits: the hot loops read as the
// formulas in SPEC.md and nothing implicit happens.
#![allow(clippy::should_implement_trait)]

use glam::{Mat2, Vec3};

/// A 3x2 matrix stored as its two columns (`F = [f0 f1]`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Mat32 {
    /// Column 0.
    pub c0: Vec3,
    /// Column 1.
    pub c1: Vec3,
}

/// A symmetric 2x2 matrix `[[a, b], [b, d]]`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sym2 {
    /// Entry (0,0).
    pub a: f32,
    /// Entries (0,1) and (1,0).
    pub b: f32,
    /// Entry (1,1).
    pub d: f32,
}

impl Sym2 {
    /// The identity.
    pub(crate) const IDENTITY: Sym2 = Sym2 { a: 1.0, b: 0.0, d: 1.0 };

    /// `s I`.
    #[inline]
    pub fn diagonal(s: f32) -> Self {
        Sym2 { a: s, b: 0.0, d: s }
    }
    /// Trace.
    #[inline]
    pub fn trace(self) -> f32 {
        self.a + self.d
    }
    /// Determinant.
    #[inline]
    pub fn det(self) -> f32 {
        self.a * self.d - self.b * self.b
    }
    /// Inverse, or `None` when the determinant is (near) zero.
    #[inline]
    pub fn inverse(self) -> Option<Sym2> {
        let det = self.det();
        if det.abs() <= f32::MIN_POSITIVE {
            return None;
        }
        let inv = 1.0 / det;
        Some(Sym2 { a: self.d * inv, b: -self.b * inv, d: self.a * inv })
    }
    /// `A:A` (sum of squared entries).
    #[inline]
    pub fn norm_squared(self) -> f32 {
        self.a * self.a + 2.0 * self.b * self.b + self.d * self.d
    }
    /// `self * s`.
    #[inline]
    pub fn scale(self, s: f32) -> Sym2 {
        Sym2 { a: self.a * s, b: self.b * s, d: self.d * s }
    }
    /// `self + other`.
    #[inline]
    pub fn add(self, other: Sym2) -> Sym2 {
        Sym2 { a: self.a + other.a, b: self.b + other.b, d: self.d + other.d }
    }
    /// As a glam matrix.
    #[inline]
    pub fn to_mat2(self) -> Mat2 {
        Mat2::from_cols_array(&[self.a, self.b, self.b, self.d])
    }
}

impl Mat32 {
    /// From columns.
    #[inline]
    pub fn new(c0: Vec3, c1: Vec3) -> Self {
        Self { c0, c1 }
    }
    /// Column `i` (0 or 1).
    #[inline]
    pub fn col(&self, i: usize) -> Vec3 {
        if i == 0 { self.c0 } else { self.c1 }
    }
    /// Column `i`, mutably.
    #[inline]
    pub fn col_mut(&mut self, i: usize) -> &mut Vec3 {
        if i == 0 { &mut self.c0 } else { &mut self.c1 }
    }
    /// `F^T F`.
    #[inline]
    pub fn gram(&self) -> Sym2 {
        Sym2 { a: self.c0.dot(self.c0), b: self.c0.dot(self.c1), d: self.c1.dot(self.c1) }
    }
    /// `F M` for a symmetric 2x2 M.
    #[inline]
    pub fn mul_sym(&self, m: Sym2) -> Mat32 {
        Mat32 { c0: self.c0 * m.a + self.c1 * m.b, c1: self.c0 * m.b + self.c1 * m.d }
    }
    /// `F M` for a general 2x2 M (glam, column-major).
    #[inline]
    pub fn mul_mat2(&self, m: Mat2) -> Mat32 {
        Mat32 { c0: self.c0 * m.x_axis.x + self.c1 * m.x_axis.y, c1: self.c0 * m.y_axis.x + self.c1 * m.y_axis.y }
    }
    /// `A^T B` (2x2) for 3x2 A = self and B.
    #[inline]
    pub fn transpose_mul(&self, b: &Mat32) -> Mat2 {
        Mat2::from_cols_array(&[self.c0.dot(b.c0), self.c1.dot(b.c0), self.c0.dot(b.c1), self.c1.dot(b.c1)])
    }
    /// `self * s`.
    #[inline]
    pub fn scale(&self, s: f32) -> Mat32 {
        Mat32 { c0: self.c0 * s, c1: self.c1 * s }
    }
    /// `self + other`.
    #[inline]
    pub fn add(&self, other: &Mat32) -> Mat32 {
        Mat32 { c0: self.c0 + other.c0, c1: self.c1 + other.c1 }
    }
    /// `self - other`.
    #[inline]
    pub fn sub(&self, other: &Mat32) -> Mat32 {
        Mat32 { c0: self.c0 - other.c0, c1: self.c1 - other.c1 }
    }
    /// Frobenius norm.
    #[inline]
    pub fn norm(&self) -> f32 {
        (self.c0.length_squared() + self.c1.length_squared()).sqrt()
    }
    /// True when every entry is finite.
    #[inline]
    pub fn is_finite(&self) -> bool {
        self.c0.is_finite() && self.c1.is_finite()
    }
}

/// Thin polar decomposition `F = R S` of a 3x2 F (SPEC 1.3): `S = (C + √det C I)/√(tr C + 2√det C)`
/// (symmetric positive semi-definite 2x2) and `R = F S^-1` (3x2, orthonormal columns).
/// Returns `None` when F has rank below 1 (S not invertible).
#[inline]
pub fn thin_polar(f: &Mat32) -> Option<(Mat32, Sym2)> {
    let c = f.gram();
    let sqrt_det = c.det().max(0.0).sqrt();
    let denom = c.trace() + 2.0 * sqrt_det;
    if denom <= 1e-30 {
        return None;
    }
    let s = c.add(Sym2::diagonal(sqrt_det)).scale(1.0 / denom.sqrt());
    let s_inv = s.inverse()?;
    Some((f.mul_sym(s_inv), s))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polar_of_a_rotated_stretch() {
        // F = R0 diag(2, 0.5) with R0 the first two columns of a rotation.
        let r0 = glam::Mat3::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
        let f = Mat32::new(r0.x_axis * 2.0, r0.y_axis * 0.5);
        let (r, s) = thin_polar(&f).unwrap();
        assert!((r.c0 - r0.x_axis).length() < 1e-5 && (r.c1 - r0.y_axis).length() < 1e-5);
        assert!((s.a - 2.0).abs() < 1e-5 && s.b.abs() < 1e-5 && (s.d - 0.5).abs() < 1e-5);
        let back = r.mul_sym(s);
        assert!(back.sub(&f).norm() < 1e-5);
    }
}
