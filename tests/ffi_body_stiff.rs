//! Stiff springs (K_s = 1e7 N/m on a 10 g body): explicit Euler fails cleanly (UNSTABLE, state
//! rolled back, a stable time step suggested) while implicit Euler and XPBD stay stable
//! (SPEC 2.2 and the extreme cases of SPEC 4).
#![cfg(feature = "body")]

mod body_util;

use body_util::*;
use softshell::ffi::SoftshellStatus;
use softshell::ffi::body::*;

fn stiff_def(integrator: u32) -> SoftshellBodyDef {
    let mut def = softshell_body_def_default();
    def.integrator = integrator;
    def.spring_stiffness = 1e7;
    def.spring_damping = 0.0;
    def.total_mass = 0.01;
    def.gas_amount = 10.0;
    def.time_step = 1.0 / 60.0;
    def
}

#[test]
fn explicit_euler_fails_cleanly_with_a_stable_step_estimate() {
    let (positions, triangles) = icosphere(2, 0.5);
    for integrator in [SOFTSHELL_INTEGRATOR_EXPLICIT_EULER, SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER] {
        let body = body(&positions, &triangles, &stiff_def(integrator));
        let mut failure = None;
        for k in 0..50 {
            let before = snapshot(&body);
            match try_step(&body) {
                Ok(stats) => assert!(stats.volume.is_finite() && stats.kinetic_energy.is_finite()),
                Err((status, message)) => {
                    assert_eq!(status, SoftshellStatus::Unstable);
                    let after = snapshot(&body);
                    assert_eq!(before.positions, after.positions, "the failed step was not rolled back");
                    assert_eq!(before.velocities, after.velocities, "the failed step was not rolled back");
                    failure = Some((k, message));
                    break;
                }
            }
        }
        let (k, message) = failure.expect("stiff springs with h = 1/60 must be reported UNSTABLE");
        println!("integrator {integrator}: UNSTABLE at step {k}: {message}");
        if integrator == SOFTSHELL_INTEGRATOR_EXPLICIT_EULER {
            // Undamped springs (K_d = 0): explicit Euler has no stable step, and says so.
            assert!(message.contains("no stable time step without spring damping"), "{message}");
            continue;
        }
        assert!(message.contains("largest stable time step"), "{message}");
        // The estimate 2/omega_max: omega^2 ~ 2 * 6 K_s / m_vertex, m_vertex ~ 0.01/162.
        let estimate: f64 = message
            .split("about ")
            .nth(1)
            .and_then(|t| t.split(' ').next())
            .and_then(|t| t.parse().ok())
            .expect("the message gives a time step");
        assert!(estimate > 1e-7 && estimate < 1e-4, "stable step estimate {estimate}");
        // Every later call still works and the state is finite.
        let s = snapshot(&body);
        assert!(s.positions.iter().all(|p| p.is_finite()));
    }
}

#[test]
fn explicit_euler_is_stable_below_the_estimate() {
    // Same body, with substeps that bring h under the estimate for symplectic Euler.
    let (positions, triangles) = icosphere(1, 0.5);
    let mut def = stiff_def(SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER);
    def.spring_stiffness = 1e4;
    def.total_mass = 1.0;
    def.time_step = 1e-3;
    def.substeps = 4;
    def.gravity = [0.0; 3];
    let body = body(&positions, &triangles, &def);
    for _ in 0..200 {
        let stats = step(&body);
        assert!(stats.max_strain < 0.5);
    }
}

fn stays_stable(integrator: u32, time_step: f32, substeps: u32) {
    // Two seconds of free fall, whatever the step.
    let steps = (2.0 / time_step).round() as usize;
    let (positions, triangles) = icosphere(2, 0.5);
    let mut def = stiff_def(integrator);
    def.time_step = time_step;
    def.substeps = substeps;
    let body = body(&positions, &triangles, &def);
    let start = snapshot(&body);
    let mut last = None;
    for _ in 0..steps {
        let stats = step(&body);
        assert!(stats.kinetic_energy.is_finite() && stats.volume.is_finite());
        last = Some(stats);
    }
    let stats = last.unwrap();
    let s = snapshot(&body);
    assert!(s.positions.iter().all(|p| p.is_finite()));
    // Stiff springs: the sphere keeps its size and shape (strain tiny, volume kept) ...
    let limit = if integrator == SOFTSHELL_INTEGRATOR_XPBD { 0.05 } else { 0.02 };
    assert!(stats.max_strain < limit, "integrator {integrator}: strain {}", stats.max_strain);
    let v0 = softshell_mesh_volume(&start);
    assert!((stats.volume / v0 - 1.0).abs() < 0.1, "integrator {integrator}: V/V0 = {}", stats.volume / v0);
    // ... and falls freely: the centre of mass follows -g t^2/2 (backward and symplectic Euler
    // both give -g h^2 n(n+1)/2).
    let n = (steps * substeps as usize) as f64;
    let h = time_step as f64 / substeps as f64;
    let expected = -9.81 * h * h * n * (n + 1.0) / 2.0;
    let fallen = s.center_y() - start.center_y();
    assert!((fallen / expected - 1.0).abs() < 0.02, "integrator {integrator}: fell {fallen}, expected {expected}");
    assert!((s.total_mass() - start.total_mass()).abs() < 1e-6);
    println!(
        "integrator {integrator}, h = {time_step}, substeps {substeps}: strain {:.2e}, V/V0 {:.4}, fell {fallen:.3} m of {expected:.3}",
        stats.max_strain,
        stats.volume / v0
    );
}

