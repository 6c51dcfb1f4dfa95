//! "Leave out what a scene does not need" (SPEC 5), through the C ABI only: for each simulator,
//! a scene without a feature holds no memory for it (`softshell_*_memory_bytes` compared with and
//! without the feature) and does no work for it (a stats counter or field that stays 0).
//!
//! Gaps (see report/error_vs_time.md): the lattice
//! stats have no per-stage counter, so for the lattice only memory is shown.
#![cfg(all(feature = "shell", feature = "body", feature = "lattice"))]

mod report_util;

use report_util::*;
use softshell::ffi::body::*;
use softshell::ffi::lattice::*;
use softshell::ffi::shell::*;
use softshell::ffi::{SoftshellBodyDef, SoftshellLatticeDef, SoftshellShellDef};

fn shell_def() -> SoftshellShellDef {
    SoftshellShellDef { stop_volume_ratio: 0.0, ..softshell_shell_def_default() }
}

#[test]
fn shell_without_bending_anisotropy_multipliers_or_pool_holds_none() {
    let (p, t) = unit_obj("sphere.obj", 1.0);
    let full = Shell::new(&p, &t, &shell_def()).unwrap();
    let plain = full.memory();

    // Bending: no stencil data, no bending work (its energy is never accumulated).
    let none = Shell::new(&p, &t, &SoftshellShellDef { bending: SOFTSHELL_BENDING_NONE, ..shell_def() }).unwrap();
    let edges = t.len() / 2; // closed mesh: 3F/2 edges
    assert!(none.memory() + edges * 16 <= plain, "bending: {} vs {plain}", none.memory());
    // kB = 0 stores none either.
    let zero = Shell::new(&p, &t, &SoftshellShellDef { bending_coefficient: 0.0, ..shell_def() }).unwrap();
    assert_eq!(zero.memory(), none.memory(), "kB = 0 keeps bending constraints");
    assert_eq!(zero.step().unwrap().bending_energy, 0.0);
    let mut bent = 0.0;
    for _ in 0..10 {
        assert_eq!(none.step().unwrap().bending_energy, 0.0);
        bent = full.step().unwrap().bending_energy;
    }
    assert!(bent > 0.0, "with bending, the contracted sphere has bending energy");

    // Anisotropy: nothing until a region is added; no fibre work without one.
    assert_eq!(full.memory(), plain, "stepping allocates nothing new");
    assert_eq!(full.step().unwrap().anisotropic_energy, 0.0);
    full.add_region(&cap_faces(&p, &t, 0.2), &softshell_anisotropy_def_default()).unwrap();
    assert!(full.memory() > plain, "a region allocates its data when added");
    full.step().unwrap();
    assert!(full.step().unwrap().anisotropic_energy > 0.0);

    // PBD keeps no XPBD multipliers.
    let pbd = Shell::new(&p, &t, &SoftshellShellDef { solver: SOFTSHELL_SOLVER_PBD, ..shell_def() }).unwrap();
    assert!(pbd.memory() < plain, "PBD: {} vs {plain}", pbd.memory());
    // PBD_DISTANCE holds its edges (12 bytes each, 18 a face, and their colour offsets) and not
    // the membranes' per-triangle inverse masses (12 bytes a face), which it never projects.
    let distance =
        Shell::new(&p, &t, &SoftshellShellDef { solver: SOFTSHELL_SOLVER_PBD_DISTANCE, ..shell_def() }).unwrap();
    let faces = t.len() / 3;
    assert!(
        distance.memory() <= pbd.memory() + (18 - 12) * faces + 1024,
        "PBD_DISTANCE: {} vs PBD {} ({faces} faces)",
        distance.memory(),
        pbd.memory()
    );
    for _ in 0..3 {
        distance.step().unwrap();
    }

    // threads = 1: no worker pool.
    let two = Shell::new(&p, &t, &SoftshellShellDef { threads: 2, ..shell_def() }).unwrap();
    assert!(two.memory() > plain, "a 2-thread shell holds its pool: {} vs {plain}", two.memory());

    // Collisions off: no BVH (at least one 48-byte box per vertex, edge and face) and no
    // collision work.
    let off = Shell::new(&p, &t, &SoftshellShellDef { collisions: false, ..shell_def() }).unwrap();
    let (vertices, faces) = (p.len() / 3, t.len() / 3);
    let boxes = 48 * (vertices + faces * 3 / 2 + faces);
    assert!(off.memory() + boxes <= plain, "collisions off {} vs on {plain}", off.memory());
    let s = off.step().unwrap();
    assert_eq!((s.collision_candidates, s.ccd_tests, s.contacts), (0, 0, 0));
    // With collisions the stage runs: candidate pairs are found (neighbouring primitives).
    let on = Shell::new(&p, &t, &shell_def()).unwrap();
    let s = on.step().unwrap();
    assert!(s.collision_candidates > 0 && s.ccd_tests <= s.collision_candidates, "{s:?}");
    println!(
        "shell memory: default {plain}, no bending {}, PBD {}, 2 threads {}, with region {}, collisions off {}",
        none.memory(),
        pbd.memory(),
        two.memory(),
        full.memory(),
        off.memory()
    );
}

