//! Explicit Euler (the paper's, SPEC 2.2) and symplectic Euler substeps.

use glam::Vec3;

use super::forces::{Model, all_forces};
use super::gas::Gas;
use crate::parallel::WorkerPool;

/// Scratch of the explicit integrators.
#[derive(Default)]
pub(crate) struct ExplicitScratch {
    pub force: Vec<Vec3>,
    pub gradient: Vec<Vec3>,
}

/// One substep of length `h`. `symplectic = false`: `x += h v; v += h a` (old v, the paper's);
/// `true`: `v += h a; x += h v`. Returns the work done by the wind, J.
pub(crate) fn substep(
    model: &Model,
    gas: Option<&mut Gas>,
    x: &mut [Vec3],
    v: &mut [Vec3],
    h: f32,
    symplectic: bool,
    pool: &WorkerPool,
    s: &mut ExplicitScratch,
) -> f64 {
    s.force.resize(x.len(), Vec3::ZERO);
    if gas.is_some() {
        s.gradient.resize(x.len(), Vec3::ZERO);
    }
    let power = all_forces(model, gas, pool, x, v, &mut s.gradient, &mut s.force);
    for i in 0..x.len() {
        let a = s.force[i] * model.inv_mass[i];
        if symplectic {
            v[i] += a * h;
            x[i] += v[i] * h;
        } else {
            x[i] += v[i] * h;
            v[i] += a * h;
        }
    }
    power * h as f64
}
