//! The shell's C ABI, used only through the exported functions: validation of meshes and defs,
//! NULLs and buffers, the defaults' behaviour on a unit-sized mesh, determinism across thread
//! counts, extreme settings with rollback, and memory that only holds what the scene uses.
#![cfg(feature = "shell")]

use std::ffi::CStr;
use std::ptr::{null, null_mut};

use softshell::ffi::boundary::SoftshellStatus;
use softshell::ffi::mesh::*;
use softshell::ffi::shell::*;
use softshell::ffi::version::softshell_last_error;

mod report_util;

fn last_error() -> String {
    // SAFETY: the library keeps the message alive until the next call on this thread.
    unsafe { CStr::from_ptr(softshell_last_error()) }.to_string_lossy().into_owned()
}

struct Mesh(*mut SoftshellMesh);
impl Drop for Mesh {
    fn drop(&mut self) {
        // SAFETY: made by the library, freed once.
        unsafe { softshell_mesh_free(self.0) }
    }
}

struct Shell(*mut SoftshellShell);
impl Drop for Shell {
    fn drop(&mut self) {
        // SAFETY: made by the library, freed once.
        unsafe { softshell_shell_free(self.0) }
    }
}

fn mesh_from(positions: &[f32], triangles: &[u32]) -> Result<Mesh, SoftshellStatus> {
    let mut m = null_mut();
    // SAFETY: live slices with their lengths; m is writable.
    let status = unsafe {
        softshell_mesh_from_arrays(
            positions.as_ptr(),
            positions.len() / 3,
            triangles.as_ptr(),
            triangles.len() / 3,
            &mut m,
        )
    };
    if status == SoftshellStatus::Ok { Ok(Mesh(m)) } else { Err(status) }
}

/// An OBJ of data/ scaled about its centre to a unit bounding-box diagonal (times `scale`).
fn unit_mesh(name: &str, scale: f32) -> Mesh {
    let (pos, tri) = report_util::unit_obj(name, scale);
    mesh_from(&pos, &tri).unwrap()
}

fn new_shell(mesh: &Mesh, def: &SoftshellShellDef) -> Result<Shell, SoftshellStatus> {
    let mut s = null_mut();
    // SAFETY: live mesh and def, writable out-pointer.
    let status = unsafe { softshell_shell_new(mesh.0, def, &mut s) };
    if status == SoftshellStatus::Ok { Ok(Shell(s)) } else { Err(status) }
}

fn step(shell: &Shell) -> Result<SoftshellShellStats, SoftshellStatus> {
    let mut stats = SoftshellShellStats::default();
    // SAFETY: live shell, writable stats.
    let status = unsafe { softshell_shell_step(shell.0, &mut stats) };
    if status == SoftshellStatus::Ok { Ok(stats) } else { Err(status) }
}

fn positions(shell: &Shell) -> Vec<f32> {
    // SAFETY: live shell; the buffer is sized from the vertex count.
    unsafe {
        let n = softshell_shell_vertex_count(shell.0) * 3;
        let mut out = vec![0.0f32; n];
        let mut len = 0;
        assert_eq!(softshell_shell_copy_positions(shell.0, out.as_mut_ptr(), n, &mut len), SoftshellStatus::Ok);
        assert_eq!(len, n);
        out
    }
}

fn memory(shell: &Shell) -> usize {
    // SAFETY: live shell.
    unsafe { softshell_shell_memory_bytes(shell.0) }
}

const TETRA_POS: [f32; 12] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
const TETRA_TRI: [u32; 12] = [0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2];

#[test]
fn defs_are_validated_field_by_field() {
    let mesh = mesh_from(&TETRA_POS, &TETRA_TRI).unwrap();
    let good = softshell_shell_def_default();
    assert!(new_shell(&mesh, &good).is_ok(), "{}", last_error());

    let mut zeroed: SoftshellShellDef = unsafe { std::mem::zeroed() };
    zeroed.time_step = 0.01;
    assert_eq!(new_shell(&mesh, &zeroed).err(), Some(SoftshellStatus::InvalidArgument));
    assert!(last_error().contains("softshell_shell_def_default"), "{}", last_error());

    type Edit = fn(&mut SoftshellShellDef);
    let cases: [(&str, Edit); 12] = [
        ("time_step", |d| d.time_step = 0.0),
        ("substeps", |d| d.substeps = 0),
        ("iterations", |d| d.iterations = 0),
        ("solver", |d| d.solver = 7),
        ("pressure", |d| d.pressure = f32::NAN),
        ("material", |d| d.material = 99),
        ("youngs_modulus", |d| d.youngs_modulus = -1.0),
        ("poisson_ratio", |d| d.poisson_ratio = 0.5),
        ("thickness", |d| d.thickness = f32::INFINITY),
        ("bending", |d| d.bending = 3),
        ("stop_volume_ratio", |d| d.stop_volume_ratio = 1.0),
        ("threads", |d| d.threads = 1000),
    ];
    for (field, edit) in cases {
        let mut def = good;
        edit(&mut def);
        assert_eq!(new_shell(&mesh, &def).err(), Some(SoftshellStatus::InvalidArgument), "{field}");
        assert!(last_error().contains(field), "{field}: {}", last_error());
    }
}

