//! `SoftshellBody`: the mass-spring soft body with gas and fracture (SPEC section 2) behind the
//! C ABI. This file checks arguments and converts types; the physics lives in `crate::body`.

#[cfg(feature = "body")]
use glam::Vec3;

use super::boundary::{
    Poisonable, SoftshellStatus, arg_kind, arg_ref, arg_slice, arg_vec3, check_cookie, check_range, handle_call,
    handle_read, out_arg, status_call, value_call,
};
#[cfg(feature = "body")]
use super::boundary::{copy_out, write_out, write_triples};
use super::mesh::SoftshellMesh;
#[cfg(feature = "body")]
use crate::body::{Body, BodySettings, BodyStats, Integrator, Obstacle};
use crate::error::{Error, Result};

/// Explicit Euler, `x += h v; v += h a` with the old velocity: the paper's integrator. Needs
/// spring damping: its springs' modes are stable only while `h < K_d/K_s` (and, where damping
/// dominates, `h < 4/(gamma + sqrt(gamma^2 - 4 omega^2))`, with `omega^2` and `gamma` the springs'
/// stiffness and damping over the lightest vertex's mass); a step that diverges returns
/// `SOFTSHELL_STATUS_UNSTABLE` with that estimate.
pub const SOFTSHELL_INTEGRATOR_EXPLICIT_EULER: u32 = 0;
/// Symplectic (semi-implicit) Euler, `v += h a; x += h v`: stable while
/// `h^2 omega^2 + 2 h gamma < 4` (`h < 2/omega` without damping; `omega`, `gamma` as above).
pub const SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER: u32 = 1;
/// Linearised backward Euler solved by conjugate gradients: stable at any time step for springs
/// and gas as stiff as allowed, with numerical damping. The default. Its one linearised solve
/// per substep makes energy where a step moves vertices far beyond the linearisation (a light
/// piece whose springs turn or fold within the step, a shred falling onto the ground), so it
/// controls its step: a step that makes energy without a source (beyond the external work) while
/// the energy the recent steps made (each step's growth plus 0.9 times the record before it)
/// exceeds the kinetic and spring energy it started with is taken again from its start in twice
/// the substeps, up to 16 times `substeps` (fewer where h would fall below 1e-6 s or the
/// substeps exceed 1000); the following steps keep that subdivision and halve it after 8 steps
/// that needed no more. Such steps cost as much more (`solver_iterations` counts every attempt;
/// a plain impact, which makes up to half that energy in one step, is not subdivided). A step is
/// `SOFTSHELL_STATUS_UNSTABLE` (rolled back; raise `substeps`) when even the finest fails: a
/// NaN, kinetic energy far beyond what the step had available, or the energy made without a
/// source (`energy_drift`) over 20 times what the body was given and more than doubled, two
/// steps in a row. What it was given: its kinetic and spring energy when made, what gravity and
/// the gas have released, and the energy impulses and the wind gave (their positive work; the
/// energy drag takes away does not count).
pub const SOFTSHELL_INTEGRATOR_IMPLICIT_EULER: u32 = 2;
/// XPBD: springs as distance constraints with compliance 1/K_s, gas as a volume constraint;
/// `iterations` Gauss-Seidel sweeps per substep. Its springs are as stiff as K_s only as far as
/// those sweeps converge, so with few of them a body whose gas or weight is large for its mass
/// comes out far softer, though finite. The issue-5 balloon (benches/body_balloon.rs) dropped on
/// the ground swings about V/V0 1.69 (1.50-1.78 over its last 100 of 600 steps) with 5 substeps
/// of 2 sweeps and about 1.05 (1.03-1.07) with 10 of 10, where implicit Euler settles at 1.0235.
/// A 10 g ball of K_s 1e7 with gas 10 J resting on the ground kept springs stretched by 143%
/// with the default 1 substep of 10 sweeps (a probe through this API); falling freely with 20
/// substeps at 1/60 s (80 at 1/15 s) under 5% (tests/ffi_body_stiff.rs). Raise `substeps`
/// (more effective than `iterations`), or use implicit Euler. Each constraint keeps the push it
/// applied in a substep and turns it onto its current direction, before each update and once
/// more at the end, so that the forces are central and a floating body neither spins up nor
/// gains energy by itself (textbook XPBD leaves each update along the direction of its moment:
/// a gas ball of 10 J spun up from 0.013 to 0.14 J of kinetic energy in 1,500 steps, with or
/// without spring damping). That costs 12 bytes a spring (and a vertex, with gas) and 2.3-2.9
/// times the step time of textbook XPBD on the issue-5 balloon, measured when both measured the
/// gas face by face on one thread (with the gas's gradient gathered on the body's threads, see
/// `gas_amount`, XPBD's steps there got 1.2-1.6 times faster: 5 substeps of 2 sweeps about 20
/// ms on 2 threads).
pub const SOFTSHELL_INTEGRATOR_XPBD: u32 = 3;

const INTEGRATORS: &str = "SOFTSHELL_INTEGRATOR_EXPLICIT_EULER (0), SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER (1), \
                           SOFTSHELL_INTEGRATOR_IMPLICIT_EULER (2), SOFTSHELL_INTEGRATOR_XPBD (3)";

/// The private cookie of `SoftshellBodyDef`.
pub(crate) const BODY_DEF_COOKIE: u32 = 0x5B0D_7DEF;

