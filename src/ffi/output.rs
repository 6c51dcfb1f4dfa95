//! Frame output of the simulators, for the tools people open meshes with: PLY files with
//! per-vertex scalars (written as float properties, one of them also as vertex colours) for
//! MeshLab, Blender and ParaView, and OBJ frames for sequences.
//!
//! Every function here only reads its handle. The scalars are computed from the handle's current
//! state by the pure helpers at the bottom (tested against hand-computed values); the files are
//! written by `crate::mesh::save_ply` and `crate::mesh::save_obj`. The lattice is read through
//! its own exported functions, so this file needs nothing private of it.

use std::ffi::{CStr, c_char};
use std::path::Path;

use glam::Vec3;

use super::body::SoftshellBody;
use super::boundary::{SoftshellStatus, arg_path, handle_read, last_error_ptr, status_call};
use super::lattice::{
    SoftshellLattice, softshell_lattice_copy_goals, softshell_lattice_copy_positions, softshell_lattice_copy_triangles,
    softshell_lattice_copy_velocities, softshell_lattice_particle_count, softshell_lattice_triangle_count,
};
use super::shell::SoftshellShell;
use crate::error::{Error, ErrorKind, Result};
#[cfg(any(feature = "shell", feature = "body"))]
use crate::mesh::CurvatureKind;
use crate::mesh::{Topology, VertexScalar, save_ply};

/// `softshell_shell_save_ply` colour: mean curvature H, 1/m (blue concave, red convex).
pub const SOFTSHELL_SHELL_PLY_MEAN_CURVATURE: u32 = 0;
/// `softshell_shell_save_ply` colour: Gaussian curvature K, 1/m^2.
pub const SOFTSHELL_SHELL_PLY_GAUSSIAN_CURVATURE: u32 = 1;
/// `softshell_shell_save_ply` colour: membrane energy per vertex, J (a third of each adjacent
/// face's energy).
pub const SOFTSHELL_SHELL_PLY_ENERGY: u32 = 2;
/// `softshell_shell_save_ply` colour: magnitude of the pressure force on each vertex, N
/// (`|P/3 sum A_j n_j|` over the adjacent faces, SPEC 1.2).
pub const SOFTSHELL_SHELL_PLY_PRESSURE_FORCE: u32 = 3;

/// `softshell_body_save_ply` colour: speed of each vertex, m/s.
pub const SOFTSHELL_BODY_PLY_SPEED: u32 = 0;
/// `softshell_body_save_ply` colour: the fragment (connected piece) of each vertex, coloured so
/// that neighbouring fragment numbers get different colours.
pub const SOFTSHELL_BODY_PLY_FRAGMENT: u32 = 1;
/// `softshell_body_save_ply` colour: mean curvature H of the current surface, 1/m.
pub const SOFTSHELL_BODY_PLY_MEAN_CURVATURE: u32 = 2;

/// `softshell_lattice_save_ply` colour: height y of each particle, m (the displacement from the
/// rest plane y = 0).
pub const SOFTSHELL_LATTICE_PLY_HEIGHT: u32 = 0;
/// `softshell_lattice_save_ply` colour: speed of each particle, m/s.
pub const SOFTSHELL_LATTICE_PLY_SPEED: u32 = 1;
/// `softshell_lattice_save_ply` colour: distance from each particle to its shape-matching goal
/// |g - x|, m (how strained the sheet is there).
pub const SOFTSHELL_LATTICE_PLY_GOAL_DISTANCE: u32 = 2;

/// Checks a `colour_by` selector against the scalars a writer offers.
fn colour_index(value: u32, constants: &[&str]) -> Result<usize> {
    if (value as usize) < constants.len() {
        return Ok(value as usize);
    }
    let allowed: Vec<String> = constants.iter().enumerate().map(|(i, c)| format!("{c} ({i})")).collect();
    Err(Error::invalid_argument(format!(
        "`colour_by` = {value} is not a known value; use one of {}",
        allowed.join(", ")
    )))
}

#[cfg(feature = "obj")]
fn write_obj(positions: &[Vec3], triangles: &[[u32; 3]], path: &Path) -> Result<()> {
    crate::mesh::save_obj(positions, triangles, path)
}

