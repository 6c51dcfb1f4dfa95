//! The coarse level of the implicit integrator's preconditioner (SPEC 2.2): vertices grouped
//! into small aggregates (a vertex and its neighbours), and the constant scalar matrix
//! `Pᵀ (M + c (h² K_s + h K_d) L) P / w` of the aggregates ([`COARSE_WEIGHT`] w), factored once.
//! The block-Jacobi preconditioner resolves what happens at one vertex; this level moves whole
//! patches at once, the smooth deformations (a resting ball carrying its weight to the contact
//! patch, a bounce) that a one-vertex preconditioner leaves to many iterations.
//!
//! The matrix does not follow the springs' directions or a topology change: it only has to be
//! positive definite to keep conjugate gradients correct, and near enough to the system to
//! speed them up. A vertex added by a split joins the aggregate of the vertex it came from.
//!
//! Measured where it does not help (benches/body_balloon.rs, cracking rows: the balloon with
//! `break_strain` 3% bursts on the ground, each of the steps after the first crack breaking
//! 1,300-1,600 springs): the solves there take 49, 54 and 66 CG iterations against 17-20 for a
//! ball that holds, with or without this level, and remade from the cracked mesh after every
//! change (47 and 100 for the first and third). Their residual stalls near the tolerance for
//! 15-20 iterations, over the inside of the contact patch (vertices on the ground whose
//! neighbours all are, sliding outward at about 1 m/s: 44-58% of the residual on 8-17% of the
//! vertices); with the contacts left to the position correction after the solve, the storm (a
//! milder one: 441-1,076 springs a step) takes 20-38. (These figures and those below predate
//! the springs on the sides of opened cracks: with them the same rows break 1,486, 1,279 and
//! 1,461 springs in 37, 44 and 79 iterations. The chains below, of broken edges not yet open,
//! remain.)
//!
//! Why, from Lanczos estimates (the CG coefficients) and the Ritz vector of the softest mode:
//! the preconditioned spectrum of a ball that holds spans 0.08-2.8; in the solve after the
//! first crack its smallest values are 3e-3, 1.7e-2 and 3.9e-2. With this level remade, 98% of
//! the softest mode lies on 200 vertices of the patch, and 80% on the 212 vertices that the
//! crack left with two springs, in chains: a face keeps its corners when one of its springs
//! breaks and no fan splits, so the bars left form linkages that turn without stretching a
//! spring, resisted by little more than their mass. One-vertex blocks see each bar's full
//! stiffness and piecewise-constant aggregates cannot turn a bar, so neither level reaches those
//! motions. Tried and not kept:
//! - exact blocks over each chain (a prototype): 49 -> 33 iterations, but a solve asked for
//!   1e-5 diverged with them, and the storm that followed broke 2,666 and then 15,115 springs,
//!   where a converged solve without them breaks 1,332, 1,435 and 1,568;
//! - keeping the spring of a broken edge until the surface opens there (no linkages; a change of
//!   the fracture model): the storm's solves took 40, 45 and 81 iterations instead of 49, 54 and
//!   66 (which soft motions remain was not measured).
//!
//! - taking the small fragments out of the solve (every fragment of at most 30, or 1,000,
//!   vertices held as if pinned, an experiment to see where the iterations go; up to a third of
//!   the vertices in the third step): 49/54/66 -> 32/53/63 and 46/47/63 iterations. The soft
//!   modes are in the large piece (the contact patch and the chains above), so solving the
//!   small fragments apart, exactly, would save their share of each iteration's work, not
//!   iterations.
//!
//! Remade, this level also takes the largest values to 51 and 264 in the next steps, likely
//! because its scalar matrix has no gas term, which is large for small closed fragments.
//!
//! Keeping the contact normal out of the correction of every aggregate that touches the ground
//! (on both sides, so the preconditioner stays symmetric) made every contact step slower:
//! 15 -> 17, 17 -> 22 and 20 -> 23 iterations for a ball that holds, 49 -> 53 and 66 -> 72 in
//! the storm. Scaling the whole correction of every aggregate that touches the ground (both
//! sides again) by 0.7, 0.85 or 1.2 took ten drops 0 to 25 mm higher than the (one
//! thread, with [`COARSE_WEIGHT`] and [`DROP_SCALE`] as they are) 8.85, 8.63 and 8.79 CG
//! iterations a step against 8.54.
//!
//! Where the contact phase's iterations go (the issue-5 balloon, benches/body_balloon.rs, one
//! thread): steps 33-120 take 14-33 CG iterations against 4-5 at rest. Their residual first falls
//! fast (150-230 times the tolerance down to about 40 in three or four iterations), then by only
//! about 0.85 an iteration. Lanczos estimates from the CG coefficients put the preconditioned
//! spectrum's largest value at 2.3-2.4 in every step, its smallest at 0.1-0.18 at rest but at
//! 0.009-0.02 in the hardest contact steps, with a cluster below 0.1 (0.009, 0.032, 0.059, 0.093
//! at step 94). The softest Ritz vector at step 45 is 78% vertical motion, 90% of it on 831
//! vertices, three quarters of it in the ring 0.8-0.95 of the way out to the contact patch's
//! edge, where the squashed surface wrinkles: free vertices on the ground or about 3 cm above it
//! (leaving the ground) between vertices in contact, lifting together. Such a cluster is
//! resisted by little more than its mass, while each vertex's block holds the full axial
//! stiffness of its slanted springs (to neighbours that move with it), and the aggregates do not
//! follow the cluster's edge. Measured and not kept (CG iterations over the drop, 5,182
//! with this level; the coarse matrices refactored exactly before every solve, a prototype):
//! - for the vertical component a Galerkin matrix without the vertices in contact (an aggregate
//!   moves only its free vertices; a spring to a vertex in contact anchors): 5,204;
//! - a matrix per axis from the springs' current blocks (each spring's weight its block's entry
//!   on that axis, `h² a + (h² b + h K_d) u²`: directions and tension followed), with the
//!   vertical one also without the vertices in contact: 5,118 (5,138 without that), the softest
//!   value at step 45 0.02 -> 0.025;
//! - each vertex's block with its springs' part scaled by θ (`m I + θ Σ K`), so that a vertex
//!   that moves with its neighbours is not held as if they stood: θ = 0.85, 0.7 and 0.5 took
//!   5,242, 5,139 and 5,315 (steps 30-179: 2,490 -> 2,504, 2,458 and 2,524).
//!
//! Deflating those soft modes (deflated PCG, Saad, Yeung, Erhel and Guyomarc'h 2000: the start
//! and every search direction made A-orthogonal to a few vectors W) works only with the modes of
//! the step's own matrix. A serial prototype that first solved each of the drop's first 200
//! steps plainly (the same iteration counts as the solve here, step for step), took the Ritz
//! vectors of its four or eight smallest values and solved again deflated by them, took 2,938 ->
//! 1,527 (four) and 966 (eight) iterations, steps 33-119 1,673 -> 840 and 565: the upper bound,
//! the vectors being made by the solve they deflate. Deflated by the previous step's vectors (as
//! a solver recycling them would be), 2,770 and 2,730, steps 33-119 1,606 and 1,581: 4-6% fewer,
//! for four or eight more products with the matrix a step and as many dot products and updates
//! an iteration. The soft clusters move from step to step as the patch wrinkles.
//!
//! Smoothed aggregation (the prolongation `(I - ω D⁻¹ A_s) P` of the scalar matrix `A_s` below,
//! and the Galerkin coarse matrix `Pᵀ A_s P` of it), measured on the issue-5 balloon
//! (benches/body_balloon.rs, one thread, five or ten drops 0 to 25 mm higher than the issue's,
//! CG iterations a step; with this level, at full weight ([`COARSE_WEIGHT`] 1), 9.12 over the
//! five, 8.97 over the ten) and not kept: what it saves in iterations it costs in the coarse
//! work of each one (the factor's two solves and the restriction were about a fifth of a step,
//! at about the same cost per entry):
//! - on these aggregates, ω = 0.67 or 0.9: 7.28 and 7.08 (five drops), but the smoothed
//!   aggregates reach two apart, so the factor has 71,097 entries against 36,620, and the
//!   prolongation 26,806 against one per vertex (10,242);
//! - the same with the coarse matrix cut back to this level's pattern (the rest added to the
//!   diagonal): 8.26, with a factor as large as this one's;
//! - on pairs of these aggregates (594, matched along the most springs): 8.62 (ten drops), a
//!   factor of 23,912 entries and a prolongation of 22,281;
//! - on two passes of aggregation (132 aggregates): 12.4 (five drops).
//!
//! Measured again with the weight and the incomplete factor ([`COARSE_WEIGHT`] 0.5,
//! [`DROP_SCALE`] 0.2; ten drops, 8.54 iterations a step with this level): on these aggregates
//! 6.65 (the factor then has 10,242 entries, by chance the vertex count, against 12,556), but
//! a step was slower, not faster: the mean over steps of each step's fastest of five
//! alternating runs (one thread, the drop) 3.45 against 3.20 ms, with a prototype that prolongs in a pass of its own (the
//! restriction and the prolongation stream 26,806 weighted entries each). Built in (the
//! Galerkin matrix assembled per aggregate, each vertex's weighted correction summed in the
//! direction pass, a split vertex taking its origin's weights): 6.4 iterations a step on the
//! issue's drop against 8.3 (3.1 against 4.4 without gravity, 11.3 against 12.4 at h = 1/15 s),
//! but no faster: the same mean of fastest steps 2.74 against 2.71 ms on one thread, 2.10
//! against 2.00 on two. Its direction pass took 16% of a step against 9%, its restriction 6%
//! against 3% (a vertex takes 2.6 entries on average, 1 to 4, in a loop of its own).
//!
//! A factored sparse approximate inverse `Zᵀ Z ≈ A_c⁻¹` (FSAI: each row of the lower triangular
//! Z from the coarse matrix on that row's pattern, so two products with no chain between rows
//! where the factor's solves go row after row) in place of the factor: on the drop
//! (one thread; 8.3 CG iterations a step with the factor) Z on the coarse matrix's own pattern
//! (4,662 entries) took 15.2, on the aggregates two apart (12,345) 12.2, three apart (24,443)
//! 10.4. The coarse matrix couples the aggregates further than a few apart (its springs
//! dominate its mass), which only a factor captures with few entries.

