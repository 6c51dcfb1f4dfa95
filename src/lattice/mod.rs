//! FastLSM elastic lattice surface (SPEC 3; Rivers and James 2007).
//!
//! Particles sit on a columns x rows lattice (with an optional mask of holes) embedded in 3D.
//! Each particle owns the square region of sites within `w` lattice steps; every region is
//! shape-matched to its rest shape, and each particle is pulled towards the mean of its regions'
//! goals. All region sums are box sums computed by separable running sums (`summation`), so a
//! step costs the same whatever `w` is.
//!
//! Files, one concept each: `params` (settings and their validation), `layout` (lattice, mask,
//! numbering, rest positions, output triangles), `summation` (fast and naive box sums),
//! `polar` (the SVD polar decomposition), `matching` (per-particle moments, region fit, goal),
//! `damping` (region damping), `simulator` (state, pins, forces) and `step` (the parallel step).
//! Nothing here knows about the C ABI.

mod damping;
mod layout;
mod matching;
mod params;
mod polar;
mod simulator;
mod step;
mod summation;

#[cfg(test)]
mod reference;

pub use layout::LatticeLayout;
pub use params::LatticeParams;
pub use simulator::{Lattice, StepStats};
