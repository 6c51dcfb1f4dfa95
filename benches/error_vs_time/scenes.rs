//! The fixed scenes of the work-precision report and their references (SPEC 4), each driven
//! through the C ABI only.

use std::time::Instant;

use softshell::ffi::body::*;
use softshell::ffi::lattice::*;
use softshell::ffi::shell::*;
use softshell::ffi::{SoftshellBodyDef, SoftshellLatticeDef, SoftshellShellDef};

use crate::Run;
use crate::report_util::*;

// ------------------------------------------------------------------------------------------ shell

/// The shell scenes' description, with the library defaults read from
/// `softshell_shell_def_default()` (never written as literals).
pub fn shell_scene() -> String {
    let d = softshell_shell_def_default();
    let i = inflate_base();
    format!(
        "Analytic scene: data/sphere.obj (482 vertices) scaled to a unit bounding-box diagonal, \
         inflated by pressure {} Pa (inside over outside), StVK with E = {} Pa, nu = {}, t = {} m, \
         no bending, damping {}/s (the default), run {INFLATE_T} s until it settles. For a uniform \
         scale s the membrane energy is A0 t 2 (mu + lambda) e^2 with e = (s^2 - 1)/2 (plane-stress \
         lambda), so the equilibrium solves 2 A0 t (mu + lambda) (s^2 - 1) = 3 |P| V0 s (A0, V0 the \
         mesh's area and volume). Error: |cbrt(V/V0) / s - 1| at t = {INFLATE_T} s. Reference scene: \
         the default contraction (from `softshell_shell_def_default()`: pressure {}, {}, kB = {}, \
         {} bending, damping {}/s, {} iterations, h = 1/{:.0} s) of the same sphere for 1/3 s \
         (20 steps of 1/60 s, before it buckles), collisions off. Reference: 256 substeps and 40 \
         iterations; the row \"reference check\" is its distance to 128 substeps: the runs at 128, \
         256 and 512 substeps differ by about that much and not in order, the f32 positions' floor \
         (doubling the iterations moves the reference about 200x less). Error: RMS vertex \
         distance to the reference at t = 1/3 s, relative to the diagonal (1). The note gives V/V0 at the end.",
        i.pressure,
        i.youngs_modulus,
        i.poisson_ratio,
        i.thickness,
        i.damping,
        d.pressure,
        material_name(d.material),
        d.bending_coefficient,
        bending_name(d.bending),
        d.damping,
        d.iterations,
        1.0 / d.time_step,
    )
}

/// The name of a shell material constant.
pub fn material_name(m: u32) -> &'static str {
    match m {
        SOFTSHELL_MATERIAL_STVK => "StVK",
        SOFTSHELL_MATERIAL_COROTATED => "corotated",
        SOFTSHELL_MATERIAL_LINEAR => "linear",
        SOFTSHELL_MATERIAL_MOONEY_RIVLIN => "Mooney-Rivlin",
        _ => "unknown material",
    }
}

/// The name of a shell bending constant.
pub fn bending_name(b: u32) -> &'static str {
    match b {
        SOFTSHELL_BENDING_NONE => "no",
        SOFTSHELL_BENDING_ISOMETRIC => "isometric (flat rest)",
        SOFTSHELL_BENDING_ISOMETRIC_REST => "isometric-with-rest-curvature",
        _ => "unknown",
    }
}

/// The name of a shell solver constant.
pub fn solver_name(s: u32) -> &'static str {
    match s {
        SOFTSHELL_SOLVER_XPBD => "XPBD",
        SOFTSHELL_SOLVER_PBD => "PBD",
        SOFTSHELL_SOLVER_PBD_DISTANCE => "PBD edge-distance",
        _ => "unknown solver",
    }
}

const SHELL_T: f64 = 20.0 / 60.0;
const INFLATE_T: f64 = 4.0;
const INFLATE_P: f32 = -0.5;

