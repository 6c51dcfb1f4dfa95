//! The shell simulator: state, the step of SPEC 1.1 and its measurements.
//!
//! Evolving state is structure-of-arrays (x, v, inverse mass, the predicted positions p, one λ
//! array per constraint kind); rest data lives in [`super::constraints`]. Nothing is allocated
//! in a step: every scratch array is sized when the shell (or a region) is made.

// NaN must fail every guard below, so comparisons are written `!(x > limit)` on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

use std::time::Instant;

use glam::Vec3;

use super::constraints::{Anisotropics, Bendings, Edges, Membranes, Region};
use super::exec::{REDUCE_CHUNK, Shared, chunk_partials, for_range};
use super::project::membrane_energy_at;
use super::settings::{AnisotropySettings, BendingKind, MAX_SUBSTEPS, MIN_TIME_STEP, ShellSettings, SolverKind};
use crate::collision::{ContactCounts, SelfContact};
use crate::error::{Error, ErrorKind, Result};
use crate::material::{Lame, Material};
use crate::mesh::{CurvatureKind, Topology, TriMesh, bounding_box, require_closed_oriented_solid, vertex_curvature};
use crate::parallel::WorkerPool;

/// What one step did (SPEC 4: error measures beside the time).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ShellStats {
    /// Steps taken so far.
    pub step: u64,
    /// Simulated time, s.
    pub time: f64,
    /// Enclosed volume, m³.
    pub volume: f64,
    /// V / V0.
    pub volume_ratio: f64,
    /// True once the volume ratio fell below the stop ratio.
    pub finished: bool,
    /// Largest relative constraint violation after the last iteration (see `SoftshellShellStats`).
    pub residual: f64,
    /// Membrane energy, J.
    pub elastic_energy: f64,
    /// Bending energy, J.
    pub bending_energy: f64,
    /// Anisotropic energy, J.
    pub anisotropic_energy: f64,
    /// Collision candidate pairs (0 until the collision stage exists).
    pub collision_candidates: u64,
    /// Exact CCD tests run.
    pub ccd_tests: u64,
    /// Contacts resolved.
    pub contacts: u64,
    /// Wall time of the step, s.
    pub step_seconds: f64,
    /// True when the volume ratio changed by less than 1e-5 per step for the last 60 steps without reaching the stop ratio (SPEC 1.7).
    pub stalled: bool,
}

/// Per-step change of the volume ratio below which a step counts as quiet.
pub(crate) const STALL_TOLERANCE: f64 = 1e-5;
/// Quiet steps in a row after which the contraction is reported stalled.
pub(crate) const STALL_STEPS: u32 = 60;

/// Above this many bounding-box diagonals moved in one substep a vertex is taken as diverged:
/// no contraction moves a surface that far, only a blow-up does.
const DIVERGED_DIAGONALS: f32 = 2.0;

/// Largest bounding-box diagonal of a shell's mesh, m. The solver works in f32 and squares
/// lengths and areas (|e1 x e2|² grows as the fourth power of the size, past f32's range near
/// 1e9 m; the energies multiply that by moduli up to 1e12): a mesh under 1e6 m keeps every such
/// product finite, a larger one is refused with the advice to rescale it.
pub(crate) const MAX_DIAGONAL: f32 = 1e6;

/// A step in which more than 1/this of the triangles' normals turn by more than 90 degrees is
/// taken as an inversion (a surface folding through itself), not as motion.
const INVERTED_FRACTION_DENOMINATOR: usize = 4;

/// What the collision stage did in the last step, in more detail than [`ShellStats`] (for
/// benchmarks): the counts summed over the substeps and the stage's wall time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CollisionReport {
    /// Candidates, filter survivors, exact tests, contacts, fail-safe reverts, rebuilds.
    pub counts: ContactCounts,
    /// Wall time of the collision stage in the step, s.
    pub seconds: f64,
}

/// Per-step constants of the projections.
#[derive(Clone, Copy)]
pub(super) struct Coefficients {
    pub(super) solver: SolverKind,
    pub(super) material: Material,
    /// Lamé parameters at unit Young's modulus (the XPBD split W = k Ŵ).
    pub(super) lame: Lame,
    /// α̃ of the membrane: 1/(E t h²).
    pub(super) alpha_membrane: f32,
    /// E t h²·kB (bending α̃ = 1/(kb_scale · stencil area)).
    pub(super) bending_scale: f32,
    pub(super) bending_coefficient: f32,
    pub(super) keep_rest: bool,
    /// t h², for the anisotropic α̃ = 1/(μ t h²).
    pub(super) aniso_scale: f32,
}

