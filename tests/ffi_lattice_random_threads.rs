//! Random sessions of the lattice through the C ABI, each replayed on 1, 2 and 3 threads: the
//! header promises for `SoftshellLatticeDef.threads` that results are bit-identical for any
//! value, and every status and error message, every stats field but the wall-clock time, and the
//! positions, velocities and goals after every call must be the same to the bit.
//!
//! A step shares its rows among threads in blocks (`lattice::summation::row_block`: 32 rows, or
//! 4w + 2 for a wider region), the fit pass in one group of consecutive blocks per thread, whose
//! size does depend on the thread count; the update sums its statistics block by block. The
//! lattices here have at least six blocks of rows (two per thread on three threads) and a last
//! block that is mostly shorter, region half-widths from 1 to 16, damping on and off, holes in
//! their masks (scattered, whole bands of rows, a corner), and are driven by steps, pins, unpins,
//! forces (up to the largest finite ones), positions set (a moved copy of the sheet, or anywhere
//! up to ±1e15 m), cleared forces and refused calls, so that the goals (which run the fit pass
//! again) and every step's passes are compared on a state that changes.
//!
//! CI runs a few sessions; `SOFTSHELL_LATTICE_THREAD_SESSIONS=<first>..<end>` runs other seeds
//! and `SOFTSHELL_LATTICE_THREAD_ACTIONS=<n>` sets the calls a session makes.
#![cfg(feature = "lattice")]

mod common;
mod random;

use std::ptr::null_mut;

use common::*;
use random::{Outcome, Rng, count, lattice_refused_calls, replay_on_threads, seeds};
use softshell::ffi::SoftshellStatus;
use softshell::ffi::lattice::*;

/// The rows of a block of the step's passes for region half-width `w` (on a lattice of more
/// rows than that): `lattice::summation::row_block`, which the C ABI does not show.
fn block_rows(w: u32) -> u32 {
    32.max(4 * w + 2)
}

/// A def as a game would set it, with six to ten blocks of rows, now and then with one field
/// at an end of its documented range (steps that diverge must be the same on every thread
/// count too).
fn random_def(rng: &mut Rng) -> SoftshellLatticeDef {
    let mut d = softshell_lattice_def_default();
    d.region_half_width = if rng.chance(0.8) { 1 + rng.below(7) as u32 } else { 8 + rng.below(9) as u32 };
    let block = block_rows(d.region_half_width);
    d.rows = block * (6 + rng.below(5) as u32) + rng.below(block as u64) as u32;
    d.columns = if rng.chance(0.1) { 1 + rng.below(3) as u32 } else { 4 + rng.below(45) as u32 };
    d.spacing = rng.decades(-2.5, 0.0);
    d.stiffness = rng.uniform(0.05, 1.0);
    d.damping = if rng.chance(0.3) { 0.0 } else { rng.uniform(0.0, 1.0) };
    d.time_step = [1.0 / 240.0, 1.0 / 60.0, 1.0 / 15.0][rng.below(3) as usize];
    d.particle_mass = rng.decades(-3.0, 1.0);
    d.velocity_damping = rng.decades(-2.0, 1.0);
    match rng.below(5) {
        0 => d.gravity = [0.0; 3],
        1 => d.gravity = [rng.uniform(-20.0, 20.0), rng.uniform(-20.0, 20.0), rng.uniform(-20.0, 20.0)],
        _ => {}
    }
    let end = rng.chance(0.5);
    match rng.below(12) {
        0 => d.spacing = if end { 1e-30 } else { 1e6 },
        1 => d.stiffness = if end { 1e-30 } else { 1.0 },
        2 => d.damping = if end { 0.0 } else { 1.0 },
        3 => d.time_step = if end { 1e-6 } else { 1.0 },
        4 => d.particle_mass = if end { 1e-30 } else { 1e12 },
        5 => d.gravity = [0.0, if end { -1e30 } else { 1e30 }, 0.0],
        6 => d.velocity_damping = if end { 0.0 } else { 1e6 },
        _ => {}
    }
    d
}

