//! A separating-axis filter on the swept hulls of two primitives (SPEC 1.6 culling), run
//! before the plane filter in the shell's self-contact.
//!
//! Moving linearly, a primitive stays inside the convex hull of its points at both ends of the
//! step, so if the two hulls are more than `thickness` apart along any direction `w`, the
//! primitives never come within `thickness`. Any `w` is valid, so the axes are cheap guesses:
//! the gap between the closest points at each end of the step (catches neighbours beside each
//! other on a smooth surface, which the plane filter cannot refute) and, for a vertex-triangle
//! pair, the triangle's normals.
//!
//! [`separated_piecewise`] applies the same argument to each of a few sub-intervals of the step
//! (the hull of the points at the two ends of the sub-interval), with the gap directions sampled
//! at those times: it refutes pairs that come close at some time but never within the thickness,
//! which neither the hull of the whole step nor the plane filter can.
//!
//! [`diagonals_separated`] is the cheap first test in f32: the six diagonal directions (with
//! the boxes' axes, an 18-DOP), exact enough by its margin.
//!
//! Exactness: a projection `w · x` in f64 is within `3U Σ|w_i||x_i| <= 3U |w|_1 M` of the exact
//! one (M = the largest |coordinate|); the difference of two adds one rounding. The test requires
//! a separation above `thickness |w|_2 + 16 U |w|_1 M` (|w|_2 computed from w scaled to a largest
//! component of 1, rounded up), far more than those.

use glam::{DVec3, Vec3A};

use super::filters::{U, UNDERFLOW_SLACK, V3};

fn dv(p: &V3) -> DVec3 {
    DVec3::new(p[0], p[1], p[2])
}

/// True when the hulls of `first` and `second` are farther apart than `thickness` along `w`.
fn separated_along(w: DVec3, first: &[V3], second: &[V3], thickness: f64, largest: f64) -> bool {
    // Any direction is valid, so scale w to a largest component of 1: its Euclidean norm is then
    // in [1, sqrt 3] and computed without underflow or overflow, within 3U (rounded up below).
    let w = w / w.abs().max_element();
    let w1 = w.x.abs() + w.y.abs() + w.z.abs();
    if !(w1 > 0.0) || !w1.is_finite() {
        return false;
    }
    let w2 = w.length() * (1.0 + 8.0 * U);
    let (mut lo_a, mut hi_a) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in first {
        let s = w.dot(dv(p));
        lo_a = lo_a.min(s);
        hi_a = hi_a.max(s);
    }
    let (mut lo_b, mut hi_b) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in second {
        let s = w.dot(dv(p));
        lo_b = lo_b.min(s);
        hi_b = hi_b.max(s);
    }
    let margin = (thickness * w2 + 16.0 * U * w1 * largest) * (1.0 + 8.0 * U) + UNDERFLOW_SLACK;
    lo_b - hi_a > margin || lo_a - hi_b > margin
}

fn largest(points: &[V3]) -> f64 {
    points.iter().flat_map(|p| p.iter()).fold(0.0f64, |m, x| m.max(x.abs()))
}

/// Vertex `p` against triangle `abc` (`start = [p, a, b, c]` at t = 0, `end` at t = 1): true
/// when the swept hulls are certainly farther apart than `thickness`.
pub fn vertex_triangle_hulls_separated(start: &[V3; 4], end: &[V3; 4], thickness: f64) -> bool {
    let first = [start[0], end[0]];
    let second = [start[1], start[2], start[3], end[1], end[2], end[3]];
    let m = largest(start).max(largest(end));
    if !(m < 1e300) {
        return false;
    }
    for ends in [start, end] {
        let [p, a, b, c] = ends.map(|x| dv(&x));
        let al = super::self_contact::closest_on_triangle(p, a, b, c);
        let gap = p - (a * al[0] + b * al[1] + c * al[2]);
        if separated_along(gap, &first, &second, thickness, m) {
            return true;
        }
        if separated_along((b - a).cross(c - a), &first, &second, thickness, m) {
            return true;
        }
    }
    false
}

/// Edge `ab` against edge `cd` (`start = [a, b, c, d]`): true when the swept hulls are certainly
/// farther apart than `thickness`.
pub fn edge_edge_hulls_separated(start: &[V3; 4], end: &[V3; 4], thickness: f64) -> bool {
    let first = [start[0], start[1], end[0], end[1]];
    let second = [start[2], start[3], end[2], end[3]];
    let m = largest(start).max(largest(end));
    if !(m < 1e300) {
        return false;
    }
    for ends in [start, end] {
        let [a, b, c, d] = ends.map(|x| dv(&x));
        let (s, t) = super::self_contact::closest_segments(a, b, c, d);
        let gap = (a + (b - a) * s) - (c + (d - c) * t);
        if separated_along(gap, &first, &second, thickness, m) {
            return true;
        }
    }
    false
}

