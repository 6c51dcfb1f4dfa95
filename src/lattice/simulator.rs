//! The lattice simulator's state and the edits a caller makes between steps: pins, external
//! forces, positions (SPEC 3). The step itself is in `step.rs`.
//!
//! State is per site (holes included, holding zeros), so the box sums need no index maps.
//! Positions and velocities are f64: region sums subtract large, nearly equal numbers, and the
//! rigid-motion test (a rotated sheet reproduced exactly) needs the extra digits. Storage for
//! pins, forces and damping exists only once a scene uses them (SPEC 5).

use super::damping::{DAMPING_FIT_CHANNELS, DAMPING_MOMENT_CHANNELS};
use super::layout::LatticeLayout;
use super::matching::{FIT_CHANNELS, IDENTITY_COLUMNS, MOMENT_CHANNELS, RegionRest, RotationColumns};
use super::params::LatticeParams;
use super::step::{FitScratch, POSITION_LIMIT, UpdateBlock, ring_rows};
use super::summation::{box_sum, row_block};
use crate::error::{Error, Result};
use crate::parallel::WorkerPool;

/// What one step did (SPEC 4: the lattice's error measure is the mean distance to the goals).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepStats {
    /// Steps completed, this one included.
    pub step: u64,
    /// Simulated time after this step, s.
    pub time: f64,
    /// Mean over all particles of `|g - x|` at the start of the step, m.
    pub goal_distance: f64,
    /// Largest `|g - x|` at the start of the step, m.
    pub max_goal_distance: f64,
    /// Kinetic energy after the step, J.
    pub kinetic_energy: f64,
    /// Wall time of the step, s.
    pub step_seconds: f64,
}

/// A FastLSM elastic lattice surface.
pub struct Lattice {
    pub(super) params: LatticeParams,
    pub(super) layout: LatticeLayout,
    pub(super) rest: Vec<RegionRest>,
    pub(super) x: Vec<[f64; 3]>,
    pub(super) v: Vec<[f64; 3]>,
    pub(super) x_next: Vec<[f64; 3]>,
    pub(super) v_next: Vec<[f64; 3]>,
    /// Each region's rotation (the polar warm start), and the one being computed.
    pub(super) rotation: Vec<RotationColumns>,
    pub(super) rotation_next: Vec<RotationColumns>,
    pub(super) pinned: Option<Vec<bool>>,
    pub(super) force: Option<Vec<[f64; 3]>>,
    /// Scratch: per worker thread, the fit pass's rows ([`FitScratch`]: a ring of `2w + 2` rows
    /// of particle moments summed along x, ...).
    pub(super) fit_scratch: Vec<FitScratch>,
    /// Scratch: per block of rows, its share of the update pass's statistics and its z window.
    pub(super) update_blocks: Vec<UpdateBlock>,
    /// Scratch: what each region hands back to its particles, summed along x.
    pub(super) spread: Vec<f64>,
    pub(super) steps: u64,
    pub(super) time: f64,
    pub(super) pool: WorkerPool,
}

impl std::fmt::Debug for Lattice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Lattice").field("params", &self.params).field("steps", &self.steps).finish_non_exhaustive()
    }
}

