//! The soft body's C ABI contract: defs and their validation, NULLs, indices, non-finite inputs,
//! buffers, memory that is not allocated for unused features, determinism across thread counts.
#![cfg(feature = "body")]

mod body_util;

use body_util::*;
use softshell::ffi::SoftshellStatus;
use softshell::ffi::body::*;

fn ball() -> (Vec<f32>, Vec<u32>) {
    icosphere(2, 0.5)
}

#[test]
fn default_def_has_the_documented_values() {
    let def = softshell_body_def_default();
    assert_eq!(def.time_step, 1.0 / 60.0);
    assert_eq!(def.integrator, SOFTSHELL_INTEGRATOR_IMPLICIT_EULER);
    assert_eq!(def.gravity, [0.0, -9.81, 0.0]);
    assert_eq!((def.gas_amount, def.break_strain, def.break_force), (0.0, 0.0, 0.0));
    assert_eq!(def.substeps, 1);
}

#[test]
fn bad_defs_are_refused_with_the_field_named() {
    let (p, t) = ball();
    let mut zeroed: SoftshellBodyDef = unsafe { std::mem::zeroed() };
    zeroed.time_step = 0.01;
    let (status, message) = try_body(&p, &t, &zeroed).err().unwrap();
    assert_eq!(status, SoftshellStatus::InvalidArgument);
    assert!(message.contains("softshell_body_def_default"), "{message}");
    type Edit = Box<dyn Fn(&mut SoftshellBodyDef)>;
    let cases: Vec<(&str, Edit)> = vec![
        ("time_step", Box::new(|d| d.time_step = f32::NAN)),
        ("time_step", Box::new(|d| d.time_step = 0.0)),
        ("substeps", Box::new(|d| d.substeps = 0)),
        ("integrator", Box::new(|d| d.integrator = 99)),
        ("total_mass", Box::new(|d| d.total_mass = -1.0)),
        ("spring_stiffness", Box::new(|d| d.spring_stiffness = f32::INFINITY)),
        ("gas_amount", Box::new(|d| d.gas_amount = -5.0)),
        ("gravity[1]", Box::new(|d| d.gravity[1] = f32::NAN)),
        ("wind[2]", Box::new(|d| d.wind[2] = f32::INFINITY)),
        ("restitution", Box::new(|d| d.restitution = 1.5)),
        ("break_strain", Box::new(|d| d.break_strain = -0.1)),
        ("threads", Box::new(|d| d.threads = 1000)),
        ("iterations", Box::new(|d| d.iterations = 0)),
    ];
    for (field, edit) in cases {
        let mut def = softshell_body_def_default();
        edit(&mut def);
        let (status, message) = try_body(&p, &t, &def).err().unwrap_or_else(|| panic!("{field} accepted"));
        assert_eq!(status, SoftshellStatus::InvalidArgument, "{field}");
        assert!(message.contains(field), "{field}: {message}");
    }
}

#[test]
fn gas_needs_a_closed_mesh_and_cloth_needs_none() {
    let (p, t) = cloth(5, 1.0);
    let mut def = softshell_body_def_default();
    assert!(try_body(&p, &t, &def).is_ok());
    def.gas_amount = 10.0;
    let (status, message) = try_body(&p, &t, &def).err().unwrap();
    assert_eq!(status, SoftshellStatus::InvalidMesh);
    assert!(message.contains("closed"), "{message}");
    // An inward-wound ball is refused with gas.
    let (p, t) = ball();
    let flipped: Vec<u32> = t.chunks_exact(3).flat_map(|c| [c[0], c[2], c[1]]).collect();
    let (status, message) = try_body(&p, &flipped, &def).err().unwrap();
    assert_eq!(status, SoftshellStatus::InvalidMesh);
    assert!(message.contains("winding"), "{message}");
    // So is one wound inward beside a larger outward one (the total volume is positive; the
    // inward piece got no gas and nothing said so: a review).
    let (mut p, mut t) = icosphere(2, 0.5);
    let (q, u) = icosphere(1, 0.3);
    let offset = (p.len() / 3) as u32;
    p.extend(q.chunks(3).flat_map(|v| [v[0] + 2.0, v[1], v[2]]));
    t.extend(u.chunks(3).flat_map(|c| [c[0] + offset, c[2] + offset, c[1] + offset]));
    assert!(Mesh::new(&p, &t).report().volume > 0.0);
    let (status, message) = try_body(&p, &t, &def).err().expect("an inward piece was accepted");
    assert_eq!(status, SoftshellStatus::InvalidMesh);
    assert!(message.contains("every closed piece wound outward"), "{message}");
    // Without gas the winding does not matter.
    def.gas_amount = 0.0;
    assert!(try_body(&p, &t, &def).is_ok());
}

