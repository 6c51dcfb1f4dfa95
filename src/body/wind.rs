//! Wind drag on faces (SPEC 2.1): a face moving through air that flows at `w` feels
//! `f = drag ((w - v_face)·n) n A`, a third on each corner (a cloth in a wind field).

use glam::Vec3;

/// SPEC 2.1 wind kernel: the force on each corner of a face with corners `p` and corner
/// velocities `v`, for wind `wind` and coefficient `drag`. Zero for a face without area.
pub(crate) fn face_drag(p: [Vec3; 3], v: [Vec3; 3], wind: Vec3, drag: f32) -> Vec3 {
    let area_vector = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]); // A n
    let area = area_vector.length();
    if area <= f32::MIN_POSITIVE {
        return Vec3::ZERO;
    }
    let v_face = (v[0] + v[1] + v[2]) / 3.0;
    // drag ((w - v)·n) n A = drag ((w - v)·(A n)) (A n) / A
    area_vector * (drag * (wind - v_face).dot(area_vector) / area / 3.0)
}

/// Adds the wind force of every face to `f`; returns the power `Σ f·v` it delivers, W.
pub(crate) fn add_wind(x: &[Vec3], v: &[Vec3], triangles: &[[u32; 3]], wind: Vec3, drag: f32, f: &mut [Vec3]) -> f64 {
    let mut power = 0.0f64;
    for t in triangles {
        let p = t.map(|i| x[i as usize]);
        let vel = t.map(|i| v[i as usize]);
        let corner = face_drag(p, vel, wind, drag);
        for (k, &i) in t.iter().enumerate() {
            f[i as usize] += corner;
            power += corner.dot(vel[k]) as f64;
        }
    }
    power
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drag_is_normal_and_scales_with_area_and_relative_speed() {
        let p = [Vec3::ZERO, Vec3::X * 2.0, Vec3::Z * 2.0]; // area 2, normal -y
        let f = face_drag(p, [Vec3::ZERO; 3], Vec3::new(1.0, 3.0, 0.0), 0.5);
        // (w·n) n A drag / 3 = (-3)(-y)(2)(0.5)/3 = y
        assert!((f - Vec3::Y).length() < 1e-6, "{f}");
        // Moving with the wind: no force.
        let f = face_drag(p, [Vec3::new(1.0, 3.0, 0.0); 3], Vec3::new(1.0, 3.0, 0.0), 0.5);
        assert!(f.length() < 1e-6);
        assert_eq!(face_drag([Vec3::ZERO; 3], [Vec3::ZERO; 3], Vec3::X, 1.0), Vec3::ZERO);
    }
}