impl Lattice {
    /// A lattice at rest in the x-z plane; `mask` as [`LatticeLayout::new`].
    pub fn new(params: LatticeParams, mask: Option<&[u8]>) -> Result<Self> {
        params.validate()?;
        let layout = LatticeLayout::new(params.columns, params.rows, params.spacing, mask)?;
        let pool = WorkerPool::new(params.threads)?;
        let (columns, rows) = (layout.columns(), layout.rows());
        let n = layout.site_count();
        let w = params.region_half_width as usize;

        // |R_s|: the particles in the box around s (exact: sums of ones).
        let ones: Vec<f64> = (0..n).map(|s| if layout.is_particle(s) { 1.0 } else { 0.0 }).collect();
        let counts = box_sum(&ones, columns, rows, 1, w);
        drop(ones);
        let mass = params.particle_mass as f64;
        let mut weighted = vec![0.0; n * 3];
        for s in 0..n {
            if layout.is_particle(s) {
                let share = mass / counts[s];
                let x0 = layout.centred_rest(s % columns, s / columns);
                weighted[s * 3..s * 3 + 3].copy_from_slice(&[share, share * x0[0], share * x0[1]]);
            }
        }
        // SPEC 3: M_r = sum m~, c0_r = sum m~ x0 / M_r.
        let sums = box_sum(&weighted, columns, rows, 3, w);
        let rest: Vec<RegionRest> = (0..n)
            .map(|s| {
                if !layout.is_particle(s) {
                    return RegionRest::default();
                }
                let m = sums[s * 3];
                RegionRest {
                    share: weighted[s * 3],
                    inv_count: 1.0 / counts[s],
                    mass: m,
                    c0: [sums[s * 3 + 1] / m, sums[s * 3 + 2] / m],
                }
            })
            .collect();
        let x: Vec<[f64; 3]> =
            (0..n).map(|s| if layout.is_particle(s) { layout.rest_position(s) } else { [0.0; 3] }).collect();
        let damping = params.damping > 0.0;
        let moment_channels = MOMENT_CHANNELS + if damping { DAMPING_MOMENT_CHANNELS } else { 0 };
        let fit_channels = FIT_CHANNELS + if damping { DAMPING_FIT_CHANNELS } else { 0 };
        Ok(Self {
            params,
            rest,
            v: vec![[0.0; 3]; n],
            x_next: x.clone(),
            v_next: vec![[0.0; 3]; n],
            x,
            rotation: vec![IDENTITY_COLUMNS; n],
            rotation_next: vec![IDENTITY_COLUMNS; n],
            pinned: None,
            force: None,
            // Sized here, so that a step allocates nothing.
            fit_scratch: (0..pool.threads())
                .map(|_| FitScratch {
                    ring: vec![0.0; ring_rows(w, rows) * columns * moment_channels],
                    fits: vec![0.0; columns * fit_channels],
                    q: vec![0.0; columns * moment_channels],
                    acc: vec![0.0; columns * moment_channels],
                })
                .collect(),
            update_blocks: vec![UpdateBlock::with_window(columns * fit_channels); rows.div_ceil(row_block(w, rows))],
            spread: vec![0.0; n * fit_channels],
            steps: 0,
            time: 0.0,
            pool,
            layout,
        })
    }

    /// The settings.
    pub fn params(&self) -> &LatticeParams {
        &self.params
    }

    /// The lattice layout (numbering, mask, triangles).
    pub fn layout(&self) -> &LatticeLayout {
        &self.layout
    }

    /// Number of particles.
    pub fn particle_count(&self) -> usize {
        self.layout.particle_count()
    }

    /// Steps completed.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Pins the particle at (column, row): it keeps its position and has zero velocity (infinite
    /// mass) until unpinned. Its position still shapes its regions.
    pub fn pin(&mut self, column: u32, row: u32, pinned: bool) -> Result<()> {
        let p = self.layout.particle(column, row)?;
        let site = self.layout.site_of_particle(p);
        if self.pinned.is_none() && !pinned {
            return Ok(());
        }
        let n = self.layout.site_count();
        let flags = self.pinned.get_or_insert_with(|| vec![false; n]);
        flags[site] = pinned;
        if pinned {
            self.v[site] = [0.0; 3];
        }
        Ok(())
    }

    /// True when (column, row) is a pinned particle.
    pub fn is_pinned(&self, site: usize) -> bool {
        self.pinned.as_ref().is_some_and(|p| p[site])
    }

    /// Adds `force` (N) to the particle at (column, row) for the next step only; forces added
    /// before one step accumulate.
    pub fn apply_force(&mut self, column: u32, row: u32, force: [f32; 3]) -> Result<()> {
        let p = self.layout.particle(column, row)?;
        let site = self.layout.site_of_particle(p);
        if let Some(axis) = force.iter().position(|f| !f.is_finite()) {
            return Err(Error::invalid_argument(format!("`force`[{axis}] = {} is not finite", force[axis])));
        }
        let n = self.layout.site_count();
        let forces = self.force.get_or_insert_with(|| vec![[0.0; 3]; n]);
        for k in 0..3 {
            forces[site][k] += force[k] as f64;
        }
        Ok(())
    }