/// Runs a shell for `duration` s: wall seconds of the steps, final positions, final V/V0.
fn shell_run(def: &SoftshellShellDef, duration: f64) -> Result<(f64, Vec<f32>, f64), String> {
    let (p, t) = unit_obj("sphere.obj", 1.0);
    let shell = Shell::new(&p, &t, def).map_err(|f| f.1)?;
    let steps = (duration / def.time_step as f64).round() as usize;
    let start = Instant::now();
    for _ in 0..steps - 1 {
        // SAFETY: live shell; stats not wanted (NULL) to time the step alone.
        let status = unsafe { softshell_shell_step(shell.0, std::ptr::null_mut()) };
        if status != softshell::ffi::SoftshellStatus::Ok {
            return Err(format!("{status:?}: {}", last_error()));
        }
    }
    let stats = shell.step().map_err(|f| format!("{:?}: {}", f.0, f.1))?;
    Ok((start.elapsed().as_secs_f64(), shell.positions(), stats.volume_ratio))
}

fn shell_base() -> SoftshellShellDef {
    SoftshellShellDef { collisions: false, stop_volume_ratio: 0.0, ..softshell_shell_def_default() }
}

fn inflate_base() -> SoftshellShellDef {
    SoftshellShellDef { pressure: INFLATE_P, bending: SOFTSHELL_BENDING_NONE, ..shell_base() }
}

/// The analytic equilibrium scale of the inflated sphere.
fn inflate_scale(def: &SoftshellShellDef) -> f64 {
    let (p, t) = unit_obj("sphere.obj", 1.0);
    let report = Mesh::new(&p, &t).unwrap().report();
    let (e, nu, th) = (def.youngs_modulus as f64, def.poisson_ratio as f64, def.thickness as f64);
    let (mu, lambda) = (e / (2.0 * (1.0 + nu)), e * nu / (1.0 - nu * nu));
    let a = 2.0 * report.area * th * (mu + lambda);
    let b = 3.0 * (def.pressure as f64).abs() * report.volume;
    (b + (b * b + 4.0 * a * a).sqrt()) / (2.0 * a) // a s^2 - b s - a = 0
}

/// The shell's families, each run on the analytic scene and the reference scene.
fn shell_families() -> Vec<(&'static str, String, SoftshellShellDef)> {
    let mut f = Vec::new();
    for it in [1, 2, 5, 10, 20] {
        f.push((
            "iterations",
            format!("{it} iterations"),
            SoftshellShellDef { iterations: it, ..softshell_shell_def_default() },
        ));
    }
    for sub in [1, 2, 4, 8] {
        f.push((
            "substeps",
            format!("{sub} substeps"),
            SoftshellShellDef { substeps: sub, ..softshell_shell_def_default() },
        ));
    }
    for (label, h) in [
        ("1/15", 1.0 / 15.0),
        ("1/30", 1.0 / 30.0),
        ("1/60", 1.0 / 60.0),
        ("1/120", 1.0 / 120.0),
        ("1/240", 1.0 / 240.0),
    ] {
        f.push((
            "time step",
            format!("h = {label} s"),
            SoftshellShellDef { time_step: h, ..softshell_shell_def_default() },
        ));
    }
    for (solver, name) in [
        (SOFTSHELL_SOLVER_XPBD, "XPBD"),
        (SOFTSHELL_SOLVER_PBD, "PBD (paper; another model)"),
        (SOFTSHELL_SOLVER_PBD_DISTANCE, "PBD edge distances (baseline; another model)"),
    ] {
        for it in [5, 20] {
            f.push((
                "solver form",
                format!("{name}, {it} iterations"),
                SoftshellShellDef { solver, iterations: it, ..softshell_shell_def_default() },
            ));
        }
    }
    for threads in [1, 2] {
        f.push((
            "threads (4 substeps)",
            format!("{threads} threads"),
            SoftshellShellDef { threads, substeps: 4, ..softshell_shell_def_default() },
        ));
    }
    f
}

