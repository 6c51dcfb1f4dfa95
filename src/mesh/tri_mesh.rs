//! The triangle mesh value: positions and counter-clockwise triangles, validated on creation so
//! that every later stage can index without checks.

use glam::Vec3;

use crate::error::{Error, Result};

/// A triangle mesh whose indices are all in range and whose coordinates are all finite.
///
/// It may still be open, non-manifold or contain degenerate triangles: [`super::MeshReport`]
/// describes that, and simulators that cannot handle it refuse it with
/// [`super::require_closed_oriented_solid`].
#[derive(Clone, Debug, PartialEq)]
pub struct TriMesh {
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// Builds a mesh from flat arrays: `positions` holds x,y,z triples, `triangles` a,b,c triples.
    /// Refuses an empty mesh, a length that is not a multiple of 3, a non-finite coordinate and an
    /// out-of-range index, naming the first offender.
    pub fn from_flat(positions: &[f32], triangles: &[u32]) -> Result<Self> {
        if positions.len() % 3 != 0 || triangles.len() % 3 != 0 {
            return Err(Error::invalid_argument(format!(
                "flat arrays must hold whole triples: {} position floats, {} triangle indices",
                positions.len(),
                triangles.len()
            )));
        }
        let points = positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])).collect();
        let faces = triangles.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        Self::new(points, faces)
    }

    /// Builds a mesh from vectors, with the same checks as [`TriMesh::from_flat`].
    pub fn new(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Result<Self> {
        if positions.is_empty() {
            return Err(Error::invalid_mesh("the mesh has no vertices"));
        }
        if triangles.is_empty() {
            return Err(Error::invalid_mesh("the mesh has no triangles"));
        }
        if positions.len() > u32::MAX as usize {
            return Err(Error::invalid_mesh(format!(
                "{} vertices is more than a uint32_t index can address",
                positions.len()
            )));
        }
        for (vertex, p) in positions.iter().enumerate() {
            if let Some(axis) = (0..3).find(|&axis| !p[axis].is_finite()) {
                return Err(Error::invalid_mesh(format!(
                    "vertex {vertex} has a non-finite coordinate: {}[{axis}] = {} (position {}, {}, {})",
                    ["x", "y", "z"][axis],
                    p[axis],
                    p.x,
                    p.y,
                    p.z
                )));
            }
        }
        let count = positions.len();
        for (triangle, t) in triangles.iter().enumerate() {
            if let Some(corner) = (0..3).find(|&corner| t[corner] as usize >= count) {
                return Err(Error::invalid_mesh(format!(
                    "triangle {triangle} ({}, {}, {}) has index {} at corner {corner}, but the mesh has only {count} vertices (valid: 0..{})",
                    t[0],
                    t[1],
                    t[2],
                    t[corner],
                    count - 1
                )));
            }
        }
        Ok(Self { positions, triangles })
    }

    /// Vertex positions.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// Triangles, counter-clockwise seen from outside.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// The three corner positions of triangle `t`.
    pub fn corners(&self, t: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[t];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }

    /// Heap bytes held by the mesh.
    pub fn memory_bytes(&self) -> usize {
        self.positions.capacity() * std::mem::size_of::<Vec3>()
            + self.triangles.capacity() * std::mem::size_of::<[u32; 3]>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::ErrorKind;

    #[test]
    fn refuses_bad_input_naming_the_offender() {
        let error = TriMesh::from_flat(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], &[0, 1, 3]).unwrap_err();
        assert_eq!(error.kind, ErrorKind::InvalidMesh);
        assert!(error.message.contains("triangle 0") && error.message.contains("index 3"), "{}", error.message);

        let error = TriMesh::from_flat(&[0.0, f32::NAN, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], &[0, 1, 2]).unwrap_err();
        assert!(error.message.contains("vertex 0") && error.message.contains("NaN"), "{}", error.message);

        assert_eq!(TriMesh::from_flat(&[], &[]).unwrap_err().kind, ErrorKind::InvalidMesh);
        assert_eq!(TriMesh::from_flat(&[0.0; 4], &[0, 0, 0]).unwrap_err().kind, ErrorKind::InvalidArgument);
    }
}
