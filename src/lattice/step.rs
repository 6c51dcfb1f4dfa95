//! One FastLSM step (SPEC 3), parallel over rows on the lattice's own worker pool.
//!
//! ```text
//! 1. moments:  per particle [m~ x', m~ x' x0^T (+ damping moments)], summed along x
//! 2. fit:      summed along z; per region c, A, R = polar(A), t
//! 3. spread:   per region [R e_x, R e_z, t (+ rigid motion)], summed along x
//!              (1-3 fused per block of rows, in parallel over blocks: the moments of a block
//!              live only in a small ring of rows, so they never leave the cache)
//! 4. update:   summed along z (row blocks in parallel); per particle goal g and
//!              v += damping (v_rigid - v);  v = keep v + alpha (g - x)/h + h (gravity + f/m);  x += h v
//!              (keep = 1 - velocity_damping h)
//! ```
//! Rows and row blocks are fixed units of work and every reduction runs in block order, so the
//! result is bit-identical whatever the thread count. The update writes into the `_next`
//! buffers; they replace the state only when every value is finite and sane, so a diverging step
//! is rolled back by not swapping (SPEC 4).

use std::time::Instant;

use glam::DVec3;

use super::damping::{
    DAMPING_FIT_CHANNELS, DAMPING_MOMENT_CHANNELS, damping_moments, region_rigid_motion, rigid_velocity,
};
use super::layout::LatticeLayout;
use super::matching::{
    FIT_CHANNELS, MOMENT_CHANNELS, RegionRest, RotationColumns, fit_channels, fit_region, goal, particle_moments,
};
use super::params::LatticeParams;
use super::simulator::{Lattice, StepStats};
use super::summation::{RowWindow, add_row, row_block, running_sum_row, shift_rows};
use crate::error::{Error, ErrorKind, Result};
use crate::parallel::{SharedSlice, WorkerPool};

/// Positions beyond this (m) count as diverged: far past anything physical, and still far
/// inside f32 range, so what a caller copies out is always finite (and a goal distance, at most
/// a few times this, too).
pub(crate) const POSITION_LIMIT: f64 = 1e15;

/// Speeds beyond this (m/s) count as diverged. Far above [`POSITION_LIMIT`]: a step moves a
/// particle by `alpha (g - x)` towards its goal whatever h is, at a speed of `alpha |g - x| / h`,
/// so with a short step or a large shape a stable step is fast (a crumpled sheet 1e14 m wide at
/// h = 1/60 s was taken for divergence at 1e15, with the advice of a shorter step that made it
/// worse; found by review): with positions within [`POSITION_LIMIT`] and steps of at least 1e-6 s
/// a stable step stays below about 1e22 m/s. Still far inside f32 range.
const SPEED_LIMIT: f64 = 1e30;

/// What the passes read.
struct Passes<'a> {
    layout: &'a LatticeLayout,
    rest: &'a [RegionRest],
    w: usize,
    damping: bool,
    moment_channels: usize,
    fit_channels: usize,
    origin: [f64; 3],
}

impl<'a> Passes<'a> {
    fn new(layout: &'a LatticeLayout, rest: &'a [RegionRest], params: &LatticeParams, x: &[[f64; 3]]) -> Self {
        let damping = params.damping > 0.0;
        let origin = x[layout.site_of_particle(0)];
        Self {
            layout,
            rest,
            w: params.region_half_width as usize,
            damping,
            moment_channels: MOMENT_CHANNELS + if damping { DAMPING_MOMENT_CHANNELS } else { 0 },
            fit_channels: FIT_CHANNELS + if damping { DAMPING_FIT_CHANNELS } else { 0 },
            origin,
        }
    }

    #[inline]
    fn relative(&self, x: [f64; 3]) -> [f64; 3] {
        [x[0] - self.origin[0], x[1] - self.origin[1], x[2] - self.origin[2]]
    }

