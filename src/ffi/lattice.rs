//! `SoftshellLattice`: the FastLSM elastic lattice surface (SPEC 3) behind the C ABI.
//!
//! This file converts between C and Rust only: the def becomes [`LatticeParams`], pointers
//! become slices, errors become status codes. Without the `lattice` cargo feature every function
//! still exists (the header never depends on features) and returns `SOFTSHELL_STATUS_UNSUPPORTED`.

use super::boundary::{
    Poisonable, SoftshellStatus, arg_ref, arg_slice, arg_vec3, check_cookie, copy_out, handle_call, handle_read,
    out_arg, status_call, value_call, write_out, write_triples,
};
#[cfg(not(feature = "lattice"))]
use crate::error::Error;
use crate::error::Result;
use backend::{Lattice, StepStats};

/// Private magic stored in `internal_cookie` by `softshell_lattice_def_default`.
pub(crate) const LATTICE_DEF_COOKIE: u32 = 0x5EA7_1A77;

/// Settings of a lattice, for `softshell_lattice_new`. Always start from
/// `softshell_lattice_def_default()` and edit fields: a def not made by it is refused.
///
/// The sheet lies in the x-z plane at rest: particle (column, row) at
/// `(column * spacing, 0, row * spacing)`, its upper side facing +y.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SoftshellLatticeDef {
    /// Particles along x, >= 1. Default 32.
    pub columns: u32,
    /// Particles along z, >= 1. Default 32. `columns * rows` is at most 67,108,864; a lattice
    /// takes about 320 bytes per site (370 with region damping), holes included, plus
    /// `(2w + 2) * columns` sites' worth of scratch per thread.
    pub rows: u32,
    /// Rest distance between neighbouring particles, m, in (0, 1e6]. Default 0.05.
    pub spacing: f32,
    /// Region half-width w >= 1: each particle's region is the (2w+1) x (2w+1) box of lattice
    /// sites around it (clipped by the border and the mask). Larger w = stiffer; the work of a
    /// step does not grow with w (at most 1.5x that of w = 1, by construction; regions wider than
    /// an eighth of the rows leave fewer blocks of rows to share among threads). Default 2.
    pub region_half_width: u32,
    /// alpha in (0, 1]: how hard particles are pulled to their goals each step (1 = all the way).
    /// Default 0.5.
    pub stiffness: f32,
    /// Region damping in [0, 1]: the fraction of each particle's velocity relative to its
    /// regions' rigid motion removed per step (damps wobble, keeps rigid motion). Default 0.2.
    /// 0 turns it off and saves its memory and time.
    pub damping: f32,
    /// Time step, s, in [1e-6, 1]. Default 1/60.
    pub time_step: f32,
    /// Mass of each particle, kg, in (0, 1e12]. Default 0.01.
    pub particle_mass: f32,
    /// Gravity, m/s^2, finite. Default (0, -9.81, 0).
    pub gravity: [f32; 3],
    /// Worker threads of this lattice: 0 = one per core, 1 = run on the caller's thread
    /// (default), at most 256. Results are bit-identical for any value.
    pub threads: u32,
    /// Viscous damping of all motion, 1/s, in [0, 1e6]: each step velocities are scaled by
    /// `max(0, 1 - velocity_damping * time_step)`. Region damping leaves the slow, locally
    /// rigid modes alone (a hanging sheet bouncing); this brings them to rest. Default 0.5.
    pub velocity_damping: f32,
    /// Set by `softshell_lattice_def_default`; do not touch.
    pub internal_cookie: u32,
}

/// What one `softshell_lattice_step` did. Fields may be appended in later versions.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SoftshellLatticeStats {
    /// Steps completed, this one included.
    pub step: u64,
    /// Simulated time after the step, s.
    pub time: f64,
    /// Mean over all particles (pinned ones included) of the distance from the particle to its
    /// goal, |g - x|, at the start of the step, m. 0 at rest and for any rigid motion.
    pub goal_distance: f64,
    /// Wall-clock time the step took, s.
    pub step_seconds: f64,
    /// Largest |g - x| over all particles at the start of the step, m.
    pub max_goal_distance: f64,
    /// Kinetic energy of all particles after the step, J.
    pub kinetic_energy: f64,
}

