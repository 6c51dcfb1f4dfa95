//! Linearised backward Euler (SPEC 2.2), solved by matrix-free preconditioned conjugate
//! gradients: `(M - h² K - h D) Δv = h f + h² K v`, then `v += Δv`, `x += h v`.
//!
//! K holds each spring's stiffness block `a I + b u uᵀ` (transverse part clamped at zero when
//! compressed, so the system is positive definite) and the rank-one gas term
//! `-(P/V) ∂V/∂x ∂V/∂xᵀ` of `∂(P ∂V/∂x)/∂x` (the indefinite `P ∂²V/∂x²` part is left out);
//! D is the spring damping `K_d u uᵀ`. Pinned vertices are filtered out of the system.

use glam::{Mat3, Vec3};

use super::forces::{Model, all_forces};
use super::gas::Gas;
use super::obstacles::{Obstacle, touching};
use super::springs::spring_block;
use crate::parallel::WorkerPool;

/// Scratch of the implicit integrator (allocated only when it is used).
#[derive(Default)]
pub(crate) struct ImplicitScratch {
    pub force: Vec<Vec3>,
    pub gradient: Vec<Vec3>,
    /// Per spring `(α, β, u)`: the system block `α I + β u uᵀ`.
    blocks: Vec<(f32, f32, Vec3)>,
    rhs: Vec<Vec3>,
    dv: Vec<Vec3>,
    r: Vec<Vec3>,
    z: Vec<Vec3>,
    p: Vec<Vec3>,
    ap: Vec<Vec3>,
    /// The block-Jacobi preconditioner: each vertex's 3x3 diagonal block of the system matrix,
    /// inverted in place once assembled.
    diag: Vec<Mat3>,
    /// Per vertex, the sum of the magnitudes of the forces acting on it (springs, gas, gravity):
    /// the scale that the residual of the solve is measured against.
    magnitude: Vec<f32>,
    /// Per fragment `h² P/V` (gas rank-one term) and a per-fragment dot product buffer.
    gas_coef: Vec<f64>,
    gas_dot: Vec<f64>,
    /// Δv of the previous substep (the warm start), reset when the vertex count changes.
    previous_dv: Vec<Vec3>,
    /// Contact normal of each vertex resting on an obstacle (only with obstacles).
    contact: Vec<Option<Vec3>>,
}

impl ImplicitScratch {
    pub fn memory_bytes(&self) -> usize {
        (self.force.capacity()
            + self.gradient.capacity()
            + self.rhs.capacity()
            + self.dv.capacity()
            + self.r.capacity()
            + self.z.capacity()
            + self.p.capacity()
            + self.ap.capacity()
            + self.previous_dv.capacity())
            * 12
            + self.contact.capacity() * std::mem::size_of::<Option<Vec3>>()
            + self.blocks.capacity() * 20
            + (self.gas_coef.capacity() + self.gas_dot.capacity()) * 8
            + self.magnitude.capacity() * 4
            + self.diag.capacity() * std::mem::size_of::<Mat3>()
    }
}

/// Relative residual at which conjugate gradients stop: against the larger of the right side and
/// the size of the forces themselves (`h Σ|f|` per vertex). Near equilibrium the net force is a
/// small difference of large spring and gas forces, so a test relative to the right side alone
/// asks for more digits than the f32 forces have and runs to the iteration cap every step.
const CG_TOLERANCE: f32 = 1e-5;

/// Vertices per parallel chunk (fixed, so the result does not depend on the thread count).
const CHUNK: usize = 2048;