/// Settings of a soft body. Fill with `softshell_body_def_default()`, then edit fields.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SoftshellBodyDef {
    /// Step length h, s, in [1e-6, 1]. Default 1/60.
    pub time_step: f32,
    /// Substeps per step (each h / substeps), in [1, 1000]. Default 1.
    pub substeps: u32,
    /// `SOFTSHELL_INTEGRATOR_EXPLICIT_EULER` (the paper's) | `_SYMPLECTIC_EULER` |
    /// `_IMPLICIT_EULER` (default) | `_XPBD`.
    pub integrator: u32,
    /// Total mass, kg, in [1e-12, 1e12]; spread over the vertices in proportion to their share of
    /// the area. Default 1.
    pub total_mass: f32,
    /// Spring stiffness K_s, N/m, in [0, 1e12]: one spring per mesh edge. Default 1000. The
    /// surface has no bending stiffness and no contact with itself, so a hard impact can crease
    /// it for good: the 100 kg, 10,242-vertex balloon of benches/body_balloon.rs, dropped at
    /// 5.4 m/s, lands whole with one implicit step per 1/60 s (whose damping smooths the impact)
    /// but creases most drops with 4 substeps.
    pub spring_stiffness: f32,
    /// Spring damping K_d along each spring, N s/m, in [0, 1e9]. Default 1.
    pub spring_damping: f32,
    /// Amount of gas nRT, J (pressure = nRT / volume), in [0, 1e12]. 0 (default) = no gas; then
    /// open meshes (cloth) are allowed. With gas the mesh must be closed, manifold and outward
    /// (every connected piece), and the body keeps each vertex's face corners to gather the
    /// gas's volume gradient there on its threads, whatever the integrator: about 57 bytes a
    /// face (96 with a break limit, which reserves room to crack).
    pub gas_amount: f32,
    /// Gravity, m/s^2, each component in [-1e6, 1e6]. Default 0, -9.81, 0.
    pub gravity: [f32; 3],
    /// Wind velocity, m/s, each component in [-1e6, 1e6]. Default 0, 0, 0.
    pub wind: [f32; 3],
    /// Wind drag coefficient, kg/(m^2 s): each face feels `drag ((wind - v)·n) n area`, in
    /// [0, 1e6]. Default 0 (no wind force). Over a (sub)step of length h a vertex of mass m
    /// takes its share times m / (m + h c), c the drag of its faces (`drag area / 3` each): the
    /// implicit response, which never carries it past the wind's speed however light it is.
    pub drag: f32,
    /// Spring strain `(length - rest)/rest` above which a spring breaks and the surface cracks,
    /// in [0, 1e6]. 0 (default) = never. Only a spring between two faces breaks: once a crack
    /// opens, each of its two sides is an edge of one face and keeps a spring of the same
    /// stiffness (as a cloth's border does), which never breaks, so every face keeps its three
    /// sides. Their rest length is set where the crack opens so that the two sides hold the
    /// energy the broken spring held (each stretched by 1/√2 of its extension; together they
    /// pull √2 times as hard): a spring that breaks and opens in one change makes and takes no
    /// energy (one that broke earlier without opening gave its energy up then, and its sides
    /// take that much back when they open). Their strain (`max_strain`) is measured against
    /// that rest length. A crack runs
    /// from a cut that opens the surface, a slit of two edges through a vertex; a cut that frees
    /// one face's corner loads no other spring (the sides hold the corner), so none runs from it.
    pub break_strain: f32,
    /// Net force on a vertex, N, above which it is cut out as a core block, in [0, 1e12]: each
    /// vertex at most once, and the vertices of a released block (and the centre of the patch it
    /// leaves) never. 0 (default) = never.
    pub break_force: f32,
    /// Gas leak through holes, m/(Pa s): `d(nRT)/dt = -leak_rate * hole_area * pressure`, in
    /// [0, 1e6]. Default 0.
    pub leak_rate: f32,
    /// A ground plane y = ground_height (normal +y); free vertices below it when the body is made
    /// start on it (`softshell_body_new` refuses a mesh entirely below it). Default false.
    pub ground: bool,
    /// Height of the ground plane, m, in [-1e9, 1e9]. Default 0.
    pub ground_height: f32,
    /// Restitution of contacts with the ground and obstacles, in [0, 1]. Default 0. It acts on
    /// each vertex at its contact (its normal speed out is at least this times its speed in): a
    /// body that lands flat leaves at that fraction of its speed, but a soft ball's bottom
    /// vertices land one after the other, and one thrown back into the falling rest meets the
    /// ground again, losing speed each time, so a soft ball may rise less with a high restitution
    /// than with 0 (its bounce comes from its own springs and gas; measured with XPBD and
    /// symplectic Euler, while implicit Euler's rose a little higher).
    pub restitution: f32,
    /// Coulomb friction coefficient of contacts, in [0, 1000]. Default 0.5.
    pub friction: f32,
    /// Worker threads: 0 = one per core, 1 = serial (default), at most 256. Results do not depend
    /// on it.
    pub threads: u32,
    /// XPBD Gauss-Seidel sweeps per substep; the implicit integrator allows 10 times as many
    /// conjugate-gradient iterations (at least 40). In [1, 1000]. Default 10.
    pub iterations: u32,
    /// Set by `softshell_body_def_default`; do not touch.
    pub internal_cookie: u32,
}

