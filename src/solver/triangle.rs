//! The triangle strain element of SPEC 1.3: rest frame, `Dm^-1`, F and the vertex gradients
//! `[∂W/∂x1, ∂W/∂x2] = A0 P Dm^-T`, `∂W/∂x0 = -(∂W/∂x1 + ∂W/∂x2)`.

use glam::Vec3;

use crate::material::Mat32;

/// Rest data of one triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleRest {
    /// `Dm^-1` row-major: `[m00, m01, m10, m11]`.
    pub dm_inv: [f32; 4],
    /// Rest area A0.
    pub area: f32,
    /// Rest-plane basis `[t1 t2]` in world space (SPEC 1.3).
    pub basis: Mat32,
}

/// SPEC 1.3: `e1 = X1 - X0, e2 = X2 - X0, t1 = e1/|e1|, t2 = normalize((e1 × e2) × t1)`,
/// `Dm = [[|e1|, t1·e2], [0, t2·e2]]`. `None` for a degenerate triangle (`det Dm` below
/// `1e-12 |e|²`): its `Dm^-1` would be meaningless.
pub fn triangle_rest(x0: Vec3, x1: Vec3, x2: Vec3) -> Option<TriangleRest> {
    // In f64: |e1 x e2|² passes f32's range for edges over about 1e9 (a NaN Dm^-1 then).
    let (e1, e2) = ((x1 - x0).as_dvec3(), (x2 - x0).as_dvec3());
    let len1 = e1.length();
    let normal = e1.cross(e2);
    let scale = e1.length_squared().max(e2.length_squared());
    if len1 <= 0.0 || normal.length() <= 1e-12 * scale || !normal.is_finite() {
        return None;
    }
    let t1 = e1 / len1;
    let t2 = normal.cross(t1).normalize();
    let (a, b, c) = (len1, t1.dot(e2), t2.dot(e2));
    // Upper triangular inverse: [[1/a, -b/(a c)], [0, 1/c]].
    let dm_inv = [1.0 / a, -b / (a * c), 0.0, 1.0 / c].map(|v| v as f32);
    let area = (0.5 * a * c) as f32;
    if !(area > 0.0 && area.is_finite() && dm_inv.iter().all(|v| v.is_finite())) {
        return None;
    }
    Some(TriangleRest { dm_inv, area, basis: Mat32::new(t1.as_vec3(), t2.as_vec3()) })
}

/// `F = Ds Dm^-1` with `Ds = [x1 - x0, x2 - x0]`.
#[inline(always)]
pub fn deformation_gradient(x: [Vec3; 3], dm_inv: &[f32; 4]) -> Mat32 {
    let (d1, d2) = (x[1] - x[0], x[2] - x[0]);
    Mat32::new(d1 * dm_inv[0] + d2 * dm_inv[2], d1 * dm_inv[1] + d2 * dm_inv[3])
}

/// Vertex gradients `scale · P Dm^-T` for x1, x2 and their negated sum for x0 (`scale` is A0, or
/// A0 times a modulus).
#[inline(always)]
pub fn scatter_stress(p: &Mat32, dm_inv: &[f32; 4], scale: f32) -> [Vec3; 3] {
    let g1 = (p.c0 * dm_inv[0] + p.c1 * dm_inv[1]) * scale;
    let g2 = (p.c0 * dm_inv[2] + p.c1 * dm_inv[3]) * scale;
    [-(g1 + g2), g1, g2]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{Lame, Material, membrane_energy};

    fn energy(x: [Vec3; 3], rest: &TriangleRest) -> (f32, [Vec3; 3]) {
        let f = deformation_gradient(x, &rest.dm_inv);
        let (psi, p) = membrane_energy(Material::StVK, Lame::from_young_poisson(1.0, 0.3), &f, &rest.basis);
        (rest.area * psi, scatter_stress(&p, &rest.dm_inv, rest.area))
    }

    #[test]
    fn rest_frame_gives_identity_and_gradients_match_finite_differences() {
        let rest_x = [Vec3::new(0.1, 0.2, 0.3), Vec3::new(1.0, 0.4, 0.2), Vec3::new(0.3, 1.1, 0.6)];
        let rest = triangle_rest(rest_x[0], rest_x[1], rest_x[2]).unwrap();
        let f = deformation_gradient(rest_x, &rest.dm_inv);
        assert!(f.sub(&rest.basis).norm() < 1e-5);
        assert!((rest.area - 0.5 * (rest_x[1] - rest_x[0]).cross(rest_x[2] - rest_x[0]).length()).abs() < 1e-6);

        let x = [Vec3::new(0.0, 0.25, 0.3), Vec3::new(1.2, 0.3, 0.1), Vec3::new(0.2, 0.9, 0.9)];
        let (_, grad) = energy(x, &rest);
        let h = 1e-3;
        for v in 0..3 {
            for axis in 0..3 {
                let (mut plus, mut minus) = (x, x);
                plus[v][axis] += h;
                minus[v][axis] -= h;
                let fd = (energy(plus, &rest).0 - energy(minus, &rest).0) / (2.0 * h);
                assert!((fd - grad[v][axis]).abs() < 2e-3 * grad[v].length().max(1.0), "v{v} axis {axis}");
            }
        }
        assert!(triangle_rest(Vec3::ZERO, Vec3::X, Vec3::X * 2.0).is_none());
    }
}