use glam::{Vec3, Vec3A};

use super::cholesky::Cholesky;
use super::forces::Model;
#[cfg(test)]
use crate::parallel::WorkerPool;

/// Share of a spring's `h² K_s + h K_d` in the scalar matrix: a spring stiffens only along its
/// direction, so a scalar matrix gets about half of it per axis for springs in a surface. On the
/// issue-5 balloon (benches/body_balloon.rs, 200 steps on the ground, measured before the
/// tangent-plane blocks at contacts) 0.4 to 0.65 give the same CG iterations (25 per step), 0.25
/// gives 34 and 1.0 gives 29. Measured again with [`COARSE_WEIGHT`] and [`DROP_SCALE`] as they
/// are (ten drops 0 to 25 mm higher than the issue's, CG iterations a step): 0.3, 0.35, 0.4,
/// 0.45, 0.5, 0.6 and 0.7 take 8.54, 8.37, 8.44, 8.31, 8.54, 8.69 and 8.63; at h = 1/15 s (six
/// drops) 0.35, 0.4 and 0.5 take 13.00, 12.93 and 12.92: a plateau, the steps between values
/// within the spread of the drops.
const SPRING_SHARE: f64 = 0.5;

/// The weight of the coarse correction in the preconditioner `D⁻¹ + w P A_c⁻¹ Pᵀ` (the coarse
/// matrix divided by it): the block-Jacobi part and this level both resolve the modes between a
/// vertex and an aggregate, and at full weight their sum overstates those. Measured on the
/// issue-5 balloon (benches/body_balloon.rs, one thread, CG iterations a step), weights 1, 0.8,
/// 0.7, 0.6, 0.5 and 0.4: over ten drops 0 to 25 mm higher than the 8.97, 8.59, 8.70,
/// 8.51, 8.47 and 8.64; at h = 1/15 s (six drops) 13.97 with 1, 13.02 with 0.6, 12.63 with 0.5
/// and 13.12 with 0.4; the drop 9.5 -> 8.4 (and 14.6 -> 11.3 at h = 1/15 s); the
/// zero-gravity balloon 4.3 -> 4.4; the burst's storm steps 47, 58 and 62 -> 46, 56 and 61
/// (with 0.6). Scaling only the springs' share (0.83 for 0.5, 8.63) or only the mass (8.73)
/// gave about the same: it is the weight that counts. Costs nothing per iteration.
const COARSE_WEIGHT: f64 = 0.5;

