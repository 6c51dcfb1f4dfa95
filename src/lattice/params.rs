//! The settings of a lattice and their validation (SPEC 3). Every message names the field, its
//! value and the valid range, so `softshell_last_error()` tells a C caller what to fix.

use crate::error::{Error, Result};

/// The settings of a [`super::Lattice`]; the C def `SoftshellLatticeDef` maps onto it field by field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LatticeParams {
    /// Particles along x.
    pub columns: u32,
    /// Particles along z.
    pub rows: u32,
    /// Distance between neighbouring particles at rest, m.
    pub spacing: f32,
    /// Region half-width w >= 1: a region is the (2w+1)^2 box of sites around its particle.
    pub region_half_width: u32,
    /// alpha in (0, 1]: the fraction of the way to the goal a particle is pulled per step.
    pub stiffness: f32,
    /// Region damping in [0, 1]: the fraction of each particle's non-rigid velocity removed per step.
    pub damping: f32,
    /// Time step h, s.
    pub time_step: f32,
    /// Viscous damping of all motion, 1/s: every step `v *= max(0, 1 - velocity_damping h)`.
    /// Region damping leaves rigid motion of regions alone, so the long, slow modes of a sheet
    /// (a hanging sheet bouncing) need this to come to rest.
    pub velocity_damping: f32,
    /// Mass of each particle, kg.
    pub particle_mass: f32,
    /// Gravity, m/s^2.
    pub gravity: [f32; 3],
    /// Worker threads: 0 = one per core, 1 = serial.
    pub threads: u32,
}

/// Lattices larger than this many sites are refused (indices are 32-bit, and the state takes
/// a few hundred bytes a site).
pub(crate) const MAX_SITES: u64 = 1 << 26;

impl Default for LatticeParams {
    fn default() -> Self {
        Self {
            columns: 32,
            rows: 32,
            spacing: 0.05,
            region_half_width: 2,
            stiffness: 0.5,
            damping: 0.2,
            time_step: 1.0 / 60.0,
            velocity_damping: 0.5,
            particle_mass: 0.01,
            gravity: [0.0, -9.81, 0.0],
            threads: 1,
        }
    }
}

fn positive(name: &str, value: f32, max: f32, why: &str) -> Result<()> {
    if !value.is_finite() || value <= 0.0 || value > max {
        return Err(Error::invalid_argument(format!("`{name}` = {value} must be finite, > 0 and at most {max}{why}")));
    }
    Ok(())
}

/// The shortest time step, s.
const MIN_TIME_STEP: f32 = 1e-6;

impl LatticeParams {
    /// Checks every field; the first bad one is named in the error.
    pub fn validate(&self) -> Result<()> {
        if self.columns == 0 || self.rows == 0 {
            return Err(Error::invalid_argument(format!(
                "`columns` = {} and `rows` = {} must both be at least 1",
                self.columns, self.rows
            )));
        }
        let sites = self.columns as u64 * self.rows as u64;
        if sites > MAX_SITES {
            return Err(Error::invalid_argument(format!(
                "`columns` x `rows` = {} x {} = {sites} sites is more than the maximum {MAX_SITES}",
                self.columns, self.rows
            )));
        }
        positive("spacing", self.spacing, 1e6, " (m)")?;
        if self.region_half_width == 0 {
            return Err(Error::invalid_argument(
                "`region_half_width` = 0 must be at least 1: a region of one particle has no shape to match",
            ));
        }
        if !self.stiffness.is_finite() || self.stiffness <= 0.0 || self.stiffness > 1.0 {
            return Err(Error::invalid_argument(format!(
                "`stiffness` (alpha) = {} must be in (0, 1]: 0 would never pull particles back, above 1 overshoots the goals",
                self.stiffness
            )));
        }
        if !self.damping.is_finite() || !(0.0..=1.0).contains(&self.damping) {
            return Err(Error::invalid_argument(format!("`damping` = {} must be finite and in [0, 1]", self.damping)));
        }
        // Not shorter (as the other simulators): a step moves a particle by `alpha (g - x)` at a
        // speed of `alpha |g - x| / h`, and far shorter steps made stable speeds beyond any
        // divergence limit (a review saw 4e30 m/s at h = 1e-33 s).
        if !self.time_step.is_finite() || !(MIN_TIME_STEP..=1.0).contains(&self.time_step) {
            return Err(Error::invalid_argument(format!(
                "`time_step` = {} must be finite and in [{MIN_TIME_STEP:e}, 1] s",
                self.time_step
            )));
        }
        if !self.velocity_damping.is_finite() || self.velocity_damping < 0.0 || self.velocity_damping > 1e6 {
            return Err(Error::invalid_argument(format!(
                "`velocity_damping` = {} must be finite and in [0, 1e6] (1/s)",
                self.velocity_damping
            )));
        }
        positive("particle_mass", self.particle_mass, 1e12, " kg")?;
        if let Some(axis) = self.gravity.iter().position(|g| !g.is_finite()) {
            return Err(Error::invalid_argument(format!("`gravity[{axis}]` = {} is not finite", self.gravity[axis])));
        }
        if self.threads > 256 {
            return Err(Error::invalid_argument(format!("`threads` = {} is more than 256", self.threads)));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_bad_fields_are_named() {
        LatticeParams::default().validate().unwrap();
        let bad = |f: &dyn Fn(&mut LatticeParams)| {
            let mut p = LatticeParams::default();
            f(&mut p);
            p.validate().unwrap_err().message
        };
        assert!(bad(&|p| p.region_half_width = 0).contains("region_half_width"));
        assert!(bad(&|p| p.stiffness = 0.0).contains("stiffness"));
        assert!(bad(&|p| p.stiffness = 1.5).contains("(0, 1]"));
        assert!(bad(&|p| p.spacing = 0.0).contains("spacing"));
        assert!(bad(&|p| p.time_step = f32::NAN).contains("time_step"));
        assert!(bad(&|p| p.rows = 0).contains("rows"));
        assert!(bad(&|p| p.gravity[1] = f32::INFINITY).contains("gravity[1]"));
        assert!(bad(&|p| p.damping = -0.1).contains("damping"));
    }
}
