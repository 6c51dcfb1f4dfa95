//! The Gauss-Seidel sweeps of the shell (SPEC 1.1 step 2): membrane, edge-distance, bending
//! and anisotropic constraints, one colour at a time, each colour in parallel on the shell's
//! pool. Kernels come from `solver` and `material`; this file only gathers and scatters.

// NaN must fail every guard below, so comparisons are written `!(x > limit)` on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use glam::{Vec3, Vec4};

use super::constraints::{Anisotropics, Membranes};
use super::exec::{MIN_PARALLEL, Shared, add_compensated, for_range, for_range_min};
use super::settings::{AnisotropySettings, SolverKind};
use super::simulator::{Coefficients, State};
use crate::material::{Mat32, Material, anisotropic_energy, membrane_energy};
use crate::solver::{
    MembraneLanes, W3, WideTarget, bending_projection_wide, bending_target, deformation_gradient, distance_correction,
    pbd_energy_correction, scatter_stress, stvk_projection_wide, xpbd_energy_correction,
};

const IDENTITY_BASIS: Mat32 = Mat32 { c0: Vec3::X, c1: Vec3::Y };

/// Ŵ (unit modulus and thickness) and its gradients for membrane constraint `i` at positions `x`.
#[inline(always)]
pub(super) fn membrane_energy_at(m: &Membranes, i: usize, x: &[Vec3], c: &Coefficients) -> (f32, [Vec3; 3]) {
    let t = &m.tri[i];
    gather_membrane(m, i, [x[t[0] as usize], x[t[1] as usize], x[t[2] as usize]], c)
}

#[inline(always)]
pub(super) fn gather_membrane(m: &Membranes, i: usize, x: [Vec3; 3], c: &Coefficients) -> (f32, [Vec3; 3]) {
    let dm = &m.dm_inv[i];
    let f = deformation_gradient(x, dm);
    let basis = if c.material == Material::Linear { &m.basis[i] } else { &IDENTITY_BASIS };
    let (psi, stress) = membrane_energy(c.material, c.lame, &f, basis);
    let area = m.area[i];
    (area * psi, scatter_stress(&stress, dm, area))
}

/// Stencil area (A0 + A1)/2 from q = 3/(A0 + A1).
#[inline(always)]
pub(super) fn stencil_area(q: f32) -> f32 {
    1.5 / q
}

/// Ŵ and gradients of anisotropic constraint `i` (unit stiffness and thickness).
#[inline(always)]
pub(super) fn gather_aniso(a: &Anisotropics, i: usize, x: [Vec3; 3]) -> (f32, [Vec3; 3], &AnisotropySettings) {
    let dm = &a.dm_inv[i];
    let f = deformation_gradient(x, dm);
    let params = &a.params[a.region[i] as usize];
    let (psi, stress) = anisotropic_energy(params.energy, 1.0, params.target_stretch, &f, a.dir[i]);
    let area = a.area[i];
    (area * psi, scatter_stress(&stress, dm, area), params)
}

