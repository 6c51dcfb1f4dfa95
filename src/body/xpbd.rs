//! XPBD substeps (SPEC 2.2): springs as distance constraints `C = |x_j - x_i| - L0` with
//! compliance `1/K_s` and damping, the gas as a volume constraint whose multiplier is the
//! pressure impulse, projected by Gauss-Seidel: gas first, then springs (so each sweep ends with
//! the stiff constraints met), then obstacle contacts.
//!
//! Gas: implicit Euler on the energy `-nRT ln V` asks for `p = p̃ + M⁻¹ ∇V λ` with
//! `λ = h² nRT / V(p)`; each iteration takes one Newton step on `λ - h² nRT / V(p) = 0`,
//! linearising `V` along `M⁻¹ ∇V`: `Δλ = -(λ - h² nRT/V) / (1 + h² nRT |∇V|²_{M⁻¹} / V²)`.

use glam::Vec3;

use super::forces::{Model, external_forces};
use super::gas::Gas;
use super::obstacles::{Obstacle, project};

/// Scratch of the XPBD integrator (allocated only when it is used).
#[derive(Default)]
pub(crate) struct XpbdScratch {
    pub force: Vec<Vec3>,
    pub gradient: Vec<Vec3>,
    /// Each vertex's displacement in this substep so far, kept apart from x so that
    /// `v = displacement / h` keeps its digits: `(x - x_before) / h` in f32 lost them once x was
    /// large against a substep's motion (ten times the error at 256 substeps as at 16 on a
    /// small ball, worse away from the origin; found by review).
    displacement: Vec<Vec3>,
    lambda: Vec<f32>,
    gas_lambda: Vec<f64>,
    gas_norm: Vec<f64>,
    /// Per fragment: this iteration's change of `gas_lambda` (kept to be reused, not made per
    /// iteration).
    gas_delta: Vec<f64>,
    /// Contact normal of each vertex in this substep (only with obstacles), with the normal
    /// speed it had before the solve.
    contact: Vec<Option<(Vec3, f32)>>,
}

impl XpbdScratch {
    /// Drops the last substep's multipliers (as if no substep had run since a topology change).
    #[cfg(test)]
    pub fn forget_multipliers(&mut self) {
        self.lambda.clear();
        self.gas_lambda.clear();
    }

    pub fn memory_bytes(&self) -> usize {
        (self.force.capacity() + self.gradient.capacity() + self.displacement.capacity()) * 12
            + self.lambda.capacity() * 4
            + (self.gas_lambda.capacity() + self.gas_norm.capacity() + self.gas_delta.capacity()) * 8
            + self.contact.capacity() * std::mem::size_of::<Option<(Vec3, f32)>>()
    }
}

/// The forces the last substep's constraints applied, on every vertex (springs with their
/// damping, and the gas), added to `f`: a constraint that moved vertex i by `w_i ∇C_i λ` in a
/// substep of length `h` pushed it with `∇C_i λ / h²`. Returns false (and adds nothing) when the
/// scratch holds no multipliers of these springs and gas fragments (no substep since the body
/// was made or its topology changed).
///
/// This is the load of an XPBD body (`break_force`, SPEC 2.4): with a few iterations its
/// constraints are far from converged, so the spring and gas laws at its positions give forces
/// that it never applied. A review saw a floating ball of gas 10 J (482 vertices, 1 substep of
/// 10 iterations) release 43 core blocks in its first step and all 482 by step 60 at
/// `break_force` 1 N, where implicit Euler's loads stay far below it and release none.
pub(crate) fn add_applied_forces(
    model: &Model,
    gas: Option<&mut Gas>,
    x: &[Vec3],
    h: f32,
    s: &mut XpbdScratch,
    f: &mut [Vec3],
) -> bool {
    let gas_fragments = gas.as_deref().map_or(0, Gas::fragment_count);
    if s.lambda.len() != model.springs.len() || (gas_fragments > 0 && s.gas_lambda.len() != gas_fragments) {
        return false;
    }
    let inv_h2 = 1.0 / (h * h);
    for (k, (&[i, j], &rest)) in model.springs.ends.iter().zip(&model.springs.rest).enumerate() {
        let (i, j) = (i as usize, j as usize);
        // As in the substep: a spring too short to have a direction moved nothing.
        let Some((u, _)) = spring_direction(x, i, j, rest) else { continue };
        let push = u * (s.lambda[k] * inv_h2);
        f[i] -= push;
        f[j] += push;
    }
    if let Some(gas) = gas {
        s.gradient.resize(x.len(), Vec3::ZERO);
        gas.measure_with_gradient(x, model.triangles, &mut s.gradient);
        for (i, g) in s.gradient.iter().enumerate() {
            let fragment = gas.vertex_fragment[i];
            if fragment != u32::MAX {
                f[i] += *g * (s.gas_lambda[fragment as usize] as f32 * inv_h2);
            }
        }
    }
    true
}

