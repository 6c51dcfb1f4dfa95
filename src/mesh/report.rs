//! What a mesh is: counts, closedness, orientation, genus, degenerate triangles, measures.
//! Also the check that simulators of closed solids run before they accept a mesh.

use super::measures::{bounding_box, signed_volume, surface_area, triangle_min_angle};
use super::topology::Topology;
use super::tri_mesh::TriMesh;
use crate::error::{Error, Result};

/// A triangle is degenerate when twice its area is below this fraction of its longest side
/// squared (the sine of its largest angle is numerically zero), or when it repeats a vertex.
pub(crate) const DEGENERATE_RELATIVE_AREA: f64 = 1e-9;

/// Everything `softshell_mesh_report` returns, plus a few extras.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshReport {
    /// Number of vertices (used or not).
    pub vertex_count: usize,
    /// Number of distinct undirected edges.
    pub edge_count: usize,
    /// Number of triangles.
    pub triangle_count: usize,
    /// Edges used by exactly one triangle.
    pub boundary_edges: usize,
    /// Edges used by more than two triangles.
    pub non_manifold_edges: usize,
    /// Triangles with zero area (a repeated vertex or three collinear corners).
    pub degenerate_triangles: usize,
    /// Connected components (through shared vertices).
    pub components: usize,
    /// Total genus of a closed, manifold, consistently oriented mesh; -1 otherwise.
    pub genus: i32,
    /// No boundary edges and no non-manifold edges.
    pub is_closed: bool,
    /// Every interior manifold edge is run in opposite directions by its two triangles.
    pub is_consistently_oriented: bool,
    /// Surface area.
    pub area: f64,
    /// Signed volume (positive for outward triangles; meaningful for closed meshes).
    pub volume: f64,
    /// Bounding box minimum.
    pub bbox_min: [f32; 3],
    /// Bounding box maximum.
    pub bbox_max: [f32; 3],
    /// Vertices where more than one fan of triangles meet.
    pub non_manifold_vertices: usize,
    /// Vertices that no triangle uses.
    pub unreferenced_vertices: usize,
    /// Smallest interior angle of any non-degenerate triangle, degrees.
    pub min_angle_degrees: f64,
    /// Index of the first degenerate triangle, if any.
    pub first_degenerate_triangle: Option<usize>,
}

/// Whether triangle `t` of `mesh` is degenerate (see [`DEGENERATE_RELATIVE_AREA`]).
fn is_degenerate(mesh: &TriMesh, t: usize) -> bool {
    let [a, b, c] = mesh.triangles()[t];
    if a == b || b == c || c == a {
        return true;
    }
    let [pa, pb, pc] = mesh.corners(t).map(|p| p.as_dvec3());
    let longest = (pb - pa).length_squared().max((pc - pb).length_squared()).max((pa - pc).length_squared());
    (pb - pa).cross(pc - pa).length() <= DEGENERATE_RELATIVE_AREA * longest
}

/// Index of the first degenerate (zero-area) triangle of `mesh`, if any: a repeated corner, or
/// corners on one line (twice the area below 1e-9 of the longest side squared).
pub fn first_degenerate_triangle(mesh: &TriMesh) -> Option<usize> {
    (0..mesh.triangle_count()).find(|&t| is_degenerate(mesh, t))
}

impl MeshReport {
    /// Computes the report of `mesh` with its `topology`.
    pub fn new(mesh: &TriMesh, topology: &Topology) -> Self {
        let degenerate: Vec<usize> = (0..mesh.triangle_count()).filter(|&t| is_degenerate(mesh, t)).collect();
        let boundary_edges = topology.boundary_edge_count();
        let non_manifold_edges = topology.non_manifold_edge_count();
        let is_closed = boundary_edges == 0 && non_manifold_edges == 0;
        let is_consistently_oriented = topology.inconsistent_edges.is_empty();
        let euler = topology.referenced_vertices as i64 - topology.edges.len() as i64 + mesh.triangle_count() as i64;
        let manifold_surface = is_closed
            && is_consistently_oriented
            && topology.non_manifold_vertices.is_empty()
            && degenerate.iter().all(|&t| {
                let [a, b, c] = mesh.triangles()[t];
                a != b && b != c && c != a
            });
        // Euler characteristic of a closed orientable surface: χ = Σ (2 - 2 g_c) = 2C - 2g.
        let genus = if manifold_surface && euler % 2 == 0 {
            (topology.component_count as i64 - euler / 2).clamp(-1, i32::MAX as i64) as i32
        } else {
            -1
        };
        let bbox = bounding_box(mesh.positions());
        let min_angle_degrees = (0..mesh.triangle_count())
            .filter(|t| degenerate.binary_search(t).is_err())
            .map(|t| {
                let [a, b, c] = mesh.corners(t);
                triangle_min_angle(a, b, c)
            })
            .fold(f64::INFINITY, f64::min);
        MeshReport {
            vertex_count: mesh.vertex_count(),
            edge_count: topology.edges.len(),
            triangle_count: mesh.triangle_count(),
            boundary_edges,
            non_manifold_edges,
            degenerate_triangles: degenerate.len(),
            components: topology.component_count,
            genus,
            is_closed,
            is_consistently_oriented,
            area: surface_area(mesh.positions(), mesh.triangles()),
            volume: signed_volume(mesh.positions(), mesh.triangles()),
            bbox_min: bbox.min.to_array(),
            bbox_max: bbox.max.to_array(),
            non_manifold_vertices: topology.non_manifold_vertices.len(),
            unreferenced_vertices: mesh.vertex_count() - topology.referenced_vertices,
            min_angle_degrees: if min_angle_degrees.is_finite() { min_angle_degrees } else { 0.0 },
            first_degenerate_triangle: degenerate.first().copied(),
        }
    }
}