impl State {
    /// StVK (the default) four triangles at a time (SSE lanes), as the bending stencils; the
    /// other materials one at a time.
    pub(super) fn project_membranes_stvk(&mut self, c: &Coefficients, parallel: bool) {
        let m = &self.membranes;
        let p = Shared::new(&mut self.p);
        let lo = Shared::new(&mut self.p_lo);
        let lambda = Shared::new(&mut self.lambda_membrane);
        let xpbd = c.solver == SolverKind::Xpbd;
        let alpha = Vec4::splat(c.alpha_membrane);
        for colour in m.colours.windows(2) {
            let (start, end) = (colour[0], colour[1]);
            for_range_min(parallel, 0, (end - start).div_ceil(4), MIN_PARALLEL / 4, |g| {
                let base = start + 4 * g;
                let real = (end - base).min(4);
                let last = real - 1;
                let lanes: [usize; 4] = [base, base + 1.min(last), base + 2.min(last), base + 3.min(last)];
                let id = |j: usize| {
                    let t = &m.tri[lanes[j]];
                    [t[0] as usize, t[1] as usize, t[2] as usize]
                };
                let idx = [id(0), id(1), id(2), id(3)];
                let lane4 = |a: &[f32]| Vec4::new(a[lanes[0]], a[lanes[1]], a[lanes[2]], a[lanes[3]]);
                let (d0, d1, d2, d3) =
                    (&m.dm_inv[lanes[0]], &m.dm_inv[lanes[1]], &m.dm_inv[lanes[2]], &m.dm_inv[lanes[3]]);
                let (w0, w1, w2, w3) =
                    (&m.inv_mass[lanes[0]], &m.inv_mass[lanes[1]], &m.inv_mass[lanes[2]], &m.inv_mass[lanes[3]]);
                let rest = MembraneLanes {
                    dm_inv: [
                        Vec4::new(d0[0], d1[0], d2[0], d3[0]),
                        Vec4::new(d0[1], d1[1], d2[1], d3[1]),
                        Vec4::new(d0[2], d1[2], d2[2], d3[2]),
                        Vec4::new(d0[3], d1[3], d2[3], d3[3]),
                    ],
                    area: lane4(&m.area),
                    inv_mass: [
                        Vec4::new(w0[0], w1[0], w2[0], w3[0]),
                        Vec4::new(w0[1], w1[1], w2[1], w3[1]),
                        Vec4::new(w0[2], w1[2], w2[2], w3[2]),
                    ],
                };
                // SAFETY: triangles of one colour touch disjoint vertices; lambda[i] is i's. The
                // padding lanes read the last real triangle again and are not written.
                unsafe {
                    let vertex =
                        |k: usize| W3::gather([p.get(idx[0][k]), p.get(idx[1][k]), p.get(idx[2][k]), p.get(idx[3][k])]);
                    let x = [vertex(0), vertex(1), vertex(2)];
                    let lam = if xpbd {
                        Vec4::new(
                            lambda.get(lanes[0]),
                            lambda.get(lanes[1]),
                            lambda.get(lanes[2]),
                            lambda.get(lanes[3]),
                        )
                    } else {
                        Vec4::ZERO
                    };
                    let (corr, dlambda, active) =
                        stvk_projection_wide(&x, &rest, c.lame.mu, c.lame.lambda, xpbd.then_some((alpha, lam)));
                    for j in 0..real {
                        if active & (1 << j) == 0 {
                            continue;
                        }
                        if xpbd {
                            lambda.set(lanes[j], lam[j] + dlambda[j]);
                        }
                        for k in 0..3 {
                            add_compensated(&p, &lo, idx[j][k], x[k].lane(j), corr[k].lane(j));
                        }
                    }
                }
            });
        }
    }

    pub(super) fn project_membranes(&mut self, c: &Coefficients, parallel: bool) {
        if c.material == Material::StVK {
            return self.project_membranes_stvk(c, parallel);
        }
        let m = &self.membranes;
        let p = Shared::new(&mut self.p);
        let lo = Shared::new(&mut self.p_lo);
        let lambda = Shared::new(&mut self.lambda_membrane);
        for colour in m.colours.windows(2) {
            for_range(parallel, colour[0], colour[1], |i| {
                let t = &m.tri[i];
                let (a, b, d) = (t[0] as usize, t[1] as usize, t[2] as usize);
                // SAFETY: constraints of one colour touch disjoint vertices, and constraint i
                // alone owns lambda[i].
                unsafe {
                    let x = [p.get(a), p.get(b), p.get(d)];
                    let (energy, grad) = gather_membrane(m, i, x, c);
                    let inv = m.inv_mass[i];
                    let mut corr = [Vec3::ZERO; 3];
                    match c.solver {
                        SolverKind::Xpbd => {
                            let l = lambda.get(i);
                            // At rest when sqrt(2 ψ) < 1e-6 (a strain of about 1e-6).
                            let min_c2 = 1e-12 * m.area[i];
                            let dl =
                                xpbd_energy_correction(energy, &grad, &inv, c.alpha_membrane, l, min_c2, &mut corr);
                            if dl == 0.0 {
                                return;
                            }
                            lambda.set(i, l + dl);
                        }
                        SolverKind::Pbd | SolverKind::PbdDistance => {
                            if !pbd_energy_correction(energy, &grad, &inv, 1.0, &mut corr) {
                                return;
                            }
                        }
                    }
                    add_compensated(&p, &lo, a, x[0], corr[0]);
                    add_compensated(&p, &lo, b, x[1], corr[1]);
                    add_compensated(&p, &lo, d, x[2], corr[2]);
                }
            });
        }
    }

