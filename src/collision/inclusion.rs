//! The exact stage of the CCD queries: an inclusion-based search for the earliest time at which
//! the gap between two primitives can be within the thickness (SPEC 1.6; the idea of
//! Tight-Inclusion, Wang et al. 2021, written from the paper's description).
//!
//! The gap `F(t, u, v)` between the primitives (vertex minus a point of the triangle, or a point
//! of one edge minus a point of the other) is affine in t for fixed (u, v) and affine in (u, v)
//! for fixed t. On a product domain `T x Q` (an interval times a triangle or a rectangle) such a
//! function takes its values in the convex hull of its values at the corners, so the box of the
//! corner values, widened by their rounding-error bound, contains every value of F on the domain.
//! A domain whose box misses `[-thickness, thickness]^3` on some axis cannot hold a contact (the
//! max-norm is at most the Euclidean norm, so this is conservative). The others are bisected.
//!
//! Search order and answer: best first by the domain's lower time bound rounded down to 2^-20
//! (ties: deeper first). The first domain popped whose values all lie within a small tolerance
//! of the thickness (a "leaf": a near contact certainly exists there) ends the search; the
//! answer is the smallest lower time bound among it and the domains still queued: every point
//! (t, u, v) with a contact lies in a domain still queued, so no contact is earlier. The number of domains examined is capped;
//! when the cap is reached the answer is a hit at the smallest lower time bound still open,
//! which is conservative too.
//!
//! Rounding-error bound (per axis, M = the largest |coordinate| on that axis over the eight input
//! points, U = 2^-53): a position at time t, `x0 + t (x1 - x0)`, is within 5 U M of the exact one;
//! `(p - a) - u (b - a) - v (c - a)` is then within 50 U M, and `(a + u (b - a)) - (c + v (d - c))`
//! within 42 U M (each step adds U times a bound of its exact magnitude, with t, u, v exact
//! doubles in [0, 1]). The code uses 64 U M. Intervals of t, u, v are split at their rounded
//! midpoint, which lies between the ends, so the halves cover the interval whatever the rounding.
//! A triangle of (u, v) is split at the midpoint of a side, which must be exact for the halves to
//! cover it: each triangle is split at most [`MAX_SPLITS`] times along a path, so its corners
//! stay multiples of 2^-MAX_SPLITS in [0, 1], exact in f64. Overflow cannot happen
//! because the caller refuses coordinates above 2^1000 in magnitude.

use super::filters::{U, UNDERFLOW_SLACK, V3, sub};

/// How often one parameter (t, or the triangle, or u, or v) may be halved along one path of the
/// search. Keeps every corner parameter an exact multiple of 2^-MAX_SPLITS.
pub(crate) const MAX_SPLITS: u8 = 50;

/// What the search found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Search {
    /// A conservative (never later than the truth) first contact time, or None for no contact.
    pub toi: Option<f64>,
    /// Domains examined.
    pub boxes: u32,
    /// True when the budget ran out and the answer is the conservative fallback.
    pub exhausted: bool,
}

enum Verdict<B> {
    /// F certainly stays out of the thickness on this domain.
    Refuted,
    /// Small enough: report a possible contact at its lower time bound.
    Leaf,
    /// Examine both halves.
    Split(B, B),
    /// Only this part can hold a contact (the rest was refuted).
    Only(B),
}

trait Domain: Copy {
    fn t_lo(&self) -> f64;
}

/// The search queues of the two kinds of query, kept by their owner between queries (a shell's
/// collision stage makes many per step: a fresh queue allocated its heap, slab and free list on
/// every query that split a domain). They grow to what the largest query so far needed: at most
/// one queued domain per examined one (a split queues one half and goes on with the other), so
/// at most `max_boxes` entries per kind, about 150 KB for both kinds at the default budget of
/// 1,024. (Shrinking them after a large query made the next large one allocate again: a shell's
/// steps with contacts kept allocating; found by review.)
#[derive(Clone, Debug, Default)]
pub struct SearchQueues {
    vertex_triangle: Queue<VfDomain>,
    edge_edge: Queue<EeDomain>,
}

impl SearchQueues {
    /// Heap bytes held.
    pub fn memory_bytes(&self) -> usize {
        self.vertex_triangle.memory_bytes() + self.edge_edge.memory_bytes()
    }
}

/// Number of time buckets of the queue: 2^20 (a bucket is about 1e-6 of the step).
const TIME_BUCKETS: f64 = (1u64 << 20) as f64;
const SLOT_BITS: u32 = 27;
const DEPTH_BITS: u32 = 16;
/// Most domains examined by one query, whatever the settings (the queue's slot index has
/// SLOT_BITS bits and holds at most two domains per examined one).
pub(crate) const MAX_BOXES_LIMIT: u32 = 1 << (SLOT_BITS - 2);