#[cfg(not(feature = "obj"))]
fn write_obj(_positions: &[Vec3], _triangles: &[[u32; 3]], _path: &Path) -> Result<()> {
    Err(Error::unsupported("OBJ output", "obj"))
}

// ---------------------------------------------------------------------------------------------
// Shell

/// Writes the shell's current shape as an ASCII PLY file with four float properties per
/// vertex: `mean_curvature` (1/m), `gaussian_curvature` (1/m^2), `energy` (membrane energy, J: a
/// third of each adjacent triangle's, so the vertex values sum to the total) and
/// `pressure_force` (N, the magnitude of the pressure force of SPEC 1.2), and vertex colours
/// from the one selected by `colour_by` (`SOFTSHELL_SHELL_PLY_MEAN_CURVATURE`,
/// `_GAUSSIAN_CURVATURE`, `_ENERGY` or `_PRESSURE_FORCE`): blue-white-red for signed values,
/// dark blue to yellow otherwise, scaled to the 2nd..98th percentiles. These are the pictures of
/// the paper's Fig. 8 and 10. Overwrites an existing file.
///
/// Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` for a NULL shell or path,
/// `SOFTSHELL_STATUS_INVALID_ARGUMENT` for an unknown `colour_by` or an empty path,
/// `SOFTSHELL_STATUS_IO` when the
/// file cannot be written, `SOFTSHELL_STATUS_UNSUPPORTED` without the `shell` feature. The shell
/// is not changed.
///
/// # Safety
/// `shell` must be NULL or a live shell; `path` NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_shell_save_ply(
    shell: *const SoftshellShell,
    path: *const c_char,
    colour_by: u32,
) -> SoftshellStatus {
    handle_read("softshell_shell_save_ply", shell, "shell", |shell| {
        // SAFETY: the caller promises a NUL-terminated string or NULL.
        let path = unsafe { arg_path(path, "path")? };
        let colour = colour_index(
            colour_by,
            &[
                "SOFTSHELL_SHELL_PLY_MEAN_CURVATURE",
                "SOFTSHELL_SHELL_PLY_GAUSSIAN_CURVATURE",
                "SOFTSHELL_SHELL_PLY_ENERGY",
                "SOFTSHELL_SHELL_PLY_PRESSURE_FORCE",
            ],
        )?;
        #[cfg(feature = "shell")]
        {
            let inner = &shell.inner;
            let (positions, triangles) = (inner.positions(), inner.triangles());
            let as_f32 = |values: Vec<f64>| -> Vec<f32> { values.into_iter().map(|v| v as f32).collect() };
            let mean = as_f32(inner.vertex_curvature(CurvatureKind::Mean));
            let gaussian = as_f32(inner.vertex_curvature(CurvatureKind::Gaussian));
            let energy = spread_to_vertices(triangles, &inner.face_energy(), positions.len());
            let force = pressure_force_magnitude(positions, triangles, inner.settings().pressure);
            let scalars = [
                VertexScalar { name: "mean_curvature", values: &mean },
                VertexScalar { name: "gaussian_curvature", values: &gaussian },
                VertexScalar { name: "energy", values: &energy },
                VertexScalar { name: "pressure_force", values: &force },
            ];
            save_ply(positions, triangles, &scalars, colour, &path)
        }
        #[cfg(not(feature = "shell"))]
        {
            let _ = (shell, path, colour);
            Err(Error::unsupported("the shell simulator", "shell"))
        }
    })
}

/// Writes the shell's current shape as a Wavefront OBJ file (1-based `f a b c` lines, the
/// mesh's triangles): one file per frame makes a sequence that Blender and MeshLab import.
/// Overwrites an existing file. Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` for a NULL shell or path,
/// `SOFTSHELL_STATUS_INVALID_ARGUMENT` for an empty path, `SOFTSHELL_STATUS_IO` when the file
/// cannot be written, `SOFTSHELL_STATUS_UNSUPPORTED` without the `shell` or `obj` feature.
///
/// # Safety
/// `shell` must be NULL or a live shell; `path` NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_shell_save_obj(
    shell: *const SoftshellShell,
    path: *const c_char,
) -> SoftshellStatus {
    handle_read("softshell_shell_save_obj", shell, "shell", |shell| {
        // SAFETY: the caller promises a NUL-terminated string or NULL.
        let path = unsafe { arg_path(path, "path")? };
        #[cfg(feature = "shell")]
        {
            write_obj(shell.inner.positions(), shell.inner.triangles(), &path)
        }
        #[cfg(not(feature = "shell"))]
        {
            let _ = (shell, path);
            Err(Error::unsupported("the shell simulator", "shell"))
        }
    })
}

