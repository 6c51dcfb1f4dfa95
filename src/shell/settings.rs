//! The shell's settings as plain Rust values (the C def is converted and validated in `ffi`).

use glam::Vec3;

use crate::material::{AnisotropicEnergy, Material};

/// The most substeps a step may take (the C ABI refuses more; an UNSTABLE step's advice never
/// asks for more).
pub const MAX_SUBSTEPS: u32 = 1000;

/// The shortest step the C ABI takes, s (likewise never advised below).
pub const MIN_TIME_STEP: f32 = 1e-6;

/// How the energy constraints are solved (SPEC 1.3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SolverKind {
    /// Consistent XPBD energy constraints: Young's modulus and thickness mean what they say.
    Xpbd,
    /// The paper's plain PBD form `C = W` (stiffness set by the iteration count).
    Pbd,
    /// Plain PBD edge-distance constraints instead of membrane energies (the paper's baseline).
    PbdDistance,
}

/// Which bending model (SPEC 1.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BendingKind {
    /// No bending constraints (none are built).
    None,
    /// The paper's isometric bending with a flat rest shape.
    Isometric,
    /// Isometric bending that keeps the rest curvature (the default).
    IsometricRest,
}

/// Everything that defines a shell simulation (see `SoftshellShellDef` for units and defaults).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShellSettings {
    /// Time step h, s.
    pub time_step: f32,
    /// Substeps per step.
    pub substeps: u32,
    /// Gauss-Seidel iterations per substep.
    pub iterations: u32,
    /// Constraint form.
    pub solver: SolverKind,
    /// Outside air pressure P, Pa.
    pub pressure: f32,
    /// Membrane material.
    pub material: Material,
    /// Young's modulus, Pa.
    pub youngs_modulus: f32,
    /// Poisson ratio in [0, 0.5).
    pub poisson_ratio: f32,
    /// Shell thickness, m.
    pub thickness: f32,
    /// Density, kg/m³.
    pub density: f32,
    /// Bending model.
    pub bending: BendingKind,
    /// kB (dimensionless).
    pub bending_coefficient: f32,
    /// Velocity damping per second.
    pub damping: f32,
    /// Finished when V/V0 falls below; 0 = never.
    pub stop_volume_ratio: f32,
    /// Self-collision stage enabled (filled by the collision module).
    pub collisions: bool,
    /// Collision thickness δ relative to the bounding-box diagonal.
    pub collision_thickness: f32,
    /// Worker threads (0 = all cores, 1 = serial).
    pub threads: u32,
}

/// One anisotropic region's settings (SPEC 1.5).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnisotropySettings {
    /// Fibre energy.
    pub energy: AnisotropicEnergy,
    /// Stiffness μ, Pa.
    pub stiffness: f32,
    /// Inward push k_A (dimensionless, see the shell's docs).
    pub inward_push: f32,
    /// Target stretch L in (0, 1].
    pub target_stretch: f32,
    /// Fibre direction in world space; zero = chosen per face.
    pub direction: Vec3,
}
