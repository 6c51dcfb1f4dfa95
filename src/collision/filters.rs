//! Cheap conservative filters run before the exact CCD search (SPEC 1.6, 1.6.1).
//!
//! Each filter answers `true` only when the two primitives certainly stay farther apart than the
//! thickness during the whole step; `false` means "maybe" and the caller goes on to the exact
//! search. Every floating-point quantity a decision rests on is compared against a rigorous bound
//! on its rounding error, so a filter can never drop a real contact.

/// A point or vector in double precision.
pub type V3 = [f64; 3];

/// Unit roundoff of f64 (round to nearest): every basic operation has relative error <= U.
pub(crate) const U: f64 = f64::EPSILON / 2.0;

/// Absolute slack covering gradual underflow: each operation that underflows adds at most
/// 2^-1075; a few dozen of them stay far below this.
pub(crate) const UNDERFLOW_SLACK: f64 = f64::MIN_POSITIVE;

#[inline(always)]
pub(crate) fn sub(a: &V3, b: &V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `x . (y x z)` together with the sum of the absolute values of its six monomials
/// (`sum |x_i| (|y_j z_k| + |y_k z_j|)`), the scale of its rounding error.
#[inline(always)]
fn det_and_scale(x: &V3, y: &V3, z: &V3) -> (f64, f64) {
    let c0 = y[1] * z[2] - y[2] * z[1];
    let c1 = y[2] * z[0] - y[0] * z[2];
    let c2 = y[0] * z[1] - y[1] * z[0];
    let det = x[0] * c0 + x[1] * c1 + x[2] * c2;
    let a0 = (y[1] * z[2]).abs() + (y[2] * z[1]).abs();
    let a1 = (y[2] * z[0]).abs() + (y[0] * z[2]).abs();
    let a2 = (y[0] * z[1]).abs() + (y[1] * z[0]).abs();
    let scale = x[0].abs() * a0 + x[1].abs() * a1 + x[2].abs() * a2;
    (det, scale)
}

#[inline(always)]
fn l1(v: &V3) -> f64 {
    v[0].abs() + v[1].abs() + v[2].abs()
}

/// Stage 1: are the boxes swept by two point sets over the step more than `thickness` apart on
/// some axis? `first` and `second` hold each primitive's points at both ends of the step (motion
/// is linear, so the swept box is the box of those points).
///
/// Exactness: with thickness 0 the test `fl(min_b - max_a) > 0` is exact (a rounded difference
/// has the sign of the exact one). With thickness > 0 the margin `thickness (1 + 2^-50)` absorbs
/// the two roundings. Any NaN makes the comparison false, i.e. "maybe".
pub fn swept_aabbs_separated(first: &[V3], second: &[V3], thickness: f64) -> bool {
    let margin = thickness * (1.0 + 4.0 * f64::EPSILON);
    for axis in 0..3 {
        let (mut lo_a, mut hi_a) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in first {
            lo_a = lo_a.min(p[axis]);
            hi_a = hi_a.max(p[axis]);
        }
        let (mut lo_b, mut hi_b) = (f64::INFINITY, f64::NEG_INFINITY);
        for p in second {
            lo_b = lo_b.min(p[axis]);
            hi_b = hi_b.max(p[axis]);
        }
        if lo_b - hi_a > margin || lo_a - hi_b > margin {
            return true;
        }
    }
    false
}

/// Stage 2: the deforming non-penetration filter (Tang et al. 2010), with a thickness.
///
/// `w(t)`, `e1(t)`, `e2(t)` are linear in t with the given end values (index 0 at t = 0, 1 at
/// t = 1). For a vertex-triangle pair `w = p - a`, `e1 = b - a`, `e2 = c - a`; for an edge pair
/// `w = c - a`, `e1 = b - a`, `e2 = d - c`. With `n(t) = e1(t) x e2(t)`, the distance between the
/// primitives is at least the distance to the plane (or between the lines), `|f(t)| / |n(t)|`
/// with the cubic `f(t) = w(t) . n(t)`. Returns `true` when `|f(t)| > thickness |n(t)|` for every
/// t in [0, 1], so the primitives never come within `thickness`.
///
/// `f` is a product of three linear factors, so its Bernstein coefficients on [0, 1] are, by
/// multilinearity of the determinant, `B0 = d000`, `B1 = (d100 + d010 + d001)/3`,
/// `B2 = (d110 + d101 + d011)/3`, `B3 = d111` with `dijk = det(w_i, e1_j, e2_k)`; `f(t)` lies
/// between the smallest and the largest of them. `|n(t)| <= max_j |e1_j| max_k |e2_k|` (norms are
/// convex along a segment; the L1 norm bounds the L2 one).
///
/// Error bound: every input vector carries one rounding (relative U per component), which moves a
/// determinant by at most `3U` times the sum of its monomials' magnitudes `S`; evaluating it adds
/// at most `5U S`; summing three adds `2U` of their scales. The bound used, `2^5 U S` per
/// determinant (plus [`UNDERFLOW_SLACK`]), is four times that. Overflow gives inf or NaN, and
/// both make the strict comparisons false ("maybe").
pub fn plane_distance_filter(w: [V3; 2], e1: [V3; 2], e2: [V3; 2], thickness: f64) -> bool {
    let (d000, s000) = det_and_scale(&w[0], &e1[0], &e2[0]);
    let (d100, s100) = det_and_scale(&w[1], &e1[0], &e2[0]);
    let (d010, s010) = det_and_scale(&w[0], &e1[1], &e2[0]);
    let (d001, s001) = det_and_scale(&w[0], &e1[0], &e2[1]);
    let (d110, s110) = det_and_scale(&w[1], &e1[1], &e2[0]);
    let (d101, s101) = det_and_scale(&w[1], &e1[0], &e2[1]);
    let (d011, s011) = det_and_scale(&w[0], &e1[1], &e2[1]);
    let (d111, s111) = det_and_scale(&w[1], &e1[1], &e2[1]);

    let k = 32.0 * U;
    // Bernstein coefficients times (1, 3, 3, 1) and their error bounds.
    let b = [d000, d100 + d010 + d001, d110 + d101 + d011, d111];
    let err = [
        k * s000 + UNDERFLOW_SLACK,
        k * (s100 + s010 + s001) + UNDERFLOW_SLACK,
        k * (s110 + s101 + s011) + UNDERFLOW_SLACK,
        k * s111 + UNDERFLOW_SLACK,
    ];
    // Upper bound of thickness |n(t)|, rounded up by a relative 2^-40 (far more than the few
    // roundings in it).
    let n_max = l1(&e1[0]).max(l1(&e1[1])) * l1(&e2[0]).max(l1(&e2[1]));
    let gap = thickness * n_max * (1.0 + 4096.0 * f64::EPSILON);
    let weight = [1.0, 3.0, 3.0, 1.0];
    let mut all_above = true;
    let mut all_below = true;
    for i in 0..4 {
        // (gap * weight + err) rounded: err is already four times the needed bound, and the
        // factor on gap covers the last additions.
        let threshold = (gap * weight[i] + err[i]) * (1.0 + 4.0 * f64::EPSILON);
        all_above &= b[i] > threshold;
        all_below &= b[i] < -threshold;
    }
    all_above || all_below
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aabb_separates_far_boxes_and_keeps_touching_ones() {
        let a = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
        let b = [[2.0, 0.0, 0.0], [3.0, 1.0, 0.0], [2.0, 1.0, 1.0]];
        assert!(swept_aabbs_separated(&a, &b, 0.0));
        assert!(swept_aabbs_separated(&a, &b, 0.99));
        assert!(!swept_aabbs_separated(&a, &b, 1.0));
        let touching = [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 1.0]];
        assert!(!swept_aabbs_separated(&a, &touching, 0.0));
    }

    #[test]
    fn plane_filter_refutes_a_vertex_staying_above_and_keeps_a_crossing() {
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let e1 = [sub(&tri[1], &tri[0]); 2];
        let e2 = [sub(&tri[2], &tri[0]); 2];
        let above = [[0.2, 0.2, 1.0], [0.2, 0.2, 0.5]];
        assert!(plane_distance_filter(above, e1, e2, 0.0));
        assert!(plane_distance_filter(above, e1, e2, 0.49));
        assert!(!plane_distance_filter(above, e1, e2, 0.5));
        let crossing = [[0.2, 0.2, 1.0], [0.2, 0.2, -1.0]];
        assert!(!plane_distance_filter(crossing, e1, e2, 0.0));
        let touching_at_end = [[0.2, 0.2, 1.0], [5.0, 5.0, 0.0]];
        assert!(!plane_distance_filter(touching_at_end, e1, e2, 0.0));
    }

    #[test]
    fn plane_filter_never_refutes_parallel_or_degenerate_edges() {
        let zero = [[0.0; 3]; 2];
        let w = [[0.0, 1.0, 0.0]; 2];
        let e = [[1.0, 0.0, 0.0]; 2];
        assert!(!plane_distance_filter(w, e, e, 0.0), "parallel edges give f = 0");
        assert!(!plane_distance_filter(w, zero, e, 0.0));
    }
}
