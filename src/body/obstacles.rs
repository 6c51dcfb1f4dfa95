//! Obstacles (SPEC 2.3): planes (the ground, walls) and spheres. A penetrating vertex is
//! projected to the surface; its normal velocity gets the restitution and its tangential velocity
//! Coulomb friction.

use glam::Vec3;

/// A static obstacle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Obstacle {
    /// The half-space behind a plane through `point` with unit `normal` (pointing to the free side).
    Plane {
        /// A point of the plane.
        point: Vec3,
        /// Unit normal towards the free side.
        normal: Vec3,
    },
    /// A solid sphere.
    Sphere {
        /// Centre.
        center: Vec3,
        /// Radius, > 0.
        radius: f32,
    },
}

impl Obstacle {
    /// Signed distance of `p` from the surface (negative inside) and the outward normal there.
    fn distance(&self, p: Vec3) -> (f32, Vec3) {
        match *self {
            Obstacle::Plane { point, normal } => ((p - point).dot(normal), normal),
            Obstacle::Sphere { center, radius } => {
                let d = p - center;
                let len = d.length();
                let n = if len > 0.0 { d / len } else { Vec3::Y };
                (len - radius, n)
            }
        }
    }
}

impl Obstacle {
    /// True when `p` is inside (strictly behind the surface).
    pub(crate) fn contains(&self, p: Vec3) -> bool {
        self.distance(p).0 < 0.0
    }
}

/// Pushes `x` out of every obstacle it is inside (positions only, for constraint solvers);
/// returns the normal of the last contact.
pub(crate) fn project(x: &mut Vec3, obstacles: &[Obstacle]) -> Option<Vec3> {
    let mut normal = None;
    for obstacle in obstacles {
        let (depth, n) = obstacle.distance(*x);
        if depth < 0.0 {
            *x -= n * depth;
            normal = Some(n);
        }
    }
    normal
}

/// Normal of the obstacle that `x` touches (within `margin` of its surface or inside it), if any.
#[inline]
pub(crate) fn touching(x: Vec3, obstacles: &[Obstacle], margin: f32) -> Option<Vec3> {
    obstacles.iter().map(|o| o.distance(x)).filter(|&(d, _)| d <= margin).map(|(_, n)| n).last()
}

/// SPEC 2.3 contact response of one vertex: projection to the surface, restitution of the
/// normal velocity, Coulomb friction on the tangential one (the friction impulse is at most
/// `friction` times the normal impulse). Returns true when the vertex touched an obstacle.
#[inline]
pub(crate) fn resolve(x: &mut Vec3, v: &mut Vec3, obstacles: &[Obstacle], restitution: f32, friction: f32) -> bool {
    let mut touched = false;
    for obstacle in obstacles {
        let (depth, n) = obstacle.distance(*x);
        if depth >= 0.0 {
            continue;
        }
        touched = true;
        *x -= n * depth;
        let vn = v.dot(n);
        if vn < 0.0 {
            let tangential = *v - n * vn;
            let normal_change = (1.0 + restitution) * -vn;
            let speed = tangential.length();
            let kept = if speed > 0.0 { (1.0 - friction * normal_change / speed).max(0.0) } else { 0.0 };
            *v = tangential * kept - n * (restitution * vn);
        }
    }
    touched
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ground_contact_projects_bounces_and_rubs() {
        let ground = [Obstacle::Plane { point: Vec3::ZERO, normal: Vec3::Y }];
        let (mut x, mut v) = (Vec3::new(0.0, -0.1, 0.0), Vec3::new(1.0, -2.0, 0.0));
        assert!(resolve(&mut x, &mut v, &ground, 0.5, 0.1));
        assert_eq!(x.y, 0.0);
        assert!((v.y - 1.0).abs() < 1e-6);
        assert!((v.x - (1.0 - 0.1 * 3.0)).abs() < 1e-6);
        // Strong friction stops the sliding, never reverses it.
        let (mut x, mut v) = (Vec3::new(0.0, -0.1, 0.0), Vec3::new(1.0, -2.0, 0.0));
        resolve(&mut x, &mut v, &ground, 0.0, 10.0);
        assert_eq!(v, Vec3::ZERO);
        let sphere = [Obstacle::Sphere { center: Vec3::ZERO, radius: 1.0 }];
        let (mut x, mut v) = (Vec3::new(0.5, 0.0, 0.0), Vec3::new(-1.0, 0.0, 0.0));
        resolve(&mut x, &mut v, &sphere, 0.0, 0.0);
        assert!((x.x - 1.0).abs() < 1e-6 && v == Vec3::ZERO);
    }
}