#[test]
fn nulls_indices_and_non_finite_inputs_change_nothing() {
    let (p, t) = ball();
    let mesh = Mesh::new(&p, &t);
    let def = softshell_body_def_default();
    let mut out = std::ptr::null_mut();
    // SAFETY: NULL arguments are documented to be refused.
    unsafe {
        assert_eq!(softshell_body_new(std::ptr::null(), &def, &mut out), SoftshellStatus::NullArgument);
        assert_eq!(softshell_body_new(mesh.0, std::ptr::null(), &mut out), SoftshellStatus::NullArgument);
        assert_eq!(softshell_body_new(mesh.0, &def, std::ptr::null_mut()), SoftshellStatus::NullArgument);
        assert!(out.is_null());
        assert_eq!(softshell_body_step(std::ptr::null_mut(), std::ptr::null_mut()), SoftshellStatus::NullArgument);
        assert_eq!(softshell_body_vertex_count(std::ptr::null()), 0);
        assert_eq!(softshell_body_triangle_count(std::ptr::null()), 0);
        assert_eq!(softshell_body_fragment_count(std::ptr::null()), 0);
        assert_eq!(softshell_body_topology_generation(std::ptr::null()), 0);
        assert_eq!(softshell_body_memory_bytes(std::ptr::null()), 0);
        softshell_body_free(std::ptr::null_mut());
    }
    let body = body(&p, &t, &def);
    let before = snapshot(&body);
    let n = before.vertex_count() as u32;
    // SAFETY: live body; bad values are documented to be refused.
    unsafe {
        assert_eq!(softshell_body_pin_vertex(body.0, n), SoftshellStatus::InvalidArgument);
        assert!(last_error().contains(&n.to_string()));
        let nan = [0.0, f32::NAN, 0.0];
        assert_eq!(softshell_body_apply_impulse(body.0, 0, nan.as_ptr()), SoftshellStatus::InvalidArgument);
        assert_eq!(
            softshell_body_apply_impulse(body.0, n, [1.0f32, 0.0, 0.0].as_ptr()),
            SoftshellStatus::InvalidArgument
        );
        assert_eq!(softshell_body_apply_impulse(body.0, 0, std::ptr::null()), SoftshellStatus::NullArgument);
        assert_eq!(
            softshell_body_add_plane_obstacle(body.0, [0.0f32; 3].as_ptr(), [0.0f32; 3].as_ptr()),
            SoftshellStatus::InvalidArgument
        );
        assert_eq!(
            softshell_body_add_sphere_obstacle(body.0, [0.0f32; 3].as_ptr(), 0.0),
            SoftshellStatus::InvalidArgument
        );
        assert_eq!(softshell_body_break_edge(body.0, 0, 0), SoftshellStatus::InvalidArgument);
        assert_eq!(softshell_body_break_edge(body.0, 0, n + 5), SoftshellStatus::InvalidArgument);
        // Two vertices that are not neighbours.
        let far =
            (0..n).max_by(|&a, &b| before.position(a as usize)[1].total_cmp(&before.position(b as usize)[1])).unwrap();
        let low =
            (0..n).min_by(|&a, &b| before.position(a as usize)[1].total_cmp(&before.position(b as usize)[1])).unwrap();
        assert_eq!(softshell_body_break_edge(body.0, far, low), SoftshellStatus::InvalidArgument);
        assert!(last_error().contains("not joined by a spring"), "{}", last_error());
        // A step with NULL stats is fine.
        assert_eq!(softshell_body_step(body.0, std::ptr::null_mut()), SoftshellStatus::Ok);
    }
    let after = snapshot(&body);
    assert_eq!(after.generation, before.generation, "a refused call changed the topology");
    assert_eq!(after.vertex_count(), before.vertex_count());
}

