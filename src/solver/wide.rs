//! Four constraints at a time (SSE lanes through glam's `Vec4`): a 3-vector per lane as three
//! `Vec4`s. Used by the bending projection, whose stencils of one colour are independent, so any
//! four can be solved together. Each lane performs the same IEEE operations as the scalar kernel.

// `add`/`sub`/`scale` are plain methods rather than operator traits: the hot loops read as the
// formulas in SPEC.md and nothing implicit happens.
#![allow(clippy::should_implement_trait)]

use glam::{Vec3, Vec4};

/// Four 3-vectors, one per lane.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct W3 {
    /// x of each lane.
    pub x: Vec4,
    /// y of each lane.
    pub y: Vec4,
    /// z of each lane.
    pub z: Vec4,
}

impl W3 {
    /// Lane j holds `v[j]`.
    #[inline(always)]
    pub fn gather(v: [Vec3; 4]) -> Self {
        W3 {
            x: Vec4::new(v[0].x, v[1].x, v[2].x, v[3].x),
            y: Vec4::new(v[0].y, v[1].y, v[2].y, v[3].y),
            z: Vec4::new(v[0].z, v[1].z, v[2].z, v[3].z),
        }
    }
    /// The vector of lane j.
    #[inline(always)]
    pub fn lane(&self, j: usize) -> Vec3 {
        Vec3::new(self.x[j], self.y[j], self.z[j])
    }
    /// `self + o`.
    #[inline(always)]
    pub fn add(self, o: W3) -> W3 {
        W3 { x: self.x + o.x, y: self.y + o.y, z: self.z + o.z }
    }
    /// `self - o`.
    #[inline(always)]
    pub fn sub(self, o: W3) -> W3 {
        W3 { x: self.x - o.x, y: self.y - o.y, z: self.z - o.z }
    }
    /// `self * s` per lane.
    #[inline(always)]
    pub fn scale(self, s: Vec4) -> W3 {
        W3 { x: self.x * s, y: self.y * s, z: self.z * s }
    }
    /// Dot product per lane (in the order x, y, z like glam's `Vec3::dot`).
    #[inline(always)]
    pub fn dot(self, o: W3) -> Vec4 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// Cross product per lane.
    #[inline(always)]
    pub fn cross(self, o: W3) -> W3 {
        W3 { x: self.y * o.z - o.y * self.z, y: self.z * o.x - o.z * self.x, z: self.x * o.y - o.x * self.y }
    }
    /// Per lane, `if mask { a } else { b }`.
    #[inline(always)]
    pub fn select(mask: glam::BVec4A, a: W3, b: W3) -> W3 {
        W3 { x: Vec4::select(mask, a.x, b.x), y: Vec4::select(mask, a.y, b.y), z: Vec4::select(mask, a.z, b.z) }
    }
}