fn softshell_mesh_volume(s: &Snapshot) -> f64 {
    Mesh::new(&s.positions, &s.triangles).report().volume
}

#[test]
fn implicit_euler_stays_stable_with_stiff_springs() {
    stays_stable(SOFTSHELL_INTEGRATOR_IMPLICIT_EULER, 1.0 / 60.0, 1);
    stays_stable(SOFTSHELL_INTEGRATOR_IMPLICIT_EULER, 1.0 / 15.0, 1);
}

#[test]
fn xpbd_stays_stable_with_stiff_springs() {
    // XPBD meets stiff springs by substepping (Macklin et al. 2019), not by iterating.
    stays_stable(SOFTSHELL_INTEGRATOR_XPBD, 1.0 / 60.0, 20);
    stays_stable(SOFTSHELL_INTEGRATOR_XPBD, 1.0 / 15.0, 80);
}

/// The explicit integrators' growth rule (an energy excess over the allowance, many times the
/// step before's) must not take rounding for divergence: a gas ball at rest far from the origin
/// with a small step measures its energies to a few 1e-7 of their size (its gravitational energy
/// 100 m up), and its first steps showed "gains" of 2e-7 J then 2e-6 J, which the first version
/// of the rule called UNSTABLE at step 2 (found in review; 3,000 steps stable without the rule).
#[test]
fn a_ball_at_rest_far_from_the_origin_is_not_called_unstable() {
    for offset in [10.0f32, 30.0, 100.0] {
        for h in [1e-4f32, 2e-4] {
            let (mut positions, triangles) = icosphere(1, 1.0);
            positions.iter_mut().skip(1).step_by(3).for_each(|y| *y += offset);
            let mut def = softshell_body_def_default();
            def.integrator = SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER;
            def.gas_amount = 5.0;
            def.time_step = h;
            let body = body(&positions, &triangles, &def);
            for k in 0..300 {
                if let Err((status, message)) = try_step(&body) {
                    panic!("{offset} m up, h = {h}: step {k}: {status:?} {message}");
                }
            }
        }
    }
}

/// Alternating small impulses along z on the first `n` vertices: a small relative motion.
fn shake(b: &Body, n: usize, size: f32) {
    for i in 0..n as u32 {
        let impulse = [0.0f32, 0.0, if i % 2 == 0 { size } else { -size }];
        // SAFETY: live body, float[3].
        assert_eq!(unsafe { softshell_body_apply_impulse(b.0, i, impulse.as_ptr()) }, SoftshellStatus::Ok);
    }
}

/// A review found that the advice of the explicit integrators' UNSTABLE message (then `2/ω_max`
/// from K_s alone) diverged in its first step with the default damping (K_d = 1 N s/m on
/// 642 light vertices): the estimate now counts the damping (symplectic Euler
/// `h² ω² + 2 h γ < 4`, explicit Euler `h < K_d/K_s`). Following it runs a second of steps,
/// falling under gravity and, without gravity, with the motion of the impulses dying out.
#[test]
fn following_the_unstable_advice_is_stable() {
    let (p, t) = icosphere(3, 0.5);
    let integrators = [SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER, SOFTSHELL_INTEGRATOR_EXPLICIT_EULER];
    for (integrator, gravity) in integrators.into_iter().flat_map(|i| [(i, true), (i, false)]) {
        let mut def = softshell_body_def_default();
        def.integrator = integrator;
        if !gravity {
            def.gravity = [0.0; 3];
        }
        let b = body(&p, &t, &def);
        shake(&b, p.len() / 3, 1e-5);
        let (status, message) = (0..100).find_map(|_| try_step(&b).err()).expect("h = 1/60 is far too long");
        assert_eq!(status, SoftshellStatus::Unstable);
        let (substeps, estimate) = unstable_advice(&message);
        def.substeps = substeps;
        let b = body(&p, &t, &def);
        shake(&b, p.len() / 3, 1e-5);
        let h = def.time_step as f64 / substeps as f64;
        assert!(h < estimate, "the advice {substeps} substeps gives h = {h} s, not below {estimate} s");
        let first = step(&b);
        let mut last = first;
        for k in 1..60 {
            let stats = try_step(&b).unwrap_or_else(|(status, m)| {
                panic!("integrator {integrator}: {substeps} substeps as advised, step {k} is {status:?}: {m}")
            });
            assert!(stats.kinetic_energy.is_finite() && stats.energy_drift.is_finite());
            if !gravity {
                // Damped, with no source after the impulses: no energy made.
                assert!(stats.energy_drift <= 0.1 * first.kinetic_energy, "step {k}: {stats:?}");
            }
            last = stats;
        }
        if !gravity {
            assert!(last.kinetic_energy < first.kinetic_energy, "{first:?} then {last:?}");
        }
    }
}

