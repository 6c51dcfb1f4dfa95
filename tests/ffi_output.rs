//! Frame output through the C ABI (`softshell_{shell,body,lattice}_save_{ply,obj}`): the PLY
//! files hold one row per vertex with the documented float properties, whose values agree with
//! the copy functions; OBJ frames read back; bad arguments fail without writing anything; a
//! successful save leaves the thread's last error alone.
#![cfg(any(feature = "shell", feature = "body", feature = "lattice"))]
#![allow(dead_code)] // helpers shared by the parts, each compiled only with its feature

#[cfg(feature = "body")]
mod body_util;
mod common;

use std::ffi::CString;
use std::path::PathBuf;
use std::ptr::{null, null_mut};

use common::*;
use softshell::ffi::SoftshellStatus;
use softshell::ffi::mesh::*;
use softshell::ffi::output::*;

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("softshell-ffi-output-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn c_path(path: &std::path::Path) -> CString {
    CString::new(path.to_str().unwrap()).unwrap()
}

/// A parsed ASCII PLY: vertex property names, vertex rows, face rows.
struct Ply {
    properties: Vec<String>,
    vertices: Vec<Vec<f64>>,
    faces: Vec<[u32; 3]>,
}

impl Ply {
    fn read(path: &std::path::Path) -> Ply {
        let text = std::fs::read_to_string(path).unwrap();
        let (header, body) = text.split_once("end_header\n").unwrap();
        let mut properties = Vec::new();
        let (mut nv, mut nf, mut in_vertex) = (0usize, 0usize, false);
        for line in header.lines() {
            let words: Vec<&str> = line.split_whitespace().collect();
            match words.as_slice() {
                ["element", "vertex", n] => (nv, in_vertex) = (n.parse().unwrap(), true),
                ["element", "face", n] => (nf, in_vertex) = (n.parse().unwrap(), false),
                ["property", _, name] if in_vertex => properties.push(name.to_string()),
                _ => {}
            }
        }
        let lines: Vec<&str> = body.lines().collect();
        assert_eq!(lines.len(), nv + nf, "{}", path.display());
        let vertices: Vec<Vec<f64>> = lines[..nv]
            .iter()
            .map(|l| l.split_whitespace().map(|w| f64::from(w.parse::<f32>().unwrap())).collect())
            .collect();
        assert!(vertices.iter().all(|v| v.len() == properties.len()));
        let faces = lines[nv..]
            .iter()
            .map(|l| {
                let w: Vec<u32> = l.split_whitespace().map(|w| w.parse().unwrap()).collect();
                assert_eq!(w[0], 3);
                [w[1], w[2], w[3]]
            })
            .collect();
        Ply { properties, vertices, faces }
    }

    fn column(&self, name: &str) -> Vec<f64> {
        let i = self.properties.iter().position(|p| p == name).unwrap_or_else(|| panic!("no property {name}"));
        self.vertices.iter().map(|v| v[i]).collect()
    }

    fn colours(&self) -> Vec<[f64; 3]> {
        let (r, g, b) = (self.column("red"), self.column("green"), self.column("blue"));
        (0..r.len()).map(|i| [r[i], g[i], b[i]]).collect()
    }
}

fn copy_f32(f: impl Fn(*mut f32, usize, *mut usize) -> SoftshellStatus) -> Vec<f32> {
    let mut len = 0usize;
    assert_eq!(f(null_mut(), 0, &mut len), SoftshellStatus::BufferTooSmall);
    let mut out = vec![0.0f32; len];
    assert_eq!(f(out.as_mut_ptr(), len, &mut len), SoftshellStatus::Ok, "{}", last_error());
    out
}

fn copy_u32(f: impl Fn(*mut u32, usize, *mut usize) -> SoftshellStatus) -> Vec<u32> {
    let mut len = 0usize;
    assert_eq!(f(null_mut(), 0, &mut len), SoftshellStatus::BufferTooSmall);
    let mut out = vec![0u32; len];
    assert_eq!(f(out.as_mut_ptr(), len, &mut len), SoftshellStatus::Ok, "{}", last_error());
    out
}

