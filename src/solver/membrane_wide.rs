//! The StVK membrane energy constraint (SPEC 1.3) for four triangles at once (SSE lanes): the
//! default material's hot path. Same formulas as `material::membrane_energy` (StVK),
//! `triangle::{deformation_gradient, scatter_stress}` and the energy constraints, fused.

use glam::Vec4;

use super::wide::W3;

/// Rest data and masses of four triangles, one per lane.
#[derive(Clone, Copy, Debug)]
pub struct MembraneLanes {
    /// `Dm^-1` entries m00, m01, m10, m11.
    pub dm_inv: [Vec4; 4],
    /// Rest areas A0.
    pub area: Vec4,
    /// Inverse masses of the three corners.
    pub inv_mass: [Vec4; 3],
}

/// Projects four StVK membrane constraints with Lamé parameters `(mu, lambda)` of unit modulus.
/// `xpbd` = `(α̃, λ)` selects the XPBD form, `None` the paper's PBD form. Returns the corrections
/// of the three corners, Δλ and the mask of lanes that changed (the others must not be applied).
#[inline(always)]
pub fn stvk_projection_wide(
    x: &[W3; 3],
    rest: &MembraneLanes,
    mu: f32,
    lambda: f32,
    xpbd: Option<(Vec4, Vec4)>,
) -> ([W3; 3], Vec4, u32) {
    let [m00, m01, m10, m11] = rest.dm_inv;
    let (d1, d2) = (x[1].sub(x[0]), x[2].sub(x[0]));
    // F = Ds Dm^-1
    let f0 = d1.scale(m00).add(d2.scale(m10));
    let f1 = d1.scale(m01).add(d2.scale(m11));
    // SPEC 1.3: E = (C - I)/2, ψ = μ E:E + λ/2 (tr E)², P = F (2μE + λ tr(E) I)
    let half = Vec4::splat(0.5);
    let ea = half * (f0.dot(f0) - Vec4::ONE);
    let eb = half * f0.dot(f1);
    let ed = half * (f1.dot(f1) - Vec4::ONE);
    let tr = ea + ed;
    let (mu4, la4) = (Vec4::splat(mu), Vec4::splat(lambda));
    let psi = mu4 * (ea * ea + Vec4::splat(2.0) * eb * eb + ed * ed) + half * la4 * tr * tr;
    let two_mu = Vec4::splat(2.0 * mu);
    let (sa, sb, sd) = (two_mu * ea + la4 * tr, two_mu * eb, two_mu * ed + la4 * tr);
    let p0 = f0.scale(sa).add(f1.scale(sb));
    let p1 = f0.scale(sb).add(f1.scale(sd));
    // [∂W/∂x1, ∂W/∂x2] = A0 P Dm^-T, ∂W/∂x0 = -(∂W/∂x1 + ∂W/∂x2)
    let g1 = p0.scale(m00).add(p1.scale(m01)).scale(rest.area);
    let g2 = p0.scale(m10).add(p1.scale(m11)).scale(rest.area);
    let g0 = W3::default().sub(g1.add(g2));
    let energy = rest.area * psi;
    let [w0, w1, w2] = rest.inv_mass;
    let gsum = w0 * g0.dot(g0) + w1 * g1.dot(g1) + w2 * g2.dot(g2);
    let (factor, dlambda, active) = match xpbd {
        Some((alpha, lam)) => {
            // XPBD (SPEC 1.3): C = sqrt(2Ŵ), Δx_i = w_i ∇Ŵ_i · (-C (C + α̃λ)/(Σ w|∇Ŵ|² + α̃C²))
            let c2 = Vec4::splat(2.0) * energy;
            let c = c2.sqrt();
            let denom = gsum + alpha * c2;
            let active = c2.cmpgt(Vec4::splat(1e-12) * rest.area) & denom.cmpgt(Vec4::splat(1e-30));
            let factor = -c * (c + alpha * lam) / denom;
            (factor, factor * c, active.bitmask())
        }
        None => {
            // The paper's PBD: Δx_i = -(W / Σ w|∇W|²) w_i ∇W_i
            let active = energy.cmpgt(Vec4::ZERO) & gsum.cmpgt(Vec4::splat(1e-30) * energy);
            (-(energy / gsum), Vec4::ZERO, active.bitmask())
        }
    };
    ([g0.scale(w0 * factor), g1.scale(w1 * factor), g2.scale(w2 * factor)], dlambda, active)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Lame, Material, membrane_energy};
    use crate::solver::{
        deformation_gradient, pbd_energy_correction, scatter_stress, triangle_rest, xpbd_energy_correction,
    };
    use glam::Vec3;

    #[test]
    fn four_lanes_give_what_the_scalar_kernels_give() {
        let rest_x = [
            [Vec3::new(0.1, 0.2, 0.3), Vec3::new(1.0, 0.4, 0.2), Vec3::new(0.3, 1.1, 0.6)],
            [Vec3::ZERO, Vec3::X, Vec3::Y],
            [Vec3::ZERO, Vec3::new(0.5, 0.0, 0.1), Vec3::new(0.2, 0.3, 0.0)],
            [Vec3::new(1.0, 1.0, 1.0), Vec3::new(1.2, 1.0, 1.0), Vec3::new(1.0, 1.3, 0.9)],
        ];
        let rests = rest_x.map(|t| triangle_rest(t[0], t[1], t[2]).unwrap());
        // The second lane stays at rest (no correction expected).
        let now = [
            [Vec3::new(0.0, 0.25, 0.3), Vec3::new(1.2, 0.3, 0.1), Vec3::new(0.2, 0.9, 0.9)],
            rest_x[1],
            [Vec3::new(0.0, 0.0, 0.2), Vec3::new(0.4, 0.1, 0.1), Vec3::new(0.25, 0.35, 0.0)],
            [Vec3::new(1.0, 1.0, 1.0), Vec3::new(1.25, 1.02, 1.0), Vec3::new(0.98, 1.3, 0.95)],
        ];
        let inv = [[1.0f32, 0.5, 2.0], [1.0, 1.0, 1.0], [0.3, 0.7, 1.1], [2.0, 2.0, 0.5]];
        let lane = |f: &dyn Fn(usize) -> f32| Vec4::new(f(0), f(1), f(2), f(3));
        let lanes = MembraneLanes {
            dm_inv: [0, 1, 2, 3].map(|k| lane(&|j| rests[j].dm_inv[k])),
            area: lane(&|j| rests[j].area),
            inv_mass: [0, 1, 2].map(|k| lane(&|j| inv[j][k])),
        };
        let x = [0, 1, 2].map(|k| W3::gather(now.map(|t| t[k])));
        let lame = Lame::from_young_poisson(1.0, 0.3);
        for xpbd in [true, false] {
            let param = xpbd.then_some((Vec4::splat(0.2), Vec4::splat(0.05)));
            let (corr, dl, active) = stvk_projection_wide(&x, &lanes, lame.mu, lame.lambda, param);
            for j in 0..4 {
                let r = &rests[j];
                let f = deformation_gradient(now[j], &r.dm_inv);
                let (psi, p) = membrane_energy(Material::StVK, lame, &f, &r.basis);
                let (energy, grad) = (r.area * psi, scatter_stress(&p, &r.dm_inv, r.area));
                let mut expected = [Vec3::ZERO; 3];
                let changed = if xpbd {
                    let d = xpbd_energy_correction(energy, &grad, &inv[j], 0.2, 0.05, 1e-12 * r.area, &mut expected);
                    if d != 0.0 {
                        assert!((dl[j] - d).abs() <= 1e-4 * d.abs(), "lane {j}: {} vs {d}", dl[j]);
                    }
                    d != 0.0
                } else {
                    pbd_energy_correction(energy, &grad, &inv[j], 1.0, &mut expected)
                };
                assert_eq!(changed, active & (1 << j) != 0, "lane {j} xpbd {xpbd}");
                if changed {
                    for k in 0..3 {
                        let got = corr[k].lane(j);
                        assert!(
                            (got - expected[k]).length() <= 1e-4 * expected[k].length().max(1e-7),
                            "lane {j} corner {k}"
                        );
                    }
                }
            }
        }
    }
}