/// Queue key of a domain, a max-heap order: earlier time bucket first, then deeper first.
/// Within one bucket the search thus goes depth first, which finds a leaf after a number of
/// steps proportional to the depth instead of refining every domain that starts within 1e-6 of
/// the contact (the cause of slow queries in a purely time-ordered search on degenerate contacts
/// such as overlapping collinear edges).
#[inline(always)]
fn key(bucket: u64, depth: u16, slot: usize) -> u64 {
    (((1u64 << 21) - 1 - bucket) << (DEPTH_BITS + SLOT_BITS)) | (u64::from(depth) << SLOT_BITS) | slot as u64
}

#[inline(always)]
fn bucket_of(t_lo: f64) -> u64 {
    // t_lo is in [0, 1]: at most 2^20.
    (t_lo * TIME_BUCKETS) as u64
}

/// The queue: keys in a binary heap, domains in a slab reused through a free list (moving 8-byte
/// keys instead of whole domains).
#[derive(Clone, Debug)]
struct Queue<B> {
    heap: std::collections::BinaryHeap<u64>,
    slab: Vec<B>,
    free: Vec<u32>,
}

impl<B> Default for Queue<B> {
    fn default() -> Self {
        Self { heap: std::collections::BinaryHeap::new(), slab: Vec::new(), free: Vec::new() }
    }
}

impl<B> Queue<B> {
    fn clear(&mut self) {
        self.heap.clear();
        self.slab.clear();
        self.free.clear();
    }

    fn memory_bytes(&self) -> usize {
        self.heap.capacity() * 8 + self.slab.capacity() * std::mem::size_of::<B>() + self.free.capacity() * 4
    }
}

impl<B: Domain> Queue<B> {
    fn push(&mut self, domain: B, depth: u16) {
        let slot = match self.free.pop() {
            Some(slot) => {
                self.slab[slot as usize] = domain;
                slot as usize
            }
            None => {
                self.slab.push(domain);
                self.slab.len() - 1
            }
        };
        self.heap.push(key(bucket_of(domain.t_lo()), depth, slot));
    }

    fn pop(&mut self) -> Option<(B, u16)> {
        let key = self.heap.pop()?;
        let slot = (key & ((1 << SLOT_BITS) - 1)) as usize;
        self.free.push(slot as u32);
        Some((self.slab[slot], ((key >> SLOT_BITS) & ((1 << DEPTH_BITS) - 1)) as u16))
    }

    /// Smallest start time among `t` and the queued domains.
    fn open_min(&self, t: f64) -> f64 {
        self.heap.iter().map(|&key| self.slab[(key & ((1 << SLOT_BITS) - 1)) as usize].t_lo()).fold(t, f64::min)
    }
}

/// Best-first search over domains by their time bucket. When a leaf is found (or the budget runs
/// out), the answer is the smallest lower time bound among it and every domain still queued:
/// every contact lies in a queued domain or in a refuted one (impossible), so none is earlier.
/// Domains are taken in bucket order, so the answer is at most one bucket (2^-20) earlier than
/// the leaf's start. A child in the bucket of its parent would be taken next anyway (it is the
/// deepest), so it is examined at once without a trip through the queue.
fn earliest<B: Domain>(queue: &mut Queue<B>, root: B, max_boxes: u32, examine: impl FnMut(&B) -> Verdict<B>) -> Search {
    queue.clear();
    search(queue, root, max_boxes, examine)
}

fn search<B: Domain>(
    queue: &mut Queue<B>,
    root: B,
    max_boxes: u32,
    mut examine: impl FnMut(&B) -> Verdict<B>,
) -> Search {
    let max_boxes = max_boxes.min(MAX_BOXES_LIMIT);
    let mut next = Some((root, 0u16));
    let mut boxes = 0u32;
    while let Some((domain, depth)) = next.take().or_else(|| queue.pop()) {
        let t_lo = domain.t_lo();
        if boxes >= max_boxes {
            return Search { toi: Some(queue.open_min(t_lo)), boxes, exhausted: true };
        }
        boxes += 1;
        let bucket = bucket_of(t_lo);
        let mut follow = |child: B, queue: &mut Queue<B>| {
            if bucket_of(child.t_lo()) == bucket {
                next = Some((child, depth + 1));
            } else {
                queue.push(child, depth + 1);
            }
        };
        match examine(&domain) {
            Verdict::Refuted => {}
            Verdict::Leaf => return Search { toi: Some(queue.open_min(t_lo)), boxes, exhausted: false },
            Verdict::Split(first, second) => {
                queue.push(second, depth + 1);
                follow(first, queue);
            }
            Verdict::Only(part) => follow(part, queue),
        }
    }
    Search { toi: None, boxes, exhausted: false }
}