/// Applies a family's solver settings to a scene's def.
fn with_solver(scene: SoftshellShellDef, s: &SoftshellShellDef) -> SoftshellShellDef {
    SoftshellShellDef {
        iterations: s.iterations,
        substeps: s.substeps,
        time_step: s.time_step,
        solver: s.solver,
        threads: s.threads,
        ..scene
    }
}

pub fn shell_runs() -> (Vec<Run>, Vec<Run>) {
    let scale = inflate_scale(&inflate_base());
    let mut analytic = Vec::new();
    let mut referenced = Vec::new();
    // 16 substeps were the reference before a review found it first-order accurate only: the
    // 8-substep row's error was half the reference's own.
    let reference_def = SoftshellShellDef { substeps: 256, iterations: 40, ..shell_base() };
    let (ref_seconds, reference, ref_ratio) = shell_run(&reference_def, SHELL_T).expect("shell reference");
    referenced.push(Run::new(
        "reference",
        "256 substeps x 40 iterations",
        ref_seconds,
        None,
        format!("V/V0 {ref_ratio:.4}"),
    ));
    let coarser = SoftshellShellDef { substeps: 128, ..reference_def };
    let (check_seconds, check, check_ratio) = shell_run(&coarser, SHELL_T).expect("shell reference check");
    referenced.push(reference_check(
        "128 substeps x 40 iterations",
        check_seconds,
        rms_distance(&check, &reference),
        format!("V/V0 {check_ratio:.4}"),
    ));
    for (family, setting, solver) in shell_families() {
        let def = with_solver(inflate_base(), &solver);
        analytic.push(match shell_run(&def, INFLATE_T) {
            Ok((s, _, r)) => Run::new(
                family,
                setting.clone(),
                s,
                Some((r.cbrt() / scale - 1.0).abs()),
                format!("s = {:.5} (analytic {scale:.5})", r.cbrt()),
            ),
            Err(m) => Run::new(family, setting.clone(), 0.0, None, m.chars().take(90).collect::<String>()),
        });
        let def = with_solver(shell_base(), &solver);
        referenced.push(match shell_run(&def, SHELL_T) {
            Ok((s, p, r)) => Run::new(family, setting, s, Some(rms_distance(&p, &reference)), format!("V/V0 {r:.4}")),
            Err(m) => Run::new(family, setting, 0.0, None, m.chars().take(90).collect::<String>()),
        });
    }
    (analytic, referenced)
}

/// The f32 stall: the default contraction with many substeps, V/V0 after 10 steps.
pub fn shell_substep_stall() -> Vec<(u32, f64)> {
    [16u32, 32, 64, 128, 256]
        .iter()
        .map(|&sub| {
            let def = SoftshellShellDef { substeps: sub, ..shell_base() };
            (sub, shell_run(&def, 10.0 / 60.0).map(|r| r.2).unwrap_or(f64::NAN))
        })
        .collect()
}

// ------------------------------------------------------------------------------------------- body

pub const BODY_SPRING_SCENE: &str = "Analytic scene 1: one equilateral triangle (side 0.1 m, an open \
mesh: 3 vertices, 3 springs), K_s = 10 N/m, total mass 0.3 kg (0.1 kg a vertex), no damping, no \
gravity, each vertex given the same outward radial speed. The three springs act as one linear \
spring on the radius r (m r'' = -3 K_s (r - r0), exactly, at any amplitude): \
r(t) = r0 + (v0/w) sin(w t), w = sqrt(9 K_s / M) = 17.3 rad/s. Error: the largest |r - r_exact| \
over 1 s, sampled every step, divided by the amplitude v0/w.";

const TRI_SIDE: f32 = 0.1;
const TRI_K: f32 = 10.0;
const TRI_MASS: f32 = 0.3;

