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
//! Search order and answer: best first by the domain's lower time bound (ties: deeper first).
//! The first domain popped that may hold a contact and is small enough to stop splitting (a
//! "leaf") gives the answer, its lower time bound: every point (t, u, v) with a contact lies in
//! a domain still queued, so no contact is earlier. The number of domains examined is capped;
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
    /// Examine both halves, the first one first.
    Split(B, B),
}

trait Domain: Copy {
    fn t_lo(&self) -> f64;
}

/// A domain waiting in the queue: earlier start first, then deeper first (so that among domains
/// that start at the same time the search goes depth first and the queue stays short).
struct Queued<B> {
    t_lo: f64,
    depth: u16,
    domain: B,
}

impl<B> PartialEq for Queued<B> {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == std::cmp::Ordering::Equal
    }
}
impl<B> Eq for Queued<B> {}
impl<B> PartialOrd for Queued<B> {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl<B> Ord for Queued<B> {
    /// Max-heap order: the greatest is popped first.
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        other.t_lo.total_cmp(&self.t_lo).then(self.depth.cmp(&other.depth))
    }
}

/// Best-first search over domains by their lower time bound. The first domain popped that is
/// small enough and not refuted gives the answer: every contact earlier than its start would lie
/// in a domain still queued, which would start earlier and so would have been popped first.
fn earliest<B: Domain>(root: B, max_boxes: u32, mut examine: impl FnMut(&B) -> Verdict<B>) -> Search {
    let mut queue = std::collections::BinaryHeap::with_capacity(64);
    queue.push(Queued { t_lo: root.t_lo(), depth: 0, domain: root });
    let mut boxes = 0u32;
    while let Some(Queued { t_lo, depth, domain }) = queue.pop() {
        if boxes >= max_boxes {
            // `t_lo` is the smallest start still open: nothing earlier was ruled in.
            return Search { toi: Some(t_lo), boxes, exhausted: true };
        }
        boxes += 1;
        match examine(&domain) {
            Verdict::Refuted => {}
            Verdict::Leaf => return Search { toi: Some(t_lo), boxes, exhausted: false },
            Verdict::Split(first, second) => {
                for half in [first, second] {
                    queue.push(Queued { t_lo: half.t_lo(), depth: depth + 1, domain: half });
                }
            }
        }
    }
    Search { toi: None, boxes, exhausted: false }
}

/// Per-axis acceptance thresholds and the leaf size shared by both queries.
struct Bounds {
    threshold: V3,
    leaf_width: f64,
}

impl Bounds {
    /// `points` are the eight inputs (four at t = 0, four at t = 1).
    fn new(start: &[V3; 4], end: &[V3; 4], thickness: f64, relative_tolerance: f64) -> Self {
        let mut threshold = [0.0; 3];
        let mut largest_error = 0.0f64;
        let mut extent = 0.0f64;
        for axis in 0..3 {
            let (mut lo, mut hi, mut magnitude) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
            for p in start.iter().chain(end.iter()) {
                lo = lo.min(p[axis]);
                hi = hi.max(p[axis]);
                magnitude = magnitude.max(p[axis].abs());
            }
            let error = 64.0 * U * magnitude + UNDERFLOW_SLACK;
            // (thickness + error) rounded up: the relative 4 eps covers the two roundings.
            threshold[axis] = (thickness + error) * (1.0 + 4.0 * f64::EPSILON);
            largest_error = largest_error.max(error);
            extent = extent.max(hi - lo);
        }
        let leaf_width = (extent * relative_tolerance).max(largest_error);
        Self { threshold, leaf_width }
    }

    /// Box of the corner values per axis: refuted, or its largest width.
    #[inline(always)]
    fn classify(&self, corners: &[V3]) -> Option<f64> {
        let mut width = 0.0f64;
        for axis in 0..3 {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for c in corners {
                lo = lo.min(c[axis]);
                hi = hi.max(c[axis]);
            }
            if lo > self.threshold[axis] || hi < -self.threshold[axis] {
                return None;
            }
            width = width.max(hi - lo);
        }
        Some(width)
    }
}