#[test]
fn obstacles_pins_and_impulses_act() {
    let (mut p, t) = ball();
    for c in p.chunks_exact_mut(3) {
        c[1] += 1.0;
    }
    let mut def = softshell_body_def_default();
    def.gas_amount = 20.0;
    def.spring_damping = 0.2;
    let body = body(&p, &t, &def);
    // SAFETY: live body, float[3] arguments.
    unsafe {
        assert_eq!(
            softshell_body_add_plane_obstacle(body.0, [0.0f32, 0.2, 0.0].as_ptr(), [0.0f32, 2.0, 0.0].as_ptr()),
            SoftshellStatus::Ok
        );
        assert_eq!(softshell_body_add_sphere_obstacle(body.0, [3.0f32, 0.0, 0.0].as_ptr(), 1.0), SoftshellStatus::Ok);
        assert_eq!(softshell_body_apply_impulse(body.0, 0, [0.0f32, 0.0, 0.01].as_ptr()), SoftshellStatus::Ok);
    }
    let s = snapshot(&body);
    assert!(s.velocities[2] > 0.0, "the impulse changed the velocity");
    for _ in 0..120 {
        step(&body);
    }
    let s = snapshot(&body);
    let lowest = s.positions.chunks_exact(3).map(|c| c[1]).fold(f32::INFINITY, f32::min);
    assert!(lowest > 0.19, "the plane at y = 0.2 holds the ball ({lowest})");
}

#[test]
fn nothing_is_allocated_for_gas_or_fracture_a_scene_does_not_use() {
    let (p, t) = ball();
    let plain = softshell_body_def_default();
    let mut gas = plain;
    gas.gas_amount = 10.0;
    let mut fracture = plain;
    fracture.break_strain = 0.5;
    let mut core = plain;
    core.break_force = 100.0;
    let (m_plain, m_gas, m_fracture, m_core) = (
        memory(&body(&p, &t, &plain)),
        memory(&body(&p, &t, &gas)),
        memory(&body(&p, &t, &fracture)),
        memory(&body(&p, &t, &core)),
    );
    println!("memory: plain {m_plain}, gas {m_gas}, fracture {m_fracture}, cores {m_core}");
    let vertices = p.len() / 3;
    // Gas bookkeeping is at least a fragment per vertex; fracture at least origins and marks.
    assert!(m_gas >= m_plain + 4 * vertices, "gas: {m_gas} vs {m_plain}");
    assert!(m_fracture >= m_plain + 4 * vertices, "fracture: {m_fracture} vs {m_plain}");
    assert_eq!(m_fracture, m_core);
    // A step allocates scratch, but none for gas or fracture.
    let a = body(&p, &t, &plain);
    let b = body(&p, &t, &gas);
    step(&a);
    step(&b);
    assert!(memory(&b) > memory(&a));
    // Breaking an edge by hand allocates the fracture bookkeeping then, not before.
    let before = memory(&a);
    let s = snapshot(&a);
    // SAFETY: live body.
    assert_eq!(unsafe { softshell_body_break_edge(a.0, s.triangles[0], s.triangles[1]) }, SoftshellStatus::Ok);
    assert!(memory(&a) > before);
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    // 2562 vertices: more than one parallel chunk, so the threads really share the work.
    let (p, t) = icosphere(4, 0.5);
    // Scenes: free, on the ground, in wind (the implicit solver then measures the gas and the
    // external forces before its team region, and sums g·v in the spring-terms claim).
    let run = |threads: u32, integrator: u32, scene: u32| {
        let ground = scene == 1;
        let mut def = softshell_body_def_default();
        if scene == 2 {
            def.drag = 0.5;
            def.wind = [3.0, 0.0, 1.0];
        }
        def.threads = threads;
        def.integrator = integrator;
        def.gas_amount = 30.0;
        def.break_strain = 0.08;
        def.substeps = 2;
        // On the ground from the 10th step: the contacts' filters in the solve.
        def.ground = ground;
        def.ground_height = -0.6;
        let body = body(&p, &t, &def);
        for _ in 0..30 {
            step(&body);
        }
        let s = snapshot(&body);
        (s.positions, s.triangles)
    };
    for integrator in [SOFTSHELL_INTEGRATOR_IMPLICIT_EULER, SOFTSHELL_INTEGRATOR_XPBD] {
        for scene in [0, 1, 2] {
            let one = run(1, integrator, scene);
            assert_eq!(one, run(2, integrator, scene));
            assert_eq!(one, run(0, integrator, scene));
            // More threads than the machine may have cores: the implicit solver's team barriers
            // must yield to members that wait for a core, and the bits stay the same.
            assert_eq!(one, run(3, integrator, scene));
        }
    }
}

