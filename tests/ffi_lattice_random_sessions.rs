//! Random sessions of the lattice through the C ABI: lattices made with settings drawn across
//! their documented ranges (and at their ends) and random masks, then driven by steps, pins,
//! unpins, forces (up to the largest finite ones), positions set (up to ±1e15 m), cleared
//! forces and refused calls. After every call, whatever it returned:
//! - the status is one the call documents; a refused call changes nothing, and an UNSTABLE
//!   step leaves the lattice exactly as before (positions, velocities and goals to the bit);
//! - no NaN or infinity reaches the caller (positions, velocities, goals, every stats field);
//! - a pinned particle stays where it was pinned (or set).
//!
//! Fixed seeds, so that a failure repeats; `SOFTSHELL_LATTICE_SESSIONS=<first>..<end>` runs
//! others and `SOFTSHELL_LATTICE_ACTIONS=<n>` makes each session n calls long instead of 40.
#![cfg(feature = "lattice")]

mod common;
mod random;

use std::ptr::null_mut;

use common::*;
use random::{Rng, count, lattice_refused_calls, seeds};
use softshell::ffi::SoftshellStatus;
use softshell::ffi::lattice::*;

fn random_def(rng: &mut Rng) -> SoftshellLatticeDef {
    let mut d = softshell_lattice_def_default();
    d.columns = 1 + rng.below(16) as u32;
    d.rows = 1 + rng.below(16) as u32;
    d.spacing = rng.decades(-3.0, 1.0);
    d.region_half_width = 1 + rng.below(5) as u32;
    d.stiffness = rng.uniform(0.01, 1.0);
    d.damping = if rng.chance(0.3) { 0.0 } else { rng.uniform(0.0, 1.0) };
    d.time_step = [1.0 / 240.0, 1.0 / 60.0, 1.0 / 15.0][rng.below(3) as usize];
    d.particle_mass = rng.decades(-4.0, 2.0);
    d.threads = rng.below(3) as u32;
    d.velocity_damping = rng.decades(-2.0, 1.0);
    if rng.chance(0.2) {
        d.gravity = [rng.uniform(-20.0, 20.0), rng.uniform(-20.0, 20.0), rng.uniform(-20.0, 20.0)];
    }
    // The ends of the documented ranges.
    if let Some(s) = rng.end(1e-30, 1e6) {
        d.spacing = s;
    }
    if let Some(a) = rng.end(1e-30, 1.0) {
        d.stiffness = a;
    }
    if let Some(c) = rng.end(0.0, 1.0) {
        d.damping = c;
    }
    if let Some(h) = rng.end(1e-6, 1.0) {
        d.time_step = h;
    }
    if let Some(m) = rng.end(1e-30, 1e12) {
        d.particle_mass = m;
    }
    if let Some(g) = rng.end(-1e30, 1e30) {
        d.gravity = [0.0, g, 0.0];
    }
    if let Some(v) = rng.end(0.0, 1e6) {
        d.velocity_damping = v;
    }
    d
}

type Copy = CopyFloats<SoftshellLattice>;

/// Positions, velocities and goals, as bits.
fn state(lattice: *mut SoftshellLattice) -> Vec<u32> {
    [softshell_lattice_copy_positions as Copy, softshell_lattice_copy_velocities, softshell_lattice_copy_goals]
        .into_iter()
        .flat_map(|copy| copied(lattice, copy))
        .map(f32::to_bits)
        .collect()
}

fn finite_state(bits: &[u32]) -> bool {
    bits.iter().all(|&b| f32::from_bits(b).is_finite())
}

#[derive(Default, Debug)]
struct Tally {
    sessions: usize,
    refused: usize,
    steps_ok: usize,
    steps_unstable: usize,
    pins: usize,
    forces: usize,
    positions_set: usize,
    refused_calls: usize,
}