/// Explicit Euler a little above its stable step (h = 2 K_d/K_s, no gravity or gas): every
/// spring mode grows by a few percent a step, slower than the per-step energy checks see. A
/// review found such a body reported OK for 1,400 steps while its kinetic energy grew to 1e43 J.
/// The step must turn UNSTABLE before the body holds 100 times the energy it was given, and the
/// same body at half the stable step must run 2,000 steps.
#[test]
fn a_slow_explicit_blow_up_is_reported_unstable() {
    let (p, t) = icosphere(2, 0.5);
    let mut def = softshell_body_def_default();
    def.integrator = SOFTSHELL_INTEGRATOR_EXPLICIT_EULER;
    def.gravity = [0.0; 3];
    def.spring_stiffness = 1e4;
    let ratio = def.spring_damping as f64 / def.spring_stiffness as f64;
    for (factor, must_fail) in [(2.0, true), (0.5, false)] {
        def.time_step = (factor * ratio) as f32;
        let b = body(&p, &t, &def);
        shake(&b, p.len() / 3, 1e-4);
        let given = step(&b).kinetic_energy.max(1e-30);
        let mut failed = None;
        for k in 1..2000 {
            match try_step(&b) {
                Ok(stats) => assert!(
                    stats.kinetic_energy + stats.energy_drift.max(0.0) < 100.0 * given,
                    "h = {factor} K_d/K_s, step {k} reported OK with kinetic energy {:.3e} J, energy drift {:.3e} J \
                     (given {given:.3e} J)",
                    stats.kinetic_energy,
                    stats.energy_drift
                ),
                Err((status, message)) => {
                    assert_eq!(status, SoftshellStatus::Unstable);
                    failed = Some((k, message));
                    break;
                }
            }
        }
        match (must_fail, failed) {
            (true, None) => panic!("h = {factor} K_d/K_s: 2,000 steps without UNSTABLE"),
            (false, Some((k, m))) => panic!("h = {factor} K_d/K_s (stable): step {k} UNSTABLE: {m}"),
            (true, Some((k, m))) => println!("h = {factor} K_d/K_s: UNSTABLE at step {k}: {m}"),
            (false, None) => {}
        }
    }
}

/// Explicit Euler gains `m (h g)² / 2` per step from gravity alone (its positions lag its
/// velocities): a body falling from rest, one step per frame at half its stable step, is not
/// called UNSTABLE for it. Its first step has made energy before gravity has released any, its
/// second as much as gravity released: the drift rule fails a step only the second time in a
/// row, and allows twice gravity's gain per substep (fails without either).
#[test]
fn explicit_euler_falls_from_rest_without_being_called_unstable() {
    let (p, t) = icosphere(2, 0.5);
    let mut def = softshell_body_def_default();
    def.integrator = SOFTSHELL_INTEGRATOR_EXPLICIT_EULER;
    let probe = body(&p, &t, &def);
    shake(&probe, p.len() / 3, 1e-5);
    let message = (0..100).find_map(|_| try_step(&probe).err()).expect("h = 1/60 is too long").1;
    let (_, estimate) = unstable_advice(&message);
    def.time_step = (0.5 * estimate) as f32;
    let b = body(&p, &t, &def);
    let mut last = None;
    for k in 0..300 {
        let stats = try_step(&b).unwrap_or_else(|(s, m)| panic!("step {k}: {s:?}: {m}"));
        last = Some(stats);
    }
    // It fell freely: kinetic energy M (g t)² / 2.
    let stats = last.unwrap();
    let expected = 0.5 * def.total_mass as f64 * (9.81 * stats.time).powi(2);
    assert!((stats.kinetic_energy - expected).abs() < 0.05 * expected, "{stats:?}, expected {expected}");
}

