//! The shell simulator: state, the step of SPEC 1.1 and its measurements.
//!
//! Evolving state is structure-of-arrays (x, v, inverse mass, the predicted positions p, one λ
//! array per constraint kind); rest data lives in [`super::constraints`]. Nothing is allocated
//! in a step: every scratch array is sized when the shell (or a region) is made.

// NaN must fail every guard below, so comparisons are written `!(x > limit)` on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

use std::time::Instant;

use glam::{Vec3, Vec4};

use super::constraints::{Anisotropics, Bendings, Edges, Membranes, Region};
use super::exec::{MIN_PARALLEL, REDUCE_CHUNK, Shared, chunk_partials, for_range, for_range_min};
use super::settings::{AnisotropySettings, BendingKind, ShellSettings, SolverKind};
use crate::error::{Error, ErrorKind, Result};
use crate::material::{Lame, Mat32, Material, anisotropic_energy, membrane_energy};
use crate::mesh::{CurvatureKind, Topology, TriMesh, bounding_box, require_closed_oriented_solid, vertex_curvature};
use crate::parallel::WorkerPool;
use crate::solver::{
    MembraneLanes, W3, bending_energy, bending_projection_wide, deformation_gradient, distance_correction,
    pbd_energy_correction, scatter_stress, stvk_projection_wide, xpbd_energy_correction,
};

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

/// Per-step constants of the projections.
#[derive(Clone, Copy)]
struct Coefficients {
    solver: SolverKind,
    material: Material,
    /// Lamé parameters at unit Young's modulus (the XPBD split W = k Ŵ).
    lame: Lame,
    /// α̃ of the membrane: 1/(E t h²).
    alpha_membrane: f32,
    /// E t h²·kB (bending α̃ = 1/(kb_scale · stencil area)).
    bending_scale: f32,
    bending_coefficient: f32,
    keep_rest: bool,
    /// t h², for the anisotropic α̃ = 1/(μ t h²).
    aniso_scale: f32,
}

/// The contraction simulator.
pub struct Shell {
    settings: ShellSettings,
    pool: WorkerPool,
    state: State,
}

struct State {
    triangles: Vec<[u32; 3]>,
    vertex_face_offsets: Vec<u32>,
    vertex_faces: Vec<u32>,
    rest: Vec<Vec3>,
    x: Vec<Vec3>,
    v: Vec<Vec3>,
    p: Vec<Vec3>,
    inv_mass: Vec<f32>,
    x_backup: Vec<Vec3>,
    v_backup: Vec<Vec3>,
    membranes: Membranes,
    /// Edge-distance constraints: only for the distance solver.
    edges: Edges,
    lambda_membrane: Vec<f32>,
    bendings: Bendings,
    lambda_bending: Vec<f32>,
    regions: Vec<Region>,
    anisotropics: Option<Anisotropics>,
    lambda_aniso: Vec<f32>,
    /// Reduction scratch, one slot per REDUCE_CHUNK items of the largest array.
    partials: Vec<[f64; 3]>,
    rest_volume: f64,
    diagonal: f32,
    /// Consecutive steps whose volume ratio changed by less than STALL_TOLERANCE.
    quiet_steps: u32,
    stats: ShellStats,
}