/// The factor of the coarse matrix is incomplete: its entries in the row of an aggregate that
/// are under `DROP_SCALE √(m / A)` of the row's diagonal entry are left out (`m` the aggregate's
/// mass, `A` its diagonal entry of the coarse matrix before the division by the weight: `m / A`
/// is the mass's share of it; see [`Cholesky::factor`]).
/// Most of an exact factor's entries are small, and the CG iterations do not miss them: on the
/// issue-5 balloon (benches/body_balloon.rs, one thread, CG iterations a step; ten drops 0 to
/// 25 mm higher than the at h = 1/60 s, six at 1/15 s) the exact factor has 36,620
/// entries and takes 8.47 and 12.63 iterations; with `DROP_SCALE` 0.1, 16,418 and 24,691 entries
/// and 8.43 and 13.22 iterations; with 0.2, 12,556 and 20,526 entries and 8.54 and 12.92. A
/// threshold without the mass share (0.01 of the diagonal) kept about 12,000 entries at both
/// steps and took 8.45 and 14.85: where the mass is a smaller share of the diagonal (a longer
/// step, stiffer springs) the coarse matrix couples the aggregates further, and its factor's
/// entries fall off more slowly with the distance, so the threshold falls with that share. The
/// zero-gravity balloon takes 4.4 iterations a step either way, and the burst's storm steps 35,
/// 55 and 56 against 36, 55 and 60. The solves stream the factor's entries twice per iteration.
const DROP_SCALE: f64 = 0.2;

