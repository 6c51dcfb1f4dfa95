//! The mesh part of the C ABI, driven only through its exported functions: NULLs, short
//! buffers, unknown kinds, NaNs, bad indices, open/non-manifold/degenerate meshes, every report
//! field on a tetrahedron, a cube, a torus and the kitten, OBJ input/output, versions.

mod common;

use std::ffi::{CStr, CString};
use std::ptr;

use common::*;
use softshell::ffi::SoftshellStatus;
use softshell::ffi::mesh::*;
use softshell::ffi::version::*;

const TETRA_POSITIONS: [f32; 12] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
const TETRA_TRIANGLES: [u32; 12] = [0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2];

fn report(mesh: *const SoftshellMesh) -> SoftshellMeshReport {
    let mut out = std::mem::MaybeUninit::<SoftshellMeshReport>::uninit();
    // SAFETY: live mesh and writable report.
    let status = unsafe { softshell_mesh_report(mesh, out.as_mut_ptr()) };
    assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
    // SAFETY: written on success.
    unsafe { out.assume_init() }
}

fn report_of(positions: &[f32], triangles: &[u32]) -> SoftshellMeshReport {
    let mesh = mesh_from(positions, triangles).unwrap();
    let r = report(mesh);
    // SAFETY: made above.
    unsafe { softshell_mesh_free(mesh) };
    r
}

