//! `SoftshellShell`: the thin-shell contraction simulator (SPEC section 1) behind the C ABI,
//! with its def, its anisotropic-region def, its per-step stats and its kind constants.

use super::boundary::{
    Poisonable, SoftshellStatus, arg_kind, arg_ref, arg_slice, handle_call, handle_read, out_arg, value_call,
};
#[cfg(feature = "shell")]
use super::boundary::{copy_out, write_out, write_triples};
use super::mesh::SoftshellMesh;
use crate::error::Error;
#[cfg(feature = "shell")]
use crate::error::Result;

/// `SoftshellShellDef.solver`: consistent XPBD energy constraints (the default): Young's modulus
/// and thickness mean what they say, whatever the iteration count (SPEC 1.3).
pub const SOFTSHELL_SOLVER_XPBD: u32 = 0;
/// `SoftshellShellDef.solver`: the paper's plain PBD energy constraints `C = W`: stiffness is set
/// by the iteration count and Young's modulus has no effect (for reproducing the paper).
pub const SOFTSHELL_SOLVER_PBD: u32 = 1;
/// `SoftshellShellDef.solver`: plain PBD edge-distance constraints instead of membrane energies
/// (the paper's baseline, for comparisons: triangles may shear and change area freely). The
/// membrane energy is still measured for the stats.
pub const SOFTSHELL_SOLVER_PBD_DISTANCE: u32 = 2;

/// `SoftshellShellDef.material`: Saint Venant-Kirchhoff (the default and the paper's).
pub const SOFTSHELL_MATERIAL_STVK: u32 = 0;
/// `SoftshellShellDef.material`: corotated linear elasticity (thin polar decomposition).
pub const SOFTSHELL_MATERIAL_COROTATED: u32 = 1;
/// `SoftshellShellDef.material`: linear elasticity in the fixed rest frame (not rotation
/// invariant: for small motions only).
pub const SOFTSHELL_MATERIAL_LINEAR: u32 = 2;
/// `SoftshellShellDef.material`: compressible neo-Hookean.
pub const SOFTSHELL_MATERIAL_NEO_HOOKEAN: u32 = 3;
/// `SoftshellShellDef.material`: incompressible Mooney-Rivlin membrane with C10 = C01 = mu/4
/// (Poisson's ratio is not used).
pub const SOFTSHELL_MATERIAL_MOONEY_RIVLIN: u32 = 4;

/// `SoftshellShellDef.bending`: no bending constraints (none are stored).
pub const SOFTSHELL_BENDING_NONE: u32 = 0;
/// `SoftshellShellDef.bending`: the paper's isometric bending, whose rest shape is flat (it
/// slowly flattens a curved shell even without pressure).
pub const SOFTSHELL_BENDING_ISOMETRIC: u32 = 1;
/// `SoftshellShellDef.bending`: isometric bending that keeps the rest curvature (the default):
/// without pressure the shell keeps its shape.
pub const SOFTSHELL_BENDING_ISOMETRIC_REST: u32 = 2;

/// `SoftshellAnisotropyDef.energy`: as-rigid-as-possible fibre energy (the default; the paper's).
pub const SOFTSHELL_ANISOTROPY_ARAP: u32 = 0;
/// `SoftshellAnisotropyDef.energy`: St. Venant-Kirchhoff fibre energy `mu/2 (I5 - L^2)^2`.
pub const SOFTSHELL_ANISOTROPY_STVK: u32 = 1;
/// `SoftshellAnisotropyDef.energy`: square-root fibre energy `mu/2 (sqrt(I5) - L)^2`.
pub const SOFTSHELL_ANISOTROPY_SQRT: u32 = 2;

pub(crate) const SHELL_DEF_COOKIE: u32 = 0x5348_4c31;
pub(crate) const ANISOTROPY_DEF_COOKIE: u32 = 0x414e_4931;

