//! Geometric measures of a triangle mesh: volume, area, normals, bounding box, angles.
//!
//! Sums are accumulated in f64 because they feed error measures (volume ratio, energy drift)
//! that must be accurate to far better than f32 rounding.

use glam::{DVec3, Vec3};

/// Axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundingBox {
    /// Smallest coordinates.
    pub min: Vec3,
    /// Largest coordinates.
    pub max: Vec3,
}

impl BoundingBox {
    /// Length of the diagonal.
    pub fn diagonal(&self) -> f32 {
        (self.max - self.min).length()
    }
}

/// Bounding box of `positions` (all zeros for an empty slice).
pub fn bounding_box(positions: &[Vec3]) -> BoundingBox {
    if positions.is_empty() {
        return BoundingBox { min: Vec3::ZERO, max: Vec3::ZERO };
    }
    let (min, max) = positions
        .iter()
        .fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(lo, hi), &p| (lo.min(p), hi.max(p)));
    BoundingBox { min, max }
}

fn centroid(positions: &[Vec3]) -> DVec3 {
    if positions.is_empty() {
        return DVec3::ZERO;
    }
    positions.iter().fold(DVec3::ZERO, |sum, p| sum + p.as_dvec3()) / positions.len() as f64
}

/// Signed volume `V = 1/6 Σ x_a · (x_b × x_c)` (SPEC 1.7), in f64 with positions taken relative
/// to their centroid: that keeps the terms small, so the sum cancels far less when the mesh sits
/// away from the origin. Positive for outward (counter-clockwise from outside) triangles.
pub fn signed_volume(positions: &[Vec3], triangles: &[[u32; 3]]) -> f64 {
    let center = centroid(positions);
    signed_volume_about(positions, triangles, center)
}

fn signed_volume_about(positions: &[Vec3], triangles: &[[u32; 3]], center: DVec3) -> f64 {
    let sum: f64 = triangles
        .iter()
        .map(|t| {
            let a = positions[t[0] as usize].as_dvec3() - center;
            let b = positions[t[1] as usize].as_dvec3() - center;
            let c = positions[t[2] as usize].as_dvec3() - center;
            a.dot(b.cross(c))
        })
        .sum();
    sum / 6.0
}

/// [`signed_volume`] for f64 positions (used where the caller holds them in double precision).
pub fn signed_volume_f64(positions: &[DVec3], triangles: &[[u32; 3]]) -> f64 {
    let center =
        if positions.is_empty() { DVec3::ZERO } else { positions.iter().sum::<DVec3>() / positions.len() as f64 };
    triangles
        .iter()
        .map(|t| {
            let a = positions[t[0] as usize] - center;
            let b = positions[t[1] as usize] - center;
            let c = positions[t[2] as usize] - center;
            a.dot(b.cross(c))
        })
        .sum::<f64>()
        / 6.0
}

/// Total surface area, in f64.
pub fn surface_area(positions: &[Vec3], triangles: &[[u32; 3]]) -> f64 {
    face_area_vectors(positions, triangles).map(|n| 0.5 * n.length()).sum()
}

/// For each triangle, `(x_b - x_a) × (x_c - x_a)` in f64: twice its area times its unit normal.
pub fn face_area_vectors<'a>(positions: &'a [Vec3], triangles: &'a [[u32; 3]]) -> impl Iterator<Item = DVec3> + 'a {
    triangles.iter().map(move |t| {
        let a = positions[t[0] as usize].as_dvec3();
        let b = positions[t[1] as usize].as_dvec3();
        let c = positions[t[2] as usize].as_dvec3();
        (b - a).cross(c - a)
    })
}

/// Area-weighted unit vertex normals (zero for a vertex whose faces cancel or that has none).
pub fn vertex_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Vec3> {
    let mut sums = vec![DVec3::ZERO; positions.len()];
    for (t, n) in triangles.iter().zip(face_area_vectors(positions, triangles)) {
        for &v in t {
            sums[v as usize] += n;
        }
    }
    sums.into_iter().map(|n| n.normalize_or_zero().as_vec3()).collect()
}

/// Smallest interior angle of a triangle, in degrees (0 for a degenerate one).
pub fn triangle_min_angle(a: Vec3, b: Vec3, c: Vec3) -> f64 {
    let (a, b, c) = (a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
    let angle = |p: DVec3, q: DVec3, r: DVec3| {
        let (u, v) = (q - p, r - p);
        let cross = u.cross(v).length();
        if cross == 0.0 { 0.0 } else { cross.atan2(u.dot(v)).to_degrees() }
    };
    angle(a, b, c).min(angle(b, c, a)).min(angle(c, a, b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_cube_corner_tetrahedron() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let t = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
        assert!((signed_volume(&p, &t) - 1.0 / 6.0).abs() < 1e-12);
        let flipped: Vec<[u32; 3]> = t.iter().map(|f| [f[0], f[2], f[1]]).collect();
        assert!((signed_volume(&p, &flipped) + 1.0 / 6.0).abs() < 1e-12);
        let area = surface_area(&p, &t);
        assert!((area - (1.5 + 3f64.sqrt() / 2.0)).abs() < 1e-6);
    }

    #[test]
    fn volume_is_accurate_far_from_the_origin() {
        let offset = Vec3::splat(1000.0);
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z].map(|q| q + offset);
        let t = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
        assert!((signed_volume(&p, &t) - 1.0 / 6.0).abs() < 1e-9);
    }

    #[test]
    fn angles() {
        let equilateral = triangle_min_angle(Vec3::ZERO, Vec3::X, Vec3::new(0.5, 3f32.sqrt() / 2.0, 0.0));
        assert!((equilateral - 60.0).abs() < 1e-4);
        assert_eq!(triangle_min_angle(Vec3::ZERO, Vec3::X, Vec3::X * 2.0), 0.0);
    }
}
