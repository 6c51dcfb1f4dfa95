//! Random sessions of calls through the C ABI on bodies large enough for their work to be shared
//! among threads, each replayed on 1, 2 and 3 threads: the header promises that results do not
//! depend on `threads`, and every status and error message, every stats field but the
//! wall-clock time, and every buffer after every call must be the same to the bit.
//!
//! `results_do_not_depend_on_the_thread_count` (tests/ffi_body_api.rs) checks that promise on
//! six fixed scenes; these sessions also crack, cut, release core blocks, pin, push and add
//! obstacles while they run, on every integrator, so that the parallel passes of the fracture
//! phase (fans found on two threads, the topology updated beside the warm start, springs and gas
//! rebuilt at the same time) and the solvers' chunked sums on a changing mesh are compared too.
//! The bodies have more than 2,048 vertices and 4,096 faces (the chunks of the parallel passes),
//! and more than 2,048 vertices is also where a body keeps its vertices in an order of its own.
//!
//! CI runs a few sessions; `SOFTSHELL_THREAD_SESSIONS=<first>..<end>` runs other seeds and
//! `SOFTSHELL_THREAD_ACTIONS=<n>` sets the calls a session makes.
#![cfg(feature = "body")]

mod body_util;
mod random;

use body_util::*;
use random::{Outcome, Rng, count, replay_on_threads, seeds};
use softshell::ffi::body::*;
use softshell::ffi::{SoftshellBodyDef, SoftshellBodyStats, SoftshellStatus};

/// A random scene: a ball of 2,562 vertices (with gas or without) or a cloth of 2,809, with
/// settings drawn as a game or a film would set them, fracture more often than not.
fn random_scene(rng: &mut Rng) -> (Vec<f32>, Vec<u32>, SoftshellBodyDef) {
    let mut def = softshell_body_def_default();
    let closed = rng.chance(0.7);
    let (mut positions, triangles) = if closed { icosphere(4, rng.uniform(0.3, 1.5)) } else { cloth(52, 2.0) };
    if !closed {
        for c in positions.chunks_exact_mut(3) {
            c[1] += 0.5;
        }
    }
    def.integrator = [
        SOFTSHELL_INTEGRATOR_EXPLICIT_EULER,
        SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER,
        SOFTSHELL_INTEGRATOR_IMPLICIT_EULER,
        SOFTSHELL_INTEGRATOR_IMPLICIT_EULER,
        SOFTSHELL_INTEGRATOR_XPBD,
    ][rng.below(5) as usize];
    let explicit = def.integrator == SOFTSHELL_INTEGRATOR_EXPLICIT_EULER
        || def.integrator == SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER;
    def.time_step = if explicit { 1.0 / 240.0 } else { [1.0 / 240.0, 1.0 / 60.0, 1.0 / 15.0][rng.below(3) as usize] };
    def.substeps = if explicit { 10 + rng.below(30) as u32 } else { 1 + rng.below(3) as u32 };
    def.iterations = 1 + rng.below(12) as u32;
    def.total_mass = rng.decades(-1.0, 2.0);
    // (The explicit integrators' stable step shrinks with the stiffness: softer springs there,
    // so that most of their steps go through.)
    def.spring_stiffness = if explicit { rng.decades(0.5, 2.5) } else { rng.decades(1.0, 4.5) };
    def.spring_damping = if rng.chance(0.3) { 0.0 } else { rng.decades(-2.0, if explicit { -1.0 } else { 1.0 }) };
    if closed && rng.chance(0.8) {
        def.gas_amount = rng.decades(0.0, 3.5);
    }
    if rng.chance(0.2) {
        def.gravity = [0.0; 3];
    }
    if rng.chance(0.3) {
        def.wind = [rng.uniform(-20.0, 20.0), rng.uniform(-3.0, 3.0), rng.uniform(-20.0, 20.0)];
        def.drag = rng.decades(-2.0, 0.5);
    }
    if rng.chance(0.6) {
        def.break_strain = rng.uniform(0.02, 0.3);
    }
    if rng.chance(0.3) {
        def.break_force = rng.decades(-1.0, 2.5);
    }
    if rng.chance(0.3) {
        def.leak_rate = rng.decades(-5.0, -2.0);
    }
    if rng.chance(0.6) {
        def.ground = true;
        let lowest = positions.chunks_exact(3).map(|c| c[1]).fold(f32::INFINITY, f32::min);
        def.ground_height = lowest - rng.uniform(0.0, 0.3);
        def.restitution = rng.uniform(0.0, 1.0);
        def.friction = rng.uniform(0.0, 1.5);
    }
    (positions, triangles, def)
}