/// XPBD with a spring stiffness at the bottom of its range: every step was UNSTABLE ("vertex 0
/// reached a NaN": `1/(K_s h²)` overflowed and met a zero), whatever the substeps the message
/// advised (found in review). The update no longer divides by K_s.
#[test]
fn xpbd_takes_the_softest_springs_allowed() {
    let (positions, triangles) = icosphere(1, 0.5);
    for (ks, kd) in [(1e-30f32, 1e9f32), (1e-38, 1.0), (0.0, 1e9)] {
        for substeps in [1u32, 20] {
            let mut def = softshell_body_def_default();
            def.integrator = SOFTSHELL_INTEGRATOR_XPBD;
            def.spring_stiffness = ks;
            def.spring_damping = kd;
            def.substeps = substeps;
            let b = body(&positions, &triangles, &def);
            for k in 0..10 {
                match try_step(&b) {
                    Ok(stats) => assert!(stats.kinetic_energy.is_finite() && stats.volume.is_finite()),
                    Err((status, message)) => {
                        panic!("K_s = {ks:e}, K_d = {kd:e}, substeps {substeps}, step {k}: {status:?}: {message}")
                    }
                }
            }
            assert!(snapshot(&b).positions.iter().all(|p| p.is_finite()));
        }
    }
}

/// A gas ball squeezed flat between two planes 2 mm apart (SPEC 2.2 clamp): its volume falls
/// under the clamp (1% of the volume it was made with), the step reports `volume_clamped` and
/// the pressure the gas pushes with, stopped at nRT over the clamp (the pressure of the volume
/// itself, about twice that here, 4,150 Pa at the third step, pushes nothing), and every step
/// stays finite, with each stable integrator.
#[test]
fn a_ball_squeezed_flat_reports_its_clamped_volume() {
    let (positions, triangles) = icosphere(3, 0.5);
    let v0 = Mesh::new(&positions, &triangles).report().volume;
    for (integrator, substeps) in [
        (SOFTSHELL_INTEGRATOR_IMPLICIT_EULER, 1),
        (SOFTSHELL_INTEGRATOR_XPBD, 1),
        (SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER, 50),
    ] {
        let mut def = softshell_body_def_default();
        def.integrator = integrator;
        def.substeps = substeps;
        def.gravity = [0.0; 3];
        def.gas_amount = 10.0;
        let body = body(&positions, &triangles, &def);
        // Half-spaces y <= 1 mm and y >= -1 mm: the body starts flattened onto them.
        for (point, normal) in [([0.0f32, 0.001, 0.0], [0.0f32, -1.0, 0.0]), ([0.0, -0.001, 0.0], [0.0, 1.0, 0.0])] {
            // SAFETY: live body, float[3] each.
            let status = unsafe { softshell_body_add_plane_obstacle(body.0, point.as_ptr(), normal.as_ptr()) };
            assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
        }
        let mut clamped_steps = 0;
        let mut highest_pressure = 0.0f64;
        for k in 0..30 {
            let stats = step(&body);
            assert!(stats.volume.is_finite() && stats.pressure.is_finite(), "step {k}: {stats:?}");
            let s = snapshot(&body);
            assert!(s.positions.iter().all(|p| p.is_finite()), "step {k}");
            if stats.volume_clamped {
                clamped_steps += 1;
                assert!(stats.volume < 0.01 * v0 * 1.01, "step {k}: clamped at V = {} m^3", stats.volume);
            }
            highest_pressure = highest_pressure.max(stats.pressure);
        }
        println!(
            "integrator {integrator}: {clamped_steps} of 30 steps clamped, highest pressure {highest_pressure:.1} Pa"
        );
        assert!(clamped_steps > 0, "integrator {integrator}: a ball 2 mm thick never reported its clamped volume");
        // nRT / (1% of V0), the clamp's pressure (reported as the pressure that pushes).
        let clamp_pressure = 10.0 / (0.01 * v0);
        assert!(
            (highest_pressure / clamp_pressure - 1.0).abs() < 1e-4,
            "integrator {integrator}: {highest_pressure} Pa, the clamp's {clamp_pressure} Pa"
        );
    }
}