/// What a step did. Filled by `softshell_body_step`. Fields may be appended in later versions.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SoftshellBodyStats {
    /// Steps taken so far.
    pub step: u64,
    /// Simulated time, s.
    pub time: f64,
    /// Enclosed volume, m^3: the sum over the pieces that hold gas (holes capped), or the signed
    /// volume of the mesh without gas.
    pub volume: f64,
    /// Mean gas pressure (total nRT / total volume), Pa; 0 without gas. A piece whose volume is
    /// clamped (`volume_clamped`) counts with its clamped volume: the pressure the gas pushes
    /// with, which stops growing there (so then `pressure * volume` is less than the total nRT).
    pub pressure: f64,
    /// Kinetic energy, J.
    pub kinetic_energy: f64,
    /// Energy error: (kinetic + spring + gas + gravitational energy) minus its initial value, the
    /// work of wind and impulses (and the kinetic energy a pin took away), and the gas energy
    /// that leaks took away, J. Damping and
    /// contacts make it negative; a growing positive value means the integrator is adding
    /// energy. A topology change (a crack, a core block, a cut) moves no energy into the drift:
    /// what it takes or gives (a spring that broke, the gas of a shred) is left out, and the
    /// drift goes on from where it was.
    pub energy_drift: f64,
    /// Springs broken during this step.
    pub springs_broken: u64,
    /// Core blocks released during this step.
    pub cores_released: u64,
    /// Bumped on every topology change (re-query buffers when it changes).
    pub topology_generation: u64,
    /// Vertices now (fracture appends vertices).
    pub vertex_count: usize,
    /// Triangles now.
    pub triangle_count: usize,
    /// Connected pieces now.
    pub fragment_count: usize,
    /// Wall-clock time of the step, s.
    pub step_seconds: f64,
    /// True when a gas volume was clamped during the step (a piece near zero or inverted volume:
    /// its pressure stopped growing).
    pub volume_clamped: bool,
    /// Largest spring strain at the end of the step (of every spring, also those on a border,
    /// which never break: see `SoftshellBodyDef::break_strain`); 0 when none is stretched (a
    /// compression is not counted).
    pub max_strain: f64,
    /// Conjugate-gradient iterations of the step (implicit Euler), 0 otherwise.
    pub solver_iterations: u64,
}

#[cfg(feature = "body")]
impl From<&BodyStats> for SoftshellBodyStats {
    fn from(s: &BodyStats) -> Self {
        Self {
            step: s.step,
            time: s.time,
            volume: s.volume,
            pressure: s.pressure,
            kinetic_energy: s.kinetic_energy,
            energy_drift: s.energy_drift,
            springs_broken: s.springs_broken,
            cores_released: s.cores_released,
            topology_generation: s.topology_generation,
            vertex_count: s.vertex_count,
            triangle_count: s.triangle_count,
            fragment_count: s.fragment_count,
            step_seconds: s.step_seconds,
            volume_clamped: s.volume_clamped,
            max_strain: s.max_strain,
            solver_iterations: s.solver_iterations,
        }
    }
}

/// A mass-spring soft body with gas and fracture (SPEC section 2).
///
/// Created by `softshell_body_new`, destroyed by `softshell_body_free`. Functions:
/// `softshell_body_add_sphere_obstacle`, `_add_plane_obstacle`, `_pin_vertex`,
/// `_apply_impulse`, `_break_edge`, `_break_edges`, `_step`, `_topology_generation`,
/// `_vertex_count`, `_triangle_count`, `_fragment_count`, `_copy_positions`, `_copy_velocities`,
/// `_copy_masses`, `_copy_triangles`, `_copy_vertex_origins`, `_copy_fragment_ids`,
/// `_memory_bytes`, `_save_ply`, `_save_obj`.
///
/// Fracture appends vertices and rewrites triangles: vertex indices are stable (survivors are
/// never renumbered), but the counts change, so re-query buffer sizes whenever
/// `softshell_body_topology_generation` changes.
///
/// Thread rules: a body may move between threads; one body must not be used from two threads at
/// once; different bodies may be stepped concurrently.
pub struct SoftshellBody {
    #[cfg(feature = "body")]
    pub(crate) body: Body,
    poisoned: bool,
}

#[cfg(feature = "body")]
impl SoftshellBody {
    /// The Rust body behind the handle, for the crate's benchmarks (which time what the C ABI
    /// does not expose, such as a step without its fracture phase); not part of the C ABI.
    #[doc(hidden)]
    pub fn body_mut(&mut self) -> &mut Body {
        &mut self.body
    }
}

impl Poisonable for SoftshellBody {
    fn is_poisoned(&self) -> bool {
        self.poisoned
    }
    fn poison(&mut self) {
        self.poisoned = true;
    }
}

#[cfg(not(feature = "body"))]
fn unsupported() -> Error {
    Error::unsupported("the soft body simulator", "body")
}

/// The default body def: h = 1/60 s, 1 substep, implicit Euler, 1 kg, K_s = 1000 N/m,
/// K_d = 1 N s/m, no gas, gravity 0,-9.81,0, no wind, no fracture, no ground, restitution 0,
/// friction 0.5, 1 thread, 10 iterations.
#[unsafe(no_mangle)]
pub extern "C" fn softshell_body_def_default() -> SoftshellBodyDef {
    SoftshellBodyDef {
        time_step: 1.0 / 60.0,
        substeps: 1,
        integrator: SOFTSHELL_INTEGRATOR_IMPLICIT_EULER,
        total_mass: 1.0,
        spring_stiffness: 1000.0,
        spring_damping: 1.0,
        gas_amount: 0.0,
        gravity: [0.0, -9.81, 0.0],
        wind: [0.0; 3],
        drag: 0.0,
        break_strain: 0.0,
        break_force: 0.0,
        leak_rate: 0.0,
        ground: false,
        ground_height: 0.0,
        restitution: 0.0,
        friction: 0.5,
        threads: 1,
        iterations: 10,
        internal_cookie: BODY_DEF_COOKIE,
    }
}

fn check_count(name: &str, value: u32, min: u32, max: u32) -> Result<()> {
    if value < min || value > max {
        return Err(Error::invalid_argument(format!("`{name}` = {value} must be in [{min}, {max}]")));
    }
    Ok(())
}

