//! Linearised backward Euler (SPEC 2.2), solved by matrix-free preconditioned conjugate
//! gradients: `(M - h² K - h D) Δv = h f + h² K v`, then `v += Δv`, `x += h v`.
//!
//! K holds each spring's stiffness block `a I + b u uᵀ` (transverse part clamped at zero when
//! compressed, so the system is positive definite) and the rank-one gas term
//! `-(P/V) ∂V/∂x ∂V/∂xᵀ` of `∂(P ∂V/∂x)/∂x` (the indefinite `P ∂²V/∂x²` part is left out);
//! D is the spring damping `K_d u uᵀ`. Pinned vertices are filtered out of the system.
//!
//! Layout for speed: the system is gathered per vertex, never scattered. Each spring's terms are
//! computed once (`spring_terms`); one pass over the vertices, eight at a time (a slice of the
//! coupling layout, `spring_sums`), gathers their springs' terms into the right side and the
//! block-Jacobi preconditioner and writes the coupling block of every (vertex, spring) pair into
//! the slices (`coupling_slices`), so each product with the matrix streams through memory once.
//! The products and the iteration's vector passes also go eight rows (or two) at a time where
//! the processor has AVX2. Every pass runs in fixed chunks of vertices, so the result does not
//! depend on the thread count.
//!
//! Preconditioner: two levels, added. The 3x3 block of each vertex (block Jacobi) resolves what
//! happens at one vertex; the coarse level (`coarse`: aggregates of about 16 vertices, a constant
//! scalar matrix factored once) moves whole patches, the smooth motions that block Jacobi alone
//! leaves to many iterations. Both are filtered by the pins and contacts (modified PCG); at a
//! sliding contact the block is inverted on the tangent plane (`start_vertex`). On the issue-5
//! balloon resting on the ground this took the solve from 70 to 7 CG iterations per step.

use glam::{Vec3, Vec3A};

use super::cg_vectors::{initial_rows, residual_rows};
use super::coarse::{CoarseSpace, CoarseView};
#[cfg(target_arch = "x86_64")]
use super::coupling_slices::load_points_transposed;
use super::coupling_slices::{
    CheckedCouplings, CouplingGroup, CouplingSlices, RowTerms, SLICE, SliceCouplingSums, SliceRowsMut, group_range,
    largest_other_offset, product_slices,
};
use super::energy::{self, SpringEnergyLanes};
use super::forces::{Model, add_gas_forces_parallel, external_forces};
use super::gas::{self, Gas};
use super::headroom::reserve_for;
use super::obstacles::{Obstacle, resolve, touching};
#[cfg(target_arch = "x86_64")]
use super::slice_update::{self, update_slice_avx2};
use super::slice_vertices::{GasTerms, RowGas, SliceGas, VertexConstants, vertex_blocks};
#[cfg(target_arch = "x86_64")]
use super::slice_vertices::{free_slice_start_avx2, slice_vertices_avx2};
#[cfg(target_arch = "x86_64")]
use super::spring_sums::slice_spring_sums_avx2;
use super::spring_sums::{SliceSums, row_spring_sums};
use super::spring_terms::{SpringInput, SpringTerms, spring_terms_range};
use super::springs::Springs;
use super::symmetric_block::SymmetricBlock;
use crate::parallel::{SharedSlice, Team, TeamSizer, WorkerPool};

/// How a vertex in contact with an obstacle is constrained inside the solve (Baraff and Witkin
/// 1998, modified PCG): its constrained velocity components are filtered out of the residual and
/// the search directions.
#[derive(Clone, Copy, Debug, PartialEq)]
enum ContactFilter {
    Free,
    /// `(v + Δv)·n = 0` for the normal n; Coulomb friction follows the solve, from the
    /// contact's reactions.
    Slide(Vec3),
}

/// The contact filters as the solve's passes read them: per vertex the slot of its contact
/// normal (`u32::MAX`: free), the normals in the slots. Four bytes a vertex instead of the
/// twenty of a [`ContactFilter`]: the three passes of each iteration read them at every vertex
/// (while anything touches an obstacle), and those passes are bound by the bytes they stream.
/// Empty when nothing touches.
#[derive(Clone, Copy, Default)]
pub(super) struct ContactRows<'a> {
    pub slot: &'a [u32],
    pub normal: &'a [Vec3A],
}

impl<'a> ContactRows<'a> {
    pub fn is_empty(&self) -> bool {
        self.slot.is_empty()
    }

    /// The slots of the vertices `rows` (indexed from 0), or empty without contacts.
    pub fn rows(self, rows: std::ops::Range<usize>) -> ContactRows<'a> {
        ContactRows { slot: self.slot.get(rows).unwrap_or(&[]), normal: self.normal }
    }

    /// The `k`-th vertex's filter applied to `value`: its component along the contact normal
    /// removed (none when the vertex is free).
    #[inline(always)]
    pub fn apply(&self, k: usize, value: Vec3A) -> Vec3A {
        let slot = self.slot[k];
        if slot == u32::MAX {
            value
        } else {
            let n = self.normal[slot as usize];
            value - n * value.dot(n)
        }
    }
}

/// Scratch of the implicit integrator (allocated only when it is used).
#[derive(Default)]
pub(crate) struct ImplicitScratch {
    /// External and gas forces at the start of the substep (the springs are added per vertex);
    /// only with wind: otherwise the assembly computes gravity and pressure per vertex.
    pub force: Vec<Vec3>,
    /// The members of each substep's team: one while another process holds a core.
    team_sizer: TeamSizer,
    pub gradient: Vec<Vec3>,
    /// The coupling block of every (vertex, spring) pair with its other end, by slices of rows
    /// (`coupling_slices`: the products stream these).
    couplings: CouplingSlices,
    /// Per spring, its share of the assembly.
    spring_terms: Vec<SpringTerms>,
    rhs: Vec<Vec3A>,
    /// Δv: between substeps the last one's (the warm start, reset when the vertex count
    /// changes), which the assembly turns into the start of the solve in place (a buffer of
    /// its own was another 164 KB read and written per substep on the balloon).
    dv: Vec<Vec3A>,
    /// The warm start and the held contacts at the start of the step (copied by its first
    /// substep's assembly, with the positions and velocities to roll back to): a step rolled
    /// back puts them back too ([`ImplicitScratch::restore_step_start`]), so that a retry is
    /// the same step and a failed one leaves no trace in later ones (it started the retry from
    /// the failed solve's Δv: found by review).
    saved_dv: Vec<Vec3A>,
    saved_held: Vec<bool>,
    r: Vec<Vec3A>,
    z: Vec<Vec3A>,
    p: Vec<Vec3A>,
    ap: Vec<Vec3A>,
    /// The inverted 3x3 diagonal block of each vertex (the block-Jacobi preconditioner).
    inv_diag: Vec<SymmetricBlock>,
    /// Per chunk of vertices, the sums of the team passes.
    sums: ChunkSums,
    /// Per fragment `h² P/V` (gas rank-one term); `gas_dot` only counts the fragments.
    gas_coef: Vec<f64>,
    gas_dot: Vec<f64>,
    /// Per chunk of vertices and per fragment, that chunk's part of `Σ g·p`.
    gas_partial: Vec<f64>,
    /// The contact constraints of the substep (allocated only with obstacles, rewritten by
    /// every assembly): per vertex its slot (u32::MAX: free), and per slot the contact's normal
    /// and, after the solve, its normal reaction (`contact_reaction`, the friction bound); each
    /// chunk's contacts fill the first slots of its own rows. The solve reads them as
    /// [`ContactRows`].
    contact_slot: Vec<u32>,
    contact_normal: Vec<Vec3A>,
    contact_reaction: Vec<f32>,
    /// Per vertex (with obstacles only): the last substep held it on an obstacle and the
    /// obstacle pushed it (`contact_reaction` >= 0), so this one holds it again while it touches
    /// and does not move away, unless its own forces pull it off hard (see `start_vertex`).
    contact_held: Vec<bool>,
    /// A fault for tests of the step's blow-up rule: every substep moves the positions
    /// `1 + test_gain` times as far as its velocities say, overshooting as a diverging
    /// linearised step does (the end state is measured after it, as a real one would be).
    #[cfg(test)]
    pub test_gain: f32,
    /// The obstacles as planes for the last pass's slices (`slice_update::planes_of`).
    planes: Vec<(Vec3, Vec3)>,
    /// Tests: the last pass one row at a time ([`ImplicitScratch::set_rows_one_at_a_time`]).
    #[cfg(test)]
    rows_one_at_a_time: bool,
    /// The coarse level of the preconditioner (made on the first substep) and the substep
    /// length it was made (or tried) for.
    coarse: Option<CoarseSpace>,
    coarse_h: f32,
    /// Whether the last substep left every position and velocity finite (checked in its last
    /// pass, in parallel, so the step need not scan them again).
    pub all_finite: bool,
    /// What the last substep made at its end for the next one (see [`Prepared`]), with the
    /// chunks' `Σ g·v` of that state; None when nothing is prepared.
    prepared: Option<Prepared>,
    prepared_gas_v: Vec<f64>,
    /// The energies of the state the last substep ended in (from the prepared terms).
    pub end_energies: Option<EndEnergies>,
}

/// At the end of a substep (without wind) the team measures the state it ended in, as the next
/// substep would at its start: the gas gradient, volumes and pressures, the spring terms and
/// `Σ g·v`. The next substep starts from them instead of measuring again, and the step takes its
/// end-of-step energies from them (the spring extensions, the gas volumes) instead of a pass of
/// its own over the springs and faces at the same positions. Valid while nothing changes the
/// state in between: the step forgets it when anything did ([`ImplicitScratch::forget_prepared`]).
#[derive(Clone, Copy, PartialEq)]
struct Prepared {
    h: f32,
    vertices: usize,
    springs: usize,
}

/// Kinetic, spring and gravitational energy (J) and the largest spring strain of a state, summed
/// in the same chunks and order as `energy::state_energies` (the same bits).
#[derive(Clone, Copy, Debug)]
pub(crate) struct EndEnergies {
    pub kinetic: f64,
    pub spring: f64,
    pub gravity: f64,
    pub max_strain: f32,
}

impl ImplicitScratch {
    /// Whether the next substep holds any vertex on an obstacle (`contact_held`).
    #[cfg(test)]
    pub fn holds_any_contact(&self) -> bool {
        self.contact_held.iter().any(|&held| held)
    }

    /// The next `substeps` substeps with a team of one member ([`TeamSizer`]).
    #[cfg(test)]
    pub fn run_alone_for(&mut self, substeps: u32) {
        self.team_sizer.alone_for(substeps);
    }

    /// Per chunk, the largest other-end offset the last assembly found (what the solve
    /// checked), and that of the chunk's coupling groups now; and that of all the groups.
    #[cfg(test)]
    pub fn largest_other_offsets(&self) -> (Vec<(u32, u32)>, u32) {
        let n = self.couplings.offsets.len().saturating_sub(1) * SLICE;
        let chunks = self.sums.largest_other.iter().enumerate().map(|(c, &found)| {
            let slices = c * CHUNK / SLICE..((c + 1) * CHUNK).min(n) / SLICE;
            let groups = self.couplings.offsets[slices.start] as usize..self.couplings.offsets[slices.end] as usize;
            (found, largest_other_offset(&self.couplings.groups[groups]))
        });
        (chunks.collect(), largest_other_offset(&self.couplings.groups))
    }

    /// The start of the solve and the last pass of every substep one row at a time (no
    /// `free_slice_start_avx2`, no `slice_update`), and the state pass's `Σ g·v` in a pass of
    /// its own, or not.
    #[cfg(test)]
    pub fn set_rows_one_at_a_time(&mut self, one_at_a_time: bool) {
        self.rows_one_at_a_time = one_at_a_time;
    }

    /// The warm start of the next solve (the last Δv per vertex) and the coarse level's
    /// aggregate of each vertex (None for a vertex it does not know, or without the level).
    #[cfg(test)]
    pub fn warm_start_and_aggregates(&self) -> (&[Vec3A], Vec<Option<u32>>) {
        let aggregates = (0..self.dv.len()).map(|v| self.coarse.as_ref().and_then(|c| c.aggregate_of(v))).collect();
        (&self.dv, aggregates)
    }

    /// Whether the last substep prepared the next.
    #[cfg(test)]
    pub fn has_prepared(&self) -> bool {
        self.prepared.is_some()
    }

