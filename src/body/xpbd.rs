//! XPBD substeps (SPEC 2.2): springs as distance constraints `C = |x_j - x_i| - L0` with
//! compliance `1/K_s` and damping, the gas as a volume constraint whose multiplier is the
//! pressure impulse, projected by Gauss-Seidel: gas first, then springs (so each sweep ends with
//! the stiff constraints met), then obstacle contacts. Each constraint keeps its push (`Σ ∇C Δλ`)
//! and re-aims it at its current gradient before each update and once more at the end of the
//! substep, so that the substep solves `p = p̃ + M⁻¹ Σ ∇C(p) λ` (implicit Euler) and its forces
//! are central at its end ([`substep`]).
//!
//! Gas: implicit Euler on the energy `-nRT ln V` asks for `p = p̃ + M⁻¹ ∇V λ` with
//! `λ = h² nRT / V(p)`; each iteration takes one Newton step on `λ - h² nRT / V(p) = 0`,
//! linearising `V` along `M⁻¹ ∇V`: `Δλ = -(λ - h² nRT/V) / (1 + h² nRT |∇V|²_{M⁻¹} / V²)`.

use glam::Vec3;

use super::forces::{Model, external_forces};
use super::gas::Gas;
use super::obstacles::{Obstacle, project};
use crate::parallel::WorkerPool;

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
    /// Per spring: `Σ u Δλ` over this substep's updates, the push it applied (vertex j moved
    /// by `w_j` times it, vertex i by `-w_i` times it), kept to re-aim it ([`reaim`]).
    spring_push: Vec<Vec3>,
    /// Per vertex: `Σ ∇V_i Δλ` of its fragment's gas over this substep's updates (it moved by
    /// `w_i` times it), kept to re-aim it.
    gas_push: Vec<Vec3>,
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
        self.spring_push.clear();
        self.gas_lambda.clear();
        self.gas_push.clear();
    }

    pub fn memory_bytes(&self) -> usize {
        (self.force.capacity()
            + self.gradient.capacity()
            + self.displacement.capacity()
            + self.spring_push.capacity()
            + self.gas_push.capacity())
            * 12
            + self.lambda.capacity() * 4
            + (self.gas_lambda.capacity() + self.gas_norm.capacity() + self.gas_delta.capacity()) * 8
            + self.contact.capacity() * std::mem::size_of::<Option<(Vec3, f32)>>()
    }
}