/// Settings of a shell, filled by `softshell_shell_def_default()` and then edited field by field.
///
/// The defaults are made for a closed mesh scaled to a unit bounding-box diagonal: the shell is
/// squeezed elastically, buckles and shrinks, its volume falling monotonically until
/// `stop_volume_ratio` (measured: the unit sphere of data/ passes V/V0 = 0.8 near step 70, the
/// finer kitten near step 20); with `pressure` 0 it keeps its rest shape. The material describes
/// a soft, thin, heavy membrane (1 kg/m^2, membrane stiffness E t = 1 N/m). For a mesh s times
/// larger, the same motion in the same time steps needs pressure x s and Young's modulus x s^2
/// (thickness and density unchanged).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SoftshellShellDef {
    /// Time step h, s, in [1e-6, 1]. Default 1/60.
    pub time_step: f32,
    /// Substeps per step (each runs the whole step with h/substeps), 1..=1000. Default 1.
    pub substeps: u32,
    /// Gauss-Seidel iterations per substep, 1..=1000. Default 5 (the paper's).
    pub iterations: u32,
    /// `SOFTSHELL_SOLVER_XPBD` (default), `SOFTSHELL_SOLVER_PBD` (the paper's form) or
    /// `SOFTSHELL_SOLVER_PBD_DISTANCE` (edge-distance baseline).
    pub solver: u32,
    /// Outside air pressure P, Pa, finite, |P| <= 1e12 (negative inflates). Default 0.7.
    pub pressure: f32,
    /// `SOFTSHELL_MATERIAL_STVK` (default), `_COROTATED`, `_LINEAR`, `_NEO_HOOKEAN` or
    /// `_MOONEY_RIVLIN`.
    pub material: u32,
    /// Young's modulus E, Pa, in (0, 1e12]. Default 1000 (with the default thickness: E t = 1 N/m).
    pub youngs_modulus: f32,
    /// Poisson's ratio, in [0, 0.49]. Default 0.3.
    pub poisson_ratio: f32,
    /// Shell thickness t, m, in (0, 1e3]. Default 0.001.
    pub thickness: f32,
    /// Density, kg/m^3, in (0, 1e9]; with the thickness and the rest areas it gives the vertex
    /// masses (a third of each adjacent face). Default 1000.
    pub density: f32,
    /// `SOFTSHELL_BENDING_ISOMETRIC_REST` (default), `_ISOMETRIC` (the paper's) or `_NONE`.
    pub bending: u32,
    /// Bending coefficient kB, dimensionless, in [0, 1e6]. Default 0.01 (the paper's). 0 stores
    /// no bending constraints, as `SOFTSHELL_BENDING_NONE` does. With XPBD,
    /// each edge stencil gets the energy `kB E t (A0+A1)/2 * E_B`: kB = 1 makes bending as stiff
    /// as stretching at the scale of one triangle. With PBD it scales each bending correction,
    /// as in the paper, and is at most 2 (the full projection; beyond it the corrections
    /// overshoot, and beyond 4 they diverge).
    pub bending_coefficient: f32,
    /// Velocity damping per second, in [0, 1e6]: velocities are scaled by max(0, 1 - damping h)
    /// each substep. Default 8: the contraction is a slow, nearly quasi-static
    /// process, and this removes the elastic rebound from the sudden pressure load (the default
    /// sphere's volume then falls monotonically).
    pub damping: f32,
    /// The shell is finished (later steps do nothing) when V/V0 falls below this, in
    /// [0, 0.999999]; 0 = never. Default 0.3.
    pub stop_volume_ratio: f32,
    /// Self-collision (continuous collision detection). Default true. Each substep finds the
    /// vertex-face and edge-edge pairs that come within `collision_thickness` over the substep
    /// (swept-box BVH, non-penetration filters, exact conservative CCD in double precision) and
    /// pushes them apart to the side they came from, so a shell that starts free of
    /// self-intersections stays so. When false, no collision data is built (see
    /// `softshell_shell_memory_bytes`) and the collision stats stay 0.
    /// Its cost follows the motion per substep: a pair is tested when the boxes its primitives
    /// sweep meet, so a substep that moves vertices across much of the mesh (a pressure hundreds
    /// of times what the material holds, a surface collapsing flat in one step) tests nearly
    /// every pair: the 482-vertex sphere at 6,000 Pa 1.5 million pairs (seconds), the
    /// 10,000-vertex kitten at 480 Pa 25 million (about two minutes for one step). Such a step is
    /// not refused; more substeps keep each substep's search local (`collision_candidates`
    /// reports the pairs).
    pub collisions: bool,
    /// Collision thickness delta relative to the bounding-box diagonal, in [0, 1]. Default 1e-4.
    /// With collisions on, it must also stay below the rest distance of every two primitives
    /// that share no vertex (about the edge length over the diagonal on a smooth mesh), or
    /// `softshell_shell_new` refuses it with `SOFTSHELL_STATUS_INVALID_ARGUMENT`.
    pub collision_thickness: f32,
    /// Worker threads: 0 = one per core, 1 = serial on the caller's thread (default), at most
    /// 256. Results are bit-identical whatever the count.
    pub threads: u32,
    /// Set by `softshell_shell_def_default`; do not touch.
    pub internal_cookie: u32,
}

