//! The five membrane materials of SPEC 1.3: energy density ψ(F) and stress P(F) = ∂ψ/∂F for a
//! 3x2 deformation gradient F (a triangle's map from its rest plane to space).

use super::mat32::{Mat32, Sym2, thin_polar};

/// Which membrane energy (SPEC 1.3 table).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Material {
    /// Saint Venant-Kirchhoff, `μ E:E + λ/2 (tr E)²` (the paper's default).
    StVK,
    /// Corotated, `μ‖F-R‖² + λ/2 (tr S - 2)²` with the thin polar decomposition.
    Corotated,
    /// Linear, `μ ε:ε + λ/2 (tr ε)²` with `ε = sym(T0^T F) - I` (not rotation invariant).
    Linear,
    /// Neo-Hookean, `μ/2 (tr C - 2) - μ ln J + λ/2 (ln J)²`.
    NeoHookean,
    /// Incompressible Mooney-Rivlin membrane, `C10 (I1 - 3) + C01 (I2 - 3)` with
    /// `C10 = C01 = μ/4` (so that `μ = 2 (C10 + C01)` at small strain; λ is not used).
    MooneyRivlin,
}

/// Lamé parameters of a membrane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lame {
    /// Shear modulus μ.
    pub mu: f32,
    /// Plane-stress first Lamé parameter λ.
    pub lambda: f32,
}

impl Lame {
    /// SPEC 1.3: `μ = E/(2(1+ν))`, plane-stress `λ = E ν/(1-ν²)`.
    pub fn from_young_poisson(young: f32, poisson: f32) -> Self {
        Self { mu: young / (2.0 * (1.0 + poisson)), lambda: young * poisson / (1.0 - poisson * poisson) }
    }
}

/// Smallest `det C` the logarithmic and inverse terms accept: below it a triangle has collapsed to
/// a segment and its energy is evaluated at this floor (large but finite), never at infinity.
const MIN_DET_C: f32 = 1e-12;

/// `(ψ, P)` of `material` at F. `t0` is the rest-plane basis `[t1 t2]` in world space, read only by
/// [`Material::Linear`]. Every branch is finite for any finite F.
#[inline(always)]
pub fn membrane_energy(material: Material, lame: Lame, f: &Mat32, t0: &Mat32) -> (f32, Mat32) {
    match material {
        Material::StVK => stvk(lame, f),
        Material::Corotated => corotated(lame, f),
        Material::Linear => linear(lame, f, t0),
        Material::NeoHookean => neo_hookean(lame, f),
        Material::MooneyRivlin => mooney_rivlin(lame, f),
    }
}

#[inline(always)]
fn stvk(lame: Lame, f: &Mat32) -> (f32, Mat32) {
    // SPEC 1.3: E = (C - I)/2, ψ = μ E:E + λ/2 (tr E)², P = F (2μE + λ tr(E) I)
    let c = f.gram();
    let e = Sym2 { a: 0.5 * (c.a - 1.0), b: 0.5 * c.b, d: 0.5 * (c.d - 1.0) };
    let tr = e.trace();
    let psi = lame.mu * e.norm_squared() + 0.5 * lame.lambda * tr * tr;
    let s = e.scale(2.0 * lame.mu).add(Sym2::diagonal(lame.lambda * tr));
    (psi, f.mul_sym(s))
}

#[inline]
fn corotated(lame: Lame, f: &Mat32) -> (f32, Mat32) {
    // SPEC 1.3: ψ = μ‖F-R‖² + λ/2 (tr S - 2)², P = 2μ(F-R) + λ(tr S - 2) R
    let Some((r, s)) = thin_polar(f) else {
        // F = 0: every direction is equally far; the energy is μ·2 + λ/2·4 and any R works.
        return (2.0 * lame.mu + 2.0 * lame.lambda, Mat32::default());
    };
    let diff = f.sub(&r);
    let tr = s.trace() - 2.0;
    let psi = lame.mu * (diff.c0.length_squared() + diff.c1.length_squared()) + 0.5 * lame.lambda * tr * tr;
    (psi, diff.scale(2.0 * lame.mu).add(&r.scale(lame.lambda * tr)))
}

#[inline]
fn linear(lame: Lame, f: &Mat32, t0: &Mat32) -> (f32, Mat32) {
    // SPEC 1.3: ε = sym(T0^T F) - I, ψ = μ ε:ε + λ/2 (tr ε)², P = T0 (2με + λ tr(ε) I)
    let g = t0.transpose_mul(f);
    let eps = Sym2 { a: g.x_axis.x - 1.0, b: 0.5 * (g.y_axis.x + g.x_axis.y), d: g.y_axis.y - 1.0 };
    let tr = eps.trace();
    let psi = lame.mu * eps.norm_squared() + 0.5 * lame.lambda * tr * tr;
    let s = eps.scale(2.0 * lame.mu).add(Sym2::diagonal(lame.lambda * tr));
    (psi, t0.mul_sym(s))
}