fn assert_close(a: &[f64], b: &[f32], tolerance: f64, what: &str) {
    assert_eq!(a.len(), b.len(), "{what}");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!((x - f64::from(*y)).abs() <= tolerance * (1.0 + x.abs()), "{what}[{i}]: {x} vs {y}");
    }
}

/// Makes the last error a known message, to check that a successful save keeps it.
fn set_marker_error() -> String {
    let mut m = null_mut();
    // SAFETY: NULL positions with a count: refused before any read.
    let status = unsafe { softshell_mesh_from_arrays(null(), 3, null(), 1, &mut m) };
    assert_eq!(status, SoftshellStatus::NullArgument);
    last_error()
}

#[cfg(feature = "shell")]
mod shell {
    use super::*;
    use softshell::ffi::shell::*;

    struct Shell(*mut SoftshellShell);
    impl Drop for Shell {
        fn drop(&mut self) {
            // SAFETY: made by the library, freed once.
            unsafe { softshell_shell_free(self.0) }
        }
    }

    /// data/sphere.obj (radius 1) contracted a few steps with pressure scaled to its size.
    fn contracted_sphere() -> (Shell, usize, usize) {
        let mesh = load_data_mesh("sphere.obj");
        let mut def = softshell_shell_def_default();
        def.pressure *= 3.46;
        def.youngs_modulus *= 3.46;
        let mut raw = null_mut();
        // SAFETY: live mesh and def; writable out-pointer.
        unsafe {
            assert_eq!(softshell_shell_new(mesh, &def, &mut raw), SoftshellStatus::Ok, "{}", last_error());
            let (nv, nt) = (softshell_mesh_vertex_count(mesh), softshell_mesh_triangle_count(mesh));
            softshell_mesh_free(mesh);
            for _ in 0..10 {
                assert_eq!(softshell_shell_step(raw, null_mut()), SoftshellStatus::Ok, "{}", last_error());
            }
            (Shell(raw), nv, nt)
        }
    }

    #[test]
    fn shell_ply_holds_curvature_energy_and_pressure_force() {
        let (shell, nv, nt) = contracted_sphere();
        let path = temp("shell.ply");
        let marker = set_marker_error();
        // SAFETY: live shell, NUL-terminated path.
        let status = unsafe { softshell_shell_save_ply(shell.0, c_path(&path).as_ptr(), SOFTSHELL_SHELL_PLY_ENERGY) };
        assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
        assert_eq!(last_error(), marker, "a successful save must keep the last error");
        let ply = Ply::read(&path);
        assert_eq!((ply.vertices.len(), ply.faces.len()), (nv, nt));
        for name in ["x", "y", "z", "red", "green", "blue", "mean_curvature", "gaussian_curvature", "energy"] {
            assert!(ply.properties.iter().any(|p| p == name), "{name} in {:?}", ply.properties);
        }

        // SAFETY: live shell; buffers sized by the size query.
        let (positions, mean, gaussian, face_energy) = unsafe {
            (
                copy_f32(|o, c, n| softshell_shell_copy_positions(shell.0, o, c, n)),
                copy_f32(|o, c, n| softshell_shell_copy_vertex_curvature(shell.0, SOFTSHELL_CURVATURE_MEAN, o, c, n)),
                copy_f32(|o, c, n| {
                    softshell_shell_copy_vertex_curvature(shell.0, SOFTSHELL_CURVATURE_GAUSSIAN, o, c, n)
                }),
                copy_f32(|o, c, n| softshell_shell_copy_face_energy(shell.0, o, c, n)),
            )
        };
        let xs: Vec<f32> = positions.iter().step_by(3).copied().collect();
        assert_close(&ply.column("x"), &xs, 0.0, "x");
        assert_close(&ply.column("mean_curvature"), &mean, 0.0, "mean curvature");
        assert_close(&ply.column("gaussian_curvature"), &gaussian, 0.0, "Gaussian curvature");
        let energy_total: f64 = ply.column("energy").iter().sum();
        let face_total: f64 = face_energy.iter().map(|&e| f64::from(e)).sum();
        assert!(face_total > 0.0);
        assert!((energy_total - face_total).abs() < 1e-4 * face_total, "{energy_total} vs {face_total}");

        // Pressure force: |P/3 sum A n| on a near-sphere is about P times the vertex's share of
        // the area, and the total is about P times the area.
        let force = ply.column("pressure_force");
        let pressure = f64::from(softshell_shell_def_default().pressure * 3.46);
        let area = {
            let mut a = 0.0f64;
            for f in &ply.faces {
                let p = |i: u32| glam::DVec3::from_slice(&ply.vertices[i as usize][..3]);
                a += 0.5 * (p(f[1]) - p(f[0])).cross(p(f[2]) - p(f[0])).length();
            }
            a
        };
        let total: f64 = force.iter().sum();
        assert!(force.iter().all(|&f| f > 0.0));
        assert!((total / (pressure * area) - 1.0).abs() < 0.1, "total force {total}, P A = {}", pressure * area);

        // The colours follow the selected scalar: the highest energy is the brightest.
        let energy = ply.column("energy");
        let colours = ply.colours();
        let hottest = (0..nv).max_by(|&a, &b| energy[a].total_cmp(&energy[b])).unwrap();
        let coolest = (0..nv).min_by(|&a, &b| energy[a].total_cmp(&energy[b])).unwrap();
        assert!(colours[hottest][0] > colours[coolest][0]);

        for colour in [
            SOFTSHELL_SHELL_PLY_MEAN_CURVATURE,
            SOFTSHELL_SHELL_PLY_GAUSSIAN_CURVATURE,
            SOFTSHELL_SHELL_PLY_PRESSURE_FORCE,
        ] {
            // SAFETY: as above.
            let status = unsafe { softshell_shell_save_ply(shell.0, c_path(&path).as_ptr(), colour) };
            assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
        }
    }