    /// Each of the `springs` springs' extension `L - L0` at the end of the last substep, as its
    /// state pass measured it for the next one (the bits of `springs::spring_extension`), while
    /// that is still the body's state (anything that changes it forgets what was prepared), and
    /// the spring count is the same; else None.
    pub fn prepared_extensions(&self, springs: usize) -> Option<impl Iterator<Item = f32> + '_> {
        (self.prepared.is_some_and(|p| p.springs == springs) && self.spring_terms.len() == springs)
            .then(|| self.spring_terms.iter().map(|t| t.extension))
    }

    /// Whether it holds a coarse level made (or tried) for substeps of `h`.
    #[cfg(test)]
    pub fn has_coarse_for(&self, h: f32) -> bool {
        self.coarse.is_some() && self.coarse_h == h
    }

    /// The warm start and the held contacts (tests of the rollback).
    #[cfg(test)]
    pub fn warm_start_and_held(&self) -> (Vec<Vec3A>, Vec<bool>) {
        (self.dv.clone(), self.contact_held.clone())
    }

    /// Puts back the warm start and the held contacts the step started with (saved by its
    /// first substep, as the positions and velocities are), after the step was rolled back.
    pub fn restore_step_start(&mut self) {
        // Both are sized by the step's first substep, after Δv and the held contacts are (no
        // step changes the vertex count before its end).
        debug_assert_eq!(self.saved_dv.len(), self.dv.len());
        debug_assert_eq!(self.saved_held.len(), self.contact_held.len());
        std::mem::swap(&mut self.dv, &mut self.saved_dv);
        std::mem::swap(&mut self.contact_held, &mut self.saved_held);
    }

    /// Forgets what the last substep prepared for the next (the state changed since).
    pub fn forget_prepared(&mut self) {
        self.prepared = None;
        self.end_energies = None;
    }

    /// Keeps the warm start across a topology change: survivors keep their index, and a vertex
    /// appended by a split starts from the Δv of the input vertex it was copied from (`origin`);
    /// without this every crack would restart the solve from the free-fall guess.
    pub fn extend_warm_start(&mut self, origin: &[u32]) {
        let old = self.dv.len();
        if old == 0 || origin.len() < old {
            return;
        }
        for k in old..origin.len() {
            let from = origin[k] as usize;
            let guess = if from < old { self.dv[from] } else { Vec3A::ZERO };
            self.dv.push(guess);
        }
        if let Some(coarse) = self.coarse.as_mut() {
            coarse.extend(origin);
        }
    }

    /// Makes now what the first substep of length `h` would make before it solves: the coarse
    /// level (factored) and the per-vertex buffers (their memory written). A body calls it when
    /// it is made, so that its first step does not carry the setup: on the issue-5 balloon
    /// (benches/body_balloon.rs) the first step took about 20 ms against 2-3 ms for the next
    /// ones, 6.4 ms of it the coarse factor and about 1,400 page faults the buffers. The same
    /// inputs (the rest positions) as the first substep's, so the same coarse level.
    pub fn prepare(&mut self, model: &Model, x: &[Vec3], h: f32, threads: usize) {
        self.lay_out(model.springs, x.len());
        self.spring_terms.resize(model.springs.len(), SpringTerms::default());
        if self.coarse_h == 0.0 {
            self.coarse = CoarseSpace::new(model, x, h, threads);
            self.coarse_h = h;
        }
    }

    /// Room for a fraction `headroom` more vertices and springs than `n` and `springs` in the
    /// buffers a topology change grows (see `headroom`), for a body that may crack; with
    /// `obstacles`, in the contact buffers too, and with `gas`, in the gas gradient (a body
    /// without gas never writes it: no room for it either, SPEC 5). After
    /// [`ImplicitScratch::prepare`].
    pub fn reserve_headroom(&mut self, n: usize, springs: usize, headroom: f64, obstacles: bool, gas: bool) {
        for buffer in
            [&mut self.rhs, &mut self.dv, &mut self.saved_dv, &mut self.r, &mut self.z, &mut self.p, &mut self.ap]
        {
            reserve_for(buffer, n, headroom);
        }
        reserve_for(&mut self.inv_diag, n, headroom);
        if gas {
            reserve_for(&mut self.gradient, n, headroom);
        }
        reserve_for(&mut self.spring_terms, springs, headroom);
        if obstacles {
            reserve_for(&mut self.contact_slot, n, headroom);
            reserve_for(&mut self.contact_normal, n, headroom);
            reserve_for(&mut self.contact_reaction, n, headroom);
            reserve_for(&mut self.contact_held, n, headroom);
            reserve_for(&mut self.saved_held, n, headroom);
        }
        self.couplings.reserve_headroom(headroom);
    }

    /// The per-vertex buffers every substep writes and the coupling layout, sized for `n`
    /// vertices and `springs` (nothing to do when they are). Every substep calls it, and a
    /// topology change too, so that the step that changed the topology makes them, not the next.
    pub fn lay_out(&mut self, springs: &Springs, n: usize) {
        for buffer in [&mut self.rhs, &mut self.r, &mut self.z, &mut self.p, &mut self.ap] {
            buffer.resize(n, Vec3A::ZERO);
        }
        self.inv_diag.resize(n, SymmetricBlock::default());
        self.couplings.layout_springs(springs);
    }

    pub fn memory_bytes(&self) -> usize {
        (self.force.capacity() + self.gradient.capacity()) * 12
            + (self.rhs.capacity()
                + self.dv.capacity()
                + self.saved_dv.capacity()
                + self.r.capacity()
                + self.z.capacity()
                + self.p.capacity()
                + self.ap.capacity())
                * 16
            + self.contact_reaction.capacity() * 4
            + self.contact_slot.capacity() * 4
            + self.contact_normal.capacity() * 16
            + self.contact_held.capacity()
            + self.saved_held.capacity()
            + self.planes.capacity() * 24
            + self.couplings.memory_bytes()
            + self.spring_terms.capacity() * std::mem::size_of::<SpringTerms>()
            + (self.gas_coef.capacity() + self.gas_dot.capacity() + self.gas_partial.capacity()) * 8
            + self.sums.memory_bytes()
            + self.prepared_gas_v.capacity() * 8
            + self.inv_diag.capacity() * std::mem::size_of::<SymmetricBlock>()
            + self.coarse.as_ref().map_or(0, CoarseSpace::memory_bytes)
    }
}

/// Conjugate gradients stop when the residual is below this fraction of the right side (an
/// inexact Newton step; the right side is the net force, zero at equilibrium, so a looser solve
/// slows the approach to equilibrium but does not move it). On the issue-5 balloon
/// (benches/body_balloon.rs) 3e-3 settles to the same volume as 1e-5 to 3 digits at under
/// two-thirds of the iterations. 1e-2 (measured again after the coarse level and the contact
/// blocks) takes 14% fewer iterations (5% of the mean step), settles to the same volume to 4
/// digits and stays stable at h = 1/15 s, but triples the error at the impact against a
/// converged solve (5.7e-3 to 1.9e-2 m RMS at step 60; the h = 1/60 s time-step error there is
/// about 5e-2), so the solve stops here ... A test in the preconditioned norm instead (`r·z`
/// against the right side's `b·D⁻¹b`, which weights the error by stiffness as the energy does)
/// took as many iterations as this one at 1e-2 for a larger error (150 steps from the drop:
/// 1,362 against 1,298 iterations, 2.3e-2 against 1.7e-2 m RMS at step 60).
const CG_RELATIVE_TOLERANCE: f64 = 3e-3;

/// ... or below this fraction of the size of the forces themselves (`h Σ|f|` per vertex): near
/// equilibrium the net force is a small difference of large spring and gas forces, and a test
/// relative to the right side alone would ask for more digits than the f32 forces have (1e-5 kept
/// the settled zero-gravity balloon iterating 10-30 times a step on that noise). Since friction
/// obeys Coulomb's bound, the balloon on the ground comes to rest, and this test decides there
/// (about 4 iterations a step): 3e-4 and 1e-3 take the issue's drop from 7.5 to 7.4 and 6.1
/// iterations a step but move it away from a converged solve (1e-6 of the right side, 1e-8 of the
/// forces): RMS position error (1e-4, 3e-4, 1e-3) at step 60 (the impact) 3.3e-3, 4.0e-3 and
/// 1.3e-2 m, at step 150 6.2e-3, 1.5e-2 and 4.6e-2 m, at rest (step 599) 5.0e-4, 7.0e-3 and
/// 7.2e-2 m.
const CG_FORCE_TOLERANCE: f64 = 1e-4;

/// A contact held from the last substep stays held against a pull of its own forces (`n·rhs`)
/// of at most this fraction of its force scale (`h Σ|f|`, as in [`CG_FORCE_TOLERANCE`]); a
/// harder pull releases it. Holding lets the neighbours that press a vertex down keep it down
/// (only the reaction after the solve tells whether they do), and without it a balloon at rest
/// chatters on the ground (22.7 against 6.1 CG iterations a step, tests/ffi_body_ground.rs). But
/// a held vertex pulled hard is held by a sticky obstacle, with a force no neighbour gives: at an
/// impact that creased the contact patch under the issue-5 balloon in 3 of 10 drops (1 thread,
/// drop heights 0 to 25 mm above the issue's), and the crease never opened (a spring surface has
/// no bending stiffness). Measured on those 10 drops (benches/body_balloon.rs,
/// `BODY_DROP_OFFSET`), creased drops and CG iterations a step: no limit 3 and 10.75; a limit of
/// 2, 1, 0.5, 0.25 and 0.1 of the force scale 3, 2, 0, 0 and 0 drops, 10.75, 10.06, 8.44, 8.72 and
/// 8.97 iterations; on eight drops 3 cm to 1 m higher, none with 0.25 or 0.1 against 2 without.
/// Releasing every held contact that pulled (a second solve with them released, the active-set
/// way) creased none either but took 10.1-10.4 iterations a step. The issue's own drop, which
/// did not crease, takes 9.5 iterations a step with this limit against 7.5 without: its rim no
/// longer sticks, and its patch takes longer to settle (steps 250-450: 1,773 iterations against
/// 960; the last 100 steps 516 against 424).
///
/// With 4 substeps a step the impact crumples the lower half of that balloon whatever the
/// contacts do (at step 50 of a drop 1119 faces turned inward, V/V0 0.78; and the same with no
/// holding at all): a spring surface without bending stiffness or self-contact buckles under a
/// 5.4 m/s impact, and the larger numerical damping of one step of implicit Euler is what
/// smooths it at h = 1/60 s.
const HELD_PULL_SHARE: f32 = 0.1;

/// A moving vertex within this distance of an obstacle's surface (or behind it) starts the
/// solve on it (`start_vertex`).
const TOUCH_MARGIN: f32 = 1e-6;

/// Vertices per parallel chunk (fixed, so the result does not depend on the thread count; whole
/// slices of the coupling layout). On the issue-5 balloon (benches/body_balloon.rs, 2 threads,
/// ten alternating pairs of runs, the same CG iterations step for step) 512 took the mean step
/// from 1.66 to 1.83 ms (per step the fastest of six runs: 1.28 -> 1.47), 2048 kept it (1.63 and
/// 1.63; fastest 1.03 -> 1.15).
const CHUNK: usize = 1024;
const _: () = assert!(CHUNK % SLICE == 0);

/// Springs per chunk of the spring pass: the energy's chunks, so that the pass can sum the
/// end-of-substep spring energy as `energy::state_energies` does (the terms need no sums).
const SPRING_CHUNK: usize = energy::SPRING_CHUNK;

/// The per-substep values every pass reads.
struct System<'a> {
    model: &'a Model<'a>,
    x: &'a [Vec3],
    v: &'a [Vec3],
    h: f32,
    /// Gas fragment of each vertex (and per slice, `Gas::slice_vertex_fragment`) and its ∂V/∂x,
    /// with `h² P/V` per fragment (no gas: empty).
    vertex_fragment: &'a [u32],
    slice_fragment: &'a [u32],
    gradient: &'a [Vec3],
    gas_coef: &'a [f64],
    gas_pressure: &'a [f64],
}

impl System<'_> {
    fn fragment(&self, i: usize) -> Option<usize> {
        self.vertex_fragment.get(i).filter(|&&f| f != u32::MAX).map(|&f| f as usize)
    }

    /// The assembly's gas terms of fragment `frag` (`gas_dot_v`: `Σ g·v` per fragment), the same
    /// for a slice of rows and a row alone.
    fn gas_terms(&self, frag: usize, gas_dot_v: &[f64]) -> GasTerms {
        GasTerms::new(self.gas_pressure[frag], self.gas_coef[frag], gas_dot_v[frag])
    }
}

/// The normal reaction `λ = n·(A Δv - rhs)_i` an obstacle gave row i in the solve (positive
/// when it pushed: the constraint's force along its normal, Baraff and Witkin's multiplier):
/// the row's mass and couplings (`coupling_sum`: the row's [`row_coupling_sum`] of Δv, the
/// product's sums) and its gas term `g_i (h² P/V Σ g·Δv)` (`gas`: `g_i` and the fragment's
/// [`gas_scale`]).
///
/// [`row_coupling_sum`]: super::coupling_slices::row_coupling_sum
fn contact_reaction(
    mass: f32,
    dv: Vec3A,
    coupling_sum: Vec3A,
    rhs: Vec3A,
    gas: Option<(Vec3A, f32)>,
    normal: Vec3A,
) -> f32 {
    let mut row = dv * mass + coupling_sum;
    if let Some((g, scale)) = gas {
        row += g * scale;
    }
    normal.dot(row - rhs)
}

/// A chunk of vertices for the assembly pass, with the matching parts of the output arrays.
struct AssemblyTask<'a> {
    first: usize,
    couplings: SliceRowsMut<'a>,
    /// The spring of each lane of those groups ([`CouplingSlices::springs`]).
    springs: &'a [[u32; SLICE]],
    rhs: &'a mut [Vec3A],
    inv_diag: &'a mut [SymmetricBlock],
    /// The start of the solve: Δv (holding the warm start, which the assembly replaces) and
    /// the contact filters (empty without obstacles).
    dv: &'a mut [Vec3A],
    contact_slot: &'a mut [u32],
    contact_normal: &'a mut [Vec3A],
    /// Per row whether the last substep held it on an obstacle that pushed (empty without
    /// obstacles).
    contact_held: &'a [bool],
    /// Over the chunk: `Σ g·Δv` per gas fragment (the start of the solve).
    gas: &'a mut [f64],
}

/// What the assembly of every chunk reads.
struct AssemblyInput<'a> {
    sys: &'a System<'a>,
    terms: &'a [SpringTerms],
    /// The external forces gathered before (wind), or empty.
    force: &'a [Vec3],
    gas_dot_v: &'a [f64],
    obstacles: &'a [Obstacle],
    /// The obstacles as planes where they all are, with AVX2 and FMA (`slice_update::planes_of`):
    /// then the rows of a slice that all move and touch none start eight at a time
    /// ([`free_slice_start_avx2`]).
    planes: Option<&'a [(Vec3, Vec3)]>,
}

/// The assembly of a chunk of vertices; returns its `Σ magnitude²`, `Σ |rhs|²` and whether a
/// contact holds. Compiled with AVX2 and FMA too, used where the processor has them (checked at
/// run time), with the springs' sums eight rows at a time ([`spring_sums`]: the same sums).
///
/// [`spring_sums`]: super::spring_sums
fn assemble_chunk(input: &AssemblyInput, t: AssemblyTask) -> (f64, f64, bool) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the processor has the features the function is compiled for (checked above).
        return unsafe { assemble_chunk_avx2_fma(input, t) };
    }
    assemble_chunk_with::<false>(input, t)
}

/// [`assemble_chunk`] with AVX2 and FMA.
///
/// # Safety
/// The processor must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn assemble_chunk_avx2_fma(input: &AssemblyInput, t: AssemblyTask) -> (f64, f64, bool) {
    assemble_chunk_with::<true>(input, t)
}