/// A body of over 2,048 vertices stores them in an order of its own (`body::vertex_order`):
/// numbering the same mesh another way gives the same motion, vertex for vertex, with pins and
/// impulses on the same (renumbered) vertices, and every buffer in the caller's numbering.
#[test]
fn a_body_moves_the_same_however_its_mesh_is_numbered() {
    let (p, t) = icosphere(4, 0.5);
    let n = p.len() / 3;
    // new index of vertex k: a fixed permutation (1237 is prime to 2562).
    assert_eq!(n, 2562);
    let renumber = |k: usize| (k * 1237 + 11) % n;
    let mut q = vec![0.0f32; p.len()];
    for k in 0..n {
        q[3 * renumber(k)..3 * renumber(k) + 3].copy_from_slice(&p[3 * k..3 * k + 3]);
    }
    let u: Vec<u32> = t.iter().map(|&k| renumber(k as usize) as u32).collect();
    let mut def = softshell_body_def_default();
    def.gas_amount = 30.0;
    def.ground = true;
    def.ground_height = -0.6;
    def.threads = 2;
    let (pinned, pushed) = (5usize, 700usize);
    let run = |positions: &[f32], triangles: &[u32], map: &dyn Fn(usize) -> usize| {
        let body = body(positions, triangles, &def);
        let start = snapshot(&body);
        assert_eq!(start.positions, positions);
        assert_eq!(start.triangles, triangles);
        // SAFETY: live body, float[3].
        unsafe {
            assert_eq!(softshell_body_pin_vertex(body.0, map(pinned) as u32), SoftshellStatus::Ok);
            let impulse = [0.0f32, 0.0, 0.05];
            assert_eq!(softshell_body_apply_impulse(body.0, map(pushed) as u32, impulse.as_ptr()), SoftshellStatus::Ok);
        }
        let after_impulse = snapshot(&body);
        let v = &after_impulse.velocities[3 * map(pushed)..3 * map(pushed) + 3];
        let m = after_impulse.masses[map(pushed)];
        assert!((v[2] * m - 0.05).abs() < 1e-6 && v[0] == 0.0, "the impulse went to vertex {}", map(pushed));
        for _ in 0..40 {
            step(&body);
        }
        let end = snapshot(&body);
        assert_eq!(end.position(map(pinned)), start.position(map(pinned)), "the pinned vertex stayed");
        // Back in the first numbering.
        let positions: Vec<[f32; 3]> = (0..n).map(|k| end.position(map(k))).collect();
        let masses: Vec<f32> = (0..n).map(|k| end.masses[map(k)]).collect();
        (positions, masses)
    };
    let (a, mass_a) = run(&p, &t, &|k| k);
    let (b, mass_b) = run(&q, &u, &renumber);
    assert_eq!(mass_a, mass_b);
    let fell = a.iter().map(|x| x[1]).fold(f32::MAX, f32::min);
    assert!(fell < -0.55, "the ball reached the ground ({fell})");
    for k in 0..n {
        let d = (0..3).map(|c| (a[k][c] - b[k][c]).abs()).fold(0.0f32, f32::max);
        assert!(d < 1e-4, "vertex {k}: {:?} vs {:?}", a[k], b[k]);
    }
}