/// The contraction simulator.
pub struct Shell {
    settings: ShellSettings,
    pool: WorkerPool,
    state: State,
}

pub(super) struct State {
    pub(super) triangles: Vec<[u32; 3]>,
    pub(super) vertex_face_offsets: Vec<u32>,
    pub(super) vertex_faces: Vec<u32>,
    pub(super) rest: Vec<Vec3>,
    pub(super) x: Vec<Vec3>,
    pub(super) v: Vec<Vec3>,
    pub(super) p: Vec<Vec3>,
    /// What f32 rounding lost from x (the position is x + x_lo): with many substeps the
    /// displacement of one substep can be below half an ulp of x.
    pub(super) x_lo: Vec<Vec3>,
    /// The same for p during a substep (written by the projections, see `add_compensated`).
    pub(super) p_lo: Vec<Vec3>,
    pub(super) x_lo_backup: Vec<Vec3>,
    pub(super) inv_mass: Vec<f32>,
    pub(super) x_backup: Vec<Vec3>,
    pub(super) v_backup: Vec<Vec3>,
    pub(super) membranes: Membranes,
    /// Edge-distance constraints: only for the distance solver.
    pub(super) edges: Edges,
    pub(super) lambda_membrane: Vec<f32>,
    pub(super) bendings: Bendings,
    pub(super) lambda_bending: Vec<f32>,
    pub(super) regions: Vec<Region>,
    pub(super) anisotropics: Option<Anisotropics>,
    pub(super) lambda_aniso: Vec<f32>,
    /// Reduction scratch, one slot per REDUCE_CHUNK items of the largest array.
    pub(super) partials: Vec<[f64; 3]>,
    pub(super) rest_volume: f64,
    pub(super) diagonal: f32,
    /// Mean rest edge length, for the stability advice.
    pub(super) mean_edge: f32,
    /// Consecutive steps whose volume ratio changed by less than STALL_TOLERANCE.
    pub(super) quiet_steps: u32,
    pub(super) stats: ShellStats,
    /// Self-contact (SPEC 1.6): BVHs and contact scratch, only when collisions are on.
    pub(super) contact: Option<SelfContact>,
    pub(super) collision_report: CollisionReport,
}

