//! `SoftshellMesh`: an immutable triangle mesh handle, its report and its OBJ input/output.

use std::ffi::c_char;

use super::boundary::{
    SoftshellStatus, arg_kind, arg_path, arg_ref, arg_slice, copy_out, out_arg, status_call, value_call, write_out,
    write_triples,
};
use crate::error::{Error, Result};
use crate::mesh::{
    CurvatureKind, MeshReport, Topology, TriMesh, VertexScalar, curvature_f32, save_ply, vertex_curvature,
};

/// Mean curvature H (1/m), for `..._copy_vertex_curvature`: positive where the surface bends away
/// from its outward normal (1 everywhere on a unit sphere).
pub const SOFTSHELL_CURVATURE_MEAN: u32 = 0;
/// Gaussian curvature K (1/m^2) from the angle defect, for `..._copy_vertex_curvature`.
pub const SOFTSHELL_CURVATURE_GAUSSIAN: u32 = 1;

impl TryFrom<u32> for CurvatureKind {
    type Error = ();
    fn try_from(value: u32) -> std::result::Result<Self, ()> {
        match value {
            SOFTSHELL_CURVATURE_MEAN => Ok(CurvatureKind::Mean),
            SOFTSHELL_CURVATURE_GAUSSIAN => Ok(CurvatureKind::Gaussian),
            _ => Err(()),
        }
    }
}

/// An immutable triangle mesh: positions (float x,y,z) and triangles (uint32_t a,b,c,
/// counter-clockwise seen from outside). Every index is in range and every coordinate finite;
/// it may be open, non-manifold or hold degenerate triangles (see `softshell_mesh_report`).
///
/// Created by `softshell_mesh_from_arrays` or `softshell_mesh_load_obj`, destroyed by
/// `softshell_mesh_free`. Simulators copy what they need, so a mesh may be freed as soon as the
/// simulators made from it exist. A mesh is never modified, so it may be read from several
/// threads at once.
pub struct SoftshellMesh {
    pub(crate) mesh: TriMesh,
    pub(crate) topology: Topology,
}

impl SoftshellMesh {
    fn new(mesh: TriMesh) -> Self {
        let topology = Topology::build(mesh.triangles(), mesh.vertex_count());
        Self { mesh, topology }
    }

    /// For each vertex, whether it lies on a boundary loop.
    pub(crate) fn boundary_flags(&self) -> Vec<bool> {
        let mut boundary = vec![false; self.mesh.vertex_count()];
        for &v in self.topology.boundary_loops.iter().flatten() {
            boundary[v as usize] = true;
        }
        boundary
    }
}

/// What a mesh is. Filled by `softshell_mesh_report`. Fields may be appended in later versions.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SoftshellMeshReport {
    /// Number of vertices, used by a triangle or not.
    pub vertex_count: usize,
    /// Number of distinct undirected edges (sides of degenerate triangles whose ends coincide do
    /// not count).
    pub edge_count: usize,
    /// Number of triangles.
    pub triangle_count: usize,
    /// Edges used by exactly one triangle (0 for a closed mesh).
    pub boundary_edges: usize,
    /// Edges used by more than two triangles.
    pub non_manifold_edges: usize,
    /// Triangles of zero area: a repeated vertex index, or corners on one line (twice the area
    /// below 1e-9 times the longest side squared). Simulators of closed solids refuse them.
    pub degenerate_triangles: usize,
    /// Connected components (triangles sharing a vertex are connected; unused vertices do not
    /// count).
    pub components: usize,
    /// Total genus (number of handles) of a closed, manifold, consistently oriented mesh;
    /// -1 otherwise. A sphere has 0, a torus 1.
    pub genus: i32,
    /// True when there are no boundary and no non-manifold edges.
    pub is_closed: bool,
    /// True when every edge shared by two triangles is run in opposite directions by them.
    pub is_consistently_oriented: bool,
    /// Total surface area, m^2.
    pub area: f64,
    /// Signed enclosed volume, m^3: > 0 for outward (counter-clockwise from outside) triangles.
    /// Meaningful only for closed meshes.
    pub volume: f64,
    /// Smallest x, y, z of the vertices.
    pub bbox_min: [f32; 3],
    /// Largest x, y, z of the vertices.
    pub bbox_max: [f32; 3],
    /// Vertices where more than one fan of triangles meet (pinch points).
    pub non_manifold_vertices: usize,
    /// Vertices used by no triangle.
    pub unreferenced_vertices: usize,
    /// Smallest interior angle of any non-degenerate triangle, degrees (slivers are below 1).
    pub min_angle_degrees: f64,
}