impl From<StepStats> for SoftshellLatticeStats {
    fn from(s: StepStats) -> Self {
        Self {
            step: s.step,
            time: s.time,
            goal_distance: s.goal_distance,
            step_seconds: s.step_seconds,
            max_goal_distance: s.max_goal_distance,
            kinetic_energy: s.kinetic_energy,
        }
    }
}

/// A FastLSM elastic lattice surface (SPEC 3): particles on a 2D lattice with an optional mask
/// of holes, shape-matched in overlapping square regions.
///
/// Created by `softshell_lattice_new`, destroyed by `softshell_lattice_free`. Edited with
/// `softshell_lattice_pin` / `_unpin` / `_apply_force` / `_clear_forces` / `_set_positions`,
/// advanced with `softshell_lattice_step`, read with `softshell_lattice_particle_count`,
/// `_triangle_count`, `_particle_index`, `_copy_positions`, `_copy_velocities`, `_copy_goals`,
/// `_copy_triangles` and `_memory_bytes`, written with `_save_ply` and `_save_obj`.
///
/// Particles are numbered row by row (row 0 first, column 0 first within a row), holes skipped.
/// Thread rules: a lattice may move between threads, but must not be used from two threads at
/// once; different lattices may be stepped concurrently. It owns its worker threads.
pub struct SoftshellLattice {
    lattice: Lattice,
    poisoned: bool,
}

impl Poisonable for SoftshellLattice {
    fn is_poisoned(&self) -> bool {
        self.poisoned
    }
    fn poison(&mut self) {
        self.poisoned = true;
    }
}

#[cfg(feature = "lattice")]
mod backend {
    pub(super) use crate::lattice::{Lattice, LatticeParams, StepStats};
}

/// Stand-ins when the `lattice` feature is off: `Lattice` has no values, so no handle can exist
/// and every function body still compiles (`create` is the only way in, and it refuses).
#[cfg(not(feature = "lattice"))]
mod backend {
    use crate::error::Result;

    pub(crate) enum Lattice {}
    pub(crate) struct StepStats {
        pub step: u64,
        pub time: f64,
        pub goal_distance: f64,
        pub step_seconds: f64,
        pub max_goal_distance: f64,
        pub kinetic_energy: f64,
    }
    pub(crate) struct Layout;
    impl Layout {
        pub fn triangle_count(&self) -> usize {
            0
        }
        pub fn triangles(&self) -> Vec<[u32; 3]> {
            Vec::new()
        }
        pub fn particle(&self, _c: u32, _r: u32) -> Result<usize> {
            unreachable!()
        }
    }
    #[allow(clippy::unused_self)]
    impl Lattice {
        pub fn pin(&mut self, _c: u32, _r: u32, _p: bool) -> Result<()> {
            match *self {}
        }
        pub fn apply_force(&mut self, _c: u32, _r: u32, _f: [f32; 3]) -> Result<()> {
            match *self {}
        }
        pub fn clear_forces(&mut self) {
            match *self {}
        }
        pub fn set_positions(&mut self, _p: &[f32]) -> Result<()> {
            match *self {}
        }
        pub fn step(&mut self) -> Result<StepStats> {
            match *self {}
        }
        pub fn particle_count(&self) -> usize {
            match *self {}
        }
        pub fn layout(&self) -> &Layout {
            match *self {}
        }
        pub fn copy_positions(&self, _o: &mut [f32]) {
            match *self {}
        }
        pub fn copy_velocities(&self, _o: &mut [f32]) {
            match *self {}
        }
        pub fn copy_goals(&self, _o: &mut [f32]) {
            match *self {}
        }
        pub fn memory_bytes(&self) -> usize {
            match *self {}
        }
    }
}

