//! Edge-distance constraint (plain PBD; Müller et al. 2007): `C = |x1 - x0| - L`,
//! `Δx0 = +w0/(w0+w1) C u`, `Δx1 = -w1/(w0+w1) C u`. The paper's baseline (Table 1, Fig. 14)
//! that energy constraints are compared against.

// NaN must fail every guard below, so comparisons are written `!(x > limit)` on purpose.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use glam::Vec3;

/// Corrections of the two ends, or `None` when the edge has collapsed or both ends are pinned.
#[inline(always)]
pub fn distance_correction(x0: Vec3, x1: Vec3, w0: f32, w1: f32, rest: f32) -> Option<(Vec3, Vec3)> {
    let d = x1 - x0;
    let len = d.length();
    let w = w0 + w1;
    if !(len > 1e-20) || !(w > 0.0) {
        return None;
    }
    let u = d / len;
    let c = len - rest;
    Some((u * (c * w0 / w), u * (-c * w1 / w)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_projection_restores_the_length_and_keeps_the_mass_centre() {
        let (a, b) = (Vec3::ZERO, Vec3::new(2.0, 1.0, 0.0));
        let (da, db) = distance_correction(a, b, 1.0, 3.0, 1.0).unwrap();
        assert!(((b + db - a - da).length() - 1.0).abs() < 1e-6);
        // Mass-weighted centre (masses 1 and 1/3) is unchanged.
        assert!((da * 1.0 + db * (1.0 / 3.0)).length() < 1e-6);
        assert!(distance_correction(a, a, 1.0, 1.0, 1.0).is_none());
        assert!(distance_correction(a, b, 0.0, 0.0, 1.0).is_none());
    }
}