// ---------------------------------------------------------------------------------------------
// Body

/// Writes the body's current surface (after fracture: every piece, split vertices included) as
/// an ASCII PLY file with four float properties per vertex, in this order: `speed` (m/s),
/// `fragment_shade` (a value in [0, 1) that differs between neighbouring fragment numbers, for
/// colours), `mean_curvature` (1/m) and `fragment` (the connected piece, as
/// `softshell_body_copy_fragment_ids` numbers them; -1 for a vertex no triangle uses), and
/// vertex colours from the one
/// selected by `colour_by` (`SOFTSHELL_BODY_PLY_SPEED`, `_FRAGMENT` or `_MEAN_CURVATURE`).
/// Overwrites an existing file.
///
/// Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` for a NULL body or path,
/// `SOFTSHELL_STATUS_INVALID_ARGUMENT` for an unknown `colour_by` or an empty path,
/// `SOFTSHELL_STATUS_IO` when the
/// file cannot be written, `SOFTSHELL_STATUS_UNSUPPORTED` without the `body` feature. The body is
/// not changed.
///
/// # Safety
/// `body` must be NULL or a live body; `path` NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_save_ply(
    body: *const SoftshellBody,
    path: *const c_char,
    colour_by: u32,
) -> SoftshellStatus {
    handle_read("softshell_body_save_ply", body, "body", |body| {
        // SAFETY: the caller promises a NUL-terminated string or NULL.
        let path = unsafe { arg_path(path, "path")? };
        let colour = colour_index(
            colour_by,
            &["SOFTSHELL_BODY_PLY_SPEED", "SOFTSHELL_BODY_PLY_FRAGMENT", "SOFTSHELL_BODY_PLY_MEAN_CURVATURE"],
        )?;
        #[cfg(feature = "body")]
        {
            let inner = &body.body;
            let (positions, triangles): (Vec<_>, Vec<_>) = (inner.positions().collect(), inner.triangles().collect());
            let (positions, triangles) = (&positions[..], &triangles[..]);
            let speed: Vec<f32> = inner.velocities().map(|v| v.as_dvec3().length() as f32).collect();
            let fragment = fragment_per_vertex(triangles, inner.fragment_ids(), positions.len());
            let shade: Vec<f32> = fragment.iter().map(|&f| fragment_shade(f)).collect();
            let boundary = boundary_flags(triangles, positions.len());
            let mean: Vec<f32> =
                crate::mesh::vertex_curvature(positions, triangles, Some(&boundary), CurvatureKind::Mean)
                    .into_iter()
                    .map(|v| v as f32)
                    .collect();
            // The colour of FRAGMENT comes from the shade; the other selectors map one to one.
            let scalars = [
                VertexScalar { name: "speed", values: &speed },
                VertexScalar { name: "fragment_shade", values: &shade },
                VertexScalar { name: "mean_curvature", values: &mean },
                VertexScalar { name: "fragment", values: &fragment },
            ];
            save_ply(positions, triangles, &scalars, colour, &path)
        }
        #[cfg(not(feature = "body"))]
        {
            let _ = (body, path, colour);
            Err(Error::unsupported("the soft body simulator", "body"))
        }
    })
}

/// Writes the body's current surface as a Wavefront OBJ file (every piece; vertex k is vertex k
/// of `softshell_body_copy_positions`). Overwrites an existing file. Returns
/// `SOFTSHELL_STATUS_NULL_ARGUMENT` for a NULL body or path, `SOFTSHELL_STATUS_INVALID_ARGUMENT`
/// for an empty path, `SOFTSHELL_STATUS_IO` when the file cannot be written,
/// `SOFTSHELL_STATUS_UNSUPPORTED` without the `body` or `obj` feature.
///
/// # Safety
/// `body` must be NULL or a live body; `path` NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_body_save_obj(body: *const SoftshellBody, path: *const c_char) -> SoftshellStatus {
    handle_read("softshell_body_save_obj", body, "body", |body| {
        // SAFETY: the caller promises a NUL-terminated string or NULL.
        let path = unsafe { arg_path(path, "path")? };
        #[cfg(feature = "body")]
        {
            write_obj(&body.body.positions().collect::<Vec<_>>(), &body.body.triangles().collect::<Vec<_>>(), &path)
        }
        #[cfg(not(feature = "body"))]
        {
            let _ = (body, path);
            Err(Error::unsupported("the soft body simulator", "body"))
        }
    })
}