fn stats_bits(s: &SoftshellBodyStats) -> Vec<u64> {
    let mut bits = vec![s.step, s.springs_broken, s.cores_released, s.topology_generation];
    bits.extend([s.vertex_count, s.triangle_count, s.fragment_count].map(|c| c as u64));
    bits.extend([s.time, s.volume, s.pressure, s.kinetic_energy, s.energy_drift, s.max_strain].map(f64::to_bits));
    bits.extend([s.volume_clamped as u64, s.solver_iterations]);
    bits
}

fn state_bits(s: &Snapshot) -> Vec<u64> {
    let mut bits = vec![s.generation, s.fragment_count as u64];
    for floats in [&s.positions, &s.velocities, &s.masses] {
        bits.push(floats.len() as u64);
        bits.extend(floats.iter().map(|x| x.to_bits() as u64));
    }
    for ints in [&s.triangles, &s.origins, &s.fragments] {
        bits.push(ints.len() as u64);
        bits.extend(ints.iter().map(|&i| i as u64));
    }
    bits
}

/// Tallies of what the sessions did (so that a change that refuses every call cannot pass
/// unseen).
#[derive(Default, Debug)]
struct Tally {
    steps_ok: usize,
    steps_unstable: usize,
    cracking_steps: usize,
    cuts_ok: usize,
    cuts_refused: usize,
    impulses: usize,
    pins: usize,
    obstacles: usize,
    /// OK steps of bodies with gas, per integrator (`SOFTSHELL_INTEGRATOR_*`): every integrator
    /// measures the gas on the body's threads, so each must be compared with gas.
    gas_steps_ok: [usize; 4],
}