/// [`assemble_chunk`]; with `SLICES` the springs' sums of each slice come from
/// [`slice_spring_sums_avx2`] (only where the processor has AVX2, and the layout's springs are
/// there), and so does the per-vertex part of its rows where they allow
/// ([`slice_vertices_avx2`]: the same bits), else row by row.
#[inline(always)]
fn assemble_chunk_with<const SLICES: bool>(input: &AssemblyInput, t: AssemblyTask) -> (f64, f64, bool) {
    let AssemblyInput { sys, terms, force, gas_dot_v, obstacles, planes } = *input;
    let model = sys.model;
    let mut t = t;
    t.gas.fill(0.0);
    let mut run = GasRun::default();
    let (mut magnitude_squared, mut rhs_squared, mut any_contact) = (0.0f64, 0.0f64, false);
    let mut contacts = 0;
    let rows = t.rhs.len();
    let slices = SLICES && t.springs.len() == t.couplings.groups.len();
    let mut slice_sums = SliceSums::default();
    // The per-vertex part of a slice's rows at once where they can (`slice_vertices`).
    #[cfg_attr(not(target_arch = "x86_64"), allow(unused_mut))]
    // (The slice's right sides and inverted blocks go into its rows of `t` at once; its force
    // magnitudes are kept here.)
    let mut slice_vertices: Option<[f32; SLICE]> = None;
    let constants = VertexConstants {
        h: sys.h,
        gravity: model.settings.gravity,
        gravity_length: model.settings.gravity.length(),
        stiffness: model.settings.spring_stiffness,
    };
    let mut k = 0;
    while k < rows {
        let i = t.first + k;
        let lane = i % SLICE;
        if slices && lane == 0 {
            let groups = t.couplings.groups_of(i);
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `SLICES` is set only where the processor has AVX2 and FMA.
            unsafe {
                slice_sums =
                    slice_spring_sums_avx2(&mut t.couplings.groups[groups.clone()], &t.springs[groups], terms, i);
                slice_vertices =
                    slice_vertex_gas(sys, i, k + SLICE <= rows && force.is_empty(), gas_dot_v).map(|gas| {
                        slice_vertices_avx2(
                            &slice_sums,
                            &model.mass[i..i + SLICE],
                            constants,
                            gas,
                            &mut t.rhs[k..k + SLICE],
                            &mut t.inv_diag[k..k + SLICE],
                        )
                    });
            }
            #[cfg(not(target_arch = "x86_64"))]
            unreachable!("{groups:?}");
            // The eight rows at once where they all move and touch nothing: each starts from its
            // warm start, free (`start_vertex`), and adds its terms to the sums in row order.
            #[cfg(target_arch = "x86_64")]
            if let (Some(magnitudes), Some(planes)) = (&slice_vertices, planes)
                && model.inv_mass[i..i + SLICE].iter().all(|&w| w > 0.0)
            {
                let rows = k..k + SLICE;
                let gradient = if sys.slice_fragment.is_empty() || sys.slice_fragment[i / SLICE] == u32::MAX {
                    &[][..]
                } else {
                    sys.gradient
                };
                // SAFETY: AVX2 and FMA (`planes` is given only with them); the slice's rows are
                // rows of the chunk (`slice_vertices` is made only then) and of x and the gradient.
                let start = unsafe {
                    let vertices = (&t.rhs[rows.clone()], magnitudes);
                    free_slice_start_avx2(vertices, sys.x, gradient, &t.dv[rows.clone()], i, planes, TOUCH_MARGIN)
                };
                if let Some(start) = start {
                    // (The right sides and inverted blocks are in place.)
                    if let Some(slots) = t.contact_slot.get_mut(rows) {
                        slots.fill(u32::MAX);
                    }
                    for lane in 0..SLICE {
                        if !gradient.is_empty() {
                            run.add(t.gas, sys.slice_fragment[i / SLICE] as usize, start.gas_dot[lane]);
                        }
                        magnitude_squared += start.magnitude_squared[lane];
                        rhs_squared += start.rhs_squared[lane];
                    }
                    k += SLICE;
                    continue;
                }
            }
        }
        let (mut rhs, mut inv_diag, magnitude) = match &slice_vertices {
            Some(magnitudes) => (t.rhs[k], t.inv_diag[k], magnitudes[lane]),
            None => {
                let springs = if slices {
                    slice_sums.lane(lane)
                } else {
                    row_spring_sums(model.springs.around(i), i, terms, t.couplings.row(i))
                };
                let gas = sys.fragment(i).map(|frag| RowGas {
                    gradient: Vec3A::from(sys.gradient[i]),
                    terms: sys.gas_terms(frag, gas_dot_v),
                });
                // The same operations as `external_forces` and `add_gas_forces_parallel`.
                let f = force.get(i).copied().unwrap_or_else(|| {
                    let mut f = model.settings.gravity * model.mass[i];
                    if let Some(gas) = gas {
                        f += sys.gradient[i] * gas.terms.pressure;
                    }
                    f
                });
                vertex_blocks(springs, model.mass[i], f, gas, constants)
            }
        };
        if model.inv_mass[i] == 0.0 {
            rhs = Vec3A::ZERO;
        }
        let held = t.contact_held.get(k).copied().unwrap_or(false);
        let hold_limit = HELD_PULL_SHARE * sys.h * magnitude;
        let (dv, filter) =
            start_vertex(model, obstacles, i, sys.x[i], sys.v[i], rhs, t.dv[k], held, hold_limit, &mut inv_diag);
        t.rhs[k] = rhs;
        t.inv_diag[k] = inv_diag;
        t.dv[k] = dv;
        if let Some(frag) = sys.fragment(i) {
            run.add(t.gas, frag, Vec3A::from(sys.gradient[i]).dot(dv) as f64);
        }
        if let Some(slot) = t.contact_slot.get_mut(k) {
            *slot = match filter {
                ContactFilter::Free => u32::MAX,
                ContactFilter::Slide(normal) => {
                    any_contact = true;
                    t.contact_normal[contacts] = normal.into();
                    contacts += 1;
                    (t.first + contacts - 1) as u32
                }
            };
        }
        magnitude_squared += (magnitude as f64) * (magnitude as f64);
        rhs_squared += rhs.length_squared() as f64;
        k += 1;
    }
    run.flush(t.gas);
    (magnitude_squared, rhs_squared, any_contact)
}

/// Whether the eight rows from `first` can be assembled at once (`whole`: they are all in the
/// chunk and no external force was gathered; and they share their gas fragment or have none),
/// and with what gas: `Some(None)` without, `Some(Some(gas))` with.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
fn slice_vertex_gas<'a>(sys: &'a System, first: usize, whole: bool, gas_dot_v: &[f64]) -> Option<Option<SliceGas<'a>>> {
    if !whole {
        return None;
    }
    if sys.vertex_fragment.is_empty() {
        return Some(None);
    }
    let frag = match sys.slice_fragment[first / SLICE] {
        gas::MIXED_FRAGMENTS => return None,
        u32::MAX => return Some(None),
        f => f as usize,
    };
    Some(Some(SliceGas { gradient: &sys.gradient[first..], terms: sys.gas_terms(frag, gas_dot_v) }))
}

/// The start of the solve at vertex i: Δv from the warm start `guess` and, if it rests on an
/// obstacle, its contact filter, with `inv_diag` restricted to the contact's tangent plane.
///
/// Contacts inside the solve (Baraff and Witkin 1998, modified PCG): a vertex resting on an
/// obstacle, moving and pushed into it, gets the constraint (v + Δv)·n = 0; so does one the
/// obstacle held and pushed in the last substep (`held`), even if its own forces now pull it
/// away by up to `hold_limit` ([`HELD_PULL_SHARE`]): its neighbours may still press it down,
/// which only the reaction after a solve tells.
/// Coulomb friction (SPEC 2.3) follows the solve, bounded by the contact's normal reaction
/// (`substep`); restitution with the other integrators' contact response.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn start_vertex(
    model: &Model,
    obstacles: &[Obstacle],
    i: usize,
    x: Vec3,
    v: Vec3,
    rhs: Vec3A,
    guess: Vec3A,
    held: bool,
    hold_limit: f32,
    inv_diag: &mut SymmetricBlock,
) -> (Vec3A, ContactFilter) {
    if model.inv_mass[i] == 0.0 {
        return (Vec3A::ZERO, ContactFilter::Free);
    }
    let Some(normal) = (!obstacles.is_empty()).then(|| touching(x, obstacles, TOUCH_MARGIN)).flatten() else {
        return (guess, ContactFilter::Free);
    };
    // Released when moving away, or pulled away by its own forces unless it was held and they
    // pull it by at most `hold_limit` (the contact cannot pull).
    let pull = Vec3::from(rhs).dot(normal);
    if v.dot(normal) > 0.0 || (pull > 0.0 && (!held || pull > hold_limit)) {
        return (guess, ContactFilter::Free);
    }
    let dv = Vec3::from(guess);
    let dv = dv - normal * (dv.dot(normal) + v.dot(normal));
    // Block Jacobi on the tangent plane: the inverse of the diagonal block restricted to it,
    // `D⁻¹ - D⁻¹n nᵀD⁻¹ / (nᵀD⁻¹n)` (z = D⁻¹(r - λ n) with n·z = 0). Filtering the unrestricted
    // inverse instead overstates the tangential response where springs couple the normal to the
    // tangent (the rim of a contact patch) and stalls the iterations.
    let n = Vec3A::from(normal);
    let dn = inv_diag.apply(n);
    let ndn = n.dot(dn);
    if ndn > 0.0 {
        let mut restricted = inv_diag.parts();
        restricted.add_outer(dn, -1.0 / ndn);
        *inv_diag = restricted.stored();
    }
    (dv.into(), ContactFilter::Slide(normal))
}

/// A chunk of rows of a product with the system matrix.
struct ProductTask<'a> {
    first: usize,
    out: &'a mut [Vec3A],
    /// `Σ input·out` over the chunk.
    dot: f64,
}

/// Rows `first..` of `A input` for the system matrix `M - h² K - h D` (pinned rows zero, contact
/// constraints filtered out when `contact` is not empty); `gas_scale` holds `h² P/V Σ g·input` per
/// fragment ([`gas_scale`]). Eight rows at a time ([`product_slices`]).
fn product_rows(
    sys: &System,
    contact: ContactRows,
    couplings: CheckedCouplings,
    input: &[Vec3A],
    gas_scale: &[f32],
    task: &mut ProductTask,
) {
    let model = sys.model;
    let rows = task.first..task.first + task.out.len();
    let terms = RowTerms {
        mass: model.mass,
        inv_mass: model.inv_mass,
        fragment: sys.vertex_fragment,
        slice_fragment: sys.slice_fragment,
        gradient: if sys.vertex_fragment.is_empty() { &[] } else { sys.gradient },
        gas_scale,
        contact_slot: contact.slot,
        contact_normal: contact.normal,
    };
    task.dot = product_slices(couplings, input, rows, &terms, task.out);
}

/// `Σ g·v` per gas fragment over a chunk's rows (`first` a multiple of [`SLICE`]; `fragment`,
/// `slice_fragment`, `gradient` and `v` hold the chunk's rows and slices) into `out`. A slice
/// whose rows share a fragment goes eight rows at once with AVX2 and FMA, its dots summed
/// within the slice as the direction pass sums `Σ g·p` (`direction_rows_avx2`), then added to
/// the fragment's running sum; other rows one at a time. Row by row, each f64 addition waited
/// for the last (about 1% of a one-thread step on the issue-5 balloon). The sums depend on
/// which path ran (not on the thread count): the same processor always takes the same one.
fn gas_dots_rows((fragment, slice_fragment, gradient): (&[u32], &[u32], &[Vec3]), v: &[Vec3], out: &mut [f64]) {
    out.fill(0.0);
    let n = v.len();
    assert!(fragment.len() == n && gradient.len() == n && slice_fragment.len() == n.div_ceil(SLICE));
    #[cfg(target_arch = "x86_64")]
    let slices = std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma");
    let mut run = GasRun::default();
    let mut k = 0;
    while k < n {
        #[cfg(target_arch = "x86_64")]
        if slices && k % SLICE == 0 && k + SLICE <= n {
            let shared = slice_fragment[k / SLICE];
            if shared == u32::MAX {
                k += SLICE;
                continue;
            }
            if shared != gas::MIXED_FRAGMENTS {
                // SAFETY: AVX2 and FMA (checked above); rows k..k + 8 of both arrays.
                let sum = unsafe { slice_dot_avx2(gradient, v, k) };
                run.add(out, shared as usize, sum);
                k += SLICE;
                continue;
            }
        }
        if fragment[k] != u32::MAX {
            run.add(out, fragment[k] as usize, Vec3A::from(gradient[k]).dot(Vec3A::from(v[k])) as f64);
        }
        k += 1;
    }
    run.flush(out);
}

/// `Σ a·b` over rows `first..first + 8`: the eight dots in f32 (fused multiply-adds), widened
/// and summed in f64 in the order of the direction pass's slice sums.
///
/// # Safety
/// The processor must have AVX2 and FMA; `first + 8` rows must be in `a` and `b`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn slice_dot_avx2(a: &[Vec3], b: &[Vec3], first: usize) -> f64 {
    use std::arch::x86_64::*;
    assert!(first + SLICE <= a.len() && first + SLICE <= b.len());
    // SAFETY: rows first..first + 8 of both (asserted above).
    let ((ax, ay, az), (bx, by, bz)) = unsafe { (load_points_transposed(a, first), load_points_transposed(b, first)) };
    lanes_sum_f64(_mm256_fmadd_ps(az, bz, _mm256_fmadd_ps(ay, by, _mm256_mul_ps(ax, bx))))
}

/// The eight lanes of `v` widened and summed in f64: lanes l and l + 4 first, then pairwise.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn lanes_sum_f64(v: std::arch::x86_64::__m256) -> f64 {
    use std::arch::x86_64::*;
    let wide =
        _mm256_add_pd(_mm256_cvtps_pd(_mm256_castps256_ps128(v)), _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(v)));
    let half = _mm_add_pd(_mm256_castpd256_pd128(wide), _mm256_extractf128_pd::<1>(wide));
    _mm_cvtsd_f64(_mm_add_sd(half, _mm_unpackhi_pd(half, half)))
}

/// `p = z + β p` (z with the coarse correction) on the rows `first..` of a chunk, leaving the
/// chunk's `Σ g·p` per fragment in `gas`.
#[allow(clippy::too_many_arguments)]
fn direction_chunk(
    sys: &System,
    first: usize,
    p: &mut [Vec3A],
    z: &[Vec3A],
    coarse: Option<(&CoarseView, &[Vec3A])>,
    contact: ContactRows,
    beta: f32,
    gas: &mut [f64],
) {
    gas.fill(0.0);
    let rows = first..first + p.len();
    // The chunk's rows of every array, sliced once: indexing the whole arrays per vertex (with
    // their bounds checks and the optional arrays' lookups) made this pass, run once per
    // iteration, cost as many instructions as a product with the matrix (cachegrind).
    let z = &z[rows.clone()];
    let inv_mass = &sys.model.inv_mass[rows.clone()];
    let contact = contact.rows(rows.clone());
    let fragment = sys.vertex_fragment.get(rows.clone()).unwrap_or(&[]);
    // (A chunk starts a slice: CHUNK is a multiple of SLICE.)
    let slices = sys.slice_fragment.get(rows.start / SLICE..rows.end.div_ceil(SLICE)).unwrap_or(&[]);
    let gradient = sys.gradient.get(rows.clone()).unwrap_or(&[]);
    if let Some((view, solution)) = coarse.filter(|(view, _)| view.rows_of(rows.clone()).is_none()) {
        // A vertex the coarse level does not know (never after a split, which extends it): the
        // general path, with a zero correction there.
        let mut run = GasRun::default();
        for k in 0..p.len() {
            let i = first + k;
            let mut zi = z[k];
            if inv_mass[k] > 0.0 {
                let c = view.correction(i, solution);
                zi += if contact.is_empty() { c } else { contact.apply(k, c) };
            }
            let value = zi + p[k] * beta;
            p[k] = value;
            if let Some(&frag) = fragment.get(k).filter(|&&f| f != u32::MAX) {
                run.add(gas, frag as usize, Vec3A::from(gradient[k]).dot(value) as f64);
            }
        }
        run.flush(gas);
        return;
    }
    let coarse = coarse.and_then(|(view, solution)| Some((view.rows_of(rows.clone())?, solution)));
    let gas_rows = (fragment, slices, gradient);
    match (coarse, contact.is_empty(), fragment.is_empty()) {
        (Some(coarse), true, true) => {
            direction_rows::<true, false, false>(p, z, inv_mass, coarse, contact, gas_rows, beta, gas)
        }
        (Some(coarse), true, false) => {
            direction_rows::<true, false, true>(p, z, inv_mass, coarse, contact, gas_rows, beta, gas)
        }
        (Some(coarse), false, true) => {
            direction_rows::<true, true, false>(p, z, inv_mass, coarse, contact, gas_rows, beta, gas)
        }
        (Some(coarse), false, false) => {
            direction_rows::<true, true, true>(p, z, inv_mass, coarse, contact, gas_rows, beta, gas)
        }
        (None, _, true) => {
            direction_rows::<false, false, false>(p, z, inv_mass, (&[], &[]), contact, gas_rows, beta, gas)
        }
        (None, _, false) => {
            direction_rows::<false, false, true>(p, z, inv_mass, (&[], &[]), contact, gas_rows, beta, gas)
        }
    }
}