/// Settings of one anisotropic region (SPEC 1.5), filled by `softshell_anisotropy_def_default()`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SoftshellAnisotropyDef {
    /// `SOFTSHELL_ANISOTROPY_ARAP` (default), `_STVK` or `_SQRT`.
    pub energy: u32,
    /// Fibre stiffness mu, Pa, in (0, 1e12]. Default 1000 (the default Young's modulus).
    pub stiffness: f32,
    /// Inward push k_A (paper section 3.3), dimensionless, in [0, 1e6]: each vertex gradient of
    /// the fibre constraint gets `+ k_A sqrt(A0) n` (n the face's outward unit normal, A0 its rest
    /// area, so the push does not depend on the mesh scale), which turns corrections into an
    /// inward motion of the region. The push acts as long as the fibre is
    /// strained, so large values make the region cave through the opposite side (without the
    /// collision stage). Default 0.003.
    pub inward_push: f32,
    /// Target stretch L along the fibre, in (0, 1]: 1 = the paper's energies, below 1 = active
    /// contraction (the fibre wants to shorten to L). Default 1.
    pub target_stretch: f32,
    /// Fibre direction in world space, finite. 0,0,0 (default) = chosen per face: the direction
    /// from the face's centre towards the region's centre, projected into the face, so fibres
    /// converge on the middle of the region.
    pub direction: [f32; 3],
    /// Set by `softshell_anisotropy_def_default`; do not touch.
    pub internal_cookie: u32,
}

/// What one `softshell_shell_step` did. Fields may be appended in later versions.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SoftshellShellStats {
    /// Steps taken so far (after this one).
    pub step: u64,
    /// Simulated time, s.
    pub time: f64,
    /// Enclosed volume V, m^3.
    pub volume: f64,
    /// V / V0 (V0 the rest volume).
    pub volume_ratio: f64,
    /// True once the volume ratio fell below `stop_volume_ratio`.
    pub finished: bool,
    /// Largest relative constraint violation after the last iteration, dimensionless: with
    /// XPBD |C + alpha lambda| and with PBD |C|, where C = sqrt(2 W^) is made relative to the
    /// element (divided by sqrt(A0) for membrane and fibre constraints, so it reads like a strain).
    /// C is that of the constraints the iterations solve: with `SOFTSHELL_BENDING_ISOMETRIC_REST`
    /// the bending target is the rest curvature as the substep's start orients it.
    pub residual: f64,
    /// Membrane energy, J.
    pub elastic_energy: f64,
    /// Bending energy, J (with the XPBD stiffness `kB E t (A0+A1)/2`, for both solvers).
    pub bending_energy: f64,
    /// Anisotropic fibre energy, J (`mu t A0 psi` summed over region faces).
    pub anisotropic_energy: f64,
    /// Vertex-face and edge-edge pairs sharing no vertex whose swept boxes overlap (the BVH's
    /// candidates), summed over the substeps; 0 with collisions off.
    pub collision_candidates: u64,
    /// Exact continuous collision tests run: the candidates left after the swept-box and
    /// non-penetration filters, summed over the substeps; 0 with collisions off.
    pub ccd_tests: u64,
    /// Contact constraints projected in the step (pairs found within the collision thickness),
    /// summed over the substeps; 0 with collisions off.
    pub contacts: u64,
    /// Wall time of the step, s.
    pub step_seconds: f64,
    /// True when the volume ratio has changed by less than 1e-5 per step for the last 60 steps
    /// without reaching `stop_volume_ratio`: the contraction has stalled (SPEC 1.7).
    pub stalled: bool,
}

/// A thin shell squeezed by outside air pressure (SPEC section 1). Made by `softshell_shell_new`
/// from a closed mesh, destroyed by `softshell_shell_free`. Functions: `softshell_shell_step`,
/// `softshell_shell_add_anisotropic_region`, `softshell_shell_vertex_count`,
/// `softshell_shell_copy_positions`, `softshell_shell_copy_face_energy`,
/// `softshell_shell_copy_vertex_curvature`, `softshell_shell_memory_bytes`.
///
/// Thread rules: a shell may move between threads but must not be used from two threads at
/// once; different shells may be stepped concurrently. Each shell owns its worker threads.
pub struct SoftshellShell {
    #[cfg(feature = "shell")]
    pub(crate) inner: crate::shell::Shell,
    poisoned: bool,
}