/// The unit vector from vertex i to j and their distance, or None when the spring of rest length
/// `rest` between them is too short to have a direction (then it moves nothing).
#[inline(always)]
fn spring_direction(x: &[Vec3], i: usize, j: usize, rest: f32) -> Option<(Vec3, f32)> {
    let d = x[j] - x[i];
    let len = d.length();
    (len > 1e-6 * rest).then(|| (d / len, len))
}

/// XPBD distance-constraint update (SPEC 2.2): returns `Δλ` for a spring with current vector
/// `d = p_j - p_i`, accumulated `lambda`, inverse masses, compliance `α̃ = 1/(K_s h²)` and
/// damping `γ = K_d/(K_s h)` times `∇C·(p - x_prev)` given as `velocity_term`:
/// `Δλ = (-C - α̃ λ - γ ∇C·Δx) / ((1 + γ)(w_i + w_j) + α̃)`, here with numerator and denominator
/// times `K_s h²` (given as `stiffness_h2`, with `damping_h = K_d h`), so a spring of tiny K_s
/// neither divides by it (1/(K_s h²) passed f32's range at K_s = 1e-38, and `∞ · 0` made a
/// NaN: a review) nor loses its damping. Positions then move by `Δp_i = -w_i u Δλ`,
/// `Δp_j = w_j u Δλ`.
pub(crate) fn distance_delta_lambda(
    c: f32,
    lambda: f32,
    wi: f32,
    wj: f32,
    stiffness_h2: f32,
    damping_h: f32,
    velocity_term: f32,
) -> f32 {
    let denominator = (stiffness_h2 + damping_h) * (wi + wj) + 1.0;
    let numerator = -c * stiffness_h2 - lambda - damping_h * velocity_term;
    numerator / denominator
}

