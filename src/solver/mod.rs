//! Position-based constraint kernels (pure functions) and the deterministic graph colouring that
//! lets Gauss-Seidel run in parallel.
//!
//! Owns: the triangle strain element (rest data, F, gradients from a stress), the PBD and XPBD
//! energy constraints of SPEC 1.3, isometric bending (SPEC 1.4), the anisotropic push (SPEC 1.5),
//! colouring. Must not know which simulator calls it or hold any state between calls.

mod bending;
mod colouring;
mod distance;
mod energy_constraint;
mod membrane_wide;
mod triangle;
mod wide;

pub use bending::{
    BendingRest, WideTarget, bending_energy, bending_projection, bending_projection_wide, bending_residual,
    bending_rest, bending_target,
};
pub use colouring::colour_constraints;
pub use distance::distance_correction;
pub use energy_constraint::{pbd_energy_correction, xpbd_energy_correction};
pub use membrane_wide::{MembraneLanes, stvk_projection_wide};
pub use triangle::{TriangleRest, deformation_gradient, scatter_stress, triangle_rest};
pub use wide::W3;