    /// The particle moments of one row, summed along x, into `out` (`moment_channels` per
    /// site); `q` is scratch of the same size.
    fn moment_row(&self, row: usize, x: &[[f64; 3]], v: &[[f64; 3]], q: &mut [f64], out: &mut [f64]) {
        let columns = self.layout.columns();
        let ch = self.moment_channels;
        q.fill(0.0);
        for c in 0..columns {
            let s = row * columns + c;
            let rest = &self.rest[s];
            if rest.share == 0.0 {
                continue;
            }
            let xp = self.relative(x[s]);
            let q = &mut q[c * ch..(c + 1) * ch];
            particle_moments(rest.share, xp, self.layout.centred_rest(c, row), &mut q[..MOMENT_CHANNELS]);
            if self.damping {
                damping_moments(rest.share, xp, v[s], &mut q[MOMENT_CHANNELS..]);
            }
        }
        running_sum_row(q, out, ch, self.w);
    }

    /// Passes 1 to 3 for each block of rows: particle moments summed along x (into a ring of
    /// `2w + 2` rows, one per worker, so they are used while in cache; a block also computes
    /// the `w` rows above and below it), summed along z; every region fitted; each row of fits summed
    /// along x at once (regions to particles, first direction). Writes the x-summed fit channels
    /// into `spread` and each region's rotation into `rotation_out`.
    #[allow(clippy::too_many_arguments)]
    fn fit(
        &self,
        pool: &WorkerPool,
        x: &[[f64; 3]],
        v: &[[f64; 3]],
        rotation: &[RotationColumns],
        scratch: &mut [FitScratch],
        spread: &mut [f64],
        rotation_out: &mut [RotationColumns],
    ) {
        let (columns, rows, w) = (self.layout.columns(), self.layout.rows(), self.w);
        let (mc, fc) = (self.moment_channels, self.fit_channels);
        let stride = columns * mc;
        let spacing_sq = self.layout.spacing() * self.layout.spacing();
        let cap = ring_rows(w, rows);
        let block_rows = row_block(w, rows);
        let blocks = rows.div_ceil(block_rows);
        assert!(spread.len() >= rows * columns * fc && rotation_out.len() >= rows * columns);
        let (spread_all, rotation_all) = (SharedSlice::new(spread), SharedSlice::new(rotation_out));
        // One ring per group of consecutive blocks, one group per worker. A block rebuilds its
        // ring from scratch, so which group it is in changes nothing in the result.
        let per_group = blocks.div_ceil(scratch.len().max(1));
        pool.for_each_chunk_mut(scratch, 1, |group, scratch| {
            let FitScratch { ring, fits, q, acc } = &mut scratch[0];
            fits.resize(columns * fc, 0.0);
            q.resize(stride, 0.0);
            acc.resize(stride, 0.0);
            for index in group * per_group..((group + 1) * per_group).min(blocks) {
                let k0 = index * block_rows;
                let k1 = (k0 + block_rows).min(rows);
                // SAFETY: the rows of block `index`, written by this group alone.
                let (spread, rotation_out) = unsafe {
                    (
                        spread_all.part(k0 * columns * fc..k1 * columns * fc),
                        rotation_all.part(k0 * columns..k1 * columns),
                    )
                };
                ring.resize(cap * stride, 0.0);
                let slot = |j: usize| (j % cap) * stride..(j % cap + 1) * stride;
                acc.fill(0.0);
                for j in k0.saturating_sub(w)..=(k0 + w).min(rows - 1) {
                    self.moment_row(j, x, v, q, &mut ring[slot(j)]);
                    add_row(acc, &ring[slot(j)]);
                }
                for k in k0..k1 {
                    for c in 0..columns {
                        let s = k * columns + c;
                        let out = &mut fits[c * fc..(c + 1) * fc];
                        let rest = &self.rest[s];
                        if rest.share == 0.0 {
                            out.fill(0.0);
                            rotation_out[s - k0 * columns] = rotation[s];
                            continue;
                        }
                        let sums = &acc[c * mc..(c + 1) * mc];
                        // Singular values of A scale as M (w h)^2; far below that, A is zero.
                        let tiny = 1e-12 * rest.mass * spacing_sq;
                        let (rot, t, centroid) = fit_region(&sums[..MOMENT_CHANNELS], rest, &rotation[s], tiny);
                        fit_channels(&rot, t, &mut out[..FIT_CHANNELS]);
                        rotation_out[s - k0 * columns] = rot;
                        if self.damping {
                            region_rigid_motion(
                                &sums[MOMENT_CHANNELS..],
                                rest.mass,
                                centroid,
                                &mut out[FIT_CHANNELS..],
                            );
                        }
                    }
                    let local_row = (k - k0) * columns * fc;
                    running_sum_row(fits, &mut spread[local_row..local_row + columns * fc], fc, w);
                    if k + 1 == k1 {
                        break;
                    }
                    // The z running sum: B(k+1) = B(k) + row(k+w+1) - row(k-w).
                    let entering = k + w + 1 < rows;
                    if entering {
                        self.moment_row(k + w + 1, x, v, q, &mut ring[slot(k + w + 1)]);
                    }
                    let ring = &ring[..];
                    shift_rows(acc, entering.then(|| &ring[slot(k + w + 1)]), (k >= w).then(|| &ring[slot(k - w)]));
                }
            }
        });
    }
}