/// [`direction_chunk`] on a chunk's rows (every slice but `solution` holds exactly the chunk's
/// rows), for one combination of a coarse level, contacts and gas (so the loop tests none of
/// them per vertex). Without the coarse level the contacts are not read: z is filtered already.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn direction_rows<const COARSE: bool, const CONTACT: bool, const GAS: bool>(
    p: &mut [Vec3A],
    z: &[Vec3A],
    inv_mass: &[f32],
    (row_of, solution): (&[u32], &[Vec3A]),
    contact: ContactRows,
    (fragment, slice_fragment, gradient): (&[u32], &[u32], &[Vec3]),
    beta: f32,
    gas: &mut [f64],
) {
    let n = p.len();
    assert!(z.len() == n && inv_mass.len() == n);
    assert!(!COARSE || row_of.len() == n);
    assert!(!CONTACT || contact.slot.len() == n);
    assert!(!GAS || (fragment.len() == n && slice_fragment.len() == n.div_ceil(SLICE) && gradient.len() == n));
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the processor has the features the function is compiled for (checked above).
        unsafe {
            direction_rows_avx2::<COARSE, CONTACT, GAS>(
                p,
                z,
                inv_mass,
                (row_of, solution),
                contact,
                (fragment, slice_fragment, gradient),
                beta,
                gas,
            )
        };
        return;
    }
    // `Σ g·p` of the current run of vertices of one fragment, in a register: added into `gas`
    // through memory at every vertex it made a chain of loads and stores that set the pace of
    // this pass.
    let mut run = GasRun::default();
    for k in 0..n {
        let mut zi = z[k];
        if COARSE && inv_mass[k] > 0.0 {
            // The coarse correction, filtered like the rest of z.
            let c = solution[row_of[k] as usize];
            zi += if CONTACT { contact.apply(k, c) } else { c };
        }
        let value = zi + p[k] * beta;
        p[k] = value;
        if GAS && fragment[k] != u32::MAX {
            run.add(gas, fragment[k] as usize, Vec3A::from(gradient[k]).dot(value) as f64);
        }
    }
    run.flush(gas);
}

/// [`direction_rows`] with AVX2 and FMA (the caller checked the slices' lengths), eight rows at
/// a time: `z + c + β p` two rows to a 256-bit register (the same bits as one row at a time),
/// and `Σ g·p` of eight rows of one fragment in registers, one f64 sum added to the fragment's
/// (one row at a time in slices of mixed fragments and in the last rows). One row at a time
/// this pass took about 42 instructions a row (callgrind, issue-5 balloon), once per iteration;
/// two rows to a register with `g·p` still one row at a time, more.
///
/// Measured, for a p stored in 16-bit floats (half the bytes of the vector that the product
/// gathers and three passes stream; not built): p rounded here to 11 bits of precision (f16's)
/// took ten drops of the issue-5 balloon 0 to 25 mm higher (one thread) 8.56 CG iterations a step
/// against 8.54, to 8 bits (bfloat16's) 8.70. f16 would need a scale per solve for its range.
///
/// # Safety
/// The processor must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn direction_rows_avx2<const COARSE: bool, const CONTACT: bool, const GAS: bool>(
    p: &mut [Vec3A],
    z: &[Vec3A],
    inv_mass: &[f32],
    (row_of, solution): (&[u32], &[Vec3A]),
    contact: ContactRows,
    (fragment, slice_fragment, gradient): (&[u32], &[u32], &[Vec3]),
    beta: f32,
    gas: &mut [f64],
) {
    use std::arch::x86_64::*;
    let n = p.len();
    let b = _mm256_set1_ps(beta);
    let mut run = GasRun::default();
    // Row k's coarse correction, filtered like the rest of z (none at a pinned vertex).
    let correction = |k: usize| -> Vec3A {
        if COARSE && inv_mass[k] > 0.0 {
            let c = solution[row_of[k] as usize];
            if CONTACT { contact.apply(k, c) } else { c }
        } else {
            Vec3A::ZERO
        }
    };
    let pp = p.as_mut_ptr() as *mut f32;
    let zp = z.as_ptr() as *const f32;
    let whole = n - n % SLICE;
    let free = _mm256_set1_epi32(-1);
    for first in (0..whole).step_by(SLICE) {
        // Rows that all move and touch nothing take their corrections straight from the
        // solution, two to a register (the same values as `correction`, which went through an
        // array on the stack row by row): on the issue-5 balloon (one thread, two profiles each
        // way) this pass went from 0.40-0.44 to 0.355-0.371 of the product's time, about 1.3% of
        // a step, with the same CG iterations step for step.
        // SAFETY: rows first..first + 8 < n of inv_mass and (with contacts) of the slots.
        let plain = COARSE
            && unsafe {
                let moving =
                    _mm256_cmp_ps::<_CMP_GT_OQ>(_mm256_loadu_ps(inv_mass.as_ptr().add(first)), _mm256_setzero_ps());
                _mm256_movemask_ps(moving) == 0xFF
                    && (!CONTACT || {
                        let slots = _mm256_loadu_si256(contact.slot.as_ptr().add(first) as *const __m256i);
                        _mm256_movemask_epi8(_mm256_cmpeq_epi32(slots, free)) == -1
                    })
            };
        let c: [Vec3A; SLICE] =
            if plain { [Vec3A::ZERO; SLICE] } else { std::array::from_fn(|lane| correction(first + lane)) };
        let mut pairs = [_mm256_setzero_ps(); SLICE / 2];
        for (q, pair) in pairs.iter_mut().enumerate() {
            let k = first + 2 * q;
            // SAFETY: rows k and k + 1 < n of p and z (eight f32), unaligned 32-byte accesses;
            // the factor rows of the coarse level are rows of its solution.
            unsafe {
                let correction = if plain {
                    let (a, b) = (solution[row_of[k] as usize], solution[row_of[k + 1] as usize]);
                    _mm256_set_m128(b.into(), a.into())
                } else {
                    _mm256_set_m128(c[2 * q + 1].into(), c[2 * q].into())
                };
                let zc = _mm256_add_ps(_mm256_loadu_ps(zp.add(4 * k)), correction);
                // `(z + c) + p β` without a fused multiply-add: the same bits as one row at a time.
                *pair = _mm256_add_ps(zc, _mm256_mul_ps(_mm256_loadu_ps(pp.add(4 * k)), b));
                _mm256_storeu_ps(pp.add(4 * k), *pair);
            }
        }
        if !GAS {
            continue;
        }
        let shared = slice_fragment[first / SLICE];
        if shared != gas::MIXED_FRAGMENTS {
            if shared == u32::MAX {
                continue;
            }
            // The eight rows as x, y and z lanes: pairs (0 1), (2 3), (4 5), (6 7) regrouped as
            // (0 | 4), (1 | 5), (2 | 6), (3 | 7), then transposed.
            let r04 = _mm256_permute2f128_ps::<0x20>(pairs[0], pairs[2]);
            let r15 = _mm256_permute2f128_ps::<0x31>(pairs[0], pairs[2]);
            let r26 = _mm256_permute2f128_ps::<0x20>(pairs[1], pairs[3]);
            let r37 = _mm256_permute2f128_ps::<0x31>(pairs[1], pairs[3]);
            let xy01 = _mm256_unpacklo_ps(r04, r15);
            let xy23 = _mm256_unpacklo_ps(r26, r37);
            let zw01 = _mm256_unpackhi_ps(r04, r15);
            let zw23 = _mm256_unpackhi_ps(r26, r37);
            let (px, py, pz) = (
                _mm256_shuffle_ps::<0x44>(xy01, xy23),
                _mm256_shuffle_ps::<0xEE>(xy01, xy23),
                _mm256_shuffle_ps::<0x44>(zw01, zw23),
            );
            // SAFETY: first + 8 <= n = gradient.len().
            let (gx, gy, gz) = unsafe { load_points_transposed(gradient, first) };
            let sum = lanes_sum_f64(_mm256_fmadd_ps(gz, pz, _mm256_fmadd_ps(gy, py, _mm256_mul_ps(gx, px))));
            run.add(gas, shared as usize, sum);
        } else {
            for (q, pair) in pairs.iter().enumerate() {
                let k = first + 2 * q;
                let rows = [Vec3A::from(_mm256_castps256_ps128(*pair)), Vec3A::from(_mm256_extractf128_ps::<1>(*pair))];
                for (lane, value) in rows.iter().enumerate() {
                    if fragment[k + lane] != u32::MAX {
                        run.add(gas, fragment[k + lane] as usize, Vec3A::from(gradient[k + lane]).dot(*value) as f64);
                    }
                }
            }
        }
    }
    for k in whole..n {
        let value = z[k] + correction(k) + p[k] * beta;
        p[k] = value;
        if GAS && fragment[k] != u32::MAX {
            run.add(gas, fragment[k] as usize, Vec3A::from(gradient[k]).dot(value) as f64);
        }
    }
    run.flush(gas);
}

/// What the conjugate-gradient solve reads: the system, its right side and preconditioner, and
/// the stopping rule.
struct SolveInput<'a> {
    sys: &'a System<'a>,
    contact: ContactRows<'a>,
    coupling: CheckedCouplings<'a>,
    rhs: &'a [Vec3A],
    inv_diag: &'a [SymmetricBlock],
    any_contact: bool,
    fragments: usize,
    /// Squared residual norm at which the solve stops.
    tolerance: f64,
    max_iterations: usize,
}

/// The vectors and sums that the members of a team share during the assembly and the solve.
/// SAFETY (of every `whole` and `part` on them): in each pass (between two barriers) a member
/// writes only the rows of the chunks it claimed in that pass ([`Team::claim`]: each chunk goes
/// to exactly one member) of the arrays the pass updates, and reads rows of other chunks only of
/// arrays that no member writes in that pass.
struct Shared<'a> {
    coupling_offsets: &'a [u32],
    coupling_springs: &'a [[u32; SLICE]],
    couplings: SharedSlice<'a, CouplingGroup>,
    rhs: SharedSlice<'a, Vec3A>,
    inv_diag: SharedSlice<'a, SymmetricBlock>,
    contact_slot: SharedSlice<'a, u32>,
    contact_normal: SharedSlice<'a, Vec3A>,
    contact_reaction: SharedSlice<'a, f32>,
    contact_held: SharedSlice<'a, bool>,
    terms: SharedSlice<'a, SpringTerms>,
    dv: SharedSlice<'a, Vec3A>,
    r: SharedSlice<'a, Vec3A>,
    z: SharedSlice<'a, Vec3A>,
    p: SharedSlice<'a, Vec3A>,
    ap: SharedSlice<'a, Vec3A>,
    /// Per chunk and fragment: `Σ g·Δv` (the assembly), then `Σ g·p` (the solve).
    gas: SharedSlice<'a, f64>,
    /// Per chunk and fragment `Σ g·v`.
    gas_v: SharedSlice<'a, f64>,
    /// Per chunk: `p·Ap`, `r·r`, `r·z` of the solve; `Σ magnitude²`, `Σ |rhs|²` and whether a
    /// contact holds (1) of the assembly.
    chunk_pap: SharedSlice<'a, f64>,
    chunk_rr: SharedSlice<'a, f64>,
    chunk_rz: SharedSlice<'a, f64>,
    chunk_magnitude: SharedSlice<'a, f64>,
    chunk_rhs: SharedSlice<'a, f64>,
    chunk_contact: SharedSlice<'a, bool>,
    chunk_largest_other: SharedSlice<'a, u32>,
    /// The coarse level: what every member reads, the restricted residual and the solution (in
    /// the factor's row order) and the parts of `r·z` of the two halves of the top dissection
    /// and of its separator.
    coarse: Option<CoarseView<'a>>,
    coarse_rhs: SharedSlice<'a, Vec3A>,
    coarse_solution: SharedSlice<'a, Vec3A>,
    coarse_own: SharedSlice<'a, Vec3A>,
    coarse_separator_parts: SharedSlice<'a, Vec3A>,
    coarse_dots: SharedSlice<'a, f64>,
    /// Each member's per-fragment values ([`Shared::member_gas`]).
    member_gas: SharedSlice<'a, f64>,
    member_scale: SharedSlice<'a, f32>,
}

/// A team member's own per-fragment values of a substep: `Σ g·v`, `Σ g·p` and `Σ g·Δv`, and the gas
/// scales of the products ([`gas_scale`]) and of the solution.
struct MemberGas<'a> {
    /// `Σ g·v` of the assembly.
    dot_v: &'a mut [f64],
    dot_p: &'a mut [f64],
    dot_dv: &'a mut [f64],
    scale: &'a mut [f32],
    end_scale: &'a mut [f32],
}

/// The length of a member's share of the [`MemberGas`] buffers holding `values` values: rounded
/// up to 16 values and 16 more, so that 64 bytes or more (f32) lie between two members' values
/// wherever the buffer starts, and two members never write the same cache line (they write
/// these every iteration).
fn member_stride(values: usize) -> usize {
    values.next_multiple_of(16) + 16
}

/// Per-chunk sums of the team passes.
#[derive(Default)]
struct ChunkSums {
    pap: Vec<f64>,
    rr: Vec<f64>,
    rz: Vec<f64>,
    magnitude: Vec<f64>,
    rhs: Vec<f64>,
    contact: Vec<bool>,
    /// The largest other-end offset of the chunk's coupling groups (for [`CheckedCouplings`]).
    largest_other: Vec<u32>,
    /// Whether every position and velocity of the chunk is finite after the last pass.
    finite: Vec<bool>,
    /// Per chunk of `energy::SPRING_CHUNK` springs its energy and largest strain, per chunk of
    /// `energy::VERTEX_CHUNK` vertices its kinetic and gravitational energy (the end energies).
    end_springs: Vec<(f64, f32)>,
    end_vertices: Vec<(f64, f64)>,
    gas_v: Vec<f64>,
    /// `Σ (rhs - m Δv)`, `Σ m` and whether no vertex is pinned.
    momentum: Vec<(glam::DVec3, f64, bool)>,
    /// The parts of the coarse `r·z`.
    coarse_dots: Vec<f64>,
    /// Per chunk of faces ([`gas::FACE_CHUNK`]) and fragment (at least one) the gas's 6 V.
    gas_six_v: Vec<f64>,
    /// Per team member, its own copies of the solve's per-fragment values ([`MemberGas`]):
    /// each member computes them itself (no barrier to hand them over), and vectors made per
    /// iteration were allocations in the loop.
    member_gas: Vec<f64>,
    member_scale: Vec<f32>,
}

impl ChunkSums {
    fn resize(&mut self, chunks: usize, fragments: usize) {
        for v in [&mut self.pap, &mut self.rr, &mut self.rz, &mut self.magnitude, &mut self.rhs] {
            v.clear();
            v.resize(chunks, 0.0);
        }
        self.contact.clear();
        self.contact.resize(chunks, false);
        self.largest_other.clear();
        self.largest_other.resize(chunks, 0);
        self.finite.clear();
        self.finite.resize(chunks, false);
        self.gas_v.clear();
        self.gas_v.resize(chunks * fragments, 0.0);
        self.momentum.clear();
        self.momentum.resize(chunks, (glam::DVec3::ZERO, 0.0, true));
        self.coarse_dots.resize(3, 0.0);
    }

    /// Room for [`MemberGas`] of `members` members and `fragments` fragments.
    fn resize_member_gas(&mut self, members: usize, fragments: usize) {
        self.member_gas.resize(members * member_stride(3 * fragments), 0.0);
        self.member_scale.resize(members * member_stride(2 * fragments), 0.0);
    }