fn run_session(seed: u64, actions: usize, tally: &mut Tally) {
    let mut rng = Rng(seed);
    let def = random_def(&mut rng);
    let (columns, rows) = (def.columns, def.rows);
    let mask: Option<Vec<u8>> = rng.chance(0.4).then(|| {
        let mut m: Vec<u8> = (0..columns * rows).map(|_| u8::from(!rng.chance(0.3))).collect();
        m[0] = 1;
        m
    });
    let mut lattice = null_mut();
    // SAFETY: readable def and mask (rows * columns bytes), writable out pointer.
    let status =
        unsafe { softshell_lattice_new(&def, mask.as_ref().map_or(std::ptr::null(), |m| m.as_ptr()), &mut lattice) };
    let message = last_error();
    let what =
        |action: usize, call: &str| format!("seed {seed}, action {action} ({call}), {def:?}, mask {}", mask.is_some());
    if status != SoftshellStatus::Ok {
        assert_eq!(status, SoftshellStatus::InvalidArgument, "{}: {message}", what(0, "new"));
        assert!(!message.is_empty());
        tally.refused += 1;
        return;
    }
    tally.sessions += 1;
    let is_site = |c: u32, r: u32| mask.as_ref().is_none_or(|m| m[(r * columns + c) as usize] == 1);
    let mut current = state(lattice);
    let particles = current.len() / 9;
    // Pinned particles (their index) and where they must stay.
    let mut pinned: Vec<(u32, u32, u32)> = Vec::new();
    for action in 1..=actions {
        let (c, r) = (rng.below(columns as u64) as u32, rng.below(rows as u64) as u32);
        let roll = rng.below(100);
        let call;
        let status;
        if roll < 55 {
            call = "step";
            let mut stats = SoftshellLatticeStats::default();
            // SAFETY: live lattice, writable stats.
            status = unsafe { softshell_lattice_step(lattice, &mut stats) };
            let message = last_error();
            let after = state(lattice);
            match status {
                SoftshellStatus::Ok => {
                    tally.steps_ok += 1;
                    let values = [stats.time, stats.goal_distance, stats.max_goal_distance, stats.kinetic_energy];
                    assert!(values.iter().all(|v| v.is_finite()), "{}: {stats:?}", what(action, call));
                    assert!(finite_state(&after), "{}: a value is not finite", what(action, call));
                    for &(_, _, i) in &pinned {
                        let i = i as usize;
                        assert_eq!(
                            after[3 * i..3 * i + 3],
                            current[3 * i..3 * i + 3],
                            "{}: a pin moved",
                            what(action, call)
                        );
                    }
                }
                SoftshellStatus::Unstable => {
                    tally.steps_unstable += 1;
                    assert!(!message.is_empty());
                    assert_eq!(
                        after,
                        current,
                        "{}: an UNSTABLE step changed the lattice: {message}",
                        what(action, call)
                    );
                    // The pending forces would drive it again.
                    // SAFETY: live lattice.
                    assert_eq!(unsafe { softshell_lattice_clear_forces(lattice) }, SoftshellStatus::Ok);
                }
                other => panic!("{}: status {other:?}: {message}", what(action, call)),
            }
            current = after;
            continue;
        } else if roll < 65 {
            call = "pin";
            // SAFETY: live lattice.
            status = unsafe { softshell_lattice_pin(lattice, c, r) };
            if status == SoftshellStatus::Ok {
                let mut index = 0u32;
                // SAFETY: live lattice, writable index.
                assert_eq!(unsafe { softshell_lattice_particle_index(lattice, c, r, &mut index) }, SoftshellStatus::Ok);
                pinned.retain(|p| (p.0, p.1) != (c, r));
                pinned.push((c, r, index));
                tally.pins += 1;
            }
        } else if roll < 70 {
            call = "unpin";
            // SAFETY: live lattice.
            status = unsafe { softshell_lattice_unpin(lattice, c, r) };
            if status == SoftshellStatus::Ok {
                pinned.retain(|p| (p.0, p.1) != (c, r));
            }
        } else if roll < 88 {
            call = "force";
            let size = rng.end(3.4e38, 3.4e38).unwrap_or_else(|| rng.decades(-3.0, 6.0));
            let force = [size * rng.uniform(-1.0, 1.0), size * rng.uniform(-1.0, 1.0), size * rng.uniform(-1.0, 1.0)];
            // SAFETY: live lattice, float[3].
            status = unsafe { softshell_lattice_apply_force(lattice, c, r, force.as_ptr()) };
            if status == SoftshellStatus::Ok {
                tally.forces += 1;
            }
        } else if roll < 95 {
            call = "set positions";
            let scale = rng.end(1e15, 1e15).unwrap_or_else(|| rng.decades(-2.0, 3.0));
            let positions: Vec<f32> = (0..3 * particles).map(|_| scale * rng.uniform(-1.0, 1.0)).collect();
            // SAFETY: live lattice; `positions` holds 3 floats a particle.
            status = unsafe { softshell_lattice_set_positions(lattice, positions.as_ptr(), positions.len()) };
            if status == SoftshellStatus::Ok {
                tally.positions_set += 1;
            }
        } else {
            call = "refused calls";
            // A site outside the lattice, a NaN force, a wrong count of positions.
            let statuses = lattice_refused_calls(lattice, columns, particles);
            assert!(
                statuses.iter().all(|&s| s == SoftshellStatus::InvalidArgument),
                "{}: {statuses:?}",
                what(action, call)
            );
            tally.refused_calls += 1;
            status = SoftshellStatus::InvalidArgument;
        }
        let message = last_error();
        let after = state(lattice);
        match status {
            SoftshellStatus::Ok => {
                assert!(finite_state(&after), "{}: a value is not finite", what(action, call));
                if call == "set positions" {
                    // Pins move with the positions set and stay there.
                    current = after;
                    continue;
                }
                if call == "pin" || call == "unpin" {
                    // Either stops the particle (a pin holds it; an unpinned one starts at rest):
                    // velocities may change, positions not.
                    let n = 3 * particles;
                    assert_eq!(after[..n], current[..n], "{}: a pin moved the lattice", what(action, call));
                    current = after;
                    continue;
                }
            }
            SoftshellStatus::InvalidArgument => {
                // Documented refusals only: a hole (pins, forces), a force or position out of
                // range, and the calls refused on purpose.
                let hole = !is_site(c, r);
                assert!(
                    hole || call == "force" || call == "set positions" || call == "refused calls",
                    "{}: {message}",
                    what(action, call)
                );
            }
            other => panic!("{}: status {other:?}: {message}", what(action, call)),
        }
        assert_eq!(after, current, "{}: a call other than a step moved the lattice", what(action, call));
    }
    // SAFETY: made above, freed once.
    unsafe { softshell_lattice_free(lattice) };
}

#[test]
fn random_lattice_sessions_keep_every_promise_of_the_abi() {
    let seeds = seeds("SOFTSHELL_LATTICE_SESSIONS", 0..100u64);
    let actions = count("SOFTSHELL_LATTICE_ACTIONS", 40);
    let mut tally = Tally::default();
    for seed in seeds.clone() {
        run_session(seed, actions, &mut tally);
    }
    println!("{tally:?}");
    let sessions = (seeds.end - seeds.start) as usize;
    assert!(tally.sessions * 4 >= sessions * 3, "{tally:?}");
    assert!(tally.steps_ok > 0 && tally.steps_unstable > 0 && tally.pins > 0, "{tally:?}");
}