fn triangle() -> (Vec<f32>, Vec<u32>) {
    let r0 = TRI_SIDE / 3f32.sqrt();
    let p = (0..3)
        .flat_map(|k| {
            let a = std::f32::consts::FRAC_PI_2 + k as f32 * std::f32::consts::TAU / 3.0;
            [r0 * a.cos(), r0 * a.sin(), 0.0]
        })
        .collect();
    (p, vec![0, 1, 2])
}

fn mean_radius(p: &[f32]) -> f64 {
    let n = p.len() / 3;
    let c: Vec<f64> = (0..3).map(|k| p.chunks(3).map(|q| q[k] as f64).sum::<f64>() / n as f64).collect();
    p.chunks(3).map(|q| (0..3).map(|k| (q[k] as f64 - c[k]).powi(2)).sum::<f64>().sqrt()).sum::<f64>() / n as f64
}

fn spring_run(def: &SoftshellBodyDef) -> Result<(f64, f64), String> {
    let (p, t) = triangle();
    let body = Body::new(&p, &t, def).map_err(|f| f.1)?;
    let masses = body.masses();
    let r0 = mean_radius(&p);
    let omega = (9.0 * TRI_K as f64 / TRI_MASS as f64).sqrt();
    let v0 = 0.2 * r0 * omega; // amplitude 0.2 r0
    for (i, q) in p.chunks(3).enumerate() {
        let dir = [q[0] as f64 / r0, q[1] as f64 / r0];
        let j = masses[i] as f64 * v0;
        body.impulse(i as u32, [(j * dir[0]) as f32, (j * dir[1]) as f32, 0.0]).map_err(|f| f.1)?;
    }
    let h = def.time_step as f64;
    let steps = (1.0 / h).round() as usize;
    let mut worst = 0.0f64;
    let mut seconds = 0.0;
    for k in 1..=steps {
        let start = Instant::now();
        let s = body.step();
        seconds += start.elapsed().as_secs_f64();
        s.map_err(|f| format!("{:?} at step {k}: {}", f.0, f.1.chars().take(70).collect::<String>()))?;
        let r = mean_radius(&body.positions());
        let exact = r0 + v0 / omega * (omega * k as f64 * h).sin();
        worst = worst.max((r - exact).abs());
    }
    Ok((seconds, worst / (v0 / omega)))
}

fn spring_base(integrator: u32) -> SoftshellBodyDef {
    SoftshellBodyDef {
        integrator,
        spring_stiffness: TRI_K,
        total_mass: TRI_MASS,
        spring_damping: 0.0,
        gravity: [0.0; 3],
        ..softshell_body_def_default()
    }
}

/// The row that says how far the reference itself is from converged: its distance to the same
/// scene refined or coarsened once (family \"reference check\", not a curve of the plots).
fn reference_check(setting: &str, seconds: f64, distance: f64, note: impl Into<String>) -> Run {
    Run::new("reference check", setting, seconds, Some(distance), note)
}

fn record(runs: &mut Vec<Run>, family: &str, setting: String, result: Result<(f64, f64), String>, note: &str) {
    runs.push(match result {
        Ok((s, e)) => Run::new(family, setting, s, Some(e), note),
        Err(m) => Run::new(family, setting, 0.0, None, m),
    });
}

const INTEGRATORS: [(u32, &str); 4] = [
    (SOFTSHELL_INTEGRATOR_EXPLICIT_EULER, "explicit Euler"),
    (SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER, "symplectic Euler"),
    (SOFTSHELL_INTEGRATOR_IMPLICIT_EULER, "implicit Euler"),
    (SOFTSHELL_INTEGRATOR_XPBD, "XPBD"),
];

const STEPS: [(&str, f32); 5] = [
    ("1/30", 1.0 / 30.0),
    ("1/60", 1.0 / 60.0),
    ("1/120", 1.0 / 120.0),
    ("1/240", 1.0 / 240.0),
    ("1/480", 1.0 / 480.0),
];