// ---------------------------------------------------------------------------------------------
// Lattice (read through its exported functions)

/// Turns the status of an inner exported call back into a `Result` with its message.
fn inner_status(status: SoftshellStatus) -> Result<()> {
    let kind = match status {
        SoftshellStatus::Ok => return Ok(()),
        SoftshellStatus::NullArgument => ErrorKind::NullArgument,
        SoftshellStatus::InvalidArgument => ErrorKind::InvalidArgument,
        SoftshellStatus::InvalidMesh => ErrorKind::InvalidMesh,
        SoftshellStatus::Io => ErrorKind::Io,
        SoftshellStatus::BufferTooSmall => ErrorKind::BufferTooSmall,
        SoftshellStatus::Unstable => ErrorKind::Unstable,
        SoftshellStatus::Unsupported => ErrorKind::Unsupported,
        SoftshellStatus::Poisoned => ErrorKind::Poisoned,
        SoftshellStatus::Internal => ErrorKind::Internal,
    };
    // SAFETY: the message stays valid until the next failing call on this thread.
    let message = unsafe { CStr::from_ptr(last_error_ptr()) }.to_string_lossy().into_owned();
    Err(Error::new(kind, message))
}

/// Copies `len` elements with an exported `(out, capacity, out_len)` function.
fn copy_lattice<T: Copy + Default>(
    lattice: *const SoftshellLattice,
    len: usize,
    copy: unsafe extern "C" fn(*const SoftshellLattice, *mut T, usize, *mut usize) -> SoftshellStatus,
) -> Result<Vec<T>> {
    let mut out = vec![T::default(); len];
    let mut written = 0usize;
    // SAFETY: `lattice` is the caller's live lattice (checked non-NULL); `out` holds `len`
    // elements and `written` is a live local.
    inner_status(unsafe { copy(lattice, out.as_mut_ptr(), len, &mut written) })?;
    out.truncate(written);
    Ok(out)
}

/// The lattice's particles and triangles as a mesh. The first copy checks the lattice (NULL,
/// poisoned) and reports its status.
fn lattice_mesh(lattice: *const SoftshellLattice) -> Result<(Vec<Vec3>, Vec<[u32; 3]>)> {
    // SAFETY: the caller promises a live lattice or NULL; the counts accept NULL.
    let (particles, triangles) =
        unsafe { (softshell_lattice_particle_count(lattice), softshell_lattice_triangle_count(lattice)) };
    let flat = copy_lattice(lattice, 3 * particles, softshell_lattice_copy_positions)?;
    let indices = copy_lattice(lattice, 3 * triangles, softshell_lattice_copy_triangles)?;
    Ok((to_vec3(&flat), indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect()))
}

fn to_vec3(flat: &[f32]) -> Vec<Vec3> {
    flat.chunks_exact(3).map(Vec3::from_slice).collect()
}

