//! Self-contact of a closed triangle mesh moving over one step (SPEC 1.6): candidate vertex-face
//! and edge-edge pairs that share no vertex, kept across steps in a cache (a Verlet list) filled
//! from BVHs of vertices, edges and faces over boxes grown by a reach margin, refit (rebuilt when
//! loose) only when a vertex leaves its reach; each step the pairs' swept boxes, the filters and
//! the exact conservative CCD of
//! [`super::ccd`], then the contact constraints `C_vf >= 0`, `C_ee >= 0` projected on the end
//! positions, with the side taken from the start of the step.
//!
//! Guarantee: when the start positions are free of intersections, the end positions returned are
//! too (the CCD never misses). Contacts are projected for a few rounds, each re-checking the pairs
//! that the projection moved; if contacts remain after that, the vertices of the offending pairs
//! are put back at their start positions (a fail-safe that ends: a pair whose four vertices are
//! all back is the start configuration, free of intersections).
//!
//! Knows nothing of the simulator that moves the mesh (positions, inverse masses in; corrected
//! positions and velocities out). Runs serially in a fixed order: results do not depend on
//! threads. Allocates only when a step has more contacts, or the cache more pairs, than the
//! largest before.

// NaN must fail every guard below, so comparisons are written `!(x > limit)` on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

use glam::{DVec3, Vec3, Vec3A};

use super::bvh::{Box32, Bvh};
use super::ccd::{CcdSettings, Stage, edge_edge_in, vertex_triangle_in};
use super::filters::V3;
use super::hull_filter::{
    diagonal_margin, diagonals_separated, edge_edge_hulls_separated, vertex_triangle_hulls_separated,
};
use super::inclusion::SearchQueues;
use crate::mesh::vertex_incidence;

/// Projection rounds (projection, then re-check of the moved pairs) before the fail-safe.
const ROUNDS: usize = 6;
/// Gauss-Seidel sweeps over the contacts in one round.
const SWEEPS: usize = 4;
/// Re-checks after a projection use this fraction of the thickness: a pair projected to the
/// thickness is not found again because of rounding.
const RECHECK_FRACTION: f64 = 0.5;

/// What one call of [`SelfContact::resolve`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactCounts {
    /// Candidate pairs of the first round: vertex-face and edge-edge pairs sharing no vertex
    /// whose swept boxes come within the thickness (the cached BVH pairs that pass the exact
    /// swept-box test; the same pairs a BVH traversal over the swept boxes would give).
    pub candidates: u64,
    /// Candidates left after the separating-axis filters on the swept hulls (the diagonal slabs,
    /// then the closest-point directions, [`super::hull_filter`]) and
    /// the exact swept-box test of each pair.
    pub after_boxes: u64,
    /// Candidates left after the deforming non-penetration (plane) filter: exact tests run. A
    /// test is the inclusion search, or, for a pair whose distance at the start or at one of a
    /// few sample times of the step is within the thickness (plus a slack), the estimate of its
    /// time from those distances (see [`CcdSettings::certain_contact_slack`]).
    pub ccd_tests: u64,
    /// Contact constraints projected (all rounds).
    pub contacts: u64,
    /// Vertices put back to their start positions by the fail-safe.
    pub reverted: u64,
    /// BVH rebuilds.
    pub rebuilds: u64,
    /// Refills of the cached candidate pairs (see `SelfContact::ensure_pairs`).
    pub pair_refills: u64,
    /// Rounds run (1 = no contact needed a re-check).
    pub rounds: u64,
}

impl ContactCounts {
    /// Adds `other` to `self` field by field.
    pub fn add(&mut self, other: &ContactCounts) {
        self.candidates += other.candidates;
        self.after_boxes += other.after_boxes;
        self.ccd_tests += other.ccd_tests;
        self.contacts += other.contacts;
        self.reverted += other.reverted;
        self.rebuilds += other.rebuilds;
        self.pair_refills += other.pair_refills;
        self.rounds += other.rounds;
    }
}

/// One linearised contact: `C = n · Σ_k g_k p_k - δ >= 0` over four vertices.
#[derive(Clone, Copy, Debug)]
struct Contact {
    idx: [u32; 4],
    /// Weights: vertex-face `[1, -α1, -α2, -α3]`, edge-edge `[1-a, a, -(1-b), -b]`.
    g: [f32; 4],
    /// Unit normal pointing from the second primitive to the first at the start of the step.
    n: Vec3,
    /// Relative normal velocity before the contact was projected (predicted motion / h): the
    /// velocity update never lets the pair separate faster than this (or than 0).
    v_before: f32,
}

/// Self-contact of one mesh across steps.
#[derive(Clone, Debug)]
pub struct SelfContact {
    edges: Vec<[u32; 2]>,
    triangles: Vec<[u32; 3]>,
    vertex_tree: Bvh,
    edge_tree: Bvh,
    face_tree: Bvh,
    /// Per vertex, edge, face: the union of its vertices' reach boxes, grown by half the
    /// thickness of the cached pairs (see [`SelfContact::ensure_pairs`]).
    vertex_boxes: Vec<Box32>,
    edge_boxes: Vec<Box32>,
    face_boxes: Vec<Box32>,
    /// Per vertex: the box its positions must stay in for the cached pairs to hold (see
    /// [`SelfContact::ensure_pairs`]).
    reach: Vec<Box32>,
    /// Cached (vertex, face) pairs sharing no vertex whose reach boxes come within
    /// `pairs_thickness`: a superset of the pairs whose swept boxes do, while every vertex stays
    /// in its reach.
    vf_pairs: Vec<(u32, u32)>,
    /// Cached (edge, edge) pairs, first index smaller, likewise.
    ee_pairs: Vec<(u32, u32)>,
    /// The thickness the cached pairs were found for; NaN when there are none.
    pairs_thickness: f64,
    /// The start positions of the step before (for the reach boxes' acceleration).
    before: Vec<Vec3>,
    /// Vertices that left their reach (scratch of [`SelfContact::ensure_pairs`]).
    escaped: Vec<u32>,
    /// Scratch of the BVH queries of a partial refill.
    query_stack: Vec<u32>,
    /// The CCD's search queues (kept between queries).
    search: SearchQueues,
    /// Scratch of the tree-against-tree traversals of a full refill.
    pair_stack: Vec<(u32, u32, bool)>,
    /// Scratch of a partial refill: the vertices, edges and faces it changed.
    changed: [Vec<u32>; 3],
    /// The edges and the faces of each vertex (CSR: those of v are at `[start[v], start[v+1])`),
    /// so that a partial refill finds the primitives of the escaped vertices without a pass
    /// over the mesh.
    vertex_edges: (Vec<u32>, Vec<u32>),
    vertex_faces: (Vec<u32>, Vec<u32>),
    /// Per vertex, edge, face: touched by an escaped vertex (scratch, all false between calls).
    dirty_vertex: Vec<bool>,
    dirty_edge: Vec<bool>,
    dirty_face: Vec<bool>,
    /// Per vertex, edge, face: the box swept over the step being resolved (see
    /// [`SelfContact::update_swept_boxes`]).
    vertex_swept: Vec<SweptBox>,
    edge_swept: Vec<SweptBox>,
    face_swept: Vec<SweptBox>,
    /// Per vertex: bit 0 = moved by the last projection round, bit 1 = put back by the fail-safe.
    flags: Vec<u8>,
    contacts: Vec<Contact>,
    /// Pairs found in the current round: (kind 0 = vertex-face, 1 = edge-edge, i, j, toi).
    hits: Vec<(u8, u32, u32, f64)>,
    settings: CcdSettings,
}