/// Aggregation passes: each groups the current nodes into a node and its free neighbours, the
/// leftovers joining a neighbouring group (about 9 to 1 on the balloon: 1,167 aggregates of its
/// 10,242 vertices, 36,620 entries in an exact factor; 642 and 17.7k when first measured).
/// Measured as above: one pass takes the CG iterations per step from 46 to 25 on the ground and
/// from 13 to 5 without gravity; two passes only to 37 and 12 (the coarse matrix then misses too much of the springs' stiffness inside
/// each aggregate); three passes to 49. Smaller aggregates (leftovers grouped among themselves:
/// 2,121 of them) save under one iteration per step (7.2 to 6.4 with the contact blocks) and cost
/// more than that in the coarse solve; measured again with the weight and the incomplete factor
/// (2,235 aggregates, 25,564 entries in the factor against 12,556): 8.54 -> 7.56 iterations a step
/// over ten drops, but the drop took 2.78 against 2.66 ms a step (the mean over steps of
/// each step's fastest of five alternating runs, one thread). In the Morton order the body
/// stores its vertices in (`vertex_order`) this pass makes 1,167 aggregates (606 KB of an exact
/// factor); visiting the vertices with a stride instead (3, 17, 101 or 7,919) makes 959-986
/// (490-520 KB) but takes 7.1-7.3 iterations per step instead of 6.3.
const PASSES: usize = 1;

pub(crate) struct CoarseSpace {
    /// Aggregate of each vertex.
    aggregate: Vec<u32>,
    factor: Cholesky,
    restricted: Vec<Vec3A>,
    solution: Vec<Vec3A>,
    work: Vec<Vec3A>,
    /// For the solves split among a team ([`CoarseSpace::split`]): the row of the factor of each
    /// vertex's aggregate, and the vertices of each row's aggregate (CSR, ascending).
    row_of: Vec<u32>,
    member_offsets: Vec<u32>,
    members: Vec<u32>,
    /// The restricted residual and the solution in the factor's row order.
    rows_rhs: Vec<Vec3A>,
    rows_solution: Vec<Vec3A>,
    /// The own copies of the solution of the members solving it (two, or one for a one-thread
    /// team), and what each half adds to the top separator's rows (two times its rows; none
    /// when the factor is one leaf), see `implicit::Shared::coarse_part`.
    own: Vec<Vec3A>,
    separator_parts: Vec<Vec3A>,
}

