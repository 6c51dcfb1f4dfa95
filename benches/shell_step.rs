//! Speed of the shell step on the kitten (10,000 vertices, 20,000 triangles, scaled to a unit
//! diagonal): 5 iterations, collisions off, 1 and 2 threads; milliseconds per step and
//! constraint projections per second. Run with `cargo bench --bench shell_step`.
//!
//! Anchor (issue 3): Bender's PositionBasedDynamics (FEM triangle + isometric bending, 5
//! iterations, one thread) reaches about 26 million projections per second on this machine.

use std::ptr::null_mut;
use std::time::Instant;

use softshell::ffi::boundary::SoftshellStatus;
use softshell::ffi::mesh::*;
use softshell::ffi::shell::*;

// The tests' OBJ reader and unit-diagonal scaling, shared rather than copied.
#[path = "../tests/report_util/mod.rs"]
mod report_util;

fn unit_kitten() -> (*mut SoftshellMesh, usize, usize) {
    let (pos, tri) = report_util::unit_obj("kitten.obj", 1.0);
    let mut mesh = null_mut();
    // SAFETY: live slices with their lengths.
    let status =
        unsafe { softshell_mesh_from_arrays(pos.as_ptr(), pos.len() / 3, tri.as_ptr(), tri.len() / 3, &mut mesh) };
    assert_eq!(status, SoftshellStatus::Ok);
    (mesh, pos.len() / 3, tri.len() / 3)
}

/// CPU seconds used by the whole process so far (all its threads): on a shared machine wall time
/// includes waiting for a core, CPU time does not.
fn process_cpu_seconds() -> f64 {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: a valid clock id and a writable timespec.
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

/// Edges of a closed mesh: 3F/2; interior edges are all of them (one bending stencil each).
fn main() {
    let (mesh, vertices, triangles) = unit_kitten();
    let edges = triangles * 3 / 2;
    let steps = 100;
    println!("kitten: {vertices} vertices, {triangles} triangles, {edges} bending stencils; {steps} steps each");
    println!(
        "{:<36} {:>9} {:>9} {:>9} {:>11} {:>11}",
        "setting", "ms/step", "min ms", "CPU ms", "Mproj/s", "Mproj/CPU-s"
    );
    for (name, solver, pressure, measure) in [
        ("XPBD, pressure 0 (at rest)", SOFTSHELL_SOLVER_XPBD, 0.0f32, false),
        ("XPBD, default pressure", SOFTSHELL_SOLVER_XPBD, -1.0, false),
        ("XPBD, default pressure, with stats", SOFTSHELL_SOLVER_XPBD, -1.0, true),
        ("PBD (paper), pressure 1", SOFTSHELL_SOLVER_PBD, 1.0, false),
    ] {
        for threads in [1u32, 2] {
            let mut def = softshell_shell_def_default();
            def.iterations = 5;
            def.collisions = false;
            def.stop_volume_ratio = 0.0;
            def.threads = threads;
            def.solver = solver;
            if pressure >= 0.0 {
                def.pressure = pressure;
            }
            let mut shell = null_mut();
            // SAFETY: live mesh and def.
            assert_eq!(unsafe { softshell_shell_new(mesh, &def, &mut shell) }, SoftshellStatus::Ok);
            let mut stats = SoftshellShellStats::default();
            let out = if measure { &mut stats as *mut _ } else { null_mut() };
            let mut times = Vec::with_capacity(steps);
            let mut cpu_start = 0.0;
            for i in 0..steps + 5 {
                if i == 5 {
                    cpu_start = process_cpu_seconds();
                }
                let start = Instant::now();
                // SAFETY: live shell; out is NULL or a live local.
                assert_eq!(unsafe { softshell_shell_step(shell, out) }, SoftshellStatus::Ok);
                times.push(start.elapsed().as_secs_f64());
            }
            let cpu = (process_cpu_seconds() - cpu_start) / steps as f64;
            let times = &times[5..];
            let mean = times.iter().sum::<f64>() / times.len() as f64;
            let min = times.iter().cloned().fold(f64::MAX, f64::min);
            let projections = (def.iterations as usize * (triangles + edges)) as f64;
            println!(
                "{:<36} {:>9.3} {:>9.3} {:>9.3} {:>11.1} {:>11.1}   ({threads} thread{})",
                name,
                mean * 1e3,
                min * 1e3,
                cpu * 1e3,
                projections / mean / 1e6,
                projections / cpu / 1e6,
                if threads == 1 { "" } else { "s" }
            );
            // SAFETY: made above, freed once.
            unsafe { softshell_shell_free(shell) };
        }
    }
    // SAFETY: made above, freed once.
    unsafe { softshell_mesh_free(mesh) };
}