#[test]
fn nulls_and_meshes_that_bound_no_solid_are_refused() {
    let def = softshell_shell_def_default();
    let mesh = mesh_from(&TETRA_POS, &TETRA_TRI).unwrap();
    let mut out = null_mut();
    // SAFETY: deliberate NULLs; the library must refuse them without dereferencing.
    unsafe {
        assert_eq!(softshell_shell_new(null(), &def, &mut out), SoftshellStatus::NullArgument);
        assert_eq!(softshell_shell_new(mesh.0, null(), &mut out), SoftshellStatus::NullArgument);
        assert_eq!(softshell_shell_new(mesh.0, &def, null_mut()), SoftshellStatus::NullArgument);
        assert!(out.is_null());
        assert_eq!(softshell_shell_step(null_mut(), null_mut()), SoftshellStatus::NullArgument);
        assert_eq!(softshell_shell_vertex_count(null()), 0);
        assert_eq!(softshell_shell_memory_bytes(null()), 0);
        softshell_shell_free(null_mut());
    }

    let open = mesh_from(&TETRA_POS, &TETRA_TRI[..9]).unwrap();
    assert_eq!(new_shell(&open, &def).err(), Some(SoftshellStatus::InvalidMesh));
    assert!(last_error().contains("edge"), "{}", last_error());

    let flipped: Vec<u32> = TETRA_TRI.chunks(3).flat_map(|t| [t[0], t[2], t[1]]).collect();
    let inward = mesh_from(&TETRA_POS, &flipped).unwrap();
    assert_eq!(new_shell(&inward, &def).err(), Some(SoftshellStatus::InvalidMesh));
    assert!(last_error().contains("winding"), "{}", last_error());

    let mut mixed = TETRA_TRI;
    mixed.swap(1, 2);
    let inconsistent = mesh_from(&TETRA_POS, &mixed).unwrap();
    assert_eq!(new_shell(&inconsistent, &def).err(), Some(SoftshellStatus::InvalidMesh));

    // A flat (zero-volume) tetrahedron: degenerate triangles are named.
    let flat = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    let degenerate = mesh_from(&flat, &TETRA_TRI).unwrap();
    assert_eq!(new_shell(&degenerate, &def).err(), Some(SoftshellStatus::InvalidMesh));
    assert!(last_error().contains("triangle"), "{}", last_error());
}

#[test]
fn defaults_contract_a_unit_mesh_below_0_8_within_200_steps_monotonically() {
    let mesh = unit_mesh("sphere.obj", 1.0);
    let shell = new_shell(&mesh, &softshell_shell_def_default()).unwrap();
    let mut reached = None;
    let mut previous = 1.0;
    for n in 1..=200u64 {
        let s = step(&shell).unwrap();
        assert!(
            s.volume_ratio <= previous + 1e-4,
            "step {n}: the volume ratio rose from {previous} to {}",
            s.volume_ratio
        );
        previous = s.volume_ratio;
        assert_eq!(s.step, n);
        assert!((s.time - n as f64 / 60.0).abs() < 1e-5);
        assert!(s.volume_ratio.is_finite() && s.residual.is_finite());
        assert!(s.elastic_energy >= 0.0 && s.bending_energy >= 0.0 && s.anisotropic_energy == 0.0);
        // A contracting sphere never touches itself: pairs may be tested, none is a contact.
        assert!(s.ccd_tests <= s.collision_candidates && s.contacts == 0, "{s:?}");
        assert!(s.step_seconds > 0.0);
        assert!(!s.stalled);
        if s.volume_ratio < 0.8 {
            reached = Some(n);
            break;
        }
    }
    assert!(reached.is_some(), "the default shell did not contract below 0.8 in 200 steps");
}