impl From<&MeshReport> for SoftshellMeshReport {
    fn from(r: &MeshReport) -> Self {
        Self {
            vertex_count: r.vertex_count,
            edge_count: r.edge_count,
            triangle_count: r.triangle_count,
            boundary_edges: r.boundary_edges,
            non_manifold_edges: r.non_manifold_edges,
            degenerate_triangles: r.degenerate_triangles,
            components: r.components,
            genus: r.genus,
            is_closed: r.is_closed,
            is_consistently_oriented: r.is_consistently_oriented,
            area: r.area,
            volume: r.volume,
            bbox_min: r.bbox_min,
            bbox_max: r.bbox_max,
            non_manifold_vertices: r.non_manifold_vertices,
            unreferenced_vertices: r.unreferenced_vertices,
            min_angle_degrees: r.min_angle_degrees,
        }
    }
}

fn hand_out(out_mesh: *mut *mut SoftshellMesh, mesh: TriMesh) {
    let handle = Box::into_raw(Box::new(SoftshellMesh::new(mesh)));
    // SAFETY: out_mesh was checked by out_arg before any work.
    unsafe { write_out(out_mesh, handle) };
}

/// Creates a mesh from arrays: `positions` holds `vertex_count` x,y,z float triples and
/// `triangles` holds `triangle_count` a,b,c index triples (counter-clockwise seen from outside).
/// The arrays are copied; the caller keeps ownership of them.
///
/// Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` if an array is NULL with a non-zero count or
/// `out_mesh` is NULL, `SOFTSHELL_STATUS_INVALID_ARGUMENT` for a count too large to address or
/// a misaligned array, and `SOFTSHELL_STATUS_INVALID_MESH` for an empty mesh, an index out of
/// range or a NaN/inf coordinate (the message names the triangle or vertex). Open,
/// non-manifold and degenerate meshes are accepted: check them with `softshell_mesh_report`.
/// On success `*out_mesh` receives a new handle to free with `softshell_mesh_free`; on failure
/// it is left unchanged.
///
/// # Safety
/// `positions` must be NULL or hold `3 * vertex_count` floats, `triangles` NULL or
/// `3 * triangle_count` uint32_t values, and `out_mesh` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_mesh_from_arrays(
    positions: *const f32,
    vertex_count: usize,
    triangles: *const u32,
    triangle_count: usize,
    out_mesh: *mut *mut SoftshellMesh,
) -> SoftshellStatus {
    status_call("softshell_mesh_from_arrays", || {
        let out_mesh = out_arg(out_mesh, "out_mesh")?;
        let float_count = vertex_count
            .checked_mul(3)
            .ok_or_else(|| Error::invalid_argument(format!("vertex_count {vertex_count} is too large")))?;
        let index_count = triangle_count
            .checked_mul(3)
            .ok_or_else(|| Error::invalid_argument(format!("triangle_count {triangle_count} is too large")))?;
        // SAFETY: the caller promises the lengths.
        let positions = unsafe { arg_slice(positions, float_count, "positions")? };
        // SAFETY: as above.
        let triangles = unsafe { arg_slice(triangles, index_count, "triangles")? };
        hand_out(out_mesh, TriMesh::from_flat(positions, triangles)?);
        Ok(())
    })
}