impl Shell {
    /// Makes a shell from a closed, consistently oriented, non-degenerate mesh (refused with
    /// `InvalidMesh` naming the first offending edge or triangle). Settings are assumed
    /// validated (the C boundary does it).
    pub fn new(mesh: &TriMesh, topology: &Topology, settings: ShellSettings) -> Result<Self> {
        require_closed_oriented_solid(mesh, topology, "the shell")?;
        let pool = WorkerPool::new(settings.threads)?;
        let rest = mesh.positions().to_vec();
        let triangles = mesh.triangles().to_vec();
        let n = rest.len();
        let membranes = Membranes::build(&rest, &triangles, settings.material == Material::Linear)?;
        let edges =
            if settings.solver == SolverKind::PbdDistance { Edges::build(&rest, topology) } else { Edges::default() };
        let mut bendings = match settings.bending {
            BendingKind::None => Bendings::default(),
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
        let inv_mass: Vec<f32> = mass.iter().map(|&m| if m > 0.0 { (1.0 / m) as f32 } else { 0.0 }).collect();
        bendings.set_inverse_masses(&inv_mass);
        let mut membranes = membranes;
        membranes.set_inverse_masses(&inv_mass);
        let xpbd = settings.solver == SolverKind::Xpbd;
        let largest = n.max(triangles.len()).max(bendings.len()).max(edges.len());
        let rest_volume = crate::mesh::signed_volume(&rest, &triangles);
        let diagonal = bounding_box(&rest).diagonal();
        let stats = ShellStats { volume: rest_volume, volume_ratio: 1.0, ..Default::default() };
        let state = State {
            vertex_face_offsets: topology.vertex_face_offsets.clone(),
            vertex_faces: topology.vertex_faces.clone(),
            x: rest.clone(),
            v: vec![Vec3::ZERO; n],
            p: rest.clone(),
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
            quiet_steps: 0,
            stats,
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
        let previous_ratio = self.state.stats.volume_ratio;
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
            out[s.membranes.face[i] as usize] = k * w;
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

fn coefficients(settings: &ShellSettings, h: f32) -> Coefficients {
    let k = settings.youngs_modulus * settings.thickness;
    Coefficients {
        solver: settings.solver,
        material: settings.material,
        lame: Lame::from_young_poisson(1.0, settings.poisson_ratio),
        alpha_membrane: 1.0 / (k * h * h),
        bending_scale: k * settings.bending_coefficient * h * h,
        bending_coefficient: settings.bending_coefficient,
        keep_rest: settings.bending == BendingKind::IsometricRest,
        aniso_scale: settings.thickness * h * h,
    }
}

const IDENTITY_BASIS: Mat32 = Mat32 { c0: Vec3::X, c1: Vec3::Y };

/// Ŵ (unit modulus and thickness) and its gradients for membrane constraint `i` at positions `x`.
#[inline(always)]
fn membrane_energy_at(m: &Membranes, i: usize, x: &[Vec3], c: &Coefficients) -> (f32, [Vec3; 3]) {
    let [a, b, d] = m.tri[i];
    gather_membrane(m, i, [x[a as usize], x[b as usize], x[d as usize]], c)
}

#[inline(always)]
fn gather_membrane(m: &Membranes, i: usize, x: [Vec3; 3], c: &Coefficients) -> (f32, [Vec3; 3]) {
    let dm = &m.dm_inv[i];
    let f = deformation_gradient(x, dm);
    let basis = if c.material == Material::Linear { &m.basis[i] } else { &IDENTITY_BASIS };
    let (psi, stress) = membrane_energy(c.material, c.lame, &f, basis);
    let area = m.area[i];
    (area * psi, scatter_stress(&stress, dm, area))
}

/// Stencil area (A0 + A1)/2 from q = 3/(A0 + A1).
#[inline(always)]
fn stencil_area(q: f32) -> f32 {
    1.5 / q
}

/// Ŵ and gradients of anisotropic constraint `i` (unit stiffness and thickness).
#[inline(always)]
fn gather_aniso(a: &Anisotropics, i: usize, x: [Vec3; 3]) -> (f32, [Vec3; 3], &AnisotropySettings) {
    let dm = &a.dm_inv[i];
    let f = deformation_gradient(x, dm);
    let params = &a.params[a.region[i] as usize];
    let (psi, stress) = anisotropic_energy(params.energy, 1.0, params.target_stretch, &f, a.dir[i]);
    let area = a.area[i];
    (area * psi, scatter_stress(&stress, dm, area), params)
}

impl State {
    fn advance(&mut self, settings: &ShellSettings, parallel: bool, measure: bool) -> Result<()> {
        self.x_backup.copy_from_slice(&self.x);
        self.v_backup.copy_from_slice(&self.v);
        let h = settings.time_step / settings.substeps as f32;
        let coeff = coefficients(settings, h);
        for substep in 0..settings.substeps {
            self.predict(settings.pressure, h, parallel);
            self.lambda_membrane.fill(0.0);
            self.lambda_bending.fill(0.0);
            self.lambda_aniso.fill(0.0);
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
            // SPEC 1.1 step 3: collisions over x_t -> p. The collision module fills this stage;
            // until then it does nothing and its counters stay 0.
            self.update_velocities(settings, h, parallel, substep)?;
            if measure && substep + 1 == settings.substeps {
                self.measure(settings, &coeff, parallel);
            }
        }
        let volume = self.volume(parallel);
        if !volume.is_finite() {
            return Err(self.unstable(settings, "the enclosed volume became non-finite"));
        }
        self.stats.volume = volume;
        self.stats.volume_ratio = volume / self.rest_volume;
        Ok(())
    }

    /// SPEC 1.1 step 1 with the pressure force of SPEC 1.2:
    /// `f_i = -P Σ_j (1/3) A_j n_j`, `v* = v + h w f`, `p = x + h v*`.
    fn predict(&mut self, pressure: f32, h: f32, parallel: bool) {
        let (x, tris, offsets, faces, w) =
            (&self.x, &self.triangles, &self.vertex_face_offsets, &self.vertex_faces, &self.inv_mass);
        let v = Shared::new(&mut self.v);
        let p = Shared::new(&mut self.p);
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
                p.set(i, x[i] + vi * h);
            }
        });
    }

    /// StVK (the default) four triangles at a time (SSE lanes), as the bending stencils; the
    /// other materials one at a time.
    fn project_membranes_stvk(&mut self, c: &Coefficients, parallel: bool) {
        let m = &self.membranes;
        let p = Shared::new(&mut self.p);
        let lambda = Shared::new(&mut self.lambda_membrane);
        let xpbd = c.solver == SolverKind::Xpbd;
        let alpha = Vec4::splat(c.alpha_membrane);
        for colour in m.colours.windows(2) {
            let (start, end) = (colour[0], colour[1]);
            for_range_min(parallel, 0, (end - start).div_ceil(4), MIN_PARALLEL / 4, |g| {
                let base = start + 4 * g;
                let real = (end - base).min(4);
                let last = real - 1;
                let lanes: [usize; 4] = [base, base + 1.min(last), base + 2.min(last), base + 3.min(last)];
                let id = |j: usize| {
                    let t = &m.tri[lanes[j]];
                    [t[0] as usize, t[1] as usize, t[2] as usize]
                };
                let idx = [id(0), id(1), id(2), id(3)];
                let lane4 = |a: &[f32]| Vec4::new(a[lanes[0]], a[lanes[1]], a[lanes[2]], a[lanes[3]]);
                let (d0, d1, d2, d3) =
                    (&m.dm_inv[lanes[0]], &m.dm_inv[lanes[1]], &m.dm_inv[lanes[2]], &m.dm_inv[lanes[3]]);
                let (w0, w1, w2, w3) =
                    (&m.inv_mass[lanes[0]], &m.inv_mass[lanes[1]], &m.inv_mass[lanes[2]], &m.inv_mass[lanes[3]]);
                let rest = MembraneLanes {
                    dm_inv: [
                        Vec4::new(d0[0], d1[0], d2[0], d3[0]),
                        Vec4::new(d0[1], d1[1], d2[1], d3[1]),
                        Vec4::new(d0[2], d1[2], d2[2], d3[2]),
                        Vec4::new(d0[3], d1[3], d2[3], d3[3]),
                    ],
                    area: lane4(&m.area),
                    inv_mass: [
                        Vec4::new(w0[0], w1[0], w2[0], w3[0]),
                        Vec4::new(w0[1], w1[1], w2[1], w3[1]),
                        Vec4::new(w0[2], w1[2], w2[2], w3[2]),
                    ],
                };
                // SAFETY: triangles of one colour touch disjoint vertices; lambda[i] is i's. The
                // padding lanes read the last real triangle again and are not written.
                unsafe {
                    let vertex =
                        |k: usize| W3::gather([p.get(idx[0][k]), p.get(idx[1][k]), p.get(idx[2][k]), p.get(idx[3][k])]);
                    let x = [vertex(0), vertex(1), vertex(2)];
                    let lam = if xpbd {
                        Vec4::new(
                            lambda.get(lanes[0]),
                            lambda.get(lanes[1]),
                            lambda.get(lanes[2]),
                            lambda.get(lanes[3]),
                        )
                    } else {
                        Vec4::ZERO
                    };
                    let (corr, dlambda, active) =
                        stvk_projection_wide(&x, &rest, c.lame.mu, c.lame.lambda, xpbd.then_some((alpha, lam)));
                    for j in 0..real {
                        if active & (1 << j) == 0 {
                            continue;
                        }
                        if xpbd {
                            lambda.set(lanes[j], lam[j] + dlambda[j]);
                        }
                        for k in 0..3 {
                            p.set(idx[j][k], x[k].lane(j) + corr[k].lane(j));
                        }
                    }
                }
            });
        }
    }

    fn project_membranes(&mut self, c: &Coefficients, parallel: bool) {
        if c.material == Material::StVK {
            return self.project_membranes_stvk(c, parallel);
        }
        let m = &self.membranes;
        let p = Shared::new(&mut self.p);
        let lambda = Shared::new(&mut self.lambda_membrane);
        for colour in m.colours.windows(2) {
            for_range(parallel, colour[0], colour[1], |i| {
                let t = &m.tri[i];
                let (a, b, d) = (t[0] as usize, t[1] as usize, t[2] as usize);
                // SAFETY: constraints of one colour touch disjoint vertices, and constraint i
                // alone owns lambda[i].
                unsafe {
                    let x = [p.get(a), p.get(b), p.get(d)];
                    let (energy, grad) = gather_membrane(m, i, x, c);
                    let inv = m.inv_mass[i];
                    let mut corr = [Vec3::ZERO; 3];
                    match c.solver {
                        SolverKind::Xpbd => {
                            let l = lambda.get(i);
                            // At rest when sqrt(2 ψ) < 1e-6 (a strain of about 1e-6).
                            let min_c2 = 1e-12 * m.area[i];
                            let dl =
                                xpbd_energy_correction(energy, &grad, &inv, c.alpha_membrane, l, min_c2, &mut corr);
                            if dl == 0.0 {
                                return;
                            }
                            lambda.set(i, l + dl);
                        }
                        SolverKind::Pbd | SolverKind::PbdDistance => {
                            if !pbd_energy_correction(energy, &grad, &inv, 1.0, &mut corr) {
                                return;
                            }
                        }
                    }
                    p.set(a, x[0] + corr[0]);
                    p.set(b, x[1] + corr[1]);
                    p.set(d, x[2] + corr[2]);
                }
            });
        }
    }

    fn project_edges(&mut self, parallel: bool) {
        let e = &self.edges;
        let w = &self.inv_mass;
        let p = Shared::new(&mut self.p);
        for colour in e.colours.windows(2) {
            for_range(parallel, colour[0], colour[1], |i| {
                let (a, b) = (e.idx[i][0] as usize, e.idx[i][1] as usize);
                // SAFETY: edges of one colour touch disjoint vertices.
                unsafe {
                    let (xa, xb) = (p.get(a), p.get(b));
                    if let Some((da, db)) = distance_correction(xa, xb, w[a], w[b], e.rest[i]) {
                        p.set(a, xa + da);
                        p.set(b, xb + db);
                    }
                }
            });
        }
    }

    /// Bending stencils four at a time (SSE lanes): a colour's stencils are independent, so
    /// groups of four consecutive ones are solved together; the last group of a colour repeats
    /// its last stencil in the unused lanes, which are never written back.
    fn project_bendings(&mut self, c: &Coefficients, parallel: bool) {
        let s = &self.bendings;
        let p = Shared::new(&mut self.p);
        let lambda = Shared::new(&mut self.lambda_bending);
        let xpbd = c.solver == SolverKind::Xpbd;
        for colour in s.colours.windows(2) {
            let (start, end) = (colour[0], colour[1]);
            for_range_min(parallel, 0, (end - start).div_ceil(4), MIN_PARALLEL / 4, |g| {
                let base = start + 4 * g;
                let real = (end - base).min(4);
                let last = real - 1;
                let lanes: [usize; 4] = [base, base + 1.min(last), base + 2.min(last), base + 3.min(last)];
                let id = |j: usize| {
                    let t = &s.idx[lanes[j]];
                    [t[0] as usize, t[1] as usize, t[2] as usize, t[3] as usize]
                };
                let idx = [id(0), id(1), id(2), id(3)];
                // SAFETY: stencils of one colour touch disjoint vertices; lambda[i] is i's. The
                // padding lanes read the last real stencil again and are not written.
                unsafe {
                    let vertex =
                        |k: usize| W3::gather([p.get(idx[0][k]), p.get(idx[1][k]), p.get(idx[2][k]), p.get(idx[3][k])]);
                    let x = [vertex(0), vertex(1), vertex(2), vertex(3)];
                    let (k0, k1, k2, k3) = (&s.k[lanes[0]], &s.k[lanes[1]], &s.k[lanes[2]], &s.k[lanes[3]]);
                    let kk = [
                        Vec4::new(k0[1], k1[1], k2[1], k3[1]),
                        Vec4::new(k0[2], k1[2], k2[2], k3[2]),
                        Vec4::new(k0[3], k1[3], k2[3], k3[3]),
                    ];
                    let lane4 = |a: &[f32]| Vec4::new(a[lanes[0]], a[lanes[1]], a[lanes[2]], a[lanes[3]]);
                    let q = lane4(&s.q);
                    let wk2 = lane4(&s.wk2);
                    let rest = c.keep_rest.then(|| {
                        let r = &s.rest_local;
                        W3::gather([r[lanes[0]], r[lanes[1]], r[lanes[2]], r[lanes[3]]])
                    });
                    let lam = if xpbd {
                        Vec4::new(
                            lambda.get(lanes[0]),
                            lambda.get(lanes[1]),
                            lambda.get(lanes[2]),
                            lambda.get(lanes[3]),
                        )
                    } else {
                        Vec4::ZERO
                    };
                    // SPEC 1.4 with W = kB E t (A0+A1)/2 · E_B (XPBD): bending as stiff as
                    // stretching over one stencil when kB = 1. The paper's PBD form scales the
                    // correction by kB instead (as Bender's library does).
                    let alpha = Vec4::ONE / (Vec4::splat(c.bending_scale) * (Vec4::splat(1.5) / q));
                    let (v, scale, dlambda, active) = bending_projection_wide(
                        &x,
                        kk,
                        rest.as_ref(),
                        q,
                        wk2,
                        xpbd.then_some((alpha, lam)),
                        c.bending_coefficient,
                        1e-7,
                    );
                    for j in 0..real {
                        if active & (1 << j) == 0 {
                            continue;
                        }
                        let i = lanes[j];
                        if xpbd {
                            lambda.set(i, lam[j] + dlambda[j]);
                        }
                        let (vj, sj, wk) = (v.lane(j), scale[j], &s.wk[i]);
                        for k in 0..4 {
                            p.set(idx[j][k], x[k].lane(j) + vj * (wk[k] * sj));
                        }
                    }
                }
            });
        }
    }

    fn project_anisotropics(&mut self, c: &Coefficients, parallel: bool) {
        let Some(s) = &self.anisotropics else { return };
        let w = &self.inv_mass;
        let p = Shared::new(&mut self.p);
        let lambda = Shared::new(&mut self.lambda_aniso);
        for colour in s.colours.windows(2) {
            for_range(parallel, colour[0], colour[1], |i| {
                let t = &s.tri[i];
                let (a, b, d) = (t[0] as usize, t[1] as usize, t[2] as usize);
                // SAFETY: constraints of one colour touch disjoint vertices; lambda[i] is i's.
                unsafe {
                    let x = [p.get(a), p.get(b), p.get(d)];
                    let (energy, mut grad, params) = gather_aniso(s, i, x);
                    // SPEC 1.5: every vertex gradient gets + k_A n (outward unit normal), so the
                    // correction moves the region inwards. k_A is scaled by √A0 so that it acts
                    // the same at any mesh scale (the gradient of A0 ψ scales with a length).
                    let n = (x[1] - x[0]).cross(x[2] - x[0]).normalize_or_zero();
                    let push = n * (params.inward_push * s.area[i].sqrt());
                    for g in &mut grad {
                        *g += push;
                    }
                    let inv = [w[a], w[b], w[d]];
                    let mut corr = [Vec3::ZERO; 3];
                    match c.solver {
                        SolverKind::Xpbd => {
                            let alpha = 1.0 / (params.stiffness * c.aniso_scale);
                            let l = lambda.get(i);
                            let min_c2 = 1e-12 * s.area[i];
                            let dl = xpbd_energy_correction(energy, &grad, &inv, alpha, l, min_c2, &mut corr);
                            if dl == 0.0 {
                                return;
                            }
                            lambda.set(i, l + dl);
                        }
                        SolverKind::Pbd | SolverKind::PbdDistance => {
                            if !pbd_energy_correction(energy, &grad, &inv, 1.0, &mut corr) {
                                return;
                            }
                        }
                    }
                    p.set(a, x[0] + corr[0]);
                    p.set(b, x[1] + corr[1]);
                    p.set(d, x[2] + corr[2]);
                }
            });
        }
    }

    /// SPEC 1.1 step 5: `v = (p - x)/h` (damped), `x = p`; refuses a non-finite or runaway
    /// vertex before anything is committed to x.
    fn update_velocities(&mut self, settings: &ShellSettings, h: f32, parallel: bool, substep: u32) -> Result<()> {
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
            let _ = substep;
            return Err(self.unstable(settings, &what));
        }
        let damp = (1.0 - settings.damping * h).max(0.0);
        let inv_h = 1.0 / h;
        let p = &self.p;
        let xs = Shared::new(&mut self.x);
        let vs = Shared::new(&mut self.v);
        for_range(parallel, 0, n, |i| {
            // SAFETY: each iteration touches only index i.
            unsafe {
                vs.set(i, (p[i] - xs.get(i)) * (inv_h * damp));
                xs.set(i, p[i]);
            }
        });
        Ok(())
    }