/// Advice the def can take: when a stable step needs more substeps than the most allowed
/// (`substeps` in [1, 1000]), the UNSTABLE message asks for a shorter `time_step` with 1000
/// substeps instead (a review saw it ask for more than 1000, which `softshell_body_new`
/// refuses), and that def is accepted and steps stably. Symplectic Euler on the body of
/// `following_the_unstable_advice_is_stable` with steps of 1 s.
#[test]
fn advice_beyond_the_most_substeps_shortens_the_time_step() {
    let (p, t) = icosphere(3, 0.5);
    let mut def = softshell_body_def_default();
    def.integrator = SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER;
    def.time_step = 1.0;
    let b = body(&p, &t, &def);
    shake(&b, p.len() / 3, 1e-5);
    let (status, message) = try_step(&b).expect_err("h = 1 s is far too long");
    assert_eq!(status, SoftshellStatus::Unstable);
    assert!(!message.contains("substeps >="), "{message}");
    let time_step: f32 = message
        .split("time_step <= ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no time_step advice: {message}"));
    assert!(message.contains("with substeps = 1000"), "{message}");
    println!("advice: time_step {time_step} s with 1000 substeps ({message})");
    def.time_step = time_step;
    def.substeps = 1000;
    let b = body(&p, &t, &def);
    shake(&b, p.len() / 3, 1e-5);
    for k in 0..5 {
        let stats = try_step(&b).unwrap_or_else(|(status, m)| panic!("step {k} as advised: {status:?}: {m}"));
        assert!(stats.kinetic_energy.is_finite());
    }
}

/// Advice beyond every allowed step: where even 1000 substeps of the shortest `time_step`
/// (1e-6 s) are too long, the message asks for no `time_step` the def refuses (it asked for
/// 5.6e-7 s: found by review) but says so and names the other integrators, and implicit Euler,
/// as named, steps the same body.
#[test]
fn advice_beyond_every_allowed_step_names_another_integrator() {
    let (p, t) = icosphere(2, 0.5);
    let mut def = softshell_body_def_default();
    def.integrator = SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER;
    def.spring_stiffness = 1e9;
    def.total_mass = 1e-6;
    def.gas_amount = 10.0;
    def.gravity = [0.0; 3];
    let b = body(&p, &t, &def);
    let (status, message) = try_step(&b).expect_err("h = 1/60 s is far too long");
    assert_eq!(status, SoftshellStatus::Unstable);
    assert!(!message.contains("time_step <=") && !message.contains("substeps >="), "{message}");
    assert!(message.contains("which no allowed step makes"), "{message}");
    assert!(message.contains("SOFTSHELL_INTEGRATOR_IMPLICIT_EULER"), "{message}");
    def.integrator = SOFTSHELL_INTEGRATOR_IMPLICIT_EULER;
    let b = body(&p, &t, &def);
    for k in 0..5 {
        try_step(&b).unwrap_or_else(|(status, m)| panic!("step {k} with implicit Euler: {status:?}: {m}"));
    }
}

/// Implicit Euler, a light ball squeezed between a sphere inside it and a plane through it at
/// h = 1/15 s, cracking: one linearised step turned a few joules into 1e13 (vertices at 5e6 m/s,
/// light copies made by the cracks under the clamped gas's forces). Once that step was rolled
/// back as UNSTABLE (and, before that, passed: the one-step test allowed what the forces could
/// give a 1e-10 kg vertex from rest, 5e18 J; found by review); now the step control takes such
/// steps again in finer substeps, and every step of the scene returns OK with its kinetic energy
/// bounded, some of them subdivided.
#[test]
fn implicit_euler_takes_a_step_that_makes_energy_from_nothing_again_finer() {
    let (positions, triangles) = icosphere(2, 0.5);
    let mut def = softshell_body_def_default();
    def.gas_amount = 200.0;
    def.restitution = 0.9;
    def.friction = 1000.0;
    def.time_step = 1.0 / 15.0;
    def.break_strain = 0.05;
    let b = body(&positions, &triangles, &def);
    let (center, point, normal) = ([0.0f32, -0.2, 0.0], [0.0f32, 0.1, 0.0], [0.0f32, 1.0, 0.3]);
    // SAFETY: live body, three floats each.
    unsafe {
        assert_eq!(softshell_body_add_sphere_obstacle(b.0, center.as_ptr(), 0.45), SoftshellStatus::Ok);
        assert_eq!(softshell_body_add_plane_obstacle(b.0, point.as_ptr(), normal.as_ptr()), SoftshellStatus::Ok);
    }
    // The gas can give at most nRT ln(V0 / V) = 200 ln(0.52 / 1e-6) J < 3e3 J, the springs
    // little more: 1e5 J is far above anything a step may make.
    let bound = 1e5;
    let mut finest = 1;
    for k in 0..8 {
        let stats = try_step(&b).unwrap_or_else(|(s, m)| panic!("step {k}: {s:?}: {m}"));
        assert!(stats.kinetic_energy < bound, "step {k}: {} J accepted", stats.kinetic_energy);
        // SAFETY: a live handle, used only here between calls.
        finest = finest.max(unsafe { &mut *b.0 }.body_mut().step_subdivision());
    }
    println!("subdivided up to {finest} times");
    assert!(finest > 1, "no step was subdivided");
}