fn check_vector(name: &str, value: [f32; 3], limit: f32) -> Result<()> {
    for (axis, &c) in value.iter().enumerate() {
        check_range(&format!("{name}[{axis}]"), c, -limit, limit)?;
    }
    Ok(())
}

impl TryFrom<u32> for IntegratorKind {
    type Error = ();
    fn try_from(value: u32) -> std::result::Result<Self, ()> {
        match value {
            SOFTSHELL_INTEGRATOR_EXPLICIT_EULER => Ok(IntegratorKind),
            SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER => Ok(IntegratorKind),
            SOFTSHELL_INTEGRATOR_IMPLICIT_EULER => Ok(IntegratorKind),
            SOFTSHELL_INTEGRATOR_XPBD => Ok(IntegratorKind),
            _ => Err(()),
        }
    }
}

/// A checked integrator selector (kept out of the header: not `pub` outside the crate).
struct IntegratorKind;

/// The most substeps a def may ask for (validated without the simulator too; with it, the
/// simulator's own limit, which its UNSTABLE advice keeps to).
const MOST_SUBSTEPS: u32 = 1000;
#[cfg(feature = "body")]
const _: () = assert!(MOST_SUBSTEPS == crate::body::MAX_SUBSTEPS);
/// The shortest `time_step` a def may ask for, s (likewise the simulator's own).
const LEAST_TIME_STEP: f32 = 1e-6;
#[cfg(feature = "body")]
const _: () = assert!(LEAST_TIME_STEP == crate::body::MIN_TIME_STEP);

/// Checks every field of a def (messages name the field, its value and the valid range).
fn validate(def: &SoftshellBodyDef) -> Result<()> {
    check_cookie(def.internal_cookie, BODY_DEF_COOKIE, "SoftshellBodyDef", "softshell_body_def_default")?;
    check_range("time_step", def.time_step, LEAST_TIME_STEP, 1.0)?;
    check_count("substeps", def.substeps, 1, MOST_SUBSTEPS)?;
    check_count("iterations", def.iterations, 1, 1000)?;
    let _: IntegratorKind = arg_kind(def.integrator, "integrator", INTEGRATORS)?;
    check_range("total_mass", def.total_mass, 1e-12, 1e12)?;
    check_range("spring_stiffness", def.spring_stiffness, 0.0, 1e12)?;
    check_range("spring_damping", def.spring_damping, 0.0, 1e9)?;
    check_range("gas_amount", def.gas_amount, 0.0, 1e12)?;
    check_vector("gravity", def.gravity, 1e6)?;
    check_vector("wind", def.wind, 1e6)?;
    check_range("drag", def.drag, 0.0, 1e6)?;
    check_range("break_strain", def.break_strain, 0.0, 1e6)?;
    check_range("break_force", def.break_force, 0.0, 1e12)?;
    check_range("leak_rate", def.leak_rate, 0.0, 1e6)?;
    check_range("ground_height", def.ground_height, -1e9, 1e9)?;
    check_range("restitution", def.restitution, 0.0, 1.0)?;
    check_range("friction", def.friction, 0.0, 1000.0)?;
    check_count("threads", def.threads, 0, 256)?;
    Ok(())
}

#[cfg(feature = "body")]
fn settings_of(def: &SoftshellBodyDef) -> BodySettings {
    BodySettings {
        time_step: def.time_step,
        substeps: def.substeps,
        iterations: def.iterations,
        integrator: match def.integrator {
            SOFTSHELL_INTEGRATOR_EXPLICIT_EULER => Integrator::ExplicitEuler,
            SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER => Integrator::SymplecticEuler,
            SOFTSHELL_INTEGRATOR_XPBD => Integrator::Xpbd,
            _ => Integrator::ImplicitEuler,
        },
        total_mass: def.total_mass,
        spring_stiffness: def.spring_stiffness,
        spring_damping: def.spring_damping,
        gas_amount: def.gas_amount,
        gravity: Vec3::from_array(def.gravity),
        wind: Vec3::from_array(def.wind),
        drag: def.drag,
        break_strain: def.break_strain,
        break_force: def.break_force,
        leak_rate: def.leak_rate,
        ground: def.ground,
        ground_height: def.ground_height,
        restitution: def.restitution,
        friction: def.friction,
        threads: def.threads,
    }
}

/// Creates a soft body from `mesh` (copied: the mesh may be freed afterwards) and `def`.
///
/// Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` for a NULL pointer, `SOFTSHELL_STATUS_INVALID_ARGUMENT`
/// for a def not made by `softshell_body_def_default` or a field out of range (the message names
/// it), for a `total_mass` that gives a vertex with faces a mass below the smallest normal float
/// (1.18e-38 kg: a tiny total on a mesh of slivers), and with `ground` for a mesh whose free
/// vertices are all below the ground, `SOFTSHELL_STATUS_INVALID_MESH` when the mesh does not suit (with gas: not closed,
/// manifold and outward, every connected piece on its own; always: a triangle with a repeated
/// corner or an edge of zero length, or a vertex with a coordinate beyond ±1e9 m, the ground
/// plane's range),
/// `SOFTSHELL_STATUS_UNSUPPORTED` when built without the `body` feature. On success
/// `*out_body` receives a new handle to free with `softshell_body_free`; on failure it is left
/// unchanged.
///
/// # Safety
/// `mesh` must be NULL or a live mesh, `def` NULL or a readable def, `out_body` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_new(
    mesh: *const SoftshellMesh,
    def: *const SoftshellBodyDef,
    out_body: *mut *mut SoftshellBody,
) -> SoftshellStatus {
    status_call("softshell_body_new", || {
        // SAFETY: the caller promises a live mesh or NULL.
        let mesh = unsafe { arg_ref(mesh, "mesh")? };
        // SAFETY: the caller promises a readable def or NULL.
        let def = unsafe { arg_ref(def, "def")? };
        let out_body = out_arg(out_body, "out_body")?;
        validate(def)?;
        #[cfg(feature = "body")]
        {
            let body = Body::new(&mesh.mesh, &mesh.topology, settings_of(def))?;
            let handle = Box::into_raw(Box::new(SoftshellBody { body, poisoned: false }));
            // SAFETY: checked by out_arg.
            unsafe { write_out(out_body, handle) };
            Ok(())
        }
        #[cfg(not(feature = "body"))]
        {
            let _ = (mesh, out_body);
            Err(unsupported())
        }
    })
}