#[test]
fn zero_pressure_keeps_the_rest_shape() {
    let mesh = unit_mesh("sphere.obj", 1.0);
    let mut def = softshell_shell_def_default();
    def.pressure = 0.0;
    let shell = new_shell(&mesh, &def).unwrap();
    let rest = positions(&shell);
    for _ in 0..300 {
        step(&shell).unwrap();
    }
    let drift = positions(&shell).iter().zip(&rest).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(drift < 1e-3, "drift {drift} of the unit diagonal");
    let s = step(&shell).unwrap();
    assert!(s.stalled && !s.finished, "a shell without pressure does not contract: stalled");
}

#[test]
fn results_are_bit_identical_for_1_2_and_4_threads() {
    // The kitten has colours of more than a thousand constraints, so the parallel path runs.
    let mesh = unit_mesh("kitten.obj", 1.0);
    let run = |threads| {
        let mut def = softshell_shell_def_default();
        def.threads = threads;
        let shell = new_shell(&mesh, &def).unwrap();
        let faces: Vec<u32> = (0..2000).collect();
        let aniso = softshell_anisotropy_def_default();
        // SAFETY: live shell, slice and def.
        let status = unsafe { softshell_shell_add_anisotropic_region(shell.0, faces.as_ptr(), faces.len(), &aniso) };
        assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
        let mut last = SoftshellShellStats::default();
        for _ in 0..6 {
            last = step(&shell).unwrap();
        }
        let bits: Vec<u32> = positions(&shell).iter().map(|v| v.to_bits()).collect();
        (bits, last.volume.to_bits(), last.elastic_energy.to_bits(), last.residual.to_bits())
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(4));
}

#[test]
fn extreme_settings_stay_finite_or_roll_back() {
    let mesh = unit_mesh("sphere.obj", 1.0);
    let base = softshell_shell_def_default();
    type Edit = fn(&mut SoftshellShellDef);
    let cases: [(&str, Edit); 7] = [
        ("Young's modulus x1e5", |d| d.youngs_modulus *= 1e5),
        ("Young's modulus 1e9 Pa", |d| d.youngs_modulus = 1e9),
        ("Young's modulus 1e2 Pa", |d| d.youngs_modulus = 1e2),
        ("volume driven through zero (300 steps, no stop)", |d| d.pressure *= 3.0),
        ("pressure x1e4", |d| d.pressure *= 1e4),
        ("time step 0.1 s", |d| d.time_step = 0.1),
        ("pressure x1e4 with PBD", |d| {
            d.pressure *= 1e4;
            d.solver = SOFTSHELL_SOLVER_PBD
        }),
    ];
    for (name, edit) in cases {
        let mut def = base;
        def.stop_volume_ratio = 0.0;
        edit(&mut def);
        let shell = new_shell(&mesh, &def).unwrap();
        let mut unstable = 0;
        for _ in 0..if name.contains("300") { 300 } else { 30 } {
            let before = positions(&shell);
            match step(&shell) {
                Ok(s) => assert!(s.volume.is_finite() && s.residual.is_finite(), "{name}"),
                Err(status) => {
                    assert_eq!(status, SoftshellStatus::Unstable, "{name}: {}", last_error());
                    assert!(
                        last_error().contains("would be stable") && last_error().contains("rolled back"),
                        "{}",
                        last_error()
                    );
                    println!("{name}: {}", last_error());
                    assert_eq!(positions(&shell), before, "{name}: an unstable step must roll back");
                    unstable += 1;
                    break;
                }
            }
            assert!(positions(&shell).iter().all(|v| v.is_finite()), "{name}");
        }
        println!("{name}: {}", if unstable > 0 { "UNSTABLE, rolled back" } else { "finite" });
    }

    // The advice holds: with the time step the message asks for (8.5e-4 s here) and a stop
    // ratio, pressure x1e4 contracts to the end without diverging (SPEC 4).
    let mut def = base;
    def.pressure *= 1e4;
    def.time_step = 8.4e-4;
    let shell = new_shell(&mesh, &def).unwrap();
    let mut finished = false;
    for n in 0..1000 {
        let s = step(&shell).unwrap_or_else(|_| panic!("step {n}: {}", last_error()));
        assert!(s.volume.is_finite());
        if s.finished {
            finished = true;
            break;
        }
    }
    assert!(finished);

    // Sliver triangles: a tetrahedron with a 0.5 degree corner.
    let sliver = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.5, 0.004, 0.0, 0.4, 0.3, 0.6];
    let mesh = mesh_from(&sliver, &TETRA_TRI).unwrap();
    let shell = new_shell(&mesh, &base).unwrap();
    for _ in 0..100 {
        match step(&shell) {
            Ok(_) => {}
            Err(status) => assert_eq!(status, SoftshellStatus::Unstable),
        }
        assert!(positions(&shell).iter().all(|v| v.is_finite()));
    }
}