/// Runs session `seed` with `threads` and returns each call's outcome. The calls depend only
/// on the seed and on what the body reports (which the comparison requires to be the same), so
/// every thread count makes the same calls as long as the outcomes agree.
fn run_session(seed: u64, actions: usize, threads: u32, tally: &mut Tally) -> Vec<Outcome> {
    let mut rng = Rng(seed);
    let (positions, triangles, mut def) = random_scene(&mut rng);
    def.threads = threads;
    let body = body(&positions, &triangles, &def);
    let mut outcomes = Vec::with_capacity(actions);
    let mut s = snapshot(&body);
    for k in 0..actions {
        let vertices = s.vertex_count() as u32;
        let (call, status, stats) = match rng.below(10) {
            0..=5 => {
                let mut stats = SoftshellBodyStats::default();
                // SAFETY: live body, writable stats.
                let status = unsafe { softshell_body_step(body.0, &mut stats) };
                match status {
                    SoftshellStatus::Ok => {
                        tally.steps_ok += 1;
                        if def.gas_amount > 0.0 {
                            tally.gas_steps_ok[def.integrator as usize] += 1;
                        }
                        tally.cracking_steps += (stats.springs_broken + stats.cores_released > 0) as usize;
                    }
                    SoftshellStatus::Unstable => tally.steps_unstable += 1,
                    other => panic!("seed {seed}, call {k}: a step returned {other:?}: {}", last_error()),
                }
                ("step".to_string(), status, Some(stats_bits(&stats)))
            }
            6 | 7 => {
                // A cut along a path of up to 8 edges from a random face (a slit), or a few
                // edges anywhere.
                let t = &s.triangles;
                let faces = t.len() / 3;
                let mut pairs: Vec<u32> = Vec::new();
                if rng.chance(0.5) {
                    let f = rng.below(faces as u64) as usize;
                    let mut a = t[3 * f];
                    let mut at = f;
                    for _ in 0..1 + rng.below(8) {
                        let b = t[3 * at + 1 + rng.below(2) as usize];
                        if a == b {
                            break;
                        }
                        pairs.extend([a, b]);
                        a = b;
                        // On to another face of b, the first one found after `at`.
                        at = (1..faces).map(|d| (at + d) % faces).find(|&g| t[3 * g] == b).unwrap_or(at);
                    }
                } else {
                    for _ in 0..1 + rng.below(4) {
                        let f = rng.below(faces as u64) as usize;
                        let side = rng.below(3) as usize;
                        pairs.extend([t[3 * f + side], t[3 * f + (side + 1) % 3]]);
                    }
                }
                let mut broken = 0usize;
                // SAFETY: `pairs` holds pairs.len() / 2 pairs; writable count.
                let status =
                    unsafe { softshell_body_break_edges(body.0, pairs.as_ptr(), pairs.len() / 2, &mut broken) };
                if status == SoftshellStatus::Ok {
                    tally.cuts_ok += 1;
                } else {
                    tally.cuts_refused += 1;
                }
                (format!("cut {pairs:?} ({broken} broken)"), status, None)
            }
            8 => {
                let v = rng.below(vertices as u64) as u32;
                let size = rng.decades(-3.0, 0.5);
                let impulse =
                    [rng.uniform(-1.0, 1.0) * size, rng.uniform(-1.0, 1.0) * size, rng.uniform(-1.0, 1.0) * size];
                tally.impulses += 1;
                // SAFETY: live body, three floats.
                let status = unsafe { softshell_body_apply_impulse(body.0, v, impulse.as_ptr()) };
                (format!("impulse {impulse:?} on {v}"), status, None)
            }
            _ => {
                if rng.chance(0.5) {
                    let v = rng.below(vertices as u64) as u32;
                    tally.pins += 1;
                    // SAFETY: live body.
                    let status = unsafe { softshell_body_pin_vertex(body.0, v) };
                    (format!("pin {v}"), status, None)
                } else {
                    let center = [rng.uniform(-2.0, 2.0), rng.uniform(-2.0, 0.0), rng.uniform(-2.0, 2.0)];
                    let radius = rng.uniform(0.05, 0.5);
                    tally.obstacles += 1;
                    // SAFETY: live body, three floats.
                    let status = unsafe { softshell_body_add_sphere_obstacle(body.0, center.as_ptr(), radius) };
                    (format!("sphere {center:?} r {radius}"), status, None)
                }
            }
        };
        let message = if status == SoftshellStatus::Ok { String::new() } else { last_error() };
        s = snapshot(&body);
        outcomes.push(Outcome { call, status, message, stats, state: state_bits(&s) });
    }
    outcomes
}

/// The seeds CI runs: among them every integrator steps a body with gas (asserted).
const DEFAULT_SEEDS: std::ops::Range<u64> = 0..6;

#[test]
fn random_sessions_give_the_same_bits_on_every_thread_count() {
    let seeds = seeds("SOFTSHELL_THREAD_SESSIONS", DEFAULT_SEEDS);
    let actions = count("SOFTSHELL_THREAD_ACTIONS", 24);
    let mut tally = Tally::default();
    let failures =
        replay_on_threads(seeds.clone(), &mut tally, |seed, threads, tally| run_session(seed, actions, threads, tally));
    eprintln!("thread sessions {seeds:?}, {actions} calls each: {tally:?}");
    assert!(failures.is_empty(), "results depend on the thread count:\n{}", failures.join("\n"));
    // The sessions did what they are for.
    let sessions = (seeds.end - seeds.start) as usize;
    assert!(tally.steps_ok >= sessions * actions / 4, "{tally:?}");
    assert!(tally.cuts_ok > 0 && tally.impulses > 0, "{tally:?}");
    if seeds == DEFAULT_SEEDS {
        assert!(tally.gas_steps_ok.iter().all(|&k| k > 0), "an integrator not stepped with gas: {tally:?}");
    }
}