/// Destroys a body. `softshell_body_free(NULL)` does nothing; freeing twice is undefined
/// behaviour.
///
/// # Safety
/// `body` must be NULL or a live body that is not used again.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_free(body: *mut SoftshellBody) {
    value_call("softshell_body_free", (), || {
        if !body.is_null() {
            // SAFETY: the caller hands back a pointer made by Box::into_raw and never uses it again.
            drop(unsafe { Box::from_raw(body) });
        }
    })
}

/// Adds a solid sphere obstacle (centre `center` float[3], m; `radius` > 0, m): vertices are
/// kept outside it with the def's restitution and friction. Free vertices inside it when it is
/// added move to its surface at once, their velocity into it removed; the energy drift goes on
/// from where it was (the move is not counted as work).
/// Returns `SOFTSHELL_STATUS_INVALID_ARGUMENT` for a non-finite centre or a radius outside
/// [1.18e-38, 1e9] m (the smallest normal float to 1e9), and (adding nothing) when every free
/// vertex of the body is inside the sphere.
///
/// # Safety
/// `body` must be NULL or a live body; `center` NULL or three readable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_add_sphere_obstacle(
    body: *mut SoftshellBody,
    center: *const f32,
    radius: f32,
) -> SoftshellStatus {
    handle_call("softshell_body_add_sphere_obstacle", body, "body", |h| {
        // SAFETY: the caller promises three floats or NULL.
        let center = unsafe { arg_vec3(center, "center")? };
        check_range("radius", radius, f32::MIN_POSITIVE, 1e9)?;
        #[cfg(feature = "body")]
        {
            h.body.add_obstacle(Obstacle::Sphere { center: Vec3::from_array(center), radius })
        }
        #[cfg(not(feature = "body"))]
        {
            let _ = (h, center);
            Err(unsupported())
        }
    })
}

/// Adds a half-space obstacle: the plane through `point` (float[3], m) with `normal` (float[3],
/// any finite length above 1e-12, pointing to the free side); vertices are kept on the normal's
/// side.
/// Free vertices behind it when it is added move onto the plane at once, their velocity into it
/// removed; the energy drift goes on from where it was (the move is not counted as work).
/// Returns `SOFTSHELL_STATUS_INVALID_ARGUMENT` for non-finite values or a normal of length 1e-12
/// or less, and (adding nothing) when every free vertex of the body is behind the plane.
///
/// # Safety
/// `body` must be NULL or a live body; `point` and `normal` NULL or three readable floats each.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_add_plane_obstacle(
    body: *mut SoftshellBody,
    point: *const f32,
    normal: *const f32,
) -> SoftshellStatus {
    handle_call("softshell_body_add_plane_obstacle", body, "body", |h| {
        // SAFETY: the caller promises three floats or NULL.
        let point = unsafe { arg_vec3(point, "point")? };
        // SAFETY: as above.
        let normal = unsafe { arg_vec3(normal, "normal")? };
        let length = (normal[0] as f64).hypot(normal[1] as f64).hypot(normal[2] as f64);
        if length.is_nan() || length <= 1e-12 || !length.is_finite() {
            return Err(Error::invalid_argument(format!(
                "`normal` = ({}, {}, {}) must have a finite length above 1e-12",
                normal[0], normal[1], normal[2]
            )));
        }
        #[cfg(feature = "body")]
        {
            let n = (Vec3::from_array(normal).as_dvec3() / length).as_vec3();
            h.body.add_obstacle(Obstacle::Plane { point: Vec3::from_array(point), normal: n })
        }
        #[cfg(not(feature = "body"))]
        {
            let _ = (h, point);
            Err(unsupported())
        }
    })
}

/// Pins vertex `vertex`: it stays where it is (velocity zero) and no longer responds to forces.
/// The kinetic energy it had counts as external work in `energy_drift`.
/// Returns `SOFTSHELL_STATUS_INVALID_ARGUMENT` for an index out of range.
///
/// # Safety
/// `body` must be NULL or a live body.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_pin_vertex(body: *mut SoftshellBody, vertex: u32) -> SoftshellStatus {
    handle_call("softshell_body_pin_vertex", body, "body", |h| {
        #[cfg(feature = "body")]
        {
            h.body.pin(vertex)
        }
        #[cfg(not(feature = "body"))]
        {
            let _ = (h, vertex);
            Err(unsupported())
        }
    })
}

/// Applies `impulse` (float[3], N s) to vertex `vertex`: its velocity changes by impulse/mass
/// (a pinned vertex ignores it). Returns `SOFTSHELL_STATUS_INVALID_ARGUMENT`, changing nothing,
/// for an index out of range, an impulse component that is not finite or beyond ±1e12 N s, or
/// an impulse that would give the vertex a velocity beyond ±1e12 m/s on an axis (a light
/// vertex).
///
/// # Safety
/// `body` must be NULL or a live body; `impulse` NULL or three readable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_apply_impulse(
    body: *mut SoftshellBody,
    vertex: u32,
    impulse: *const f32,
) -> SoftshellStatus {
    handle_call("softshell_body_apply_impulse", body, "body", |h| {
        // SAFETY: the caller promises three floats or NULL.
        let impulse = unsafe { arg_vec3(impulse, "impulse")? };
        check_vector("impulse", impulse, 1e12)?;
        #[cfg(feature = "body")]
        {
            h.body.apply_impulse(vertex, Vec3::from_array(impulse))
        }
        #[cfg(not(feature = "body"))]
        {
            let _ = (h, vertex);
            Err(unsupported())
        }
    })
}