    #[test]
    fn shell_save_refuses_bad_arguments_and_writes_nothing() {
        let (shell, _, _) = contracted_sphere();
        let path = temp("shell_refused.ply");
        let c = c_path(&path);
        // SAFETY: NULLs, an unknown kind and an unwritable path are refused; the rest are live.
        unsafe {
            assert_eq!(softshell_shell_save_ply(shell.0, c.as_ptr(), 4), SoftshellStatus::InvalidArgument);
            assert!(last_error().contains("SOFTSHELL_SHELL_PLY_PRESSURE_FORCE (3)"), "{}", last_error());
            assert!(!path.exists(), "a refused call must not create the file");
            assert_eq!(softshell_shell_save_ply(null(), c.as_ptr(), 0), SoftshellStatus::NullArgument);
            assert_eq!(softshell_shell_save_ply(shell.0, null(), 0), SoftshellStatus::NullArgument);
            assert_eq!(softshell_shell_save_obj(null(), c.as_ptr()), SoftshellStatus::NullArgument);
            let bad = CString::new("/nonexistent-softshell-dir/x.ply").unwrap();
            assert_eq!(softshell_shell_save_ply(shell.0, bad.as_ptr(), 0), SoftshellStatus::Io);
            assert!(last_error().contains("/nonexistent-softshell-dir/x.ply"), "{}", last_error());
        }
    }

    #[cfg(feature = "obj")]
    #[test]
    fn shell_obj_frame_reads_back() {
        let (shell, nv, nt) = contracted_sphere();
        let path = temp("shell.obj");
        // SAFETY: live shell and path; the mesh read back is freed below.
        unsafe {
            assert_eq!(softshell_shell_save_obj(shell.0, c_path(&path).as_ptr()), SoftshellStatus::Ok);
            let mut mesh = null_mut();
            assert_eq!(softshell_mesh_load_obj(c_path(&path).as_ptr(), &mut mesh), SoftshellStatus::Ok);
            assert_eq!((softshell_mesh_vertex_count(mesh), softshell_mesh_triangle_count(mesh)), (nv, nt));
            let read = mesh_positions(mesh);
            let now = copy_f32(|o, c, n| softshell_shell_copy_positions(shell.0, o, c, n));
            assert_eq!(read, now, "OBJ coordinates read back exactly");
            softshell_mesh_free(mesh);
        }
    }
}

#[cfg(feature = "body")]
mod body {
    use super::*;
    use softshell::ffi::body::*;