    /// Drops the forces given since the last step (what an UNSTABLE step left pending).
    pub fn clear_forces(&mut self) {
        if let Some(f) = self.force.as_mut() {
            f.fill([0.0; 3]);
        }
    }

    /// Sets every particle's position from `positions` (x, y, z per particle, in particle order).
    /// Velocities are kept. Nothing changes if the length is wrong or a value is not finite or
    /// beyond ±[`POSITION_LIMIT`] (a step would take such a position for divergence).
    pub fn set_positions(&mut self, positions: &[f32]) -> Result<()> {
        let count = self.particle_count();
        if positions.len() != 3 * count {
            return Err(Error::invalid_argument(format!(
                "`positions` holds {} floats but the lattice has {count} particles (3 floats each = {})",
                positions.len(),
                3 * count
            )));
        }
        if let Some(i) = positions.iter().position(|v| !v.is_finite() || v.abs() as f64 > POSITION_LIMIT) {
            return Err(Error::invalid_argument(format!(
                "`positions`[{i}] (particle {}) = {} must be finite and within ±{POSITION_LIMIT:e} m",
                i / 3,
                positions[i]
            )));
        }
        for p in 0..count {
            let site = self.layout.site_of_particle(p);
            self.x[site] = [positions[3 * p] as f64, positions[3 * p + 1] as f64, positions[3 * p + 2] as f64];
        }
        Ok(())
    }

    /// Writes each particle's value of a per-site array, as f32 triples, in particle order.
    fn copy_particles(&self, values: &[[f64; 3]], out: &mut [f32]) {
        for (p, chunk) in out.chunks_exact_mut(3).enumerate() {
            let value = values[self.layout.site_of_particle(p)];
            chunk.copy_from_slice(&value.map(|c| c as f32));
        }
    }

    /// Positions (x, y, z per particle, particle order) into `out` (3 * particle_count floats).
    pub fn copy_positions(&self, out: &mut [f32]) {
        self.copy_particles(&self.x, out);
    }

    /// Velocities (m/s) into `out`, as [`Self::copy_positions`].
    pub fn copy_velocities(&self, out: &mut [f32]) {
        self.copy_particles(&self.v, out);
    }

    /// The current goal positions (SPEC 3) into `out`, as [`Self::copy_positions`].
    pub fn copy_goals(&self, out: &mut [f32]) {
        let goals = self.goals();
        self.copy_particles(&goals, out);
    }

    /// Positions of every site in f64 (holes hold zeros); for tests and benches.
    pub fn site_positions(&self) -> &[[f64; 3]] {
        &self.x
    }

    /// Heap bytes held by the simulator (its worker threads' stacks are not counted).
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        let v3 = size_of::<[f64; 3]>();
        self.layout.memory_bytes()
            + self.rest.capacity() * size_of::<RegionRest>()
            + (self.x.capacity() + self.v.capacity() + self.x_next.capacity() + self.v_next.capacity()) * v3
            + (self.rotation.capacity() + self.rotation_next.capacity()) * size_of::<RotationColumns>()
            + self.pinned.as_ref().map_or(0, |p| p.capacity())
            + self.force.as_ref().map_or(0, |f| f.capacity() * v3)
            + self.fit_scratch.iter().map(FitScratch::memory_bytes).sum::<usize>()
            + self.spread.capacity() * size_of::<f64>()
            + self.fit_scratch.capacity() * size_of::<FitScratch>()
            + self.update_blocks.iter().map(UpdateBlock::memory_bytes).sum::<usize>()
            + (self.update_blocks.capacity() - self.update_blocks.len()) * size_of::<UpdateBlock>()
            + self.pool.memory_bytes()
    }
}
