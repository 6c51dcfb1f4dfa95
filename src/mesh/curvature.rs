//! Per-vertex discrete curvature (Meyer, Desbrun, Schröder, Barr 2003): mean curvature from the
//! cotangent Laplacian and Gaussian curvature from the angle defect, both divided by the mixed
//! Voronoi area, so that they converge on well-shaped meshes (a unit sphere gives H = K = 1).

use glam::{DVec3, Vec3};

use super::report::DEGENERATE_RELATIVE_AREA;

/// Which curvature to compute.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CurvatureKind {
    /// Mean curvature H (1/m): positive where the surface bends away from its outward normal,
    /// as on a sphere with outward triangles.
    Mean,
    /// Gaussian curvature K (1/m²) from the angle defect.
    Gaussian,
}

/// Below this |u × v| a corner is treated as degenerate and contributes nothing (SPEC 1.4 guard).
const DEGENERATE: f64 = 1e-30;

/// A curvature as the f32 the C ABI hands out: saturated at ±f32::MAX, never infinite (a
/// nearly degenerate fan can pass f32's range; NaN cannot arise, areas are checked).
pub fn curvature_f32(value: f64) -> f32 {
    value.clamp(-f32::MAX as f64, f32::MAX as f64) as f32
}

fn cot(u: DVec3, v: DVec3) -> f64 {
    let cross = u.cross(v).length();
    if cross < DEGENERATE { 0.0 } else { u.dot(v) / cross }
}

/// Per-vertex curvature of `kind`. `boundary` marks vertices on a boundary (their angle defect is
/// taken against π instead of 2π); pass `None` for a closed mesh. Vertices with no area get 0.
pub fn vertex_curvature(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    boundary: Option<&[bool]>,
    kind: CurvatureKind,
) -> Vec<f64> {
    let n = positions.len();
    let mut area = vec![0.0f64; n];
    let mut laplace = vec![DVec3::ZERO; n];
    let mut normal = vec![DVec3::ZERO; n];
    let mut angle_sum = vec![0.0f64; n];

    for t in triangles {
        let p = t.map(|v| positions[v as usize].as_dvec3());
        let face_normal = (p[1] - p[0]).cross(p[2] - p[0]);
        let double_area = face_normal.length();
        let longest =
            (p[1] - p[0]).length_squared().max((p[2] - p[1]).length_squared()).max((p[0] - p[2]).length_squared());
        // A face the mesh report calls degenerate (relative to its size) gives nothing: its
        // cotangents and angle sums would make curvatures past any float's range.
        if double_area < DEGENERATE || double_area <= DEGENERATE_RELATIVE_AREA * longest {
            continue;
        }
        let face_area = 0.5 * double_area;
        for corner in 0..3 {
            let (i, j, k) = (corner, (corner + 1) % 3, (corner + 2) % 3);
            let (u, v) = (p[j] - p[i], p[k] - p[i]);
            let angle = u.cross(v).length().atan2(u.dot(v));
            angle_sum[t[i] as usize] += angle;
            normal[t[i] as usize] += face_normal;
            // The edge (j, k) faces the angle at i: cot(angle_i) weighs it for both ends.
            let weight = cot(u, v);
            laplace[t[j] as usize] += weight * (p[j] - p[k]);
            laplace[t[k] as usize] += weight * (p[k] - p[j]);
        }
        // Mixed Voronoi area: the Voronoi region for non-obtuse triangles, otherwise half or a
        // quarter of the triangle (Meyer et al., section 3.3).
        let obtuse = (0..3).find(|&i| (p[(i + 1) % 3] - p[i]).dot(p[(i + 2) % 3] - p[i]) < 0.0);
        for i in 0..3 {
            let (j, k) = ((i + 1) % 3, (i + 2) % 3);
            let share = match obtuse {
                None => {
                    let cot_j = cot(p[i] - p[j], p[k] - p[j]);
                    let cot_k = cot(p[i] - p[k], p[j] - p[k]);
                    ((p[k] - p[i]).length_squared() * cot_j + (p[j] - p[i]).length_squared() * cot_k) / 8.0
                }
                Some(o) if o == i => face_area / 2.0,
                Some(_) => face_area / 4.0,
            };
            area[t[i] as usize] += share;
        }
    }

    (0..n)
        .map(|v| {
            if area[v] <= 0.0 {
                return 0.0;
            }
            match kind {
                CurvatureKind::Mean => {
                    // K(x) = 1/(2A) Σ (cot α + cot β)(x_i - x_j) = 2 H n.
                    let mean_curvature_normal = laplace[v] / (2.0 * area[v]);
                    0.5 * mean_curvature_normal.dot(normal[v].normalize_or_zero())
                }
                CurvatureKind::Gaussian => {
                    let full =
                        if boundary.is_some_and(|b| b[v]) { std::f64::consts::PI } else { std::f64::consts::TAU };
                    (full - angle_sum[v]) / area[v]
                }
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An octahedron refined by midpoint subdivision and projected to the unit sphere.
    fn sphere(levels: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut p = vec![Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
        let mut t = vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
        for _ in 0..levels {
            let mut cache = std::collections::HashMap::new();
            let mut mid = |a: u32, b: u32, p: &mut Vec<Vec3>| {
                *cache.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    p.push(((p[a as usize] + p[b as usize]) * 0.5).normalize());
                    p.len() as u32 - 1
                })
            };
            let mut next = Vec::new();
            for &[a, b, c] in &t {
                let (ab, bc, ca) = (mid(a, b, &mut p), mid(b, c, &mut p), mid(c, a, &mut p));
                next.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
            }
            t = next;
        }
        (p, t)
    }

    #[test]
    fn unit_sphere_has_unit_curvatures() {
        let (p, t) = sphere(4);
        let mean = vertex_curvature(&p, &t, None, CurvatureKind::Mean);
        let gauss = vertex_curvature(&p, &t, None, CurvatureKind::Gaussian);
        let avg = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        assert!((avg(&mean) - 1.0).abs() < 0.02, "mean {}", avg(&mean));
        assert!((avg(&gauss) - 1.0).abs() < 0.02, "gauss {}", avg(&gauss));
        // Gauss-Bonnet: Σ K A = 4π, independent of the mesh.
        assert!(mean.iter().all(|h| (h - 1.0).abs() < 0.1));
    }

    #[test]
    fn flat_patch_has_zero_curvature_inside() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Z, -Vec3::X, -Vec3::Z];
        let t = vec![[0, 2, 1], [0, 3, 2], [0, 4, 3], [0, 1, 4]];
        let boundary = [false, true, true, true, true];
        let mean = vertex_curvature(&p, &t, Some(&boundary), CurvatureKind::Mean);
        let gauss = vertex_curvature(&p, &t, Some(&boundary), CurvatureKind::Gaussian);
        assert!(mean[0].abs() < 1e-12 && gauss[0].abs() < 1e-12);
    }
}