/// Per-axis acceptance thresholds and the leaf size shared by both queries.
struct Bounds {
    /// |F| above this on an axis (thickness plus the rounding-error bound) rules a contact out.
    threshold: V3,
    /// A domain whose values all lie within this of zero on every axis is a leaf: a contact
    /// within the tolerance certainly exists there (or the thickness is nearly reached).
    near: V3,
}

/// What the box of the corner values says about a domain.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Class {
    /// Certainly no contact.
    Refuted,
    /// Every value is within the tolerance of the thickness: report a contact.
    Near,
    /// Undecided: split. True for the axes whose values are not all near zero yet: only their
    /// variation matters when choosing the split.
    Open([bool; 3]),
}

impl Bounds {
    /// `start` and `end` are the four points at t = 0 and t = 1.
    fn new(start: &[V3; 4], end: &[V3; 4], thickness: f64, relative_tolerance: f64) -> Self {
        let mut threshold = [0.0; 3];
        let mut error = [0.0; 3];
        let mut extent = 0.0f64;
        let mut motion = 0.0f64;
        for axis in 0..3 {
            let (mut lo, mut hi, mut magnitude) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
            for p in start.iter().chain(end.iter()) {
                lo = lo.min(p[axis]);
                hi = hi.max(p[axis]);
                magnitude = magnitude.max(p[axis].abs());
            }
            error[axis] = 64.0 * U * magnitude + UNDERFLOW_SLACK;
            // (thickness + error) rounded up: the relative 4 eps covers the two roundings.
            threshold[axis] = (thickness + error[axis]) * (1.0 + 4.0 * f64::EPSILON);
            extent = extent.max(hi - lo);
            for (p, q) in start.iter().zip(end.iter()) {
                motion = motion.max((q[axis] - p[axis]).abs());
            }
        }
        // Relative to the motion, so that the answer's time is accurate whatever the scale of the
        // motion, but not below a far smaller fraction of the extent (static near contacts), nor
        // below 1/64 of the thickness: with a thickness the contact set is a volume, and
        // resolving its boundary much finer than the thickness itself only costs time.
        let tolerance =
            (motion * relative_tolerance).max(extent * relative_tolerance * relative_tolerance).max(thickness / 64.0);
        // The tolerance is at least the error bound: below it nothing can be resolved anyway.
        let near = std::array::from_fn(|axis| threshold[axis] + tolerance.max(error[axis]));
        Self { threshold, near }
    }

    #[inline(always)]
    fn classify(&self, corners: &[V3]) -> Class {
        let mut open = [false; 3];
        for axis in 0..3 {
            // Plain comparisons (no NaN can occur: the caller bounds the coordinates).
            let (mut lo, mut hi) = (corners[0][axis], corners[0][axis]);
            for c in &corners[1..] {
                if c[axis] < lo {
                    lo = c[axis];
                }
                if c[axis] > hi {
                    hi = c[axis];
                }
            }
            if lo > self.threshold[axis] || hi < -self.threshold[axis] {
                return Class::Refuted;
            }
            open[axis] = lo < -self.near[axis] || hi > self.near[axis];
        }
        if open.iter().any(|&o| o) { Class::Open(open) } else { Class::Near }
    }
}

/// Largest change between two corners over the open axes.
#[inline(always)]
fn max_abs_diff(a: &V3, b: &V3, open: &[bool; 3]) -> f64 {
    let mut change = 0.0f64;
    for axis in 0..3 {
        let d = (a[axis] - b[axis]).abs();
        if open[axis] && d > change {
            change = d;
        }
    }
    change
}

#[inline(always)]
fn lerp_points(start: &[V3; 4], delta: &[V3; 4], t: f64) -> [V3; 4] {
    let mut out = [[0.0; 3]; 4];
    for k in 0..4 {
        for axis in 0..3 {
            out[k][axis] = start[k][axis] + t * delta[k][axis];
        }
    }
    out
}

fn deltas(start: &[V3; 4], end: &[V3; 4]) -> [V3; 4] {
    [sub(&end[0], &start[0]), sub(&end[1], &start[1]), sub(&end[2], &start[2]), sub(&end[3], &start[3])]
}