/// The slabs points span along the six diagonal directions: the sums (x+y, y+z, z+x) and the
/// differences (x-y, y-z, z-x) of their coordinates, each as (lowest, highest).
#[inline(always)]
fn diagonal_slabs(points: &[Vec3A]) -> [Vec3A; 4] {
    let mut slabs = [Vec3A::INFINITY, Vec3A::NEG_INFINITY, Vec3A::INFINITY, Vec3A::NEG_INFINITY];
    for &p in points {
        let turned = Vec3A::new(p.y, p.z, p.x);
        let (sum, diff) = (p + turned, p - turned);
        slabs = [slabs[0].min(sum), slabs[1].max(sum), slabs[2].min(diff), slabs[3].max(diff)];
    }
    slabs
}

/// Whether the points `first` and `second` (the positions a pair's primitives take at both ends
/// of the step) are farther apart than `margin` (from [`diagonal_margin`]) along one of the six
/// diagonal directions: then so are their swept hulls, by more than the thickness. With the
/// boxes' axes, an 18-DOP test: on a curved sheet, pairs two rings apart (most of the cached
/// pairs) often overlap in their boxes but not along a diagonal. On the kitten at default
/// settings it refutes 3 in 4 of the pairs that pass the boxes, for much less than the swept-hull
/// filter's closest points (and some that filter cannot).
#[inline(always)]
pub(crate) fn diagonals_separated(first: &[Vec3A], second: &[Vec3A], margin: Vec3A) -> bool {
    let (a, b) = (diagonal_slabs(first), diagonal_slabs(second));
    ((b[0] - a[1]).cmpgt(margin)
        | (a[0] - b[1]).cmpgt(margin)
        | (b[2] - a[3]).cmpgt(margin)
        | (a[2] - b[3]).cmpgt(margin))
    .any()
}

/// The f32 margin for [`diagonals_separated`] with positions up to `largest` in absolute value:
/// along a diagonal (length sqrt 2) the thickness is `sqrt 2 t`, taken 2^-20 larger; each
/// computed slab bound is within 2^-23 `largest` of the exact one (one rounding of a value up to
/// 2 `largest`) and a computed gap within a relative 2^-24, so a computed gap above this margin
/// means an exact one above `sqrt 2 t`. Infinite (nothing separated) when it does not fit in f32.
pub(crate) fn diagonal_margin(thickness: f64, largest: f64) -> Vec3A {
    let m = (thickness * std::f64::consts::SQRT_2 * (1.0 + 1.0 / (1u64 << 20) as f64)
        + 4.0 * largest / (1u64 << 23) as f64) as f32;
    Vec3A::splat(if m.is_finite() { m } else { f32::INFINITY })
}

/// Halvings of a sample interval [`separated_piecewise`] tries before giving up. On the kitten's
/// contracting shell, 2 left 345 edge pairs in 70 steps to the inclusion search, 5 left 28 (all
/// within 1% of the thickness); the time per step was the same for 2 and 4.
const HALVINGS: u32 = 4;

/// Points of a pair at time `t` of the step (linear motion). Exact at t = 0 and t = 1; in
/// between, each coordinate is within `5 U M` of the exact one (three roundings, M = the largest
/// |coordinate| at either end).
fn points_at(start: &[V3; 4], end: &[V3; 4], t: f64) -> [V3; 4] {
    if t == 0.0 {
        return *start;
    }
    if t == 1.0 {
        return *end;
    }
    std::array::from_fn(|k| std::array::from_fn(|i| start[k][i] + (end[k][i] - start[k][i]) * t))
}