    fn memory_bytes(&self) -> usize {
        (self.pap.capacity()
            + self.rr.capacity()
            + self.rz.capacity()
            + self.magnitude.capacity()
            + self.rhs.capacity()
            + self.gas_v.capacity()
            + self.gas_six_v.capacity()
            + self.member_gas.capacity())
            * 8
            + self.member_scale.capacity() * 4
            + self.contact.capacity()
            + self.largest_other.capacity() * 4
            + self.finite.capacity()
            + self.end_springs.capacity() * 16
            + self.end_vertices.capacity() * 16
            + self.momentum.capacity() * std::mem::size_of::<(glam::DVec3, f64, bool)>()
    }
}

impl Shared<'_> {
    /// This member's [`MemberGas`] for `fragments` fragments.
    fn member_gas(&self, team: &Team, fragments: usize) -> MemberGas<'_> {
        let first = team.index() * member_stride(3 * fragments);
        let first_scale = team.index() * member_stride(2 * fragments);
        // SAFETY: each member's own ranges (sized for every member the pool can run), used by
        // it alone, once per substep.
        unsafe {
            MemberGas {
                dot_v: self.member_gas.part(first..first + fragments),
                dot_p: self.member_gas.part(first + fragments..first + 2 * fragments),
                dot_dv: self.member_gas.part(first + 2 * fragments..first + 3 * fragments),
                scale: self.member_scale.part(first_scale..first_scale + fragments),
                end_scale: self.member_scale.part(first_scale + fragments..first_scale + 2 * fragments),
            }
        }
    }

    /// The coarse system for the current residual, solved together: members 0 and 1 restrict
    /// the residual to the rows of one half of the top dissection each, solve them forward in
    /// a copy of their own and add up their half's part of the top separator's rows; after a
    /// barrier each solves the separator (its rows among themselves: a fifth of its entries on
    /// the balloon) in its copy and then its half backward (with one member, member 0 all of it
    /// in one copy: the same bits). Returns the coarse part of `r·z`, the same on every member.
    ///
    /// Member 0 solved the separator in the shared solution while member 1 waited, between two
    /// barriers: on the balloon (benches/body_balloon.rs, 2 threads, four alternating pairs) the
    /// step took 2.53-2.68 ms that way and 2.16-2.61 ms this way (6.5 -> 6.3 CG iterations per
    /// step: the separator rows are summed in another order).
    ///
    /// Measured and not kept: every member solving the whole coarse system in copies of its own
    /// (as a one-member team does: the same bits), so that no barrier is needed inside this part
    /// nor after it (each member's direction pass reads its own copy). One body, the two ways
    /// switched every other step (four runs): the step 1.09-1.18 times this one's; the coarse
    /// work a member then does costs more than the two barriers' waits.
    fn coarse_part(&self, team: &Team) -> f64 {
        let Some(view) = &self.coarse else { return 0.0 };
        let factor = view.factor;
        let y = self.coarse_solution.as_mut_ptr();
        // SAFETY: nobody writes r in this pass.
        let r = unsafe { self.r.whole() };
        // `rhs·solution` over the rows of a part (its separator only when `separator_only`).
        let dot = |node: usize, separator_only: bool| -> f64 {
            let (subtree, separator) = factor.part_rows(node);
            let rows = if separator_only { separator } else { subtree };
            // SAFETY: the rows of this part are this member's alone in this pass.
            let (rhs, solution) = unsafe { (self.coarse_rhs.part(rows.clone()), self.coarse_solution.part(rows)) };
            rhs.iter().zip(solution.iter()).map(|(a, b)| a.dot(*b) as f64).sum()
        };
        let root = factor.root();
        match factor.top_halves() {
            None => {
                if team.index() == 0 {
                    let rows = 0..factor.len();
                    // SAFETY: member 0 alone touches the coarse vectors in this pass.
                    unsafe {
                        let (rhs, solution) =
                            (self.coarse_rhs.part(rows.clone()), self.coarse_solution.part(rows.clone()));
                        view.restrict(rows, r, rhs);
                        solution.copy_from_slice(rhs);
                        factor.forward_part(root, y);
                        factor.backward_part(root, y);
                    }
                    // SAFETY: this member's slot.
                    unsafe { self.coarse_dots.part(0..3).copy_from_slice(&[dot(root, false), 0.0, 0.0]) };
                }
                team.barrier();
            }
            Some((a, b)) => {
                // Members 0 and 1 each solve a half in a copy of their own (member 0 both with
                // one member), then the top separator (small: its rows among themselves) each
                // in its copy from both halves' parts: one barrier between the halves' forward
                // and backward solves, and nobody waits for a member solving the separator
                // alone. Every row gets the same bits whoever solves it.
                let halves = [a, b];
                let me = team.index();
                let solver = |half: usize| if team.size() > 1 { half } else { 0 };
                let solves = me < 2 && (me == 0 || team.size() > 1);
                let len = factor.len();
                let (_, separator) = factor.part_rows(root);
                let separator_len = separator.len();
                if solves {
                    // SAFETY: this member's copy (members 0 and 1 have one each).
                    let own = unsafe { self.coarse_own.part(me * len..(me + 1) * len) };
                    for (h, &node) in halves.iter().enumerate().filter(|&(h, _)| solver(h) == me) {
                        let (rows, _) = factor.part_rows(node);
                        // SAFETY: the half's rows and its slot of the parts are this member's.
                        let (rhs, part) = unsafe {
                            (
                                self.coarse_rhs.part(rows.clone()),
                                self.coarse_separator_parts.part(h * separator_len..(h + 1) * separator_len),
                            )
                        };
                        view.restrict(rows.clone(), r, rhs);
                        own[rows].copy_from_slice(rhs);
                        // SAFETY: the member's own copy.
                        unsafe { factor.forward_part(node, own.as_mut_ptr()) };
                        factor.top_separator_part(h, own, part);
                    }
                    if me == 0 {
                        // SAFETY: the separator rows of the right side are member 0's.
                        let rhs = unsafe { self.coarse_rhs.part(separator.clone()) };
                        view.restrict(separator.clone(), r, rhs);
                        own[separator.clone()].copy_from_slice(rhs);
                    } else {
                        view.restrict(separator.clone(), r, &mut own[separator.clone()]);
                    }
                }
                team.barrier();
                if solves {
                    // SAFETY: as above; nobody writes the parts in this pass.
                    let (own, parts) = unsafe {
                        (self.coarse_own.part(me * len..(me + 1) * len), self.coarse_separator_parts.whole())
                    };
                    factor.top_separator_solve(own, [&parts[..separator_len], &parts[separator_len..]]);
                    for (h, &node) in halves.iter().enumerate().filter(|&(h, _)| solver(h) == me) {
                        let (rows, _) = factor.part_rows(node);
                        // SAFETY: the member's own copy; the half's rows of the right side, the
                        // solution and its dot slot are this member's.
                        unsafe {
                            factor.backward_part(node, own.as_mut_ptr());
                            self.coarse_solution.part(rows.clone()).copy_from_slice(&own[rows.clone()]);
                            self.coarse_dots.part(h..h + 1)[0] = dot(node, false);
                        }
                    }
                    if me == 0 {
                        // SAFETY: the separator rows of the solution and the last slot are
                        // member 0's.
                        unsafe {
                            self.coarse_solution.part(separator.clone()).copy_from_slice(&own[separator]);
                            self.coarse_dots.part(2..3)[0] = dot(root, true);
                        }
                    }
                }
                team.barrier();
            }
        }
        // SAFETY: nobody writes the slots in this pass.
        let dots = unsafe { self.coarse_dots.whole() };
        (dots[0] + dots[1]) + dots[2]
    }

    /// p = z + (coarse) + β p over the member's chunks, then everyone's Σ g·p.
    fn direction(&self, team: &Team, input: &SolveInput, beta: f32, gas_dot: &mut [f64]) {
        let n = self.dv.len();
        let chunks = n.div_ceil(CHUNK);
        let fragments = input.fragments;
        {
            // SAFETY: nobody writes the coarse solution in this pass.
            let coarse = self.coarse.as_ref().map(|view| (view, unsafe { self.coarse_solution.whole() }));
            team.claim(chunks, |c| {
                let rows = c * CHUNK..((c + 1) * CHUNK).min(n);
                // SAFETY: p and this chunk's gas sums are written by this member only; z is
                // written by nobody in this pass.
                let (p_rows, z_all, gas_part) =
                    unsafe { (self.p.part(rows), self.z.whole(), self.gas.part(c * fragments..(c + 1) * fragments)) };
                if beta == 0.0 {
                    p_rows.fill(Vec3A::ZERO);
                }
                direction_chunk(input.sys, c * CHUNK, p_rows, z_all, coarse, input.contact, beta, gas_part);
            });
        }
        team.barrier();
        // SAFETY: nobody writes the gas sums in this pass.
        sum_gas_partial(unsafe { self.gas.whole() }, gas_dot);
    }

    /// Preconditioned conjugate gradients (modified PCG: every vector filtered by the contacts)
    /// from the start in `dv`, whose `Σ g·Δv` per fragment and chunk is in `gas`; returns the
    /// iterations and `Σ g·Δv` per fragment of the solution (kept up as Δv moves, `Σ g·p` being
    /// known at each step: for the contacts' reactions). Run by every member of the team.
    ///
    /// Each member claims chunks of rows, its own block first ([`Team::claim`]), the passes over
    /// them are separated by barriers, and every reduction adds the chunks' partial sums in chunk
    /// order (each member adds all of them itself, so all take the same decisions), so the bits
    /// never depend on who did which chunk. The coarse solve is split between members 0 and 1
    /// ([`Shared::coarse_part`]).
    ///
    /// On the issue-5 balloon (benches/body_balloon.rs, 2 threads, alternating runs on a quiet
    /// machine) this region (with the gas gradient, the assembly and the last update in it, one
    /// fork per substep) took a step from 2.35-2.77 ms (10th percentile 1.48-1.67) with a fork
    /// and join per pass (four per iteration) to 2.03-2.07 ms (1.25-1.32); claiming instead of
    /// fixed blocks alone: 2.18-2.34 ms to 2.03-2.07 ms (the two cores of the test machine do not
    /// run equally fast).
    fn solve(&self, team: &Team, input: &SolveInput, own: &mut MemberGas) -> usize {
        let SolveInput { sys, contact, coupling, rhs, inv_diag, any_contact, fragments, tolerance, max_iterations } =
            *input;
        let Shared { dv, r, z, p, ap, gas, chunk_pap, chunk_rr, chunk_rz, .. } = self;
        let n = dv.len();
        let chunks = n.div_ceil(CHUNK);
        let rows = |c: usize| c * CHUNK..((c + 1) * CHUNK).min(n);
        {
            let MemberGas { dot_p: gas_dot, dot_dv: gas_dot_dv, scale, .. } = own;
            debug_assert_eq!(gas_dot.len(), fragments);
            // SAFETY: nobody writes the gas sums (made by the assembly) in this pass.
            sum_gas_partial(unsafe { gas.whole() }, gas_dot);
            gas_dot_dv.copy_from_slice(gas_dot);
            gas_scale(sys, gas_dot, scale);
            // r = rhs - A Δv, z = M⁻¹ r: a member's rows of r need only its own rows of A Δv, so
            // no barrier between the two.
            team.claim(chunks, |c| {
                // SAFETY: this member's chunks of ap, r, z and of the sums; Δv is written by nobody.
                let (out, r_rows, z_rows, sum, dv_all) = unsafe {
                    (ap.part(rows(c)), r.part(rows(c)), z.part(rows(c)), chunk_rz.part(c..c + 1), dv.whole())
                };
                let mut task = ProductTask { first: c * CHUNK, out, dot: 0.0 };
                product_rows(sys, contact, coupling, dv_all, scale, &mut task);
                sum[0] = initial_rows(c * CHUNK, (r_rows, z_rows), rhs, task.out, inv_diag, contact, any_contact);
            });
            team.barrier();
            // SAFETY: nobody writes the chunks' sums in this pass.
            let mut rz: f64 = unsafe { chunk_rz.whole() }.iter().sum();
            rz += self.coarse_part(team);
            self.direction(team, input, 0.0, gas_dot);
            let mut iterations = 0;
            while iterations < max_iterations {
                iterations += 1;
                gas_scale(sys, gas_dot, scale);
                team.claim(chunks, |c| {
                    // SAFETY: this member's chunks of ap and of the sums; p is written by nobody.
                    let (out, sum, p_all) = unsafe { (ap.part(rows(c)), chunk_pap.part(c..c + 1), p.whole()) };
                    let mut task = ProductTask { first: c * CHUNK, out, dot: 0.0 };
                    product_rows(sys, contact, coupling, p_all, scale, &mut task);
                    sum[0] = task.dot;
                });
                team.barrier();
                // SAFETY: nobody writes the chunks' sums in this pass.
                let pap: f64 = unsafe { chunk_pap.whole() }.iter().sum();
                if pap <= 0.0 || !pap.is_finite() {
                    break;
                }
                let alpha = (rz / pap) as f32;
                for (sum, &dot) in gas_dot_dv.iter_mut().zip(gas_dot.iter()) {
                    *sum += alpha as f64 * dot;
                }
                // Fused: Δv and r updates, z = M⁻¹ r, and the two dot products in one pass.
                team.claim(chunks, |c| {
                    // SAFETY: this member's chunks of Δv, r, z, ap and of the sums; p is written by
                    // nobody.
                    let (dv_rows, r_rows, z_rows, ap_rows, rr, rz, p_all) = unsafe {
                        (
                            dv.part(rows(c)),
                            r.part(rows(c)),
                            z.part(rows(c)),
                            ap.part(rows(c)),
                            chunk_rr.part(c..c + 1),
                            chunk_rz.part(c..c + 1),
                            p.whole(),
                        )
                    };
                    (rr[0], rz[0]) = residual_rows(
                        c * CHUNK,
                        (dv_rows, r_rows, z_rows),
                        p_all,
                        ap_rows,
                        inv_diag,
                        contact,
                        alpha,
                        any_contact,
                    );
                });
                team.barrier();
                // SAFETY: nobody writes the chunks' sums in this pass.
                let (rr, rz_next) = unsafe { (chunk_rr.whole(), chunk_rz.whole()) };
                let (rr, mut rz_next) = rr.iter().zip(rz_next).fold((0.0, 0.0), |(a, b), (x, y)| (a + x, b + y));
                if rr <= tolerance {
                    break;
                }
                rz_next += self.coarse_part(team);
                let beta = (rz_next / rz) as f32;
                rz = rz_next;
                // p = z + β p, with Σ g·p per gas fragment in the same pass.
                self.direction(team, input, beta, gas_dot);
            }
            iterations
        }
    }
}

/// A running sum per fragment over consecutive vertices, added into the per-fragment sums when
/// the fragment changes (the sums then depend only on the vertex order, not the thread count).
struct GasRun {
    fragment: usize,
    sum: f64,
}

impl Default for GasRun {
    fn default() -> Self {
        Self { fragment: usize::MAX, sum: 0.0 }
    }
}

impl GasRun {
    #[inline(always)]
    fn add(&mut self, sums: &mut [f64], fragment: usize, value: f64) {
        if fragment != self.fragment {
            self.flush(sums);
            self.fragment = fragment;
        }
        self.sum += value;
    }