impl Poisonable for SoftshellShell {
    fn is_poisoned(&self) -> bool {
        self.poisoned
    }
    fn poison(&mut self) {
        self.poisoned = true;
    }
}

/// The default shell settings (see each field of `SoftshellShellDef`).
#[unsafe(no_mangle)]
pub extern "C" fn softshell_shell_def_default() -> SoftshellShellDef {
    SoftshellShellDef {
        time_step: 1.0 / 60.0,
        substeps: 1,
        iterations: 5,
        solver: SOFTSHELL_SOLVER_XPBD,
        pressure: 0.7,
        material: SOFTSHELL_MATERIAL_STVK,
        youngs_modulus: 1000.0,
        poisson_ratio: 0.3,
        thickness: 0.001,
        density: 1000.0,
        bending: SOFTSHELL_BENDING_ISOMETRIC_REST,
        bending_coefficient: 0.01,
        damping: 8.0,
        stop_volume_ratio: 0.3,
        collisions: true,
        collision_thickness: 1e-4,
        threads: 1,
        internal_cookie: SHELL_DEF_COOKIE,
    }
}

/// The default anisotropic-region settings (see each field of `SoftshellAnisotropyDef`).
#[unsafe(no_mangle)]
pub extern "C" fn softshell_anisotropy_def_default() -> SoftshellAnisotropyDef {
    SoftshellAnisotropyDef {
        energy: SOFTSHELL_ANISOTROPY_ARAP,
        stiffness: 1000.0,
        inward_push: 0.003,
        target_stretch: 1.0,
        direction: [0.0; 3],
        internal_cookie: ANISOTROPY_DEF_COOKIE,
    }
}

#[cfg(feature = "shell")]
mod convert {
    use super::*;
    use crate::ffi::boundary::{check_cookie, check_range};

    fn check_count(name: &str, value: u32, min: u32, max: u32) -> Result<()> {
        if value < min || value > max {
            return Err(Error::invalid_argument(format!("`{name}` = {value} must be in [{min}, {max}]")));
        }
        Ok(())
    }

    fn check_positive(name: &str, value: f32, max: f32) -> Result<()> {
        if !value.is_finite() || value <= 0.0 || value > max {
            return Err(Error::invalid_argument(format!("`{name}` = {value} must be finite and in (0, {max}]")));
        }
        Ok(())
    }
    use crate::material::{AnisotropicEnergy, Material};
    use crate::shell::{AnisotropySettings, BendingKind, ShellSettings, SolverKind};

    impl TryFrom<u32> for SolverKind {
        type Error = ();
        fn try_from(v: u32) -> std::result::Result<Self, ()> {
            match v {
                SOFTSHELL_SOLVER_XPBD => Ok(SolverKind::Xpbd),
                SOFTSHELL_SOLVER_PBD => Ok(SolverKind::Pbd),
                SOFTSHELL_SOLVER_PBD_DISTANCE => Ok(SolverKind::PbdDistance),
                _ => Err(()),
            }
        }
    }

    impl TryFrom<u32> for Material {
        type Error = ();
        fn try_from(v: u32) -> std::result::Result<Self, ()> {
            match v {
                SOFTSHELL_MATERIAL_STVK => Ok(Material::StVK),
                SOFTSHELL_MATERIAL_COROTATED => Ok(Material::Corotated),
                SOFTSHELL_MATERIAL_LINEAR => Ok(Material::Linear),
                SOFTSHELL_MATERIAL_NEO_HOOKEAN => Ok(Material::NeoHookean),
                SOFTSHELL_MATERIAL_MOONEY_RIVLIN => Ok(Material::MooneyRivlin),
                _ => Err(()),
            }
        }
    }

    impl TryFrom<u32> for BendingKind {
        type Error = ();
        fn try_from(v: u32) -> std::result::Result<Self, ()> {
            match v {
                SOFTSHELL_BENDING_NONE => Ok(BendingKind::None),
                SOFTSHELL_BENDING_ISOMETRIC => Ok(BendingKind::Isometric),
                SOFTSHELL_BENDING_ISOMETRIC_REST => Ok(BendingKind::IsometricRest),
                _ => Err(()),
            }
        }
    }