/// True when, on every interval `[k/n, (k+1)/n]` (n = `gaps.len() - 1`), the hulls of the two
/// primitives' points at the interval's ends are farther apart than `thickness` along the gap
/// direction sampled at one of its ends (`gaps[k]` at t = k/n: the first primitive's closest
/// point minus the second's), or, failing that, on each half ([`HALVINGS`] times at most) along the gap
/// `gap_at` gives at the midpoint. Then the primitives never come within `thickness` over the
/// step. The first `first_points` entries of `start`/`end` are the first primitive (1 for a
/// vertex-triangle pair, 2 for an edge pair).
///
/// Exactness: as [`separated_along`], with the interpolated points' error (`5 U M` per
/// coordinate, at most `10 U |w|_1 M` on a separation) absorbed by testing against
/// `thickness + 16 U M`.
pub(crate) fn separated_piecewise(
    start: &[V3; 4],
    end: &[V3; 4],
    first_points: usize,
    gaps: &[DVec3],
    thickness: f64,
    gap_at: impl Fn(&[V3; 4]) -> DVec3,
) -> bool {
    let m = largest(start).max(largest(end));
    if !(m < 1e300) || gaps.len() < 2 {
        return false;
    }
    let limit = thickness + 16.0 * U * m;
    let intervals = (gaps.len() - 1) as f64;
    let separated = |a: &[V3; 4], b: &[V3; 4], w: DVec3| {
        let (mut first, mut second) = ([[0.0; 3]; 4], [[0.0; 3]; 6]);
        let (mut nf, mut ns) = (0, 0);
        for ends in [a, b] {
            for (k, p) in ends.iter().enumerate() {
                if k < first_points {
                    first[nf] = *p;
                    nf += 1;
                } else {
                    second[ns] = *p;
                    ns += 1;
                }
            }
        }
        separated_along(w, &first[..nf], &second[..ns], limit, m)
    };
    // Interval [ta, tb] with points pa, pb and gaps ga, gb at its ends; `depth` halvings left.
    fn interval(
        ta: f64,
        tb: f64,
        (pa, pb): (&[V3; 4], &[V3; 4]),
        (ga, gb): (DVec3, DVec3),
        depth: u32,
        ctx: &(&[V3; 4], &[V3; 4], &dyn Fn(&[V3; 4], &[V3; 4], DVec3) -> bool, &dyn Fn(&[V3; 4]) -> DVec3),
    ) -> bool {
        let (start, end, separated, gap_at) = ctx;
        if separated(pa, pb, ga) || separated(pa, pb, gb) {
            return true;
        }
        if depth == 0 {
            return false;
        }
        let tm = 0.5 * (ta + tb);
        let pm = points_at(start, end, tm);
        let gm = gap_at(&pm);
        interval(ta, tm, (pa, &pm), (ga, gm), depth - 1, ctx) && interval(tm, tb, (&pm, pb), (gm, gb), depth - 1, ctx)
    }
    let ctx: (&[V3; 4], &[V3; 4], &dyn Fn(&[V3; 4], &[V3; 4], DVec3) -> bool, &dyn Fn(&[V3; 4]) -> DVec3) =
        (start, end, &separated, &gap_at);
    let mut pa = *start;
    for k in 0..gaps.len() - 1 {
        let tb = (k + 1) as f64 / intervals;
        let pb = points_at(start, end, tb);
        if !interval(k as f64 / intervals, tb, (&pa, &pb), (gaps[k], gaps[k + 1]), HALVINGS, &ctx) {
            return false;
        }
        pa = pb;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collision::filters::sub;
    use crate::collision::{edge_edge, vertex_triangle};

    struct Rng(u64);
    impl Rng {
        fn unit(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
        }
        fn vec(&mut self, s: f64) -> V3 {
            [s * (self.unit() - 0.5), s * (self.unit() - 0.5), s * (self.unit() - 0.5)]
        }
    }

    #[test]
    fn never_refutes_a_certain_contact_and_refutes_neighbours() {
        let mut rng = Rng(7);
        let (mut refuted, mut hits) = (0, 0);
        for case in 0..20000 {
            let scale = [1.0, 1e-3, 1e3][case % 3];
            let motion = [0.3, 0.01, 1.0][case % 3 / 1 % 3] * scale;
            let thickness = if case % 2 == 0 { 0.0 } else { 0.01 * scale };
            let start: [V3; 4] = std::array::from_fn(|_| rng.vec(scale));
            let end: [V3; 4] = std::array::from_fn(|k| {
                let d = rng.vec(motion);
                [start[k][0] + d[0], start[k][1] + d[1], start[k][2] + d[2]]
            });
            let vt = certain_contact(&start, &end, thickness, true);
            let ee = certain_contact(&start, &end, thickness, false);
            let svt = vertex_triangle_hulls_separated(&start, &end, thickness);
            let see = edge_edge_hulls_separated(&start, &end, thickness);
            assert!(!(vt && svt), "case {case}: vertex-triangle contact refuted");
            assert!(!(ee && see), "case {case}: edge-edge contact refuted");
            hits += usize::from(vt) + usize::from(ee);
            refuted += usize::from(svt) + usize::from(see);
        }
        assert!(hits > 100 && refuted > 1000, "hits {hits}, refuted {refuted}");
        // A vertex beside a triangle in its plane, barely moving: the plane filter cannot refute
        // it, this filter does.
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let start = [[1.0, 1.0, 0.0], tri[0], tri[1], tri[2]];
        let end = [[1.0, 1.0, 1e-3], tri[0], tri[1], tri[2]];
        assert!(vertex_triangle_hulls_separated(&start, &end, 1e-3));
        assert!(!vertex_triangle_hulls_separated(&start, &end, 0.8));
    }

    #[test]
    fn diagonal_slabs_never_refute_a_certain_contact_and_refute_diagonal_neighbours() {
        let mut rng = Rng(11);
        let (mut refuted, mut hits) = (0, 0);
        for case in 0..20000 {
            let scale = [1.0, 1e-3, 1e3][case % 3];
            let motion = [0.3, 0.01, 1.0][case / 3 % 3] * scale;
            let thickness = if case % 2 == 0 { 0.0 } else { 0.02 * scale };
            // f32 positions, as the shell has them.
            let f32_point = |p: V3| p.map(|x| x as f32 as f64);
            let start: [V3; 4] = std::array::from_fn(|_| f32_point(rng.vec(scale)));
            let end: [V3; 4] = std::array::from_fn(|k| {
                let d = rng.vec(motion);
                f32_point([start[k][0] + d[0], start[k][1] + d[1], start[k][2] + d[2]])
            });
            let largest = largest(&start).max(largest(&end));
            let margin = diagonal_margin(thickness, largest);
            let p = |x: &V3| Vec3A::new(x[0] as f32, x[1] as f32, x[2] as f32);
            let (s, e) = (start.map(|x| p(&x)), end.map(|x| p(&x)));
            let vt = diagonals_separated(&[s[0], e[0]], &[s[1], s[2], s[3], e[1], e[2], e[3]], margin);
            let ee = diagonals_separated(&[s[0], s[1], e[0], e[1]], &[s[2], s[3], e[2], e[3]], margin);
            let (vt_hit, ee_hit) =
                (certain_contact(&start, &end, thickness, true), certain_contact(&start, &end, thickness, false));
            assert!(!(vt && vt_hit), "case {case}: vertex-triangle contact refuted");
            assert!(!(ee && ee_hit), "case {case}: edge-edge contact refuted");
            hits += usize::from(vt_hit) + usize::from(ee_hit);
            refuted += usize::from(vt) + usize::from(ee);
        }
        assert!(hits > 100 && refuted > 1000, "hits {hits}, refuted {refuted}");
        // Two parallel edges side by side along a diagonal, 0.1 apart: their boxes overlap on
        // every axis (each spans 0.5 on x and y), the diagonal x+y separates them.
        let ab = [Vec3A::new(0.0, 0.5, 0.0), Vec3A::new(0.5, 0.0, 0.0)];
        let cd = [Vec3A::new(0.0, 0.6, 0.0), Vec3A::new(0.6, 0.0, 0.0)];
        let (first, second) = ([ab[0], ab[1], ab[0], ab[1]], [cd[0], cd[1], cd[0], cd[1]]);
        assert!(diagonals_separated(&first, &second, diagonal_margin(0.05, 0.6)));
        assert!(!diagonals_separated(&first, &second, diagonal_margin(0.08, 0.6)), "0.0707 apart along x+y");
    }

    /// Whether the pair certainly comes within `thickness` (Euclidean): the exact search at
    /// thickness 0 says so (a hit or a near miss within its tolerance), or one of 1,025 evenly
    /// spaced samples of the distance is within the thickness. (The exact search with a
    /// thickness is not the reference: it measures the gap per axis, so it also reports pairs up
    /// to about sqrt(3) thicknesses apart, which these filters may refute.)
    fn certain_contact(start: &[V3; 4], end: &[V3; 4], thickness: f64, vertex_face: bool) -> bool {
        let (exact_at_zero, gap): (bool, fn(&[V3; 4]) -> DVec3) = if vertex_face {
            (vertex_triangle(start, end, 0.0).is_some(), vt_gap)
        } else {
            (edge_edge(start, end, 0.0).is_some(), ee_gap)
        };
        exact_at_zero || (0..=1024).any(|k| !(gap(&points_at(start, end, k as f64 / 1024.0)).length() > thickness))
    }

    /// The gaps of a pair at the times k/8 (as the shell's CCD samples them).
    fn gaps_of(start: &[V3; 4], end: &[V3; 4], gap: &dyn Fn(&[V3; 4]) -> DVec3) -> Vec<DVec3> {
        (0..=8).map(|k| gap(&points_at(start, end, k as f64 / 8.0))).collect()
    }

    fn vt_gap(x: &[V3; 4]) -> DVec3 {
        let [p, a, b, c] = x.map(|v| dv(&v));
        let al = crate::collision::self_contact::closest_on_triangle(p, a, b, c);
        p - (a * al[0] + b * al[1] + c * al[2])
    }

    fn ee_gap(x: &[V3; 4]) -> DVec3 {
        let [a, b, c, d] = x.map(|v| dv(&v));
        let (s, t) = crate::collision::self_contact::closest_segments(a, b, c, d);
        (a + (b - a) * s) - (c + (d - c) * t)
    }

    #[test]
    fn piecewise_separation_never_refutes_a_certain_contact() {
        let mut rng = Rng(11);
        let (mut refuted, mut hits) = (0, 0);
        for case in 0..20000 {
            let scale = [1.0, 1e-3, 1e3][case % 3];
            // Small thicknesses against the motion, and thick ones, so that pairs pass close.
            let thickness = [0.0, 0.01, 0.1, 0.3][case % 4] * scale;
            let start: [V3; 4] = std::array::from_fn(|_| rng.vec(scale));
            let end: [V3; 4] = std::array::from_fn(|k| {
                let d = rng.vec(0.5 * scale);
                [start[k][0] + d[0], start[k][1] + d[1], start[k][2] + d[2]]
            });
            let vt = certain_contact(&start, &end, thickness, true);
            let ee = certain_contact(&start, &end, thickness, false);
            let svt = separated_piecewise(&start, &end, 1, &gaps_of(&start, &end, &vt_gap), thickness, vt_gap);
            let see = separated_piecewise(&start, &end, 2, &gaps_of(&start, &end, &ee_gap), thickness, ee_gap);
            assert!(!(vt && svt), "case {case}: vertex-triangle contact refuted");
            assert!(!(ee && see), "case {case}: edge-edge contact refuted");
            hits += usize::from(vt) + usize::from(ee);
            refuted += usize::from(svt) + usize::from(see);
        }
        assert!(hits > 1000 && refuted > 1000, "hits {hits}, refuted {refuted}");
    }

    #[test]
    fn a_vertex_sliding_past_a_triangle_edge_in_its_plane_is_refuted_piecewise() {
        // The vertex slides along the hypotenuse x + y = 1 of the triangle, 1.5 thicknesses away,
        // in the triangle's plane: the plane filter cannot refute it (coplanar all along), nor
        // can the hull of the whole step (its end directions point at the corners), but the hull
        // of each eighth of the step along the gap sampled there does.
        let delta = 1e-3;
        let off = 1.5 * delta * std::f64::consts::SQRT_2;
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let start = [[1.3 + off, -0.3, 0.0], tri[0], tri[1], tri[2]];
        let end = [[-0.3 + off, 1.3, 0.0], tri[0], tri[1], tri[2]];
        assert!(!vertex_triangle_hulls_separated(&start, &end, delta));
        let w = [sub(&start[0], &start[1]), sub(&end[0], &end[1])];
        let (e1, e2) = ([sub(&tri[1], &tri[0]); 2], [sub(&tri[2], &tri[0]); 2]);
        assert!(!crate::collision::filters::plane_distance_filter(w, e1, e2, delta));
        assert!(separated_piecewise(&start, &end, 1, &gaps_of(&start, &end, &vt_gap), delta, vt_gap));
        // (The exact search is no reference here: it measures the gap per axis.)
        let closest = (0..=4096).map(|k| vt_gap(&points_at(&start, &end, k as f64 / 4096.0)).length());
        let closest = closest.fold(f64::INFINITY, f64::min);
        assert!((closest - 1.5 * delta).abs() < 1e-9, "{closest}");
        // 0.9 thicknesses away: a contact, never refuted.
        let closer = |p: V3| [p[0] - 0.5 * off, p[1], p[2]];
        let (start, end) = ([closer(start[0]), tri[0], tri[1], tri[2]], [closer(end[0]), tri[0], tri[1], tri[2]]);
        assert!(!separated_piecewise(&start, &end, 1, &gaps_of(&start, &end, &vt_gap), delta, vt_gap));
        assert!(vertex_triangle(&start, &end, delta).is_some());
    }
}