/// A mask (or none): scattered holes, a band of whole rows of holes (a block with no particle
/// at all), or a corner cut away; at least one particle.
fn random_mask(rng: &mut Rng, columns: u32, rows: u32) -> Option<Vec<u8>> {
    let sites = (columns * rows) as usize;
    let mut m = match rng.below(5) {
        0 | 1 => return None,
        2 => (0..sites).map(|_| u8::from(!rng.chance(0.3))).collect::<Vec<u8>>(),
        3 => {
            let (first, band) = (rng.below(rows as u64) as u32, 1 + rng.below(80) as u32);
            (0..sites).map(|s| u8::from(!(first..first + band).contains(&(s as u32 / columns)))).collect()
        }
        _ => {
            let (c0, r0) = (rng.below(columns as u64) as u32, rng.below(rows as u64) as u32);
            (0..sites).map(|s| u8::from(s as u32 % columns < c0 || s as u32 / columns < r0)).collect()
        }
    };
    m[rng.below(sites as u64) as usize] = 1;
    Some(m)
}

type Copy = CopyFloats<SoftshellLattice>;

/// Positions, velocities and goals, floats as bits.
fn state_bits(lattice: *mut SoftshellLattice) -> Vec<u64> {
    let mut bits = Vec::new();
    for copy in
        [softshell_lattice_copy_positions as Copy, softshell_lattice_copy_velocities, softshell_lattice_copy_goals]
    {
        let floats = copied(lattice, copy);
        bits.push(floats.len() as u64);
        bits.extend(floats.iter().map(|x| x.to_bits() as u64));
    }
    bits
}

fn stats_bits(s: &SoftshellLatticeStats) -> Vec<u64> {
    let mut bits = vec![s.step];
    bits.extend([s.time, s.goal_distance, s.max_goal_distance, s.kinetic_energy].map(f64::to_bits));
    bits
}

/// Tallies of what the sessions did (so that a change that refuses every call cannot pass
/// unseen).
#[derive(Default, Debug)]
struct Tally {
    lattices: usize,
    refused: usize,
    steps_ok: usize,
    steps_unstable: usize,
    pins: usize,
    unpins: usize,
    forces: usize,
    positions_set: usize,
    refused_calls: usize,
}