#[cfg(feature = "lattice")]
fn create(def: &SoftshellLatticeDef, mask: *const u8) -> Result<Lattice> {
    let params = backend::LatticeParams {
        columns: def.columns,
        rows: def.rows,
        spacing: def.spacing,
        region_half_width: def.region_half_width,
        stiffness: def.stiffness,
        damping: def.damping,
        time_step: def.time_step,
        velocity_damping: def.velocity_damping,
        particle_mass: def.particle_mass,
        gravity: def.gravity,
        threads: def.threads,
    };
    params.validate()?;
    let sites = def.columns as usize * def.rows as usize;
    let mask = if mask.is_null() {
        None
    } else {
        // SAFETY: the caller promises `columns * rows` readable bytes (checked non-NULL).
        Some(unsafe { arg_slice(mask, sites, "mask")? })
    };
    Lattice::new(params, mask)
}

#[cfg(not(feature = "lattice"))]
fn create(_def: &SoftshellLatticeDef, _mask: *const u8) -> Result<Lattice> {
    Err(Error::unsupported("the lattice simulator", "lattice"))
}

/// The default lattice settings (see each field of `SoftshellLatticeDef`), with the private
/// cookie that `softshell_lattice_new` checks. Never fails.
#[unsafe(no_mangle)]
pub extern "C" fn softshell_lattice_def_default() -> SoftshellLatticeDef {
    SoftshellLatticeDef {
        columns: 32,
        rows: 32,
        spacing: 0.05,
        region_half_width: 2,
        stiffness: 0.5,
        damping: 0.2,
        time_step: 1.0 / 60.0,
        particle_mass: 0.01,
        gravity: [0.0, -9.81, 0.0],
        threads: 1,
        velocity_damping: 0.5,
        internal_cookie: LATTICE_DEF_COOKIE,
    }
}

/// Creates a lattice at rest from `def` and an optional `mask` of `rows * columns` bytes
/// (row-major: entry `row * columns + column`; 1 = particle, 0 = hole). NULL `mask` = a full sheet.
///
/// Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` when `def` or `out_lattice` is NULL,
/// `SOFTSHELL_STATUS_INVALID_ARGUMENT` when the def was not made by
/// `softshell_lattice_def_default`, a field is out of range (`region_half_width` = 0, `stiffness`
/// outside (0, 1], `spacing` <= 0, a NaN...) or the mask holds no particle or a value other than
/// 0 and 1 (the message names the field or mask entry), `SOFTSHELL_STATUS_UNSUPPORTED` when built
/// without the `lattice` feature. On success `*out_lattice` receives a new handle to free with
/// `softshell_lattice_free`; on failure it is left unchanged. The mask is copied.
///
/// # Safety
/// `def` must be NULL or point to a `SoftshellLatticeDef`; `mask` NULL or `rows * columns`
/// readable bytes; `out_lattice` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_new(
    def: *const SoftshellLatticeDef,
    mask: *const u8,
    out_lattice: *mut *mut SoftshellLattice,
) -> SoftshellStatus {
    status_call("softshell_lattice_new", || {
        // SAFETY: the caller promises a readable def or NULL.
        let def = unsafe { arg_ref(def, "def")? };
        let out_lattice = out_arg(out_lattice, "out_lattice")?;
        check_cookie(def.internal_cookie, LATTICE_DEF_COOKIE, "SoftshellLatticeDef", "softshell_lattice_def_default")?;
        let lattice = create(def, mask)?;
        let handle = Box::into_raw(Box::new(SoftshellLattice { lattice, poisoned: false }));
        // SAFETY: checked by out_arg before any work.
        unsafe { write_out(out_lattice, handle) };
        Ok(())
    })
}