fn body_def() -> SoftshellBodyDef {
    SoftshellBodyDef { gravity: [0.0; 3], ..softshell_body_def_default() }
}

#[test]
fn body_without_gas_fracture_cg_or_pool_holds_none() {
    let (p, t) = unit_obj("sphere.obj", 1.0);
    let n = p.len() / 3;
    let plain = Body::new(&p, &t, &body_def()).unwrap();
    let gas = Body::new(&p, &t, &SoftshellBodyDef { gas_amount: 1.0, ..body_def() }).unwrap();
    let fracture = Body::new(&p, &t, &SoftshellBodyDef { break_strain: 0.5, ..body_def() }).unwrap();
    let (m_plain, m_gas, m_fracture) = (plain.memory(), gas.memory(), fracture.memory());
    assert!(m_gas >= m_plain + 4 * n, "gas bookkeeping: {m_gas} vs {m_plain}");
    assert!(m_fracture >= m_plain + 4 * n, "fracture bookkeeping: {m_fracture} vs {m_plain}");

    // No gas work without gas: pressure 0; and a step allocates nothing for gas or fracture.
    plain.step().unwrap();
    let after_one = plain.memory();
    for _ in 0..5 {
        let s = plain.step().unwrap();
        assert_eq!(s.pressure, 0.0);
        assert!(!s.volume_clamped);
        assert_eq!((s.springs_broken, s.cores_released, s.topology_generation), (0, 0, 0));
    }
    assert_eq!(plain.memory(), after_one, "steady stepping allocates nothing");
    assert!(gas.step().unwrap().pressure > 0.0);

    // No conjugate-gradient work for the explicit integrators and XPBD.
    for integrator in
        [SOFTSHELL_INTEGRATOR_EXPLICIT_EULER, SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER, SOFTSHELL_INTEGRATOR_XPBD]
    {
        let def = SoftshellBodyDef { integrator, spring_stiffness: 10.0, ..body_def() };
        let b = Body::new(&p, &t, &def).unwrap();
        assert_eq!(b.step().unwrap().solver_iterations, 0, "integrator {integrator}");
    }
    let implicit = Body::new(&p, &t, &SoftshellBodyDef { gas_amount: 1.0, ..body_def() }).unwrap();
    assert!(implicit.step().unwrap().solver_iterations > 0);

    // threads = 1: no worker pool.
    let two = Body::new(&p, &t, &SoftshellBodyDef { threads: 2, ..body_def() }).unwrap();
    assert!(two.memory() > m_plain, "a 2-thread body holds its pool: {} vs {m_plain}", two.memory());
    println!("body memory: plain {m_plain}, gas {m_gas}, fracture {m_fracture}, 2 threads {}", two.memory());
}

/// A plain body (no gas, no fracture, no wind, no obstacle, one thread) holds what its state
/// needs and not much more, with the explicit, symplectic or XPBD integrator: per vertex its
/// position, velocity, rest position, mass and inverse (44 bytes), the saved state a
/// rolled-back step returns to (24),
/// the caller's numbering both ways (8) and the integrator's per-vertex vectors; per face its
/// corners and fragment (16); per spring its ends and rest length (12). A budget, not a
/// snapshot of today's figure: a per-vertex spring adjacency kept by an integrator that does
/// not gather by vertex (16 bytes a spring, a third of such a body), fracture bookkeeping or a
/// kept topology all break it.
#[test]
fn a_plain_body_holds_its_state_and_its_integrators_vectors_only() {
    let (p, t) = unit_obj("sphere.obj", 1.0);
    let (n, faces) = (p.len() / 3, t.len() / 3);
    let springs = faces * 3 / 2; // closed mesh
    let state = 44 * n + 24 * n + 8 * n + 16 * faces + 12 * springs;
    // The integrators' own vectors: explicit and symplectic Euler a force and a gas gradient
    // per vertex (12 bytes each); XPBD those and the substep's displacement, and a multiplier
    // and a push per spring (4 + 12: the push is re-aimed at the spring's direction, SPEC 2.2).
    for (integrator, per_vertex, per_spring) in [
        (SOFTSHELL_INTEGRATOR_EXPLICIT_EULER, 24, 0),
        (SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER, 24, 0),
        (SOFTSHELL_INTEGRATOR_XPBD, 36, 16),
    ] {
        let def = SoftshellBodyDef { integrator, spring_stiffness: 10.0, ..body_def() };
        let body = Body::new(&p, &t, &def).unwrap();
        body.step().unwrap();
        let budget = state + per_vertex * n + per_spring * springs + 4096;
        println!("integrator {integrator}: {} bytes, budget {budget}", body.memory());
        assert!(
            body.memory() <= budget,
            "integrator {integrator}: {} bytes against a budget of {budget}",
            body.memory()
        );
    }
}