#[inline(always)]
fn max_abs_diff(a: &V3, b: &V3) -> f64 {
    (a[0] - b[0]).abs().max((a[1] - b[1]).abs()).max((a[2] - b[2]).abs())
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
#[derive(Clone, Copy)]
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

/// Earliest time at which vertex `p` can be within `thickness` of triangle `abc` (max-norm, so
/// conservative for the Euclidean distance). `start = [p, a, b, c]` at t = 0, `end` at t = 1.
/// Coordinates must be finite and at most 2^1000 in magnitude (checked by the caller).
pub fn vertex_triangle(
    start: &[V3; 4],
    end: &[V3; 4],
    thickness: f64,
    relative_tolerance: f64,
    max_boxes: u32,
) -> Search {
    let bounds = Bounds::new(start, end, thickness, relative_tolerance);
    let delta = deltas(start, end);
    let root = VfDomain { t: [0.0, 1.0], q: [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], t_splits: 0, q_splits: 0 };
    earliest(root, max_boxes, |d| {
        // corners[j * 3 + i]: time t[j], triangle corner q[i].
        let mut corners = [[0.0; 3]; 6];
        for j in 0..2 {
            let [p, a, b, c] = lerp_points(start, &delta, d.t[j]);
            let pa = sub(&p, &a);
            let ba = sub(&b, &a);
            let ca = sub(&c, &a);
            for i in 0..3 {
                let [u, v] = d.q[i];
                for axis in 0..3 {
                    corners[j * 3 + i][axis] = (pa[axis] - u * ba[axis]) - v * ca[axis];
                }
            }
        }
        let Some(width) = bounds.classify(&corners) else { return Verdict::Refuted };
        if width <= bounds.leaf_width {
            return Verdict::Leaf;
        }
        let along_t = (0..3).map(|i| max_abs_diff(&corners[3 + i], &corners[i])).fold(0.0, f64::max);
        // Side k joins corners k and k+1 (mod 3).
        let mut side = 0;
        let mut along_side = -1.0;
        for k in 0..3 {
            let l = (k + 1) % 3;
            let variation = max_abs_diff(&corners[k], &corners[l]).max(max_abs_diff(&corners[3 + k], &corners[3 + l]));
            if variation > along_side {
                along_side = variation;
                side = k;
            }
        }
        let can_split_t = d.t_splits < MAX_SPLITS;
        let can_split_q = d.q_splits < MAX_SPLITS;
        if can_split_t && (along_t >= along_side || !can_split_q) {
            let mid = 0.5 * (d.t[0] + d.t[1]);
            let early = VfDomain { t: [d.t[0], mid], t_splits: d.t_splits + 1, ..*d };
            let late = VfDomain { t: [mid, d.t[1]], t_splits: d.t_splits + 1, ..*d };
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
#[derive(Clone, Copy)]
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

/// Earliest time at which edge `ab` can be within `thickness` of edge `cd` (max-norm, so
/// conservative for the Euclidean distance). `start = [a, b, c, d]` at t = 0, `end` at t = 1.
/// Coordinates must be finite and at most 2^1000 in magnitude (checked by the caller).
pub fn edge_edge(start: &[V3; 4], end: &[V3; 4], thickness: f64, relative_tolerance: f64, max_boxes: u32) -> Search {
    let bounds = Bounds::new(start, end, thickness, relative_tolerance);
    let delta = deltas(start, end);
    let root = EeDomain { range: [[0.0, 1.0]; 3], splits: [0; 3] };
    earliest(root, max_boxes, |d| {
        // corners[4 j + 2 i + k]: time range[0][j], u = range[1][i], v = range[2][k].
        let mut corners = [[0.0; 3]; 8];
        for j in 0..2 {
            let [a, b, c, e] = lerp_points(start, &delta, d.range[0][j]);
            let ba = sub(&b, &a);
            let dc = sub(&e, &c);
            for i in 0..2 {
                let u = d.range[1][i];
                for k in 0..2 {
                    let v = d.range[2][k];
                    for axis in 0..3 {
                        corners[4 * j + 2 * i + k][axis] = (a[axis] + u * ba[axis]) - (c[axis] + v * dc[axis]);
                    }
                }
            }
        }
        let Some(width) = bounds.classify(&corners) else { return Verdict::Refuted };
        if width <= bounds.leaf_width {
            return Verdict::Leaf;
        }
        // Variation of F along each parameter: the largest change over the four parallel edges.
        let mut variation = [0.0f64; 3];
        for n in 0..8 {
            for (dim, stride) in [4usize, 2, 1].into_iter().enumerate() {
                if n & stride == 0 {
                    variation[dim] = variation[dim].max(max_abs_diff(&corners[n], &corners[n + stride]));
                }
            }
        }
        let mut dim = usize::MAX;
        let mut largest = -1.0;
        for k in 0..3 {
            if d.splits[k] < MAX_SPLITS && variation[k] > largest {
                largest = variation[k];
                dim = k;
            }
        }
        if dim == usize::MAX {
            return Verdict::Leaf;
        }
        let [lo, hi] = d.range[dim];
        let mid = 0.5 * (lo + hi);
        let mut first = *d;
        let mut second = *d;
        first.range[dim] = [lo, mid];
        second.range[dim] = [mid, hi];
        first.splits[dim] += 1;
        second.splits[dim] += 1;
        Verdict::Split(first, second)
    })
}