    impl TryFrom<u32> for AnisotropicEnergy {
        type Error = ();
        fn try_from(v: u32) -> std::result::Result<Self, ()> {
            match v {
                SOFTSHELL_ANISOTROPY_ARAP => Ok(AnisotropicEnergy::Arap),
                SOFTSHELL_ANISOTROPY_STVK => Ok(AnisotropicEnergy::StVK),
                SOFTSHELL_ANISOTROPY_SQRT => Ok(AnisotropicEnergy::Sqrt),
                _ => Err(()),
            }
        }
    }

    /// The largest bending coefficient the PBD solvers take (see `shell_settings`).
    const PBD_MAX_BENDING: f32 = 2.0;

    /// Validates every field of a shell def (cookie first) into settings.
    pub(super) fn shell_settings(def: &SoftshellShellDef) -> Result<ShellSettings> {
        check_cookie(def.internal_cookie, SHELL_DEF_COOKIE, "SoftshellShellDef", "softshell_shell_def_default")?;
        // (Not shorter: the f32 solver divides by h and h², which underflow far below it; a
        // review saw a step of 1e-40 s leave NaN velocities behind an OK.)
        check_range("time_step", def.time_step, crate::shell::MIN_TIME_STEP, 1.0)?;
        check_count("substeps", def.substeps, 1, crate::shell::MAX_SUBSTEPS)?;
        check_count("iterations", def.iterations, 1, 1000)?;
        let solver = arg_kind(
            def.solver,
            "solver",
            "SOFTSHELL_SOLVER_XPBD (0), SOFTSHELL_SOLVER_PBD (1), SOFTSHELL_SOLVER_PBD_DISTANCE (2)",
        )?;
        check_range("pressure", def.pressure, -1e12, 1e12)?;
        let material = arg_kind(
            def.material,
            "material",
            "SOFTSHELL_MATERIAL_STVK (0), _COROTATED (1), _LINEAR (2), _NEO_HOOKEAN (3), _MOONEY_RIVLIN (4)",
        )?;
        check_positive("youngs_modulus", def.youngs_modulus, 1e12)?;
        check_range("poisson_ratio", def.poisson_ratio, 0.0, 0.49)?;
        check_positive("thickness", def.thickness, 1e3)?;
        check_positive("density", def.density, 1e9)?;
        let bending = arg_kind(
            def.bending,
            "bending",
            "SOFTSHELL_BENDING_NONE (0), SOFTSHELL_BENDING_ISOMETRIC (1), SOFTSHELL_BENDING_ISOMETRIC_REST (2)",
        )?;
        check_range("bending_coefficient", def.bending_coefficient, 0.0, 1e6)?;
        // With PBD, kB scales each bending correction: 2 is the full projection, beyond 4 each
        // correction overshoots by more than it corrects and the first step diverges whatever
        // h is (a review saw kB = 10 fail with advice that could not help).
        if solver != SolverKind::Xpbd && def.bending_coefficient > PBD_MAX_BENDING {
            return Err(Error::invalid_argument(format!(
                "`bending_coefficient` = {} must be at most {PBD_MAX_BENDING} with the PBD solvers (it scales each \
                 bending correction, and {PBD_MAX_BENDING} is the full projection); stiffer bending needs \
                 SOFTSHELL_SOLVER_XPBD",
                def.bending_coefficient
            )));
        }
        check_range("damping", def.damping, 0.0, 1e6)?;
        check_range("stop_volume_ratio", def.stop_volume_ratio, 0.0, 0.999_999)?;
        check_range("collision_thickness", def.collision_thickness, 0.0, 1.0)?;
        check_count("threads", def.threads, 0, 256)?;
        Ok(ShellSettings {
            time_step: def.time_step,
            substeps: def.substeps,
            iterations: def.iterations,
            solver,
            pressure: def.pressure,
            material,
            youngs_modulus: def.youngs_modulus,
            poisson_ratio: def.poisson_ratio,
            thickness: def.thickness,
            density: def.density,
            bending,
            bending_coefficient: def.bending_coefficient,
            damping: def.damping,
            stop_volume_ratio: def.stop_volume_ratio,
            collisions: def.collisions,
            collision_thickness: def.collision_thickness,
            threads: def.threads,
        })
    }