/// Breaks the spring between vertices `a` and `b` by hand (an interactive cut): the same crack
/// as a spring over `break_strain`. The surface opens where a chain of broken edges passes through
/// a vertex (that vertex is split; copies are appended), and each side of the opened edge is then
/// a spring of its own face. Bumps the topology generation. Works whatever the break limits are;
/// a body made without any builds its topology and fracture buffers at its first cut (3-9 ms on
/// the issue-5 balloon, 10,242 vertices, against 0.7-1.5 ms for a cut of 1 to 100 edges on the
/// same body made with a break limit, which reserves them when it is made: give a body that
/// will be cut a limit it never reaches, `break_strain` 1e6 say, to cut at a steady cost).
/// Returns `SOFTSHELL_STATUS_INVALID_ARGUMENT`, with nothing changed, when an index is out of
/// range, `a` and `b` are not joined by a spring (not an edge, or broken and not yet open), or
/// their edge has one face (a border of the mesh, or a side of an open crack: nothing to part).
///
/// # Safety
/// `body` must be NULL or a live body.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_break_edge(body: *mut SoftshellBody, a: u32, b: u32) -> SoftshellStatus {
    handle_call("softshell_body_break_edge", body, "body", |h| {
        #[cfg(feature = "body")]
        {
            h.body.break_edge(a, b)
        }
        #[cfg(not(feature = "body"))]
        {
            let _ = (h, a, b);
            Err(unsupported())
        }
    })
}

/// Breaks the springs between `pair_count` vertex pairs by hand in one topology change (a cut
/// along several edges: a slit, a knife's path): `pairs` holds `2 * pair_count` vertex indices,
/// pair k being `pairs[2k]`, `pairs[2k + 1]`. Each pair as in `softshell_body_break_edge`; a pair
/// given twice (either way round) counts once. The surface opens once where the whole cut
/// passes, and the generation is bumped once (not at all for `pair_count` 0, where `pairs` may
/// be NULL). Every pair is checked first: `SOFTSHELL_STATUS_INVALID_ARGUMENT`, with nothing
/// changed and the pair named in the message, if any pair would be refused by
/// `softshell_body_break_edge`. `*out_broken`, when not NULL, gets the springs broken (it is
/// not written when the call fails).
///
/// # Safety
/// `body` must be NULL or a live body; `pairs` NULL or `2 * pair_count` readable indices;
/// `out_broken` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_break_edges(
    body: *mut SoftshellBody,
    pairs: *const u32,
    pair_count: usize,
    out_broken: *mut usize,
) -> SoftshellStatus {
    handle_call("softshell_body_break_edges", body, "body", |h| {
        let indices = pair_count
            .checked_mul(2)
            .ok_or_else(|| Error::invalid_argument(format!("`pair_count` = {pair_count} is too large")))?;
        // SAFETY: the caller promises 2 * pair_count indices or NULL.
        let indices = unsafe { arg_slice(pairs, indices, "pairs")? };
        // Checked before anything changes (NULL is allowed: not written).
        let out_broken = if out_broken.is_null() { None } else { Some(out_arg(out_broken, "out_broken")?) };
        #[cfg(feature = "body")]
        {
            let pairs: Vec<[u32; 2]> = indices.chunks_exact(2).map(|p| [p[0], p[1]]).collect();
            let broken = h.body.break_edges(&pairs)?;
            if let Some(out) = out_broken {
                // SAFETY: checked by out_arg; the caller promises a writable size_t.
                unsafe { write_out(out, broken as usize) };
            }
            Ok(())
        }
        #[cfg(not(feature = "body"))]
        {
            let _ = (h, indices, out_broken);
            Err(unsupported())
        }
    })
}

/// Advances the body by one `time_step`: forces, integration (substeps), obstacles, gas leak,
/// then fracture (springs over `break_strain` crack, nodes over `break_force` release core
/// blocks). Writes what happened into `*out_stats` when it is not NULL.
///
/// Returns `SOFTSHELL_STATUS_UNSTABLE` when the step diverged (a NaN, or energy growing without a
/// source: in one step, or, with every integrator but XPBD, over many steps beyond what the body
/// was given): the state is rolled back to before the step, `*out_stats` is not written, and the
/// message gives the largest stable time step it estimates. A body's def is fixed when it is
/// made: advice such as "substeps >= 2" is for a new body made with that def.
///
/// Positions are f32, in the caller's frame: far from the origin they move in steps of one unit
/// in the last place (2.4e-7 m at 2 m, 1e-3 m at 1e4 m, 8e-3 m at 1e5 m), and a substep that
/// moves the body by less than that loses its motion. With the default def a 1 m ball still
/// falls 3e4 m from the origin, and a 0.5 m ball 1e5 m from it is UNSTABLE at its first step;
/// more substeps do not help (each moves the body less). Very short steps meet the same limit
/// near the origin: in a step of T from rest, gravity moves a body by about `|g| T h` in the last
/// substep of `h`. A ball of radius 1 m whose top is 2 m up, stepped 200 times at time_step
/// 1e-5 s in 10 substeps, falls 4.4e-6 m instead of 2.0e-5 m with implicit Euler and XPBD (not
/// reported), and is UNSTABLE with symplectic Euler. When such a step is UNSTABLE, the message
/// says why in a note. The note names the distance, the step of the positions there, the body's
/// shortest spring and its motion in a substep. Translate the scene so that the body is near the
/// origin, and keep `|g| T h` above the step of the positions.
///
/// # Safety
/// `body` must be NULL or a live body; `out_stats` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_step(
    body: *mut SoftshellBody,
    out_stats: *mut SoftshellBodyStats,
) -> SoftshellStatus {
    handle_call("softshell_body_step", body, "body", |h| {
        let out_stats = if out_stats.is_null() { None } else { Some(out_arg(out_stats, "out_stats")?) };
        #[cfg(feature = "body")]
        {
            let stats = h.body.step()?;
            if let Some(out) = out_stats {
                // SAFETY: checked by out_arg.
                unsafe { write_out(out, SoftshellBodyStats::from(&stats)) };
            }
            Ok(())
        }
        #[cfg(not(feature = "body"))]
        {
            let _ = (h, out_stats);
            Err(unsupported())
        }
    })
}