/// Rows in a block's ring of x-summed moments: the `2w + 1` rows of the z window plus the one
/// entering, or all rows when there are fewer.
pub(super) fn ring_rows(w: usize, rows: usize) -> usize {
    (2 * w + 2).min(rows)
}

/// A worker's scratch of the fit pass, kept between steps (made per step, they were
/// allocations every step): the ring of `2w + 2` rows of particle moments summed along x, one
/// row of fits, and a row's particle moments and their running z sums.
#[derive(Clone, Debug, Default)]
pub(super) struct FitScratch {
    pub ring: Vec<f64>,
    pub fits: Vec<f64>,
    pub q: Vec<f64>,
    pub acc: Vec<f64>,
}

impl FitScratch {
    pub fn memory_bytes(&self) -> usize {
        (self.ring.capacity() + self.fits.capacity() + self.q.capacity() + self.acc.capacity())
            * std::mem::size_of::<f64>()
    }
}

/// One block of rows of the update pass: its share of the statistics and the buffer of its z
/// window (kept between steps).
#[derive(Clone, Debug, Default)]
pub(super) struct UpdateBlock {
    distance_sum: f64,
    distance_max: f64,
    kinetic: f64,
    diverged: Option<(usize, &'static str, f64)>,
    window: Vec<f64>,
}

impl UpdateBlock {
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>() + self.window.capacity() * std::mem::size_of::<f64>()
    }

    /// Statistics of 0 and a window buffer of `len` values.
    pub fn with_window(len: usize) -> Self {
        Self { window: vec![0.0; len], ..Self::default() }
    }

    fn reset(&mut self) {
        (self.distance_sum, self.distance_max, self.kinetic, self.diverged) = (0.0, 0.0, 0.0, None);
    }
}

