//! Isometric bending (SPEC 1.4; Bergou et al. 2006): per interior edge (x0, x1) with opposite
//! vertices x2 (triangle x0 x1 x2) and x3 (triangle x0 x1 x3),
//! `E = q/2 |Σ K_i x_i - target|²`, `q = 3/(A0 + A1)`, `∂E/∂x_i = q K_i (Σ K_j x_j - target)`.
//!
//! `target = 0` is the paper's flat-rest model. The rest-preserving default uses
//! `target = R Σ K_i X_i`, with R the rotation that takes the stencil's rest frame (edge
//! direction, mean face normal, their cross product) to its current frame. R is held fixed while
//! the gradient is taken (it changes only with the stencil's rigid motion, as in shape matching),
//! so the energy is zero at the rest shape and after any rigid motion of the stencil.

// NaN must fail every guard below, so comparisons are written `!(x > limit)` on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use glam::{Vec3, Vec4};

use super::wide::W3;

/// Below this `|u × v|` a cotangent is taken as 0 (SPEC 1.4 guard).
const MIN_CROSS: f32 = 1e-20;

/// Rest data of one bending stencil.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BendingRest {
    /// `K = (c03 + c04, c01 + c02, -c01 - c03, -c02 - c04)`, `Σ K = 0`.
    pub k: [f32; 4],
    /// `q = 3/(A0 + A1)`.
    pub q: f32,
    /// `Σ K_i X_i` in the rest frame's coordinates (edge, normal, binormal).
    pub rest_local: Vec3,
}

fn cot(u: Vec3, v: Vec3) -> f32 {
    let cross = u.cross(v).length();
    if cross < MIN_CROSS { 0.0 } else { u.dot(v) / cross }
}

/// The stencil's frame: unit edge direction, unit mean normal and their cross product; `None`
/// when the two faces fold onto each other or collapse. The normal
/// `m = e0 × (x2 - x0) + (x3 - x0) × e0` is perpendicular to the edge by construction.
#[inline(always)]
fn frame(x: &[Vec3; 4]) -> Option<[Vec3; 3]> {
    let e0 = x[1] - x[0];
    let m = e0.cross(x[2] - x[0]) + (x[3] - x[0]).cross(e0);
    let (l2, m2) = (e0.length_squared(), m.length_squared());
    if !(l2 > 0.0) || !(m2 > 1e-24 * l2 * l2) {
        return None;
    }
    let (inv_l, inv_m) = (l2.sqrt().recip(), m2.sqrt().recip());
    let (e, n) = (e0 * inv_l, m * inv_m);
    Some([e, n, e.cross(n)])
}

#[inline(always)]
fn stencil_vector(x: &[Vec3; 4], k: &[f32; 4]) -> Vec3 {
    // SPEC 1.4 precision: Σ K_i (x_i - x_0), never the expanded quadratic form.
    (x[1] - x[0]) * k[1] + (x[2] - x[0]) * k[2] + (x[3] - x[0]) * k[3]
}

/// Rest data from rest positions, `None` when a face of the stencil is degenerate.
pub fn bending_rest(x: [Vec3; 4]) -> Option<BendingRest> {
    let e0 = x[1] - x[0];
    let (e1, e2, e3, e4) = (x[2] - x[0], x[3] - x[0], x[2] - x[1], x[3] - x[1]);
    let (a0, a1) = (0.5 * e0.cross(e1).length(), 0.5 * e0.cross(e2).length());
    if !(a0 + a1 > 0.0) || a0 <= MIN_CROSS || a1 <= MIN_CROSS {
        return None;
    }
    let (c01, c02, c03, c04) = (cot(e0, e1), cot(e0, e2), cot(-e0, e3), cot(-e0, e4));
    let k = [c03 + c04, c01 + c02, -c01 - c03, -c02 - c04];
    let v0 = stencil_vector(&x, &k);
    let rest_local = match frame(&x) {
        Some([e, n, b]) => Vec3::new(v0.dot(e), v0.dot(n), v0.dot(b)),
        None => return None,
    };
    Some(BendingRest { k, q: 3.0 / (a0 + a1), rest_local })
}