/// Destroys a lattice and stops its worker threads. `softshell_lattice_free(NULL)` does
/// nothing. Freeing a lattice twice is undefined behaviour.
///
/// # Safety
/// `lattice` must be NULL or a live lattice that is not used again.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_free(lattice: *mut SoftshellLattice) {
    value_call("softshell_lattice_free", (), || {
        if !lattice.is_null() {
            // SAFETY: the caller hands back a pointer made by Box::into_raw and never uses it again.
            drop(unsafe { Box::from_raw(lattice) });
        }
    })
}

/// Pins the particle at (`column`, `row`): from now on it keeps its position and has zero
/// velocity (it still shapes its regions). Pinning twice is harmless. Returns
/// `SOFTSHELL_STATUS_INVALID_ARGUMENT` when (column, row) is outside the lattice or a hole.
///
/// # Safety
/// `lattice` must be NULL or a live lattice.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_pin(
    lattice: *mut SoftshellLattice,
    column: u32,
    row: u32,
) -> SoftshellStatus {
    handle_call("softshell_lattice_pin", lattice, "lattice", |h| h.lattice.pin(column, row, true))
}

/// Releases a particle pinned by `softshell_lattice_pin` (it starts at rest). Unpinning a
/// particle that is not pinned is harmless. Errors as `softshell_lattice_pin`.
///
/// # Safety
/// `lattice` must be NULL or a live lattice.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_unpin(
    lattice: *mut SoftshellLattice,
    column: u32,
    row: u32,
) -> SoftshellStatus {
    handle_call("softshell_lattice_unpin", lattice, "lattice", |h| h.lattice.pin(column, row, false))
}

/// Adds `force` (N, float[3]) to the particle at (`column`, `row`) for the next step only:
/// forces given before one step add up, and the step clears them. A force on a pinned particle
/// has no effect. Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` for a NULL `force`,
/// `SOFTSHELL_STATUS_INVALID_ARGUMENT` for a NaN/inf component or a site outside the lattice or
/// in a hole.
///
/// # Safety
/// `lattice` must be NULL or a live lattice; `force` NULL or three readable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_apply_force(
    lattice: *mut SoftshellLattice,
    column: u32,
    row: u32,
    force: *const f32,
) -> SoftshellStatus {
    handle_call("softshell_lattice_apply_force", lattice, "lattice", |h| {
        // SAFETY: the caller promises three floats or NULL.
        let force = unsafe { arg_vec3(force, "force")? };
        h.lattice.apply_force(column, row, force)
    })
}

/// Drops the forces given by `softshell_lattice_apply_force` since the last step (an UNSTABLE
/// step leaves them pending; its message says when they drove it).
///
/// # Safety
/// `lattice` must be NULL or a live lattice.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_clear_forces(lattice: *mut SoftshellLattice) -> SoftshellStatus {
    handle_call("softshell_lattice_clear_forces", lattice, "lattice", |h| {
        h.lattice.clear_forces();
        Ok(())
    })
}

/// Sets the position of every particle from `positions` (x,y,z per particle in particle order,
/// `float_count` = 3 * particle count floats), e.g. to start from a draped or rotated shape.
/// Velocities are kept; the rest shape does not change. Pinned particles move to their new
/// positions too and stay there, so this also drives pins (grab handles) frame by frame. Returns
/// `SOFTSHELL_STATUS_NULL_ARGUMENT` for NULL `positions` with a non-zero count and
/// `SOFTSHELL_STATUS_INVALID_ARGUMENT` (changing nothing) for a wrong count or a value that is
/// not finite or beyond ±1e15 m (where a step would call the lattice diverged).
///
/// # Safety
/// `lattice` must be NULL or a live lattice; `positions` NULL or `float_count` readable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_set_positions(
    lattice: *mut SoftshellLattice,
    positions: *const f32,
    float_count: usize,
) -> SoftshellStatus {
    handle_call("softshell_lattice_set_positions", lattice, "lattice", |h| {
        // SAFETY: the caller promises `float_count` floats.
        let positions = unsafe { arg_slice(positions, float_count, "positions")? };
        h.lattice.set_positions(positions)
    })
}

