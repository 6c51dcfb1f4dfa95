//! The force loop (SPEC 2.1, 2.5): gravity, springs with damping, gas pressure and wind, summed
//! per vertex. The springs in a serial scatter in a fixed order, the gas's gradient gathered per
//! vertex in fixed chunks: the sums are the same whatever the thread count.

use glam::Vec3;

use super::gas::Gas;
use super::settings::BodySettings;
use super::springs::{Springs, spring_force};

/// What the force loops read from a body (borrowed for one substep).
pub(crate) struct Model<'a> {
    pub settings: &'a BodySettings,
    pub triangles: &'a [[u32; 3]],
    pub springs: &'a Springs,
    pub mass: &'a [f32],
    pub inv_mass: &'a [f32],
    /// The wind's force on each vertex at the start of the substep (empty without wind):
    /// `Body::substep` measures it once, for the wind's work and for the integrator, where both
    /// measured it (and allocated a per-vertex buffer for it) each substep.
    pub wind_force: &'a [Vec3],
}

impl Model<'_> {
    /// True when the wind does anything.
    pub fn has_wind(&self) -> bool {
        self.settings.drag > 0.0
    }
}

/// Gravity and wind into `f` (overwritten); returns the wind power, W.
pub(crate) fn external_forces(model: &Model, v: &[Vec3], f: &mut [Vec3]) -> f64 {
    let g = model.settings.gravity;
    for (fi, &m) in f.iter_mut().zip(model.mass) {
        *fi = g * m;
    }
    if model.has_wind() {
        debug_assert_eq!(model.wind_force.len(), f.len(), "the wind is measured at the substep's start");
        let mut power = 0.0f64;
        for ((fi, &wind), vi) in f.iter_mut().zip(model.wind_force).zip(v) {
            *fi += wind;
            power += wind.dot(*vi) as f64;
        }
        power
    } else {
        0.0
    }
}

/// Spring and damping forces added to `f` (SPEC 2.1 eq. 1-2).
pub(crate) fn add_spring_forces(model: &Model, x: &[Vec3], v: &[Vec3], f: &mut [Vec3]) {
    let (ks, kd) = (model.settings.spring_stiffness, model.settings.spring_damping);
    for (&[i, j], &rest) in model.springs.ends.iter().zip(&model.springs.rest) {
        let (i, j) = (i as usize, j as usize);
        let force = spring_force(x[i], x[j], v[i], v[j], rest, ks, kd);
        f[i] += force;
        f[j] -= force;
    }
}

/// Gas pressure forces `P_f ∂V_f/∂x_i` added to `f` (SPEC 2.1 eq. 8-9); measures the gas at `x`
/// on `pool` (each vertex gathers its corners' terms, in fixed chunks: the same bits on any
/// number of threads) and leaves `∂V/∂x` in `gradient`.
pub(crate) fn add_gas_forces_parallel(
    model: &Model,
    pool: &crate::parallel::WorkerPool,
    gas: &mut Gas,
    x: &[Vec3],
    gradient: &mut [Vec3],
    f: &mut [Vec3],
) {
    gas.measure_with_gradient_parallel(pool, x, model.triangles, gradient);
    for (i, g) in gradient.iter().enumerate() {
        let frag = gas.vertex_fragment[i];
        if frag != u32::MAX {
            f[i] += *g * gas.pressure[frag as usize] as f32;
        }
    }
}

/// Every force at (x, v) into `f`; returns the wind power.
pub(crate) fn all_forces(
    model: &Model,
    gas: Option<&mut Gas>,
    pool: &crate::parallel::WorkerPool,
    x: &[Vec3],
    v: &[Vec3],
    gradient: &mut [Vec3],
    f: &mut [Vec3],
) -> f64 {
    let power = external_forces(model, v, f);
    add_spring_forces(model, x, v, f);
    if let Some(gas) = gas {
        add_gas_forces_parallel(model, pool, gas, x, gradient, f);
    }
    power
}