impl Lattice {
    /// Advances the lattice by one time step (SPEC 3). On divergence (a non-finite value, or a
    /// position or speed beyond 1e15) the state is left as it was before the call and an
    /// `Unstable` error says which particle blew up and what would be stable.
    pub fn step(&mut self) -> Result<StepStats> {
        let start = Instant::now();
        let passes = Passes::new(&self.layout, &self.rest, &self.params, &self.x);
        let (columns, rows) = (self.layout.columns(), self.layout.rows());
        let n = self.layout.site_count();
        let fc = passes.fit_channels;
        passes.fit(
            &self.pool,
            &self.x,
            &self.v,
            &self.rotation,
            &mut self.fit_scratch,
            &mut self.spread,
            &mut self.rotation_next,
        );
        let spread = &self.spread[..n * fc];

        let h = self.params.time_step as f64;
        let alpha = self.params.stiffness as f64;
        let damping = self.params.damping as f64;
        let keep = (1.0 - self.params.velocity_damping as f64 * self.params.time_step as f64).max(0.0);
        let mass = self.params.particle_mass as f64;
        let gravity = DVec3::from(self.params.gravity.map(|g| g as f64));
        let (x, v) = (&self.x, &self.v);
        let pinned = self.pinned.as_deref();
        let force = self.force.as_deref();
        let block_rows = row_block(passes.w, rows);
        let blocks = rows.div_ceil(block_rows);
        self.update_blocks.resize(blocks, UpdateBlock::default());
        self.update_blocks.iter_mut().for_each(UpdateBlock::reset);
        let (x_next, v_next) = (SharedSlice::new(&mut self.x_next), SharedSlice::new(&mut self.v_next));
        let passes = &passes;
        self.pool.for_each_chunk_mut(&mut self.update_blocks, 1, |index, block| {
            for b in block.iter_mut() {
                let k0 = index * block_rows;
                let rows_of_block = k0 * columns..(k0 + block_rows).min(rows) * columns;
                // SAFETY: the sites of block `index`, written by this task alone.
                let (new_x, new_v) = unsafe { (x_next.part(rows_of_block.clone()), v_next.part(rows_of_block)) };
                let mut window = RowWindow::new(spread, columns * fc, rows, passes.w, k0, &mut b.window);
                for k in k0..(k0 + block_rows).min(rows) {
                    let sums_row = window.current();
                    for c in 0..columns {
                        let s = k * columns + c;
                        let local = s - k0 * columns;
                        let rest = &passes.rest[s];
                        if rest.share == 0.0 {
                            new_x[local] = x[s];
                            new_v[local] = v[s];
                            continue;
                        }
                        let sums = &sums_row[c * fc..(c + 1) * fc];
                        let xp = passes.relative(x[s]);
                        let g = goal(&sums[..FIT_CHANNELS], passes.layout.centred_rest(c, k), rest.inv_count);
                        let to_goal = DVec3::from(g) - DVec3::from(xp);
                        let distance = to_goal.length();
                        b.distance_sum += distance;
                        b.distance_max = b.distance_max.max(distance);
                        if pinned.is_some_and(|p| p[s]) {
                            new_x[local] = x[s];
                            new_v[local] = [0.0; 3];
                            continue;
                        }
                        let mut vel = DVec3::from(v[s]);
                        if passes.damping {
                            let rigid = rigid_velocity(&sums[FIT_CHANNELS..], xp, rest.inv_count);
                            vel += (rigid - vel) * damping;
                        }
                        // SPEC 3: v += alpha (g - x)/h + h f_ext/m;  x += h v.
                        let mut accel = gravity;
                        if let Some(f) = force {
                            accel += DVec3::from(f[s]) / mass;
                        }
                        vel = vel * keep + to_goal * (alpha / h) + accel * h;
                        let moved = DVec3::from(x[s]) + vel * h;
                        b.kinetic += 0.5 * mass * vel.length_squared();
                        if b.diverged.is_none() {
                            let speed = vel.length();
                            let reach = moved.abs().max_element();
                            if !moved.is_finite() || reach > POSITION_LIMIT {
                                b.diverged = Some((s, "position", reach));
                            } else if speed.is_nan() || speed > SPEED_LIMIT {
                                b.diverged = Some((s, "speed", speed));
                            }
                        }
                        new_x[local] = moved.to_array();
                        new_v[local] = vel.to_array();
                    }
                    window.advance();
                }
            }
        });

        let particles = self.layout.particle_count() as f64;
        let mut stats = StepStats::default();
        let mut distance_sum = 0.0;
        for b in &self.update_blocks {
            if let Some((s, what, value)) = b.diverged {
                return Err(self.divergence_error(s, what, value));
            }
            distance_sum += b.distance_sum;
            stats.max_goal_distance = stats.max_goal_distance.max(b.distance_max);
            stats.kinetic_energy += b.kinetic;
        }
        if !stats.kinetic_energy.is_finite() {
            return Err(self.divergence_error(self.layout.site_of_particle(0), "kinetic energy", stats.kinetic_energy));
        }
        std::mem::swap(&mut self.x, &mut self.x_next);
        std::mem::swap(&mut self.v, &mut self.v_next);
        std::mem::swap(&mut self.rotation, &mut self.rotation_next);
        self.clear_forces();
        self.steps += 1;
        self.time = self.steps as f64 * h;
        stats.step = self.steps;
        stats.time = self.time;
        stats.goal_distance = distance_sum / particles;
        stats.step_seconds = start.elapsed().as_secs_f64();
        Ok(stats)
    }