pub fn body_spring_runs() -> Vec<Run> {
    let mut runs = Vec::new();
    for (integrator, name) in INTEGRATORS {
        record(&mut runs, "integrator (h = 1/60)", name.into(), spring_run(&spring_base(integrator)), "");
    }
    for (integrator, name) in
        [(SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER, "symplectic"), (SOFTSHELL_INTEGRATOR_IMPLICIT_EULER, "implicit")]
    {
        for (label, h) in STEPS {
            let def = SoftshellBodyDef { time_step: h, ..spring_base(integrator) };
            record(&mut runs, &format!("time step, {name} Euler"), format!("h = {label} s"), spring_run(&def), "");
        }
    }
    for sub in [1, 2, 4, 8, 16, 32] {
        let def = SoftshellBodyDef { substeps: sub, ..spring_base(SOFTSHELL_INTEGRATOR_XPBD) };
        record(&mut runs, "substeps, XPBD", format!("{sub} substeps"), spring_run(&def), "");
    }
    for it in [1, 2, 5, 10, 20] {
        let def = SoftshellBodyDef { iterations: it, ..spring_base(SOFTSHELL_INTEGRATOR_XPBD) };
        record(&mut runs, "iterations, XPBD", format!("{it} iterations"), spring_run(&def), "");
    }
    runs
}

/// Scene 2's description; K_s and the mass are the library defaults, read from
/// `softshell_body_def_default()`.
pub fn body_gas_scene() -> String {
    let d = gas_base(SOFTSHELL_INTEGRATOR_XPBD);
    format!(
        "Analytic scene 2: data/sphere.obj (482 vertices, 1440 springs) scaled to a unit diagonal, gas \
         nRT = {} J, K_s = {} N/m (default), K_d = {} N s/m, {} kg (default), no gravity, run 3 s \
         from rest until it settles. For a uniform scale s of the rest shape, spring energy \
         K_s/2 (s-1)^2 sum L0^2 and gas energy -nRT ln V are stationary at K_s (s - 1) s sum L0^2 = \
         3 nRT: the analytic equilibrium radius s R0 (exact for uniform scaling; the polyhedron's \
         residual non-uniformity is part of the floor). Error: |mean radius / (s R0) - 1| at t = 3 s.",
        d.gas_amount, d.spring_stiffness, d.spring_damping, d.total_mass
    )
}

fn sphere_springs_sum_sq(p: &[f32], t: &[u32]) -> f64 {
    let mut edges: Vec<(u32, u32)> =
        t.chunks(3).flat_map(|f| (0..3).map(move |k| (f[k].min(f[(k + 1) % 3]), f[k].max(f[(k + 1) % 3])))).collect();
    edges.sort();
    edges.dedup();
    edges
        .iter()
        .map(|&(a, b)| {
            (0..3).map(|k| (p[3 * a as usize + k] as f64 - p[3 * b as usize + k] as f64).powi(2)).sum::<f64>()
        })
        .sum()
}

fn gas_base(integrator: u32) -> SoftshellBodyDef {
    SoftshellBodyDef {
        integrator,
        gas_amount: 1.0,
        spring_damping: 5.0,
        gravity: [0.0; 3],
        ..softshell_body_def_default()
    }
}

fn gas_run(def: &SoftshellBodyDef) -> Result<(f64, f64), String> {
    let (p, t) = unit_obj("sphere.obj", 1.0);
    let sum = sphere_springs_sum_sq(&p, &t);
    let c = 3.0 * def.gas_amount as f64 / (def.spring_stiffness as f64 * sum);
    let s = 0.5 + (0.25 + c).sqrt(); // s^2 - s - c = 0
    let target = s * mean_radius(&p);
    let body = Body::new(&p, &t, def).map_err(|f| f.1)?;
    let steps = (3.0 / def.time_step as f64).round() as usize;
    let start = Instant::now();
    for k in 0..steps {
        // (Steps counted from 1, as the failure messages count them.)
        body.step()
            .map_err(|f| format!("{:?} at step {}: {}", f.0, k + 1, f.1.chars().take(70).collect::<String>()))?;
    }
    let seconds = start.elapsed().as_secs_f64();
    let p = body.positions();
    if max_abs(&p) > 100.0 {
        return Err(format!("blew up (max |x| = {:.1e} m) while every step returned OK", max_abs(&p)));
    }
    Ok((seconds, (mean_radius(&p) / target - 1.0).abs()))
}