fn cube() -> (Vec<f32>, Vec<u32>) {
    let mut p = Vec::new();
    for i in 0..8u32 {
        p.extend([(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32]);
    }
    // Two counter-clockwise (from outside) triangles per face.
    let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let mut t = Vec::new();
    for q in quads {
        t.extend([q[0], q[1], q[2], q[0], q[2], q[3]]);
    }
    (p, t)
}

#[test]
fn tetrahedron_report_every_field() {
    let r = report_of(&TETRA_POSITIONS, &TETRA_TRIANGLES);
    assert_eq!((r.vertex_count, r.edge_count, r.triangle_count), (4, 6, 4));
    assert_eq!((r.boundary_edges, r.non_manifold_edges, r.degenerate_triangles, r.components), (0, 0, 0, 1));
    assert_eq!(r.genus, 0);
    assert!(r.is_closed && r.is_consistently_oriented);
    assert!((r.area - (1.5 + 3f64.sqrt() / 2.0)).abs() < 1e-6, "area {}", r.area);
    assert!((r.volume - 1.0 / 6.0).abs() < 1e-12, "volume {}", r.volume);
    assert_eq!(r.bbox_min, [0.0, 0.0, 0.0]);
    assert_eq!(r.bbox_max, [1.0, 1.0, 1.0]);
    assert_eq!((r.non_manifold_vertices, r.unreferenced_vertices), (0, 0));
    assert!((r.min_angle_degrees - 45.0).abs() < 1e-4);
}

#[test]
fn cube_report_every_field() {
    let (p, t) = cube();
    let r = report_of(&p, &t);
    assert_eq!((r.vertex_count, r.edge_count, r.triangle_count), (8, 18, 12));
    assert_eq!((r.boundary_edges, r.non_manifold_edges, r.degenerate_triangles, r.components), (0, 0, 0, 1));
    assert_eq!(r.genus, 0);
    assert!(r.is_closed && r.is_consistently_oriented);
    assert!((r.area - 6.0).abs() < 1e-9);
    assert!((r.volume - 1.0).abs() < 1e-12);
    assert_eq!((r.bbox_min, r.bbox_max), ([0.0; 3], [1.0; 3]));
    assert!((r.min_angle_degrees - 45.0).abs() < 1e-4);
}

#[cfg(feature = "obj")]
#[test]
fn torus_report_every_field() {
    let mesh = load_data_mesh("torus.obj");
    let r = report(mesh);
    assert_eq!((r.vertex_count, r.edge_count, r.triangle_count), (1200, 3600, 2400));
    assert_eq!((r.boundary_edges, r.non_manifold_edges, r.degenerate_triangles, r.components), (0, 0, 0, 1));
    assert_eq!(r.genus, 1);
    assert!(r.is_closed && r.is_consistently_oriented);
    // data/SOURCES.md: V_mesh = 1.2113 (2 pi^2 R r^2 = 1.2337 for the smooth torus).
    assert!((r.volume - 1.2113).abs() < 1e-3, "volume {}", r.volume);
    // A torus R = 1, r = 0.25 has area 4 pi^2 R r = 9.87; the mesh is inscribed, a little less.
    assert!(r.area > 9.6 && r.area < 9.87, "area {}", r.area);
    assert!((r.bbox_max[0] - 1.25).abs() < 1e-3 && (r.bbox_min[0] + 1.25).abs() < 1e-3);
    assert!((r.bbox_max[2] - r.bbox_min[2] - 0.5).abs() < 1e-2 || (r.bbox_max[1] - r.bbox_min[1] - 0.5).abs() < 1e-2);
    assert!((r.min_angle_degrees - 31.0).abs() < 0.5, "min angle {}", r.min_angle_degrees);
    // SAFETY: made by load_data_mesh.
    unsafe { softshell_mesh_free(mesh) };
}

#[cfg(feature = "obj")]
#[test]
fn kitten_report_every_field() {
    let mesh = load_data_mesh("kitten.obj");
    let r = report(mesh);
    assert_eq!((r.vertex_count, r.edge_count, r.triangle_count), (10000, 30000, 20000));
    assert_eq!((r.boundary_edges, r.non_manifold_edges, r.degenerate_triangles, r.components), (0, 0, 0, 1));
    assert_eq!(r.genus, 1);
    assert!(r.is_closed && r.is_consistently_oriented);
    assert!(r.volume > 0.99 && r.volume < 1.0, "volume {}", r.volume);
    assert!(r.area > 6.7 && r.area < 6.8, "area {}", r.area);
    // data/SOURCES.md: (-0.651,-0.999,-0.591) .. (0.651,0.998,0.591), min angle 7.7 degrees.
    for (got, want) in r.bbox_min.iter().zip([-0.651, -0.999, -0.591]) {
        assert!((got - want).abs() < 1e-3, "bbox_min {:?}", r.bbox_min);
    }
    for (got, want) in r.bbox_max.iter().zip([0.651, 0.998, 0.591]) {
        assert!((got - want).abs() < 1e-3, "bbox_max {:?}", r.bbox_max);
    }
    assert!((r.min_angle_degrees - 7.7).abs() < 0.05, "min angle {}", r.min_angle_degrees);
    // SAFETY: made by load_data_mesh.
    unsafe { softshell_mesh_free(mesh) };
}

#[cfg(feature = "obj")]
#[test]
fn genus_two_and_the_other_shared_meshes() {
    for (name, genus) in [("eight.obj", 2), ("hand.obj", 0), ("bear.obj", 0), ("wapiti_elk.obj", 1), ("sphere.obj", 0)]
    {
        let mesh = load_data_mesh(name);
        let r = report(mesh);
        assert_eq!(r.genus, genus, "{name}");
        assert!(r.is_closed && r.is_consistently_oriented && r.volume > 0.0, "{name}");
        // SAFETY: made by load_data_mesh.
        unsafe { softshell_mesh_free(mesh) };
    }
}

#[test]
fn open_mesh_is_accepted_and_reported() {
    let r = report_of(&TETRA_POSITIONS, &TETRA_TRIANGLES[..9]);
    assert_eq!(r.boundary_edges, 3);
    assert!(!r.is_closed);
    assert!(r.is_consistently_oriented);
    assert_eq!(r.genus, -1);
    assert_eq!(r.edge_count, 6);
}

#[test]
fn non_manifold_edge_and_vertex_are_reported() {
    // Three triangles on edge (0, 1).
    let p = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.5, -1.0, 0.0, 0.5, 0.0, 1.0];
    let r = report_of(&p, &[0, 1, 2, 1, 0, 3, 0, 1, 4]);
    assert_eq!(r.non_manifold_edges, 1);
    assert!(!r.is_closed);
    assert_eq!(r.genus, -1);

    // Two tetrahedra touching at vertex 0: closed edges, but vertex 0 is a pinch.
    let mut p = TETRA_POSITIONS.to_vec();
    p.extend([-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0]);
    let mut t = TETRA_TRIANGLES.to_vec();
    t.extend([0, 5, 4, 0, 4, 6, 4, 5, 6, 0, 6, 5]);
    let r = report_of(&p, &t);
    assert!(r.is_closed);
    assert_eq!(r.non_manifold_vertices, 1);
    assert_eq!(r.genus, -1);
}