/// Implicit Euler's contacts make some energy at long steps (velocities kept after the solve,
/// restitution): a ball bouncing on the ground at h = 1 s with restitution 0.9 made 39.7 J from
/// 9.0 J available, and is not a divergence. Without any allowance for it (the first fix of the
/// 1e13 J step above) this was reported UNSTABLE at its second step; it runs 240 steps, bounded
/// (found by review).
#[test]
fn implicit_euler_bouncing_at_one_second_steps_is_not_called_unstable() {
    let (positions, triangles) = icosphere(2, 0.5);
    let lowest = positions.chunks(3).map(|p| p[1]).fold(f32::INFINITY, f32::min);
    let mut def = softshell_body_def_default();
    def.ground = true;
    def.ground_height = lowest;
    def.time_step = 1.0;
    def.restitution = 0.9;
    let b = body(&positions, &triangles, &def);
    let mut most = 0.0f64;
    for k in 0..240 {
        let stats = try_step(&b).unwrap_or_else(|e| panic!("step {k}: {e:?}"));
        most = most.max(stats.kinetic_energy);
    }
    println!("most kinetic energy {most:.1} J");
    assert!(most < 1e3, "{most} J");
}

/// A free stiff ball keeps the momentum a push gave it under implicit Euler: internal forces
/// cannot change it, and the step's correction aims at the external force alone (zero here),
/// not at the sum of the f32 forces, whose large spring and gas terms cancel only to their
/// rounding (that moved this ball's momentum by 4.2% of the push in 30 steps).
#[test]
fn a_free_stiff_ball_keeps_its_momentum_under_implicit_euler() {
    let (p, t) = icosphere(2, 0.5);
    let def = SoftshellBodyDef {
        integrator: SOFTSHELL_INTEGRATOR_IMPLICIT_EULER,
        gravity: [0.0; 3],
        spring_stiffness: 1e5,
        total_mass: 0.1,
        gas_amount: 700.0,
        time_step: 0.05,
        ..softshell_body_def_default()
    };
    let ball = body(&p, &t, &def);
    let push = [1e-3f32, 0.0, 0.0];
    // SAFETY: live body, float[3].
    assert_eq!(unsafe { softshell_body_apply_impulse(ball.0, 5, push.as_ptr()) }, SoftshellStatus::Ok);
    let start = snapshot(&ball).momentum();
    let mut worst = 0.0f64;
    for _ in 0..30 {
        step(&ball);
        let now = snapshot(&ball).momentum();
        worst = worst.max((0..3).map(|a| (now[a] - start[a]).powi(2)).sum::<f64>().sqrt());
    }
    println!("momentum {start:?}, worst change {worst:.3e}");
    assert!(worst < 1e-5 * push[0] as f64, "the momentum moved by {worst:e} after a push of {}", push[0]);
}

/// A light (1e-12 kg), very stiff (K_s 1e12 N/m) ball in a strong wind and gravity (1e6), a
/// plane obstacle cutting through it, cracking at 5%: each of two planes (found by a review's
/// random probe; every value within the documented ranges), with the plane's normal.
fn light_stiff_bodies_pushed_against_planes() -> Vec<([f32; 3], Body)> {
    let planes: [([f32; 3], [f32; 3]); 2] = [
        ([0.0, 2.0563602e-5, 0.0], [-0.081627846, -0.19251376, -0.2849782]),
        ([0.0, -0.11276281, 0.0], [0.06855184, 0.03778088, 0.018837929]),
    ];
    planes
        .into_iter()
        .map(|(point, normal)| {
            let (p, t) = icosphere(1, 0.5);
            let mut def = softshell_body_def_default();
            def.total_mass = 1e-12;
            def.spring_stiffness = 1e12;
            def.gravity = [1e6, -1e6, 0.0];
            def.drag = 1e6;
            def.iterations = 100;
            def.break_strain = 0.05;
            let body = body(&p, &t, &def);
            // SAFETY: live body, float[3] arguments.
            let status = unsafe { softshell_body_add_plane_obstacle(body.0, point.as_ptr(), normal.as_ptr()) };
            assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
            (normal, body)
        })
        .collect()
}