/// A time interval times a triangle of barycentric parameters (u, v): the point of the triangle
/// is `a + u (b - a) + v (c - a)`.
#[derive(Clone, Copy, Debug)]
struct VfDomain {
    t: [f64; 2],
    q: [[f64; 2]; 3],
    t_splits: u8,
    q_splits: u8,
}

impl Domain for VfDomain {
    fn t_lo(&self) -> f64 {
        self.t[0]
    }
}

/// Classifies the two halves in time of a domain whose corner values at its start, middle and
/// end times are `early`, `middle`, `late` (each a slice of N corners). Dropping a refuted half
/// before any split in space keeps the domains that later split in space close to the first
/// contact time, so a contact along a whole edge or face does not multiply them.
#[inline(always)]
fn halves<const N: usize>(bounds: &Bounds, early: &[V3; N], middle: &[V3; N], late: &[V3; N]) -> (Class, Class) {
    let mut first = [[0.0; 3]; 8];
    let mut second = [[0.0; 3]; 8];
    first[..N].copy_from_slice(early);
    first[N..2 * N].copy_from_slice(middle);
    second[..N].copy_from_slice(middle);
    second[N..2 * N].copy_from_slice(late);
    (bounds.classify(&first[..2 * N]), bounds.classify(&second[..2 * N]))
}

/// Outcome of the time-halving test; `None` when both halves stay open.
#[inline(always)]
fn time_verdict<B>(halves: (Class, Class), early: B, late: B) -> Option<Verdict<B>> {
    match halves {
        (Class::Refuted, Class::Refuted) => Some(Verdict::Refuted),
        (Class::Near, _) => Some(Verdict::Leaf),
        (Class::Refuted, _) => Some(Verdict::Only(late)),
        (_, Class::Refuted) => Some(Verdict::Only(early)),
        _ => None,
    }
}

/// Earliest time at which vertex `p` can be within `thickness` of triangle `abc` (max-norm, so
/// conservative for the Euclidean distance). `start = [p, a, b, c]` at t = 0, `end` at t = 1.
/// Coordinates must be finite and at most 2^1000 in magnitude (checked by the caller).
pub fn vertex_triangle(
    start: &[V3; 4],
    end: &[V3; 4],
    thickness: f64,
    relative_tolerance: f64,
    max_boxes: u32,
    queues: &mut SearchQueues,
) -> Search {
    let bounds = Bounds::new(start, end, thickness, relative_tolerance);
    let delta = deltas(start, end);
    // Gap values at time t at the three corners of the parameter triangle q.
    let slice = |t: f64, q: &[[f64; 2]; 3]| -> [V3; 3] {
        let [p, a, b, c] = lerp_points(start, &delta, t);
        let pa = sub(&p, &a);
        let ba = sub(&b, &a);
        let ca = sub(&c, &a);
        std::array::from_fn(|i| {
            let [u, v] = q[i];
            std::array::from_fn(|axis| (pa[axis] - u * ba[axis]) - v * ca[axis])
        })
    };
    let root = VfDomain { t: [0.0, 1.0], q: [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], t_splits: 0, q_splits: 0 };
    earliest(&mut queues.vertex_triangle, root, max_boxes, |d| {
        let s0 = slice(d.t[0], &d.q);
        let s1 = slice(d.t[1], &d.q);
        let corners = [s0[0], s0[1], s0[2], s1[0], s1[1], s1[2]];
        let open = match bounds.classify(&corners) {
            Class::Refuted => return Verdict::Refuted,
            Class::Near => return Verdict::Leaf,
            Class::Open(open) => open,
        };
        let can_split_t = d.t_splits < MAX_SPLITS;
        let can_split_q = d.q_splits < MAX_SPLITS;
        let mid = 0.5 * (d.t[0] + d.t[1]);
        let early = VfDomain { t: [d.t[0], mid], t_splits: d.t_splits + 1, ..*d };
        let late = VfDomain { t: [mid, d.t[1]], t_splits: d.t_splits + 1, ..*d };
        if can_split_t {
            let sm = slice(mid, &d.q);
            if let Some(verdict) = time_verdict(halves(&bounds, &s0, &sm, &s1), early, late) {
                return verdict;
            }
        }
        let along_t = (0..3).map(|i| max_abs_diff(&s1[i], &s0[i], &open)).fold(0.0, f64::max);
        // Side k joins corners k and k+1 (mod 3).
        let mut side = 0;
        let mut along_side = -1.0;
        for k in 0..3 {
            let l = (k + 1) % 3;
            let variation = max_abs_diff(&s0[k], &s0[l], &open).max(max_abs_diff(&s1[k], &s1[l], &open));
            if variation > along_side {
                along_side = variation;
                side = k;
            }
        }
        if can_split_t && (along_t >= along_side || !can_split_q) {
            Verdict::Split(early, late)
        } else if can_split_q {
            let (k, l, o) = (side, (side + 1) % 3, (side + 2) % 3);
            let m = [0.5 * (d.q[k][0] + d.q[l][0]), 0.5 * (d.q[k][1] + d.q[l][1])];
            let first = VfDomain { q: [d.q[k], m, d.q[o]], q_splits: d.q_splits + 1, ..*d };
            let second = VfDomain { q: [m, d.q[l], d.q[o]], q_splits: d.q_splits + 1, ..*d };
            Verdict::Split(first, second)
        } else {
            Verdict::Leaf
        }
    })
}

