//! Random sessions of the shell through the C ABI: shells made with settings drawn across their
//! documented ranges (and at their ends), every solver, material and bending kind, collisions
//! on and off, anisotropic regions added on the way, then stepped. After every call, whatever
//! it returned:
//! - the status is one the call documents (a step: OK or UNSTABLE; a region: OK, or
//!   INVALID_ARGUMENT for one this test makes invalid on purpose);
//! - an UNSTABLE step left the positions as they were (to the bit) and its message says which
//!   settings would be stable; a refused region changed nothing;
//! - no NaN or infinity reaches the caller (positions, face energies, curvatures, every stats
//!   field), and a finished shell stays where it finished.
//!
//! Fixed seeds, so that a failure repeats; `SOFTSHELL_SHELL_SESSIONS=<first>..<end>` runs others
//! and `SOFTSHELL_SHELL_ACTIONS=<n>` makes each session n calls long instead of 12.
#![cfg(feature = "shell")]

mod common;
mod random;

use std::ptr::null_mut;

use common::*;
use random::{Rng, count, seeds};
use softshell::ffi::SoftshellStatus;
use softshell::ffi::mesh::*;
use softshell::ffi::shell::*;

fn random_def(rng: &mut Rng) -> SoftshellShellDef {
    let mut d = softshell_shell_def_default();
    d.solver = rng.below(3) as u32;
    d.material = rng.below(5) as u32;
    d.bending = rng.below(3) as u32;
    d.time_step = [1.0 / 240.0, 1.0 / 60.0, 1.0 / 15.0][rng.below(3) as usize];
    d.substeps = 1 + rng.below(3) as u32;
    d.iterations = 1 + rng.below(10) as u32;
    d.threads = rng.below(3) as u32;
    d.pressure = rng.decades(-2.0, 3.0) * if rng.chance(0.2) { -1.0 } else { 1.0 };
    d.youngs_modulus = rng.decades(1.0, 6.0);
    d.poisson_ratio = rng.uniform(0.0, 0.49);
    d.thickness = rng.decades(-4.0, -1.0);
    d.density = rng.decades(1.0, 4.0);
    d.bending_coefficient = if rng.chance(0.2) { 0.0 } else { rng.decades(-3.0, 0.0) };
    d.damping = rng.decades(-1.0, 2.0);
    d.stop_volume_ratio = rng.uniform(0.0, 0.9);
    // Collisions cost what the motion per substep sweeps (documented): on only at moderate
    // pressures, so that the sessions stay short.
    d.collisions = rng.chance(0.3);
    if d.collisions {
        d.pressure = d.pressure.clamp(-10.0, 10.0);
    }
    // The ends of the documented ranges, each with probability 1/4.
    if let Some(h) = rng.end(1e-6, 1.0) {
        d.time_step = h;
    }
    if let Some(i) = rng.end(1.0, 1000.0) {
        d.iterations = i as u32;
    }
    if let (false, Some(p)) = (d.collisions, rng.end(-1e12, 1e12)) {
        d.pressure = p;
    }
    if let Some(e) = rng.end(1e-30, 1e12) {
        d.youngs_modulus = e;
    }
    if let Some(n) = rng.end(0.0, 0.49) {
        d.poisson_ratio = n;
    }
    if let Some(t) = rng.end(1e-6, 1e3) {
        d.thickness = t;
    }
    if let Some(r) = rng.end(1e-6, 1e9) {
        d.density = r;
    }
    if let Some(k) = rng.end(0.0, 1e6) {
        d.bending_coefficient = k;
    }
    if let Some(c) = rng.end(0.0, 1e6) {
        d.damping = c;
    }
    if let Some(s) = rng.end(0.0, 0.999_999) {
        d.stop_volume_ratio = s;
    }
    d
}

fn positions(shell: *mut SoftshellShell) -> Vec<f32> {
    let mut len = 0usize;
    // SAFETY: live shell; a NULL buffer asks for the size.
    let status = unsafe { softshell_shell_copy_positions(shell, null_mut(), 0, &mut len) };
    assert_eq!(status, SoftshellStatus::BufferTooSmall);
    let mut out = vec![0.0f32; len];
    // SAFETY: `out` holds `len` floats.
    let status = unsafe { softshell_shell_copy_positions(shell, out.as_mut_ptr(), len, &mut len) };
    assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
    out
}

fn finite_stats(s: &SoftshellShellStats) -> bool {
    [
        s.time,
        s.volume,
        s.volume_ratio,
        s.residual,
        s.elastic_energy,
        s.bending_energy,
        s.anisotropic_energy,
        s.step_seconds,
    ]
    .iter()
    .all(|v| v.is_finite())
}

#[derive(Default, Debug)]
struct Tally {
    sessions: usize,
    refused: usize,
    steps_ok: usize,
    steps_unstable: usize,
    finished: usize,
    regions: usize,
    regions_refused: usize,
}