/// A reordered body (2,562 vertices) names the caller's vertices in its messages.
#[test]
fn messages_name_the_callers_indices_on_a_large_body() {
    let (p, t) = icosphere(4, 0.5);
    let n = p.len() / 3;
    let def = softshell_body_def_default();
    let b = body(&p, &t, &def);
    // Two vertices not joined by an edge.
    // SAFETY: live body.
    let status = unsafe { softshell_body_break_edge(b.0, 1000, 17) };
    assert_eq!(status, SoftshellStatus::InvalidArgument);
    let m = last_error();
    assert!(m.contains("1000") && m.contains("17"), "{m}");
    // SAFETY: live body.
    let status = unsafe { softshell_body_pin_vertex(b.0, n as u32) };
    assert!(last_error().contains(&format!("{n}")));
    assert_eq!(status, SoftshellStatus::InvalidArgument);
    // Zero-length edge: move vertex t[1] onto t[0].
    let (a, c) = (t[0] as usize, t[1] as usize);
    let mut q = p.clone();
    for k in 0..3 {
        q[3 * c + k] = p[3 * a + k];
    }
    match try_body(&q, &t, &def) {
        Ok(_) => panic!("accepted"),
        Err((_, m)) => {
            assert!(m.contains(&format!("{}", a.min(c))) && m.contains(&format!("{}", a.max(c))), "{m}");
        }
    }
}

/// Positions and triangles after `steps` steps of a gas body falling onto the ground.
fn run_on_ground(p: &[f32], t: &[u32], threads: u32, steps: usize) -> (Vec<f32>, Vec<u32>) {
    let mut def = softshell_body_def_default();
    def.threads = threads;
    def.gas_amount = 30.0;
    def.substeps = 2;
    def.ground = true;
    def.ground_height = -0.6;
    let b = body(p, t, &def);
    for _ in 0..steps {
        step(&b);
    }
    let s = snapshot(&b);
    (s.positions, s.triangles)
}

/// Two balls of 2,562 vertices in one body (two fragments, each with its gas): the coarse
/// level's split solve gives the same bits on 1, 2 and 3 threads.
#[test]
fn two_disjoint_balls_bit_identical_across_threads() {
    let (p, t) = icosphere(4, 0.5);
    let n = (p.len() / 3) as u32;
    let mut q = p.clone();
    for k in 0..p.len() / 3 {
        q.push(p[3 * k] + 3.0);
        q.push(p[3 * k + 1]);
        q.push(p[3 * k + 2]);
    }
    let mut u = t.clone();
    u.extend(t.iter().map(|&i| i + n));
    let one = run_on_ground(&q, &u, 1, 20);
    assert_eq!(one, run_on_ground(&q, &u, 2, 20));
    assert_eq!(one, run_on_ground(&q, &u, 3, 20));
}

/// A big face and a sliver beside it (legs 10 m and 1e-15 m): both pass the mesh checks, and the
/// sliver's corners get about 1e-32 of the mass.
fn big_face_and_sliver() -> (Vec<f32>, Vec<u32>) {
    let positions = vec![
        0.0, 0.0, 0.0, 10.0, 0.0, 0.0, 0.0, 10.0, 0.0, //
        0.0, 0.0, 1e-6, 1e-15, 0.0, 1e-6, 0.0, 1e-15, 1e-6,
    ];
    (positions, vec![0, 1, 2, 3, 4, 5])
}