/// Loads a mesh from a Wavefront OBJ file (UTF-8 or byte path). Polygons are triangulated as
/// fans; all objects and groups are merged; texture coordinates, normals, points and lines are
/// ignored. Vertex k of the mesh is the k-th `v` line of the file, used by a face or not.
///
/// Returns `SOFTSHELL_STATUS_IO` when the file cannot be read or a line is malformed (the
/// message gives `file:line:` and the problem where the line is known; some errors found by
/// the OBJ parser, such as a face index out of bounds, name only the file and the problem),
/// `SOFTSHELL_STATUS_INVALID_MESH` for an empty
/// mesh or NaN/inf coordinates, `SOFTSHELL_STATUS_UNSUPPORTED` when built without the `obj`
/// feature. On success `*out_mesh` receives a new handle; on failure it is left unchanged.
///
/// # Safety
/// `path` must be NULL or a NUL-terminated string; `out_mesh` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_mesh_load_obj(
    path: *const c_char,
    out_mesh: *mut *mut SoftshellMesh,
) -> SoftshellStatus {
    status_call("softshell_mesh_load_obj", || {
        // SAFETY: the caller promises a NUL-terminated string.
        let path = unsafe { arg_path(path, "path")? };
        let out_mesh = out_arg(out_mesh, "out_mesh")?;
        hand_out(out_mesh, load(&path)?);
        Ok(())
    })
}

#[cfg(feature = "obj")]
fn load(path: &std::path::Path) -> Result<TriMesh> {
    crate::mesh::load_obj(path)
}

#[cfg(not(feature = "obj"))]
fn load(_path: &std::path::Path) -> Result<TriMesh> {
    Err(Error::unsupported("OBJ loading", "obj"))
}

/// Writes a mesh as a Wavefront OBJ file (1-based `f a b c` lines, coordinates that read back
/// exactly). Overwrites an existing file. Returns `SOFTSHELL_STATUS_IO` when the file cannot be
/// written, `SOFTSHELL_STATUS_UNSUPPORTED` when built without the `obj` feature.
///
/// # Safety
/// `mesh` must be NULL or a live mesh; `path` NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_mesh_save_obj(mesh: *const SoftshellMesh, path: *const c_char) -> SoftshellStatus {
    status_call("softshell_mesh_save_obj", || {
        // SAFETY: the caller promises a live mesh or NULL.
        let mesh = unsafe { arg_ref(mesh, "mesh")? };
        // SAFETY: the caller promises a NUL-terminated string.
        let path = unsafe { arg_path(path, "path")? };
        save(&mesh.mesh, &path)
    })
}

#[cfg(feature = "obj")]
pub(crate) fn save(mesh: &TriMesh, path: &std::path::Path) -> Result<()> {
    crate::mesh::save_obj(mesh.positions(), mesh.triangles(), path)
}

#[cfg(not(feature = "obj"))]
pub(crate) fn save(_mesh: &TriMesh, _path: &std::path::Path) -> Result<()> {
    Err(Error::unsupported("OBJ writing", "obj"))
}