#[test]
fn memory_holds_only_what_the_scene_uses() {
    let mesh = unit_mesh("sphere.obj", 1.0);
    let def = softshell_shell_def_default();
    let shell = new_shell(&mesh, &def).unwrap();
    let plain = memory(&shell);
    assert!(plain > 0);

    let mut no_bending = def;
    no_bending.bending = SOFTSHELL_BENDING_NONE;
    assert!(memory(&new_shell(&mesh, &no_bending).unwrap()) < plain);
    let mut pbd = def;
    pbd.solver = SOFTSHELL_SOLVER_PBD;
    assert!(memory(&new_shell(&mesh, &pbd).unwrap()) < plain, "PBD keeps no multipliers");

    // Anisotropy storage appears only with a region.
    step(&shell).unwrap();
    assert_eq!(memory(&shell), plain, "stepping allocates nothing");
    let faces: Vec<u32> = (0..100).collect();
    let aniso = softshell_anisotropy_def_default();
    // SAFETY: live shell, slice and def.
    unsafe {
        assert_eq!(softshell_shell_add_anisotropic_region(shell.0, faces.as_ptr(), 100, &aniso), SoftshellStatus::Ok);
    }
    let with_region = memory(&shell);
    assert!(with_region >= plain + 100 * 40, "{plain} -> {with_region}");
}

#[test]
fn regions_and_buffers_are_checked() {
    let mesh = unit_mesh("sphere.obj", 1.0);
    let shell = new_shell(&mesh, &softshell_shell_def_default()).unwrap();
    let aniso = softshell_anisotropy_def_default();
    // SAFETY: live shell; deliberate bad arguments.
    unsafe {
        let bad = [0u32, 5000];
        assert_eq!(
            softshell_shell_add_anisotropic_region(shell.0, bad.as_ptr(), 2, &aniso),
            SoftshellStatus::InvalidArgument
        );
        assert!(last_error().contains("5000"), "{}", last_error());
        let twice = [3u32, 3];
        assert_eq!(
            softshell_shell_add_anisotropic_region(shell.0, twice.as_ptr(), 2, &aniso),
            SoftshellStatus::InvalidArgument
        );
        assert_eq!(softshell_shell_add_anisotropic_region(shell.0, null(), 2, &aniso), SoftshellStatus::NullArgument);
        assert_eq!(
            softshell_shell_add_anisotropic_region(shell.0, null(), 0, &aniso),
            SoftshellStatus::InvalidArgument
        );
        let mut wrong = aniso;
        wrong.energy = 9;
        let ok = [1u32, 2];
        assert_eq!(
            softshell_shell_add_anisotropic_region(shell.0, ok.as_ptr(), 2, &wrong),
            SoftshellStatus::InvalidArgument
        );
        wrong = aniso;
        wrong.stiffness = 0.0;
        assert_eq!(
            softshell_shell_add_anisotropic_region(shell.0, ok.as_ptr(), 2, &wrong),
            SoftshellStatus::InvalidArgument
        );
        assert!(last_error().contains("stiffness"));
        wrong = aniso;
        wrong.target_stretch = 1.5;
        assert_eq!(
            softshell_shell_add_anisotropic_region(shell.0, ok.as_ptr(), 2, &wrong),
            SoftshellStatus::InvalidArgument
        );
        assert!(last_error().contains("target_stretch"));
        wrong = aniso;
        wrong.direction[1] = f32::NAN;
        assert_eq!(
            softshell_shell_add_anisotropic_region(shell.0, ok.as_ptr(), 2, &wrong),
            SoftshellStatus::InvalidArgument
        );
        wrong = aniso;
        wrong.internal_cookie = 0;
        assert_eq!(
            softshell_shell_add_anisotropic_region(shell.0, ok.as_ptr(), 2, &wrong),
            SoftshellStatus::InvalidArgument
        );

        let n = softshell_shell_vertex_count(shell.0);
        assert_eq!(n, 482);
        let mut small = [0.0f32; 3];
        let mut len = 0;
        assert_eq!(
            softshell_shell_copy_positions(shell.0, small.as_mut_ptr(), 3, &mut len),
            SoftshellStatus::BufferTooSmall
        );
        assert_eq!((len, small), (3 * n, [0.0; 3]));
        assert_eq!(
            softshell_shell_copy_positions(shell.0, small.as_mut_ptr(), 3, null_mut()),
            SoftshellStatus::NullArgument
        );

        let mut energy = vec![-1.0f32; 960];
        assert_eq!(softshell_shell_copy_face_energy(shell.0, null_mut(), 0, &mut len), SoftshellStatus::BufferTooSmall);
        assert_eq!(len, 960);
        assert_eq!(softshell_shell_copy_face_energy(shell.0, energy.as_mut_ptr(), 960, &mut len), SoftshellStatus::Ok);
        assert!(energy.iter().all(|&e| e.abs() < 1e-9), "at rest every face energy is 0");

        let mut curvature = vec![0.0f32; n];
        assert_eq!(
            softshell_shell_copy_vertex_curvature(shell.0, 7, curvature.as_mut_ptr(), n, &mut len),
            SoftshellStatus::InvalidArgument
        );
        assert_eq!(
            softshell_shell_copy_vertex_curvature(
                shell.0,
                SOFTSHELL_CURVATURE_MEAN,
                curvature.as_mut_ptr(),
                n,
                &mut len
            ),
            SoftshellStatus::Ok
        );
        // The unit-diagonal sphere has radius 1/(2 sqrt 3): mean curvature about 3.46.
        let mean = curvature.iter().sum::<f32>() / n as f32;
        assert!((mean - 2.0 * 3f32.sqrt()).abs() < 0.2, "{mean}");
        assert_eq!(
            softshell_shell_copy_vertex_curvature(
                shell.0,
                SOFTSHELL_CURVATURE_GAUSSIAN,
                curvature.as_mut_ptr(),
                n,
                &mut len
            ),
            SoftshellStatus::Ok
        );
    }
    // After contracting, faces carry energy.
    for _ in 0..20 {
        step(&shell).unwrap();
    }
    let mut energy = vec![0.0f32; 960];
    let mut len = 0;
    // SAFETY: live shell and buffer.
    unsafe { softshell_shell_copy_face_energy(shell.0, energy.as_mut_ptr(), 960, &mut len) };
    assert!(energy.iter().any(|&e| e > 0.0) && energy.iter().all(|e| e.is_finite() && *e >= 0.0));
}

