//! The thin-shell contraction simulator (SPEC section 1): a closed triangle mesh squeezed by
//! outside air pressure, solved by position-based dynamics with energy constraints (membrane,
//! bending, local anisotropic), Gauss-Seidel in parallel by colour.
//!
//! Owns: the settings, the flat rest data of every constraint kind, the evolving state and the
//! step of SPEC 1.1. Uses `mesh`, `material` and `solver`; knows nothing of the C ABI.
//! The collision stage (SPEC 1.1 step 3) runs `collision::SelfContact` when collisions are on.

mod constraints;
mod exec;
mod measure;
mod project;
mod settings;
mod simulator;

pub use settings::{AnisotropySettings, BendingKind, MAX_SUBSTEPS, MIN_TIME_STEP, ShellSettings, SolverKind};
pub use simulator::{CollisionReport, Shell, ShellStats};