    #[inline(always)]
    fn flush(&mut self, sums: &mut [f64]) {
        if self.fragment != usize::MAX {
            sums[self.fragment] += self.sum;
        }
        self.sum = 0.0;
    }
}

/// `h² P/V Σ g·p` per fragment (as f32, the factor of the gas term of each row of a product)
/// from `Σ g·p` per fragment: once per product, not once per row.
fn gas_scale(sys: &System, gas_dot: &[f64], scale: &mut [f32]) {
    for ((scale, &coef), &dot) in scale.iter_mut().zip(sys.gas_coef.iter()).zip(gas_dot.iter()) {
        *scale = (coef * dot) as f32;
    }
}

/// `Σ g·p` per fragment from the chunks' parts (in chunk order).
fn sum_gas_partial(partial: &[f64], gas_dot: &mut [f64]) {
    if gas_dot.is_empty() {
        return;
    }
    gas_dot.fill(0.0);
    for part in partial.chunks_exact(gas_dot.len()) {
        for (total, value) in gas_dot.iter_mut().zip(part) {
            *total += value;
        }
    }
}

/// One substep of length `h`; returns (wind work in J, conjugate-gradient iterations).
#[allow(clippy::too_many_arguments)]
pub(crate) fn substep(
    model: &Model,
    mut gas: Option<&mut Gas>,
    x: &mut [Vec3],
    v: &mut [Vec3],
    save: Option<(&mut [Vec3], &mut [Vec3])>,
    h: f32,
    max_iterations: usize,
    pool: &WorkerPool,
    obstacles: &[Obstacle],
    s: &mut ImplicitScratch,
) -> (f64, usize) {
    let n = x.len();
    // The state to roll back to, copied by the assembly's chunks (before anything changes it).
    let saving = save.is_some();
    let (save_x, save_v) = match save {
        Some((save_x, save_v)) => {
            assert!(save_x.len() == n && save_v.len() == n, "the saved state's arrays are not one per vertex");
            (SharedSlice::new(save_x), SharedSlice::new(save_v))
        }
        None => (SharedSlice::new(&mut [][..]), SharedSlice::new(&mut [][..])),
    };
    // Set again by the last pass (a substep that does not reach it leaves the step to check).
    s.all_finite = false;
    s.lay_out(model.springs, n);
    // Without wind the assembly adds gravity and the pressure per vertex (two serial passes
    // fewer); with wind the external forces are gathered here first.
    let wind = model.has_wind();
    let power = if wind {
        s.force.resize(n, Vec3::ZERO);
        external_forces(model, v, &mut s.force)
    } else {
        s.force = Vec::new();
        0.0
    };
    // The wind's total force (gravity's is summed with the masses below), before the gas adds
    // to these forces: what the momentum correction after the solve aims at.
    let wind_total: glam::DVec3 = if wind {
        let g = model.settings.gravity.as_dvec3();
        s.force.iter().zip(model.mass).map(|(f, &m)| f.as_dvec3() - g * m as f64).sum()
    } else {
        glam::DVec3::ZERO
    };
    let h2 = h * h;
    // `h² P/V` per fragment (the gas rank-one term).
    let gas_coefficients = |gas: &Gas, out: &mut [f64]| {
        for (f, coef) in out.iter_mut().enumerate() {
            let vol = gas.volume[f].max(gas.v_min[f]);
            *coef = if gas.pressure[f] > 0.0 && vol > 0.0 { (h2 as f64) * gas.pressure[f] / vol } else { 0.0 };
        }
    };
    // The gas gradient: without wind the first pass of the team region below (after
    // `Gas::prepare_corners` here), with wind here with the external forces.
    let gradient_in_team = gas.is_some() && !wind;
    // What the last substep prepared for this one (see `Prepared`), if it still fits; this one
    // prepares the next unless there is wind (whose forces are measured here each time).
    let now = Prepared { h, vertices: n, springs: model.springs.len() };
    let reuse = !wind && s.prepared.take() == Some(now) && s.spring_terms.len() == now.springs;
    s.end_energies = None;
    let prepare = !wind;
    if let Some(gas) = gas.as_deref_mut() {
        s.gradient.resize(n, Vec3::ZERO);
        let frags = gas.fragment_count();
        s.gas_coef.clear();
        s.gas_coef.resize(frags, 0.0);
        if wind {
            add_gas_forces_parallel(model, pool, gas, x, &mut s.gradient, &mut s.force);
            gas_coefficients(gas, &mut s.gas_coef);
        } else if reuse {
            // Measured at the end of the last substep; a leak may have changed nRT since.
            gas.refresh_pressures();
            gas_coefficients(gas, &mut s.gas_coef);
        } else {
            gas.prepare_corners(model.triangles, n);
        }
        s.gas_dot.resize(frags, 0.0);
    }
    // Each spring's terms once, then each vertex gathers its springs'.
    s.spring_terms.resize(model.springs.len(), SpringTerms::default());
    // The warm start: the previous substep's Δv (the velocity change varies slowly from step
    // to step), or on the first substep the free-fall guess Δv = h g: either solves the rigid
    // translation, the mode that a Jacobi preconditioner dominated by stiff springs resolves
    // worst. Measured on the issue-5 balloon (benches/body_balloon.rs, CG iterations over 600
    // steps, 3,771 with this start) and not kept:
    // - the Galerkin combination of the last k Δv (their products with the matrix taken from
    //   the residuals their solves ended with, so no extra product): 3,330 (k = 2), 3,265
    //   (k = 3), all of it at rest (the impact and wobble got no better); on its own the zero
    //   gravity balloon went from 4.3 to 1.2 iterations per step. Its passes over 2k + 2 stored
    //   vectors cost about what the 0.8 iterations a step it saves do;
    // - a few CG iterations on the contact patch and two rings around it (which hold 95-100% of
    //   the first residual during the wobble) before the global solve: 3,482 with 3 of them, 3,497
    //   with 12, which moved the residual out of the patch (down 3-5x), not away;
    // - extrapolating from the last two (Δv + θ (Δv - Δv before), measured after
    //   `HELD_PULL_SHARE`, CG iterations a step): θ from 0.3 to 1 took the issue's drop from 9.5
    //   to 9.6-11.7; θ from -0.1 to -0.5 (a weighted mean of the two) took ten drops 0 to 25 mm
    //   higher from 8.97 to 8.36-8.63 but the h = 1/15 s row from 13.38 to 14.12, and the mean
    //   only where a vertex's Δv turned back took 8.54-9.04.
    if s.dv.len() != n {
        let g = Vec3A::from(model.settings.gravity * h);
        s.dv.clear();
        s.dv.resize(n, g);
    }
    if !obstacles.is_empty() {
        s.contact_slot.resize(n, u32::MAX);
        s.contact_normal.resize(n, Vec3A::ZERO);
        s.contact_reaction.resize(n, 0.0);
        // A vertex appended by a split starts free (the reaction is measured per vertex).
        s.contact_held.resize(n, false);
    }
    if saving {
        s.saved_dv.resize(n, Vec3A::ZERO);
        s.saved_held.resize(s.contact_held.len(), false);
    }
    let fragments = s.gas_dot.len();
    let chunks = n.div_ceil(CHUNK);
    let face_chunks = model.triangles.len().div_ceil(gas::FACE_CHUNK);
    s.gas_partial.resize(chunks * fragments, 0.0);
    s.sums.resize(chunks, fragments);
    s.sums.resize_member_gas(pool.threads().max(1), fragments);
    s.sums.gas_six_v.clear();
    s.sums.gas_six_v.resize(face_chunks * fragments.max(1), 0.0);
    if reuse {
        s.sums.gas_v.copy_from_slice(&s.prepared_gas_v);
    }
    if prepare {
        s.sums.end_springs.clear();
        s.sums.end_springs.resize(model.springs.len().div_ceil(energy::SPRING_CHUNK), (0.0, 0.0));
        s.sums.end_vertices.clear();
        s.sums.end_vertices.resize(n.div_ceil(energy::VERTEX_CHUNK), (0.0, 0.0));
    }
    // The coarse level: made once, for the first substep length (the body's own, `prepare`);
    // after a topology change it is extended, not remade, so a cracking step costs no
    // factorization. The step control's finer substeps (`Body::step`) go without it: their
    // systems are better conditioned (h² K / m a quarter for each halving), and a level for
    // each length costs a factorization (6.4 ms on the issue-5 balloon) and its allocations;
    // on the burst balloon (the step control's main user) such levels, made from its shredded
    // state, took the solves to their cap: its first 100 steps took 6.0 s with a level made and
    // kept for each finer length and 1.6 s without (step 40: 486 against 106 CG iterations).
    if s.coarse_h == 0.0 {
        s.coarse = CoarseSpace::new(model, x, h, pool.threads());
        s.coarse_h = h;
    }
    let own_length = s.coarse_h == h;
    let mut coarse = if own_length { s.coarse.take() } else { None };
    let (coarse_view, coarse_buffers) = match coarse.as_mut() {
        Some(c) => {
            let (view, buffers) = c.split();
            (Some(view), Some(buffers))
        }
        None => (None, None),
    };
    let (coarse_rhs, coarse_solution, coarse_own, coarse_separator_parts) = match coarse_buffers {
        Some(b) => (b.rhs, b.solution, b.own, b.separator_parts),
        None => (&mut [][..], &mut [][..], &mut [][..], &mut [][..]),
    };
    let shared = Shared {
        coupling_offsets: &s.couplings.offsets,
        coupling_springs: &s.couplings.springs,
        couplings: SharedSlice::new(&mut s.couplings.groups),
        rhs: SharedSlice::new(&mut s.rhs),
        inv_diag: SharedSlice::new(&mut s.inv_diag),
        contact_slot: SharedSlice::new(&mut s.contact_slot),
        contact_normal: SharedSlice::new(&mut s.contact_normal),
        contact_reaction: SharedSlice::new(&mut s.contact_reaction),
        contact_held: SharedSlice::new(&mut s.contact_held),
        terms: SharedSlice::new(&mut s.spring_terms),
        dv: SharedSlice::new(&mut s.dv),
        r: SharedSlice::new(&mut s.r),
        z: SharedSlice::new(&mut s.z),
        p: SharedSlice::new(&mut s.p),
        ap: SharedSlice::new(&mut s.ap),
        gas: SharedSlice::new(&mut s.gas_partial),
        gas_v: SharedSlice::new(&mut s.sums.gas_v),
        chunk_pap: SharedSlice::new(&mut s.sums.pap),
        chunk_rr: SharedSlice::new(&mut s.sums.rr),
        chunk_rz: SharedSlice::new(&mut s.sums.rz),
        chunk_magnitude: SharedSlice::new(&mut s.sums.magnitude),
        chunk_rhs: SharedSlice::new(&mut s.sums.rhs),
        chunk_contact: SharedSlice::new(&mut s.sums.contact),
        chunk_largest_other: SharedSlice::new(&mut s.sums.largest_other),
        coarse: coarse_view,
        coarse_rhs: SharedSlice::new(coarse_rhs),
        coarse_solution: SharedSlice::new(coarse_solution),
        coarse_own: SharedSlice::new(coarse_own),
        coarse_separator_parts: SharedSlice::new(coarse_separator_parts),
        coarse_dots: SharedSlice::new(&mut s.sums.coarse_dots),
        member_gas: SharedSlice::new(&mut s.sums.member_gas),
        member_scale: SharedSlice::new(&mut s.sums.member_scale),
    };
    let force = &s.force;
    let (saved_dv, saved_held) = (SharedSlice::new(&mut s.saved_dv), SharedSlice::new(&mut s.saved_held));
    let (gradient, gas_coef) = (SharedSlice::new(&mut s.gradient), SharedSlice::new(&mut s.gas_coef));
    let (xs, vs) = (SharedSlice::new(x), SharedSlice::new(v));
    let momentum = SharedSlice::new(&mut s.sums.momentum);
    let chunk_finite = SharedSlice::new(&mut s.sums.finite);
    let gas_six_v = SharedSlice::new(&mut s.sums.gas_six_v);
    let (end_springs, end_vertices) =
        (SharedSlice::new(&mut s.sums.end_springs), SharedSlice::new(&mut s.sums.end_vertices));
    let gas_lock = std::sync::RwLock::new(gas);
    // Gas gradient, assembly, solve and the update of x and v: one parallel region (see
    // `Shared::solve`).
    let rows = |c: usize| c * CHUNK..((c + 1) * CHUNK).min(n);
    // The state pass, at the state (x, v) the team reads from `xs` and `vs`: the spring terms
    // (chunks of springs) and `Σ g·v` per chunk of vertices; with `energies` also the chunks'
    // energies of that state (in the chunks and order of `energy::state_energies`: the same
    // bits), each spring chunk's from its terms while they are still in the cache (a pass of its
    // own read all the balloon's terms again for their extensions). With `measure_gas` it
    // first measures the gas there: gradient in
    // chunks of vertices and volume in chunks of faces (those of `energy::state_energies`: the
    // same bits) in the same claim as the spring terms, which do not need them, then member 0
    // finishes the volumes, pressures and gas coefficients, and only `Σ g·v` waits for that.
    // (The gas and the spring terms were two passes: one barrier more, and each pass ended
    // with a member waiting for the other's last chunk.)
    // (Tests: `Σ g·v` in a pass of its own, as with caps, with the rows one at a time.)
    #[cfg(test)]
    let separate_dots = s.rows_one_at_a_time;
    #[cfg(not(test))]
    let separate_dots = false;
    let state_pass = |team: &Team, measure_gas: bool, energies: bool| {
        // SAFETY: nobody writes x and v in this pass.
        let (x, v) = unsafe { (xs.whole(), vs.whole()) };
        let spring_input = SpringInput {
            ends: &model.springs.ends,
            rest: &model.springs.rest,
            x,
            v,
            stiffness: model.settings.spring_stiffness,
            damping: model.settings.spring_damping,
            h,
        };
        let spring_chunks = model.springs.len().div_ceil(SPRING_CHUNK);
        let vertex_chunks = if energies { n.div_ceil(energy::VERTEX_CHUNK) } else { 0 };
        let (gradient_chunks, volume_chunks) = if measure_gas { (chunks, face_chunks) } else { (0, 0) };
        let gas_chunks = if fragments > 0 { chunks } else { 0 };
        // `Σ g·v` in the first claim when the gradient is already there.
        let first_gas_chunks = if measure_gas { 0 } else { gas_chunks };
        let (ks, g) = (model.settings.spring_stiffness, model.settings.gravity);
        // (The caller holds a read guard of the gas: a second read lock by the same thread may
        // panic, says std.)
        // The rows and slices of a chunk's `rows` of the gas's per-vertex arrays.
        fn gas_rows(gas: &Gas, rows: std::ops::Range<usize>) -> (&[u32], &[u32]) {
            let slices = rows.start / SLICE..rows.end.div_ceil(SLICE);
            (&gas.vertex_fragment[rows], &gas.slice_vertex_fragment[slices])
        }
        let gas_dots = |gas: Option<&Gas>, c: usize| {
            let Some(gas) = gas else { return };
            // SAFETY: this chunk's sums, written by this member alone; the gradient is written
            // by nobody in this pass.
            let (out, gradient) = unsafe { (shared.gas_v.part(c * fragments..(c + 1) * fragments), gradient.whole()) };
            let (fragment, slices) = gas_rows(gas, rows(c));
            gas_dots_rows((fragment, slices, &gradient[rows(c)]), &v[rows(c)], out);
        };
        // Without caps with gas (holes) the gradient chunks are final where they are made, and
        // each takes its `Σ g·v` along (a pass and a barrier fewer); the caps add to the
        // gradient after every chunk is made (`Gas::finish_gradient`).
        let dots_with_gradient = measure_gas && fragments > 0 && !separate_dots && {
            let guard = gas_lock.read().unwrap_or_else(|e| e.into_inner());
            guard.as_deref().is_some_and(|gas| gas.caps.iter().all(|cap| gas.n_rt[cap.fragment as usize] <= 0.0))
        };
        {
            let guard = gas_lock.read().unwrap_or_else(|e| e.into_inner());
            let gas = guard.as_deref();
            let six_v_parts = fragments.max(1);
            let tasks = [spring_chunks, gradient_chunks, volume_chunks, vertex_chunks, first_gas_chunks];
            team.claim(tasks.iter().sum(), |c| {
                if c < spring_chunks {
                    let range = c * SPRING_CHUNK..((c + 1) * SPRING_CHUNK).min(model.springs.len());
                    let first = range.start;
                    // SAFETY: this chunk of the terms, written by this member alone.
                    let terms = unsafe { shared.terms.part(range.clone()) };
                    // With `energies`, the extensions of `springs::spring_extension` (the same
                    // bits) summed as `energy::state_energies` sums them.
                    let mut lanes = energies.then(|| SpringEnergyLanes::new(ks));
                    spring_terms_range(&spring_input, first, terms, lanes.as_mut());
                    if let Some(lanes) = lanes {
                        // SAFETY: this chunk's slot (the spring chunks are the energy's), written
                        // by this member alone.
                        unsafe { end_springs.part(c..c + 1)[0] = lanes.finish() };
                    }
                    return;
                }
                let c = c - spring_chunks;
                if c < gradient_chunks {
                    if let Some(gas) = gas {
                        // SAFETY: this member's chunk of the gradient.
                        let part = unsafe { gradient.part(rows(c)) };
                        gas.gradient_rows(x, c * CHUNK, part);
                        if dots_with_gradient {
                            // No cap adds to it: the chunk's gradient is final, so its `Σ g·v`
                            // too (`gas_dots` on the chunk's rows).
                            // SAFETY: this chunk's sums, written by this member alone.
                            let out = unsafe { shared.gas_v.part(c * fragments..(c + 1) * fragments) };
                            let (fragment, slices) = gas_rows(gas, rows(c));
                            gas_dots_rows((fragment, slices, part), &v[rows(c)], out);
                        }
                    }
                    return;
                }
                let c = c - gradient_chunks;
                if c < volume_chunks {
                    if let Some(gas) = gas {
                        // SAFETY: this member's face chunk of the sums.
                        let six_v = unsafe { gas_six_v.part(c * six_v_parts..(c + 1) * six_v_parts) };
                        gas.face_chunk_volumes(x, model.triangles, c, six_v);
                    }
                    return;
                }
                let c = c - volume_chunks;
                if c < vertex_chunks {
                    let range = c * energy::VERTEX_CHUNK..((c + 1) * energy::VERTEX_CHUNK).min(n);
                    let kinetic = energy::kinetic(&model.mass[range.clone()], &v[range.clone()]);
                    let gravity = energy::gravity(&model.mass[range.clone()], &x[range], g);
                    // SAFETY: this chunk's slot, written by this member alone.
                    unsafe { end_vertices.part(c..c + 1)[0] = (kinetic, gravity) };
                    return;
                }
                gas_dots(gas, c - vertex_chunks);
            });
        }
        team.barrier();
        if measure_gas {
            if team.index() == 0 {
                let mut guard = gas_lock.write().unwrap_or_else(|e| e.into_inner());
                if let Some(gas) = guard.as_deref_mut() {
                    // SAFETY: member 0 alone works in this pass.
                    unsafe {
                        gas.finish_gradient(x, gas_six_v.whole(), gradient.part(0..n));
                        gas_coefficients(gas, gas_coef.part(0..gas_coef.len()));
                    }
                }
            }
            team.barrier();
            if !dots_with_gradient {
                let guard = gas_lock.read().unwrap_or_else(|e| e.into_inner());
                team.claim(gas_chunks, |c| gas_dots(guard.as_deref(), c));
                drop(guard);
                team.barrier();
            }
        }
    };
    #[cfg(test)]
    let test_gain = s.test_gain;
    let members = s.team_sizer.members(pool.threads());
    #[cfg(target_arch = "x86_64")]
    let slice_planes = (std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
        && slice_update::planes_of(obstacles, &mut s.planes))
    .then_some(&s.planes[..]);
    #[cfg(all(target_arch = "x86_64", test))]
    let slice_planes = slice_planes.filter(|_| !s.rows_one_at_a_time);
    let (iterations, team_stats) = pool.team_of(members, |team| {
        if !reuse {
            state_pass(team, gradient_in_team, false);
        }
        let (iterations, any_contact, end_gas_scale) = {
            let gas_guard = gas_lock.read().unwrap_or_else(|e| e.into_inner());
            let gas = gas_guard.as_deref();
            // SAFETY: nobody writes x and v until the last pass below, after a barrier and after
            // the last use of these; nobody writes the gradient and the gas coefficients from
            // here on.
            let sys = System {
                model,
                x: unsafe { xs.whole() },
                v: unsafe { vs.whole() },
                h,
                vertex_fragment: gas.map_or(&[][..], |g| &g.vertex_fragment),
                slice_fragment: gas.map_or(&[][..], |g| &g.slice_vertex_fragment),
                gradient: unsafe { gradient.whole() },
                gas_coef: unsafe { gas_coef.whole() },
                gas_pressure: gas.map_or(&[][..], |g| &g.pressure),
            };
            let gas_rows = |c: usize| c * fragments..(c + 1) * fragments;
            let own = shared.member_gas(team, fragments);
            // SAFETY: nobody writes the sums or the terms in this pass.
            let (gas_v, terms) = unsafe { (shared.gas_v.whole(), shared.terms.whole()) };
            sum_gas_partial(gas_v, own.dot_v);
            let gas_dot_v = &*own.dot_v;
            #[cfg(target_arch = "x86_64")]
            let planes = slice_planes;
            #[cfg(not(target_arch = "x86_64"))]
            let planes = None;
            let assembly = AssemblyInput { sys: &sys, terms, force, gas_dot_v, obstacles, planes };
            // Assembly: forces, right side, coupling blocks and the block-Jacobi preconditioner (per
            // vertex the springs are stiff along the surface and soft across it, which a diagonal
            // (per axis) preconditioner cannot tell apart on a curved surface; the 3x3 block can),
            // then the start of the solve (warm start, contacts).
            team.claim(chunks, |c| {
                let rows = rows(c);
                if saving {
                    // SAFETY: this member's chunk of the saved state and of Δv and the held
                    // contacts (written by this chunk's assembly after the copy); nobody writes
                    // x and v in this pass.
                    unsafe {
                        save_x.part(rows.clone()).copy_from_slice(&sys.x[rows.clone()]);
                        save_v.part(rows.clone()).copy_from_slice(&sys.v[rows.clone()]);
                        // The warm start before this chunk's assembly turns it into the start
                        // of the solve, and the contacts the last substep held.
                        saved_dv.part(rows.clone()).copy_from_slice(shared.dv.part(rows.clone()));
                        if !obstacles.is_empty() {
                            saved_held.part(rows.clone()).copy_from_slice(&shared.contact_held.whole()[rows.clone()]);
                        }
                    }
                }
                let (first, end) = (rows.start, rows.end);
                let groups = group_range(shared.coupling_offsets, first..end);
                let chunk_groups = groups.clone();
                let has_contact = !obstacles.is_empty();
                // SAFETY: this member's chunks of every array the assembly writes.
                let task = unsafe {
                    AssemblyTask {
                        first,
                        couplings: SliceRowsMut {
                            offsets: shared.coupling_offsets,
                            groups: shared.couplings.part(groups.clone()),
                            first_row: first,
                        },
                        springs: shared.coupling_springs.get(groups).unwrap_or(&[]),
                        rhs: shared.rhs.part(rows.clone()),
                        inv_diag: shared.inv_diag.part(rows.clone()),
                        dv: shared.dv.part(rows.clone()),
                        contact_slot: if has_contact { shared.contact_slot.part(rows.clone()) } else { &mut [] },
                        contact_normal: if has_contact { shared.contact_normal.part(rows.clone()) } else { &mut [] },
                        // (Read only: written by the last pass of the substep.)
                        contact_held: if has_contact { &shared.contact_held.whole()[rows] } else { &[] },
                        gas: shared.gas.part(gas_rows(c)),
                    }
                };
                let (magnitude, rhs, contact) = assemble_chunk(&assembly, task);
                // SAFETY: this chunk's groups and sums, written by this member alone.
                unsafe {
                    shared.chunk_largest_other.part(c..c + 1)[0] =
                        largest_other_offset(shared.couplings.part(chunk_groups));
                    shared.chunk_magnitude.part(c..c + 1)[0] = magnitude;
                    shared.chunk_rhs.part(c..c + 1)[0] = rhs;
                    shared.chunk_contact.part(c..c + 1)[0] = contact;
                }
            });
            team.barrier();
            // SAFETY: from here on nobody writes the sums of the assembly or what it made.
            let (magnitude, rhs_sums, contacts) =
                unsafe { (shared.chunk_magnitude.whole(), shared.chunk_rhs.whole(), shared.chunk_contact.whole()) };
            let magnitude_squared: f64 = magnitude.iter().sum();
            let rhs_squared: f64 = rhs_sums.iter().sum();
            let any_contact = contacts.iter().any(|&c| c);
            let force_scale = h as f64 * magnitude_squared.sqrt();
            let rhs_norm = rhs_squared.sqrt();
            let r0 = (CG_RELATIVE_TOLERANCE * rhs_norm).max(CG_FORCE_TOLERANCE * force_scale);
            if r0 <= 0.0 {
                // SAFETY: nobody writes the gas sums (made by the assembly) in this pass.
                sum_gas_partial(unsafe { shared.gas.whole() }, own.dot_dv);
                gas_scale(&sys, own.dot_dv, own.end_scale);
                (0, any_contact, &*own.end_scale)
            } else {
                // The chunks' groups cover them all (whole slices).
                // SAFETY: written by nobody from here on.
                let largest_other = unsafe { shared.chunk_largest_other.whole() }.iter().copied().max().unwrap_or(0);
                // SAFETY: as above; every group's other ends are in the chunks' maxima.
                let input = unsafe {
                    SolveInput {
                        sys: &sys,
                        contact: if any_contact {
                            ContactRows { slot: shared.contact_slot.whole(), normal: shared.contact_normal.whole() }
                        } else {
                            ContactRows::default()
                        },
                        coupling: CheckedCouplings::with_largest(
                            shared.coupling_offsets,
                            shared.couplings.whole(),
                            n,
                            largest_other,
                        ),
                        rhs: shared.rhs.whole(),
                        inv_diag: shared.inv_diag.whole(),
                        any_contact,
                        fragments,
                        tolerance: r0.powi(2),
                        max_iterations,
                    }
                };
                let mut own = own;
                let iterations = shared.solve(team, &input, &mut own);
                gas_scale(&sys, own.dot_dv, own.end_scale);
                (iterations, any_contact, &*own.end_scale)
            }
        };
        // SAFETY: from here on each member writes only the rows of its own chunks (the contacts
        // are written by nobody; Δv only by the last pass, in its own rows).
        let contact = unsafe {
            if any_contact {
                ContactRows { slot: shared.contact_slot.whole(), normal: shared.contact_normal.whole() }
            } else {
                ContactRows::default()
            }
        };
        // Internal forces cannot change the momentum: Σ m Δv is h times the external force
        // (gravity, wind). A truncated solve leaves an error there, and so do the f32 roundings
        // of large internal forces that cancel (a stiff ball's springs and gas: they moved a
        // free ball's momentum by 4% of a push in 30 steps, found by review, where the target
        // was Σ rhs); a uniform correction removes it. Not with pins or contacts: their
        // reactions are external forces.
        let mut correction = Vec3A::ZERO;
        if !any_contact {
            // SAFETY: Δv is written by nobody in this pass; the chunk's sums by this member
            // alone.
            let dv = unsafe { shared.dv.whole() };
            team.claim(chunks, |c| {
                let (mut momentum_change, mut mass, mut free) = (glam::DVec3::ZERO, 0.0f64, true);
                for i in rows(c) {
                    momentum_change += dv[i].as_dvec3() * model.mass[i] as f64;
                    mass += model.mass[i] as f64;
                    free &= model.inv_mass[i] > 0.0 || model.mass[i] == 0.0;
                }
                // SAFETY: this chunk's slot.
                unsafe { momentum.part(c..c + 1)[0] = (momentum_change, mass, free) };
            });
            team.barrier();
            // SAFETY: nobody writes the sums in this pass.
            let sums = unsafe { momentum.whole() };
            if sums.iter().all(|s| s.2) {
                let (change, mass) = sums.iter().fold((glam::DVec3::ZERO, 0.0f64), |(e, m), s| (e + s.0, m + s.1));
                if mass > 0.0 {
                    let external = model.settings.gravity.as_dvec3() * mass + wind_total;
                    correction = Vec3A::from(((external * h as f64 - change) / mass).as_vec3());
                }
            }
        }
        // With contacts, each one's reactions in the solve first (a pass of its own: the friction
        // of a vertex reads its neighbours'); then v += Δv, friction, x += h v, and the contact
        // response (SPEC 2.3) of each vertex.
        let (restitution, friction) = (model.settings.restitution, model.settings.friction);
        // The obstacles as planes for the slices of the last pass, with AVX2 and FMA (None:
        // every row one at a time).
        #[cfg(all(target_arch = "x86_64", test))]
        let slice_planes = slice_planes.filter(|_| test_gain == 0.0);
        let gas_guard = gas_lock.read().unwrap_or_else(|e| e.into_inner());
        let vertex_fragment = gas_guard.as_deref().map_or(&[][..], |g| &g.vertex_fragment[..]);
        // SAFETY: with contacts there is no momentum correction, so nobody writes Δv in this
        // pass; nobody writes the right side, the couplings and the gradient in it (the state
        // pass after the next barrier measures the gradient again; these are not used there).
        let reactions = any_contact.then(|| unsafe {
            let coupling = (shared.coupling_offsets, shared.couplings.whole());
            (shared.dv.whole(), shared.rhs.whole(), coupling, gradient.whole())
        });
        // With contacts, first each contact's reactions: the normal one `λ_n` (whether the next
        // substep holds it, and the friction it can give), and the tangential velocity `δ` that
        // sticking would take off (in z, free after the solve; zero elsewhere).
        if let Some((dv_all, rhs, coupling, gradient)) = reactions {
            team.claim(chunks, |c| {
                let rows = rows(c);
                // SAFETY: this member's chunks; x, v, Δv, the right side and the couplings are
                // written by nobody in this pass.
                let (v, held, slip, reaction) = unsafe {
                    (
                        vs.whole(),
                        shared.contact_held.part(rows.clone()),
                        shared.z.part(rows.clone()),
                        shared.contact_reaction.part(rows.clone()),
                    )
                };
                held.fill(false);
                slip.fill(Vec3A::ZERO);
                let mut coupling_sums = SliceCouplingSums::default();
                for (k, i) in rows.clone().enumerate() {
                    let Some(&slot) = contact.slot.get(i).filter(|&&slot| slot != u32::MAX) else { continue };
                    if model.inv_mass[i] == 0.0 {
                        continue;
                    }
                    let normal = contact.normal[slot as usize];
                    let gas = vertex_fragment
                        .get(i)
                        .filter(|&&f| f != u32::MAX)
                        .map(|&f| (Vec3A::from(gradient[i]), end_gas_scale[f as usize]));
                    let coupling_sum = coupling_sums.row(coupling.0, coupling.1, dv_all, i);
                    let lambda = contact_reaction(model.mass[i], dv_all[i], coupling_sum, rhs[i], gas, normal);
                    held[k] = lambda >= 0.0;
                    reaction[slot as usize - rows.start] = lambda;
                    if lambda > 0.0 && friction > 0.0 {
                        let after = Vec3A::from(v[i]) + dv_all[i];
                        slip[k] = after - normal * after.dot(normal);
                    }
                }
            });
            team.barrier();
        }
        // SAFETY: written by the pass above only.
        let (reaction, slip) = unsafe {
            if any_contact { (shared.contact_reaction.whole(), shared.z.whole()) } else { (&[][..], &[][..]) }
        };
        let (coupling_offsets, couplings) = reactions.map_or((&[][..], &[][..]), |r| r.2);
        team.claim(chunks, |c| {
            let rows = rows(c);
            let first = rows.start;
            // SAFETY: this member's chunks.
            let (x, v, finite) = unsafe { (xs.part(rows.clone()), vs.part(rows.clone()), chunk_finite.part(c..c + 1)) };
            if reactions.is_none() && !obstacles.is_empty() {
                // Nothing touched: nothing is held next substep (the pass above clears them
                // otherwise).
                // SAFETY: this member's chunk.
                unsafe { shared.contact_held.part(rows.clone()) }.fill(false);
            }
            // Δv, kept as the next substep's warm start (corrected here without contacts, in this
            // member's rows).
            let dv: &[Vec3A] = match reactions {
                Some((dv, ..)) => &dv[rows],
                None => {
                    // SAFETY: this member's chunk; without contacts nobody reads other rows of Δv
                    // in this pass.
                    let dv = unsafe { shared.dv.part(rows) };
                    for d in dv.iter_mut() {
                        *d += correction;
                    }
                    dv
                }
            };
            // The chunk's rows of the arrays read per row, sliced once (no bounds check per row).
            let n_rows = x.len();
            let inv_mass = &model.inv_mass[first..first + n_rows];
            let (dv, slots) = (&dv[..n_rows], contact.slot.get(first..first + n_rows).unwrap_or(&[]));
            let mut all_finite = true;
            // The friction's sums of the rows' slip (a contact's slices at once).
            let mut slip_sums = SliceCouplingSums::default();
            let mut k = 0;
            while k < n_rows {
                // Eight rows at once where they all move and touch nothing (`slice_update`).
                #[cfg(target_arch = "x86_64")]
                if let Some(planes) = slice_planes {
                    let rows = k..k + SLICE;
                    if k % SLICE == 0
                        && rows.end <= n_rows
                        && inv_mass[rows.clone()].iter().all(|&w| w > 0.0)
                        && slots.get(rows.clone()).is_none_or(|s| s.iter().all(|&s| s == u32::MAX))
                    {
                        // SAFETY: AVX2 and FMA (checked with the planes); rows of the chunk.
                        let update = unsafe { update_slice_avx2(x, v, dv, k, h, planes) };
                        if update.inside {
                            for r in rows {
                                resolve(&mut x[r], &mut v[r], obstacles, restitution, friction);
                                all_finite &= x[r].is_finite() && v[r].is_finite();
                            }
                        } else {
                            all_finite &= update.finite;
                        }
                        k += SLICE;
                        continue;
                    }
                }
                // One row (advanced past first: the row's `continue`s go to the next).
                let row = k;
                k += 1;
                let i = first + row;
                let dvi = dv[row];
                if inv_mass[row] == 0.0 {
                    all_finite &= x[row].is_finite() && v[row].is_finite();
                    continue;
                }
                let v = &mut v[row];
                *v += Vec3::from(dvi);
                if let Some(&slot) = slots.get(row).filter(|&&slot| slot != u32::MAX) {
                    let normal = contact.normal[slot as usize];
                    let delta = slip[i];
                    if delta != Vec3A::ZERO {
                        // SPEC 2.3 Coulomb friction: sticking takes δ off every contact; the
                        // tangential impulse that takes at this vertex is its row of A δ (its mass
                        // and the springs to its neighbours, which stick too or not). Within
                        // `friction λ_n` it sticks; beyond, it slides with the friction at that
                        // bound (δ scaled down). (The gas term of A is left out: δ lies along the
                        // obstacle, across which the gas gradient of a flattened patch points.)
                        // A bound on the velocity taken off instead (`friction` times the normal
                        // speed change, as before) is not Coulomb's: a stiff spring lets a vertex
                        // move only `h f / (m + h² k)` in a step, so that friction held springs
                        // stretched about ten times beyond the bound (tests/ffi_body_ground.rs:
                        // a flung cloth kept a strain of 2.0e-3 against 2.2e-4 now; the issue-5
                        // balloon's contact patch at rest kept 18.7 N s of tangential right side,
                        // now 0.07), and made energy in a flattened ball.
                        //
                        // Measured on the issue-5 balloon (benches/body_balloon.rs, seven drops 0
                        // to 25 mm higher, 8.6 CG iterations a step with this) and not kept:
                        // - holding the vertices that stuck inside the next solve (`v + Δv = 0`,
                        //   every component filtered; released when the reaction leaves the cone):
                        //   17.6, and 17 a step at rest instead of 4.3. The coarse level still
                        //   moves the stuck vertices (its matrix does not know them), so its
                        //   correction no longer fits; without the coarse level sticking helps a
                        //   little (26.2 -> 24.9). With a coarse matrix that pins them (the
                        //   Galerkin matrix of the filtered aggregates, factored again whenever
                        //   the stuck set changed: 567 times in the 600 steps) the issue's drop
                        //   took 7.4 iterations a step against 7.5 without sticking, and 4-7 at
                        //   rest: no gain to pay the factorizations with;
                        // - Δv after friction kept as the next warm start: 11.7 (the solve's own
                        //   Δv predicts the next solve better).
                        // The patch now slides until its stress is inside the cone, which costs
                        // iterations after the impact: 5.9 -> 7.5 a step for the issue's drop
                        // (9.5 since `HELD_PULL_SHARE`, against 7.2 with friction 0).
                        let mut needed = delta * model.mass[i] + slip_sums.row(coupling_offsets, couplings, slip, i);
                        needed -= normal * needed.dot(normal);
                        let (needed, allowed) = (needed.length(), friction * reaction[slot as usize]);
                        let share = if needed <= allowed { 1.0 } else { allowed / needed };
                        *v -= Vec3::from(delta * share);
                    }
                }
                x[row] += *v * h;
                #[cfg(test)]
                if test_gain != 0.0 {
                    x[row] += *v * (h * test_gain);
                }
                if !obstacles.is_empty() {
                    resolve(&mut x[row], v, obstacles, restitution, friction);
                }
                all_finite &= x[row].is_finite() && v.is_finite();
            }
            finite[0] = all_finite;
        });
        drop(gas_guard);
        if prepare {
            team.barrier();
            state_pass(team, gradient_in_team, true);
        }
        iterations
    });
    s.team_sizer.record(team_stats);
    s.all_finite = s.sums.finite.iter().all(|&f| f);
    if prepare {
        s.prepared = Some(now);
        s.prepared_gas_v.clone_from(&s.sums.gas_v);
        let (mut kinetic, mut spring, mut gravity, mut max_strain) = (0.0, 0.0, 0.0, 0.0f32);
        for &(e, strain) in &s.sums.end_springs {
            spring += e;
            max_strain = max_strain.max(strain);
        }
        for &(k, g) in &s.sums.end_vertices {
            kinetic += k;
            gravity += g;
        }
        s.end_energies = Some(EndEnergies { kinetic, spring, gravity, max_strain });
    }
    if own_length {
        s.coarse = coarse;
    }
    (power * h as f64, iterations)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Σ g·v` per fragment over a chunk: slices of one fragment (eight rows at once with AVX2),
    /// slices without gas (skipped), mixed slices and a last partial slice (row by row), each
    /// fragment's sum that of its rows' dots.
    #[test]
    fn gas_dots_are_the_sums_of_each_fragments_rows() {
        let mut unit = crate::body::test_randoms(0x9a5d_0075_0f0a_11ce);
        let n = 45;
        // Slices: 0 and 1 fragment 0, 2 no gas, 3 mixed (0, 1, none), 4 fragment 1, 5 (five
        // rows) fragment 1.
        let fragment: Vec<u32> = (0..n)
            .map(|i| match i / SLICE {
                0 | 1 => 0,
                2 => u32::MAX,
                3 => [0, 1, u32::MAX][i % 3],
                _ => 1,
            })
            .collect();
        let slice_fragment = gas::slice_fragments(&fragment);
        let gradient: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), unit(), unit())).collect();
        let v: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), unit(), unit()) * 4.0).collect();
        let mut out = [f64::NAN; 2];
        gas_dots_rows((&fragment, &slice_fragment, &gradient), &v, &mut out);
        let mut want = [0.0f64; 2];
        let mut size = [0.0f64; 2];
        for i in 0..n {
            if fragment[i] != u32::MAX {
                let dot = gradient[i].as_dvec3().dot(v[i].as_dvec3());
                want[fragment[i] as usize] += dot;
                size[fragment[i] as usize] += dot.abs();
            }
        }
        for f in 0..2 {
            assert!((out[f] - want[f]).abs() <= 1e-6 * size[f], "fragment {f}: {} vs {}", out[f], want[f]);
        }
    }

    /// Every specialisation of the direction pass (coarse level, contacts, gas: each on or off)
    /// against the plain formula `p = z + F(c) + β p` at every vertex (F the contact filter,
    /// c the coarse correction, none at a pinned vertex) and `Σ g·p` per fragment.
    #[test]
    fn direction_rows_match_the_formula_for_every_combination() {
        // Five slices of eight rows and a tail of five.
        let n = 45;
        let mut unit = crate::body::test_randoms(0x9e37_79b9_7f4a_7c15);
        let mut vec3a = || Vec3A::new(unit(), unit(), unit());
        let z: Vec<Vec3A> = (0..n).map(|_| vec3a()).collect();
        let p0: Vec<Vec3A> = (0..n).map(|_| vec3a()).collect();
        let solution: Vec<Vec3A> = (0..5).map(|_| vec3a()).collect();
        let gradient: Vec<Vec3> = (0..n).map(|_| Vec3::from(vec3a())).collect();
        // Pinned vertices in the first two slices and contacts in the first three: the fourth
        // and fifth all move and touch nothing (their corrections two rows at a time), the third
        // moves but touches.
        let inv_mass: Vec<f32> = (0..n).map(|k| if k % 7 == 3 && k < 16 { 0.0 } else { 1.0 }).collect();
        let row_of: Vec<u32> = (0..n).map(|k| (k * 3 % 5) as u32).collect();
        // Fragments in runs, with vertices of no gas fragment among them: the first slice all in
        // fragment 0, the fifth in none, the others mixed.
        let fragment: Vec<u32> = (0..n)
            .map(|k| match k {
                0..8 => 0,
                32..40 => u32::MAX,
                _ if k % 9 == 4 => u32::MAX,
                _ => (k / 10) as u32 % 3,
            })
            .collect();
        let slice_fragment = gas::slice_fragments(&fragment);
        assert!(slice_fragment.contains(&0) && slice_fragment.contains(&u32::MAX));
        assert!(slice_fragment.contains(&gas::MIXED_FRAGMENTS));
        // Every fourth vertex of the first three slices touches, its normal in the next free slot.
        let mut slot = vec![u32::MAX; n];
        let mut normal = vec![Vec3A::ZERO; n];
        for (used, k) in (1..24).step_by(4).enumerate() {
            normal[used] = vec3a().normalize();
            slot[k] = used as u32;
        }
        let beta = 0.37f32;
        for coarse in [false, true] {
            for contact in [false, true] {
                for gas in [false, true] {
                    let contacts =
                        if contact { ContactRows { slot: &slot, normal: &normal } } else { ContactRows::default() };
                    let mut expected_p = p0.clone();
                    let mut expected_gas = vec![0.0f64; 3];
                    let mut gas_scale = 0.0f64;
                    for k in 0..n {
                        let mut zi = z[k];
                        if coarse && inv_mass[k] > 0.0 {
                            let c = solution[row_of[k] as usize];
                            zi += if contact { contacts.apply(k, c) } else { c };
                        }
                        expected_p[k] = zi + p0[k] * beta;
                        if gas && fragment[k] != u32::MAX {
                            let term = Vec3A::from(gradient[k]).dot(expected_p[k]) as f64;
                            expected_gas[fragment[k] as usize] += term;
                            gas_scale += term.abs();
                        }
                    }
                    let mut p = p0.clone();
                    let mut sums = [0.0f64; 3];
                    let coarse_rows = if coarse { (&row_of[..], &solution[..]) } else { (&[][..], &[][..]) };
                    let gas_rows = if gas {
                        (&fragment[..], &slice_fragment[..], &gradient[..])
                    } else {
                        (&[][..], &[][..], &[][..])
                    };
                    let args = (&mut p, &z[..], &inv_mass[..], coarse_rows, contacts, gas_rows, beta, &mut sums[..]);
                    match (coarse, contact, gas) {
                        (false, _, false) => direction_rows::<false, false, false>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7,
                        ),
                        (false, _, true) => direction_rows::<false, false, true>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7,
                        ),
                        (true, false, false) => direction_rows::<true, false, false>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7,
                        ),
                        (true, false, true) => direction_rows::<true, false, true>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7,
                        ),
                        (true, true, false) => direction_rows::<true, true, false>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7,
                        ),
                        (true, true, true) => direction_rows::<true, true, true>(
                            args.0, args.1, args.2, args.3, args.4, args.5, args.6, args.7,
                        ),
                    }
                    let case = format!("coarse {coarse}, contact {contact}, gas {gas}");
                    // Without the coarse level the contacts are not read (z is filtered already).
                    assert_eq!(p, expected_p, "{case}");
                    for (got, want) in sums.iter().zip(&expected_gas) {
                        // (A slice of one fragment may sum its rows in f32 first.)
                        assert!((got - want).abs() <= 1e-6 * (1.0 + gas_scale), "{case}: {got} vs {want}");
                    }
                    assert_eq!(sums.iter().any(|&s| s != 0.0), gas, "{case}");
                    if contact && coarse {
                        // The filter took the normal part off the correction at touching vertices.
                        let k = 5;
                        let c = solution[row_of[k] as usize];
                        let n = normal[slot[k] as usize];
                        assert!(((p[k] - z[k] - p0[k] * beta) - (c - n * c.dot(n))).length() < 1e-6, "{case}");
                    }
                }
            }
        }
    }
}
