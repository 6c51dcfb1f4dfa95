//! The mass-spring soft body with gas and fracture (SPEC section 2).
//!
//! Vertices are mass points, mesh edges are damped springs, a closed body holds an ideal gas, and
//! over-strained springs crack the surface (virtual nodes by fan splitting, SPEC 2.4) while
//! over-loaded nodes release core blocks. Design:
//! - rest data (spring ends and rest lengths) in flat arrays, evolving state (x, v, masses) as
//!   structure-of-arrays in [`Body`];
//! - each force is a pure kernel with a finite-difference test (`springs`, `gas`, `wind`);
//! - one file per integrator (`explicit`, `implicit`, `xpbd`), all driven by [`Body::step`];
//! - topology changes (`crack`, `core_block`) run at one point of the step, after integration and
//!   outside every parallel loop, then `surface` rebuilds what they invalidated and bumps the
//!   generation.
//!
//! This module knows nothing of the C ABI.

mod cg_vectors;
mod cholesky;
mod coarse;
mod core_block;
mod coupling_slices;
mod crack;
mod energy;
mod explicit;
mod fan_rings;
mod forces;
mod gas;
mod headroom;
mod implicit;
mod obstacles;
mod settings;
mod simulator;
mod slice_update;
mod slice_vertices;
mod spring_sums;
mod spring_terms;
mod springs;
mod surface;
mod symmetric_block;
mod vertex_order;
mod wind;
mod xpbd;

/// The unit tests' random numbers: uniform in [-1, 1) from an xorshift64 generator started at
/// `seed` (the same sequence on every machine).
#[cfg(test)]
fn test_randoms(seed: u64) -> impl FnMut() -> f32 {
    let mut seed = seed;
    move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    }
}

pub use obstacles::Obstacle;
pub use settings::{BodySettings, Integrator, MAX_SUBSTEPS, MIN_TIME_STEP};
pub use simulator::{Body, BodyStats};