/// A box of time and the two edge parameters: points `a + u (b - a)` and `c + v (d - c)`.
#[derive(Clone, Copy, Debug)]
struct EeDomain {
    /// t, u, v intervals.
    range: [[f64; 2]; 3],
    splits: [u8; 3],
}

impl Domain for EeDomain {
    fn t_lo(&self) -> f64 {
        self.range[0][0]
    }
}

impl EeDomain {
    fn halved(&self, dim: usize) -> (Self, Self) {
        let [lo, hi] = self.range[dim];
        let mid = 0.5 * (lo + hi);
        let mut first = *self;
        let mut second = *self;
        first.range[dim] = [lo, mid];
        second.range[dim] = [mid, hi];
        first.splits[dim] += 1;
        second.splits[dim] += 1;
        (first, second)
    }
}

/// Earliest time at which edge `ab` can be within `thickness` of edge `cd` (max-norm, so
/// conservative for the Euclidean distance). `start = [a, b, c, d]` at t = 0, `end` at t = 1.
/// Coordinates must be finite and at most 2^1000 in magnitude (checked by the caller).
pub fn edge_edge(
    start: &[V3; 4],
    end: &[V3; 4],
    thickness: f64,
    relative_tolerance: f64,
    max_boxes: u32,
    queues: &mut SearchQueues,
) -> Search {
    let bounds = Bounds::new(start, end, thickness, relative_tolerance);
    let delta = deltas(start, end);
    // Gap values at time t at the four corners (u, v) of the box, index 2 i + k.
    let slice = |t: f64, u: [f64; 2], v: [f64; 2]| -> [V3; 4] {
        let [a, b, c, e] = lerp_points(start, &delta, t);
        let ba = sub(&b, &a);
        let dc = sub(&e, &c);
        std::array::from_fn(|n| {
            let (u, v) = (u[n >> 1], v[n & 1]);
            std::array::from_fn(|axis| (a[axis] + u * ba[axis]) - (c[axis] + v * dc[axis]))
        })
    };
    let root = EeDomain { range: [[0.0, 1.0]; 3], splits: [0; 3] };
    earliest(&mut queues.edge_edge, root, max_boxes, |d| {
        let [t, u, v] = d.range;
        let s0 = slice(t[0], u, v);
        let s1 = slice(t[1], u, v);
        let corners = [s0[0], s0[1], s0[2], s0[3], s1[0], s1[1], s1[2], s1[3]];
        let open = match bounds.classify(&corners) {
            Class::Refuted => return Verdict::Refuted,
            Class::Near => return Verdict::Leaf,
            Class::Open(open) => open,
        };
        if d.splits[0] < MAX_SPLITS {
            let (early, late) = d.halved(0);
            let sm = slice(early.range[0][1], u, v);
            if let Some(verdict) = time_verdict(halves(&bounds, &s0, &sm, &s1), early, late) {
                return verdict;
            }
        }
        // Variation of F along each parameter: the largest change over the four parallel edges.
        let mut variation = [0.0f64; 3];
        for n in 0..4 {
            variation[0] = variation[0].max(max_abs_diff(&s0[n], &s1[n], &open));
        }
        for s in [&s0, &s1] {
            variation[1] = variation[1].max(max_abs_diff(&s[0], &s[2], &open)).max(max_abs_diff(&s[1], &s[3], &open));
            variation[2] = variation[2].max(max_abs_diff(&s[0], &s[1], &open)).max(max_abs_diff(&s[2], &s[3], &open));
        }
        let mut dim = usize::MAX;
        let mut largest = -1.0;
        for (k, &change) in variation.iter().enumerate() {
            if d.splits[k] < MAX_SPLITS && change > largest {
                largest = change;
                dim = k;
            }
        }
        if dim == usize::MAX {
            return Verdict::Leaf;
        }
        let (first, second) = d.halved(dim);
        Verdict::Split(first, second)
    })
}