/// The wind's work over a substep was summed from f32 products: on faces stretched far beyond
/// their size (a light, stiff body pushed out of an obstacle and torn) a product overflowed,
/// the work became NaN and the step still returned OK, with `energy_drift` NaN; the NaN stayed
/// in the energy reference, so every later drift was NaN and no drift test could fail again.
/// (Every value is within the documented ranges.)
#[test]
fn the_wind_never_makes_the_energy_drift_nan() {
    for (normal, body) in light_stiff_bodies_pushed_against_planes() {
        for k in 0..4 {
            match try_step(&body) {
                Ok(stats) => assert!(stats.energy_drift.is_finite(), "plane {normal:?}: step {k} OK with {stats:?}"),
                Err((status, message)) => {
                    assert_eq!(status, SoftshellStatus::Unstable, "{message}");
                    break;
                }
            }
        }
    }
}

/// The def an UNSTABLE message advises: its `substeps >= N`, or its `time_step <= X s with
/// substeps = 1000`.
fn advised(def: &SoftshellBodyDef, message: &str) -> SoftshellBodyDef {
    let field = |after: &str| message.split(after).nth(1).and_then(|t| t.split([' ', ')']).next()).map(str::to_owned);
    if let Some(substeps) = field("substeps >= ").and_then(|t| t.parse().ok()) {
        return SoftshellBodyDef { substeps, ..*def };
    }
    let time_step =
        field("time_step <= ").and_then(|t| t.parse().ok()).unwrap_or_else(|| panic!("no advice: {message}"));
    SoftshellBodyDef { time_step, substeps: 1000, ..*def }
}

/// Symplectic Euler's advice must hold for a body whose gas, not its springs, is the stiff part
/// (SPEC 2.2: UNSTABLE "with the largest stable h it can estimate"; the pressure's stiffness,
/// SPEC 2.1 eq. 8-9, is part of `ω_max`). A ball of nRT 1e9 J at K_s 1000 N/m was advised
/// "substeps >= 30" from the springs alone (h = 5.6e-4 s); with them its first step reached
/// 6.9e29 J and was UNSTABLE again, now advising itself, symplectic Euler.
#[test]
fn symplectic_advice_counts_the_gas_stiffness() {
    let (p, t) = icosphere(2, 0.5);
    let mut def = softshell_body_def_default();
    def.integrator = SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER;
    def.gas_amount = 1e9;
    let b = body(&p, &t, &def);
    let (status, message) = try_step(&b).expect_err("h = 1/60 s is far too long for nRT = 1e9 J");
    assert_eq!(status, SoftshellStatus::Unstable);
    let def = advised(&def, &message);
    println!("advice: time_step {} s, {} substeps ({message})", def.time_step, def.substeps);
    let b = body(&p, &t, &def);
    for k in 0..5 {
        let stats = try_step(&b).unwrap_or_else(|(s, m)| panic!("step {k} as advised ({message}): {s:?}: {m}"));
        assert!(stats.kinetic_energy.is_finite());
    }
}