/// One substep of length `h` with `iterations` Gauss-Seidel sweeps; returns the wind work, J.
#[allow(clippy::too_many_arguments)]
pub(crate) fn substep(
    model: &Model,
    mut gas: Option<&mut Gas>,
    x: &mut [Vec3],
    v: &mut [Vec3],
    h: f32,
    iterations: u32,
    obstacles: &[Obstacle],
    s: &mut XpbdScratch,
) -> f64 {
    let n = x.len();
    s.force.resize(n, Vec3::ZERO);
    let power = external_forces(model, v, &mut s.force);
    s.displacement.clear();
    s.displacement.resize(n, Vec3::ZERO);
    for i in 0..n {
        v[i] += s.force[i] * (model.inv_mass[i] * h);
        s.displacement[i] = v[i] * h;
        x[i] += s.displacement[i];
    }
    let (ks, kd) = (model.settings.spring_stiffness, model.settings.spring_damping);
    s.contact.clear();
    if !obstacles.is_empty() {
        s.contact.resize(n, None);
    }
    s.lambda.clear();
    s.lambda.resize(model.springs.len(), 0.0);
    let h2 = (h * h) as f64;
    if let Some(gas) = gas.as_deref() {
        s.gradient.resize(n, Vec3::ZERO);
        s.gas_lambda.clear();
        s.gas_lambda.resize(gas.fragment_count(), 0.0);
        s.gas_norm.resize(gas.fragment_count(), 0.0);
        s.gas_delta.resize(gas.fragment_count(), 0.0);
    }
    let (stiffness_h2, damping_h) = (ks * h * h, kd * h);
    for _ in 0..iterations.max(1) {
        if let Some(gas) = gas.as_deref_mut() {
            gas.measure_with_gradient(x, model.triangles, &mut s.gradient);
            s.gas_norm.fill(0.0);
            for (i, g) in s.gradient.iter().enumerate() {
                let f = gas.vertex_fragment[i];
                if f != u32::MAX {
                    s.gas_norm[f as usize] += (model.inv_mass[i] * g.length_squared()) as f64;
                }
            }
            for (f, delta) in s.gas_delta.iter_mut().enumerate() {
                *delta = {
                    if gas.n_rt[f] <= 0.0 {
                        0.0
                    } else {
                        let vol = gas.volume[f].max(gas.v_min[f]).max(f64::MIN_POSITIVE);
                        let target = h2 * gas.n_rt[f] / vol;
                        let slope = if gas.volume[f] > gas.v_min[f] { h2 * gas.n_rt[f] / (vol * vol) } else { 0.0 };
                        let delta = -(s.gas_lambda[f] - target) / (1.0 + slope * s.gas_norm[f]);
                        // Trust region: one update changes the volume by at most a tenth (the
                        // linearisation is only good that far; shreds near zero volume need it).
                        let limit = 0.1 * vol / s.gas_norm[f].max(f64::MIN_POSITIVE);
                        delta.clamp(-limit, limit)
                    }
                };
            }
            for (lambda, d) in s.gas_lambda.iter_mut().zip(&s.gas_delta) {
                *lambda += d;
            }
            let deltas = &s.gas_delta;
            for (i, g) in s.gradient.iter().enumerate() {
                let f = gas.vertex_fragment[i];
                if f != u32::MAX {
                    let step = *g * (model.inv_mass[i] * deltas[f as usize] as f32);
                    x[i] += step;
                    s.displacement[i] += step;
                }
            }
        }
        if ks > 0.0 {
            for (k, (&[i, j], &rest)) in model.springs.ends.iter().zip(&model.springs.rest).enumerate() {
                let (i, j) = (i as usize, j as usize);
                let Some((u, len)) = spring_direction(x, i, j, rest) else { continue };
                let velocity_term = u.dot(s.displacement[j] - s.displacement[i]);
                let dl = distance_delta_lambda(
                    len - rest,
                    s.lambda[k],
                    model.inv_mass[i],
                    model.inv_mass[j],
                    stiffness_h2,
                    damping_h,
                    velocity_term,
                );
                s.lambda[k] += dl;
                let (step_i, step_j) = (u * (model.inv_mass[i] * dl), u * (model.inv_mass[j] * dl));
                x[i] -= step_i;
                x[j] += step_j;
                s.displacement[i] -= step_i;
                s.displacement[j] += step_j;
            }
        }
        if !obstacles.is_empty() {
            s.contact.resize(n, None);
            for i in 0..n {
                if model.inv_mass[i] > 0.0 {
                    let before = x[i];
                    if let Some(normal) = project(&mut x[i], obstacles) {
                        s.displacement[i] += x[i] - before;
                        if s.contact[i].is_none() {
                            s.contact[i] = Some((normal, v[i].dot(normal)));
                        }
                    }
                }
            }
        }
    }
    for i in 0..n {
        v[i] = s.displacement[i] / h;
    }
    if !obstacles.is_empty() {
        let (restitution, friction) = (model.settings.restitution, model.settings.friction);
        for i in 0..n {
            if let Some((normal, vn_before)) = s.contact[i] {
                // Restitution from the normal speed before the solve; friction on the rest.
                let vn = v[i].dot(normal);
                let bounce = (-restitution * vn_before).max(vn);
                let mut tangential = v[i] - normal * vn;
                let removed = (bounce - vn_before).max(0.0);
                let speed = tangential.length();
                if speed > 0.0 {
                    tangential *= (1.0 - friction * removed / speed).max(0.0);
                }
                v[i] = tangential + normal * bounce;
            }
        }
    }
    power * h as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stiff_distance_constraint_is_solved_in_one_update() {
        // K_s h² = 1e12 (the stiffest spring allowed at h = 1): as good as rigid.
        let dl = distance_delta_lambda(0.5, 0.0, 1.0, 1.0, 1e12, 0.0, 0.0);
        // Each end moves by 0.25 towards the other: the constraint is met.
        assert!((dl + 0.25).abs() < 1e-6);
        assert_eq!(distance_delta_lambda(0.5, 0.0, 0.0, 0.0, 1e12, 0.0, 0.0), -0.5e12);
        // Compliance (α̃ = 1/(K_s h²) = 2) softens it: -0.5 / (2 + 2).
        assert!((distance_delta_lambda(0.5, 0.0, 1.0, 1.0, 0.5, 0.0, 0.0) + 0.125).abs() < 1e-6);
    }

    /// The form of the update without 1/K_s: the same as the textbook one where that is finite,
    /// and finite (damping only) where K_s is too small for it.
    #[test]
    fn the_update_needs_no_division_by_the_stiffness() {
        let (ks, kd, h) = (300.0f32, 2.0f32, 0.01f32);
        let (alpha, gamma) = (1.0 / (ks * h * h), kd / (ks * h));
        let (c, lambda, wi, wj, vt) = (0.02f32, -0.003f32, 2.0f32, 0.5f32, 0.004f32);
        let textbook = (-c - alpha * lambda - gamma * vt) / ((1.0 + gamma) * (wi + wj) + alpha);
        let ours = distance_delta_lambda(c, lambda, wi, wj, ks * h * h, kd * h, vt);
        assert!((ours - textbook).abs() <= 1e-6 * textbook.abs(), "{ours} vs {textbook}");
        for ks in [1e-30f32, 1e-38, 1e-45] {
            let dl = distance_delta_lambda(c, lambda, wi, wj, ks * h * h, 1e9 * h, vt);
            assert!(dl.is_finite(), "K_s = {ks:e}: {dl}");
            // Damping alone: -(λ + K_d h vt) / (K_d h W + 1).
            let damped = -(lambda + 1e9 * h * vt) / (1e9 * h * (wi + wj) + 1.0);
            assert!((dl - damped).abs() <= 1e-5 * damped.abs(), "K_s = {ks:e}: {dl} vs {damped}");
        }
    }
}