#[test]
fn a_finished_shell_stops_moving_and_stats_may_be_skipped() {
    let mesh = unit_mesh("sphere.obj", 1.0);
    let mut def = softshell_shell_def_default();
    def.stop_volume_ratio = 0.95;
    let shell = new_shell(&mesh, &def).unwrap();
    let mut finished = None;
    for _ in 0..200 {
        // SAFETY: live shell; NULL stats are allowed.
        assert_eq!(unsafe { softshell_shell_step(shell.0, null_mut()) }, SoftshellStatus::Ok);
        let s = step(&shell).unwrap();
        if s.finished {
            assert!(s.volume_ratio < 0.95);
            finished = Some(s);
            break;
        }
    }
    let at_stop = finished.expect("the shell never reached its stop ratio");
    let frozen = positions(&shell);
    let again = step(&shell).unwrap();
    assert!(again.finished && again.step == at_stop.step);
    assert_eq!(positions(&shell), frozen);
}

/// The residual measures how far the iterations got on the constraints they solve: with each
/// kind of bending it falls as the iterations grow. (With the rest curvature kept, the
/// default, it was measured against the stencils' frames at the end of the step while the
/// iterations hold the target of the frames at the substep's start: it stayed at 3.1e-5 from 5
/// to 1,000 iterations, found in a review.)
#[test]
fn the_residual_falls_as_the_iterations_grow_with_every_bending() {
    let mesh = unit_mesh("sphere.obj", 1.0);
    for bending in [SOFTSHELL_BENDING_ISOMETRIC_REST, SOFTSHELL_BENDING_ISOMETRIC, SOFTSHELL_BENDING_NONE] {
        let residual = |iterations: u32| {
            let def = SoftshellShellDef { bending, iterations, collisions: false, ..softshell_shell_def_default() };
            let shell = new_shell(&mesh, &def).unwrap();
            (0..10).map(|_| step(&shell).unwrap().residual).last().unwrap()
        };
        let (few, many) = (residual(5), residual(100));
        assert!(many < 0.2 * few, "bending {bending}: residual {few:.3e} after 5 iterations, {many:.3e} after 100");
    }
}