/// Writes a mesh as an ASCII PLY file with two float properties per vertex, `mean_curvature`
/// and `gaussian_curvature` (as `softshell_mesh_copy_vertex_curvature` computes them), and vertex
/// colours from the one selected by `colour_by` (`SOFTSHELL_CURVATURE_MEAN` or
/// `SOFTSHELL_CURVATURE_GAUSSIAN`): blue for negative, white for zero, red for positive, scaled
/// to the 2nd..98th percentiles. Opens in MeshLab, Blender and ParaView. Overwrites an existing
/// file. Returns `SOFTSHELL_STATUS_INVALID_ARGUMENT` for an unknown `colour_by` and
/// `SOFTSHELL_STATUS_IO` when the file cannot be written.
///
/// # Safety
/// `mesh` must be NULL or a live mesh; `path` NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_mesh_save_ply(
    mesh: *const SoftshellMesh,
    path: *const c_char,
    colour_by: u32,
) -> SoftshellStatus {
    status_call("softshell_mesh_save_ply", || {
        // SAFETY: the caller promises a live mesh or NULL.
        let mesh = unsafe { arg_ref(mesh, "mesh")? };
        // SAFETY: the caller promises a NUL-terminated string.
        let path = unsafe { arg_path(path, "path")? };
        let kind: CurvatureKind =
            arg_kind(colour_by, "colour_by", "SOFTSHELL_CURVATURE_MEAN (0), SOFTSHELL_CURVATURE_GAUSSIAN (1)")?;
        let boundary = mesh.boundary_flags();
        let (positions, triangles) = (mesh.mesh.positions(), mesh.mesh.triangles());
        let as_f32 = |k| -> Vec<f32> {
            vertex_curvature(positions, triangles, Some(&boundary), k).into_iter().map(curvature_f32).collect()
        };
        let (mean, gaussian) = (as_f32(CurvatureKind::Mean), as_f32(CurvatureKind::Gaussian));
        let scalars = [
            VertexScalar { name: "mean_curvature", values: &mean },
            VertexScalar { name: "gaussian_curvature", values: &gaussian },
        ];
        save_ply(positions, triangles, &scalars, if kind == CurvatureKind::Mean { 0 } else { 1 }, &path)
    })
}

/// Destroys a mesh made by `softshell_mesh_from_arrays` or `softshell_mesh_load_obj`.
/// `softshell_mesh_free(NULL)` does nothing. Freeing a mesh twice is undefined behaviour.
///
/// # Safety
/// `mesh` must be NULL or a live mesh that is not used again.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_mesh_free(mesh: *mut SoftshellMesh) {
    value_call("softshell_mesh_free", (), || {
        if !mesh.is_null() {
            // SAFETY: the caller hands back a pointer made by Box::into_raw and never uses it again.
            drop(unsafe { Box::from_raw(mesh) });
        }
    })
}

/// Number of vertices of `mesh`; 0 for NULL.
///
/// # Safety
/// `mesh` must be NULL or a live mesh.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_mesh_vertex_count(mesh: *const SoftshellMesh) -> usize {
    value_call("softshell_mesh_vertex_count", 0, || {
        // SAFETY: the caller promises a live mesh or NULL.
        unsafe { arg_ref(mesh, "mesh") }.map_or(0, |m| m.mesh.vertex_count())
    })
}

/// Number of triangles of `mesh`; 0 for NULL.
///
/// # Safety
/// `mesh` must be NULL or a live mesh.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_mesh_triangle_count(mesh: *const SoftshellMesh) -> usize {
    value_call("softshell_mesh_triangle_count", 0, || {
        // SAFETY: the caller promises a live mesh or NULL.
        unsafe { arg_ref(mesh, "mesh") }.map_or(0, |m| m.mesh.triangle_count())
    })
}

/// Fills `*out` with the counts, topology and measures of `mesh` (see `SoftshellMeshReport`).
/// Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` if either pointer is NULL (then nothing is written).
///
/// # Safety
/// `mesh` must be NULL or a live mesh; `out` NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_mesh_report(
    mesh: *const SoftshellMesh,
    out: *mut SoftshellMeshReport,
) -> SoftshellStatus {
    status_call("softshell_mesh_report", || {
        // SAFETY: the caller promises a live mesh or NULL.
        let mesh = unsafe { arg_ref(mesh, "mesh")? };
        let out = out_arg(out, "out")?;
        let report = MeshReport::new(&mesh.mesh, &mesh.topology);
        // SAFETY: checked by out_arg.
        unsafe { write_out(out, SoftshellMeshReport::from(&report)) };
        Ok(())
    })
}