    fn unstable(&self, settings: &ShellSettings, what: &str) -> Error {
        let h = settings.time_step;
        Error::new(
            ErrorKind::Unstable,
            format!(
                "the shell diverged in step {}: {what}; the step was rolled back. With time_step {h} s, {} substeps, \
                 pressure {} Pa and Young's modulus {} Pa this scene is too stiff or too fast: use substeps >= {} \
                 (or time_step <= {:.3e} s), or a pressure below {:.3e} Pa",
                self.stats.step + 1,
                settings.substeps,
                settings.pressure,
                settings.youngs_modulus,
                settings.substeps * 4,
                h / 4.0,
                settings.pressure / 10.0
            ),
        )
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
                let [a, b, c] = t.map(|k| x[k as usize].as_dvec3() - centre);
                v += a.dot(b.cross(c));
            }
            [v, 0.0, 0.0]
        });
        parts.iter().map(|s| s[0]).sum::<f64>() / 6.0
    }

    /// Energies (J) and the residual after the last iteration: the largest relative constraint
    /// violation, |C + α̃ λ| for XPBD and |C| for PBD, with C = sqrt(2 Ŵ) made dimensionless
    /// (divided by √A0 for membrane and anisotropic constraints; bending's C already is).
    fn measure(&mut self, settings: &ShellSettings, c: &Coefficients, parallel: bool) {
        let k = settings.youngs_modulus * settings.thickness;
        let xpbd = c.solver == SolverKind::Xpbd;
        let (x, m, lm) = (&self.x, &self.membranes, &self.lambda_membrane);
        let parts = &mut self.partials[..m.len().div_ceil(REDUCE_CHUNK)];
        chunk_partials(parallel, m.len(), parts, |s, e| {
            let (mut energy, mut residual) = (0.0f64, 0.0f64);
            for i in s..e {
                let (w, _) = membrane_energy_at(m, i, x, c);
                energy += (k * w) as f64;
                let cval = (2.0 * w).max(0.0).sqrt();
                let r = if xpbd { cval + c.alpha_membrane * lm[i] } else { cval };
                residual = residual.max((r.abs() / m.area[i].sqrt()) as f64);
            }
            [energy, residual, 0.0]
        });
        let elastic = parts.iter().map(|s| s[0]).sum::<f64>();
        let mut residual = parts.iter().fold(0.0f64, |a, s| a.max(s[1]));
        if c.solver == SolverKind::PbdDistance {
            // The distance solver's own constraints: the largest relative edge-length error.
            let e = &self.edges;
            let parts = &mut self.partials[..e.len().div_ceil(REDUCE_CHUNK)];
            chunk_partials(parallel, e.len(), parts, |s, end| {
                let mut worst = 0.0f64;
                for i in s..end {
                    let [a, b] = e.idx[i];
                    let len = (x[b as usize] - x[a as usize]).length();
                    worst = worst.max(((len - e.rest[i]) / e.rest[i]).abs() as f64);
                }
                [worst, 0.0, 0.0]
            });
            residual = parts.iter().fold(0.0f64, |a, s| a.max(s[0]));
        }

        let mut bending = 0.0;
        if settings.bending != BendingKind::None {
            let (b, lb) = (&self.bendings, &self.lambda_bending);
            let parts = &mut self.partials[..b.len().div_ceil(REDUCE_CHUNK)];
            chunk_partials(parallel, b.len(), parts, |s, e| {
                let (mut energy, mut res) = (0.0f64, 0.0f64);
                for i in s..e {
                    let xs = b.idx[i].map(|v| x[v as usize]);
                    let (w, _) = bending_stencil(b, i, &xs, c.keep_rest);
                    let stiffness = k * settings.bending_coefficient * stencil_area(b.q[i]);
                    energy += (stiffness * w) as f64;
                    let cval = (2.0 * w).max(0.0).sqrt();
                    let r = if xpbd && stiffness > 0.0 {
                        cval + lb[i] / (stiffness * settings.time_step.powi(2) / (settings.substeps as f32).powi(2))
                    } else {
                        cval
                    };
                    res = res.max(r.abs() as f64);
                }
                [energy, res, 0.0]
            });
            bending = parts.iter().map(|s| s[0]).sum::<f64>();
            if settings.bending_coefficient > 0.0 {
                residual = residual.max(parts.iter().fold(0.0f64, |a, s| a.max(s[1])));
            }
        }

        let mut aniso = 0.0;
        if let Some(a) = &self.anisotropics {
            let la = &self.lambda_aniso;
            let parts = &mut self.partials[..a.len().div_ceil(REDUCE_CHUNK)];
            chunk_partials(parallel, a.len(), parts, |s, e| {
                let (mut energy, mut res) = (0.0f64, 0.0f64);
                for i in s..e {
                    let xs = a.tri[i].map(|v| x[v as usize]);
                    let (w, _, params) = gather_aniso(a, i, xs);
                    energy += (params.stiffness * settings.thickness * w) as f64;
                    let cval = (2.0 * w).max(0.0).sqrt();
                    let r = if xpbd { cval + la[i] / (params.stiffness * c.aniso_scale) } else { cval };
                    res = res.max((r.abs() / a.area[i].sqrt()) as f64);
                }
                [energy, res, 0.0]
            });
            aniso = parts.iter().map(|s| s[0]).sum::<f64>();
            residual = residual.max(parts.iter().fold(0.0f64, |acc, s| acc.max(s[1])));
        }
        self.stats.elastic_energy = elastic;
        self.stats.bending_energy = bending;
        self.stats.anisotropic_energy = aniso;
        self.stats.residual = residual;
    }
}

#[inline(always)]
fn bending_stencil(s: &Bendings, i: usize, x: &[Vec3; 4], keep_rest: bool) -> (f32, [Vec3; 4]) {
    let rest = crate::solver::BendingRest {
        k: s.k[i],
        q: s.q[i],
        rest_local: if keep_rest { s.rest_local[i] } else { Vec3::ZERO },
    };
    bending_energy(x, &rest, keep_rest)
}