/// Advances the lattice by one time step (SPEC 3): shape matching of every region, goals,
/// region damping, gravity and the forces given since the last step, pins.
/// `out_stats` may be NULL; otherwise it receives what the step did.
///
/// Returns `SOFTSHELL_STATUS_UNSTABLE` when the step diverged (a value not finite, a position
/// beyond 1e15 m or a speed beyond 1e30 m/s): the lattice is then exactly as before the call
/// (the pending forces included: `softshell_lattice_clear_forces` drops them) and the message
/// names the particle and the setting to change.
///
/// # Safety
/// `lattice` must be NULL or a live lattice; `out_stats` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_step(
    lattice: *mut SoftshellLattice,
    out_stats: *mut SoftshellLatticeStats,
) -> SoftshellStatus {
    handle_call("softshell_lattice_step", lattice, "lattice", |h| {
        let out_stats = if out_stats.is_null() { None } else { Some(out_arg(out_stats, "out_stats")?) };
        let stats = h.lattice.step()?;
        if let Some(out) = out_stats {
            // SAFETY: checked by out_arg.
            unsafe { write_out(out, SoftshellLatticeStats::from(stats)) };
        }
        Ok(())
    })
}

fn read_count(lattice: *const SoftshellLattice, name: &str, count: impl FnOnce(&Lattice) -> usize) -> usize {
    value_call(name, 0, || {
        // SAFETY: the caller promises a live lattice or NULL.
        match unsafe { arg_ref(lattice, "lattice") } {
            Ok(h) if !h.poisoned => count(&h.lattice),
            _ => 0,
        }
    })
}

/// Number of particles (sites of the mask that are not holes); 0 for NULL.
///
/// # Safety
/// `lattice` must be NULL or a live lattice.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_particle_count(lattice: *const SoftshellLattice) -> usize {
    read_count(lattice, "softshell_lattice_particle_count", |l| l.particle_count())
}

/// Number of triangles of the triangulated grid (`softshell_lattice_copy_triangles`): two per
/// lattice cell whose four corners are particles, one per cell with three; 0 for NULL.
///
/// # Safety
/// `lattice` must be NULL or a live lattice.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_triangle_count(lattice: *const SoftshellLattice) -> usize {
    read_count(lattice, "softshell_lattice_triangle_count", |l| l.layout().triangle_count())
}

/// Heap bytes the lattice holds (the worker threads and the thread pool's own bookkeeping, inside
/// rayon, excluded); 0 for NULL. Storage for region damping, pins and forces exists only when
/// they are used; once made it is kept (unpinning every particle or a step clearing the forces
/// does not release it), so forces applied every step allocate nothing after the first. A step
/// allocates nothing (its scratch is made with the lattice; on more than one thread the thread
/// pool's job queue takes a block about once every 32 steps: a step hands it two jobs).
///
/// # Safety
/// `lattice` must be NULL or a live lattice.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_memory_bytes(lattice: *const SoftshellLattice) -> usize {
    read_count(lattice, "softshell_lattice_memory_bytes", |l| {
        std::mem::size_of::<SoftshellLattice>() + l.memory_bytes()
    })
}

/// Writes to `*out_index` the number of the particle at (`column`, `row`), the index into
/// positions and triangles. Returns `SOFTSHELL_STATUS_INVALID_ARGUMENT` when (column, row) is
/// outside the lattice or a hole (then nothing is written).
///
/// # Safety
/// `lattice` must be NULL or a live lattice; `out_index` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_particle_index(
    lattice: *const SoftshellLattice,
    column: u32,
    row: u32,
    out_index: *mut u32,
) -> SoftshellStatus {
    handle_read("softshell_lattice_particle_index", lattice, "lattice", |h| {
        let out_index = out_arg(out_index, "out_index")?;
        let index = h.lattice.layout().particle(column, row)?;
        // SAFETY: checked by out_arg.
        unsafe { write_out(out_index, index as u32) };
        Ok(())
    })
}