/// Gas costs a body what it needs and not much more, with every integrator: per face its
/// three corners (the next and previous vertex and the fragment, 12 bytes each: every
/// integrator gathers the gas's gradient at each vertex from them) and its fragment (4); per
/// vertex its fragment, the corner offsets, whether its fan is closed and the ring of its
/// neighbours that the gathering walks (about six, with their offsets and slices: 56 bytes in
/// all), and the integrator's own per-vertex gas vectors once it has stepped (the gradient, 12
/// bytes; XPBD also each vertex's gas push, 12 more). A budget, not today's figure: a second
/// copy of the corners, a per-face gradient or fracture buffers made for gas break it.
#[test]
fn gas_holds_its_fragments_corners_and_rings_only() {
    let (p, t) = unit_obj("sphere.obj", 1.0);
    let (n, faces) = (p.len() / 3, t.len() / 3);
    for (integrator, per_vertex_vectors) in [
        (SOFTSHELL_INTEGRATOR_EXPLICIT_EULER, 12),
        (SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER, 12),
        (SOFTSHELL_INTEGRATOR_IMPLICIT_EULER, 12),
        (SOFTSHELL_INTEGRATOR_XPBD, 24),
    ] {
        // Short substeps, so that the explicit integrators' steps go through.
        let def = SoftshellBodyDef { integrator, spring_stiffness: 10.0, substeps: 100, ..body_def() };
        let plain = Body::new(&p, &t, &def).unwrap();
        let gas = Body::new(&p, &t, &SoftshellBodyDef { gas_amount: 0.01, ..def }).unwrap();
        plain.step().unwrap();
        gas.step().unwrap();
        let (without, with) = (plain.memory(), gas.memory());
        let budget = 40 * faces + (56 + per_vertex_vectors) * n + 1024;
        println!("integrator {integrator}: gas adds {} bytes, budget {budget}", with - without);
        assert!(with > without, "integrator {integrator}: gas holds nothing?");
        assert!(
            with - without <= budget,
            "integrator {integrator}: gas adds {} bytes against a budget of {budget}",
            with - without
        );
    }
}

#[test]
fn lattice_without_damping_pins_forces_or_pool_holds_none() {
    let def = SoftshellLatticeDef { columns: 48, rows: 48, ..softshell_lattice_def_default() };
    let n = 48 * 48;
    let plain = Lattice::new(&SoftshellLatticeDef { damping: 0.0, ..def }).unwrap();
    let damped = Lattice::new(&SoftshellLatticeDef { damping: 0.2, ..def }).unwrap();
    let (a, b) = (plain.memory(), damped.memory());
    assert!(b >= a + n * 8 * 5, "region damping needs its own sums: {a} vs {b}");
    for _ in 0..3 {
        plain.step().unwrap();
    }
    assert_eq!(plain.memory(), a, "stepping allocates nothing");
    plain.pin(0, 0).unwrap();
    let pinned = plain.memory();
    assert!(pinned > a, "pins are stored once used");
    plain.force(5, 5, [0.0, 1.0, 0.0]).unwrap();
    let forced = plain.memory();
    assert!(forced > pinned, "forces are stored once used");
    // Kept once made: a step clears the forces, not their storage, so a force applied every
    // step costs no allocation after the first.
    for _ in 0..3 {
        plain.step().unwrap();
        plain.force(5, 5, [0.0, 1.0, 0.0]).unwrap();
        assert_eq!(plain.memory(), forced, "the force storage is kept");
    }
    let two = Lattice::new(&SoftshellLatticeDef { damping: 0.0, threads: 2, ..def }).unwrap();
    println!(
        "lattice memory: plain {a}, damped {b}, pinned {pinned}, forced {}, 2 threads {}",
        plain.memory(),
        two.memory()
    );
    assert!(two.memory() >= a, "2 threads: {} vs {a}", two.memory());
}