/// `out = A input` for the system matrix `M - h² K - h D` (pinned rows zero). The spring part is
/// gathered per vertex in a fixed order, in parallel chunks; the gas rank-one part is serial.
fn apply(
    model: &Model,
    pool: &WorkerPool,
    gas: Option<&Gas>,
    s: &ImplicitScratch,
    input: &[Vec3],
    out: &mut [Vec3],
    gas_dot: &mut [f64],
) {
    let springs = model.springs;
    let blocks = &s.blocks;
    pool.for_each_chunk_mut(out, CHUNK, |c, chunk| {
        for (k, o) in chunk.iter_mut().enumerate() {
            let i = c * CHUNK + k;
            let mut acc = input[i] * model.mass[i];
            for &(spring, j) in springs.around(i) {
                let (alpha, beta, u) = blocks[spring as usize];
                let d = input[i] - input[j as usize];
                acc += d * alpha + u * (beta * u.dot(d));
            }
            *o = acc;
        }
    });
    if let Some(gas) = gas {
        gas_dot.iter_mut().for_each(|d| *d = 0.0);
        for (i, g) in s.gradient.iter().enumerate() {
            let f = gas.vertex_fragment[i];
            if f != u32::MAX {
                gas_dot[f as usize] += g.dot(input[i]) as f64;
            }
        }
        for (i, g) in s.gradient.iter().enumerate() {
            let f = gas.vertex_fragment[i];
            if f != u32::MAX && s.gas_coef[f as usize] != 0.0 {
                out[i] += *g * (s.gas_coef[f as usize] * gas_dot[f as usize]) as f32;
            }
        }
    }
    // Pinned vertices are not unknowns.
    for (o, &w) in out.iter_mut().zip(model.inv_mass) {
        if w == 0.0 {
            *o = Vec3::ZERO;
        }
    }
}

/// `a bᵀ`.
fn outer(a: Vec3, b: Vec3) -> Mat3 {
    Mat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// Inverse of a symmetric positive definite block; its diagonal inverse when the block is
/// (numerically) singular, or zero for an empty row.
fn invert_block(m: Mat3) -> Mat3 {
    let det = m.determinant();
    let scale = m.x_axis.x.abs() + m.y_axis.y.abs() + m.z_axis.z.abs();
    if det.is_finite() && det > 1e-12 * scale * scale * scale {
        m.inverse()
    } else {
        let d = Vec3::new(m.x_axis.x, m.y_axis.y, m.z_axis.z);
        Mat3::from_diagonal(Vec3::ONE / d.max(Vec3::splat(f32::MIN_POSITIVE)))
    }
}

fn dot(a: &[Vec3], b: &[Vec3]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a.dot(*b) as f64).sum()
}