#[inline]
fn neo_hookean(lame: Lame, f: &Mat32) -> (f32, Mat32) {
    // SPEC 1.3: ψ = μ/2 (tr C - 2) - μ ln J + λ/2 (ln J)², P = F [μ(I - C^-1) + λ ln J C^-1]
    let c = f.gram();
    let det = c.det().max(MIN_DET_C);
    let c_inv = Sym2 { a: c.d / det, b: -c.b / det, d: c.a / det };
    let ln_j = 0.5 * det.ln();
    let psi = 0.5 * lame.mu * (c.trace() - 2.0) - lame.mu * ln_j + 0.5 * lame.lambda * ln_j * ln_j;
    let s = Sym2::IDENTITY.add(c_inv.scale(-1.0)).scale(lame.mu).add(c_inv.scale(lame.lambda * ln_j));
    (psi.max(0.0), f.mul_sym(s))
}

#[inline]
fn mooney_rivlin(lame: Lame, f: &Mat32) -> (f32, Mat32) {
    // SPEC 1.3: I1 = tr C + 1/det C, I2 = det C + tr C/det C, ψ = C10(I1-3) + C01(I2-3),
    // S = 2[C10(I - C^-1/det C) + C01(det C C^-1 + I/det C - (tr C/det C) C^-1)], P = F S
    let (c10, c01) = (0.25 * lame.mu, 0.25 * lame.mu);
    let c = f.gram();
    let det = c.det().max(MIN_DET_C);
    let tr = c.trace();
    let c_inv = Sym2 { a: c.d / det, b: -c.b / det, d: c.a / det };
    let i1 = tr + 1.0 / det;
    let i2 = det + tr / det;
    let psi = c10 * (i1 - 3.0) + c01 * (i2 - 3.0);
    let s1 = Sym2::IDENTITY.add(c_inv.scale(-1.0 / det)).scale(c10);
    let s2 = c_inv.scale(det - tr / det).add(Sym2::diagonal(1.0 / det)).scale(c01);
    (psi.max(0.0), f.mul_sym(s1.add(s2).scale(2.0)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::fd;
    use glam::{Mat3, Vec3};

    const ALL: [Material; 5] =
        [Material::StVK, Material::Corotated, Material::Linear, Material::NeoHookean, Material::MooneyRivlin];

    fn samples() -> Vec<Mat32> {
        let rot = Mat3::from_axis_angle(Vec3::new(0.3, -1.0, 0.5).normalize(), 0.9);
        vec![
            Mat32::new(Vec3::X, Vec3::Y),
            Mat32::new(Vec3::new(1.2, 0.1, -0.05), Vec3::new(-0.2, 0.8, 0.1)),
            Mat32::new(rot * Vec3::new(0.7, 0.2, 0.0), rot * Vec3::new(0.1, 1.3, 0.0)),
            Mat32::new(Vec3::new(0.5, 0.3, 0.2), Vec3::new(0.1, 0.4, -0.6)),
        ]
    }

    #[test]
    fn stresses_match_finite_differences() {
        let lame = Lame::from_young_poisson(3.0, 0.3);
        let t0 = Mat32::new(Vec3::X, Vec3::Y);
        for material in ALL {
            for f in samples() {
                let err = fd::check(f, |g| membrane_energy(material, lame, &g, &t0));
                assert!(err < 2e-3, "{material:?} at {f:?}: finite-difference error {err}");
            }
        }
    }

    #[test]
    fn rest_and_rigid_motions_cost_nothing() {
        let lame = Lame::from_young_poisson(1.0, 0.3);
        let rot = Mat3::from_axis_angle(Vec3::new(1.0, 1.0, 0.0).normalize(), 1.1);
        let t0 = Mat32::new(Vec3::X, Vec3::Y);
        let rotated = Mat32::new(rot * Vec3::X, rot * Vec3::Y);
        for material in ALL {
            let (psi, p) = membrane_energy(material, lame, &t0, &t0);
            assert!(psi.abs() < 1e-6 && p.norm() < 1e-5, "{material:?} at rest: {psi} {p:?}");
            if material != Material::Linear {
                let (psi, p) = membrane_energy(material, lame, &rotated, &t0);
                assert!(psi.abs() < 1e-5 && p.norm() < 1e-4, "{material:?} rotated: {psi} {p:?}");
            }
        }
    }

    #[test]
    fn small_strain_agrees_with_linear_elasticity() {
        // An equibiaxial stretch of 1e-3: every material's energy density is (μ + λ) 2 ε² to first
        // order (Mooney-Rivlin: incompressible, its own value).
        let lame = Lame::from_young_poisson(1.0, 0.3);
        let e = 1e-3f32;
        let f = Mat32::new(Vec3::X * (1.0 + e), Vec3::Y * (1.0 + e));
        let t0 = Mat32::new(Vec3::X, Vec3::Y);
        let expected = (lame.mu + lame.lambda) * 2.0 * e * e;
        for material in [Material::StVK, Material::Corotated, Material::Linear, Material::NeoHookean] {
            let (psi, _) = membrane_energy(material, lame, &f, &t0);
            assert!((psi - expected).abs() < 0.02 * expected, "{material:?}: {psi} vs {expected}");
        }
    }

    #[test]
    fn collapsed_triangles_stay_finite() {
        let lame = Lame::from_young_poisson(1.0, 0.3);
        let t0 = Mat32::new(Vec3::X, Vec3::Y);
        for f in [Mat32::default(), Mat32::new(Vec3::X, Vec3::X)] {
            for material in ALL {
                let (psi, p) = membrane_energy(material, lame, &f, &t0);
                assert!(psi.is_finite() && p.is_finite(), "{material:?} at {f:?}");
            }
        }
    }
}