impl Shell {
    /// Makes a shell from a closed, consistently oriented, non-degenerate mesh (refused with
    /// `InvalidMesh` naming the first offending edge or triangle). Settings are assumed
    /// validated (the C boundary does it).
    pub fn new(mesh: &TriMesh, topology: &Topology, settings: ShellSettings) -> Result<Self> {
        require_closed_oriented_solid(mesh, topology, "the shell")?;
        let extent = bounding_box(mesh.positions()).diagonal();
        if !(extent <= MAX_DIAGONAL) {
            return Err(Error::invalid_mesh(format!(
                "the shell's mesh is {extent:e} m across (its bounding-box diagonal); at most {MAX_DIAGONAL:e} m is \
                 supported (the f32 solver squares lengths and areas): scale the mesh down and the pressure and \
                 moduli with it"
            )));
        }
        let pool = WorkerPool::new(settings.threads)?;
        let rest = mesh.positions().to_vec();
        let triangles = mesh.triangles().to_vec();
        let n = rest.len();
        let membranes = Membranes::build(&rest, &triangles, settings.material == Material::Linear)?;
        let edges =
            if settings.solver == SolverKind::PbdDistance { Edges::build(&rest, topology) } else { Edges::default() };
        // kB = 0 is no bending either: no stencils (half of a shell's memory without collisions)
        // and no work for them.
        let mut bendings = match settings.bending {
            BendingKind::None => Bendings::default(),
            _ if settings.bending_coefficient == 0.0 => Bendings::default(),
            kind => Bendings::build(&rest, &triangles, topology, kind == BendingKind::IsometricRest),
        };
        // Lumped masses: a third of the area of each face around a vertex, times ρ t (SPEC 1.1).
        let mut mass = vec![0.0f64; n];
        for t in &triangles {
            let [a, b, c] = t.map(|v| rest[v as usize].as_dvec3());
            let area = 0.5 * (b - a).cross(c - a).length();
            for &v in t {
                mass[v as usize] += area / 3.0 * settings.density as f64 * settings.thickness as f64;
            }
        }
        // A vertex mass whose inverse f32 cannot hold (below about 3e-39 kg) made a shell that
        // was accepted and could never step (found by review).
        if let Some(v) = (0..n).find(|&v| mass[v] > 0.0 && !((1.0 / mass[v]) as f32).is_finite()) {
            return Err(Error::invalid_argument(format!(
                "vertex {v} gets a mass of {:e} kg (a third of its faces' area times density {:e} kg/m^3 and \
                 thickness {:e} m), too small for the f32 solver (its inverse overflows below about 3e-39 kg): \
                 raise density or thickness, or scale the mesh up",
                mass[v], settings.density, settings.thickness
            )));
        }
        let inv_mass: Vec<f32> = mass.iter().map(|&m| if m > 0.0 { (1.0 / m) as f32 } else { 0.0 }).collect();
        bendings.set_inverse_masses(&inv_mass);
        let mut membranes = membranes;
        // The distance solver projects edges only: the membranes are kept for the energy report,
        // without the per-triangle inverse masses of their projection (12 bytes a triangle).
        if settings.solver != SolverKind::PbdDistance {
            membranes.set_inverse_masses(&inv_mass);
        }
        let xpbd = settings.solver == SolverKind::Xpbd;
        let largest = n.max(triangles.len()).max(bendings.len()).max(edges.len());
        let rest_volume = crate::mesh::signed_volume(&rest, &triangles);
        let diagonal = bounding_box(&rest).diagonal();
        let mean_edge =
            (topology.edges.iter().map(|&[a, b]| (rest[b as usize] - rest[a as usize]).length() as f64).sum::<f64>()
                / topology.edges.len().max(1) as f64) as f32;
        let stats = ShellStats { volume: rest_volume, volume_ratio: 1.0, ..Default::default() };
        // SPEC 5: no BVH when collisions are off.
        let mut contact = settings.collisions.then(|| SelfContact::new(&rest, &topology.edges, &triangles));
        // SPEC 1.6: a thickness above the rest gap of two primitives sharing no vertex makes the
        // contact stage push them apart at once, every step (the shell inflates, or diverges).
        let delta = settings.collision_thickness as f64 * diagonal as f64;
        if let Some(contact) = contact.as_mut().filter(|_| delta > 0.0) {
            if let Some((kind, i, j)) = contact.pair_within_at_rest(&rest, delta) {
                let what = if kind == 0 {
                    format!("vertex {i} and triangle {j}")
                } else {
                    let (a, b) = (topology.edges[i as usize], topology.edges[j as usize]);
                    format!("edges {}-{} and {}-{}", a[0], a[1], b[0], b[1])
                };
                return Err(Error::invalid_argument(format!(
                    "`collision_thickness` = {} (delta = {delta:e} m, relative to the bounding-box diagonal \
                     {diagonal:e} m) is larger than the rest distance of {what}, which share no vertex: the contact \
                     stage would push them apart from the first step; use a smaller collision_thickness",
                    settings.collision_thickness
                )));
            }
        }
        let state = State {
            vertex_face_offsets: topology.vertex_face_offsets.clone(),
            vertex_faces: topology.vertex_faces.clone(),
            x: rest.clone(),
            v: vec![Vec3::ZERO; n],
            p: rest.clone(),
            x_lo: vec![Vec3::ZERO; n],
            p_lo: vec![Vec3::ZERO; n],
            x_lo_backup: vec![Vec3::ZERO; n],
            x_backup: vec![Vec3::ZERO; n],
            v_backup: vec![Vec3::ZERO; n],
            inv_mass,
            lambda_membrane: if xpbd { vec![0.0; membranes.len()] } else { Vec::new() },
            lambda_bending: if xpbd { vec![0.0; bendings.len()] } else { Vec::new() },
            membranes,
            edges,
            bendings,
            regions: Vec::new(),
            anisotropics: None,
            lambda_aniso: Vec::new(),
            partials: vec![[0.0; 3]; largest.div_ceil(REDUCE_CHUNK)],
            rest_volume,
            diagonal,
            mean_edge,
            quiet_steps: 0,
            stats,
            contact,
            collision_report: CollisionReport::default(),
            rest,
            triangles,
        };
        Ok(Self { settings, pool, state })
    }

    /// The settings the shell was made with.
    pub fn settings(&self) -> &ShellSettings {
        &self.settings
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.state.x.len()
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.state.triangles.len()
    }

    /// Current positions.
    pub fn positions(&self) -> &[Vec3] {
        &self.state.x
    }

    /// Stats of the last step (or of the rest state before any step).
    pub fn last_stats(&self) -> ShellStats {
        self.state.stats
    }