    struct Body(*mut SoftshellBody);
    impl Drop for Body {
        fn drop(&mut self) {
            // SAFETY: made by the library, freed once.
            unsafe { softshell_body_free(self.0) }
        }
    }

    /// A gas-filled sphere cut open by hand at one corner, a few steps later.
    fn cut_balloon() -> Body {
        let mesh = load_data_mesh("sphere.obj");
        let mut def = softshell_body_def_default();
        def.gas_amount = 20.0;
        def.gravity = [0.0; 3];
        let mut raw = null_mut();
        // SAFETY: live mesh and def; buffers sized by the size query.
        unsafe {
            assert_eq!(softshell_body_new(mesh, &def, &mut raw), SoftshellStatus::Ok, "{}", last_error());
            softshell_mesh_free(mesh);
            let t = copy_u32(|o, c, n| softshell_body_copy_triangles(raw, o, c, n));
            assert_eq!(softshell_body_break_edge(raw, t[0], t[1]), SoftshellStatus::Ok, "{}", last_error());
            assert_eq!(softshell_body_break_edge(raw, t[1], t[2]), SoftshellStatus::Ok, "{}", last_error());
            for _ in 0..3 {
                assert_eq!(softshell_body_step(raw, null_mut()), SoftshellStatus::Ok, "{}", last_error());
            }
        }
        Body(raw)
    }

    #[test]
    fn body_ply_after_a_cut_has_every_vertex_speed_and_fragment() {
        let body = cut_balloon();
        let path = temp("body.ply");
        // SAFETY: live body; buffers sized by the size query.
        unsafe {
            let status = softshell_body_save_ply(body.0, c_path(&path).as_ptr(), SOFTSHELL_BODY_PLY_FRAGMENT);
            assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
            let ply = Ply::read(&path);
            let nv = softshell_body_vertex_count(body.0);
            assert!(nv > 482, "the cut appended vertices");
            assert_eq!(ply.vertices.len(), nv);
            assert_eq!(ply.faces.len(), softshell_body_triangle_count(body.0));
            let velocities = copy_f32(|o, c, n| softshell_body_copy_velocities(body.0, o, c, n));
            let speeds: Vec<f32> = velocities.chunks(3).map(|v| glam::Vec3::from_slice(v).length()).collect();
            assert_close(&ply.column("speed"), &speeds, 1e-6, "speed");
            let fragments = copy_u32(|o, c, n| softshell_body_copy_fragment_ids(body.0, o, c, n));
            let per_vertex = ply.column("fragment");
            for (f, t) in ply.faces.iter().enumerate() {
                for &v in t {
                    assert_eq!(per_vertex[v as usize], f64::from(fragments[f]), "vertex {v} of triangle {f}");
                }
            }
            let shade = ply.column("fragment_shade");
            assert!(shade.iter().all(|s| (0.0..1.0).contains(s)));
            assert!(ply.column("mean_curvature").iter().all(|h| h.is_finite()));
            for colour in [SOFTSHELL_BODY_PLY_SPEED, SOFTSHELL_BODY_PLY_MEAN_CURVATURE] {
                assert_eq!(softshell_body_save_ply(body.0, c_path(&path).as_ptr(), colour), SoftshellStatus::Ok);
            }
            assert_eq!(softshell_body_save_ply(body.0, c_path(&path).as_ptr(), 3), SoftshellStatus::InvalidArgument);
            assert_eq!(softshell_body_save_ply(null(), c_path(&path).as_ptr(), 0), SoftshellStatus::NullArgument);
            assert_eq!(softshell_body_save_obj(body.0, null()), SoftshellStatus::NullArgument);
        }
    }

    #[cfg(feature = "obj")]
    #[test]
    fn body_obj_frame_reads_back_with_the_split_vertices() {
        let body = cut_balloon();
        let path = temp("body.obj");
        // SAFETY: live body and path; the mesh read back is freed below.
        unsafe {
            assert_eq!(softshell_body_save_obj(body.0, c_path(&path).as_ptr()), SoftshellStatus::Ok);
            let mut mesh = null_mut();
            assert_eq!(softshell_mesh_load_obj(c_path(&path).as_ptr(), &mut mesh), SoftshellStatus::Ok);
            assert_eq!(softshell_mesh_vertex_count(mesh), softshell_body_vertex_count(body.0));
            assert_eq!(softshell_mesh_triangle_count(mesh), softshell_body_triangle_count(body.0));
            softshell_mesh_free(mesh);
        }
    }