    /// Validates every field of an anisotropy def (cookie first) into settings.
    pub(super) fn anisotropy_settings(def: &SoftshellAnisotropyDef) -> Result<AnisotropySettings> {
        check_cookie(
            def.internal_cookie,
            ANISOTROPY_DEF_COOKIE,
            "SoftshellAnisotropyDef",
            "softshell_anisotropy_def_default",
        )?;
        let energy = arg_kind(
            def.energy,
            "energy",
            "SOFTSHELL_ANISOTROPY_ARAP (0), SOFTSHELL_ANISOTROPY_STVK (1), SOFTSHELL_ANISOTROPY_SQRT (2)",
        )?;
        check_positive("stiffness", def.stiffness, 1e12)?;
        check_range("inward_push", def.inward_push, 0.0, 1e6)?;
        check_positive("target_stretch", def.target_stretch, 1.0)?;
        for (axis, &d) in def.direction.iter().enumerate() {
            if !d.is_finite() {
                return Err(Error::invalid_argument(format!("`direction`[{axis}] = {d} is not finite")));
            }
        }
        Ok(AnisotropySettings {
            energy,
            stiffness: def.stiffness,
            inward_push: def.inward_push,
            target_stretch: def.target_stretch,
            direction: glam::Vec3::from_array(def.direction),
        })
    }

    pub(super) fn stats(s: &crate::shell::ShellStats) -> SoftshellShellStats {
        SoftshellShellStats {
            step: s.step,
            time: s.time,
            volume: s.volume,
            volume_ratio: s.volume_ratio,
            finished: s.finished,
            residual: s.residual,
            elastic_energy: s.elastic_energy,
            bending_energy: s.bending_energy,
            anisotropic_energy: s.anisotropic_energy,
            collision_candidates: s.collision_candidates,
            ccd_tests: s.ccd_tests,
            contacts: s.contacts,
            step_seconds: s.step_seconds,
            stalled: s.stalled,
        }
    }
}

#[cfg(not(feature = "shell"))]
fn unsupported() -> Error {
    Error::unsupported("the shell simulator", "shell")
}

/// Creates a shell from `mesh` (copied: the mesh may be freed afterwards) with the settings of
/// `def` (made by `softshell_shell_def_default` and edited).
///
/// Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` for a NULL argument, `SOFTSHELL_STATUS_INVALID_ARGUMENT`
/// for a def not made by `softshell_shell_def_default`, an unknown kind or a field out of range
/// (the message names the field, its value and the valid range), a `collision_thickness` above
/// the rest distance of two primitives sharing no vertex, or a density, thickness and mesh that
/// give a vertex a mass below about 3e-39 kg (the f32 solver cannot invert it),
/// `SOFTSHELL_STATUS_INVALID_MESH`
/// for a mesh that is not closed, manifold, consistently oriented with outward normals (every
/// connected piece on its own) and free of degenerate triangles (the message names the first
/// offending edge or triangle), or larger than 1e6 m across (bounding-box diagonal),
/// `SOFTSHELL_STATUS_UNSUPPORTED` without the `shell` feature. On success `*out_shell` receives a
/// new handle to free with `softshell_shell_free`; on failure it is left unchanged.
///
/// # Safety
/// `mesh` must be NULL or a live mesh, `def` NULL or a readable def, `out_shell` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_shell_new(
    mesh: *const SoftshellMesh,
    def: *const SoftshellShellDef,
    out_shell: *mut *mut SoftshellShell,
) -> SoftshellStatus {
    super::boundary::status_call("softshell_shell_new", || {
        // SAFETY: the caller promises a live mesh or NULL.
        let mesh = unsafe { arg_ref(mesh, "mesh")? };
        // SAFETY: the caller promises a readable def or NULL.
        let def = unsafe { arg_ref(def, "def")? };
        let out_shell = out_arg(out_shell, "out_shell")?;
        #[cfg(feature = "shell")]
        {
            let settings = convert::shell_settings(def)?;
            let inner = crate::shell::Shell::new(&mesh.mesh, &mesh.topology, settings)?;
            let handle = Box::into_raw(Box::new(SoftshellShell { inner, poisoned: false }));
            // SAFETY: checked by out_arg before any work.
            unsafe { write_out(out_shell, handle) };
            Ok(())
        }
        #[cfg(not(feature = "shell"))]
        {
            let _ = (mesh, def, out_shell);
            Err(unsupported())
        }
    })
}

/// Destroys a shell. `softshell_shell_free(NULL)` does nothing; freeing twice is undefined
/// behaviour.
///
/// # Safety
/// `shell` must be NULL or a live shell that is not used again.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_shell_free(shell: *mut SoftshellShell) {
    value_call("softshell_shell_free", (), || {
        if !shell.is_null() {
            // SAFETY: the caller hands back a pointer made by Box::into_raw and never uses it again.
            drop(unsafe { Box::from_raw(shell) });
        }
    })
}