    /// Adds an anisotropic region on `faces` (SPEC 1.5). Faces must be in range and distinct
    /// (checked here; nothing changes on error). Rebuilds the anisotropic constraints and their
    /// colouring (not a per-step cost).
    pub fn add_anisotropic_region(&mut self, faces: &[u32], settings: AnisotropySettings) -> Result<()> {
        let count = self.state.triangles.len();
        if faces.is_empty() {
            return Err(Error::invalid_argument("`faces` is empty: a region needs at least one face"));
        }
        let mut seen = vec![false; count];
        for (i, &f) in faces.iter().enumerate() {
            if f as usize >= count {
                return Err(Error::invalid_argument(format!(
                    "faces[{i}] = {f} is out of range: the shell has {count} triangles"
                )));
            }
            if std::mem::replace(&mut seen[f as usize], true) {
                return Err(Error::invalid_argument(format!("faces[{i}] = {f} appears twice in the region")));
            }
        }
        let s = &mut self.state;
        s.regions.push(Region { faces: faces.to_vec(), settings });
        let aniso = Anisotropics::build(&s.rest, &s.triangles, &s.regions);
        let largest = s.x.len().max(s.triangles.len()).max(s.bendings.len()).max(s.edges.len()).max(aniso.len());
        s.partials.resize(largest.div_ceil(REDUCE_CHUNK), [0.0; 3]);
        s.lambda_aniso = if self.settings.solver == SolverKind::Xpbd { vec![0.0; aniso.len()] } else { Vec::new() };
        s.anisotropics = Some(aniso);
        Ok(())
    }

    /// Heap and handle bytes held by the shell (what the scene uses and nothing else).
    pub fn memory_bytes(&self) -> usize {
        fn b<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        let s = &self.state;
        std::mem::size_of::<Shell>()
            + self.pool.memory_bytes()
            + b(&s.triangles)
            + b(&s.vertex_face_offsets)
            + b(&s.vertex_faces)
            + b(&s.rest)
            + b(&s.x)
            + b(&s.v)
            + b(&s.p)
            + b(&s.x_lo)
            + b(&s.p_lo)
            + b(&s.x_lo_backup)
            + b(&s.inv_mass)
            + b(&s.x_backup)
            + b(&s.v_backup)
            + s.membranes.memory_bytes()
            + s.edges.memory_bytes()
            + b(&s.lambda_membrane)
            + s.bendings.memory_bytes()
            + b(&s.lambda_bending)
            + b(&s.regions)
            + s.regions.iter().map(|r| b(&r.faces)).sum::<usize>()
            + s.anisotropics.as_ref().map_or(0, |a| a.memory_bytes())
            + b(&s.lambda_aniso)
            + b(&s.partials)
            + s.contact.as_ref().map_or(0, |c| c.memory_bytes())
    }

    /// The collision stage's detailed counts and time in the last step (zero without collisions).
    pub fn collision_report(&self) -> CollisionReport {
        self.state.collision_report
    }

    /// Bytes of anisotropic storage (0 until a region is added).
    pub fn anisotropy_bytes(&self) -> usize {
        self.state.anisotropics.as_ref().map_or(0, |a| a.memory_bytes())
    }

    /// Advances one step (SPEC 1.1), `substeps` times `h/substeps`. With `measure`, the energies
    /// and the residual are evaluated after the last iteration (one extra pass over the
    /// constraints); otherwise they keep their last values. After the shell finished (volume
    /// ratio below the stop ratio) a step does nothing. A step that diverges is rolled back and
    /// returns `Unstable`.
    pub fn step(&mut self, measure: bool) -> Result<ShellStats> {
        if self.state.stats.finished {
            let mut stats = self.state.stats;
            stats.step_seconds = 0.0;
            return Ok(stats);
        }
        let start = Instant::now();
        let settings = self.settings;
        let parallel = self.pool.threads() > 1;
        let previous_stats = self.state.stats;
        let previous_ratio = previous_stats.volume_ratio;
        let state = &mut self.state;
        let outcome = self.pool.install(|| state.advance(&settings, parallel, measure));
        let s = &mut self.state;
        match outcome {
            Ok(()) => {
                let change = (s.stats.volume_ratio - previous_ratio).abs();
                s.quiet_steps = if change < STALL_TOLERANCE { s.quiet_steps.saturating_add(1) } else { 0 };
                s.stats.step += 1;
                s.stats.time += settings.time_step as f64;
                s.stats.finished =
                    settings.stop_volume_ratio > 0.0 && s.stats.volume_ratio < settings.stop_volume_ratio as f64;
                s.stats.stalled = !s.stats.finished && s.quiet_steps >= STALL_STEPS;
                s.stats.step_seconds = start.elapsed().as_secs_f64();
                Ok(s.stats)
            }
            Err(error) => {
                s.x.copy_from_slice(&s.x_backup);
                s.v.copy_from_slice(&s.v_backup);
                s.p.copy_from_slice(&s.x_backup);
                s.x_lo.copy_from_slice(&s.x_lo_backup);
                s.stats = previous_stats;
                Err(error)
            }
        }
    }

