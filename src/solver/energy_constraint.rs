//! The two forms of an energy constraint (SPEC 1.3): the paper's plain PBD form `C = W` and the
//! consistent XPBD form `C = sqrt(2 Ŵ)` with compliance `α̃ = 1/(k h²)`.
//!
//! Both take the element's energy and per-vertex gradients (with unit modulus for XPBD) and the
//! inverse masses, and return per-vertex corrections; they are shared by the membrane,
//! bending and anisotropic constraints.

// NaN must fail every guard below, so comparisons are written `!(x > limit)` on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use glam::Vec3;

/// Below this squared gradient sum (per unit energy) an element gives no correction: its gradient
/// vanishes (a collapsed element or all vertices pinned).
const MIN_DENOMINATOR: f32 = 1e-30;

/// The paper's PBD energy constraint (SPEC 1.3): `s = C / Σ w_j |∇_j C|²`,
/// `Δx_i = -stiffness · s · w_i ∇_i C` with `C = energy`. Independent of the energy's scale.
/// Returns `false` (and leaves `correction` untouched) when there is nothing to do.
#[inline(always)]
pub fn pbd_energy_correction<const N: usize>(
    energy: f32,
    grad: &[Vec3; N],
    inv_mass: &[f32; N],
    stiffness: f32,
    correction: &mut [Vec3; N],
) -> bool {
    let denom: f32 = (0..N).map(|i| inv_mass[i] * grad[i].length_squared()).sum();
    if energy <= 0.0 || !(denom > MIN_DENOMINATOR * energy.abs().max(1e-30)) {
        return false;
    }
    let s = stiffness * energy / denom;
    for i in 0..N {
        correction[i] = grad[i] * (-s * inv_mass[i]);
    }
    true
}

/// The XPBD energy constraint of SPEC 1.3 with `W = k Ŵ`: `C = sqrt(2 Ŵ)`,
/// `Δλ = -C² (C + α̃ λ) / (Σ_i w_i |∇_i Ŵ|² + α̃ C²)`, `Δx_i = w_i ∇_i Ŵ (Δλ / C)`.
/// `energy` is Ŵ (unit modulus), `grad` its gradients, `alpha` = α̃ = 1/(k h²), `lambda` the
/// accumulated multiplier of this step. Skips an element whose `C²` is below `min_c2` (at rest).
/// Returns Δλ (0 when skipped, then `correction` is untouched).
#[inline(always)]
pub fn xpbd_energy_correction<const N: usize>(
    energy: f32,
    grad: &[Vec3; N],
    inv_mass: &[f32; N],
    alpha: f32,
    lambda: f32,
    min_c2: f32,
    correction: &mut [Vec3; N],
) -> f32 {
    let c2 = 2.0 * energy;
    if !(c2 > min_c2) {
        return 0.0;
    }
    let c = c2.sqrt();
    let gsum: f32 = (0..N).map(|i| inv_mass[i] * grad[i].length_squared()).sum();
    let denom = gsum + alpha * c2;
    if !(denom > MIN_DENOMINATOR) {
        return 0.0;
    }
    // Δλ / C = -C (C + α̃λ)/denom: one division, none by C.
    let factor = -c * (c + alpha * lambda) / denom;
    let dlambda = factor * c;
    for i in 0..N {
        correction[i] = grad[i] * (inv_mass[i] * factor);
    }
    dlambda
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A spring between two points written as an energy W = k/2 (|d| - L)²: one XPBD step with
    /// α̃ = 0 must solve it exactly (C is linear in the distance along the spring).
    fn spring(x: [Vec3; 2], rest: f32) -> (f32, [Vec3; 2]) {
        let d = x[1] - x[0];
        let len = d.length();
        let u = d / len;
        (0.5 * (len - rest) * (len - rest), [-u * (len - rest), u * (len - rest)])
    }

    #[test]
    fn hard_xpbd_constraint_solves_a_spring_in_one_step() {
        let x = [Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0)];
        let (w, g) = spring(x, 1.0);
        let mut corr = [Vec3::ZERO; 2];
        let dl = xpbd_energy_correction(w, &g, &[1.0, 1.0], 0.0, 0.0, 1e-18, &mut corr);
        assert!(dl < 0.0);
        let len = (x[1] + corr[1] - x[0] - corr[0]).length();
        assert!((len - 1.0).abs() < 1e-6, "{len}");
    }

    #[test]
    fn compliance_gives_the_spring_equilibrium() {
        // Iterating XPBD with compliance converges to the minimiser of k/2 C² + 1/2 |x - x̃|²/h²
        // weighted by masses: for one free end (w = 1, m = 1) at x̃ = 2, rest 1, k h² = 1:
        // (x - 1) k + (x - 2)/h² = 0 -> x = 1.5.
        let mut x = [Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0)];
        let mut lambda = 0.0;
        for _ in 0..50 {
            let (w, g) = spring(x, 1.0);
            let mut corr = [Vec3::ZERO; 2];
            lambda += xpbd_energy_correction(w, &g, &[0.0, 1.0], 1.0, lambda, 1e-18, &mut corr);
            x[1] += corr[1];
        }
        assert!((x[1].x - 1.5).abs() < 1e-4, "{}", x[1].x);
    }

    #[test]
    fn pbd_form_ignores_the_energy_scale_and_guards_zero_gradients() {
        let x = [Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0)];
        let (w, g) = spring(x, 1.0);
        let (mut a, mut b) = ([Vec3::ZERO; 2], [Vec3::ZERO; 2]);
        assert!(pbd_energy_correction(w, &g, &[1.0, 1.0], 1.0, &mut a));
        assert!(pbd_energy_correction(w * 1e3, &g.map(|v| v * 1e3), &[1.0, 1.0], 1.0, &mut b));
        assert!((a[1] - b[1]).length() < 1e-6);
        let mut c = [Vec3::ZERO; 2];
        assert!(!pbd_energy_correction(1.0, &[Vec3::ZERO; 2], &[1.0, 1.0], 1.0, &mut c));
        assert_eq!(xpbd_energy_correction(1.0, &[Vec3::ZERO; 2], &[1.0, 1.0], 0.0, 0.0, 1e-18, &mut c), 0.0);
        assert_eq!(xpbd_energy_correction(0.0, &g, &[1.0, 1.0], 0.0, 0.0, 1e-18, &mut c), 0.0);
    }
}