/// The forces the last substep's constraints applied, on every vertex (springs with their
/// damping, and the gas), added to `f`: a constraint whose updates moved vertex i by
/// `w_i Σ ∇C_i Δλ` in a substep of length `h` pushed it with `Σ ∇C_i Δλ / h²` (the pushes the
/// substep kept, so exact whatever direction each update took). Returns false (and adds
/// nothing) when the scratch holds no pushes of these springs and gas fragments (no substep
/// since the body was made or its topology changed).
///
/// This is the load of an XPBD body (`break_force`, SPEC 2.4): with a few iterations its
/// constraints are far from converged, so the spring and gas laws at its positions give forces
/// that it never applied. A review saw a floating ball of gas 10 J (482 vertices, 1 substep of
/// 10 iterations) release 43 core blocks in its first step and all 482 by step 60 at
/// `break_force` 1 N, where implicit Euler's loads stay far below it and release none.
pub(crate) fn add_applied_forces(model: &Model, gas: Option<&Gas>, h: f32, s: &XpbdScratch, f: &mut [Vec3]) -> bool {
    let gas_fragments = gas.map_or(0, Gas::fragment_count);
    let has_gas = gas_fragments > 0;
    if s.spring_push.len() != model.springs.len()
        || (has_gas && (s.gas_push.len() != f.len() || s.gas_lambda.len() != gas_fragments))
    {
        return false;
    }
    let inv_h2 = 1.0 / (h * h);
    for (&[i, j], push) in model.springs.ends.iter().zip(&s.spring_push) {
        let push = *push * inv_h2;
        f[i as usize] -= push;
        f[j as usize] += push;
    }
    if has_gas {
        for (f, push) in f.iter_mut().zip(&s.gas_push) {
            *f += *push * inv_h2;
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

/// How far one re-aim of a spring may move its ends apart (`(w_i + w_j) |Δpush|`), in its rest
/// length. A spring whose push turned further than that (it flipped, or shrank to nearly no
/// length, on a shattering body) is turned there by steps: re-aimed whole at once, a balloon
/// that shatters in wind (`ffi_body_cloth`) went to NaN in its second step.
const SPRING_TURN: f32 = 0.1;

/// How far one re-aim of the gas may move a vertex, in its push `|∇V_i λ|` there: as the
/// trust region of the gas's update, the gas's linearisation is only good that far.
const GAS_TURN: f32 = 0.5;

/// Moves a constraint's push (`push`, `Σ ∇C Δλ` so far) by `fraction` of the way towards
/// `target` (`∇C λ` at the current positions), by at most `limit`, and returns the change, which
/// the caller applies to the positions times the inverse masses (nothing when it is not finite).
///
/// Why a fraction: re-aiming is a fixed-point iteration on the directions, and a push that moved
/// its vertices by `D` (`w |∇C λ|`) turns by `D / L` when they move sideways by `L`: where `D`
/// is not small against the lengths of the mesh, whole re-aims feed on each other. With
/// `fraction = 1 / (1 + c D / L)` they still converge to the consistent pushes, more slowly
/// where the pushes are large. Whole re-aims cracked a ball of gas 30 J (642 vertices, 50
/// iterations, break strain 0.1) into ~700 fragments where textbook XPBD leaves it whole, and
/// the gas's made NaN positions in the first step of one of 300 J (`ffi_body_xpbd`).
#[inline(always)]
fn reaim(target: Vec3, push: &mut Vec3, fraction: f32, limit: f32) -> Vec3 {
    let mut turn = (target - *push) * fraction;
    // Squared lengths compared (a square root only for a turn that is cut short). A turn whose
    // square overflows is cut to nothing (limit / ∞), as when lengths were compared, also where
    // the limit's own square overflows (a limit over 1.8e19: only in a blow-up).
    let squared = turn.length_squared();
    if squared > limit * limit || (squared == f32::INFINITY && limit < f32::INFINITY) {
        turn *= limit / squared.sqrt();
    }
    if !turn.is_finite() {
        return Vec3::ZERO;
    }
    *push += turn;
    turn
}

/// Re-aims the gas's push on every vertex at the gradient in `s.gradient` (measured at the
/// current positions), and adds to `s.gas_delta` each fragment's volume change by it, to first
/// order.
fn reaim_gas(model: &Model, gas: &Gas, x: &mut [Vec3], s: &mut XpbdScratch) {
    let XpbdScratch { gradient, gas_lambda, gas_push, gas_delta, displacement, .. } = s;
    for (i, g) in gradient.iter().enumerate() {
        let f = gas.vertex_fragment[i];
        if f != u32::MAX {
            let lambda = gas_lambda[f as usize] as f32;
            // `D / L` of [`reaim`], with `L ≈ √|∇V_i|` (a vertex's ∇V is about 0.9 L² on a
            // regular mesh). The gas's re-aims feed on themselves (pressure pushes a bulge
            // further out), so they go more slowly than the springs' (c = 4: without it the ball
            // of 300 J made NaN; c = 16 left the spinning ball of `ffi_body_xpbd` 1.2e-3 J of
            // its 1.4e-3 J limit).
            let reach = model.inv_mass[i] * lambda.abs() * g.length().sqrt();
            let fraction = 1.0 / (1.0 + 4.0 * reach);
            let turn = reaim(*g * lambda, &mut gas_push[i], fraction, GAS_TURN * g.length() * lambda.abs());
            let step = turn * model.inv_mass[i];
            x[i] += step;
            displacement[i] += step;
            gas_delta[f as usize] += g.dot(step) as f64;
        }
    }
}

/// Re-aims spring `k` (ends i, j) at its direction `u` and length `len` at the current positions
/// (moves them by `w (u λ - push)` times the fraction of [`reaim`], at most [`SPRING_TURN`]).
#[inline(always)]
fn reaim_spring(
    x: &mut [Vec3],
    s: &mut XpbdScratch,
    k: usize,
    (i, j): (usize, usize),
    (wi, wj): (f32, f32),
    (u, len): (Vec3, f32),
    rest: f32,
) {
    // `D / L` of [`reaim`]: how far the spring's push moved its ends, against its length.
    let fraction = 1.0 / (1.0 + (wi + wj) * s.lambda[k].abs() / len);
    let turn = reaim(u * s.lambda[k], &mut s.spring_push[k], fraction, SPRING_TURN * rest / (wi + wj));
    let (step_i, step_j) = (turn * wi, turn * wj);
    x[i] -= step_i;
    x[j] += step_j;
    s.displacement[i] -= step_i;
    s.displacement[j] += step_j;
}

/// Projects the vertices that entered an obstacle back to its surface, noting the first contact
/// of each in this substep (with the normal speed it had before the solve).
fn project_contacts(model: &Model, x: &mut [Vec3], v: &[Vec3], obstacles: &[Obstacle], s: &mut XpbdScratch) {
    for i in 0..x.len() {
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

/// One substep of length `h` with `iterations` Gauss-Seidel sweeps; returns the wind work, J.
///
/// Implicit Euler asks for `p = p̃ + M⁻¹ Σ ∇C(p) λ` (SPEC 2.2): every constraint's push along
/// its gradient at the END of the substep. Textbook XPBD adds each update along the gradient of
/// that moment, so a spring held in tension by the gas (large λ) keeps pushes along directions
/// it no longer has once the body turned within the substep: net forces that are not central,
/// a torque from nothing. A floating ball of gas 10 J without damping (162 vertices, 1 substep
/// of 10 iterations) spun up from 0.013 J to 0.14 J of kinetic energy in 1,500 steps, and 1 or
/// 10 substeps, 10 or 200 iterations did not stop it. So each update first re-aims the
/// constraint's whole push so far at its current gradient (Gauss-Seidel on the nonlinear
/// system), and a last sweep after the iterations re-aims them all at the final positions.
/// Re-aims go part of the way where pushes are large ([`reaim`]) and are bounded
/// ([`SPRING_TURN`], [`GAS_TURN`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn substep(
    model: &Model,
    mut gas: Option<&mut Gas>,
    x: &mut [Vec3],
    v: &mut [Vec3],
    h: f32,
    iterations: u32,
    obstacles: &[Obstacle],
    pool: &WorkerPool,
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
    s.spring_push.clear();
    s.spring_push.resize(model.springs.len(), Vec3::ZERO);
    let h2 = (h * h) as f64;
    if let Some(gas) = gas.as_deref() {
        s.gradient.resize(n, Vec3::ZERO);
        s.gas_lambda.clear();
        s.gas_lambda.resize(gas.fragment_count(), 0.0);
        s.gas_norm.resize(gas.fragment_count(), 0.0);
        s.gas_delta.resize(gas.fragment_count(), 0.0);
        s.gas_push.clear();
        s.gas_push.resize(n, Vec3::ZERO);
    }
    let (stiffness_h2, damping_h) = (ks * h * h, kd * h);
    for _ in 0..iterations.max(1) {
        if let Some(gas) = gas.as_deref_mut() {
            gas.measure_with_gradient_parallel(pool, x, model.triangles, &mut s.gradient);
            // gas_delta first holds the volume change of the re-aim, to correct the volume
            // measured before it.
            s.gas_delta.fill(0.0);
            reaim_gas(model, gas, x, s);
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
                        let volume = gas.volume[f] + *delta;
                        let vol = volume.max(gas.v_min[f]).max(f64::MIN_POSITIVE);
                        let target = h2 * gas.n_rt[f] / vol;
                        let slope = if volume > gas.v_min[f] { h2 * gas.n_rt[f] / (vol * vol) } else { 0.0 };
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
                    let push = *g * deltas[f as usize] as f32;
                    s.gas_push[i] += push;
                    let step = push * model.inv_mass[i];
                    x[i] += step;
                    s.displacement[i] += step;
                }
            }
        }
        if ks > 0.0 {
            for (k, (&[i, j], &rest)) in model.springs.ends.iter().zip(&model.springs.rest).enumerate() {
                let (i, j) = (i as usize, j as usize);
                let (wi, wj) = (model.inv_mass[i], model.inv_mass[j]);
                let Some((mut u, mut len)) = spring_direction(x, i, j, rest) else { continue };
                if s.lambda[k] != 0.0 {
                    reaim_spring(x, s, k, (i, j), (wi, wj), (u, len), rest);
                    let Some(moved) = spring_direction(x, i, j, rest) else { continue };
                    (u, len) = moved;
                }
                let velocity_term = u.dot(s.displacement[j] - s.displacement[i]);
                let dl = distance_delta_lambda(len - rest, s.lambda[k], wi, wj, stiffness_h2, damping_h, velocity_term);
                s.lambda[k] += dl;
                s.spring_push[k] += u * dl;
                let (step_i, step_j) = (u * (wi * dl), u * (wj * dl));
                x[i] -= step_i;
                x[j] += step_j;
                s.displacement[i] -= step_i;
                s.displacement[j] += step_j;
            }
        }
        if !obstacles.is_empty() {
            project_contacts(model, x, v, obstacles, s);
        }
    }
    // The last sweep: every push re-aimed at the end of the substep, the gas's (its gradient
    // was measured before the last springs moved) and the springs' (each was aimed before the
    // springs after it in the sweep moved its ends). Without it the ball above still gained
    // 1.5e-3 J in 1,500 steps (after 0.16 J without re-aims), and with 1 iteration a substep,
    // where no update has a push to re-aim, it spun up as before.
    if let Some(gas) = gas.as_deref_mut() {
        gas.measure_with_gradient_parallel(pool, x, model.triangles, &mut s.gradient);
        s.gas_delta.fill(0.0);
        reaim_gas(model, gas, x, s);
    }
    if ks > 0.0 {
        for (k, (&[i, j], &rest)) in model.springs.ends.iter().zip(&model.springs.rest).enumerate() {
            let (i, j) = (i as usize, j as usize);
            if s.lambda[k] != 0.0 {
                let Some(direction) = spring_direction(x, i, j, rest) else { continue };
                reaim_spring(x, s, k, (i, j), (model.inv_mass[i], model.inv_mass[j]), direction, rest);
            }
        }
    }
    if !obstacles.is_empty() {
        project_contacts(model, x, v, obstacles, s);
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

    /// A re-aim moves the push by its fraction of the way to its target when that is within
    /// the limit, else by the limit towards it, and never by a non-finite step.
    #[test]
    fn a_reaim_turns_a_push_at_most_by_its_limit() {
        let mut push = Vec3::new(2.0, 0.0, 0.0);
        assert_eq!(reaim(Vec3::new(0.0, 2.0, 0.0), &mut push, 1.0, 3.0), Vec3::new(-2.0, 2.0, 0.0));
        assert_eq!(push, Vec3::new(0.0, 2.0, 0.0));
        let mut push = Vec3::new(2.0, 0.0, 0.0);
        let turn = reaim(Vec3::new(0.0, 2.0, 0.0), &mut push, 0.25, 3.0);
        assert_eq!((turn, push), (Vec3::new(-0.5, 0.5, 0.0), Vec3::new(1.5, 0.5, 0.0)));
        let mut push = Vec3::new(2.0, 0.0, 0.0);
        let turn = reaim(Vec3::new(-2.0, 0.0, 0.0), &mut push, 1.0, 1.0);
        assert_eq!((turn, push), (Vec3::new(-1.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0)));
        for target in [Vec3::splat(f32::NAN), Vec3::splat(f32::INFINITY)] {
            let mut push = Vec3::X;
            assert_eq!(reaim(target, &mut push, 1.0, f32::INFINITY), Vec3::ZERO);
            assert_eq!(push, Vec3::X);
        }
        // A zero limit (no multiplier yet) leaves the push.
        let mut push = Vec3::X;
        assert_eq!(reaim(Vec3::Y, &mut push, 1.0, 0.0), Vec3::ZERO);
        assert_eq!(push, Vec3::X);
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