    /// Elastic (membrane) energy of each mesh triangle, J.
    pub fn face_energy(&self) -> Vec<f32> {
        let s = &self.state;
        let coeff = coefficients(&self.settings, self.settings.time_step);
        let k = self.settings.youngs_modulus * self.settings.thickness;
        let mut out = vec![0.0f32; s.triangles.len()];
        for i in 0..s.membranes.len() {
            let (w, _) = membrane_energy_at(&s.membranes, i, &s.x, &coeff);
            // Saturated at f32::MAX rather than infinite (a huge mesh of a stiff material).
            out[s.membranes.face[i] as usize] = (k as f64 * w as f64).min(f32::MAX as f64) as f32;
        }
        out
    }

    /// Per-vertex curvature of the current shape.
    pub fn vertex_curvature(&self, kind: CurvatureKind) -> Vec<f64> {
        vertex_curvature(&self.state.x, &self.state.triangles, None, kind)
    }

    /// The mesh's triangles (never change).
    pub(crate) fn triangles(&self) -> &[[u32; 3]] {
        &self.state.triangles
    }
}

pub(super) fn coefficients(settings: &ShellSettings, h: f32) -> Coefficients {
    let k = settings.youngs_modulus * settings.thickness;
    Coefficients {
        solver: settings.solver,
        material: settings.material,
        lame: Lame::from_young_poisson(1.0, settings.poisson_ratio),
        // Clamped: a modulus so small that 1/(k h²) overflows must not turn α̃ λ into inf·0.
        alpha_membrane: (1.0 / (k * h * h)).min(f32::MAX),
        bending_scale: k * settings.bending_coefficient * h * h,
        bending_coefficient: settings.bending_coefficient,
        keep_rest: settings.bending == BendingKind::IsometricRest,
        aniso_scale: settings.thickness * h * h,
    }
}

/// How a def with this `time_step` gets substeps of at most `substep` (s): more substeps up to
/// [`MAX_SUBSTEPS`], else a shorter step with that many, never a step below [`MIN_TIME_STEP`]
/// (reviews saw "Substeps >= 4000" and "a time_step of at most 7.1e-7 s" advised, which the def
/// refuses).
fn substeps_advice(time_step: f32, substep: f32) -> String {
    // (Less a hair: a quarter of a substep must read as exactly four times the substeps.)
    let substeps = (time_step / substep * (1.0 - 1e-6)).ceil().max(1.0);
    if substeps <= MAX_SUBSTEPS as f32 {
        format!("Substeps >= {substeps} (a substep of at most {substep:.3e} s)")
    } else if substep * MAX_SUBSTEPS as f32 >= MIN_TIME_STEP {
        format!(
            "A time_step of at most {:.3e} s with substeps = {MAX_SUBSTEPS} (a substep of at most {substep:.3e} s)",
            substep * MAX_SUBSTEPS as f32
        )
    } else {
        format!(
            "No allowed step makes substeps of {substep:.3e} s (time_step >= {MIN_TIME_STEP:e} s with at most \
             {MAX_SUBSTEPS} substeps)"
        )
    }
}