pub fn body_gas_runs() -> Vec<Run> {
    let mut runs = Vec::new();
    for (integrator, name) in INTEGRATORS {
        record(&mut runs, "integrator (h = 1/60)", name.into(), gas_run(&gas_base(integrator)), "");
    }
    for sub in [1, 4, 16] {
        let def = SoftshellBodyDef { substeps: sub, ..gas_base(SOFTSHELL_INTEGRATOR_XPBD) };
        record(&mut runs, "substeps, XPBD", format!("{sub} substeps"), gas_run(&def), "");
    }
    for sub in [64, 256] {
        let def = SoftshellBodyDef { substeps: sub, ..gas_base(SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER) };
        record(&mut runs, "substeps, symplectic Euler", format!("{sub} substeps"), gas_run(&def), "");
    }
    runs
}

/// The reference scene's description (defaults read from `softshell_body_def_default()`).
pub fn body_ref_scene() -> String {
    let d = SoftshellBodyDef { spring_damping: 1.0, ..gas_base(SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER) };
    format!(
        "Reference scene: the same gas sphere (nRT = {} J, K_s = {} N/m, K_d = {} N s/m, {} kg, no \
         gravity) inflating from rest for 0.5 s, with an impulse on vertex 0 at the start. Reference: \
         symplectic Euler at h = 1/{:.0} s with 256 substeps (step {:.1e} s); the row \"reference \
         check\" is the larger of its distances to 512 and to 1,024 substeps (the second at a \
         quarter of the step with 256), which do not shrink with more substeps (the f32 \
         positions' rounding): errors below it are not resolved. Error: RMS vertex distance to the \
         reference at t = 0.5 s / diagonal.",
        d.gas_amount,
        d.spring_stiffness,
        d.spring_damping,
        d.total_mass,
        1.0 / d.time_step,
        d.time_step / 256.0
    )
}

fn reference_run(def: &SoftshellBodyDef) -> Result<(f64, Vec<f32>), String> {
    let (p, t) = unit_obj("sphere.obj", 1.0);
    let body = Body::new(&p, &t, def).map_err(|f| f.1)?;
    body.impulse(0, [0.0, 0.002, 0.0]).map_err(|f| f.1)?;
    let steps = (0.5 / def.time_step as f64).round() as usize;
    let start = Instant::now();
    for k in 0..steps {
        // (Steps counted from 1, as the failure messages count them.)
        body.step()
            .map_err(|f| format!("{:?} at step {}: {}", f.0, k + 1, f.1.chars().take(70).collect::<String>()))?;
    }
    let seconds = start.elapsed().as_secs_f64();
    let p = body.positions();
    if max_abs(&p) > 100.0 {
        return Err(format!("blew up (max |x| = {:.1e} m) while every step returned OK", max_abs(&p)));
    }
    Ok((seconds, p))
}