/// The buffers of a coarse solve split among a team ([`CoarseSpace::split`]).
pub(crate) struct CoarseBuffers<'a> {
    /// The restricted residual and the solution in the factor's row order.
    pub rhs: &'a mut [Vec3A],
    pub solution: &'a mut [Vec3A],
    /// A copy of the solution per member solving a half (one with a one-thread team).
    pub own: &'a mut [Vec3A],
    /// Per half, its part of the top separator's forward solve.
    pub separator_parts: &'a mut [Vec3A],
}

/// What the members of a team read of a coarse space while they solve it together
/// ([`CoarseSpace::split`]).
pub(crate) struct CoarseView<'a> {
    pub factor: &'a Cholesky,
    row_of: &'a [u32],
    member_offsets: &'a [u32],
    members: &'a [u32],
}

impl CoarseView<'_> {
    /// `out[k - rows.start]` = the sum of `r` over the aggregate of factor row k, for the rows
    /// `rows` (in vertex order, alternate members in two running sums, so that each addition
    /// does not wait for the one before; the order is fixed by the aggregate).
    ///
    /// On two threads each member restricts its half of the rows after the residual pass, and
    /// about half of those residuals were just written by the other core (the issue-5 balloon,
    /// benches/body_balloon.rs: 126-190 thousand cycles a step per member, against 203 for all
    /// rows on one thread). Measured and not kept: the aggregates that lie in one chunk of the
    /// residual pass (883 of 1,167, 7,729 of the 10,242 vertices) restricted by that pass while
    /// the chunk's residual is in the core's cache, the others here (the same sums, the same
    /// bits). Two bodies stepped in turn in one process, one each way: the step 0.97-1.00 of
    /// the old on two threads in three runs, 0.99-1.03 in three more, and 1.01-1.03 on one
    /// thread.
    pub fn restrict(&self, rows: std::ops::Range<usize>, r: &[Vec3A], out: &mut [Vec3A]) {
        for (o, k) in out.iter_mut().zip(rows) {
            let members = &self.members[self.member_offsets[k] as usize..self.member_offsets[k + 1] as usize];
            let (mut even, mut odd) = (Vec3A::ZERO, Vec3A::ZERO);
            let pairs = members.chunks_exact(2);
            let last = pairs.remainder().first().map_or(Vec3A::ZERO, |&i| r[i as usize]);
            for pair in pairs {
                even += r[pair[0] as usize];
                odd += r[pair[1] as usize];
            }
            *o = (even + last) + odd;
        }
    }

    /// The factor rows of the aggregates of the vertices `rows`, if it knows them all.
    #[inline]
    pub fn rows_of(&self, rows: std::ops::Range<usize>) -> Option<&[u32]> {
        self.row_of.get(rows)
    }

    /// The coarse correction at vertex i from the solution `y` in row order (zero for a vertex
    /// it does not know).
    #[inline]
    pub fn correction(&self, i: usize, y: &[Vec3A]) -> Vec3A {
        self.row_of.get(i).map_or(Vec3A::ZERO, |&k| y[k as usize])
    }
}

/// Groups the nodes of a graph (CSR `offsets`, `neighbors`): a node whose neighbours are all free
/// starts an aggregate with them; the others join an aggregate of a neighbour; a node without
/// any is alone. Returns the aggregate of each node and the count.
fn aggregate(offsets: &[u32], neighbors: &[u32]) -> (Vec<u32>, usize) {
    let n = offsets.len() - 1;
    let free = u32::MAX;
    let mut group = vec![free; n];
    let mut count = 0u32;
    let around = |i: usize| &neighbors[offsets[i] as usize..offsets[i + 1] as usize];
    for i in 0..n {
        if group[i] == free && around(i).iter().all(|&j| group[j as usize] == free) {
            group[i] = count;
            for &j in around(i) {
                group[j as usize] = count;
            }
            count += 1;
        }
    }
    for i in 0..n {
        if group[i] == free {
            group[i] = around(i).iter().map(|&j| group[j as usize]).find(|&g| g != free).unwrap_or_else(|| {
                count += 1;
                count - 1
            });
        }
    }
    (group, count as usize)
}