/// An impulse that would give a light vertex a velocity beyond ±1e12 m/s on an axis (infinite
/// in f32 for this one: every step after it diverged back to that state) is refused with
/// INVALID_ARGUMENT and a message naming the vertex's mass, and nothing changes; a smaller one
/// on the same vertex is taken, and the body steps on (found by review).
#[test]
fn an_impulse_that_would_make_a_velocity_too_large_is_refused() {
    let (positions, triangles) = big_face_and_sliver();
    let mut def = softshell_body_def_default();
    def.gas_amount = 0.0;
    let b = body(&positions, &triangles, &def);
    let before = snapshot(&b);
    // SAFETY: live body, three floats.
    let status = unsafe { softshell_body_apply_impulse(b.0, 3, [1e12f32, 0.0, 0.0].as_ptr()) };
    assert_eq!(status, SoftshellStatus::InvalidArgument);
    let message = last_error();
    assert!(message.contains("vertex 3") && message.contains("mass"), "{message}");
    let after = snapshot(&b);
    assert_eq!(after.velocities, before.velocities, "a refused impulse changed a velocity");
    let mass = after.masses[3];
    // Finite but beyond the bound: 1e13 m/s.
    // SAFETY: as above.
    let status = unsafe { softshell_body_apply_impulse(b.0, 3, [mass * 1e13, 0.0, 0.0].as_ptr()) };
    assert_eq!(status, SoftshellStatus::InvalidArgument, "1e13 m/s");
    assert!(last_error().contains("1e12"), "{}", last_error());
    assert_eq!(snapshot(&b).velocities, before.velocities);
    // 1 m/s on that vertex.
    // SAFETY: as above.
    let status = unsafe { softshell_body_apply_impulse(b.0, 3, [mass, 0.0, 0.0].as_ptr()) };
    assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
    let v = snapshot(&b).velocities;
    assert!((v[9] - 1.0).abs() < 1e-5, "{:?}", &v[9..12]);
    assert!(v.iter().all(|c| c.is_finite()));
}

/// A `total_mass` that gives a vertex with faces a mass below the smallest normal float is
/// refused when the body is made (such a body was accepted and every step of it diverged), with
/// INVALID_ARGUMENT and a message naming the vertex and what to change; the same mesh with a
/// mass of 1 kg is accepted and steps (found by review).
#[test]
fn a_total_mass_too_small_for_a_vertex_is_refused() {
    let (positions, triangles) = big_face_and_sliver();
    let mut def = softshell_body_def_default();
    def.gas_amount = 0.0;
    def.total_mass = 1e-12;
    let Err((status, message)) = try_body(&positions, &triangles, &def) else {
        panic!("a body whose sliver corners get a subnormal mass was accepted");
    };
    assert_eq!(status, SoftshellStatus::InvalidArgument, "{message}");
    assert!(message.contains("total_mass") && message.contains("vertex"), "{message}");
    def.total_mass = 1.0;
    let b = body(&positions, &triangles, &def);
    assert!(snapshot(&b).masses.iter().all(|&m| m.is_normal()));
}

/// The plane's normal: refused at a length of 1e-12 or less, with a message that says so
/// (it said "non-zero" of a non-zero normal), taken just above.
#[test]
fn a_plane_normal_is_refused_only_at_the_documented_length() {
    let (positions, triangles) = icosphere(1, 0.5);
    let b = body(&positions, &triangles, &softshell_body_def_default());
    let point = [0.0f32, -2.0, 0.0];
    // SAFETY: live body, three floats each.
    let status = unsafe { softshell_body_add_plane_obstacle(b.0, point.as_ptr(), [0.0f32, 1e-13, 0.0].as_ptr()) };
    assert_eq!(status, SoftshellStatus::InvalidArgument);
    assert!(last_error().contains("above 1e-12"), "{}", last_error());
    // SAFETY: as above.
    let status = unsafe { softshell_body_add_plane_obstacle(b.0, point.as_ptr(), [0.0f32, 1e-11, 0.0].as_ptr()) };
    assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
}