    pub(super) fn project_edges(&mut self, parallel: bool) {
        let e = &self.edges;
        let w = &self.inv_mass;
        let p = Shared::new(&mut self.p);
        let lo = Shared::new(&mut self.p_lo);
        for colour in e.colours.windows(2) {
            for_range(parallel, colour[0], colour[1], |i| {
                let (a, b) = (e.idx[i][0] as usize, e.idx[i][1] as usize);
                // SAFETY: edges of one colour touch disjoint vertices.
                unsafe {
                    let (xa, xb) = (p.get(a), p.get(b));
                    if let Some((da, db)) = distance_correction(xa, xb, w[a], w[b], e.rest[i]) {
                        add_compensated(&p, &lo, a, xa, da);
                        add_compensated(&p, &lo, b, xb, db);
                    }
                }
            });
        }
    }

    /// Rest-preserving bending: carries each stencil's rest vector by its frame at the start of
    /// the substep (after prediction); the iterations then hold it (SPEC 1.4: R is the stencil's
    /// rotation, held fixed while the gradient is taken).
    pub(super) fn update_bending_targets(&mut self, parallel: bool) {
        let s = &mut self.bendings;
        if s.target.is_empty() {
            return;
        }
        let (p, idx, rest) = (&self.p, &s.idx, &s.rest_local);
        let target = Shared::new(&mut s.target);
        for_range(parallel, 0, idx.len(), |i| {
            let t = &idx[i];
            let x = [p[t[0] as usize], p[t[1] as usize], p[t[2] as usize], p[t[3] as usize]];
            // SAFETY: each iteration writes only target[i].
            unsafe { target.set(i, bending_target(&x, rest[i])) };
        });
    }

    /// Bending stencils four at a time (SSE lanes): a colour's stencils are independent, so
    /// groups of four consecutive ones are solved together; the last group of a colour repeats
    /// its last stencil in the unused lanes, which are never written back.
    pub(super) fn project_bendings(&mut self, c: &Coefficients, parallel: bool) {
        let s = &self.bendings;
        let p = Shared::new(&mut self.p);
        let lo = Shared::new(&mut self.p_lo);
        let lambda = Shared::new(&mut self.lambda_bending);
        let xpbd = c.solver == SolverKind::Xpbd;
        for colour in s.colours.windows(2) {
            let (start, end) = (colour[0], colour[1]);
            for_range_min(parallel, 0, (end - start).div_ceil(4), MIN_PARALLEL / 4, |g| {
                let base = start + 4 * g;
                let real = (end - base).min(4);
                let last = real - 1;
                let lanes: [usize; 4] = [base, base + 1.min(last), base + 2.min(last), base + 3.min(last)];
                let id = |j: usize| {
                    let t = &s.idx[lanes[j]];
                    [t[0] as usize, t[1] as usize, t[2] as usize, t[3] as usize]
                };
                let idx = [id(0), id(1), id(2), id(3)];
                // SAFETY: stencils of one colour touch disjoint vertices; lambda[i] is i's. The
                // padding lanes read the last real stencil again and are not written.
                unsafe {
                    let vertex =
                        |k: usize| W3::gather([p.get(idx[0][k]), p.get(idx[1][k]), p.get(idx[2][k]), p.get(idx[3][k])]);
                    let x = [vertex(0), vertex(1), vertex(2), vertex(3)];
                    let (k0, k1, k2, k3) = (&s.k[lanes[0]], &s.k[lanes[1]], &s.k[lanes[2]], &s.k[lanes[3]]);
                    let kk = [
                        Vec4::new(k0[1], k1[1], k2[1], k3[1]),
                        Vec4::new(k0[2], k1[2], k2[2], k3[2]),
                        Vec4::new(k0[3], k1[3], k2[3], k3[3]),
                    ];
                    let lane4 = |a: &[f32]| Vec4::new(a[lanes[0]], a[lanes[1]], a[lanes[2]], a[lanes[3]]);
                    let q = lane4(&s.q);
                    let wk2 = lane4(&s.wk2);
                    let held = c.keep_rest.then(|| {
                        let t = &s.target;
                        W3::gather([t[lanes[0]], t[lanes[1]], t[lanes[2]], t[lanes[3]]])
                    });
                    let target = match &held {
                        Some(t) => WideTarget::Fixed(t),
                        None => WideTarget::Flat,
                    };
                    let lam = if xpbd {
                        Vec4::new(
                            lambda.get(lanes[0]),
                            lambda.get(lanes[1]),
                            lambda.get(lanes[2]),
                            lambda.get(lanes[3]),
                        )
                    } else {
                        Vec4::ZERO
                    };
                    // SPEC 1.4 with W = kB E t (A0+A1)/2 · E_B (XPBD): bending as stiff as
                    // stretching over one stencil when kB = 1. The paper's PBD form scales the
                    // correction by kB instead (as Bender's library does).
                    let alpha = (Vec4::ONE / (Vec4::splat(c.bending_scale) * (Vec4::splat(1.5) / q)))
                        .min(Vec4::splat(f32::MAX));
                    let (v, scale, dlambda, active) = bending_projection_wide(
                        &x,
                        kk,
                        target,
                        q,
                        wk2,
                        xpbd.then_some((alpha, lam)),
                        c.bending_coefficient,
                        1e-7,
                    );
                    for j in 0..real {
                        if active & (1 << j) == 0 {
                            continue;
                        }
                        let i = lanes[j];
                        if xpbd {
                            lambda.set(i, lam[j] + dlambda[j]);
                        }
                        let (vj, sj, wk) = (v.lane(j), scale[j], &s.wk[i]);
                        for k in 0..4 {
                            add_compensated(&p, &lo, idx[j][k], x[k].lane(j), vj * (wk[k] * sj));
                        }
                    }
                }
            });
        }
    }