/// A body so far from the origin that its f32 positions cannot resolve its motion (a 0.5 m ball
/// 1e5 m up: positions move in steps of 7.8 mm there, its first step falls 2.7 mm) is UNSTABLE
/// at any time step, and its message says why and what helps (it advised only more substeps,
/// found by review); the same ball near the origin steps, and a 1 m ball 3e4 m up (steps of
/// 2 mm there, a first step of 2.7 mm) falls as the header says.
#[test]
fn a_body_far_from_the_origin_is_told_to_move_near_it() {
    let (p, t) = icosphere(1, 0.5);
    let far: Vec<f32> = p.chunks_exact(3).flat_map(|c| [c[0], c[1] + 1e5, c[2]]).collect();
    let def = softshell_body_def_default();
    let near = body(&p, &t, &def);
    for _ in 0..5 {
        step(&near);
    }
    let (p2, t2) = icosphere(2, 1.0);
    let raised = |height: f32| -> Vec<f32> { p2.chunks_exact(3).flat_map(|c| [c[0], c[1] + height, c[2]]).collect() };
    // How far the centre of a ball of radius 1 raised by `height` falls in `steps` steps.
    let fall = |height: f32, def: &SoftshellBodyDef, steps: usize| -> f64 {
        let b = body(&raised(height), &t2, def);
        let start = snapshot(&b).center_y();
        for _ in 0..steps {
            step(&b);
        }
        start - snapshot(&b).center_y()
    };
    // Half a second of free fall: 1.2 m (to the resolution of 2 mm there).
    let fallen = fall(3e4, &def, 30);
    assert!((fallen - 0.5 * 9.81 * 0.25).abs() < 0.1, "fell {fallen} m");
    let far = body(&far, &t, &def);
    match try_step(&far) {
        Err((status, message)) => {
            assert_eq!(status, SoftshellStatus::Unstable, "{message}");
            assert!(message.contains("from the origin") && message.contains("near the origin"), "{message}");
        }
        Ok(stats) => panic!("the far body stepped: {stats:?}"),
    }
    // Steps so short that gravity moves a body by 1e-10 m in the last substep of a step from
    // rest (|g| T h), against steps of 2.4e-7 m of the positions 2 m up (the top of a ball of
    // radius 1 centred 1 m up): symplectic Euler is UNSTABLE there, and the note says why.
    // Implicit Euler and XPBD step but lose most of the fall, unreported, as the header says
    // (a known limit: this part changes when positions keep their remainders).
    for integrator in [SOFTSHELL_INTEGRATOR_IMPLICIT_EULER, SOFTSHELL_INTEGRATOR_XPBD] {
        let def = SoftshellBodyDef { time_step: 1e-5, substeps: 10, integrator, ..softshell_body_def_default() };
        let fallen = fall(1.0, &def, 200);
        // 0.5 g (200 T)^2 = 1.96e-5 m; the header says 4.4e-6 m.
        assert!((fallen - 4.4e-6).abs() < 0.5e-6, "integrator {integrator}: fell {fallen:e} m");
    }
    let short = SoftshellBodyDef {
        time_step: 1e-5,
        substeps: 10,
        integrator: SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER,
        ..softshell_body_def_default()
    };
    let short = body(&raised(1.0), &t2, &short);
    let failed = (0..5).find_map(|_| try_step(&short).err());
    let (status, message) = failed.expect("the short substeps' body stepped");
    assert_eq!(status, SoftshellStatus::Unstable, "{message}");
    assert!(message.contains("times its motion in a substep") && message.contains("near the origin"), "{message}");
    // Near the origin, without gravity and at rest, a body that diverges for its stiffness gets
    // no such note (it has no motion to compare; the first form of the note then always fired).
    let stiff = SoftshellBodyDef {
        integrator: SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER,
        gravity: [0.0; 3],
        gas_amount: 1.0,
        spring_stiffness: 1e9,
        ..softshell_body_def_default()
    };
    let stiff = body(&p2, &t2, &stiff);
    let (status, message) = (0..5).find_map(|_| try_step(&stiff).err()).expect("the stiff body stepped");
    assert_eq!(status, SoftshellStatus::Unstable, "{message}");
    assert!(!message.contains("from the origin"), "{message}");
    // Nor with gravity and 200 substeps (h = 8.3e-5 s, 65 times its stable step): its first
    // substep's fall |g| h^2 (6.8e-8 m) is below the step of the positions at 1 m (1.2e-7 m),
    // but the step's fall from rest is not, and its trouble is its stiffness (found by review).
    let stiff = SoftshellBodyDef {
        integrator: SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER,
        total_mass: 0.01,
        gas_amount: 10.0,
        spring_stiffness: 1e7,
        substeps: 200,
        ..softshell_body_def_default()
    };
    let (p1, t1) = icosphere(2, 1.0);
    let stiff = body(&p1, &t1, &stiff);
    let (status, message) = (0..5).find_map(|_| try_step(&stiff).err()).expect("the stiff body stepped");
    assert_eq!(status, SoftshellStatus::Unstable, "{message}");
    assert!(!message.contains("from the origin"), "{message}");
}

/// A step of implicit Euler whose energy made from nothing jumps by many orders of magnitude is
/// UNSTABLE at once (the drift rule otherwise waits for a second step over its limit, as one
/// step may spike): a light, very stiff body pushed by wind against a plane went from a drift
/// of -1.1e11 J to 1.3e33 J in one step and returned OK (found by review).
#[test]
fn a_huge_jump_of_the_energy_drift_is_unstable_at_once() {
    for (normal, body) in light_stiff_bodies_pushed_against_planes() {
        // The first step loses 3e10-1e11 J (pushed out of the plane); after it, no step that returns
        // OK may make a million times the largest drift so far.
        let mut largest = step(&body).energy_drift.abs().max(1.0);
        for k in 1..8 {
            match try_step(&body) {
                Ok(stats) => {
                    let drift = stats.energy_drift;
                    assert!(drift <= 1e6 * largest, "plane {normal:?}: step {k} OK with a drift of {drift:.3e} J");
                    largest = largest.max(drift.abs());
                }
                Err((status, message)) => {
                    assert_eq!(status, SoftshellStatus::Unstable, "{message}");
                    break;
                }
            }
        }
    }
}
