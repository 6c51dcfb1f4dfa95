//! Random sessions of the shell through the C ABI, each replayed on 1, 2 and 3 threads: the
//! header promises for `SoftshellShellDef.threads` that results are bit-identical whatever the
//! count, and every status and error message, every stats field but the wall-clock time, and the
//! positions, face energies and curvatures after every call must be the same to the bit.
//!
//! `results_are_bit_identical_for_1_2_and_4_threads` (tests/ffi_shell.rs) checks that promise on
//! one scene (the default def on the kitten with one region); these sessions draw every solver,
//! material and bending kind, collisions on and off, steps that measure and steps that do not
//! (NULL stats: the energies and the residual keep their last values), steps that diverge and are
//! rolled back, and anisotropic regions of every energy added on the way (some refused), so that
//! every parallel pass and every reduction of the step is compared, on a state that changes.
//! The meshes are the hand (6,338 vertices, 12,672 faces), the kitten (10,000 and 20,000) and the
//! bear (10,141 and 20,278): a pass runs on several threads only for a colour of at least
//! 2 x 256 constraints (`shell::exec::MIN_PARALLEL`), and a reduction splits into chunks of
//! 2,048 items (`REDUCE_CHUNK`), so smaller meshes (the sphere's 960 faces) would compare the
//! serial path with itself.
//!
//! CI runs a few sessions; `SOFTSHELL_SHELL_THREAD_SESSIONS=<first>..<end>` runs other seeds and
//! `SOFTSHELL_SHELL_THREAD_ACTIONS=<n>` sets the calls a session makes.
#![cfg(feature = "shell")]

mod common;
mod random;

use std::ptr::null_mut;

use common::*;
use random::{Outcome, Rng, count, replay_on_threads, seeds};
use softshell::ffi::SoftshellStatus;
use softshell::ffi::mesh::*;
use softshell::ffi::shell::*;

/// Meshes whose colours and reductions are large enough to be split among threads.
const MESHES: [&str; 3] = ["hand.obj", "kitten.obj", "bear.obj"];

/// A def as a film would set it (a bounding-box diagonal of about 2.5 m, as these meshes have),
/// now and then with a field at an end of its documented range, which may be refused or make
/// steps diverge (a rolled-back step must be the same on every thread count too).
fn random_def(rng: &mut Rng) -> SoftshellShellDef {
    let mut d = softshell_shell_def_default();
    d.solver = rng.below(3) as u32;
    d.material = rng.below(5) as u32;
    d.bending = rng.below(3) as u32;
    d.time_step = [1.0 / 240.0, 1.0 / 60.0, 1.0 / 15.0][rng.below(3) as usize];
    d.substeps = 1 + rng.below(3) as u32;
    d.iterations = 1 + rng.below(8) as u32;
    d.pressure = rng.decades(-1.0, 1.5) * if rng.chance(0.15) { -1.0 } else { 1.0 };
    d.youngs_modulus = rng.decades(2.0, 4.5);
    d.poisson_ratio = rng.uniform(0.0, 0.49);
    d.thickness = rng.decades(-3.5, -2.5);
    d.density = rng.decades(2.5, 3.5);
    d.bending_coefficient = if rng.chance(0.15) { 0.0 } else { rng.decades(-3.0, 0.0) };
    d.damping = rng.decades(-1.0, 1.5);
    // Mostly never finished: a finished shell's steps do nothing, and would compare nothing.
    d.stop_volume_ratio = if rng.chance(0.6) { 0.0 } else { rng.uniform(0.1, 0.7) };
    // Collisions cost what the motion per substep sweeps (documented): on only with short
    // steps and moderate pressures, so that the sessions stay short.
    d.collisions = rng.chance(0.4);
    if d.collisions {
        d.time_step = d.time_step.min(1.0 / 60.0);
        d.pressure = d.pressure.clamp(-3.0, 3.0);
        d.collision_thickness = [0.0, 1e-5, 1e-4][rng.below(3) as usize];
    }
    // Now and then one field at an end of its documented range: most make every step diverge
    // (or the def refused), which is compared too, but should not fill the sessions. (Not with
    // collisions, whose cost grows with the motion: a blow-up without them costs a step.)
    match rng.below(16) {
        0 if !d.collisions => d.pressure = if rng.chance(0.5) { -1e12 } else { 1e12 },
        1 if !d.collisions => d.youngs_modulus = if rng.chance(0.5) { 1e-30 } else { 1e12 },
        2 if !d.collisions => d.time_step = if rng.chance(0.5) { 1e-6 } else { 1.0 },
        3 => d.poisson_ratio = if rng.chance(0.5) { 0.0 } else { 0.49 },
        4 => d.bending_coefficient = if rng.chance(0.5) { 0.0 } else { 1e6 },
        5 => d.damping = if rng.chance(0.5) { 0.0 } else { 1e6 },
        _ => {}
    }
    d
}