impl State {
    fn advance(&mut self, settings: &ShellSettings, parallel: bool, measure: bool) -> Result<()> {
        self.x_backup.copy_from_slice(&self.x);
        self.v_backup.copy_from_slice(&self.v);
        self.x_lo_backup.copy_from_slice(&self.x_lo);
        let h = settings.time_step / settings.substeps as f32;
        let coeff = coefficients(settings, h);
        let mut report = CollisionReport::default();
        for substep in 0..settings.substeps {
            self.predict(settings.pressure, h, parallel);
            self.lambda_membrane.fill(0.0);
            self.lambda_bending.fill(0.0);
            self.lambda_aniso.fill(0.0);
            if coeff.keep_rest && coeff.bending_coefficient > 0.0 {
                self.update_bending_targets(parallel);
            }
            for _ in 0..settings.iterations {
                if settings.solver == SolverKind::PbdDistance {
                    self.project_edges(parallel);
                } else {
                    self.project_membranes(&coeff, parallel);
                }
                if coeff.bending_coefficient > 0.0 {
                    self.project_bendings(&coeff, parallel);
                }
                self.project_anisotropics(&coeff, parallel);
            }
            // SPEC 1.1 step 3: collisions over x_t -> p, between the constraint sweeps and the
            // velocity update.
            if self.contact.is_some() {
                // A diverged p would give the collision stage infinite boxes: fail first.
                self.check_motion(settings, parallel)?;
                let start = Instant::now();
                let counts = self.resolve_collisions(settings, h);
                report.counts.add(&counts);
                report.seconds += start.elapsed().as_secs_f64();
            }
            self.update_velocities(settings, h, parallel)?;
            if let Some(contact) = &self.contact {
                contact.limit_velocities(&mut self.v, &self.inv_mass);
            }
            if measure && substep + 1 == settings.substeps {
                self.measure(settings, &coeff, parallel);
            }
        }
        let volume = self.volume(parallel);
        if !volume.is_finite() {
            return Err(self.unstable(settings, "the enclosed volume became non-finite"));
        }
        // SPEC 4: a shell turned inside out is a divergence, not a result.
        if !(volume / self.rest_volume > 0.0) {
            let what = format!("the shell turned inside out (V/V0 = {:.3})", volume / self.rest_volume);
            return Err(self.inverted(settings, &what));
        }
        let flipped = self.flipped_normals();
        if flipped * INVERTED_FRACTION_DENOMINATOR > self.triangles.len() {
            let what = format!(
                "{flipped} of {} triangle normals turned around in one step (the surface folded through itself)",
                self.triangles.len()
            );
            return Err(self.inverted(settings, &what));
        }
        self.stats.volume = volume;
        self.stats.volume_ratio = volume / self.rest_volume;
        self.stats.collision_candidates = report.counts.candidates;
        self.stats.ccd_tests = report.counts.ccd_tests;
        self.stats.contacts = report.counts.contacts;
        self.collision_report = report;
        Ok(())
    }

    /// SPEC 1.6, the collision stage: finds the vertex-face and edge-edge pairs that come closer
    /// than δ = collision_thickness × bounding-box diagonal over x -> p and projects them apart,
    /// on `p`, to the side they came from (see `collision::self_contact`).
    fn resolve_collisions(&mut self, settings: &ShellSettings, h: f32) -> ContactCounts {
        let Some(contact) = self.contact.as_mut() else { return ContactCounts::default() };
        let delta = settings.collision_thickness as f64 * self.diagonal as f64;
        contact.resolve(&self.x, &mut self.p, &self.inv_mass, delta, h)
    }

    /// SPEC 1.1 step 1 with the pressure force of SPEC 1.2:
    /// `f_i = -P Σ_j (1/3) A_j n_j`, `v* = v + h w f`, `p = x + h v*`.
    fn predict(&mut self, pressure: f32, h: f32, parallel: bool) {
        let (x, x_lo, tris, offsets, faces, w) =
            (&self.x, &self.x_lo, &self.triangles, &self.vertex_face_offsets, &self.vertex_faces, &self.inv_mass);
        let v = Shared::new(&mut self.v);
        let p = Shared::new(&mut self.p);
        let p_lo = Shared::new(&mut self.p_lo);
        // (1/3) A n = (1/6) (x_b - x_a) × (x_c - x_a).
        let scale = -pressure / 6.0;
        for_range(parallel, 0, x.len(), |i| {
            let mut f = Vec3::ZERO;
            for &face in &faces[offsets[i] as usize..offsets[i + 1] as usize] {
                let t = &tris[face as usize];
                let (a, b, c) = (x[t[0] as usize], x[t[1] as usize], x[t[2] as usize]);
                f += (b - a).cross(c - a);
            }
            // SAFETY: each iteration touches only index i.
            unsafe {
                let vi = v.get(i) + f * (scale * h * w[i]);
                v.set(i, vi);
                // p = x + x_lo + h v*, keeping what rounding loses (Fast2Sum).
                let dx = vi * h + x_lo[i];
                let pi = x[i] + dx;
                p.set(i, pi);
                p_lo.set(i, dx - (pi - x[i]));
            }
        });
    }