/// The graph between the aggregates of `group`: CSR offsets, neighbours and the number of
/// edges between each pair.
fn coarse_graph(offsets: &[u32], neighbors: &[u32], weights: &[f64], group: &[u32], count: usize) -> CsrGraph {
    let mut pairs: Vec<(u32, u32, f64)> = Vec::new();
    for i in 0..group.len() {
        for p in offsets[i] as usize..offsets[i + 1] as usize {
            let (a, b) = (group[i], group[neighbors[p] as usize]);
            if a != b {
                pairs.push((a, b, weights[p]));
            }
        }
    }
    pairs.sort_unstable_by_key(|&(a, b, _)| (a, b));
    let mut graph = CsrGraph { offsets: vec![0; count + 1], neighbors: Vec::new(), weights: Vec::new() };
    let mut k = 0;
    for a in 0..count {
        while k < pairs.len() && pairs[k].0 as usize == a {
            let b = pairs[k].1;
            let mut weight = 0.0;
            while k < pairs.len() && pairs[k].0 as usize == a && pairs[k].1 == b {
                weight += pairs[k].2;
                k += 1;
            }
            graph.neighbors.push(b);
            graph.weights.push(weight);
        }
        graph.offsets[a + 1] = graph.neighbors.len() as u32;
    }
    graph
}

struct CsrGraph {
    offsets: Vec<u32>,
    neighbors: Vec<u32>,
    weights: Vec<f64>,
}

impl CoarseSpace {
    /// Aggregates the vertices of `model` and factors the coarse matrix for substeps of `h`
    /// (`x` places the aggregates for the ordering), for solves by a team of `threads` (the
    /// members' own copies of the solution). None when the matrix cannot be factored.
    pub fn new(model: &Model, x: &[Vec3], h: f32, threads: usize) -> Option<Self> {
        let n = x.len();
        let springs = &model.springs;
        let mut graph = CsrGraph {
            offsets: springs.offsets.clone(),
            neighbors: springs.adjacency.iter().map(|&(_, j)| j).collect(),
            weights: vec![1.0; springs.adjacency.len()],
        };
        let mut vertex_group: Vec<u32> = (0..n as u32).collect();
        let mut count = n;
        for _ in 0..PASSES {
            let (group, c) = aggregate(&graph.offsets, &graph.neighbors);
            graph = coarse_graph(&graph.offsets, &graph.neighbors, &graph.weights, &group, c);
            for g in vertex_group.iter_mut() {
                *g = group[*g as usize];
            }
            count = c;
        }
        let w = SPRING_SHARE
            * ((h * h * model.settings.spring_stiffness) as f64 + (h * model.settings.spring_damping) as f64);
        let mut mass = vec![0.0f64; count];
        let mut center = vec![Vec3::ZERO; count];
        let mut members = vec![0u32; count];
        for i in 0..n {
            let g = vertex_group[i] as usize;
            mass[g] += model.mass[i] as f64;
            center[g] += x[i];
            members[g] += 1;
        }
        let mut diagonal = vec![0.0f64; count];
        for (a, d) in diagonal.iter_mut().enumerate() {
            let edges: f64 = graph.weights[graph.offsets[a] as usize..graph.offsets[a + 1] as usize].iter().sum();
            *d = (mass[a] + w * edges) / COARSE_WEIGHT;
            // An aggregate of vertices no triangle uses (a mesh's unused vertices: no mass, no
            // springs) has an empty row: 0/0 made its drop tolerance NaN (a panic in
            // `softshell_body_new`, found by review). A unit diagonal keeps the matrix
            // factorable; its correction is never applied (those vertices are held, inverse
            // mass 0).
            if *d <= 0.0 {
                *d = 1.0;
            }
            center[a] /= members[a].max(1) as f32;
        }
        let values: Vec<f64> = graph.weights.iter().map(|&e| -w * e / COARSE_WEIGHT).collect();
        // Per aggregate, the share of its mass in its diagonal (the weight cancels).
        let drop_tolerance: Vec<f64> =
            (0..count).map(|a| DROP_SCALE * (mass[a] / COARSE_WEIGHT / diagonal[a]).sqrt()).collect();
        let factor = Cholesky::factor(&diagonal, &graph.offsets, &graph.neighbors, &values, &center, &drop_tolerance)?;
        let mut space = Self {
            aggregate: vertex_group,
            factor,
            restricted: vec![Vec3A::ZERO; count],
            solution: vec![Vec3A::ZERO; count],
            work: Vec::new(),
            row_of: Vec::new(),
            member_offsets: Vec::new(),
            members: Vec::new(),
            rows_rhs: vec![Vec3A::ZERO; count],
            rows_solution: vec![Vec3A::ZERO; count],
            own: Vec::new(),
            separator_parts: Vec::new(),
        };
        space.own = vec![Vec3A::ZERO; threads.clamp(1, 2) * count];
        // (Only a factor split in two halves has a top separator to share.)
        let separator = space.factor.top_halves().map_or(0, |_| space.factor.part_rows(space.factor.root()).1.len());
        space.separator_parts = vec![Vec3A::ZERO; 2 * separator];
        space.index_rows();
        Some(space)
    }