/// Reach of a vertex: the box of its two positions and of the end position carried on by
/// [`REACH_AHEAD`] more steps of the same displacement (steady motion stays inside for that many
/// steps), grown by [`REACH_OWN`] times its own displacement plus [`REACH_SHARED`] times the
/// largest one (and the thickness). Measured on the kitten at default settings (the bench): these
/// balance refills against the size of the cache. With the f32 trees, 4 steps ahead was 2-3%
/// faster than 3 and 5 on the kitten at default settings (min of 5 runs each), but 1.6 times as
/// slow on the kitten crushed by 30 times the pressure (20 steps: 5.2 s against 3.2 s per step),
/// where large motions make the look-ahead boxes huge.
const REACH_AHEAD: f32 = 3.0;
/// See [`REACH_AHEAD`].
const REACH_OWN: f32 = 0.5;
/// See [`REACH_AHEAD`]: a vertex at rest in that step may start moving.
const REACH_SHARED: f32 = 0.1;

/// The reach box of a vertex moving from `x0` to `x1` (see [`REACH_AHEAD`]), in f32: it must
/// hold the positions only, which [`SelfContact::ensure_pairs`] checks exactly, so its rounding
/// does not matter (and subtracting or adding a margin >= 0 never rounds past the point).
fn reach_box(before: Vec3, x0: Vec3, x1: Vec3, margin: f32) -> Box32 {
    let motion = x1 - x0;
    let ahead = x1 + motion * REACH_AHEAD;
    // With the change of motion since the step before, carried on as a constant acceleration.
    let change = motion - (x0 - before);
    let accelerated = ahead + change * (0.5 * REACH_AHEAD * (REACH_AHEAD + 1.0));
    let (x0, x1, ahead, accelerated) = (Vec3A::from(x0), Vec3A::from(x1), Vec3A::from(ahead), Vec3A::from(accelerated));
    let margin = Vec3A::splat(margin);
    Box32 { lo: x0.min(x1).min(ahead).min(accelerated) - margin, hi: x0.max(x1).max(ahead).max(accelerated) + margin }
}

/// `b` grown by at least `g` >= 0 on every side despite the f32 rounding: each bound moves by
/// `g (1 + 2^-18)` plus `2^-22` of its own size. Computing that shift and the sum round within a
/// relative 2^-24 each, less than those extra terms (the sum's error is within `2^-24` of the
/// bound plus the shift), so the computed bound is at least `g` out. Two boxes grown by `g` each
/// therefore overlap whenever their exact gap is at most `2 g (1 + 2^-19)`.
fn grown_outward(b: &Box32, g: f32) -> Box32 {
    let g = g * (1.0 + 1.0 / (1u32 << 18) as f32);
    let ulps = 1.0 / (1u32 << 22) as f32;
    Box32 { lo: b.lo - (Vec3A::splat(g) + b.lo.abs() * ulps), hi: b.hi + (Vec3A::splat(g) + b.hi.abs() * ulps) }
}
/// When at most 1/this of the vertices left their reach, only their pairs are found again (kitten
/// bench: 1/6 was at least as fast as 1/3, 1/10 and 1/20; escapes mostly come all at once).
const PARTIAL_REFILL_SHARE: usize = 6;

/// See [`CcdSettings::certain_contact_slack`]: pairs sampled within the thickness are contacts
/// without a search. A slack (up to 3/4 stays within the search's own false positives) was not
/// faster on the squeezed eight and left more contacts to the fail-safe (233 reverts in 60 steps
/// against 36 without).
const CERTAIN_CONTACT_SLACK: f64 = 0.0;

const MOVED: u8 = 1;
const REVERTED: u8 = 2;

#[inline]
fn d(v: Vec3) -> V3 {
    [v.x as f64, v.y as f64, v.z as f64]
}

/// The boxes of primitives at rest at `x`.
fn boxes_at_rest<const N: usize>(x: &[Vec3], prims: &[[u32; N]]) -> Vec<Box32> {
    let point = |v: u32| Box32 { lo: Vec3A::from(x[v as usize]), hi: Vec3A::from(x[v as usize]) };
    prims.iter().map(|prim| prim.iter().fold(Box32::EMPTY, |acc, &v| acc.union(&point(v)))).collect()
}

/// The box a primitive sweeps over the step: the exact bounds of its f32 positions at both ends.
#[derive(Clone, Copy, Debug)]
struct SweptBox {
    lo: Vec3A,
    hi: Vec3A,
}

impl SweptBox {
    const EMPTY: SweptBox = SweptBox { lo: Vec3A::INFINITY, hi: Vec3A::NEG_INFINITY };

    fn of_vertex(a: Vec3, b: Vec3) -> SweptBox {
        let (a, b) = (Vec3A::from(a), Vec3A::from(b));
        SweptBox { lo: a.min(b), hi: a.max(b) }
    }

    fn union(self, other: &SweptBox) -> SweptBox {
        SweptBox { lo: self.lo.min(other.lo), hi: self.hi.max(other.hi) }
    }

    /// Whether the boxes are more than the thickness `margin` apart on some axis, `margin` from
    /// [`swept_margin`]. Exact enough: a difference of two f32 values is computed within a
    /// relative 2^-24, so a computed gap above `margin` (the thickness rounded up by 2^-20 or
    /// more) means an exact gap above the thickness, and a NaN compares false ("maybe"). Only
    /// pairs within 2^-20 of the thickness on every separating axis are kept where the f64 test of
    /// [`super::filters::swept_aabbs_separated`] would drop them.
    #[inline]
    fn separated(&self, other: &SweptBox, margin: Vec3A) -> bool {
        ((other.lo - self.hi).cmpgt(margin) | (self.lo - other.hi).cmpgt(margin)).any()
    }
}

/// The f32 margin for [`SweptBox::separated`]: `thickness` rounded up (infinite when it does not
/// fit in an f32, so that nothing is separated).
fn swept_margin(thickness: f64) -> Vec3A {
    let m = (thickness * (1.0 + 1.0 / (1u64 << 20) as f64)) as f32;
    Vec3A::splat(if m.is_finite() { m } else { f32::INFINITY })
}