    /// A body of 2,601 vertices (a cloth; stored in an order of its own inside) writes its OBJ
    /// frame and its copies in the caller's numbering: before a step, the input itself.
    #[cfg(feature = "obj")]
    #[test]
    fn a_large_body_writes_its_frame_in_the_callers_numbering() {
        // Numbered row by row: not the order the body keeps inside.
        let (positions, triangles) = crate::body_util::cloth(51, 1.0);
        let path = temp("large_body.obj");
        let mesh = crate::body_util::Mesh::new(&positions, &triangles);
        // SAFETY: live mesh, def and path; the mesh read back is freed below.
        unsafe {
            let def = softshell_body_def_default();
            let mut raw = null_mut();
            assert_eq!(softshell_body_new(mesh.0, &def, &mut raw), SoftshellStatus::Ok, "{}", last_error());
            let body = Body(raw);
            assert_eq!(copy_f32(|o, c, n| softshell_body_copy_positions(body.0, o, c, n)), positions);
            assert_eq!(copy_u32(|o, c, n| softshell_body_copy_triangles(body.0, o, c, n)), triangles);
            assert_eq!(softshell_body_save_obj(body.0, c_path(&path).as_ptr()), SoftshellStatus::Ok);
            let mut back = null_mut();
            assert_eq!(softshell_mesh_load_obj(c_path(&path).as_ptr(), &mut back), SoftshellStatus::Ok);
            let read = copy_f32(|o, c, n| softshell_mesh_copy_positions(back, o, c, n));
            assert_eq!(copy_u32(|o, c, n| softshell_mesh_copy_triangles(back, o, c, n)), triangles);
            softshell_mesh_free(back);
            assert_eq!(read.len(), positions.len());
            assert!(read.iter().zip(&positions).all(|(a, b)| (a - b).abs() <= 1e-6), "OBJ positions differ");
        }
    }
}

#[cfg(feature = "lattice")]
mod lattice {
    use super::*;
    use softshell::ffi::lattice::*;

    struct Lattice(*mut SoftshellLattice);
    impl Drop for Lattice {
        fn drop(&mut self) {
            // SAFETY: made by the library, freed once.
            unsafe { softshell_lattice_free(self.0) }
        }
    }

    /// A 12 x 8 sheet pinned along both short edges, poked downwards in the middle.
    fn poked_sheet() -> Lattice {
        let mut def = softshell_lattice_def_default();
        (def.columns, def.rows) = (12, 8);
        def.gravity = [0.0; 3];
        let mut raw = null_mut();
        // SAFETY: live def; writable out-pointer; a live force.
        unsafe {
            assert_eq!(softshell_lattice_new(&def, null(), &mut raw), SoftshellStatus::Ok, "{}", last_error());
            for r in 0..8 {
                assert_eq!(softshell_lattice_pin(raw, 0, r), SoftshellStatus::Ok);
                assert_eq!(softshell_lattice_pin(raw, 11, r), SoftshellStatus::Ok);
            }
            for _ in 0..6 {
                assert_eq!(softshell_lattice_apply_force(raw, 6, 4, [0.0, -1.0, 0.0].as_ptr()), SoftshellStatus::Ok);
                assert_eq!(softshell_lattice_step(raw, null_mut()), SoftshellStatus::Ok, "{}", last_error());
            }
        }
        Lattice(raw)
    }