    pub(super) fn project_anisotropics(&mut self, c: &Coefficients, parallel: bool) {
        let Some(s) = &self.anisotropics else { return };
        let w = &self.inv_mass;
        let p = Shared::new(&mut self.p);
        let lo = Shared::new(&mut self.p_lo);
        let lambda = Shared::new(&mut self.lambda_aniso);
        for colour in s.colours.windows(2) {
            for_range(parallel, colour[0], colour[1], |i| {
                let t = &s.tri[i];
                let (a, b, d) = (t[0] as usize, t[1] as usize, t[2] as usize);
                // SAFETY: constraints of one colour touch disjoint vertices; lambda[i] is i's.
                unsafe {
                    let x = [p.get(a), p.get(b), p.get(d)];
                    let (energy, mut grad, params) = gather_aniso(s, i, x);
                    // SPEC 1.5: every vertex gradient gets + k_A n (outward unit normal), so the
                    // correction moves the region inwards. k_A is scaled by √A0 so that it acts
                    // the same at any mesh scale (the gradient of A0 ψ scales with a length).
                    let n = (x[1] - x[0]).cross(x[2] - x[0]).normalize_or_zero();
                    let push = n * (params.inward_push * s.area[i].sqrt());
                    for g in &mut grad {
                        *g += push;
                    }
                    let inv = [w[a], w[b], w[d]];
                    let mut corr = [Vec3::ZERO; 3];
                    match c.solver {
                        SolverKind::Xpbd => {
                            let alpha = (1.0 / (params.stiffness * c.aniso_scale)).min(f32::MAX);
                            let l = lambda.get(i);
                            let min_c2 = 1e-12 * s.area[i];
                            let dl = xpbd_energy_correction(energy, &grad, &inv, alpha, l, min_c2, &mut corr);
                            if dl == 0.0 {
                                return;
                            }
                            lambda.set(i, l + dl);
                        }
                        SolverKind::Pbd | SolverKind::PbdDistance => {
                            if !pbd_energy_correction(energy, &grad, &inv, 1.0, &mut corr) {
                                return;
                            }
                        }
                    }
                    add_compensated(&p, &lo, a, x[0], corr[0]);
                    add_compensated(&p, &lo, b, x[1], corr[1]);
                    add_compensated(&p, &lo, d, x[2], corr[2]);
                }
            });
        }
    }
}
