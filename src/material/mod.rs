//! Membrane energies and their stresses as pure functions of the 3x2 deformation gradient F
//! (SPEC 1.3) and the anisotropic fibre energies of SPEC 1.5.
//!
//! Owns: the small 3x2 / 2x2 algebra these formulas need, the energy density ψ(F) and its first
//! Piola-Kirchhoff stress P(F) = ∂ψ/∂F for every material. Must not touch meshes, constraints or
//! simulators: the solver gathers positions into F and scatters P back into vertex gradients.
//! Every stress is checked against finite differences of its energy in the tests below each file.

mod anisotropic;
mod mat32;
mod membrane;

pub use anisotropic::{AnisotropicEnergy, anisotropic_energy};
pub use mat32::{Mat32, Sym2};
pub use membrane::{Lame, Material, membrane_energy};

#[cfg(test)]
pub(crate) mod fd {
    //! Finite-difference check of P = ∂ψ/∂F for a 3x2 F.
    use super::Mat32;

    /// Returns the largest error of `stress(f)` against central differences of `energy`,
    /// relative to max(1, |P|).
    pub(crate) fn check(f: Mat32, energy: impl Fn(Mat32) -> (f32, Mat32)) -> f32 {
        let (_, p) = energy(f);
        let h = 1e-3f32;
        let mut worst = 0.0f32;
        let scale = p.norm().max(1.0);
        for col in 0..2 {
            for row in 0..3 {
                let mut plus = f;
                let mut minus = f;
                plus.col_mut(col)[row] += h;
                minus.col_mut(col)[row] -= h;
                let fd = (energy(plus).0 as f64 - energy(minus).0 as f64) / (2.0 * h as f64);
                let err = (fd as f32 - p.col(col)[row]).abs() / scale;
                worst = worst.max(err);
            }
        }
        worst
    }
}