fn curvature(shell: *mut SoftshellShell, kind: u32) -> Vec<f32> {
    // SAFETY: live shell.
    let mut out = vec![0.0f32; unsafe { softshell_shell_vertex_count(shell) }];
    let mut len = 0usize;
    // SAFETY: live shell; `out` holds one float per vertex.
    let status = unsafe { softshell_shell_copy_vertex_curvature(shell, kind, out.as_mut_ptr(), out.len(), &mut len) };
    assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
    out
}

/// Positions, face energies and both curvatures, floats as bits.
fn state_bits(shell: *mut SoftshellShell) -> Vec<u64> {
    let mut bits = Vec::new();
    for floats in [
        copied(shell, softshell_shell_copy_positions),
        copied(shell, softshell_shell_copy_face_energy),
        curvature(shell, SOFTSHELL_CURVATURE_MEAN),
        curvature(shell, SOFTSHELL_CURVATURE_GAUSSIAN),
    ] {
        bits.push(floats.len() as u64);
        bits.extend(floats.iter().map(|x| x.to_bits() as u64));
    }
    bits
}

fn stats_bits(s: &SoftshellShellStats) -> Vec<u64> {
    let mut bits = vec![s.step, s.collision_candidates, s.ccd_tests, s.contacts, s.finished as u64, s.stalled as u64];
    bits.extend(
        [s.time, s.volume, s.volume_ratio, s.residual, s.elastic_energy, s.bending_energy, s.anisotropic_energy]
            .map(f64::to_bits),
    );
    bits
}

/// Tallies of what the sessions did (so that a change that refuses every call cannot pass
/// unseen).
#[derive(Default, Debug)]
struct Tally {
    shells: usize,
    refused: usize,
    steps_ok: usize,
    steps_unmeasured: usize,
    steps_unstable: usize,
    steps_with_contacts: usize,
    finished: usize,
    regions: usize,
    regions_refused: usize,
}