/// One substep of length `h`; returns (wind work in J, conjugate-gradient iterations).
#[allow(clippy::too_many_arguments)]
pub(crate) fn substep(
    model: &Model,
    mut gas: Option<&mut Gas>,
    x: &mut [Vec3],
    v: &mut [Vec3],
    h: f32,
    max_iterations: usize,
    pool: &WorkerPool,
    obstacles: &[Obstacle],
    s: &mut ImplicitScratch,
) -> (f64, usize) {
    let n = x.len();
    for buffer in [&mut s.force, &mut s.rhs, &mut s.dv, &mut s.r, &mut s.z, &mut s.p, &mut s.ap] {
        buffer.resize(n, Vec3::ZERO);
    }
    s.magnitude.resize(n, 0.0);
    s.diag.resize(n, Mat3::ZERO);
    if gas.is_some() {
        s.gradient.resize(n, Vec3::ZERO);
    }
    let power = all_forces(model, gas.as_deref_mut(), x, v, &mut s.gradient, &mut s.force);
    let (ks, kd) = (model.settings.spring_stiffness, model.settings.spring_damping);
    let h2 = h * h;

    // Right side h f + h² K v, spring blocks and the Jacobi preconditioner.
    s.blocks.clear();
    for (i, rhs) in s.rhs.iter_mut().enumerate() {
        *rhs = s.force[i] * h;
        s.diag[i] = Mat3::from_diagonal(Vec3::splat(model.mass[i]));
        s.magnitude[i] = model.mass[i] * model.settings.gravity.length();
    }
    for (&[i, j], &rest) in model.springs.ends.iter().zip(&model.springs.rest) {
        let (i, j) = (i as usize, j as usize);
        let (a, b, u) = spring_block(x[i], x[j], rest, ks);
        let tension = (ks * ((x[j] - x[i]).length() - rest)).abs();
        s.magnitude[i] += tension;
        s.magnitude[j] += tension;
        // h² K v at i: h² B (v_j - v_i)
        let dvel = v[j] - v[i];
        let kv = (dvel * a + u * (b * u.dot(dvel))) * h2;
        s.rhs[i] += kv;
        s.rhs[j] -= kv;
        let (alpha, beta) = (h2 * a, h2 * b + h * kd);
        s.blocks.push((alpha, beta, u));
        let d = Mat3::from_diagonal(Vec3::splat(alpha)) + outer(u * beta, u);
        s.diag[i] += d;
        s.diag[j] += d;
    }
    if let Some(gas) = gas.as_deref() {
        let frags = gas.fragment_count();
        s.gas_coef.clear();
        s.gas_coef.extend((0..frags).map(|f| {
            let vol = gas.volume[f].max(gas.v_min[f]);
            if gas.pressure[f] > 0.0 && vol > 0.0 { (h2 as f64) * gas.pressure[f] / vol } else { 0.0 }
        }));
        s.gas_dot.resize(frags, 0.0);
        s.gas_dot.fill(0.0);
        for (i, g) in s.gradient.iter().enumerate() {
            let f = gas.vertex_fragment[i];
            if f != u32::MAX {
                s.gas_dot[f as usize] += g.dot(v[i]) as f64;
                s.magnitude[i] += g.length() * gas.pressure[f as usize].max(0.0) as f32;
                s.diag[i] += outer(*g * s.gas_coef[f as usize] as f32, *g);
            }
        }
        for (i, g) in s.gradient.iter().enumerate() {
            let f = gas.vertex_fragment[i];
            if f != u32::MAX {
                // -h² (P/V) g (g·v)
                s.rhs[i] -= *g * (s.gas_coef[f as usize] * s.gas_dot[f as usize]) as f32;
            }
        }
    }
    for i in 0..n {
        if model.inv_mass[i] == 0.0 {
            s.rhs[i] = Vec3::ZERO;
        }
    }

    // Preconditioned conjugate gradients, warm-started from the previous substep's Δv (the
    // velocity change varies slowly from step to step), or on the first substep from the
    // free-fall guess Δv = h g: either solves the rigid translation, the mode that a Jacobi
    // preconditioner dominated by stiff springs resolves worst.
    if s.previous_dv.len() != n {
        let g = model.settings.gravity * h;
        s.previous_dv.clear();
        s.previous_dv.resize(n, g);
    }
    for i in 0..n {
        s.dv[i] = if model.inv_mass[i] == 0.0 { Vec3::ZERO } else { s.previous_dv[i] };
    }
    // Contacts inside the solve (Baraff and Witkin 1998, modified PCG): a vertex resting on an
    // obstacle, moving and pushed into it, gets the constraint (v + Δv)·n = 0; its normal component is
    // filtered out of the residual and the search directions. Restitution and friction follow
    // after the solve, with the other integrators' contact response.
    s.contact.clear();
    let mut any_contact = false;
    if !obstacles.is_empty() {
        s.contact.resize(n, None);
        for i in 0..n {
            if model.inv_mass[i] > 0.0 {
                if let Some(normal) = touching(x[i], obstacles, 1e-6) {
                    // Released when moving away or pulled away (the contact cannot pull).
                    if v[i].dot(normal) <= 0.0 && s.force[i].dot(normal) <= 0.0 {
                        s.contact[i] = Some(normal);
                        any_contact = true;
                        let dv = s.dv[i];
                        s.dv[i] = dv - normal * (dv.dot(normal) + v[i].dot(normal));
                    }
                }
            }
        }
    }
    let filter = |values: &mut [Vec3], contact: &[Option<Vec3>]| {
        for (value, c) in values.iter_mut().zip(contact) {
            if let Some(normal) = c {
                *value -= *normal * value.dot(*normal);
            }
        }
    };
    let mut ap = std::mem::take(&mut s.ap);
    let mut gas_dot = std::mem::take(&mut s.gas_dot);
    apply(model, pool, gas.as_deref(), s, &s.dv, &mut ap, &mut gas_dot);
    s.ap = ap;
    s.gas_dot = gas_dot;
    // The block-Jacobi preconditioner, inverted once (stored in `diag`). Per vertex the springs
    // are stiff along the surface and soft across it, which a diagonal (per axis) preconditioner
    // cannot tell apart on a curved surface; the 3x3 block can.
    for d in s.diag.iter_mut() {
        *d = invert_block(*d);
    }
    for i in 0..n {
        s.r[i] = s.rhs[i] - s.ap[i];
    }
    if any_contact {
        filter(&mut s.r, &s.contact);
    }
    let mut rz = 0.0f64;
    for i in 0..n {
        let mut z = s.diag[i] * s.r[i];
        if let Some(Some(normal)) = s.contact.get(i) {
            z -= *normal * z.dot(*normal);
        }
        s.z[i] = z;
        rz += s.r[i].dot(s.z[i]) as f64;
    }
    s.p.copy_from_slice(&s.z);
    let force_scale = h as f64 * s.magnitude.iter().map(|&m| (m as f64) * (m as f64)).sum::<f64>().sqrt();
    let r0 = dot(&s.rhs, &s.rhs).sqrt().max(force_scale);
    let mut gas_dot = std::mem::take(&mut s.gas_dot);
    let mut iterations = 0;
    if r0 > 0.0 {
        let tolerance = (CG_TOLERANCE as f64 * r0).powi(2);
        while iterations < max_iterations {
            iterations += 1;
            let mut ap = std::mem::take(&mut s.ap);
            apply(model, pool, gas.as_deref(), s, &s.p, &mut ap, &mut gas_dot);
            if any_contact {
                filter(&mut ap, &s.contact);
            }
            s.ap = ap;
            let pap = dot(&s.p, &s.ap);
            if pap <= 0.0 || !pap.is_finite() {
                break;
            }
            let alpha = (rz / pap) as f32;
            // Fused: Δv and r updates, z = M⁻¹ r, and the two dot products in one pass.
            let (mut rr, mut rz_next) = (0.0f64, 0.0f64);
            for i in 0..n {
                s.dv[i] += s.p[i] * alpha;
                s.r[i] -= s.ap[i] * alpha;
                let mut z = s.diag[i] * s.r[i];
                if let Some(Some(normal)) = s.contact.get(i) {
                    z -= *normal * z.dot(*normal);
                }
                s.z[i] = z;
                rr += s.r[i].length_squared() as f64;
                rz_next += s.r[i].dot(s.z[i]) as f64;
            }
            if rr <= tolerance {
                break;
            }
            let beta = (rz_next / rz) as f32;
            rz = rz_next;
            for i in 0..n {
                s.p[i] = s.z[i] + s.p[i] * beta;
            }
        }
    }
    s.gas_dot = gas_dot;
    // Internal forces cannot change the momentum, so Σ m Δv = Σ rhs exactly (every coupling term
    // of the matrix sums to zero); a truncated solve leaves a small error there, removed by a
    // uniform correction. Not with pins or contacts: their reactions are external forces.
    if !any_contact && model.inv_mass.iter().zip(model.mass).all(|(&w, &m)| w > 0.0 || m == 0.0) {
        let (mut error, mut mass) = (glam::DVec3::ZERO, 0.0f64);
        for i in 0..n {
            error += s.rhs[i].as_dvec3() - s.dv[i].as_dvec3() * model.mass[i] as f64;
            mass += model.mass[i] as f64;
        }
        if mass > 0.0 {
            let correction = (error / mass).as_vec3();
            for dv in s.dv.iter_mut() {
                *dv += correction;
            }
        }
    }
    s.previous_dv.copy_from_slice(&s.dv);
    for i in 0..n {
        if model.inv_mass[i] == 0.0 {
            continue;
        }
        v[i] += s.dv[i];
        x[i] += v[i] * h;
    }
    (power * h as f64, iterations)
}
