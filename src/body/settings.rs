//! The settings of a soft body (the Rust side of `SoftshellBodyDef`).

use super::springs::Adjacency;
use glam::Vec3;

/// Time integrator of a soft body (SPEC 2.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Integrator {
    /// `x += h v; v += h a` with the old v: the paper's; stable only with spring damping, for
    /// `h < K_d/K_s` (see `Body::stable_time_step`).
    ExplicitEuler,
    /// `v += h a; x += h v`: stable for `h² ω_max² + 2 h γ_max < 4` (`h < 2/ω_max` without
    /// damping), energy-conserving on average.
    SymplecticEuler,
    /// Linearised backward Euler solved by matrix-free conjugate gradients: stable at any `h`.
    ImplicitEuler,
    /// Springs as distance constraints with compliance `1/K_s`, gas as a volume constraint.
    Xpbd,
}

/// The most substeps a step may take (the C ABI refuses more; the advice of an UNSTABLE step
/// never asks for more).
pub const MAX_SUBSTEPS: u32 = 1000;

/// The shortest step the C ABI takes, s (the advice of an UNSTABLE step never asks for less).
pub const MIN_TIME_STEP: f32 = 1e-6;

/// Settings of a [`crate::body::Body`]. Validated by the caller (the C boundary checks ranges);
/// [`crate::body::Body::new`] checks what depends on the mesh.
#[derive(Clone, Debug)]
pub struct BodySettings {
    /// Step length h, s.
    pub time_step: f32,
    /// Substeps per step (each of h / substeps), at most [`MAX_SUBSTEPS`] through the C ABI.
    pub substeps: u32,
    /// XPBD Gauss-Seidel iterations per substep; cap on conjugate-gradient iterations / 10 for
    /// the implicit integrator.
    pub iterations: u32,
    /// Integrator.
    pub integrator: Integrator,
    /// Total mass, kg, spread over the vertices by area.
    pub total_mass: f32,
    /// K_s, N/m.
    pub spring_stiffness: f32,
    /// K_d, N s/m.
    pub spring_damping: f32,
    /// nRT, J; 0 = no gas.
    pub gas_amount: f32,
    /// m/s^2.
    pub gravity: Vec3,
    /// Wind velocity, m/s.
    pub wind: Vec3,
    /// Drag coefficient of the wind, kg/(m^2 s).
    pub drag: f32,
    /// Spring strain that cracks; 0 = never.
    pub break_strain: f32,
    /// Net node force that releases a core block, N; 0 = never.
    pub break_force: f32,
    /// Gas leak coefficient through holes, m/(Pa s) (SPEC 2.4).
    pub leak_rate: f32,
    /// A ground plane y = ground_height.
    pub ground: bool,
    /// Height of the ground plane, m.
    pub ground_height: f32,
    /// Restitution of obstacle contacts, in [0, 1].
    pub restitution: f32,
    /// Coulomb friction coefficient of obstacle contacts.
    pub friction: f32,
    /// Worker threads (0 = all cores, 1 = serial).
    pub threads: u32,
}

impl Default for BodySettings {
    fn default() -> Self {
        Self {
            time_step: 1.0 / 60.0,
            substeps: 1,
            iterations: 10,
            integrator: Integrator::ImplicitEuler,
            total_mass: 1.0,
            spring_stiffness: 1000.0,
            spring_damping: 1.0,
            gas_amount: 0.0,
            gravity: Vec3::new(0.0, -9.81, 0.0),
            wind: Vec3::ZERO,
            drag: 0.0,
            break_strain: 0.0,
            break_force: 0.0,
            leak_rate: 0.0,
            ground: false,
            ground_height: 0.0,
            restitution: 0.0,
            friction: 0.5,
            threads: 1,
        }
    }
}

impl BodySettings {
    /// True when fracture can happen by itself (a break limit is set).
    pub fn fracture_enabled(&self) -> bool {
        self.break_strain > 0.0 || self.break_force > 0.0
    }

    /// Whether the springs keep their per-vertex adjacency: only for the implicit integrator,
    /// which gathers its system by vertex ([`Adjacency`]).
    pub(crate) fn spring_adjacency(&self) -> Adjacency {
        if self.integrator == Integrator::ImplicitEuler { Adjacency::Built } else { Adjacency::LeftOut }
    }
}
