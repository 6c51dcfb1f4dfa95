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

/// What the drag acts on: the mesh at (x, v), the vertex masses and the step length `h` its
/// force is held over.
pub(crate) struct DragState<'a> {
    pub x: &'a [Vec3],
    pub v: &'a [Vec3],
    pub triangles: &'a [[u32; 3]],
    pub mass: &'a [f32],
    pub h: f32,
}

/// Adds the wind force of every face to `f`; returns the power `Σ f·v` it delivers, W.
///
/// Each vertex's drag is scaled by `m / (m + h c)` with `c = Σ drag A / 3` over its faces: the
/// backward-Euler response of a mass `m` under a drag `c (w - v)` over a step `h`, which never
/// overshoots the air's speed, where the force held for the whole step (explicit) reverses the
/// relative velocity and grows it once `h c / m > 2`. (`c` bounds the coupling of a vertex
/// through the face velocities: the three corners moving together feel `drag A / 3` each.) For
/// a cloth, `h c / m` is small and the force is nearly unchanged; after a fracture storm,
/// split nodes share their masses and small fragments went past the limit: with XPBD on a
/// shattered balloon in wind the kinetic energy went from 20 J to 1e35 J in ten steps.
pub(crate) fn add_wind(state: &DragState, wind: Vec3, drag: f32, f: &mut [Vec3], coefficient: &mut Vec<f32>) -> f64 {
    let DragState { x, v, triangles, mass, h } = *state;
    coefficient.clear();
    coefficient.resize(x.len(), 0.0);
    for t in triangles {
        let p = t.map(|i| x[i as usize]);
        let area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
        for &i in t {
            coefficient[i as usize] += drag * area / 3.0;
        }
    }
    for (c, &m) in coefficient.iter_mut().zip(mass) {
        *c = if m > 0.0 { m / (m + h * *c) } else { 1.0 };
    }
    let mut power = 0.0f64;
    for t in triangles {
        let p = t.map(|i| x[i as usize]);
        let vel = t.map(|i| v[i as usize]);
        let corner = face_drag(p, vel, wind, drag);
        for (k, &i) in t.iter().enumerate() {
            let force = corner * coefficient[i as usize];
            f[i as usize] += force;
            power += force.dot(vel[k]) as f64;
        }
    }
    power
}

/// The most power the wind can give the mesh at positions `x`, W: `Σ drag A (w·n)² / 4` over
/// its faces. A face moving at `b = v·n` in a wind `a = w·n` takes `drag A (a - b) b`, at most
/// `drag A a² / 4` (at `b = a/2`) whatever its speed. The step control holds the wind's work to
/// it ([`super::simulator`]): the work it measures (the force at a substep's start times the
/// displacement) grew without bound on a blown-up body, whose corners swapped huge velocities
/// within the substep, and so explained away the energy the blow-up made.
pub(crate) fn power_bound(x: &[Vec3], triangles: &[[u32; 3]], wind: Vec3, drag: f32) -> f64 {
    let wind = wind.as_dvec3();
    triangles
        .iter()
        .map(|t| {
            let p = t.map(|i| x[i as usize].as_dvec3());
            let area_vector = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]); // A n
            let area = area_vector.length();
            // drag A (w·n)² / 4 = drag (w·(A n))² / (4 A)
            if area > 0.0 { drag as f64 * wind.dot(area_vector).powi(2) / (4.0 * area) } else { 0.0 }
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One explicit step with the force `add_wind` returns never carries a face past the air's
    /// speed along its normal, however light its corners (the held force would reverse the
    /// relative velocity once `h c / m > 2`); for heavy corners it is the plain drag.
    #[test]
    fn the_drag_of_a_step_never_overshoots_the_wind() {
        let x = [Vec3::ZERO, Vec3::X, Vec3::Z]; // normal -y, area 1/2
        let triangles = [[0u32, 1, 2]];
        let wind = Vec3::new(0.0, 4.0, 0.0);
        let h = 1.0 / 60.0;
        for m in [1e-6f32, 1e-3, 1.0, 1e3] {
            let (v, mass) = ([Vec3::ZERO; 3], [m; 3]);
            let mut f = [Vec3::ZERO; 3];
            add_wind(
                &DragState { x: &x, v: &v, triangles: &triangles, mass: &mass, h },
                wind,
                2.0,
                &mut f,
                &mut Vec::new(),
            );
            let plain = face_drag(x, v, wind, 2.0);
            for fi in f {
                let speed = (fi * (h / m)).y;
                assert!(speed > 0.0 && speed <= wind.y, "m = {m}: speed {speed}");
                if m >= 1.0 {
                    // h c / m = h (2 * 1/2 / 3) / m, under 0.6% at 1 kg.
                    assert!((fi - plain).length() <= 1e-2 / m * plain.length(), "m = {m}: {fi} vs {plain}");
                }
            }
        }
    }

    /// The power the drag gives a face, over every speed of the face along its normal, never
    /// exceeds [`power_bound`], and reaches it at half the wind's normal speed.
    #[test]
    fn the_power_bound_holds_at_every_speed_and_is_reached() {
        let x = [Vec3::ZERO, Vec3::new(2.0, 0.0, 0.5), Vec3::new(0.3, 0.2, 2.0)];
        let triangles = [[0u32, 1, 2]];
        let (wind, drag) = (Vec3::new(1.0, -4.0, 0.5), 0.7);
        let bound = power_bound(&x, &triangles, wind, drag);
        let normal = (x[1] - x[0]).cross(x[2] - x[0]).normalize();
        let a = wind.dot(normal);
        let mut largest = 0.0f64;
        for k in -200..=200 {
            let v = normal * (a * k as f32 / 100.0) + Vec3::new(0.3, 0.0, -0.2);
            let corner = face_drag(x, [v; 3], wind, drag);
            let power = 3.0 * corner.dot(v) as f64;
            assert!(power <= bound * (1.0 + 1e-5), "speed {k}/100 of the wind's: {power} > {bound}");
            largest = largest.max(power);
        }
        assert!(largest >= bound * (1.0 - 1e-4), "{largest} never reaches {bound}");
    }

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