    fn divergence_error(&self, site: usize, what: &str, value: f64) -> Error {
        let columns = self.layout.columns();
        let force = self.force.as_ref().map_or(0.0, |f| DVec3::from(f[site]).length());
        let limit = if what == "speed" { SPEED_LIMIT } else { POSITION_LIMIT };
        // The forces stay pending through the rollback: say how to drop them, or the next step
        // fails alike (found by review).
        let advice = if force > 0.0 {
            "drop the pending forces (softshell_lattice_clear_forces) and apply smaller ones"
        } else {
            "no force is pending on it: gravity or a position set far away drove it; use a smaller gravity or \
             time_step, or set positions nearer"
        };
        Error::new(
            ErrorKind::Unstable,
            format!(
                "the lattice step diverged: the {what} of particle (column {}, row {}) became {value:e} \
                 (limit {limit:e}); the step was rolled back, the forces given since the last step still \
                 pending. Shape matching itself is stable for stiffness in (0, 1]: the external force on it \
                 ({force:e} N on {} kg) or gravity drove it (time_step {} s); {advice}",
                site % columns,
                site / columns,
                self.params.particle_mass,
                self.params.time_step
            ),
        )
    }

    /// The goal of every site for the current positions (SPEC 3), world space (holes: zeros).
    /// Computed with the same passes as [`Lattice::step`], in fresh scratch buffers.
    pub fn goals(&self) -> Vec<[f64; 3]> {
        let passes = Passes::new(&self.layout, &self.rest, &self.params, &self.x);
        let (columns, rows) = (self.layout.columns(), self.layout.rows());
        let n = self.layout.site_count();
        let fc = passes.fit_channels;
        let mut rings = vec![FitScratch::default(); self.pool.threads()];
        let mut rotation_out = vec![[0.0; 6]; n];
        let mut spread = vec![0.0; n * fc];
        passes.fit(&self.pool, &self.x, &self.v, &self.rotation, &mut rings, &mut spread, &mut rotation_out);
        let mut goals = vec![[0.0; 3]; n];
        let block_rows = row_block(passes.w, rows);
        let mut window_sums = Vec::new();
        for k0 in (0..rows).step_by(block_rows) {
            let mut window = RowWindow::new(&spread, columns * fc, rows, passes.w, k0, &mut window_sums);
            for k in k0..(k0 + block_rows).min(rows) {
                for c in 0..columns {
                    let s = k * columns + c;
                    let rest = &passes.rest[s];
                    if rest.share == 0.0 {
                        continue;
                    }
                    let sums = &window.current()[c * fc..c * fc + FIT_CHANNELS];
                    let g = goal(sums, passes.layout.centred_rest(c, k), rest.inv_count);
                    goals[s] = [g[0] + passes.origin[0], g[1] + passes.origin[1], g[2] + passes.origin[2]];
                }
                window.advance();
            }
        }
        goals
    }
}