/// Refuses a mesh that cannot bound a solid: the first degenerate triangle, boundary edge,
/// non-manifold edge, inconsistently wound edge or pinch vertex is named, and an inward-facing
/// (negative volume) mesh is refused with the advice to flip its winding. `what` names the caller
/// ("the shell", "a body with gas").
pub fn require_closed_oriented_solid(mesh: &TriMesh, topology: &Topology, what: &str) -> Result<()> {
    let triangles = mesh.triangles();
    if let Some(t) = (0..mesh.triangle_count()).find(|&t| is_degenerate(mesh, t)) {
        let [a, b, c] = triangles[t];
        return Err(Error::invalid_mesh(format!(
            "{what} needs non-degenerate triangles: triangle {t} ({a}, {b}, {c}) has zero area; remove or re-mesh it"
        )));
    }
    for (edge, &count) in topology.edge_face_count.iter().enumerate() {
        let [a, b] = topology.edges[edge];
        let face = topology.edge_faces[edge][0];
        if count == 1 {
            return Err(Error::invalid_mesh(format!(
                "{what} needs a closed mesh: edge ({a}, {b}) of triangle {face} is on a boundary (used by one triangle only)"
            )));
        }
        if count > 2 {
            return Err(Error::invalid_mesh(format!(
                "{what} needs a manifold mesh: edge ({a}, {b}) is shared by {count} triangles (first {face})"
            )));
        }
    }
    if let Some(&edge) = topology.inconsistent_edges.first() {
        let [a, b] = topology.edges[edge as usize];
        let [f0, f1] = topology.edge_faces[edge as usize];
        return Err(Error::invalid_mesh(format!(
            "{what} needs consistently oriented triangles: triangles {f0} and {f1} both run edge ({a}, {b}) in the same direction; flip one of them"
        )));
    }
    if let Some(&v) = topology.non_manifold_vertices.first() {
        return Err(Error::invalid_mesh(format!(
            "{what} needs a manifold mesh: vertex {v} joins more than one fan of triangles (a pinch point)"
        )));
    }
    let volume = signed_volume(mesh.positions(), triangles);
    if volume <= 0.0 {
        return Err(Error::invalid_mesh(format!(
            "{what} needs outward (counter-clockwise from outside) triangles: the signed volume is {volume:e}; reverse the winding of every triangle"
        )));
    }
    // Each closed piece on its own: an inward piece beside a larger outward one leaves the total
    // positive, but pressure would inflate it and a gas body would give it no gas. (A hollow
    // solid, an inward surface nested in an outward one, is refused too: neither simulator
    // models a cavity.)
    if topology.component_count > 1 {
        let positions = mesh.positions();
        let mut volumes = vec![0.0f64; topology.component_count];
        let mut first_face = vec![u32::MAX; topology.component_count];
        for (f, _) in triangles.iter().enumerate().rev() {
            first_face[topology.face_components[f] as usize] = f as u32;
        }
        for (f, t) in triangles.iter().enumerate() {
            let c = topology.face_components[f] as usize;
            // About a corner of the piece, not the origin: the same volume, less cancellation.
            let origin = positions[triangles[first_face[c] as usize][0] as usize].as_dvec3();
            let [a, b, d] = t.map(|v| positions[v as usize].as_dvec3() - origin);
            volumes[c] += a.dot(b.cross(d)) / 6.0;
        }
        if let Some(c) = (0..volumes.len()).find(|&c| volumes[c] <= 0.0) {
            return Err(Error::invalid_mesh(format!(
                "{what} needs every closed piece wound outward (counter-clockwise from outside): the piece of triangle {} \
                 encloses a signed volume of {:e}; reverse the winding of its triangles",
                first_face[c], volumes[c]
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn tetra() -> TriMesh {
        TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z], vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
            .unwrap()
    }

    #[test]
    fn tetrahedron_report() {
        let mesh = tetra();
        let report = MeshReport::new(&mesh, &Topology::build(mesh.triangles(), 4));
        assert_eq!((report.edge_count, report.genus, report.components), (6, 0, 1));
        assert!(report.is_closed && report.is_consistently_oriented);
        assert!((report.volume - 1.0 / 6.0).abs() < 1e-12);
        assert!((report.min_angle_degrees - 45.0).abs() < 1e-4);
        require_closed_oriented_solid(&mesh, &Topology::build(mesh.triangles(), 4), "test").unwrap();
    }

    #[test]
    fn inward_mesh_is_refused() {
        let mesh = tetra();
        let flipped =
            TriMesh::new(mesh.positions().to_vec(), mesh.triangles().iter().map(|t| [t[0], t[2], t[1]]).collect())
                .unwrap();
        let error = require_closed_oriented_solid(&flipped, &Topology::build(flipped.triangles(), 4), "x").unwrap_err();
        assert!(error.message.contains("reverse the winding"), "{}", error.message);
    }
}