pub fn body_reference_runs() -> Vec<Run> {
    let base = |integrator| SoftshellBodyDef { spring_damping: 1.0, ..gas_base(integrator) };
    let reference_def = SoftshellBodyDef { substeps: 256, ..base(SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER) };
    let (ref_seconds, reference) = reference_run(&reference_def).expect("body reference");
    let mut runs = vec![Run::new("reference", "symplectic Euler, 256 substeps", ref_seconds, None, "")];
    // Two refinements (one alone put the reference's error at a third of what the second
    // shows: a review).
    let finer = SoftshellBodyDef { substeps: 512, ..reference_def };
    let (check_seconds, check) = reference_run(&finer).expect("body reference check");
    let finest = SoftshellBodyDef { substeps: 256, time_step: reference_def.time_step / 4.0, ..reference_def };
    let (finest_seconds, finest_check) = reference_run(&finest).expect("body reference check");
    let (d512, d1024) = (rms_distance(&check, &reference), rms_distance(&finest_check, &reference));
    runs.push(reference_check(
        "symplectic Euler, 512 and 1,024 substeps (the larger distance)",
        check_seconds + finest_seconds,
        d512.max(d1024),
        format!(
            "512 substeps {d512:.2e}, 1,024 {d1024:.2e}: refined, it moves away (the f32 state's rounding, not \
             the step)"
        ),
    ));
    let mut go = |family: &str, setting: String, def: SoftshellBodyDef| {
        let result = reference_run(&def).map(|(s, p)| (s, rms_distance(&p, &reference)));
        record(&mut runs, family, setting, result, "");
    };
    for (integrator, name) in INTEGRATORS {
        go("integrator (h = 1/60)", name.into(), base(integrator));
    }
    for (label, h) in STEPS {
        go(
            "time step, implicit Euler",
            format!("h = {label} s"),
            SoftshellBodyDef { time_step: h, ..base(SOFTSHELL_INTEGRATOR_IMPLICIT_EULER) },
        );
    }
    // (No iterations family for implicit Euler: its conjugate gradients stop at their
    // tolerance, and the cap of 10 x iterations (at least 40) never binds here: every cap gave
    // the same iterations and the same error.)
    for sub in [1, 4, 16, 64] {
        go(
            "substeps, XPBD",
            format!("{sub} substeps"),
            SoftshellBodyDef { substeps: sub, ..base(SOFTSHELL_INTEGRATOR_XPBD) },
        );
    }
    for it in [1, 5, 20, 50] {
        go(
            "iterations, XPBD (4 substeps)",
            format!("{it}"),
            SoftshellBodyDef { iterations: it, substeps: 4, ..base(SOFTSHELL_INTEGRATOR_XPBD) },
        );
    }
    for sub in [32, 64, 128] {
        go(
            "substeps, symplectic Euler",
            format!("{sub} substeps"),
            SoftshellBodyDef { substeps: sub, ..base(SOFTSHELL_INTEGRATOR_SYMPLECTIC_EULER) },
        );
    }
    for threads in [1, 2] {
        go(
            "threads (implicit Euler)",
            format!("{threads} threads"),
            SoftshellBodyDef { threads, ..base(SOFTSHELL_INTEGRATOR_IMPLICIT_EULER) },
        );
    }
    runs
}

// ---------------------------------------------------------------------------------------- lattice

pub const LATTICE_SCENE: &str = "Analytic scene: a 24 x 16 sheet (spacing 0.05 m), no gravity, \
rotated rigidly by 1.9 rad about (1, 2, -0.5) and shifted (`softshell_lattice_set_positions`), then \
stepped for 1 s: shape matching must leave a rigid motion exactly where it is. Reference scene: a \
32 x 32 sheet pinned along row 0, sagging under gravity for 0.5 s, w = 2, no region damping, \
velocity damping 0.5/s. FastLSM's alpha pulls a fixed fraction of the way to the goal per step, so \
the material's stiffness is alpha m / h^2: the time-step family keeps alpha / h^2 fixed \
(alpha = 0.5 at h = 1/60) so that every run models the same sheet. Reference: h = 1/30720 s \
(alpha = 1.9e-6); the row \"reference check\" is its distance to h = 1/15360 s, its own error to \
first order. FastLSM has no iterations, substeps or solver forms to vary.";