/// Copies the positions (x,y,z per vertex, `3 * vertex_count` floats) into `out`.
/// If `out` is NULL or `capacity` (in floats) is too small, returns
/// `SOFTSHELL_STATUS_BUFFER_TOO_SMALL`, writes the number of floats needed to `*out_len` and
/// nothing else. On success `*out_len` is the number of floats written. Returns
/// `SOFTSHELL_STATUS_NULL_ARGUMENT`, writing nothing, when the mesh or `out_len` is NULL.
///
/// # Safety
/// `mesh` must be NULL or a live mesh; `out` NULL or `capacity` writable floats; `out_len` NULL
/// or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_mesh_copy_positions(
    mesh: *const SoftshellMesh,
    out: *mut f32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    status_call("softshell_mesh_copy_positions", || {
        // SAFETY: the caller promises a live mesh or NULL.
        let mesh = unsafe { arg_ref(mesh, "mesh")? };
        let positions = mesh.mesh.positions();
        // SAFETY: the caller promises the buffer.
        unsafe {
            copy_out(positions.len() * 3, out, capacity, out_len, |dst| {
                write_triples(dst, positions.iter().map(|p| p.to_array()))
            })
        }
    })
}

/// Copies the triangles (a,b,c per triangle, `3 * triangle_count` uint32_t) into `out`, with the
/// buffer rules of `softshell_mesh_copy_positions` (capacity and `*out_len` count uint32_t).
///
/// # Safety
/// As `softshell_mesh_copy_positions`, with `capacity` writable uint32_t.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_mesh_copy_triangles(
    mesh: *const SoftshellMesh,
    out: *mut u32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    status_call("softshell_mesh_copy_triangles", || {
        // SAFETY: the caller promises a live mesh or NULL.
        let mesh = unsafe { arg_ref(mesh, "mesh")? };
        let triangles = mesh.mesh.triangles();
        // SAFETY: the caller promises the buffer.
        unsafe {
            copy_out(triangles.len() * 3, out, capacity, out_len, |dst| write_triples(dst, triangles.iter().copied()))
        }
    })
}

/// Copies one curvature value per vertex into `out`: `kind` is `SOFTSHELL_CURVATURE_MEAN`
/// (cotangent Laplacian over the mixed Voronoi area) or `SOFTSHELL_CURVATURE_GAUSSIAN` (angle
/// defect over the same area; boundary vertices use pi instead of 2 pi). Degenerate triangles
/// (twice the area at most 1e-9 of the longest side squared) count for nothing, vertices without
/// area get 0, and a value beyond the float range is saturated at +-FLT_MAX. Any other `kind` is
/// `SOFTSHELL_STATUS_INVALID_ARGUMENT`. Buffer rules as `softshell_mesh_copy_positions` (one
/// float per vertex).
///
/// # Safety
/// As `softshell_mesh_copy_positions`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_mesh_copy_vertex_curvature(
    mesh: *const SoftshellMesh,
    kind: u32,
    out: *mut f32,
    capacity: usize,
    out_len: *mut usize,
) -> SoftshellStatus {
    status_call("softshell_mesh_copy_vertex_curvature", || {
        // SAFETY: the caller promises a live mesh or NULL.
        let mesh = unsafe { arg_ref(mesh, "mesh")? };
        let kind: CurvatureKind =
            arg_kind(kind, "kind", "SOFTSHELL_CURVATURE_MEAN (0), SOFTSHELL_CURVATURE_GAUSSIAN (1)")?;
        let n = mesh.mesh.vertex_count();
        let boundary = mesh.boundary_flags();
        // Check the buffer before computing, so a size query costs nothing.
        // SAFETY: the caller promises the buffer; out_len is written in both branches.
        unsafe {
            copy_out(n, out, capacity, out_len, |dst| {
                let values = vertex_curvature(mesh.mesh.positions(), mesh.mesh.triangles(), Some(&boundary), kind);
                for (d, v) in dst.iter_mut().zip(values) {
                    *d = curvature_f32(v);
                }
            })
        }
    })
}