/// Writes the lattice's current sheet (its triangulated grid) as an ASCII PLY file with three
/// float properties per particle: `height` (y, m: the displacement from the rest plane),
/// `speed` (m/s) and `goal_distance` (|g - x|, m: where the sheet is strained), and vertex
/// colours from the one selected by `colour_by` (`SOFTSHELL_LATTICE_PLY_HEIGHT`, `_SPEED` or
/// `_GOAL_DISTANCE`). Computing the goals costs about one step. Overwrites an existing file.
///
/// Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` for a NULL lattice or path,
/// `SOFTSHELL_STATUS_INVALID_ARGUMENT` for an unknown `colour_by` or an empty path,
/// `SOFTSHELL_STATUS_IO` when the
/// file cannot be written, `SOFTSHELL_STATUS_UNSUPPORTED` without the `lattice` feature. The
/// lattice is not changed.
///
/// # Safety
/// `lattice` must be NULL or a live lattice; `path` NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_save_ply(
    lattice: *const SoftshellLattice,
    path: *const c_char,
    colour_by: u32,
) -> SoftshellStatus {
    status_call("softshell_lattice_save_ply", || {
        // SAFETY: the caller promises a NUL-terminated string or NULL.
        let path = unsafe { arg_path(path, "path")? };
        let colour = colour_index(
            colour_by,
            &["SOFTSHELL_LATTICE_PLY_HEIGHT", "SOFTSHELL_LATTICE_PLY_SPEED", "SOFTSHELL_LATTICE_PLY_GOAL_DISTANCE"],
        )?;
        let (positions, triangles) = lattice_mesh(lattice)?;
        let n = positions.len();
        let velocities = to_vec3(&copy_lattice(lattice, 3 * n, softshell_lattice_copy_velocities)?);
        let goals = to_vec3(&copy_lattice(lattice, 3 * n, softshell_lattice_copy_goals)?);
        let height: Vec<f32> = positions.iter().map(|p| p.y).collect();
        let speed: Vec<f32> = velocities.iter().map(|v| v.as_dvec3().length() as f32).collect();
        let goal_distance: Vec<f32> =
            positions.iter().zip(&goals).map(|(p, g)| p.as_dvec3().distance(g.as_dvec3()) as f32).collect();
        let scalars = [
            VertexScalar { name: "height", values: &height },
            VertexScalar { name: "speed", values: &speed },
            VertexScalar { name: "goal_distance", values: &goal_distance },
        ];
        save_ply(&positions, &triangles, &scalars, colour, &path)
    })
}

/// Writes the lattice's current sheet (its triangulated grid, as
/// `softshell_lattice_copy_triangles`) as a Wavefront OBJ file. Overwrites an existing file.
/// Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` for a NULL lattice or path,
/// `SOFTSHELL_STATUS_INVALID_ARGUMENT` for an empty path, `SOFTSHELL_STATUS_IO` when the file
/// cannot be written, `SOFTSHELL_STATUS_UNSUPPORTED` without the `lattice` or `obj` feature.
///
/// # Safety
/// `lattice` must be NULL or a live lattice; `path` NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_lattice_save_obj(
    lattice: *const SoftshellLattice,
    path: *const c_char,
) -> SoftshellStatus {
    status_call("softshell_lattice_save_obj", || {
        // SAFETY: the caller promises a NUL-terminated string or NULL.
        let path = unsafe { arg_path(path, "path")? };
        let (positions, triangles) = lattice_mesh(lattice)?;
        write_obj(&positions, &triangles, &path)
    })
}

// ---------------------------------------------------------------------------------------------
// Per-vertex scalars (pure functions)

/// Spreads per-triangle values to the vertices, a third of each to each corner (so the vertex
/// values sum to the triangle values).
#[cfg_attr(not(feature = "shell"), allow(dead_code))]
fn spread_to_vertices(triangles: &[[u32; 3]], face_values: &[f32], vertex_count: usize) -> Vec<f32> {
    let mut out = vec![0.0f64; vertex_count];
    for (t, &value) in triangles.iter().zip(face_values) {
        for &v in t {
            out[v as usize] += f64::from(value) / 3.0;
        }
    }
    out.into_iter().map(|v| v as f32).collect()
}

/// `|f_i|` with `f_i = -P sum_j (1/3) A_j n_j` over the triangles j around vertex i (SPEC 1.2).
#[cfg_attr(not(feature = "shell"), allow(dead_code))]
fn pressure_force_magnitude(positions: &[Vec3], triangles: &[[u32; 3]], pressure: f32) -> Vec<f32> {
    let mut sums = vec![glam::DVec3::ZERO; positions.len()];
    for (t, twice_area_normal) in triangles.iter().zip(crate::mesh::face_area_vectors(positions, triangles)) {
        for &v in t {
            sums[v as usize] += twice_area_normal / 6.0; // (1/3) A n = (1/6) (twice the area) n
        }
    }
    sums.into_iter().map(|s| (f64::from(pressure).abs() * s.length()) as f32).collect()
}