fn copy_vectors(
    function: &str,
    lattice: *const SoftshellLattice,
    out: *mut f32,
    capacity: usize,
    out_len: *mut usize,
    fill: impl FnOnce(&Lattice, &mut [f32]),
) -> SoftshellStatus {
    handle_read(function, lattice, "lattice", |h| {
        let len = 3 * h.lattice.particle_count();
        // SAFETY: the exported functions forward the caller's promise about the buffer.
        unsafe { copy_out(len, out, capacity, out_len, |dst| fill(&h.lattice, dst)) }
    })
}

/// Copies the positions (x,y,z per particle in particle order, 3 * particle count floats, m)
/// into `out`. If `out` is NULL or `capacity` (in floats) is too small, returns
/// `SOFTSHELL_STATUS_BUFFER_TOO_SMALL`, writes the number of floats needed to `*out_len` and
/// nothing else. On success `*out_len` is the number of floats written. Returns
/// `SOFTSHELL_STATUS_NULL_ARGUMENT`, writing nothing, when the lattice or `out_len` is NULL.
///
/// # Safety
/// `lattice` must be NULL or a live lattice; `out` NULL or `capacity` writable floats;
/// `out_len` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_copy_positions(
    lattice: *const SoftshellLattice,
    out: *mut f32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    copy_vectors("softshell_lattice_copy_positions", lattice, out, capacity, out_len, |l, dst| l.copy_positions(dst))
}

/// Copies the velocities (m/s, 3 floats per particle) into `out`; buffer rules as
/// `softshell_lattice_copy_positions`.
///
/// # Safety
/// As `softshell_lattice_copy_positions`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_copy_velocities(
    lattice: *const SoftshellLattice,
    out: *mut f32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    copy_vectors("softshell_lattice_copy_velocities", lattice, out, capacity, out_len, |l, dst| l.copy_velocities(dst))
}

/// Copies the goal positions of the current state (m, 3 floats per particle: where shape
/// matching pulls each particle, SPEC 3) into `out`; buffer rules as
/// `softshell_lattice_copy_positions`. Costs about one step; for inspection and debugging.
///
/// # Safety
/// As `softshell_lattice_copy_positions`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_copy_goals(
    lattice: *const SoftshellLattice,
    out: *mut f32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    copy_vectors("softshell_lattice_copy_goals", lattice, out, capacity, out_len, |l, dst| l.copy_goals(dst))
}

/// Copies the triangulated grid (a,b,c particle indices per triangle, 3 * triangle count
/// uint32_t, counter-clockwise seen from +y at rest) into `out`, e.g. to write the sheet as a
/// mesh. Buffer rules as `softshell_lattice_copy_positions` (capacity and `*out_len` count
/// uint32_t). The triangles never change, so one copy serves every frame.
///
/// # Safety
/// `lattice` must be NULL or a live lattice; `out` NULL or `capacity` writable uint32_t;
/// `out_len` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_copy_triangles(
    lattice: *const SoftshellLattice,
    out: *mut u32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    handle_read("softshell_lattice_copy_triangles", lattice, "lattice", |h| {
        let layout = h.lattice.layout();
        // SAFETY: the caller promises the buffer.
        unsafe {
            copy_out(3 * layout.triangle_count(), out, capacity, out_len, |dst| {
                write_triples(dst, layout.triangles().iter().copied())
            })
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn def_default_carries_the_cookie_and_valid_settings() {
        let def = softshell_lattice_def_default();
        assert_eq!(def.internal_cookie, LATTICE_DEF_COOKIE);
        let mut out = std::ptr::null_mut();
        // SAFETY: live locals.
        let status = unsafe { softshell_lattice_new(&def, std::ptr::null(), &mut out) };
        if cfg!(feature = "lattice") {
            assert_eq!(status, SoftshellStatus::Ok);
        } else {
            assert_eq!(status, SoftshellStatus::Unsupported);
        }
        // SAFETY: made above or NULL.
        unsafe { softshell_lattice_free(out) };
    }
}