/// Makes the triangles `faces[0..face_count]` (indices into the mesh's triangles, distinct) an
/// anisotropic region with the settings of `def` (SPEC 1.5). Regions may be added at any time;
/// a face may belong to several regions. Storage for anisotropy exists only once a region is
/// added (see `softshell_shell_memory_bytes`).
///
/// Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` for a NULL shell or def or NULL faces with a count,
/// `SOFTSHELL_STATUS_INVALID_ARGUMENT` for an empty region, a face out of range or repeated, a
/// def not made by `softshell_anisotropy_def_default` or a field out of range. Nothing changes
/// on failure.
///
/// # Safety
/// `shell` must be NULL or a live shell; `faces` NULL or `face_count` readable uint32_t; `def`
/// NULL or a readable def.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_shell_add_anisotropic_region(
    shell: *mut SoftshellShell,
    faces: *const u32,
    face_count: usize,
    def: *const SoftshellAnisotropyDef,
) -> SoftshellStatus {
    handle_call("softshell_shell_add_anisotropic_region", shell, "shell", |shell| {
        // SAFETY: the caller promises face_count readable indices or NULL.
        let faces = unsafe { arg_slice(faces, face_count, "faces")? };
        // SAFETY: the caller promises a readable def or NULL.
        let def = unsafe { arg_ref(def, "def")? };
        #[cfg(feature = "shell")]
        {
            let settings = convert::anisotropy_settings(def)?;
            shell.inner.add_anisotropic_region(faces, settings)
        }
        #[cfg(not(feature = "shell"))]
        {
            let _ = (shell, faces, def);
            Err(unsupported())
        }
    })
}

/// Advances the shell by one time step (SPEC 1.1): pressure, prediction, `iterations`
/// Gauss-Seidel sweeps over the membrane, bending and anisotropic constraints, (collisions),
/// velocity update, volume ratio, all `substeps` times.
///
/// `out_stats` may be NULL. When it is not, the energies and the residual are evaluated after
/// the last iteration (one extra pass over the constraints) and the stats are written there.
/// Once the shell is finished (volume ratio below `stop_volume_ratio`) a step does nothing and
/// returns the last stats with `finished` true and `step_seconds` 0.
///
/// Returns `SOFTSHELL_STATUS_UNSTABLE` when the step diverged (a position became NaN or moved
/// more than two bounding-box diagonals in a substep; the volume became non-finite; the shell
/// turned inside out, or more than a quarter of its triangle normals turned around in one step):
/// the shell is rolled back to its state before the step and the message says what blew up and
/// which settings would be stable (settings a def accepts). `out_stats` is then not written.
///
/// # Safety
/// `shell` must be NULL or a live shell; `out_stats` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_shell_step(
    shell: *mut SoftshellShell,
    out_stats: *mut SoftshellShellStats,
) -> SoftshellStatus {
    handle_call("softshell_shell_step", shell, "shell", |shell| {
        let want = !out_stats.is_null();
        if want {
            out_arg(out_stats, "out_stats")?;
        }
        #[cfg(feature = "shell")]
        {
            let stats = shell.inner.step(want)?;
            if want {
                // SAFETY: checked by out_arg above.
                unsafe { write_out(out_stats, convert::stats(&stats)) };
            }
            Ok(())
        }
        #[cfg(not(feature = "shell"))]
        {
            let _ = (shell, want);
            Err(unsupported())
        }
    })
}

/// Number of vertices of the shell (the mesh's); 0 for NULL.
///
/// # Safety
/// `shell` must be NULL or a live shell.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_shell_vertex_count(shell: *const SoftshellShell) -> usize {
    value_call("softshell_shell_vertex_count", 0, || {
        // SAFETY: the caller promises a live shell or NULL.
        match unsafe { arg_ref(shell, "shell") } {
            #[cfg(feature = "shell")]
            Ok(s) => s.inner.vertex_count(),
            #[cfg(not(feature = "shell"))]
            Ok(_) => 0,
            Err(_) => 0,
        }
    })
}