#[test]
fn degenerate_and_flipped_triangles_are_reported() {
    // A zero-area triangle (collinear corners) and one with a repeated index beside a good one.
    let p = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let r = report_of(&p, &[0, 1, 2, 0, 0, 3, 0, 1, 3]);
    assert_eq!(r.degenerate_triangles, 2);

    let mut flipped = TETRA_TRIANGLES;
    flipped.swap(7, 8); // triangle 2 becomes (1, 3, 2)
    let r = report_of(&TETRA_POSITIONS, &flipped);
    assert!(r.is_closed);
    assert!(!r.is_consistently_oriented);
    assert_eq!(r.genus, -1);

    // Inward winding everywhere: consistent, closed, negative volume.
    let inward: Vec<u32> = TETRA_TRIANGLES.chunks(3).flat_map(|t| [t[0], t[2], t[1]]).collect();
    let r = report_of(&TETRA_POSITIONS, &inward);
    assert!(r.is_consistently_oriented && r.volume < 0.0);
}

#[test]
fn unreferenced_vertices_and_components() {
    let mut p = TETRA_POSITIONS.to_vec();
    p.extend([5.0, 5.0, 5.0]);
    let mut t = TETRA_TRIANGLES.to_vec();
    // A second tetrahedron, shifted, as another component.
    p.extend(TETRA_POSITIONS.iter().enumerate().map(|(i, &x)| if i % 3 == 0 { x + 3.0 } else { x }));
    t.extend(TETRA_TRIANGLES.iter().map(|&v| v + 5));
    let r = report_of(&p, &t);
    assert_eq!((r.vertex_count, r.unreferenced_vertices, r.components, r.genus), (9, 1, 2, 0));
    assert!((r.volume - 2.0 / 6.0).abs() < 1e-9);
}

#[test]
fn bad_arrays_are_refused_naming_the_offender_and_output_untouched() {
    let sentinel = ptr::NonNull::<SoftshellMesh>::dangling().as_ptr();
    let mut out = sentinel;
    let mut bad = TETRA_TRIANGLES;
    bad[7] = 4;
    // SAFETY: valid arrays; out is a local.
    let status = unsafe { softshell_mesh_from_arrays(TETRA_POSITIONS.as_ptr(), 4, bad.as_ptr(), 4, &mut out) };
    assert_eq!(status, SoftshellStatus::InvalidMesh);
    assert!(last_error().contains("triangle 2") && last_error().contains("index 4"), "{}", last_error());
    assert_eq!(out, sentinel, "a failing call must not write its output");

    for (value, word) in [(f32::NAN, "NaN"), (f32::INFINITY, "inf"), (f32::NEG_INFINITY, "-inf")] {
        let mut p = TETRA_POSITIONS;
        p[4] = value;
        let error = mesh_from(&p, &TETRA_TRIANGLES).unwrap_err();
        assert_eq!(error.0, SoftshellStatus::InvalidMesh);
        assert!(error.1.contains("vertex 1") && error.1.contains(word), "{}", error.1);
    }

    let error = mesh_from(&[], &[]).unwrap_err();
    assert_eq!(error.0, SoftshellStatus::InvalidMesh);
    assert!(error.1.contains("no vertices"), "{}", error.1);
    let error = mesh_from(&TETRA_POSITIONS, &[]).unwrap_err();
    assert!(error.1.contains("no triangles"), "{}", error.1);
}