/// Runs session `seed` with `threads` and returns each call's outcome, `new` first. The calls
/// depend only on the seed and on what the lattice reports (which the comparison requires to be
/// the same), so every thread count makes the same calls as long as the outcomes agree.
fn run_session(seed: u64, actions: usize, threads: u32, tally: &mut Tally) -> Vec<Outcome> {
    let mut rng = Rng(seed);
    let mut def = random_def(&mut rng);
    let (columns, rows) = (def.columns, def.rows);
    let mask = random_mask(&mut rng, columns, rows);
    let holes = mask.as_ref().map_or(0, |m| m.iter().filter(|&&b| b == 0).count());
    let call = format!("new with {holes} holes, {def:?}");
    def.threads = threads;
    let mut lattice = null_mut();
    // SAFETY: readable def and mask (rows * columns bytes), writable out pointer.
    let status =
        unsafe { softshell_lattice_new(&def, mask.as_ref().map_or(std::ptr::null(), |m| m.as_ptr()), &mut lattice) };
    if status != SoftshellStatus::Ok {
        // (Every def drawn here is in range; a refusal would have to be the same on every
        // thread count too.)
        tally.refused += 1;
        return vec![Outcome { call, status, message: last_error(), stats: None, state: Vec::new() }];
    }
    tally.lattices += 1;
    let mut outcomes = Vec::with_capacity(actions + 1);
    outcomes.push(Outcome { call, status, message: String::new(), stats: None, state: state_bits(lattice) });
    // SAFETY: live lattice.
    let particles = unsafe { softshell_lattice_particle_count(lattice) };
    for _ in 0..actions {
        let (c, r) = (rng.below(columns as u64) as u32, rng.below(rows as u64) as u32);
        let roll = rng.below(100);
        let (call, status, stats) = if roll < 55 {
            let mut stats = SoftshellLatticeStats::default();
            // SAFETY: live lattice, writable stats.
            let status = unsafe { softshell_lattice_step(lattice, &mut stats) };
            match status {
                SoftshellStatus::Ok => tally.steps_ok += 1,
                SoftshellStatus::Unstable => tally.steps_unstable += 1,
                other => panic!("seed {seed}: a step returned {other:?}: {}", last_error()),
            }
            ("step".to_string(), status, Some(stats_bits(&stats)))
        } else if roll < 65 {
            // SAFETY: live lattice.
            let status = unsafe { softshell_lattice_pin(lattice, c, r) };
            tally.pins += (status == SoftshellStatus::Ok) as usize;
            (format!("pin ({c}, {r})"), status, None)
        } else if roll < 70 {
            // SAFETY: live lattice.
            let status = unsafe { softshell_lattice_unpin(lattice, c, r) };
            tally.unpins += (status == SoftshellStatus::Ok) as usize;
            (format!("unpin ({c}, {r})"), status, None)
        } else if roll < 88 {
            // Now and then the largest a float holds (the step then diverges).
            let size = if rng.chance(1.0 / 16.0) { 3.4e38 } else { rng.decades(-3.0, 3.0) };
            let force = [size * rng.uniform(-1.0, 1.0), size * rng.uniform(-1.0, 1.0), size * rng.uniform(-1.0, 1.0)];
            // SAFETY: live lattice, float[3].
            let status = unsafe { softshell_lattice_apply_force(lattice, c, r, force.as_ptr()) };
            tally.forces += (status == SoftshellStatus::Ok) as usize;
            (format!("force {force:?} on ({c}, {r})"), status, None)
        } else if roll < 95 {
            // The sheet as it is, shifted, bent and shaken (a grab handle dragged), or anywhere.
            let positions: Vec<f32> = if rng.chance(0.7) {
                let shift = [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)];
                let (bend, shake) = (rng.uniform(-0.5, 0.5), rng.decades(-4.0, -1.0));
                let now = copied(lattice, softshell_lattice_copy_positions);
                now.chunks_exact(3)
                    .flat_map(|p| [p[0] + shift[0], p[1] + shift[1] + bend * p[0] * p[2], p[2] + shift[2]])
                    .map(|x| x + shake * rng.uniform(-1.0, 1.0))
                    .collect()
            } else {
                let scale = rng.end(1e15, 1e15).unwrap_or_else(|| rng.decades(-2.0, 3.0));
                (0..3 * particles).map(|_| scale * rng.uniform(-1.0, 1.0)).collect()
            };
            // SAFETY: live lattice; `positions` holds 3 floats a particle.
            let status = unsafe { softshell_lattice_set_positions(lattice, positions.as_ptr(), positions.len()) };
            tally.positions_set += (status == SoftshellStatus::Ok) as usize;
            ("set positions".to_string(), status, None)
        } else if roll < 97 {
            // SAFETY: live lattice.
            let status = unsafe { softshell_lattice_clear_forces(lattice) };
            ("clear forces".to_string(), status, None)
        } else {
            // A site outside the lattice, a NaN force, a wrong count of positions: each refused
            // with nothing changed.
            let statuses = lattice_refused_calls(lattice, columns, particles);
            tally.refused_calls += 1;
            (format!("refused calls {statuses:?}"), statuses[2], None)
        };
        let message = if status == SoftshellStatus::Ok { String::new() } else { last_error() };
        let unstable = status == SoftshellStatus::Unstable;
        outcomes.push(Outcome { call, status, message, stats, state: state_bits(lattice) });
        if unstable {
            // The forces still pending would drive it again: drop them, as a host told so would
            // (they are not part of the state compared).
            // SAFETY: live lattice.
            assert_eq!(unsafe { softshell_lattice_clear_forces(lattice) }, SoftshellStatus::Ok);
        }
    }
    // SAFETY: made above, freed once.
    unsafe { softshell_lattice_free(lattice) };
    outcomes
}

#[test]
fn random_lattice_sessions_give_the_same_bits_on_every_thread_count() {
    let seeds = seeds("SOFTSHELL_LATTICE_THREAD_SESSIONS", 0..32u64);
    let actions = count("SOFTSHELL_LATTICE_THREAD_ACTIONS", 40);
    let mut tally = Tally::default();
    let failures =
        replay_on_threads(seeds.clone(), &mut tally, |seed, threads, tally| run_session(seed, actions, threads, tally));
    eprintln!("lattice thread sessions {seeds:?}, {actions} calls each: {tally:?}");
    assert!(failures.is_empty(), "results depend on the thread count:\n{}", failures.join("\n"));
    // The sessions did what they are for.
    let sessions = (seeds.end - seeds.start) as usize;
    assert!(tally.lattices * 4 >= sessions * 3, "{tally:?}");
    assert!(tally.steps_ok >= tally.lattices * actions / 4, "{tally:?}");
    assert!(tally.pins > 0 && tally.forces > 0 && tally.positions_set > 0, "{tally:?}");
}