/// Copies the current positions (x,y,z per vertex, `3 * vertex_count` floats) into `out`.
/// If `out` is NULL or `capacity` (in floats) is too small, returns
/// `SOFTSHELL_STATUS_BUFFER_TOO_SMALL`, writes the number of floats needed to `*out_len` and
/// nothing else. On success `*out_len` is the number of floats written. Returns
/// `SOFTSHELL_STATUS_NULL_ARGUMENT`, writing nothing, when the shell or `out_len` is NULL.
///
/// # Safety
/// `shell` must be NULL or a live shell; `out` NULL or `capacity` writable floats; `out_len`
/// NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_shell_copy_positions(
    shell: *const SoftshellShell,
    out: *mut f32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    handle_read("softshell_shell_copy_positions", shell, "shell", |shell| {
        #[cfg(feature = "shell")]
        {
            let positions = shell.inner.positions();
            // SAFETY: the caller promises the buffer.
            unsafe {
                copy_out(positions.len() * 3, out, capacity, out_len, |dst| {
                    write_triples(dst, positions.iter().map(|p| p.to_array()))
                })
            }
        }
        #[cfg(not(feature = "shell"))]
        {
            let _ = (shell, out, capacity, out_len);
            Err(unsupported())
        }
    })
}

/// Copies the membrane (elastic) energy of each triangle, J, in mesh triangle order (one float
/// per triangle), with the buffer rules of `softshell_shell_copy_positions`. Computed from the
/// current positions when called.
///
/// # Safety
/// As `softshell_shell_copy_positions`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_shell_copy_face_energy(
    shell: *const SoftshellShell,
    out: *mut f32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    handle_read("softshell_shell_copy_face_energy", shell, "shell", |shell| {
        #[cfg(feature = "shell")]
        {
            let n = shell.inner.triangle_count();
            // SAFETY: the caller promises the buffer.
            unsafe { copy_out(n, out, capacity, out_len, |dst| dst.copy_from_slice(&shell.inner.face_energy())) }
        }
        #[cfg(not(feature = "shell"))]
        {
            let _ = (shell, out, capacity, out_len);
            Err(unsupported())
        }
    })
}

/// Copies one curvature value per vertex of the current shape: `kind` is
/// `SOFTSHELL_CURVATURE_MEAN` (1/m) or `SOFTSHELL_CURVATURE_GAUSSIAN` (1/m^2), as in
/// `softshell_mesh_copy_vertex_curvature`; any other kind is `SOFTSHELL_STATUS_INVALID_ARGUMENT`.
/// Buffer rules as `softshell_shell_copy_positions` (one float per vertex).
///
/// # Safety
/// As `softshell_shell_copy_positions`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_shell_copy_vertex_curvature(
    shell: *const SoftshellShell,
    kind: u32,
    out: *mut f32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    handle_read("softshell_shell_copy_vertex_curvature", shell, "shell", |shell| {
        let kind: crate::mesh::CurvatureKind =
            arg_kind(kind, "kind", "SOFTSHELL_CURVATURE_MEAN (0), SOFTSHELL_CURVATURE_GAUSSIAN (1)")?;
        #[cfg(feature = "shell")]
        {
            let n = shell.inner.vertex_count();
            // SAFETY: the caller promises the buffer.
            unsafe {
                copy_out(n, out, capacity, out_len, |dst| {
                    for (d, v) in dst.iter_mut().zip(shell.inner.vertex_curvature(kind)) {
                        *d = crate::mesh::curvature_f32(v);
                    }
                })
            }
        }
        #[cfg(not(feature = "shell"))]
        {
            let _ = (shell, kind, out, capacity, out_len);
            Err(unsupported())
        }
    })
}

/// Bytes held by the shell: its handle, rest data, state and scratch (the worker threads and the
/// thread pool's own bookkeeping, inside rayon, excluded).
/// Only what the scene uses is allocated: no bending data with `SOFTSHELL_BENDING_NONE`, no
/// anisotropy data before a region is added, no multipliers with the PBD solver, no pool with
/// `threads = 1`. A step allocates nothing without collisions; with them it only grows the
/// contact buffers (cached pairs, contacts, CCD search queues) to the largest contact set so
/// far, so this figure can rise while the shell contracts. (On more than one thread the thread
/// pool's job queue takes a block about once every 63 steps.) 0 for NULL.
///
/// # Safety
/// `shell` must be NULL or a live shell.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_shell_memory_bytes(shell: *const SoftshellShell) -> usize {
    value_call("softshell_shell_memory_bytes", 0, || {
        // SAFETY: the caller promises a live shell or NULL.
        match unsafe { arg_ref(shell, "shell") } {
            #[cfg(feature = "shell")]
            Ok(s) => s.inner.memory_bytes(),
            #[cfg(not(feature = "shell"))]
            Ok(_) => std::mem::size_of::<SoftshellShell>(),
            Err(_) => 0,
        }
    })
}