/// `v = Σ K_i x_i - target`: the paper's target 0 when `rest_local` is `None`, else the rest
/// vector carried by the stencil's current frame. `E = q/2 |v|²`, `∂E/∂x_i = q K_i v`.
#[inline(always)]
pub fn bending_residual(x: &[Vec3; 4], k: &[f32; 4], rest_local: Option<Vec3>) -> Vec3 {
    let v = stencil_vector(x, k);
    match rest_local.and_then(|r| frame(x).map(|f| (r, f))) {
        Some((r, [e, n, b])) => v - (e * r.x + n * r.y + b * r.z),
        None => v,
    }
}

/// Energy `E` and gradients of one stencil (see the module doc). `keep_rest` selects the
/// rest-preserving target; `false` is the paper's flat-rest model.
#[inline(always)]
pub fn bending_energy(x: &[Vec3; 4], rest: &BendingRest, keep_rest: bool) -> (f32, [Vec3; 4]) {
    let v = bending_residual(x, &rest.k, keep_rest.then_some(rest.rest_local));
    let energy = 0.5 * rest.q * v.length_squared();
    let qv = v * rest.q;
    (energy, [qv * rest.k[0], qv * rest.k[1], qv * rest.k[2], qv * rest.k[3]])
}

/// The energy constraints of SPEC 1.3 specialised to a bending stencil, whose gradients are all
/// parallel to v: with `wk2 = Σ w_i K_i²`, both forms give `Δx_i = v · (w_i K_i · scale)`.
/// XPBD (`alpha` = α̃, `lambda` accumulated): `C² = q|v|²`, `Δλ = -C²(C + α̃λ)/(q² |v|² wk2 + α̃ C²)`,
/// `scale = q Δλ / C`. PBD (`alpha` = `None`, `stiffness` = kB): `scale = -kB / (2 wk2)`.
/// Returns `(scale, Δλ)`, or `None` when the stencil is at rest (C below `min_c`) or immovable.
#[inline(always)]
pub fn bending_projection(
    v: Vec3,
    q: f32,
    wk2: f32,
    xpbd: Option<(f32, f32)>,
    stiffness: f32,
    min_c: f32,
) -> Option<(f32, f32)> {
    let vv = v.length_squared();
    let c2 = q * vv;
    if !(c2 > min_c * min_c) || !(wk2 > 0.0) {
        return None;
    }
    match xpbd {
        Some((alpha, lambda)) => {
            let c = c2.sqrt();
            let denom = q * q * vv * wk2 + alpha * c2;
            // Δλ / C = -C (C + α̃λ)/denom: one division, no division by C.
            let per_c = -c * (c + alpha * lambda) / denom;
            Some((q * per_c, per_c * c))
        }
        None => Some((-stiffness / (2.0 * wk2), 0.0)),
    }
}