/// For each vertex, the fragment of a triangle that uses it (-1 for an unused vertex).
#[cfg_attr(not(feature = "body"), allow(dead_code))]
fn fragment_per_vertex(triangles: &[[u32; 3]], fragment_ids: &[u32], vertex_count: usize) -> Vec<f32> {
    let mut out = vec![-1.0f32; vertex_count];
    for (t, &fragment) in triangles.iter().zip(fragment_ids) {
        for &v in t {
            out[v as usize] = fragment as f32;
        }
    }
    out
}

/// A shade in [0, 1) from a fragment number: golden-ratio steps, so neighbouring numbers get
/// far-apart colours; 0 for -1 (no fragment).
#[cfg_attr(not(feature = "body"), allow(dead_code))]
fn fragment_shade(fragment: f32) -> f32 {
    if fragment < 0.0 {
        return 0.0;
    }
    ((f64::from(fragment) * 0.618_033_988_749_895 + 0.1).fract()) as f32
}

/// For each vertex, whether it lies on a boundary (an edge used by one triangle): the curvature
/// of such vertices uses the boundary's angle sum.
#[cfg_attr(not(feature = "body"), allow(dead_code))]
fn boundary_flags(triangles: &[[u32; 3]], vertex_count: usize) -> Vec<bool> {
    let topology = Topology::build(triangles, vertex_count);
    let mut boundary = vec![false; vertex_count];
    for (edge, &count) in topology.edges.iter().zip(&topology.edge_face_count) {
        if count == 1 {
            boundary[edge[0] as usize] = true;
            boundary[edge[1] as usize] = true;
        }
    }
    boundary
}

#[cfg(test)]
mod tests {
    use super::*;

    const TETRA: [[u32; 3]; 4] = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];

    fn tetra() -> Vec<Vec3> {
        vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z]
    }

    #[test]
    fn spreading_keeps_the_total() {
        let v = spread_to_vertices(&TETRA, &[3.0, 6.0, 9.0, 12.0], 4);
        assert!((v.iter().sum::<f32>() - 30.0).abs() < 1e-5);
        // Vertex 0 is in faces 0, 1, 3: (3 + 6 + 12) / 3.
        assert!((v[0] - 7.0).abs() < 1e-6);
    }

    #[test]
    fn pressure_force_is_the_volume_gradient_times_pressure() {
        // Finite differences of P V at vertex 3 of the tetrahedron.
        let p = tetra();
        let f = pressure_force_magnitude(&p, &TETRA, 2.0);
        let volume = |q: &[Vec3]| crate::mesh::signed_volume(q, &TETRA);
        let h = 1e-3f32;
        let mut grad = [0.0f64; 3];
        for (axis, g) in grad.iter_mut().enumerate() {
            let (mut plus, mut minus) = (p.clone(), p.clone());
            plus[3][axis] += h;
            minus[3][axis] -= h;
            *g = 2.0 * (volume(&plus) - volume(&minus)) / (2.0 * f64::from(h));
        }
        let expected = (grad[0] * grad[0] + grad[1] * grad[1] + grad[2] * grad[2]).sqrt();
        assert!((f64::from(f[3]) - expected).abs() < 1e-4 * expected, "{} vs {expected}", f[3]);
        // Pressure 0: no force anywhere.
        assert!(pressure_force_magnitude(&p, &TETRA, 0.0).iter().all(|&x| x == 0.0));
    }

    #[test]
    fn fragments_boundaries_and_shades() {
        let fragment = fragment_per_vertex(&[[0, 1, 2], [3, 4, 5]], &[0, 1], 7);
        assert_eq!(fragment, vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0, -1.0]);
        let shades: Vec<f32> = (0..5).map(|f| fragment_shade(f as f32)).collect();
        assert!(shades.iter().all(|s| (0.0..1.0).contains(s)));
        assert!(shades.windows(2).all(|w| (w[0] - w[1]).abs() > 0.2), "{shades:?}");
        assert_eq!(boundary_flags(&TETRA, 4), vec![false; 4]);
        assert_eq!(boundary_flags(&TETRA[..1], 4), vec![true, true, true, false]);
    }

    #[test]
    fn unknown_colour_names_the_choices() {
        let error = colour_index(3, &["A", "B"]).unwrap_err();
        assert_eq!(error.kind, ErrorKind::InvalidArgument);
        assert!(error.message.contains("A (0), B (1)"), "{}", error.message);
        assert_eq!(colour_index(1, &["A", "B"]).unwrap(), 1);
    }
}