    /// `row_of` and the members of each row from `aggregate`.
    fn index_rows(&mut self) {
        let count = self.factor.len();
        let mut row = vec![0u32; count];
        for (k, &g) in self.factor.perm().iter().enumerate() {
            row[g as usize] = k as u32;
        }
        self.row_of = self.aggregate.iter().map(|&g| row[g as usize]).collect();
        let rows: Vec<[u32; 1]> = self.row_of.iter().map(|&k| [k]).collect();
        let (offsets, members) = crate::mesh::vertex_incidence(count, &rows, |i, _| i as u32);
        self.member_offsets = offsets;
        self.members = members;
    }

    /// A topology change appended vertices: each joins the aggregate of its `origin`. (Making
    /// the coarse level again for the cracked surface instead did worse on the issue-5 balloon's
    /// burst, benches/body_balloon.rs: 47, 87 and 100 CG iterations in the three storm steps
    /// after the first crack, against 49, 54 and 66 extended, and 65, 56 and 59 without a coarse
    /// level at all.)
    pub fn extend(&mut self, origin: &[u32]) {
        let known = self.aggregate.len();
        for &from in origin.iter().skip(known) {
            let group = self.aggregate.get(from as usize).copied().unwrap_or(0);
            self.aggregate.push(group);
        }
        self.index_rows();
    }

    /// The aggregate of vertex `v`, if the level knows it.
    #[cfg(test)]
    pub fn aggregate_of(&self, v: usize) -> Option<u32> {
        self.aggregate.get(v).copied()
    }

    /// What a team reads (the factor and the aggregates), and the buffers its members write in
    /// turn.
    pub fn split(&mut self) -> (CoarseView<'_>, CoarseBuffers<'_>) {
        (
            CoarseView {
                factor: &self.factor,
                row_of: &self.row_of,
                member_offsets: &self.member_offsets,
                members: &self.members,
            },
            CoarseBuffers {
                rhs: &mut self.rows_rhs,
                solution: &mut self.rows_solution,
                own: &mut self.own,
                separator_parts: &mut self.separator_parts,
            },
        )
    }

    /// Solves the coarse system for the residual `r` (summed per aggregate); returns `r·(P x)`,
    /// the coarse part of `r·z`.
    #[cfg(test)]
    pub fn solve(&mut self, pool: &WorkerPool, r: &[Vec3A]) -> f64 {
        self.restricted.fill(Vec3A::ZERO);
        for (ri, &g) in r.iter().zip(&self.aggregate) {
            self.restricted[g as usize] += *ri;
        }
        self.factor.solve(pool, &self.restricted, &mut self.solution, &mut self.work);
        self.restricted.iter().zip(&self.solution).map(|(a, b)| a.dot(*b) as f64).sum()
    }