/// Runs session `seed` with `threads` and returns each call's outcome, `new` first. The calls
/// depend only on the seed and on what the shell reports (which the comparison requires to be
/// the same), so every thread count makes the same calls as long as the outcomes agree.
fn run_session(seed: u64, actions: usize, threads: u32, tally: &mut Tally) -> Vec<Outcome> {
    let mut rng = Rng(seed);
    let name = MESHES[rng.below(MESHES.len() as u64) as usize];
    let mut def = random_def(&mut rng);
    let call = format!("new on {name}, {def:?}");
    def.threads = threads;
    let mesh = load_data_mesh(name);
    let faces = mesh_triangles(mesh).len() / 3;
    let mut shell = null_mut();
    // SAFETY: live mesh and def, writable out pointer.
    let status = unsafe { softshell_shell_new(mesh, &def, &mut shell) };
    // SAFETY: made above; the shell keeps what it needs.
    unsafe { softshell_mesh_free(mesh) };
    if status != SoftshellStatus::Ok {
        // (A def at an end of its range: PBD bending beyond 2, for one.)
        tally.refused += 1;
        return vec![Outcome { call, status, message: last_error(), stats: None, state: Vec::new() }];
    }
    tally.shells += 1;
    let mut outcomes = Vec::with_capacity(actions + 1);
    outcomes.push(Outcome { call, status, message: String::new(), stats: None, state: state_bits(shell) });
    let mut finished = false;
    for _ in 0..actions {
        let (call, status, stats) = match rng.below(20) {
            0..=11 => {
                let mut stats = SoftshellShellStats::default();
                // SAFETY: live shell, writable stats.
                let status = unsafe { softshell_shell_step(shell, &mut stats) };
                match status {
                    SoftshellStatus::Ok => {
                        tally.steps_ok += 1;
                        tally.steps_with_contacts += (stats.contacts > 0) as usize;
                        if stats.finished && !finished {
                            tally.finished += 1;
                            finished = true;
                        }
                    }
                    SoftshellStatus::Unstable => tally.steps_unstable += 1,
                    other => panic!("seed {seed}: a step returned {other:?}: {}", last_error()),
                }
                ("step".to_string(), status, Some(stats_bits(&stats)))
            }
            12..=14 => {
                // SAFETY: live shell; NULL stats measure nothing.
                let status = unsafe { softshell_shell_step(shell, null_mut()) };
                match status {
                    SoftshellStatus::Ok => tally.steps_unmeasured += 1,
                    SoftshellStatus::Unstable => tally.steps_unstable += 1,
                    other => panic!("seed {seed}: a step returned {other:?}: {}", last_error()),
                }
                ("step without stats".to_string(), status, None)
            }
            _ => {
                // A region of a stretch of faces (every face, or every second or third), some
                // large enough for their colours to be split among threads; now and then one
                // with a face repeated or out of range, which must be refused.
                let most = if rng.chance(0.5) { faces as u64 / 3 } else { 64 };
                let count = 1 + rng.below(most) as usize;
                let stride = 1 + rng.below(3) as usize;
                let start = rng.below(faces as u64) as usize;
                let mut region: Vec<u32> = (0..count).map(|k| ((start + stride * k) % faces) as u32).collect();
                region.sort_unstable();
                region.dedup();
                match rng.below(10) {
                    0 => region.push(region[0]),
                    1 => region.push(faces as u32),
                    _ => {}
                }
                let mut a = softshell_anisotropy_def_default();
                a.energy = rng.below(3) as u32;
                a.stiffness = rng.decades(1.0, 5.0);
                a.inward_push = if rng.chance(0.2) { 0.0 } else { rng.decades(-4.0, -1.0) };
                a.target_stretch = rng.uniform(0.5, 1.0);
                if rng.chance(0.3) {
                    a.direction = [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)];
                }
                // SAFETY: live shell; `region` holds its faces.
                let status =
                    unsafe { softshell_shell_add_anisotropic_region(shell, region.as_ptr(), region.len(), &a) };
                if status == SoftshellStatus::Ok {
                    tally.regions += 1;
                } else {
                    tally.regions_refused += 1;
                }
                (format!("region of {} faces from {start} by {stride}, {a:?}", region.len()), status, None)
            }
        };
        let message = if status == SoftshellStatus::Ok { String::new() } else { last_error() };
        outcomes.push(Outcome { call, status, message, stats, state: state_bits(shell) });
    }
    // SAFETY: made above, freed once.
    unsafe { softshell_shell_free(shell) };
    outcomes
}

#[test]
fn random_shell_sessions_give_the_same_bits_on_every_thread_count() {
    let seeds = seeds("SOFTSHELL_SHELL_THREAD_SESSIONS", 0..6u64);
    let actions = count("SOFTSHELL_SHELL_THREAD_ACTIONS", 12);
    let mut tally = Tally::default();
    let failures =
        replay_on_threads(seeds.clone(), &mut tally, |seed, threads, tally| run_session(seed, actions, threads, tally));
    eprintln!("shell thread sessions {seeds:?}, {actions} calls each: {tally:?}");
    assert!(failures.is_empty(), "results depend on the thread count:\n{}", failures.join("\n"));
    // The sessions did what they are for.
    let sessions = (seeds.end - seeds.start) as usize;
    assert!(tally.shells * 4 >= sessions * 3, "{tally:?}");
    assert!(tally.steps_ok >= tally.shells * actions / 4, "{tally:?}");
    assert!(tally.regions > 0, "{tally:?}");
}