fn rotate(p: [f64; 3]) -> [f64; 3] {
    let a = [1.0f64, 2.0, -0.5];
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    let axis = a.map(|v| v / n);
    let (s, c) = 1.9f64.sin_cos();
    let d = axis[0] * p[0] + axis[1] * p[1] + axis[2] * p[2];
    let cross = [axis[1] * p[2] - axis[2] * p[1], axis[2] * p[0] - axis[0] * p[2], axis[0] * p[1] - axis[1] * p[0]];
    [0, 1, 2].map(|k| p[k] * c + cross[k] * s + axis[k] * d * (1.0 - c) + [0.5, -1.0, 2.0][k])
}

pub fn lattice_rigid_runs() -> Vec<Run> {
    let mut runs = Vec::new();
    for w in [1u32, 2, 4] {
        for (label, h) in [("1/30", 1.0f32 / 30.0), ("1/60", 1.0 / 60.0), ("1/240", 1.0 / 240.0)] {
            let def = SoftshellLatticeDef {
                columns: 24,
                rows: 16,
                region_half_width: w,
                gravity: [0.0; 3],
                time_step: h,
                ..softshell_lattice_def_default()
            };
            let lattice = Lattice::new(&def).unwrap();
            let moved: Vec<f32> = lattice_rest(24, 16, def.spacing)
                .chunks(3)
                .flat_map(|p| rotate([p[0] as f64, p[1] as f64, p[2] as f64]).map(|v| v as f32))
                .collect();
            lattice.set_positions(&moved).unwrap();
            let steps = (1.0 / h).round() as usize;
            let start = Instant::now();
            for _ in 0..steps {
                lattice.step().unwrap();
            }
            let seconds = start.elapsed().as_secs_f64();
            let err = lattice.positions().iter().zip(&moved).map(|(a, b)| (a - b).abs() as f64).fold(0.0, f64::max);
            runs.push(Run::new(&format!("w = {w}"), format!("h = {label} s"), seconds, Some(err), ""));
        }
    }
    runs
}

fn sag_run(h: f64, threads: u32) -> (f64, Vec<f32>) {
    let alpha = 0.5 * (h * 60.0).powi(2);
    let def = SoftshellLatticeDef {
        columns: 32,
        rows: 32,
        time_step: h as f32,
        stiffness: alpha as f32,
        damping: 0.0,
        velocity_damping: 0.5,
        threads,
        ..softshell_lattice_def_default()
    };
    let lattice = Lattice::new(&def).unwrap();
    for c in 0..32 {
        lattice.pin(c, 0).unwrap();
    }
    let steps = (0.5 / h).round() as usize;
    let start = Instant::now();
    for _ in 0..steps {
        lattice.step().unwrap();
    }
    (start.elapsed().as_secs_f64(), lattice.positions())
}

pub fn lattice_reference_runs() -> Vec<Run> {
    // h = 1/1920 s was the reference before a review found it moved 9.5e-4 m when refined, as
    // much as the 1/960 row's error.
    let (ref_seconds, reference) = sag_run(1.0 / 30720.0, 1);
    let mut runs = vec![Run::new("reference", "h = 1/30720 s", ref_seconds, None, "")];
    let (check_seconds, check) = sag_run(1.0 / 15360.0, 1);
    runs.push(reference_check("h = 1/15360 s", check_seconds, rms_distance(&check, &reference), ""));
    for (label, h) in [
        ("1/60", 1.0 / 60.0),
        ("1/120", 1.0 / 120.0),
        ("1/240", 1.0 / 240.0),
        ("1/480", 1.0 / 480.0),
        ("1/960", 1.0 / 960.0),
    ] {
        let (s, p) = sag_run(h, 1);
        runs.push(Run::new(
            "time step (alpha/h^2 fixed)",
            format!("h = {label} s"),
            s,
            Some(rms_distance(&p, &reference)),
            "",
        ));
    }
    for threads in [1, 2] {
        let (s, p) = sag_run(1.0 / 240.0, threads);
        runs.push(Run::new(
            "threads (h = 1/240)",
            format!("{threads} threads"),
            s,
            Some(rms_distance(&p, &reference)),
            "",
        ));
    }
    runs
}