#[test]
fn null_arguments() {
    let mut out = ptr::null_mut();
    // SAFETY: NULL arrays with non-zero counts must be refused without dereferencing.
    unsafe {
        assert_eq!(
            softshell_mesh_from_arrays(ptr::null(), 4, TETRA_TRIANGLES.as_ptr(), 4, &mut out),
            SoftshellStatus::NullArgument
        );
        assert!(last_error().contains("positions"), "{}", last_error());
        assert_eq!(
            softshell_mesh_from_arrays(TETRA_POSITIONS.as_ptr(), 4, ptr::null(), 4, &mut out),
            SoftshellStatus::NullArgument
        );
        assert!(last_error().contains("triangles"));
        let status =
            softshell_mesh_from_arrays(TETRA_POSITIONS.as_ptr(), 4, TETRA_TRIANGLES.as_ptr(), 4, ptr::null_mut());
        assert_eq!(status, SoftshellStatus::NullArgument);
        assert!(last_error().contains("out_mesh"));
        // Overflowing counts are refused, not wrapped.
        let status =
            softshell_mesh_from_arrays(TETRA_POSITIONS.as_ptr(), usize::MAX, TETRA_TRIANGLES.as_ptr(), 4, &mut out);
        assert_eq!(status, SoftshellStatus::InvalidArgument);
        assert!(out.is_null());

        let mut r = std::mem::MaybeUninit::uninit();
        assert_eq!(softshell_mesh_report(ptr::null(), r.as_mut_ptr()), SoftshellStatus::NullArgument);
        assert_eq!(softshell_mesh_vertex_count(ptr::null()), 0);
        assert_eq!(softshell_mesh_triangle_count(ptr::null()), 0);
        softshell_mesh_free(ptr::null_mut());
        assert_eq!(softshell_mesh_load_obj(ptr::null(), &mut out), SoftshellStatus::NullArgument);
        let mut len = 0;
        assert_eq!(
            softshell_mesh_copy_positions(ptr::null(), ptr::null_mut(), 0, &mut len),
            SoftshellStatus::NullArgument
        );
    }
    let mesh = mesh_from(&TETRA_POSITIONS, &TETRA_TRIANGLES).unwrap();
    // SAFETY: live mesh; NULL outputs must be refused.
    unsafe {
        assert_eq!(softshell_mesh_report(mesh, ptr::null_mut()), SoftshellStatus::NullArgument);
        assert!(last_error().contains("`out`"), "{}", last_error());
        let mut buffer = [0.0f32; 12];
        let status = softshell_mesh_copy_positions(mesh, buffer.as_mut_ptr(), 12, ptr::null_mut());
        assert_eq!(status, SoftshellStatus::NullArgument);
        assert_eq!(buffer, [0.0; 12], "nothing is written when out_len is NULL");
        assert_eq!(softshell_mesh_save_obj(mesh, ptr::null()), SoftshellStatus::NullArgument);
        assert_eq!(softshell_mesh_vertex_count(mesh), 4);
        assert_eq!(softshell_mesh_triangle_count(mesh), 4);
        softshell_mesh_free(mesh);
    }
}

#[test]
fn short_buffers_report_the_size_needed_and_write_nothing() {
    let mesh = mesh_from(&TETRA_POSITIONS, &TETRA_TRIANGLES).unwrap();
    let mut buffer = [-1.0f32; 11];
    let mut len = 0usize;
    // SAFETY: buffer of 11 floats, capacity says 11.
    let status = unsafe { softshell_mesh_copy_positions(mesh, buffer.as_mut_ptr(), 11, &mut len) };
    assert_eq!(status, SoftshellStatus::BufferTooSmall);
    assert_eq!(len, 12);
    assert!(buffer.iter().all(|&x| x == -1.0));
    assert!(last_error().contains("12"), "{}", last_error());

    let mut triangles = [7u32; 12];
    // SAFETY: exact capacity.
    let status = unsafe { softshell_mesh_copy_triangles(mesh, triangles.as_mut_ptr(), 12, &mut len) };
    assert_eq!(status, SoftshellStatus::Ok);
    assert_eq!((triangles, len), (TETRA_TRIANGLES, 12));

    let mut curvature = [0.0f32; 3];
    // SAFETY: buffer of 3 floats.
    let status = unsafe {
        softshell_mesh_copy_vertex_curvature(mesh, SOFTSHELL_CURVATURE_GAUSSIAN, curvature.as_mut_ptr(), 3, &mut len)
    };
    assert_eq!((status, len), (SoftshellStatus::BufferTooSmall, 4));
    assert_eq!(curvature, [0.0; 3]);
    // SAFETY: made above.
    unsafe { softshell_mesh_free(mesh) };
}

