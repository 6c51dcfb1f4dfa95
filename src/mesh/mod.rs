//! Triangle meshes: storage, topology, validation, measures (volume, area, normals, curvature)
//! and OBJ input/output.
//!
//! This module knows nothing of the simulators or the C ABI; they build on it.

mod curvature;
mod incidence;
mod measures;
#[cfg(feature = "obj")]
mod obj;
mod ply;
mod report;
mod topology;
mod tri_mesh;

pub use curvature::{CurvatureKind, curvature_f32, vertex_curvature};
pub(crate) use incidence::vertex_incidence;
pub use measures::{
    BoundingBox, bounding_box, face_area_vectors, signed_volume, signed_volume_f64, surface_area, triangle_min_angle,
    vertex_normals,
};
#[cfg(feature = "obj")]
pub use obj::{load_obj, save_obj};
pub use ply::{VertexScalar, save_ply};
pub use report::{MeshReport, first_degenerate_triangle, require_closed_oriented_solid};
#[cfg(feature = "body")]
pub(crate) use topology::NO_FACE;
#[cfg(all(test, feature = "body"))]
pub(crate) use topology::torus_grid;
pub use topology::{Topology, TopologySpare};
pub use tri_mesh::TriMesh;