    /// The coarse correction at vertex i (zero for a vertex it does not know).
    #[cfg(test)]
    pub fn correction(&self, i: usize) -> Vec3A {
        self.aggregate.get(i).map_or(Vec3A::ZERO, |&g| self.solution[g as usize])
    }

    pub fn memory_bytes(&self) -> usize {
        (self.aggregate.capacity() + self.row_of.capacity() + self.member_offsets.capacity() + self.members.capacity())
            * 4
            + self.factor.memory_bytes()
            + (self.restricted.capacity()
                + self.solution.capacity()
                + self.work.capacity()
                + self.rows_rhs.capacity()
                + self.rows_solution.capacity()
                + self.own.capacity()
                + self.separator_parts.capacity())
                * 16
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::settings::BodySettings;
    use crate::body::springs::Springs;

    /// A `side` x `side` grid of unit masses joined by springs along its rows and columns.
    fn grid(side: usize) -> (Vec<Vec3>, Springs, Vec<f32>) {
        let x: Vec<Vec3> = (0..side * side).map(|i| Vec3::new((i % side) as f32, (i / side) as f32, 0.0)).collect();
        let mut springs = Springs::default();
        for i in 0..side * side {
            if i % side + 1 < side {
                springs.ends.push([i as u32, i as u32 + 1]);
            }
            if i / side + 1 < side {
                springs.ends.push([i as u32, (i + side) as u32]);
            }
        }
        springs.rest = vec![1.0; springs.ends.len()];
        springs.build_adjacency(x.len());
        (x, springs, vec![1.0; side * side])
    }

    #[test]
    fn aggregates_cover_every_vertex_and_the_coarse_operator_is_symmetric_positive() {
        let (x, springs, mass) = grid(12);
        let settings = BodySettings::default();
        let model = Model {
            settings: &settings,
            triangles: &[],
            springs: &springs,
            mass: &mass,
            inv_mass: &mass,
            wind_force: &[],
        };
        let mut coarse = CoarseSpace::new(&model, &x, 1.0 / 60.0, 1).unwrap();
        let n = x.len();
        let count = coarse.restricted.len();
        assert!(coarse.aggregate.iter().all(|&g| (g as usize) < count));
        assert!(count > 1 && count <= n / 3, "{count} aggregates for {n} vertices");
        // z = P A_c⁻¹ Pᵀ r: (a, P A_c⁻¹ Pᵀ b) = (b, P A_c⁻¹ Pᵀ a) and (a, P A_c⁻¹ Pᵀ a) > 0.
        let pool = WorkerPool::new(1).unwrap();
        let a: Vec<Vec3A> = (0..n).map(|i| Vec3A::new((i as f32).sin(), (i % 7) as f32 - 3.0, 1.0)).collect();
        let b: Vec<Vec3A> = (0..n).map(|i| Vec3A::new((i as f32 * 0.3).cos(), 0.5, (i % 5) as f32)).collect();
        let apply = |coarse: &mut CoarseSpace, r: &[Vec3A]| -> (f64, Vec<Vec3A>) {
            let rz = coarse.solve(&pool, r);
            (rz, (0..n).map(|i| coarse.correction(i)).collect())
        };
        let (aa, za) = apply(&mut coarse, &a);
        let (_, zb) = apply(&mut coarse, &b);
        let dot = |u: &[Vec3A], v: &[Vec3A]| u.iter().zip(v).map(|(p, q)| p.dot(*q) as f64).sum::<f64>();
        assert!(aa > 0.0 && (aa - dot(&a, &za)).abs() < 1e-4 * aa);
        let (ab, ba) = (dot(&a, &zb), dot(&b, &za));
        assert!((ab - ba).abs() < 1e-4 * ab.abs().max(ba.abs()), "{ab} vs {ba}");
        // A vertex appended by a split joins its origin's aggregate.
        let mut origin: Vec<u32> = (0..n as u32).collect();
        origin.push(17);
        coarse.extend(&origin);
        assert_eq!(coarse.aggregate[n], coarse.aggregate[17]);
    }
}