#[test]
fn unknown_curvature_kind_is_invalid_argument() {
    let mesh = mesh_from(&TETRA_POSITIONS, &TETRA_TRIANGLES).unwrap();
    let mut out = [0.0f32; 4];
    let mut len = 99usize;
    for kind in [2u32, 7, u32::MAX] {
        // SAFETY: live mesh and buffer.
        let status = unsafe { softshell_mesh_copy_vertex_curvature(mesh, kind, out.as_mut_ptr(), 4, &mut len) };
        assert_eq!(status, SoftshellStatus::InvalidArgument);
        assert!(last_error().contains(&kind.to_string()) && last_error().contains("SOFTSHELL_CURVATURE_MEAN"));
        assert_eq!(len, 99, "nothing written on failure");
    }
    // SAFETY: made above.
    unsafe { softshell_mesh_free(mesh) };
}

#[cfg(feature = "obj")]
#[test]
fn sphere_curvatures_are_near_one() {
    let mesh = load_data_mesh("sphere.obj");
    let n = 482;
    for kind in [SOFTSHELL_CURVATURE_MEAN, SOFTSHELL_CURVATURE_GAUSSIAN] {
        let mut out = vec![0.0f32; n];
        let mut len = 0;
        // SAFETY: buffer of n floats.
        let status = unsafe { softshell_mesh_copy_vertex_curvature(mesh, kind, out.as_mut_ptr(), n, &mut len) };
        assert_eq!((status, len), (SoftshellStatus::Ok, n));
        let mean = out.iter().map(|&x| x as f64).sum::<f64>() / n as f64;
        assert!((mean - 1.0).abs() < 0.05, "kind {kind}: average {mean}");
    }
    // SAFETY: made by load_data_mesh.
    unsafe { softshell_mesh_free(mesh) };
}

fn temp_path(name: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("softshell-ffi-mesh-{}-{name}", std::process::id()))
}