/// The body of a getter that returns a plain value: `$value` of a live, unpoisoned body; 0 for
/// NULL, for a poisoned body and in a build without the `body` feature. Panics are caught.
macro_rules! body_getter {
    ($name:literal, $body:ident, |$b:ident| $value:expr) => {
        value_call($name, 0, || {
            #[cfg(feature = "body")]
            {
                read_body($body, 0, |$b| $value)
            }
            #[cfg(not(feature = "body"))]
            {
                let _ = $body;
                0
            }
        })
    };
}

#[cfg(feature = "body")]
fn read_body<T>(body: *const SoftshellBody, fallback: T, f: impl FnOnce(&Body) -> T) -> T {
    // SAFETY: the caller promises a live body or NULL.
    match unsafe { arg_ref(body, "body") } {
        Ok(h) if !h.poisoned => f(&h.body),
        _ => fallback,
    }
}

/// Topology generation: 0 at creation, bumped by every topology change (a crack, a core block,
/// `softshell_body_break_edge`, `softshell_body_break_edges`). When it changes, re-query vertex and triangle counts and
/// buffer sizes. 0 for NULL.
///
/// # Safety
/// `body` must be NULL or a live body.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_topology_generation(body: *const SoftshellBody) -> u64 {
    body_getter!("softshell_body_topology_generation", body, |b| b.topology_generation())
}

/// Number of vertices now (grows with fracture); 0 for NULL.
///
/// # Safety
/// `body` must be NULL or a live body.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_vertex_count(body: *const SoftshellBody) -> usize {
    body_getter!("softshell_body_vertex_count", body, |b| b.vertex_count())
}

/// Number of triangles now (grows when core blocks are released); 0 for NULL.
///
/// # Safety
/// `body` must be NULL or a live body.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_triangle_count(body: *const SoftshellBody) -> usize {
    body_getter!("softshell_body_triangle_count", body, |b| b.triangle_count())
}

/// Number of connected pieces (fragments) now; 0 for NULL.
///
/// # Safety
/// `body` must be NULL or a live body.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_fragment_count(body: *const SoftshellBody) -> usize {
    body_getter!("softshell_body_fragment_count", body, |b| b.fragment_count())
}

/// Heap bytes held by the body (positions, springs, gas and fracture bookkeeping, scratch; the
/// worker threads and the thread pool's own bookkeeping, inside rayon, excluded); nothing is
/// held for gas without gas, nor for fracture while both break limits are 0 and no edge was
/// broken by hand. A body with a break limit holds its vertex, spring and topology buffers,
/// the implicit solver's per-vertex buffers and coupling layout and the gas's corner lists from
/// the start, with room for an eighth more vertices, edges and faces, and a second set of the
/// gas's rings to make the next ones in (the issue-5 balloon with `break_strain` 3%: 13.2 MB
/// against 7.2 MB without break limits), so that a step that cracks within that room moves no
/// large array and faults in few fresh pages; beyond the room the arrays grow, so the figure
/// can rise after a crack. A step that changes no topology allocates nothing once the body has taken its
/// first steps (its scratch is sized by them); on several threads the implicit integrator's
/// solve still asks the thread pool for a small job record per substep for each worker that
/// joins it (and with more than 4 threads for their claim counters), and on more than one
/// thread the pool's job queue takes a block about once every 63 steps. 0 for NULL.
///
/// # Safety
/// `body` must be NULL or a live body.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_memory_bytes(body: *const SoftshellBody) -> usize {
    body_getter!("softshell_body_memory_bytes", body, |b| b.memory_bytes())
}

/// Shared body of the copy functions: `len` elements filled by `fill` from the body.
#[cfg(feature = "body")]
unsafe fn copy_from<T>(
    function: &str,
    body: *const SoftshellBody,
    out: *mut T,
    capacity: usize,
    out_len: *mut usize,
    len: impl FnOnce(&Body) -> usize,
    fill: impl FnOnce(&Body, &mut [T]),
) -> SoftshellStatus {
    handle_read(function, body, "body", |h| {
        let n = len(&h.body);
        // SAFETY: the caller promises the buffer; copy_out checks its size before writing.
        unsafe { copy_out(n, out, capacity, out_len, |dst| fill(&h.body, dst)) }
    })
}

