//! What a step measures after its last iteration (SPEC 4): the energies and the residual.
//! Sums run in fixed chunks, so they do not depend on the thread count.

#![allow(clippy::needless_range_loop)]

use super::exec::{REDUCE_CHUNK, chunk_partials};
use super::project::{gather_aniso, membrane_energy_at, stencil_area};
use super::settings::{BendingKind, ShellSettings, SolverKind};
use super::simulator::{Coefficients, State};
use crate::solver::bending_residual;

impl State {
    /// Energies (J) and the residual after the last iteration: the largest relative constraint
    /// violation, |C + α̃ λ| for XPBD and |C| for PBD, with C = sqrt(2 Ŵ) made dimensionless
    /// (divided by √A0 for membrane and anisotropic constraints; bending's C already is).
    pub(super) fn measure(&mut self, settings: &ShellSettings, c: &Coefficients, parallel: bool) {
        let k = settings.youngs_modulus * settings.thickness;
        let xpbd = c.solver == SolverKind::Xpbd;
        let (x, m, lm) = (&self.x, &self.membranes, &self.lambda_membrane);
        let parts = &mut self.partials[..m.len().div_ceil(REDUCE_CHUNK)];
        chunk_partials(parallel, m.len(), parts, |s, e| {
            let (mut energy, mut residual) = (0.0f64, 0.0f64);
            for i in s..e {
                let (w, _) = membrane_energy_at(m, i, x, c);
                // In f64: k w can pass f32's range on a large mesh of a stiff material.
                energy += k as f64 * w as f64;
                let cval = (2.0 * w).max(0.0).sqrt();
                let r = if xpbd { cval + c.alpha_membrane * lm[i] } else { cval };
                residual = residual.max((r.abs() / m.area[i].sqrt()) as f64);
            }
            [energy, residual, 0.0]
        });
        let elastic = parts.iter().map(|s| s[0]).sum::<f64>();
        let mut residual = parts.iter().fold(0.0f64, |a, s| a.max(s[1]));
        if c.solver == SolverKind::PbdDistance {
            // The distance solver's own constraints: the largest relative edge-length error.
            let e = &self.edges;
            let parts = &mut self.partials[..e.len().div_ceil(REDUCE_CHUNK)];
            chunk_partials(parallel, e.len(), parts, |s, end| {
                let mut worst = 0.0f64;
                for i in s..end {
                    let [a, b] = e.idx[i];
                    let len = (x[b as usize] - x[a as usize]).length();
                    worst = worst.max(((len - e.rest[i]) / e.rest[i]).abs() as f64);
                }
                [worst, 0.0, 0.0]
            });
            residual = parts.iter().fold(0.0f64, |a, s| a.max(s[0]));
        }

        let mut bending = 0.0;
        if settings.bending != BendingKind::None {
            let (b, lb) = (&self.bendings, &self.lambda_bending);
            let parts = &mut self.partials[..b.len().div_ceil(REDUCE_CHUNK)];
            chunk_partials(parallel, b.len(), parts, |s, e| {
                let (mut energy, mut res) = (0.0f64, 0.0f64);
                for i in s..e {
                    let t = &b.idx[i];
                    let xs = [x[t[0] as usize], x[t[1] as usize], x[t[2] as usize], x[t[3] as usize]];
                    // The energy: the rest vector carried by the stencil's frame at these
                    // positions (SPEC 1.4).
                    let v = bending_residual(&xs, &b.k[i], c.keep_rest.then(|| b.rest_local[i]));
                    let w = 0.5 * b.q[i] * v.length_squared();
                    let stiffness = k * settings.bending_coefficient * stencil_area(b.q[i]);
                    energy += k as f64 * settings.bending_coefficient as f64 * stencil_area(b.q[i]) as f64 * w as f64;
                    // The residual: the constraint the iterations solve, whose target (the rest
                    // vector in the frame at the substep's start) they hold fixed. Measured
                    // against the frame at the end instead it stayed at 3.1e-5 on the sphere,
                    // from 5 to 1,000 iterations (a review), however well they converged.
                    let held = if c.keep_rest && !b.target.is_empty() {
                        bending_residual(&xs, &b.k[i], None) - b.target[i]
                    } else {
                        v
                    };
                    let cval = (b.q[i] * held.length_squared()).max(0.0).sqrt();
                    // α̃ as the projection clamps it, and α̃ λ in f64: with a tiny kB the
                    // stiffness h² underflows, and the division made the residual inf (a review).
                    let r = if xpbd && stiffness > 0.0 {
                        let h = settings.time_step / settings.substeps as f32;
                        let alpha = (1.0 / (stiffness * h * h)).min(f32::MAX);
                        cval as f64 + alpha as f64 * lb[i] as f64
                    } else {
                        cval as f64
                    };
                    res = res.max(r.abs());
                }
                [energy, res, 0.0]
            });
            bending = parts.iter().map(|s| s[0]).sum::<f64>();
            if settings.bending_coefficient > 0.0 {
                residual = residual.max(parts.iter().fold(0.0f64, |a, s| a.max(s[1])));
            }
        }

        let mut aniso = 0.0;
        if let Some(a) = &self.anisotropics {
            let la = &self.lambda_aniso;
            let parts = &mut self.partials[..a.len().div_ceil(REDUCE_CHUNK)];
            chunk_partials(parallel, a.len(), parts, |s, e| {
                let (mut energy, mut res) = (0.0f64, 0.0f64);
                for i in s..e {
                    let t = &a.tri[i];
                    let xs = [x[t[0] as usize], x[t[1] as usize], x[t[2] as usize]];
                    let (w, _, params) = gather_aniso(a, i, xs);
                    energy += params.stiffness as f64 * settings.thickness as f64 * w as f64;
                    let cval = (2.0 * w).max(0.0).sqrt();
                    // (α̃ clamped as the projection has it, α̃ λ in f64: see the bending above.)
                    let r = if xpbd {
                        let alpha = (1.0 / (params.stiffness * c.aniso_scale)).min(f32::MAX);
                        cval as f64 + alpha as f64 * la[i] as f64
                    } else {
                        cval as f64
                    };
                    res = res.max(r.abs() / a.area[i].sqrt() as f64);
                }
                [energy, res, 0.0]
            });
            aniso = parts.iter().map(|s| s[0]).sum::<f64>();
            residual = residual.max(parts.iter().fold(0.0f64, |acc, s| acc.max(s[1])));
        }
        self.stats.elastic_energy = elastic;
        self.stats.bending_energy = bending;
        self.stats.anisotropic_energy = aniso;
        self.stats.residual = residual;
    }
}