#[cfg(feature = "obj")]
#[test]
fn obj_round_trip_and_errors_with_file_and_line() {
    let mesh = load_data_mesh("eight.obj");
    let path = temp_path("eight.obj");
    let c_path = CString::new(path.to_str().unwrap()).unwrap();
    // SAFETY: live mesh, valid path.
    assert_eq!(unsafe { softshell_mesh_save_obj(mesh, c_path.as_ptr()) }, SoftshellStatus::Ok);
    let mut again = ptr::null_mut();
    // SAFETY: valid path and out-pointer.
    assert_eq!(unsafe { softshell_mesh_load_obj(c_path.as_ptr(), &mut again) }, SoftshellStatus::Ok);
    assert_eq!(mesh_positions(mesh), mesh_positions(again));
    assert_eq!(mesh_triangles(mesh), mesh_triangles(again));
    // SAFETY: made above.
    unsafe {
        softshell_mesh_free(mesh);
        softshell_mesh_free(again);
    }
    std::fs::remove_file(&path).ok();

    let bad = temp_path("bad.obj");
    std::fs::write(&bad, "# a comment\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 oops\n").unwrap();
    let c_bad = CString::new(bad.to_str().unwrap()).unwrap();
    let mut out = ptr::null_mut();
    // SAFETY: valid path and out-pointer.
    assert_eq!(unsafe { softshell_mesh_load_obj(c_bad.as_ptr(), &mut out) }, SoftshellStatus::Io);
    let message = last_error();
    assert!(message.contains("bad.obj:6:") && message.contains("oops"), "{message}");
    assert!(out.is_null());
    std::fs::remove_file(&bad).ok();

    let missing = CString::new("/nonexistent/softshell/none.obj").unwrap();
    // SAFETY: valid path and out-pointer.
    assert_eq!(unsafe { softshell_mesh_load_obj(missing.as_ptr(), &mut out) }, SoftshellStatus::Io);
    assert!(last_error().contains("/nonexistent/softshell/none.obj"));

    let nan = temp_path("nan.obj");
    std::fs::write(&nan, "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let c_nan = CString::new(nan.to_str().unwrap()).unwrap();
    // SAFETY: valid path and out-pointer.
    assert_eq!(unsafe { softshell_mesh_load_obj(c_nan.as_ptr(), &mut out) }, SoftshellStatus::InvalidMesh);
    assert!(last_error().contains("vertex 1"), "{}", last_error());
    std::fs::remove_file(&nan).ok();

    let unwritable = CString::new("/nonexistent/softshell/out.obj").unwrap();
    let mesh = mesh_from(&TETRA_POSITIONS, &TETRA_TRIANGLES).unwrap();
    // SAFETY: live mesh, valid path.
    assert_eq!(unsafe { softshell_mesh_save_obj(mesh, unwritable.as_ptr()) }, SoftshellStatus::Io);
    // SAFETY: made above.
    unsafe { softshell_mesh_free(mesh) };
}

#[cfg(not(feature = "obj"))]
#[test]
fn obj_compiled_out_is_unsupported() {
    let path = CString::new(data_path("kitten.obj").to_str().unwrap()).unwrap();
    let mut out = ptr::null_mut();
    // SAFETY: valid path and out-pointer.
    assert_eq!(unsafe { softshell_mesh_load_obj(path.as_ptr(), &mut out) }, SoftshellStatus::Unsupported);
    assert!(last_error().contains("`obj`"), "{}", last_error());
    assert!(out.is_null());
    let mesh = mesh_from(&TETRA_POSITIONS, &TETRA_TRIANGLES).unwrap();
    let target = CString::new(temp_path("never.obj").to_str().unwrap()).unwrap();
    // SAFETY: live mesh, valid path.
    assert_eq!(unsafe { softshell_mesh_save_obj(mesh, target.as_ptr()) }, SoftshellStatus::Unsupported);
    // SAFETY: made above.
    unsafe { softshell_mesh_free(mesh) };
}

#[test]
fn versions_agree_with_the_header() {
    let (major, minor, patch) = header_version();
    assert_eq!(softshell_abi_version(), (major << 16) | (minor << 8) | patch);
    // SAFETY: static string.
    let version = unsafe { CStr::from_ptr(softshell_version_string()) }.to_str().unwrap();
    assert_eq!(version, format!("{major}.{minor}.{patch}"));
    assert_eq!(version, env!("CARGO_PKG_VERSION"));
}

#[test]
fn status_names() {
    let names = [
        "OK",
        "NULL_ARGUMENT",
        "INVALID_ARGUMENT",
        "INVALID_MESH",
        "IO",
        "BUFFER_TOO_SMALL",
        "UNSTABLE",
        "UNSUPPORTED",
        "POISONED",
        "INTERNAL",
    ];
    for (value, name) in names.iter().enumerate() {
        // SAFETY: static string.
        assert_eq!(unsafe { CStr::from_ptr(softshell_status_name(value as u32)) }.to_str().unwrap(), *name);
    }
    assert_eq!(SoftshellStatus::Internal as u32, 9);
    for unknown in [10u32, 99, u32::MAX] {
        // SAFETY: static string.
        assert_eq!(unsafe { CStr::from_ptr(softshell_status_name(unknown)) }.to_str().unwrap(), "UNKNOWN");
    }
}

#[test]
fn last_error_is_per_thread_and_empty_at_first() {
    std::thread::spawn(|| {
        assert_eq!(last_error(), "");
        let _ = mesh_from(&[], &[]);
        assert!(!last_error().is_empty());
    })
    .join()
    .unwrap();
    std::thread::spawn(|| assert_eq!(last_error(), "", "another thread's failure must not show here")).join().unwrap();
}

/// The message pointer stays valid, and its text unchanged, across calls that do not fail: a
/// C `fprintf(..., softshell_status_name(s), softshell_last_error())` may evaluate either first.
#[test]
fn the_last_error_survives_calls_that_do_not_fail() {
    std::thread::spawn(|| {
        let _ = mesh_from(&[], &[]);
        let pointer = softshell_last_error();
        // SAFETY: never NULL, NUL-terminated.
        let text = unsafe { CStr::from_ptr(pointer) }.to_owned();
        let _ = softshell_status_name(SoftshellStatus::InvalidMesh as u32);
        let _ = (softshell_abi_version(), softshell_version_string());
        let mesh = mesh_from(&TETRA_POSITIONS, &TETRA_TRIANGLES).unwrap();
        let _ = report(mesh);
        // SAFETY: made above.
        unsafe { softshell_mesh_free(mesh) };
        assert_eq!(softshell_last_error(), pointer);
        // SAFETY: the same pointer, still valid.
        assert_eq!(unsafe { CStr::from_ptr(pointer) }, text.as_c_str());
    })
    .join()
    .unwrap();
}

#[test]
fn ply_output_carries_both_curvatures_and_colours() {
    let (p, t) = cube();
    let mesh = mesh_from(&p, &t).unwrap();
    let path = temp_path("cube.ply");
    let c_path = CString::new(path.to_str().unwrap()).unwrap();
    // SAFETY: live mesh, valid path.
    assert_eq!(unsafe { softshell_mesh_save_ply(mesh, c_path.as_ptr(), 9) }, SoftshellStatus::InvalidArgument);
    assert!(!path.exists(), "nothing written on failure");
    // SAFETY: as above.
    assert_eq!(
        unsafe { softshell_mesh_save_ply(mesh, c_path.as_ptr(), SOFTSHELL_CURVATURE_GAUSSIAN) },
        SoftshellStatus::Ok
    );
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.starts_with("ply\nformat ascii 1.0\n"));
    assert!(text.contains("element vertex 8\n") && text.contains("element face 12\n"));
    assert!(text.contains("property float mean_curvature\nproperty float gaussian_curvature\n"));
    let first_vertex: Vec<f64> = text
        .split("end_header\n")
        .nth(1)
        .unwrap()
        .lines()
        .next()
        .unwrap()
        .split(' ')
        .map(|x| x.parse().unwrap())
        .collect();
    assert_eq!(first_vertex.len(), 3 + 3 + 2);
    // A cube corner has angle defect 2 pi - 3 pi/2 = pi/2 > 0.
    assert!(first_vertex[7] > 0.0, "{first_vertex:?}");
    // SAFETY: made above.
    unsafe { softshell_mesh_free(mesh) };
    std::fs::remove_file(&path).ok();
}

#[test]
fn curvature_of_an_accepted_sliver_mesh_is_finite() {
    // A sliver tetrahedron 1e10 m long and a subnormal 1e-39 m thick: accepted (the mesh
    // functions take degenerate meshes), and its curvature must not come back infinite.
    let (l, h) = (1e10f32, 1e-39f32);
    let positions = [0.0, 0.0, 0.0, l, 0.0, 0.0, 0.5 * l, h, 0.0, 0.5 * l, 0.0, h];
    let mesh = mesh_from(&positions, &TETRA_TRIANGLES).unwrap();
    for kind in [SOFTSHELL_CURVATURE_MEAN, SOFTSHELL_CURVATURE_GAUSSIAN] {
        let mut out = [0.0f32; 4];
        let mut len = 0;
        // SAFETY: live mesh, writable buffer of 4.
        let status = unsafe { softshell_mesh_copy_vertex_curvature(mesh, kind, out.as_mut_ptr(), 4, &mut len) };
        assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
        assert!(out.iter().all(|v| v.is_finite()), "curvature kind {kind}: {out:?}");
    }
    // SAFETY: made above.
    unsafe { softshell_mesh_free(mesh) };
}