    /// The divergence test of a substep: every vertex's move `p - x` finite and under
    /// `DIVERGED_DIAGONALS` bounding-box diagonals. Run before the collision stage too, whose
    /// bounding boxes must be finite.
    fn check_motion(&mut self, settings: &ShellSettings, parallel: bool) -> Result<()> {
        let n = self.x.len();
        let limit = (DIVERGED_DIAGONALS * self.diagonal).powi(2);
        let (x, pp) = (&self.x, &self.p);
        let partials = &mut self.partials[..n.div_ceil(REDUCE_CHUNK)];
        chunk_partials(parallel, n, partials, |start, end| {
            let mut worst = 0.0f64;
            for i in start..end {
                let d = (pp[i] - x[i]).length_squared();
                // NaN compares false: map it to infinity so it is caught.
                worst = worst.max(if d.is_finite() { d as f64 } else { f64::INFINITY });
            }
            [worst, 0.0, 0.0]
        });
        let worst = partials.iter().fold(0.0f64, |m, s| m.max(s[0]));
        if !(worst <= limit as f64) {
            let what = if worst.is_finite() {
                format!(
                    "a vertex moved {:.3e} m in one substep ({:.1} times the mesh's bounding-box diagonal)",
                    worst.sqrt(),
                    worst.sqrt() / self.diagonal as f64
                )
            } else {
                "a vertex position became NaN or infinite".to_owned()
            };
            return Err(self.unstable(settings, &what));
        }
        Ok(())
    }

    /// SPEC 1.1 step 5: `v = (p - x)/h` (damped), `x = p`; refuses a non-finite or runaway
    /// vertex before anything is committed to x.
    fn update_velocities(&mut self, settings: &ShellSettings, h: f32, parallel: bool) -> Result<()> {
        self.check_motion(settings, parallel)?;
        let n = self.x.len();
        let damp = (1.0 - settings.damping * h).max(0.0);
        let inv_h = 1.0 / h;
        let (p, p_lo) = (&self.p, &self.p_lo);
        let xs = Shared::new(&mut self.x);
        let lo = Shared::new(&mut self.x_lo);
        let vs = Shared::new(&mut self.v);
        for_range(parallel, 0, n, |i| {
            // SAFETY: each iteration touches only index i.
            unsafe {
                // v = ((p + p_lo) - (x + x_lo)) / h: p - x is exact for nearby values, so a
                // displacement below half an ulp of x still makes a velocity (issue: many
                // substeps stalled in f32). x = p exactly (what the collision stage checked);
                // the rest stays in x_lo.
                let dx = (p[i] - xs.get(i)) + (p_lo[i] - lo.get(i));
                vs.set(i, dx * (inv_h * damp));
                xs.set(i, p[i]);
                lo.set(i, p_lo[i]);
            }
        });
        Ok(())
    }

    /// The divergence error with an estimate of what would be stable. From rest the pressure
    /// alone moves a vertex by `T² P / (ρ t)` in a step of length T (substeps do not change the
    /// acceleration); keeping that below a tenth of the mean rest edge length L needs
    /// `T <= sqrt(0.1 L ρ t / P)` or `P <= 0.1 L ρ t / T²`. When the pressure is not the cause,
    /// four times more substeps is suggested.
    fn unstable(&self, settings: &ShellSettings, what: &str) -> Error {
        let step = settings.time_step;
        let areal_mass = settings.density * settings.thickness;
        let budget = 0.1 * self.mean_edge * areal_mass;
        let pressure = settings.pressure.abs();
        let stable_step = if pressure > 0.0 { (budget / pressure).sqrt() } else { f32::INFINITY };
        let substep = step / settings.substeps as f32;
        let advice = if stable_step < substep {
            // As a def allows it: more substeps, else a shorter step with the most substeps,
            // never below the shortest step (a review saw "a time_step of at most 7.1e-7 s").
            format!(
                "The pressure alone moves a vertex {:.3e} m per substep against a mean edge of {:.3e} m: {} or a \
                 pressure of at most {:.3e} Pa would be stable.",
                substep * substep * pressure / areal_mass,
                self.mean_edge,
                substeps_advice(step, stable_step),
                budget / (substep * substep)
            )
        } else {
            // Four times shorter substeps; with XPBD also a softer material (PBD's projections do
            // not read Young's modulus).
            let shorter = substeps_advice(step, substep / 4.0);
            if settings.solver == SolverKind::Xpbd {
                format!("{shorter} or a lower Young's modulus than {} Pa would be stable.", settings.youngs_modulus)
            } else {
                format!("{shorter} would be stable (the PBD solvers do not read Young's modulus).")
            }
        };
        Error::new(
            ErrorKind::Unstable,
            format!("the shell diverged in step {}: {what}; the step was rolled back. {advice}", self.stats.step + 1),
        )
    }