/// Copies the positions (x,y,z per vertex, `3 * vertex_count` floats, m) into `out`.
/// If `out` is NULL or `capacity` (in floats) is too small, returns
/// `SOFTSHELL_STATUS_BUFFER_TOO_SMALL`, writes the number of floats needed to `*out_len` and
/// nothing else. On success `*out_len` is the number of floats written. Returns
/// `SOFTSHELL_STATUS_NULL_ARGUMENT`, writing nothing, when the body or `out_len` is NULL.
///
/// # Safety
/// `body` must be NULL or a live body; `out` NULL or `capacity` writable floats; `out_len` NULL
/// or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_copy_positions(
    body: *const SoftshellBody,
    out: *mut f32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    #[cfg(feature = "body")]
    // SAFETY: forwarded from the caller.
    unsafe {
        copy_from(
            "softshell_body_copy_positions",
            body,
            out,
            capacity,
            out_len,
            |b| b.vertex_count() * 3,
            |b, dst| write_triples(dst, b.positions().map(|p| p.to_array())),
        )
    }
    #[cfg(not(feature = "body"))]
    {
        let _ = (out, capacity, out_len);
        handle_read("softshell_body_copy_positions", body, "body", |_| Err(unsupported()))
    }
}

/// Copies the velocities (x,y,z per vertex, `3 * vertex_count` floats, m/s) into `out`, with the
/// buffer rules of `softshell_body_copy_positions`.
///
/// # Safety
/// As `softshell_body_copy_positions`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_copy_velocities(
    body: *const SoftshellBody,
    out: *mut f32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    #[cfg(feature = "body")]
    // SAFETY: forwarded from the caller.
    unsafe {
        copy_from(
            "softshell_body_copy_velocities",
            body,
            out,
            capacity,
            out_len,
            |b| b.vertex_count() * 3,
            |b, dst| write_triples(dst, b.velocities().map(|p| p.to_array())),
        )
    }
    #[cfg(not(feature = "body"))]
    {
        let _ = (out, capacity, out_len);
        handle_read("softshell_body_copy_velocities", body, "body", |_| Err(unsupported()))
    }
}

/// Copies the vertex masses (one float per vertex, kg; pinned vertices keep theirs) into `out`,
/// with the buffer rules of `softshell_body_copy_positions`. Their sum stays `total_mass`
/// through fracture.
///
/// # Safety
/// As `softshell_body_copy_positions`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_copy_masses(
    body: *const SoftshellBody,
    out: *mut f32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    #[cfg(feature = "body")]
    // SAFETY: forwarded from the caller.
    unsafe {
        copy_from(
            "softshell_body_copy_masses",
            body,
            out,
            capacity,
            out_len,
            |b| b.vertex_count(),
            |b, dst| {
                for (d, m) in dst.iter_mut().zip(b.masses()) {
                    *d = m;
                }
            },
        )
    }
    #[cfg(not(feature = "body"))]
    {
        let _ = (out, capacity, out_len);
        handle_read("softshell_body_copy_masses", body, "body", |_| Err(unsupported()))
    }
}

/// Copies the triangles (a,b,c per triangle, `3 * triangle_count` uint32_t, counter-clockwise
/// from outside) into `out`, with the buffer rules of `softshell_body_copy_positions`
/// (capacity and `*out_len` count uint32_t).
///
/// # Safety
/// As `softshell_body_copy_positions`, with `capacity` writable uint32_t.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_copy_triangles(
    body: *const SoftshellBody,
    out: *mut u32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    #[cfg(feature = "body")]
    // SAFETY: forwarded from the caller.
    unsafe {
        copy_from(
            "softshell_body_copy_triangles",
            body,
            out,
            capacity,
            out_len,
            |b| b.triangle_count() * 3,
            |b, dst| write_triples(dst, b.triangles()),
        )
    }
    #[cfg(not(feature = "body"))]
    {
        let _ = (out, capacity, out_len);
        handle_read("softshell_body_copy_triangles", body, "body", |_| Err(unsupported()))
    }
}

/// Copies, for each vertex, the input-mesh vertex it was split from (one uint32_t per vertex;
/// the identity before any fracture). Vertex indices are stable: fracture appends vertices and
/// never renumbers. A crack's copies start where their origin is. A core block adds two more
/// vertices that are not copies: the centres of the caps that close the block and the hole, at
/// the mean of the ring around the released vertex; the block's centre has the released
/// vertex's origin, the hole's that of a vertex of the ring. Buffer rules of
/// `softshell_body_copy_positions` (counts in uint32_t).
///
/// # Safety
/// As `softshell_body_copy_triangles`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_copy_vertex_origins(
    body: *const SoftshellBody,
    out: *mut u32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    #[cfg(feature = "body")]
    // SAFETY: forwarded from the caller.
    unsafe {
        copy_from(
            "softshell_body_copy_vertex_origins",
            body,
            out,
            capacity,
            out_len,
            |b| b.vertex_count(),
            |b, dst| {
                for (i, d) in dst.iter_mut().enumerate() {
                    *d = b.vertex_origin(i);
                }
            },
        )
    }
    #[cfg(not(feature = "body"))]
    {
        let _ = (out, capacity, out_len);
        handle_read("softshell_body_copy_vertex_origins", body, "body", |_| Err(unsupported()))
    }
}

/// Copies, for each triangle, its connected piece (fragment) in `0..fragment_count` (one
/// uint32_t per triangle). Buffer rules of `softshell_body_copy_positions` (counts in uint32_t).
///
/// # Safety
/// As `softshell_body_copy_triangles`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_copy_fragment_ids(
    body: *const SoftshellBody,
    out: *mut u32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    #[cfg(feature = "body")]
    // SAFETY: forwarded from the caller.
    unsafe {
        copy_from(
            "softshell_body_copy_fragment_ids",
            body,
            out,
            capacity,
            out_len,
            |b| b.fragment_ids().len(),
            |b, dst| dst.copy_from_slice(b.fragment_ids()),
        )
    }
    #[cfg(not(feature = "body"))]
    {
        let _ = (out, capacity, out_len);
        handle_read("softshell_body_copy_fragment_ids", body, "body", |_| Err(unsupported()))
    }
}