fn run_session(seed: u64, actions: usize, tally: &mut Tally) {
    let mut rng = Rng(seed);
    let name = ["sphere.obj", "eight.obj"][rng.below(2) as usize];
    let def = random_def(&mut rng);
    let mesh = load_data_mesh(name);
    let faces = mesh_triangles(mesh).len() / 3;
    let mut shell = null_mut();
    // SAFETY: live mesh and def, writable out pointer.
    let status = unsafe { softshell_shell_new(mesh, &def, &mut shell) };
    let message = last_error();
    // SAFETY: made above; the shell keeps what it needs.
    unsafe { softshell_mesh_free(mesh) };
    let what = |action: usize, call: &str| format!("seed {seed}, action {action} ({call}), {name}, {def:?}");
    if status != SoftshellStatus::Ok {
        // Only a refusal the def explains (a vertex too light for f32, a collision thickness
        // above the mesh's spacing), with its reason.
        assert_eq!(status, SoftshellStatus::InvalidArgument, "{}: {message}", what(0, "new"));
        assert!(!message.is_empty());
        tally.refused += 1;
        return;
    }
    tally.sessions += 1;
    let mut current = positions(shell);
    let mut finished_at: Option<Vec<f32>> = None;
    for action in 1..=actions {
        if rng.chance(0.2) {
            // An anisotropic region of random faces; now and then one that repeats a face,
            // which must be refused with nothing changed.
            let count = 1 + rng.below(faces as u64 / 4) as usize;
            let start = rng.below(faces as u64) as usize;
            let mut region: Vec<u32> = (0..count).map(|k| ((start + 3 * k) % faces) as u32).collect();
            region.sort_unstable();
            region.dedup();
            let invalid = rng.chance(0.2);
            if invalid {
                region.push(region[0]);
            }
            let mut a = softshell_anisotropy_def_default();
            a.energy = rng.below(3) as u32;
            a.stiffness = rng.decades(0.0, 6.0);
            a.inward_push = rng.decades(-4.0, 0.0);
            a.target_stretch = rng.uniform(0.5, 1.0);
            // SAFETY: live shell; `region` holds its faces.
            let status = unsafe { softshell_shell_add_anisotropic_region(shell, region.as_ptr(), region.len(), &a) };
            let message = last_error();
            let after = positions(shell);
            if invalid {
                assert_eq!(status, SoftshellStatus::InvalidArgument, "{}: {message}", what(action, "region"));
                tally.regions_refused += 1;
            } else {
                assert_eq!(status, SoftshellStatus::Ok, "{}: {message}", what(action, "region"));
                tally.regions += 1;
            }
            assert_eq!(after, current, "{}: a region moved vertices", what(action, "region"));
            continue;
        }
        let mut stats = SoftshellShellStats::default();
        // SAFETY: live shell, writable stats.
        let status = unsafe { softshell_shell_step(shell, &mut stats) };
        let message = last_error();
        let after = positions(shell);
        let call = what(action, "step");
        match status {
            SoftshellStatus::Ok => {
                tally.steps_ok += 1;
                assert!(finite_stats(&stats), "{call}: stats {stats:?}");
                assert!(after.iter().all(|v| v.is_finite()), "{call}: a position is not finite");
                let energy = copied(shell, softshell_shell_copy_face_energy);
                assert!(energy.iter().all(|v| v.is_finite()), "{call}: a face energy is not finite");
                for kind in [SOFTSHELL_CURVATURE_MEAN, SOFTSHELL_CURVATURE_GAUSSIAN] {
                    let mut len = 0usize;
                    let mut curvature = vec![0.0f32; after.len() / 3];
                    // SAFETY: live shell; `curvature` holds one float per vertex.
                    let status = unsafe {
                        softshell_shell_copy_vertex_curvature(
                            shell,
                            kind,
                            curvature.as_mut_ptr(),
                            curvature.len(),
                            &mut len,
                        )
                    };
                    assert_eq!(status, SoftshellStatus::Ok, "{call}: {}", last_error());
                    assert!(curvature.iter().all(|v| v.is_finite()), "{call}: a curvature (kind {kind}) is not finite");
                }
                if let Some(at) = &finished_at {
                    assert!(stats.finished, "{call}: a finished shell is no longer finished");
                    assert_eq!(&after, at, "{call}: a finished shell moved");
                } else if stats.finished {
                    tally.finished += 1;
                    finished_at = Some(after.clone());
                }
            }
            SoftshellStatus::Unstable => {
                tally.steps_unstable += 1;
                assert!(message.contains("would be stable"), "{call}: no advice in {message}");
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&after), bits(&current), "{call}: an UNSTABLE step moved vertices");
            }
            other => panic!("{call}: status {other:?}: {message}"),
        }
        current = after;
    }
    // SAFETY: made above, freed once.
    unsafe { softshell_shell_free(shell) };
}

#[test]
fn random_shell_sessions_keep_every_promise_of_the_abi() {
    let seeds = seeds("SOFTSHELL_SHELL_SESSIONS", 0..40u64);
    let actions = count("SOFTSHELL_SHELL_ACTIONS", 12);
    let mut tally = Tally::default();
    for seed in seeds.clone() {
        run_session(seed, actions, &mut tally);
    }
    println!("{tally:?}");
    let sessions = (seeds.end - seeds.start) as usize;
    assert!(tally.sessions * 4 >= sessions * 3, "{tally:?}");
    assert!(tally.steps_ok > 0 && tally.steps_unstable > 0 && tally.regions > 0, "{tally:?}");
}