    /// Triangles whose normal points against its direction at the start of the step.
    fn flipped_normals(&self) -> usize {
        let (x, old) = (&self.x, &self.x_backup);
        self.triangles
            .iter()
            .filter(|t| {
                let [a, b, c] = t.map(|v| v as usize);
                let n0 = (old[b] - old[a]).cross(old[c] - old[a]);
                let n1 = (x[b] - x[a]).cross(x[c] - x[a]);
                n0.dot(n1) < 0.0
            })
            .count()
    }

    /// The inversion error: [`State::unstable`]'s advice plus what prevents an inversion.
    fn inverted(&self, settings: &ShellSettings, what: &str) -> Error {
        let base = self.unstable(settings, what);
        let hint = if settings.collisions {
            " A smaller time_step or more substeps keep the collision stage ahead of the motion."
        } else {
            " Turn collisions on (the shell then cannot pass through itself), or keep stop_volume_ratio above 0 so \
             the run ends first; a smaller anisotropic inward_push also helps."
        };
        Error::new(ErrorKind::Unstable, format!("{}{hint}", base.message))
    }

    /// SPEC 1.7: V = 1/6 Σ x_a · (x_b × x_c) about the vertex centroid, in f64, summed in fixed
    /// chunks so the result does not depend on the thread count.
    fn volume(&mut self, parallel: bool) -> f64 {
        let (x, tris) = (&self.x, &self.triangles);
        let n = x.len();
        let parts = &mut self.partials[..n.div_ceil(REDUCE_CHUNK)];
        chunk_partials(parallel, n, parts, |s, e| {
            let c = x[s..e].iter().fold(glam::DVec3::ZERO, |acc, p| acc + p.as_dvec3());
            [c.x, c.y, c.z]
        });
        let sum = parts.iter().fold([0.0; 3], |a, s| [a[0] + s[0], a[1] + s[1], a[2] + s[2]]);
        let centre = glam::DVec3::from_array(sum) / n as f64;
        let parts = &mut self.partials[..tris.len().div_ceil(REDUCE_CHUNK)];
        chunk_partials(parallel, tris.len(), parts, |s, e| {
            let mut v = 0.0f64;
            for t in &tris[s..e] {
                let a = x[t[0] as usize].as_dvec3() - centre;
                let b = x[t[1] as usize].as_dvec3() - centre;
                let c = x[t[2] as usize].as_dvec3() - centre;
                v += a.dot(b.cross(c));
            }
            [v, 0.0, 0.0]
        });
        parts.iter().map(|s| s[0]).sum::<f64>() / 6.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The advice for shorter substeps asks only for what a def accepts: more substeps up to the
    /// most allowed, then a shorter time step with that many, and none below the shortest step.
    #[test]
    fn substeps_advice_stays_within_what_a_def_accepts() {
        let h = 1.0f32 / 60.0;
        assert!(substeps_advice(h, h / 4.0).starts_with("Substeps >= 4 "));
        assert!(substeps_advice(h, h / 250.0 / 4.0).starts_with("Substeps >= 1000 "));
        let beyond = substeps_advice(h, h / 4000.0);
        assert!(beyond.starts_with("A time_step of at most 4.167e-3 s with substeps = 1000"), "{beyond}");
        let none = substeps_advice(2e-6, 2e-6 / 4000.0);
        assert!(none.starts_with("No allowed step makes substeps"), "{none}");
        // The pressure's advice for the unit sphere at 1e10 Pa asked for a time step of 7.1e-7 s.
        let pressure = substeps_advice(h, 7.073e-7);
        assert!(pressure.starts_with("A time_step of at most 7.073e-4 s with substeps = 1000"), "{pressure}");
        assert!(substeps_advice(1e-6, 7.073e-11).starts_with("No allowed step"));
        for (step, substep) in [(1.0f32, 0.25f32), (1.0, 1.0 / 1004.0), (1e-3, 2.5e-7), (4e-6, 1e-9), (1e-6, 0.1)] {
            let advice = substeps_advice(step, substep);
            let asked = |key: &str| advice.split(key).nth(1).and_then(|t| t.split(' ').next()?.parse::<f32>().ok());
            assert!(asked("Substeps >= ").is_none_or(|n| n <= MAX_SUBSTEPS as f32), "{advice}");
            assert!(asked("time_step of at most ").is_none_or(|h| h >= MIN_TIME_STEP), "{advice}");
        }
    }
}