/// The target `Σ K_i x_i` is compared with, for four stencils (lanes).
#[derive(Clone, Copy, Debug)]
pub enum WideTarget<'a> {
    /// The paper's flat rest: 0.
    Flat,
    /// The rest vectors (frame coordinates), carried by each stencil's current frame.
    Frame(&'a W3),
    /// Targets already in world space (see [`bending_target`]).
    Fixed(&'a W3),
}

/// The rest-preserving target `R Σ K_i X_i` of a stencil at positions `x`: its rest vector in
/// frame coordinates carried by the current frame (0 when the frame is degenerate, as in
/// [`bending_residual`]). A solver may evaluate it once per substep and hold it through the
/// iterations (the frame's rotation lags by at most one substep).
#[inline(always)]
pub fn bending_target(x: &[Vec3; 4], rest_local: Vec3) -> Vec3 {
    match frame(x) {
        Some([e, n, b]) => e * rest_local.x + n * rest_local.y + b * rest_local.z,
        None => Vec3::ZERO,
    }
}

/// [`bending_residual`] followed by [`bending_projection`] for four stencils at once (lanes).
/// `x[k]` holds vertex k of every stencil, `k` the coefficients K1..K3, `target` what
/// `Σ K_i x_i` is compared with. Returns `(v, scale, Δλ, active)`: lane j is to be applied
/// as `Δx_i = v_j · (w_i K_i · scale_j)` when bit j of `active` is set.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn bending_projection_wide(
    x: &[W3; 4],
    k: [Vec4; 3],
    target: WideTarget,
    q: Vec4,
    wk2: Vec4,
    xpbd: Option<(Vec4, Vec4)>,
    stiffness: f32,
    min_c: f32,
) -> (W3, Vec4, Vec4, u32) {
    let (d1, d2, d3) = (x[1].sub(x[0]), x[2].sub(x[0]), x[3].sub(x[0]));
    let mut v = d1.scale(k[0]).add(d2.scale(k[1])).add(d3.scale(k[2]));
    if let WideTarget::Fixed(t) = target {
        v = v.sub(*t);
    }
    if let WideTarget::Frame(r) = target {
        let m = d1.cross(d2).add(d3.cross(d1));
        let (l2, m2) = (d1.dot(d1), m.dot(m));
        let valid = l2.cmpgt(Vec4::ZERO) & m2.cmpgt(Vec4::splat(1e-24) * l2 * l2);
        let (inv_l, inv_m) = (l2.sqrt().recip(), m2.sqrt().recip());
        let (e, n) = (d1.scale(inv_l), m.scale(inv_m));
        let b = e.cross(n);
        let target = e.scale(r.x).add(n.scale(r.y)).add(b.scale(r.z));
        v = W3::select(valid, v.sub(target), v);
    }
    let vv = v.dot(v);
    let c2 = q * vv;
    let active = (c2.cmpgt(Vec4::splat(min_c * min_c)) & wk2.cmpgt(Vec4::ZERO)).bitmask();
    match xpbd {
        Some((alpha, lambda)) => {
            let c = c2.sqrt();
            let denom = q * q * vv * wk2 + alpha * c2;
            let per_c = -c * (c + alpha * lambda) / denom;
            (v, q * per_c, per_c * c, active)
        }
        None => (v, Vec4::splat(-stiffness) / (Vec4::splat(2.0) * wk2), Vec4::ZERO, active),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Mat3;

    fn stencil() -> [Vec3; 4] {
        [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.1, 0.0), Vec3::new(0.4, 0.9, 0.3), Vec3::new(0.6, -0.8, 0.25)]
    }

    #[test]
    fn k_sums_to_zero_and_flat_stencils_have_no_paper_energy() {
        let r = bending_rest(stencil()).unwrap();
        assert!(r.k.iter().sum::<f32>().abs() < 1e-5);
        let flat = [Vec3::ZERO, Vec3::X, Vec3::new(0.4, 0.9, 0.0), Vec3::new(0.6, -0.8, 0.0)];
        let rf = bending_rest(flat).unwrap();
        assert!(bending_energy(&flat, &rf, false).0 < 1e-10);
        // The paper's model pulls a bent rest shape towards flat (SPEC 1.4).
        assert!(bending_energy(&stencil(), &r, false).0 > 1e-3);
    }

    #[test]
    fn rest_preserving_energy_vanishes_at_rest_and_after_rigid_motion() {
        let x = stencil();
        let r = bending_rest(x).unwrap();
        assert!(bending_energy(&x, &r, true).0 < 1e-10);
        let rot = Mat3::from_axis_angle(Vec3::new(0.2, 1.0, -0.4).normalize(), 2.0);
        let moved = x.map(|p| rot * p + Vec3::new(3.0, -1.0, 2.0));
        assert!(bending_energy(&moved, &r, true).0 < 1e-9);
        let mut bent = x;
        bent[2].z += 0.3;
        assert!(bending_energy(&bent, &r, true).0 > 1e-3);
    }

    #[test]
    fn gradients_match_finite_differences() {
        let x0 = stencil();
        let r = bending_rest(x0).unwrap();
        let mut x = x0;
        x[2] += Vec3::new(0.05, -0.1, 0.2);
        x[3] += Vec3::new(-0.1, 0.05, -0.15);
        // Paper form: exact gradient.
        let (_, g) = bending_energy(&x, &r, false);
        let h = 1e-3;
        for v in 0..4 {
            for axis in 0..3 {
                let (mut p, mut m) = (x, x);
                p[v][axis] += h;
                m[v][axis] -= h;
                let fd = (bending_energy(&p, &r, false).0 - bending_energy(&m, &r, false).0) / (2.0 * h);
                assert!(
                    (fd - g[v][axis]).abs() < 2e-3 * g[v].length().max(1.0),
                    "v{v} axis {axis}: {fd} vs {}",
                    g[v][axis]
                );
            }
        }
        // The specialised projection equals the generic energy constraints.
        let inv = [1.0f32, 0.5, 2.0, 0.7];
        let wk2: f32 = (0..4).map(|i| inv[i] * r.k[i] * r.k[i]).sum();
        for keep in [false, true] {
            let (energy, g) = bending_energy(&x, &r, keep);
            let v = bending_residual(&x, &r.k, keep.then_some(r.rest_local));
            let mut generic = [Vec3::ZERO; 4];
            let dl = crate::solver::xpbd_energy_correction(energy, &g, &inv, 0.3, 0.1, 1e-18, &mut generic);
            let (scale, dl2) = bending_projection(v, r.q, wk2, Some((0.3, 0.1)), 1.0, 1e-9).unwrap();
            assert!((dl - dl2).abs() < 1e-4 * dl.abs().max(1e-6));
            for i in 0..4 {
                assert!((generic[i] - v * (inv[i] * r.k[i] * scale)).length() < 1e-4 * generic[i].length().max(1e-6));
            }
            let mut generic = [Vec3::ZERO; 4];
            assert!(crate::solver::pbd_energy_correction(energy, &g, &inv, 0.3, &mut generic));
            let (scale, _) = bending_projection(v, r.q, wk2, None, 0.3, 1e-9).unwrap();
            for i in 0..4 {
                assert!((generic[i] - v * (inv[i] * r.k[i] * scale)).length() < 1e-4 * generic[i].length().max(1e-6));
            }
        }
        // Four lanes give what the scalar kernel gives, lane by lane.
        let stencils = [x, x0, x.map(|p| p * 1.1), x.map(|p| p + Vec3::X)];
        let wx: [W3; 4] = [0, 1, 2, 3].map(|v| W3::gather(stencils.map(|s| s[v])));
        let kk = [Vec4::splat(r.k[1]), Vec4::splat(r.k[2]), Vec4::splat(r.k[3])];
        for keep in [false, true] {
            let rest = W3::gather([r.rest_local; 4]);
            let xp = Some((Vec4::splat(0.3), Vec4::splat(0.1)));
            let (v4, s4, l4, act) = bending_projection_wide(
                &wx,
                kk,
                if keep { WideTarget::Frame(&rest) } else { WideTarget::Flat },
                Vec4::splat(r.q),
                Vec4::splat(wk2),
                xp,
                1.0,
                1e-9,
            );
            for (j, st) in stencils.iter().enumerate() {
                let v = bending_residual(st, &r.k, keep.then_some(r.rest_local));
                match bending_projection(v, r.q, wk2, Some((0.3, 0.1)), 1.0, 1e-9) {
                    Some((scale, dl)) => {
                        assert!(act & (1 << j) != 0);
                        assert!((v4.lane(j) - v).length() <= 1e-6 * v.length().max(1e-6), "lane {j}");
                        assert!((s4[j] - scale).abs() <= 1e-5 * scale.abs().max(1e-9));
                        assert!((l4[j] - dl).abs() <= 1e-5 * dl.abs().max(1e-9));
                    }
                    None => assert!(act & (1 << j) == 0),
                }
            }
        }
        // A target evaluated beforehand gives the same residual as the frame inside.
        for st in &stencils {
            let fixed = bending_target(st, r.rest_local);
            let direct = bending_residual(st, &r.k, Some(r.rest_local));
            let held = bending_residual(st, &r.k, None) - fixed;
            assert!((direct - held).length() <= 1e-6 * direct.length().max(1e-6));
        }
        // Rest-preserving form: the gradient with the frame rotation held fixed.
        let (_, g) = bending_energy(&x, &r, true);
        let [e, n, b] = frame(&x).unwrap();
        let target = e * r.rest_local.x + n * r.rest_local.y + b * r.rest_local.z;
        let frozen = |y: &[Vec3; 4]| 0.5 * r.q * (stencil_vector(y, &r.k) - target).length_squared();
        for v in 0..4 {
            for axis in 0..3 {
                let (mut p, mut m) = (x, x);
                p[v][axis] += h;
                m[v][axis] -= h;
                let fd = (frozen(&p) - frozen(&m)) / (2.0 * h);
                assert!((fd - g[v][axis]).abs() < 2e-3 * g[v].length().max(1.0), "rest v{v} axis {axis}");
            }
        }
    }

    #[test]
    fn degenerate_stencils_are_refused() {
        assert!(bending_rest([Vec3::ZERO, Vec3::X, Vec3::X * 2.0, Vec3::Y]).is_none());
    }
}
