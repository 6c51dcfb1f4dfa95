//! Fibre energies of SPEC 1.5 (Kim, De Goes, Iben 2019) with the optional active-contraction
//! target stretch L: `I5 = |F a|²`, `I4 = a^T S a`, `A = a a^T`.

use glam::Vec2;

use super::mat32::{Mat32, thin_polar};

/// Which anisotropic energy (SPEC 1.5 table).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AnisotropicEnergy {
    /// `μ/2 (√I5 - L sign(I4))²` (the paper's ARAP; equals Sqrt on a membrane).
    Arap,
    /// `μ/2 (I5 - L²)²`.
    StVK,
    /// `μ/2 (√I5 - L)²`.
    Sqrt,
}

/// Below this `√I5` the fibre has collapsed: the √ energies keep their value and give no stress.
const MIN_STRETCH: f32 = 1e-12;

/// `(ψ, P)` of the fibre energy with stiffness `mu`, target stretch `target` (1 = the paper's
/// energies) and unit fibre direction `a` in the rest basis.
#[inline]
pub fn anisotropic_energy(kind: AnisotropicEnergy, mu: f32, target: f32, f: &Mat32, a: Vec2) -> (f32, Mat32) {
    let fa = f.c0 * a.x + f.c1 * a.y;
    let i5 = fa.length_squared();
    // P = factor · F A, with F A = (F a) a^T.
    let fa_a = |factor: f32| Mat32::new(fa * (factor * a.x), fa * (factor * a.y));
    match kind {
        AnisotropicEnergy::StVK => {
            // SPEC 1.5: ψ = μ/2 (I5 - 1)², P = 2μ (I5 - 1) F A  (with L²: active contraction)
            let d = i5 - target * target;
            (0.5 * mu * d * d, fa_a(2.0 * mu * d))
        }
        AnisotropicEnergy::Sqrt | AnisotropicEnergy::Arap => {
            // SPEC 1.5: ψ = μ/2 (√I5 - s)², P = μ (1 - s/√I5) F A, s = L (Sqrt) or L sign(I4) (ARAP)
            let sign = if kind == AnisotropicEnergy::Arap {
                match thin_polar(f) {
                    Some((_, s)) if s.a * a.x * a.x + 2.0 * s.b * a.x * a.y + s.d * a.y * a.y < 0.0 => -1.0,
                    _ => 1.0,
                }
            } else {
                1.0
            };
            let s = target * sign;
            let root = i5.sqrt();
            if root < MIN_STRETCH {
                return (0.5 * mu * s * s, Mat32::default());
            }
            let d = root - s;
            (0.5 * mu * d * d, fa_a(mu * (1.0 - s / root)))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::fd;
    use glam::Vec3;

    #[test]
    fn stresses_match_finite_differences() {
        let a = Vec2::new(0.6, 0.8);
        let fs = [
            Mat32::new(Vec3::new(1.1, 0.2, 0.1), Vec3::new(-0.1, 0.9, 0.3)),
            Mat32::new(Vec3::new(0.5, 0.3, 0.2), Vec3::new(0.1, 0.4, -0.6)),
        ];
        for kind in [AnisotropicEnergy::Arap, AnisotropicEnergy::StVK, AnisotropicEnergy::Sqrt] {
            for target in [1.0, 0.7] {
                for f in fs {
                    let err = fd::check(f, |g| anisotropic_energy(kind, 2.0, target, &g, a));
                    assert!(err < 2e-3, "{kind:?} L={target}: error {err}");
                }
            }
        }
    }

    #[test]
    fn rest_is_free_and_arap_equals_sqrt_on_a_membrane() {
        let a = Vec2::new(0.6, 0.8);
        let rest = Mat32::new(Vec3::X, Vec3::Y);
        for kind in [AnisotropicEnergy::Arap, AnisotropicEnergy::StVK, AnisotropicEnergy::Sqrt] {
            let (psi, p) = anisotropic_energy(kind, 1.0, 1.0, &rest, a);
            assert!(psi.abs() < 1e-10 && p.norm() < 1e-6);
        }
        let f = Mat32::new(Vec3::new(0.5, 0.3, 0.2), Vec3::new(0.1, 0.4, -0.6));
        let (e1, p1) = anisotropic_energy(AnisotropicEnergy::Arap, 1.0, 0.8, &f, a);
        let (e2, p2) = anisotropic_energy(AnisotropicEnergy::Sqrt, 1.0, 0.8, &f, a);
        assert_eq!((e1, p1), (e2, p2));
        // A target stretch below 1 makes the rest state stressed (active contraction).
        let (psi, _) = anisotropic_energy(AnisotropicEnergy::Sqrt, 1.0, 0.5, &rest, a);
        assert!((psi - 0.125).abs() < 1e-6);
    }
}