    #[test]
    fn lattice_ply_holds_height_speed_and_goal_distance() {
        let sheet = poked_sheet();
        let path = temp("lattice.ply");
        let marker = set_marker_error();
        // SAFETY: live lattice; buffers sized by the size query.
        unsafe {
            let status = softshell_lattice_save_ply(sheet.0, c_path(&path).as_ptr(), SOFTSHELL_LATTICE_PLY_HEIGHT);
            assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
            assert_eq!(last_error(), marker, "a successful save must keep the last error");
            let ply = Ply::read(&path);
            assert_eq!(ply.vertices.len(), 96);
            assert_eq!(ply.faces.len(), softshell_lattice_triangle_count(sheet.0));
            let positions = copy_f32(|o, c, n| softshell_lattice_copy_positions(sheet.0, o, c, n));
            let heights: Vec<f32> = positions.iter().skip(1).step_by(3).copied().collect();
            assert_close(&ply.column("height"), &heights, 0.0, "height");
            let middle = {
                let mut i = 0;
                assert_eq!(softshell_lattice_particle_index(sheet.0, 6, 4, &mut i), SoftshellStatus::Ok);
                i as usize
            };
            assert!(heights[middle] < 0.0, "the poke pushed the middle down");
            let goals = copy_f32(|o, c, n| softshell_lattice_copy_goals(sheet.0, o, c, n));
            let distance: Vec<f32> = positions
                .chunks(3)
                .zip(goals.chunks(3))
                .map(|(p, g)| glam::Vec3::from_slice(p).distance(glam::Vec3::from_slice(g)))
                .collect();
            assert_close(&ply.column("goal_distance"), &distance, 1e-6, "goal distance");
            assert!(ply.column("speed").iter().any(|&s| s > 0.0));
            // The colours follow the height: the lowest particle is not coloured like the highest.
            let colours = ply.colours();
            let h = ply.column("height");
            let low = (0..h.len()).min_by(|&a, &b| h[a].total_cmp(&h[b])).unwrap();
            let high = (0..h.len()).max_by(|&a, &b| h[a].total_cmp(&h[b])).unwrap();
            assert_ne!(colours[low], colours[high]);
            for colour in [SOFTSHELL_LATTICE_PLY_SPEED, SOFTSHELL_LATTICE_PLY_GOAL_DISTANCE] {
                assert_eq!(softshell_lattice_save_ply(sheet.0, c_path(&path).as_ptr(), colour), SoftshellStatus::Ok);
            }
            assert_eq!(
                softshell_lattice_save_ply(sheet.0, c_path(&path).as_ptr(), 3),
                SoftshellStatus::InvalidArgument
            );
            assert_eq!(softshell_lattice_save_ply(null(), c_path(&path).as_ptr(), 0), SoftshellStatus::NullArgument);
            assert_eq!(softshell_lattice_save_obj(null(), c_path(&path).as_ptr()), SoftshellStatus::NullArgument);
            assert_eq!(softshell_lattice_save_obj(sheet.0, null()), SoftshellStatus::NullArgument);
        }
    }

    #[cfg(feature = "obj")]
    #[test]
    fn lattice_obj_frame_reads_back() {
        let sheet = poked_sheet();
        let path = temp("lattice.obj");
        // SAFETY: live lattice and path; the mesh read back is freed below.
        unsafe {
            assert_eq!(softshell_lattice_save_obj(sheet.0, c_path(&path).as_ptr()), SoftshellStatus::Ok);
            let mut mesh = null_mut();
            assert_eq!(softshell_mesh_load_obj(c_path(&path).as_ptr(), &mut mesh), SoftshellStatus::Ok);
            assert_eq!(softshell_mesh_vertex_count(mesh), 96);
            let read = mesh_positions(mesh);
            let now = copy_f32(|o, c, n| softshell_lattice_copy_positions(sheet.0, o, c, n));
            assert_eq!(read, now);
            softshell_mesh_free(mesh);
        }
    }
}

#[cfg(not(feature = "obj"))]
#[test]
fn obj_frames_are_unsupported_without_the_obj_feature() {
    #[cfg(feature = "lattice")]
    {
        let def = softshell::ffi::lattice::softshell_lattice_def_default();
        let mut raw = null_mut();
        // SAFETY: live def and path; the lattice is freed below.
        unsafe {
            assert_eq!(softshell::ffi::lattice::softshell_lattice_new(&def, null(), &mut raw), SoftshellStatus::Ok);
            let path = c_path(&temp("unsupported.obj"));
            assert_eq!(softshell_lattice_save_obj(raw, path.as_ptr()), SoftshellStatus::Unsupported);
            softshell::ffi::lattice::softshell_lattice_free(raw);
        }
    }
}
