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
//! Exactness: a projection `w · x` in f64 is within `3U Σ|w_i||x_i| <= 3U |w|_1 M` of the exact
//! one (M = the largest |coordinate|); the difference of two adds one rounding. The test requires
//! a separation above `thickness |w|_1 + 16 U |w|_1 M` (|w|_2 <= |w|_1), far more than those.

use glam::DVec3;

use super::filters::{U, UNDERFLOW_SLACK, V3};

fn dv(p: &V3) -> DVec3 {
    DVec3::new(p[0], p[1], p[2])
}

/// True when the hulls of `first` and `second` are farther apart than `thickness` along `w`.
fn separated_along(w: DVec3, first: &[V3], second: &[V3], thickness: f64, largest: f64) -> bool {
    let w1 = w.x.abs() + w.y.abs() + w.z.abs();
    if !(w1 > 0.0) || !w1.is_finite() {
        return false;
    }
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
    let margin = (thickness * w1 + 16.0 * U * w1 * largest) * (1.0 + 8.0 * U) + UNDERFLOW_SLACK;
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

#[cfg(test)]
mod tests {
    use super::*;
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
    fn never_refutes_what_the_exact_test_finds_and_refutes_neighbours() {
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
            let vt = vertex_triangle(&start, &end, thickness).is_some();
            let ee = edge_edge(&start, &end, thickness).is_some();
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
}