/// Closest point of `p` on triangle `abc`: barycentric weights (α_a, α_b, α_c) (Ericson,
/// "Real-Time Collision Detection" 5.1.5).
pub(crate) fn closest_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> [f64; 3] {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = va + vb + vc;
    if !(denom.abs() > 0.0) {
        return [1.0 / 3.0; 3]; // degenerate triangle
    }
    let (v, w) = (vb / denom, vc / denom);
    [1.0 - v - w, v, w]
}

/// Parameters (s, t) of the closest points of segments p1q1 and p2q2 (Ericson 5.1.9).
pub(crate) fn closest_segments(p1: DVec3, q1: DVec3, p2: DVec3, q2: DVec3) -> (f64, f64) {
    let (d1, d2, r) = (q1 - p1, q2 - p2, p1 - p2);
    let (a, e, f) = (d1.length_squared(), d2.length_squared(), d2.dot(r));
    let tiny = 1e-300;
    if a <= tiny && e <= tiny {
        return (0.0, 0.0);
    }
    if a <= tiny {
        return (0.0, (f / e).clamp(0.0, 1.0));
    }
    let c = d1.dot(r);
    if e <= tiny {
        return ((-c / a).clamp(0.0, 1.0), 0.0);
    }
    let b = d1.dot(d2);
    let denom = a * e - b * b;
    let mut s = if denom > 0.0 { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
    let mut t = (b * s + f) / e;
    if t < 0.0 {
        t = 0.0;
        s = (-c / a).clamp(0.0, 1.0);
    } else if t > 1.0 {
        t = 1.0;
        s = ((b - c) / a).clamp(0.0, 1.0);
    }
    (s, t)
}

fn lerp(x0: &[Vec3], x1: &[Vec3], v: u32, t: f64) -> DVec3 {
    let (a, b) = (x0[v as usize].as_dvec3(), x1[v as usize].as_dvec3());
    a + (b - a) * t
}

/// The side a pair came from: the sign of `n · w0` at the start, or of the motion's reverse.
fn side(n: DVec3, w_start: DVec3, w_end: DVec3) -> f64 {
    let s0 = n.dot(w_start);
    if s0 != 0.0 {
        return s0.signum();
    }
    let motion = n.dot(w_end - w_start);
    if motion != 0.0 { -motion.signum() } else { 1.0 }
}

impl SelfContact {
    /// Builds the trees for a mesh at rest (`x` at both ends of the step).
    pub fn new(x: &[Vec3], edges: &[[u32; 2]], triangles: &[[u32; 3]]) -> Self {
        let ids: Vec<[u32; 1]> = (0..x.len() as u32).map(|v| [v]).collect();
        let (vertex_boxes, edge_boxes, face_boxes) =
            (boxes_at_rest(x, &ids), boxes_at_rest(x, edges), boxes_at_rest(x, triangles));
        // A few contacts per hundred vertices before the first reallocation.
        let reserve = 64 + x.len() / 16;
        Self {
            edges: edges.to_vec(),
            triangles: triangles.to_vec(),
            // Keys: the vertices, so that neighbours sharing one are skipped in the traversals.
            vertex_tree: Bvh::build32(vertex_boxes.clone(), (0..x.len() as u32).map(|v| [v; 3]).collect()),
            edge_tree: Bvh::build32(edge_boxes.clone(), edges.iter().map(|&[a, b]| [a, b, a]).collect()),
            face_tree: Bvh::build32(face_boxes.clone(), triangles.to_vec()),
            vertex_boxes,
            edge_boxes,
            face_boxes,
            reach: vec![Box32::EMPTY; x.len()],
            // Enough for the pairs of a mesh at rest (the first step) without reallocation.
            vf_pairs: Vec::with_capacity(x.len() + 64),
            ee_pairs: Vec::with_capacity(edges.len() + 64),
            pairs_thickness: f64::NAN,
            escaped: Vec::with_capacity(x.len()),
            query_stack: Vec::with_capacity(64),
            pair_stack: Vec::with_capacity(64),
            search: SearchQueues::default(),
            changed: Default::default(),
            before: x.to_vec(),
            vertex_edges: vertex_incidence(x.len(), edges, |e, _| e as u32),
            vertex_faces: vertex_incidence(x.len(), triangles, |f, _| f as u32),
            dirty_vertex: vec![false; x.len()],
            dirty_edge: vec![false; edges.len()],
            dirty_face: vec![false; triangles.len()],
            vertex_swept: vec![SweptBox::EMPTY; x.len()],
            edge_swept: vec![SweptBox::EMPTY; edges.len()],
            face_swept: vec![SweptBox::EMPTY; triangles.len()],
            flags: vec![0; x.len()],
            contacts: Vec::with_capacity(reserve),
            hits: Vec::with_capacity(reserve),
            // Most pairs that reach the exact stage in a contracting shell do collide: pairs
            // projected to the thickness in the last step start this one about the thickness
            // apart, and most others are within it at some sample time. The time of such a
            // contact only sets its normal and weights (SPEC 1.6; the side comes from the start
            // of the step), so it is estimated from below instead of searched to 2^-20: the
            // search is left for the pairs whose answer is in doubt.
            settings: CcdSettings { certain_contact_slack: Some(CERTAIN_CONTACT_SLACK), ..CcdSettings::default() },
        }
    }

    /// Heap bytes (each array's capacity, the trees' too; the struct itself is its owner's:
    /// the shell holds it inline, and counted it twice).
    pub fn memory_bytes(&self) -> usize {
        fn b<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        b(&self.edges)
            + b(&self.triangles)
            + self.vertex_tree.memory_bytes()
            + self.edge_tree.memory_bytes()
            + self.face_tree.memory_bytes()
            + b(&self.vertex_boxes)
            + b(&self.edge_boxes)
            + b(&self.face_boxes)
            + b(&self.reach)
            + b(&self.vf_pairs)
            + b(&self.ee_pairs)
            + b(&self.escaped)
            + b(&self.query_stack)
            + b(&self.pair_stack)
            + self.search.memory_bytes()
            + self.changed.iter().map(b).sum::<usize>()
            + b(&self.before)
            + b(&self.vertex_edges.0)
            + b(&self.vertex_edges.1)
            + b(&self.vertex_faces.0)
            + b(&self.vertex_faces.1)
            + b(&self.dirty_vertex)
            + b(&self.dirty_edge)
            + b(&self.dirty_face)
            + b(&self.vertex_swept)
            + b(&self.edge_swept)
            + b(&self.face_swept)
            + b(&self.flags)
            + b(&self.contacts)
            + b(&self.hits)
    }

    /// Makes sure the cached pairs hold every pair whose swept boxes over `x0 -> x1` come within
    /// `thickness` (a Verlet list, as in molecular dynamics): they do while every vertex's
    /// positions at both ends stay in its reach box and `thickness` is at most the one they were
    /// found for. Then a primitive's swept box lies in the union of its vertices' reach boxes,
    /// so two swept boxes within `thickness` imply reach unions within it, and the traversal
    /// that filled the cache collected the pair. Otherwise the reach boxes of the vertices that
    /// left are set anew (the box of the vertex's positions now and a few steps ahead, grown by a
    /// margin, see [`REACH_AHEAD`], so that steady motion keeps the cache for several steps),
    /// and only their pairs are found again
    /// ([`SelfContact::refill_escaped`]); when many left, or the thickness grew, every reach box
    /// is set anew, the trees are refit (or rebuilt) over the reach unions and the cache is
    /// refilled. Returns the number of trees rebuilt, or None when the cache still held.
    fn ensure_pairs(&mut self, x0: &[Vec3], x1: &[Vec3], thickness: f64) -> Option<u64> {
        let n = x0.len();
        let motion = |v: usize| (x1[v] - x0[v]).abs().max_element();
        let outside = |r: &Box32, v: usize| !(r.contains_point(x0[v].into()) && r.contains_point(x1[v].into()));
        if thickness <= self.pairs_thickness {
            self.escaped.clear();
            self.escaped.extend((0..n as u32).filter(|&v| outside(&self.reach[v as usize], v as usize)));
            if self.escaped.is_empty() {
                return None;
            }
            if self.escaped.len() * PARTIAL_REFILL_SHARE <= n {
                self.refill_escaped(x0, x1);
                return Some(0);
            }
        }
        let largest = (0..n).map(motion).fold(0.0, f32::max);
        let slack = REACH_SHARED * largest + thickness as f32;
        for v in 0..n {
            self.reach[v] = reach_box(self.before[v], x0[v], x1[v], REACH_OWN * motion(v) + slack);
        }
        let half = (0.5 * thickness) as f32;
        let reach = &self.reach;
        let union = |prim: &[u32]| {
            grown_outward(&prim.iter().fold(Box32::EMPTY, |acc, &v| acc.union(&reach[v as usize])), half)
        };
        for (v, b) in self.vertex_boxes.iter_mut().enumerate() {
            *b = union(&[v as u32]);
        }
        for (e, b) in self.edges.iter().zip(self.edge_boxes.iter_mut()) {
            *b = union(e);
        }
        for (t, b) in self.triangles.iter().zip(self.face_boxes.iter_mut()) {
            *b = union(t);
        }
        let rebuilt = u64::from(self.vertex_tree.update32(&self.vertex_boxes))
            + u64::from(self.edge_tree.update32(&self.edge_boxes))
            + u64::from(self.face_tree.update32(&self.face_boxes));
        let (tris, edges) = (&self.triangles, &self.edges);
        let (vf, ee) = (&mut self.vf_pairs, &mut self.ee_pairs);
        vf.clear();
        ee.clear();
        let stack = &mut self.pair_stack;
        self.vertex_tree.for_each_overlap_with(&self.face_tree, stack, |v, f| {
            if !tris[f as usize].contains(&v) {
                vf.push((v, f));
            }
        });
        self.edge_tree.for_each_self_overlap_with(stack, |i, j| {
            let ([a, b], [c, e]) = (edges[i as usize], edges[j as usize]);
            if a != c && a != e && b != c && b != e {
                ee.push((i, j));
            }
        });
        self.pairs_thickness = thickness;
        Some(rebuilt)
    }

    /// The partial refill of [`SelfContact::ensure_pairs`] when few vertices (`self.escaped`)
    /// left their reach: new reach boxes for them, new boxes for the primitives they belong to,
    /// the trees refit, the cached pairs of those primitives dropped and found again by querying
    /// small trees over them against the full ones. The cache then equals what a full refill
    /// with these reach boxes would hold.
    fn refill_escaped(&mut self, x0: &[Vec3], x1: &[Vec3]) {
        let motion = |v: usize| (x1[v] - x0[v]).abs().max_element();
        let largest = (0..x0.len()).map(motion).fold(0.0, f32::max);
        let thickness = self.pairs_thickness;
        let slack = REACH_SHARED * largest + thickness as f32;
        let half = (0.5 * thickness) as f32;
        for &v in &self.escaped {
            let v = v as usize;
            self.reach[v] = reach_box(self.before[v], x0[v], x1[v], REACH_OWN * motion(v) + slack);
            self.dirty_vertex[v] = true;
        }
        let reach = &self.reach;
        let union = |prim: &[u32]| {
            grown_outward(&prim.iter().fold(Box32::EMPTY, |acc, &v| acc.union(&reach[v as usize])), half)
        };
        let [mut mv, mut me, mut mf] = std::mem::take(&mut self.changed);
        for changed in [&mut mv, &mut me, &mut mf] {
            changed.clear();
        }
        for &v in &self.escaped {
            self.vertex_boxes[v as usize] = union(&[v]);
            mv.push(v);
            let (es, el) = &self.vertex_edges;
            for &e in &el[es[v as usize] as usize..es[v as usize + 1] as usize] {
                if !self.dirty_edge[e as usize] {
                    self.dirty_edge[e as usize] = true;
                    self.edge_boxes[e as usize] = union(&self.edges[e as usize]);
                    me.push(e);
                }
            }
            let (fs, fl) = &self.vertex_faces;
            for &f in &fl[fs[v as usize] as usize..fs[v as usize + 1] as usize] {
                if !self.dirty_face[f as usize] {
                    self.dirty_face[f as usize] = true;
                    self.face_boxes[f as usize] = union(&self.triangles[f as usize]);
                    mf.push(f);
                }
            }
        }
        // Fixed order (the traversal order follows it): as a pass over the mesh would list them.
        me.sort_unstable();
        mf.sort_unstable();
        // Grow the nodes above them only: the full refills refit and check the trees' looseness.
        self.vertex_tree.update_some(&mv, &self.vertex_boxes);
        self.edge_tree.update_some(&me, &self.edge_boxes);
        self.face_tree.update_some(&mf, &self.face_boxes);
        let (dv, de, df) = (&self.dirty_vertex, &self.dirty_edge, &self.dirty_face);
        self.vf_pairs.retain(|&(v, f)| !dv[v as usize] && !df[f as usize]);
        self.ee_pairs.retain(|&(i, j)| !de[i as usize] && !de[j as usize]);
        let (tris, edges) = (&self.triangles, &self.edges);
        let (vf, ee) = (&mut self.vf_pairs, &mut self.ee_pairs);
        // One query per changed primitive: the changed ones are scattered over the mesh, where
        // a tree over them would have huge upper nodes (a dual traversal took 1.6x as long).
        let stack = &mut self.query_stack;
        // Escaped vertices against every face; every other vertex against the touched faces.
        for &v in &mv {
            self.face_tree.for_each_overlap_of(&self.vertex_boxes[v as usize], stack, |f| {
                if !tris[f as usize].contains(&v) {
                    vf.push((v, f));
                }
            });
        }
        for &f in &mf {
            self.vertex_tree.for_each_overlap_of(&self.face_boxes[f as usize], stack, |v| {
                if !dv[v as usize] && !tris[f as usize].contains(&v) {
                    vf.push((v, f));
                }
            });
        }
        // Touched edges against every edge; a pair of two touched edges once.
        for &i in &me {
            self.edge_tree.for_each_overlap_of(&self.edge_boxes[i as usize], stack, |j| {
                let ([a, b], [c, e]) = (edges[i as usize], edges[j as usize]);
                if (!de[j as usize] || i < j) && a != c && a != e && b != c && b != e {
                    ee.push((i.min(j), i.max(j)));
                }
            });
        }
        for &v in &self.escaped {
            self.dirty_vertex[v as usize] = false;
        }
        for &e in &me {
            self.dirty_edge[e as usize] = false;
        }
        for &f in &mf {
            self.dirty_face[f as usize] = false;
        }
        self.changed = [mv, me, mf];
    }

    /// [`SelfContact::ensure_pairs`], counting cache refills; returns the tree rebuilds.
    fn ensure_pairs_counted(&mut self, x0: &[Vec3], x1: &[Vec3], thickness: f64, counts: &mut ContactCounts) -> u64 {
        match self.ensure_pairs(x0, x1, thickness) {
            Some(rebuilt) => {
                counts.pair_refills += 1;
                rebuilt
            }
            None => 0,
        }
    }

    /// Finds the pairs that may come within `thickness` over `x0 -> x1` into `self.hits`.
    /// With `only_moved`, only pairs with a vertex flagged MOVED are tested; pairs whose four
    /// vertices were all put back are skipped (they do not move).
    /// Sets the swept boxes over `x0 -> x1` of every primitive, or with `only_moved` of the
    /// primitives of the vertices flagged MOVED (the only ones whose positions changed since).
    fn update_swept_boxes(&mut self, x0: &[Vec3], x1: &[Vec3], only_moved: bool) {
        if !only_moved {
            for (v, b) in self.vertex_swept.iter_mut().enumerate() {
                *b = SweptBox::of_vertex(x0[v], x1[v]);
            }
            let vb = &self.vertex_swept;
            for (e, b) in self.edges.iter().zip(self.edge_swept.iter_mut()) {
                *b = vb[e[0] as usize].union(&vb[e[1] as usize]);
            }
            for (t, b) in self.triangles.iter().zip(self.face_swept.iter_mut()) {
                *b = vb[t[0] as usize].union(&vb[t[1] as usize]).union(&vb[t[2] as usize]);
            }
            return;
        }
        // Also flags the primitives of the moved vertices in the `dirty_*` scratch (cleared by
        // `clear_moved_primitives`), so that the pairs to re-check are found with two lookups.
        for v in 0..x0.len() {
            if self.flags[v] & MOVED != 0 {
                self.vertex_swept[v] = SweptBox::of_vertex(x0[v], x1[v]);
                self.dirty_vertex[v] = true;
            }
        }
        let ((es, el), (fs, fl)) = (&self.vertex_edges, &self.vertex_faces);
        let vb = &self.vertex_swept;
        for v in 0..x0.len() {
            if self.flags[v] & MOVED == 0 {
                continue;
            }
            for &e in &el[es[v] as usize..es[v + 1] as usize] {
                let [a, b] = self.edges[e as usize];
                self.edge_swept[e as usize] = vb[a as usize].union(&vb[b as usize]);
                self.dirty_edge[e as usize] = true;
            }
            for &f in &fl[fs[v] as usize..fs[v + 1] as usize] {
                let [a, b, c] = self.triangles[f as usize];
                self.face_swept[f as usize] = vb[a as usize].union(&vb[b as usize]).union(&vb[c as usize]);
                self.dirty_face[f as usize] = true;
            }
        }
    }

    /// Clears the flags `update_swept_boxes` set on the primitives of the moved vertices.
    fn clear_moved_primitives(&mut self) {
        let ((es, el), (fs, fl)) = (&self.vertex_edges, &self.vertex_faces);
        for v in 0..self.flags.len() {
            if self.flags[v] & MOVED == 0 {
                continue;
            }
            self.dirty_vertex[v] = false;
            for &e in &el[es[v] as usize..es[v + 1] as usize] {
                self.dirty_edge[e as usize] = false;
            }
            for &f in &fl[fs[v] as usize..fs[v + 1] as usize] {
                self.dirty_face[f as usize] = false;
            }
        }
    }

    fn detect(&mut self, x0: &[Vec3], x1: &[Vec3], thickness: f64, only_moved: bool, counts: &mut ContactCounts) {
        self.hits.clear();
        self.update_swept_boxes(x0, x1, only_moved);
        let margin = swept_margin(thickness);
        let largest = x0.iter().chain(x1.iter()).fold(0.0f32, |m, p| m.max(p.abs().max_element())) as f64;
        let diagonal = diagonal_margin(thickness, largest);
        let at = |x: &[Vec3], v: u32| Vec3A::from(x[v as usize]);
        let (vb, eb, fb) = (&self.vertex_swept, &self.edge_swept, &self.face_swept);
        // With `only_moved`: the primitives with a moved vertex.
        let (mv, me, mf) = (&self.dirty_vertex, &self.dirty_edge, &self.dirty_face);
        let (tris, edges, flags, settings) = (&self.triangles, &self.edges, &self.flags, &self.settings);
        let hits = &mut self.hits;
        let search = &mut self.search;
        let first = !only_moved;
        // Stage None: refuted by the hull filter.
        let mut tally = |stage: Option<Stage>| {
            if first {
                counts.candidates += 1;
                if let Some(stage) = stage.filter(|&s| s != Stage::SweptAabb) {
                    counts.after_boxes += 1;
                    if stage != Stage::PlaneFilter {
                        counts.ccd_tests += 1;
                    }
                }
            }
        };
        let wanted = |idx: [u32; 4]| {
            let f = idx.map(|v| flags[v as usize]);
            if f.iter().all(|&x| x & REVERTED != 0) {
                return false;
            }
            !only_moved || f.iter().any(|&x| x & MOVED != 0)
        };
        // One pair whose swept boxes come within the margin: kind 0 = (vertex, face), 1 = (edge,
        // edge). The loops below test the boxes first, so that only these pairs make the call.
        let mut test = |kind: u8, i: u32, j: u32| {
            if kind == 0 {
                let (v, f) = (i, j);
                let t = tris[f as usize];
                if t.contains(&v) || !wanted([v, t[0], t[1], t[2]]) {
                    return;
                }
                let face = [at(x0, t[0]), at(x0, t[1]), at(x0, t[2]), at(x1, t[0]), at(x1, t[1]), at(x1, t[2])];
                if diagonals_separated(&[at(x0, v), at(x1, v)], &face, diagonal) {
                    tally(None);
                    return;
                }
                let start = [d(x0[v as usize]), d(x0[t[0] as usize]), d(x0[t[1] as usize]), d(x0[t[2] as usize])];
                let end = [d(x1[v as usize]), d(x1[t[0] as usize]), d(x1[t[1] as usize]), d(x1[t[2] as usize])];
                if vertex_triangle_hulls_separated(&start, &end, thickness) {
                    tally(None);
                    return;
                }
                let out = vertex_triangle_in(&start, &end, thickness, settings, search);
                tally(Some(out.stage));
                if let Some(toi) = out.toi {
                    hits.push((0, v, f, toi));
                }
            } else {
                let (i, j) = (i.min(j), i.max(j));
                let ([a, b], [c, e]) = (edges[i as usize], edges[j as usize]);
                if a == c || a == e || b == c || b == e || !wanted([a, b, c, e]) {
                    return;
                }
                let first = [at(x0, a), at(x0, b), at(x1, a), at(x1, b)];
                if diagonals_separated(&first, &[at(x0, c), at(x0, e), at(x1, c), at(x1, e)], diagonal) {
                    tally(None);
                    return;
                }
                let start = [d(x0[a as usize]), d(x0[b as usize]), d(x0[c as usize]), d(x0[e as usize])];
                let end = [d(x1[a as usize]), d(x1[b as usize]), d(x1[c as usize]), d(x1[e as usize])];
                if edge_edge_hulls_separated(&start, &end, thickness) {
                    tally(None);
                    return;
                }
                let out = edge_edge_in(&start, &end, thickness, settings, search);
                tally(Some(out.stage));
                if let Some(toi) = out.toi {
                    hits.push((1, i, j, toi));
                }
            }
        };
        // The cached pairs are a superset: the swept boxes decide who is a candidate (with
        // `only_moved`, flags first: most pairs are not wanted).
        for &(v, f) in &self.vf_pairs {
            if only_moved && !(mv[v as usize] || mf[f as usize]) || vb[v as usize].separated(&fb[f as usize], margin) {
                continue;
            }
            test(0, v, f);
        }
        for &(i, j) in &self.ee_pairs {
            if only_moved && !(me[i as usize] || me[j as usize]) || eb[i as usize].separated(&eb[j as usize], margin) {
                continue;
            }
            test(1, i, j);
        }
        // The traversal order is fixed, but sort anyway so the projection order is the pairs'.
        self.hits.sort_unstable_by(|x, y| (x.0, x.1, x.2).cmp(&(y.0, y.1, y.2)));
        self.hits.dedup_by(|x, y| (x.0, x.1, x.2) == (y.0, y.1, y.2));
        if only_moved {
            self.clear_moved_primitives();
        }
    }

    /// A contact constraint for hit `k` of `self.hits`: weights and barycentrics at the time of
    /// impact, normal from the configuration there, side from the start of the step.
    fn contact_of(&self, hit: (u8, u32, u32, f64), x0: &[Vec3], x1: &[Vec3], h: f32) -> Option<Contact> {
        let (kind, i, j, toi) = hit;
        let (idx, g, n) = if kind == 0 {
            let t = self.triangles[j as usize];
            let idx = [i, t[0], t[1], t[2]];
            let y = idx.map(|v| lerp(x0, x1, v, toi));
            let s = idx.map(|v| x0[v as usize].as_dvec3());
            let e = idx.map(|v| x1[v as usize].as_dvec3());
            let al = closest_on_triangle(y[0], y[1], y[2], y[3]);
            let q = |p: &[DVec3; 4]| p[0] - (p[1] * al[0] + p[2] * al[1] + p[3] * al[2]);
            let mut n = (y[2] - y[1]).cross(y[3] - y[1]);
            if !(n.length_squared() > 0.0) {
                n = q(&y);
            }
            let n = n.normalize_or_zero();
            if n == DVec3::ZERO {
                return None;
            }
            let n = n * side(n, q(&s), q(&e));
            (idx, [1.0, -al[0], -al[1], -al[2]], n)
        } else {
            let ([a, b], [c, e]) = (self.edges[i as usize], self.edges[j as usize]);
            let idx = [a, b, c, e];
            let y = idx.map(|v| lerp(x0, x1, v, toi));
            let s = idx.map(|v| x0[v as usize].as_dvec3());
            let en = idx.map(|v| x1[v as usize].as_dvec3());
            let (sa, sb) = closest_segments(y[0], y[1], y[2], y[3]);
            let w = |p: &[DVec3; 4]| (p[0] * (1.0 - sa) + p[1] * sa) - (p[2] * (1.0 - sb) + p[3] * sb);
            let (e1, e2) = (y[1] - y[0], y[3] - y[2]);
            let mut n = e1.cross(e2);
            // Nearly parallel edges: the cross product's direction is noise; use the gap.
            if !(n.length_squared() > 1e-12 * e1.length_squared() * e2.length_squared()) {
                n = w(&y);
                if !(n.length_squared() > 0.0) {
                    n = w(&s);
                }
            }
            let n = n.normalize_or_zero();
            if n == DVec3::ZERO {
                return None;
            }
            let n = n * side(n, w(&s), w(&en));
            (idx, [1.0 - sa, sa, -(1.0 - sb), -sb], n)
        };
        let g = g.map(|x| x as f32);
        let n = n.as_vec3();
        let mut rel = Vec3::ZERO;
        for k in 0..4 {
            rel += (x1[idx[k] as usize] - x0[idx[k] as usize]) * g[k];
        }
        Some(Contact { idx, g, n, v_before: n.dot(rel) / h })
    }

    /// A pair sharing no vertex that is within `thickness` of each other at rest at `x`, if
    /// any: (0 = vertex-face, 1 = edge-edge, vertex or first edge, face or second edge). Such a
    /// pair would be pushed apart by the first step's contact stage whatever the motion.
    pub fn pair_within_at_rest(&mut self, x: &[Vec3], thickness: f64) -> Option<(u8, u32, u32)> {
        self.flags.fill(0);
        self.ensure_pairs(x, x, thickness);
        self.detect(x, x, thickness, false, &mut ContactCounts::default());
        let first = self.hits.first().map(|&(kind, i, j, _)| (kind, i, j));
        self.hits.clear();
        first
    }

    /// Resolves self-contact over the step `x0 -> p` at contact distance `thickness`: corrects
    /// `p` in place (vertices with inverse mass 0 do not move). `h` is the (sub)step length, for
    /// the velocities of [`SelfContact::limit_velocities`].
    pub fn resolve(&mut self, x0: &[Vec3], p: &mut [Vec3], inv_mass: &[f32], thickness: f64, h: f32) -> ContactCounts {
        let counts = self.resolve_from(x0, p, inv_mass, thickness, h);
        self.before.copy_from_slice(x0);
        counts
    }

    fn resolve_from(&mut self, x0: &[Vec3], p: &mut [Vec3], inv_mass: &[f32], thickness: f64, h: f32) -> ContactCounts {
        let mut counts = ContactCounts::default();
        self.contacts.clear();
        self.flags.fill(0);
        counts.rebuilds += self.ensure_pairs_counted(x0, p, thickness, &mut counts);
        for round in 0..ROUNDS {
            counts.rounds += 1;
            let check = if round == 0 { thickness } else { RECHECK_FRACTION * thickness };
            if round > 0 {
                counts.rebuilds += self.ensure_pairs_counted(x0, p, check, &mut counts);
            }
            self.detect(x0, p, check, round > 0, &mut counts);
            if self.hits.is_empty() {
                return counts;
            }
            let first_new = self.contacts.len();
            for k in 0..self.hits.len() {
                if let Some(c) = self.contact_of(self.hits[k], x0, p, h) {
                    self.contacts.push(c);
                }
            }
            counts.contacts += (self.contacts.len() - first_new) as u64;
            self.flags.fill(0);
            self.project(p, inv_mass, thickness as f32);
            // Re-check every pair found (its constraint may hold at the end of the step while its
            // path still crosses) besides every pair the projection moved.
            for k in 0..self.hits.len() {
                for v in self.hit_vertices(k) {
                    self.flags[v as usize] |= MOVED;
                }
            }
        }
        // Fail-safe: contacts remain after the projection rounds. Put the vertices of every pair
        // that may still intersect (thickness 0) back to the start, until none does.
        // Pairs whose trajectories did not change since they were last found clear (at a larger
        // thickness) stay clear: only pairs with a vertex moved by the last projection, then with
        // a vertex newly put back, are tested.
        loop {
            counts.rounds += 1;
            counts.rebuilds += self.ensure_pairs_counted(x0, p, 0.0, &mut counts);
            self.detect(x0, p, 0.0, true, &mut ContactCounts::default());
            for f in &mut self.flags {
                *f &= REVERTED;
            }
            if self.hits.is_empty() {
                return counts;
            }
            for k in 0..self.hits.len() {
                for v in self.hit_vertices(k) {
                    if self.flags[v as usize] & REVERTED == 0 {
                        self.flags[v as usize] |= REVERTED | MOVED;
                        p[v as usize] = x0[v as usize];
                        counts.reverted += 1;
                    }
                }
            }
        }
    }

    /// The four vertices of hit `k`.
    fn hit_vertices(&self, k: usize) -> [u32; 4] {
        let (kind, i, j, _) = self.hits[k];
        if kind == 0 {
            let t = self.triangles[j as usize];
            [i, t[0], t[1], t[2]]
        } else {
            let ([a, b], [c, e]) = (self.edges[i as usize], self.edges[j as usize]);
            [a, b, c, e]
        }
    }

    /// Gauss-Seidel over the contacts: `Δλ = -C / Σ w_k g_k²`, `Δp_k = w_k g_k Δλ n` when `C < 0`.
    /// Flags every vertex it moves.
    fn project(&mut self, p: &mut [Vec3], inv_mass: &[f32], thickness: f32) {
        for _ in 0..SWEEPS {
            for c in &self.contacts {
                let mut gap = -thickness;
                let mut denom = 0.0;
                for k in 0..4 {
                    let v = c.idx[k] as usize;
                    gap += c.g[k] * c.n.dot(p[v]);
                    denom += inv_mass[v] * c.g[k] * c.g[k];
                }
                if !(gap < 0.0) || !(denom > 0.0) {
                    continue;
                }
                let dl = -gap / denom;
                for k in 0..4 {
                    let v = c.idx[k] as usize;
                    let step = inv_mass[v] * c.g[k] * dl;
                    if step != 0.0 {
                        p[v] += c.n * step;
                        self.flags[v] |= MOVED;
                    }
                }
            }
        }
    }

    /// After the velocity update: no contact of the last [`SelfContact::resolve`] may leave with a
    /// relative normal velocity larger than it had before the contact (or 0), so the push out of
    /// the thickness adds no energy (an inelastic, mass-weighted normal impulse can only remove
    /// kinetic energy).
    pub fn limit_velocities(&self, v: &mut [Vec3], inv_mass: &[f32]) {
        for c in &self.contacts {
            let mut rel = 0.0;
            let mut denom = 0.0;
            for k in 0..4 {
                let i = c.idx[k] as usize;
                rel += c.g[k] * c.n.dot(v[i]);
                denom += inv_mass[i] * c.g[k] * c.g[k];
            }
            let allowed = c.v_before.max(0.0);
            if !(rel > allowed) || !(denom > 0.0) {
                continue;
            }
            let dl = (allowed - rel) / denom;
            for k in 0..4 {
                let i = c.idx[k] as usize;
                v[i] += c.n * (inv_mass[i] * c.g[k] * dl);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two parallel unit squares (two triangles each), `gap` apart along z.
    fn two_plates(gap: f32) -> (Vec<Vec3>, Vec<[u32; 3]>, Vec<[u32; 2]>) {
        let mut x = Vec::new();
        for z in [0.0, gap] {
            x.extend([Vec3::new(0.0, 0.0, z), Vec3::new(1.0, 0.0, z), Vec3::new(1.0, 1.0, z), Vec3::new(0.0, 1.0, z)]);
        }
        let tris = vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
        let edges = crate::mesh::Topology::build(&tris, x.len()).edges;
        (x, tris, edges)
    }

    #[test]
    fn a_plate_pushed_through_another_stays_on_its_side() {
        let (x0, tris, edges) = two_plates(0.1);
        // The upper plate moves down through the lower one, slightly tilted.
        let mut p: Vec<Vec3> = x0
            .iter()
            .enumerate()
            .map(|(i, &v)| if i >= 4 { v - Vec3::new(0.0, 0.0, 0.3 + 0.01 * i as f32) } else { v })
            .collect();
        let w = vec![1.0; x0.len()];
        let mut sc = SelfContact::new(&x0, &edges, &tris);
        let counts = sc.resolve(&x0, &mut p, &w, 1e-3, 0.01);
        assert!(counts.contacts > 0 && counts.ccd_tests > 0, "{counts:?}");
        for j in 0..4 {
            // Each corner of the upper plate stays above the same corner of the lower one.
            assert!(p[j + 4].z > p[j].z, "corner {j}: {} not above {}", p[j + 4].z, p[j].z);
        }
        // Nothing left to find.
        let mut again = SelfContact::new(&x0, &edges, &tris);
        let mut q = p.clone();
        let c = again.resolve(&x0, &mut q, &w, 0.0, 0.01);
        assert_eq!(c.contacts, 0, "{c:?}");
        assert_eq!(q, p);
    }

    #[test]
    fn contact_velocities_do_not_gain_energy() {
        let (x0, tris, edges) = two_plates(0.1);
        let h = 0.01;
        let mut p: Vec<Vec3> =
            x0.iter().enumerate().map(|(i, &v)| if i >= 4 { v - Vec3::new(0.0, 0.0, 0.2) } else { v }).collect();
        let w = vec![1.0; x0.len()];
        let mut sc = SelfContact::new(&x0, &edges, &tris);
        let before: f32 = p.iter().zip(&x0).map(|(a, b)| ((*a - *b) / h).length_squared()).sum();
        sc.resolve(&x0, &mut p, &w, 1e-3, h);
        let mut v: Vec<Vec3> = p.iter().zip(&x0).map(|(a, b)| (*a - *b) / h).collect();
        sc.limit_velocities(&mut v, &w);
        let after: f32 = v.iter().map(|a| a.length_squared()).sum();
        assert!(after <= before, "{before} -> {after}");
        // No pair separates along its normal after the contact.
        for i in 4..8 {
            assert!(v[i].z <= 1e-4, "{:?}", v[i]);
        }
    }

    #[test]
    fn cached_pairs_hold_every_pair_whose_swept_boxes_meet() {
        // A crumpled 10 x 10 sheet moved randomly, with motions that grow and shrink so that
        // vertices leave their reach one by one (partial refills) and all at once (full ones).
        let mut seed = 0x1234_5678_9ABC_DEF0u64;
        let mut unit = move || {
            seed ^= seed >> 12;
            seed ^= seed << 25;
            seed ^= seed >> 27;
            (seed.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        let n = 10;
        let mut x: Vec<Vec3> = (0..n * n)
            .map(|k| Vec3::new((k % n) as f32 / n as f32, (k / n) as f32 / n as f32, 0.02 * unit()))
            .collect();
        let mut tris = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let v = (j * n + i) as u32;
                let n = n as u32;
                tris.extend([[v, v + 1, v + n + 1], [v, v + n + 1, v + n]]);
            }
        }
        let edges = crate::mesh::Topology::build(&tris, x.len()).edges;
        let mut sc = SelfContact::new(&x, &edges, &tris);
        let thickness = 0.01;
        let (mut partial, mut full) = (0, 0);
        for step in 0..60 {
            let amount = [0.002, 0.02, 0.005, 0.05][step % 4] * if step % 7 == 0 { 3.0 } else { 1.0 };
            let few = step % 3 == 1;
            let x1: Vec<Vec3> = x
                .iter()
                .enumerate()
                .map(|(v, &p)| {
                    let s = if few && v % 17 != 0 { 0.01 } else { 1.0 };
                    p + Vec3::new(unit(), unit(), unit()) * amount * s
                })
                .collect();
            if sc.ensure_pairs(&x, &x1, thickness).is_some() {
                if sc.escaped.len() * PARTIAL_REFILL_SHARE <= x.len() && sc.escaped.len() > 0 && step > 0 {
                    partial += 1;
                } else {
                    full += 1;
                }
            }
            // What `detect` asks of the cache: every pair whose swept boxes are not separated.
            let swept = |prim: &[u32]| {
                prim.iter()
                    .fold(SweptBox::EMPTY, |acc, &v| acc.union(&SweptBox::of_vertex(x[v as usize], x1[v as usize])))
            };
            let meet = |p: &[u32], q: &[u32]| !swept(p).separated(&swept(q), swept_margin(thickness));
            let (mut vf, mut ee) = (sc.vf_pairs.clone(), sc.ee_pairs.clone());
            vf.sort_unstable();
            ee.sort_unstable();
            for v in 0..x.len() as u32 {
                for (f, t) in tris.iter().enumerate() {
                    if !t.contains(&v) && meet(&[v], t) {
                        assert!(vf.binary_search(&(v, f as u32)).is_ok(), "step {step}: ({v}, {f}) missing");
                    }
                }
            }
            for i in 0..edges.len() {
                for j in i + 1..edges.len() {
                    let ([a, b], [c, e]) = (edges[i], edges[j]);
                    if a != c && a != e && b != c && b != e && meet(&edges[i], &edges[j]) {
                        assert!(ee.binary_search(&(i as u32, j as u32)).is_ok(), "step {step}: edges {i}, {j} missing");
                    }
                }
            }
            // No pair twice.
            let (l1, l2) = (vf.len(), ee.len());
            vf.dedup();
            ee.dedup();
            assert_eq!((vf.len(), ee.len()), (l1, l2), "step {step}: duplicates");
            x = x1;
        }
        assert!(partial > 3 && full >= 2, "partial {partial}, full {full}");
    }

    #[test]
    fn boxes_grown_outward_grow_by_at_least_the_margin() {
        let values = [0.0f32, 1.0, -1.0, 0.3, -0.7, 1e-30, -1e-30, 123.456, -98765.4, 3.0e7, -1.0e-3];
        for &g in &[0.0f32, 1e-7, 1e-3, 0.25, 10.0] {
            for &a in &values {
                for &b in &values {
                    let (lo, hi) = (a.min(b), a.max(b));
                    let grown = grown_outward(&Box32 { lo: Vec3A::splat(lo), hi: Vec3A::splat(hi) }, g);
                    for k in 0..3 {
                        assert!(grown.lo[k] as f64 <= lo as f64 - g as f64, "lo {lo} by {g}: {}", grown.lo[k]);
                        assert!(grown.hi[k] as f64 >= hi as f64 + g as f64, "hi {hi} by {g}: {}", grown.hi[k]);
                    }
                }
            }
        }
    }

    #[test]
    fn swept_boxes_separate_only_beyond_the_thickness() {
        let a = SweptBox::of_vertex(Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0));
        let b = |x: f32| SweptBox::of_vertex(Vec3::new(x, 0.0, 0.0), Vec3::new(x, 1.0, 0.0));
        let t = 0.25;
        assert!(!a.separated(&b(1.25), swept_margin(t)), "exactly the thickness apart");
        assert!(!b(1.25).separated(&a, swept_margin(t)));
        assert!(a.separated(&b(1.26), swept_margin(t)));
        assert!(b(-0.26).separated(&a, swept_margin(t)));
        assert!(!a.separated(&b(1.26), swept_margin(f64::MAX)), "a thickness beyond f32 separates nothing");
        let nan = SweptBox::of_vertex(Vec3::splat(f32::NAN), Vec3::splat(f32::NAN));
        assert!(!a.separated(&nan, swept_margin(t)) && !nan.separated(&a, swept_margin(t)));
        // The union holds both.
        let u = a.union(&b(3.0));
        assert_eq!((u.lo, u.hi), (Vec3A::ZERO, Vec3A::new(3.0, 1.0, 0.0)));
    }

    #[test]
    fn closest_points_match_simple_cases() {
        let (a, b, c) = (DVec3::ZERO, DVec3::X, DVec3::Y);
        assert_eq!(closest_on_triangle(DVec3::new(0.25, 0.25, 1.0), a, b, c), [0.5, 0.25, 0.25]);
        assert_eq!(closest_on_triangle(DVec3::new(-1.0, -1.0, 0.0), a, b, c), [1.0, 0.0, 0.0]);
        let (s, t) = closest_segments(
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::X,
            DVec3::new(0.5, -1.0, 1.0),
            DVec3::new(0.5, 1.0, 1.0),
        );
        assert!((s - 0.5).abs() < 1e-12 && (t - 0.5).abs() < 1e-12);
    }
}