/// Pinning a moving vertex takes its kinetic energy away; that counts as external work (as an
/// impulse's does), so `energy_drift` keeps measuring the integrator alone: a ball moving at
/// 1 m/s with a vertex pinned after its first step drifts as much as the same ball unpinned,
/// to well under a tenth of what the pin took (undamped, and with substeps enough that the
/// integrator's own error after the jolt is small; before, the drift was the pin's -2.05e-3 J).
#[test]
fn pinning_a_moving_vertex_is_not_taken_for_energy_drift() {
    let (p, t) = icosphere(2, 0.5);
    let def = SoftshellBodyDef {
        integrator: SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER,
        gravity: [0.0; 3],
        spring_stiffness: 200.0,
        spring_damping: 0.0,
        substeps: 200,
        total_mass: 1.0,
        ..softshell_body_def_default()
    };
    let moving = |pin: bool| {
        let body = body(&p, &t, &def);
        let start = snapshot(&body);
        for k in 0..start.vertex_count() {
            let impulse = [start.masses[k], 0.0, 0.0]; // 1 m/s along x
            // SAFETY: live body, float[3].
            assert_eq!(
                unsafe { softshell_body_apply_impulse(body.0, k as u32, impulse.as_ptr()) },
                SoftshellStatus::Ok
            );
        }
        step(&body);
        let before = snapshot(&body);
        let taken = 0.5 * before.masses[0] as f64 * (0..3).map(|a| (before.velocities[a] as f64).powi(2)).sum::<f64>();
        if pin {
            // SAFETY: live body.
            assert_eq!(unsafe { softshell_body_pin_vertex(body.0, 0) }, SoftshellStatus::Ok);
        }
        let mut drift = 0.0;
        for _ in 0..3 {
            drift = step(&body).energy_drift;
        }
        (drift, taken)
    };
    let (free, _) = moving(false);
    let (pinned, taken) = moving(true);
    assert!(taken > 1e-4, "the pinned vertex carried {taken} J");
    assert!(
        (pinned - free).abs() < 0.1 * taken,
        "drift {pinned} J with the pin against {free} J without; the pin took {taken} J"
    );
}

/// A mesh with a vertex no triangle uses (common in OBJ files: the body gives it no mass and
/// holds it) made `softshell_body_new` panic with the default def (implicit Euler): its coarse
/// level divided the vertex's zero mass by its zero diagonal, and the NaN drop tolerance failed
/// an assert, so the call returned INTERNAL ("this is a bug in softshell").
#[test]
fn a_mesh_with_an_unused_vertex_makes_a_body_with_the_default_def() {
    let (mut p, t) = icosphere(1, 0.5);
    p.extend([5.0, 5.0, 5.0]);
    for gas in [0.0f32, 5.0] {
        let mut def = softshell_body_def_default();
        def.gas_amount = gas;
        let body = try_body(&p, &t, &def).unwrap_or_else(|(s, m)| panic!("gas {gas}: {s:?}: {m}"));
        for _ in 0..10 {
            let stats = step(&body);
            assert!(stats.kinetic_energy.is_finite() && stats.energy_drift.is_finite());
        }
        let s = snapshot(&body);
        assert!(s.positions.iter().chain(&s.velocities).all(|v| v.is_finite()));
        let unused = s.vertex_count() - 1;
        assert_eq!(s.position(unused), [5.0, 5.0, 5.0], "the unused vertex has no mass and stays");
    }
}

/// A vertex beyond ±1e9 m (the ground plane's range) is refused when the body is made, with the
/// vertex named: a ball of radius 1e20 m was accepted and then UNSTABLE at every step (f32
/// squares of its lengths overflow), and a unit ball 2e9 m out was refused for a degenerate
/// triangle, which hid the cause. A ball of radius 5e8 m is made and steps.
#[test]
fn a_vertex_beyond_the_coordinate_range_is_refused_by_name() {
    let (p, t) = icosphere(1, 1.0);
    let def = softshell_body_def_default();
    let scaled = |scale: f32, offset: f32| -> Vec<f32> { p.iter().map(|&c| c * scale + offset).collect() };
    for (scale, offset) in [(1e20f32, 0.0f32), (2e9, 0.0), (1.0, 2e9), (1.0, -3e9)] {
        let positions = scaled(scale, offset);
        let first = positions.chunks_exact(3).position(|c| c.iter().any(|v| v.abs() > 1e9)).unwrap();
        match try_body(&positions, &t, &def) {
            Err((status, message)) => {
                assert_eq!(status, SoftshellStatus::InvalidMesh, "{message}");
                assert!(message.contains(&format!("vertex {first} is at")) && message.contains("1e9"), "{message}");
            }
            Ok(_) => panic!("a ball of radius {scale:e} at {offset:e} was made"),
        }
    }
    let big = body(&scaled(5e8, 0.0), &t, &def);
    step(&big);
}
