//! The trends of the paper's experiments (SPEC 1.8), through the C ABI only: bending
//! coefficient, anisotropic regions, materials, energy versus edge-distance constraints, and
//! the initial scale.
#![cfg(feature = "shell")]

use std::ffi::CStr;
use std::ptr::null_mut;

use softshell::ffi::boundary::SoftshellStatus;
use softshell::ffi::mesh::*;
use softshell::ffi::shell::*;
use softshell::ffi::version::softshell_last_error;

mod report_util;

fn last_error() -> String {
    // SAFETY: the library keeps the message alive until the next call on this thread.
    unsafe { CStr::from_ptr(softshell_last_error()) }.to_string_lossy().into_owned()
}

struct Mesh {
    handle: *mut SoftshellMesh,
    positions: Vec<f32>,
    triangles: Vec<u32>,
}
impl Drop for Mesh {
    fn drop(&mut self) {
        // SAFETY: made by the library, freed once.
        unsafe { softshell_mesh_free(self.handle) }
    }
}

struct Shell(*mut SoftshellShell);
impl Drop for Shell {
    fn drop(&mut self) {
        // SAFETY: made by the library, freed once.
        unsafe { softshell_shell_free(self.0) }
    }
}

/// An OBJ of data/ scaled about its centre to a bounding-box diagonal of `scale`.
fn unit_mesh(name: &str, scale: f32) -> Mesh {
    let (pos, tri) = report_util::unit_obj(name, scale);
    let mut handle = null_mut();
    // SAFETY: live slices with their lengths.
    let status =
        unsafe { softshell_mesh_from_arrays(pos.as_ptr(), pos.len() / 3, tri.as_ptr(), tri.len() / 3, &mut handle) };
    assert_eq!(status, SoftshellStatus::Ok);
    Mesh { handle, positions: pos, triangles: tri }
}

fn new_shell(mesh: &Mesh, def: &SoftshellShellDef) -> Shell {
    let mut s = null_mut();
    // SAFETY: live mesh and def.
    let status = unsafe { softshell_shell_new(mesh.handle, def, &mut s) };
    assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
    Shell(s)
}

fn step(shell: &Shell) -> SoftshellShellStats {
    let mut stats = SoftshellShellStats::default();
    // SAFETY: live shell, writable stats.
    let status = unsafe { softshell_shell_step(shell.0, &mut stats) };
    assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
    stats
}

/// Volume ratios of `steps` steps.
fn run(shell: &Shell, steps: usize) -> Vec<f64> {
    (0..steps).map(|_| step(shell).volume_ratio).collect()
}

fn def() -> SoftshellShellDef {
    let mut d = softshell_shell_def_default();
    d.stop_volume_ratio = 0.0;
    d
}

/// Number of times the volume ratio turns from falling to rising or back (by more than `tol`).
fn turns(ratios: &[f64], tol: f64) -> usize {
    let mut last = 0i32;
    let mut count = 0;
    for w in ratios.windows(2) {
        let d = w[1] - w[0];
        let sign = if d > tol {
            1
        } else if d < -tol {
            -1
        } else {
            0
        };
        if sign != 0 {
            if last != 0 && sign != last {
                count += 1;
            }
            last = sign;
        }
    }
    count
}

#[test]
fn stiff_bending_resists_contraction_and_weak_bending_falls_monotonically() {
    // The eight (genus 2) buckles at once, like the paper's models; a perfect sphere first
    // rebounds elastically from the sudden load before it buckles.
    let mesh = unit_mesh("eight.obj", 1.0);
    let mut stiff = def();
    stiff.bending_coefficient = 1.0;
    let stiff_r = run(&new_shell(&mesh, &stiff), 150);
    let weak_r = run(&new_shell(&mesh, &def()), 150);
    println!("XPBD r(150): kB=1 {:.4}  kB=1e-2 {:.4}", stiff_r[149], weak_r[149]);
    assert!(stiff_r[149] > weak_r[149] + 0.05, "kB = 1 must contract less than kB = 1e-2");

    // The paper's form: PBD energy constraints with its flat-rest isometric bending.
    let mut paper = def();
    paper.solver = SOFTSHELL_SOLVER_PBD;
    // The PBD form ignores Young's modulus and is as stiff as its iterations make it: it needs
    // more pressure to contract the same shell.
    paper.pressure = 1.0;
    // ... and the paper damps little (SPEC 1.1: "optionally damped").
    paper.damping = 1.0;
    paper.bending = SOFTSHELL_BENDING_ISOMETRIC;
    let weak_pbd = run(&new_shell(&mesh, &paper), 150);
    paper.bending_coefficient = 1.0;
    let stiff_pbd = run(&new_shell(&mesh, &paper), 150);
    println!(
        "PBD r(150): kB=1 {:.4} ({} turns)  kB=1e-2 {:.4} ({} turns)",
        stiff_pbd[149],
        turns(&stiff_pbd, 1e-4),
        weak_pbd[149],
        turns(&weak_pbd, 1e-4)
    );
    assert!(stiff_pbd[149] > weak_pbd[149], "PBD: kB = 1 must contract less than kB = 1e-2");
    assert!(turns(&stiff_pbd, 1e-4) >= 2, "PBD with kB = 1: the volume ratio oscillates (paper Fig. 8)");
    // Monotone while the shell contracts: before it has lost 80% of its volume and, without the
    // collision stage, starts to fold through itself, and up to its smallest volume (with the
    // collision stage the folds meet there and the contacts push back a little).
    let lowest = (0..weak_pbd.len()).min_by(|&a, &b| weak_pbd[a].total_cmp(&weak_pbd[b])).unwrap();
    let rebound = weak_pbd[lowest..].iter().copied().fold(f64::MIN, f64::max) - weak_pbd[lowest];
    assert!(rebound < 0.01 * weak_pbd[lowest], "PBD kB=1e-2: the volume rebounds by {rebound} after its minimum");
    let contracting: Vec<f64> = weak_pbd[..=lowest].iter().copied().take_while(|&r| r > 0.2).collect();
    println!("PBD kB=1e-2: {} steps above 0.2, {} turns", contracting.len(), turns(&contracting, 1e-4));

    assert!(contracting.len() > 50);
    assert!(
        contracting.windows(2).all(|w| w[1] <= w[0] + 1e-4),
        "PBD with kB = 1e-2 falls monotonically: {contracting:?}"
    );
    let weak_contracting: Vec<f64> = weak_r.iter().copied().take_while(|&r| r > 0.2).collect();
    assert!(weak_contracting.windows(2).all(|w| w[1] <= w[0] + 1e-3), "XPBD kB = 1e-2: {weak_contracting:?}");
}

#[test]
fn bending_1e_3_is_close_to_no_bending() {
    // Paper Fig. 16/17: kB = 1e-3 behaves like kB = 0.
    let mesh = unit_mesh("eight.obj", 1.0);
    let mut tiny = def();
    tiny.bending_coefficient = 1e-3;
    let mut none = def();
    none.bending = SOFTSHELL_BENDING_NONE;
    let (a, b) = (run(&new_shell(&mesh, &tiny), 60)[59], run(&new_shell(&mesh, &none), 60)[59]);
    let c = run(&new_shell(&mesh, &def()), 60)[59];
    println!("r(60): kB=1e-3 {a:.4}, no bending {b:.4}, kB=1e-2 {c:.4}");
    // Measured 0.43, 0.36 and 0.75: kB = 1e-3 sits much nearer to no bending than to 1e-2.
    assert!((a - b).abs() < 0.25 * (c - b).abs(), "kB = 1e-3 {a}, none {b}, kB = 1e-2 {c}");
}

/// Faces whose centre lies within `radius` of the vertex farthest along +x.
fn cap_faces(mesh: &Mesh, radius: f32) -> Vec<u32> {
    let p = |v: u32| [0, 1, 2].map(|k| mesh.positions[3 * v as usize + k]);
    let tip = (0..mesh.positions.len() as u32 / 3).max_by(|&a, &b| p(a)[0].total_cmp(&p(b)[0])).unwrap();
    let tip = p(tip);
    (0..mesh.triangles.len() as u32 / 3)
        .filter(|&f| {
            let c = (0..3).fold([0.0f32; 3], |acc, k| {
                let q = p(mesh.triangles[3 * f as usize + k]);
                [acc[0] + q[0] / 3.0, acc[1] + q[1] / 3.0, acc[2] + q[2] / 3.0]
            });
            (0..3).map(|k| (c[k] - tip[k]).powi(2)).sum::<f32>().sqrt() < radius
        })
        .collect()
}

#[test]
fn every_anisotropic_energy_makes_the_volume_fall_faster() {
    let mesh = unit_mesh("sphere.obj", 1.0);
    let faces = cap_faces(&mesh, 0.25);
    assert!(faces.len() > 50, "{}", faces.len());
    let steps = 60;
    let plain = run(&new_shell(&mesh, &def()), steps);
    for (name, energy) in
        [("ARAP", SOFTSHELL_ANISOTROPY_ARAP), ("StVK", SOFTSHELL_ANISOTROPY_STVK), ("Sqrt", SOFTSHELL_ANISOTROPY_SQRT)]
    {
        for target in [1.0f32, 0.8] {
            let shell = new_shell(&mesh, &def());
            let mut a = softshell_anisotropy_def_default();
            a.energy = energy;
            a.target_stretch = target;
            // SAFETY: live shell, slice and def.
            let status = unsafe { softshell_shell_add_anisotropic_region(shell.0, faces.as_ptr(), faces.len(), &a) };
            assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
            let r = run(&shell, steps);
            let last = step(&shell);
            println!(
                "{name} L={target}: r({steps}) {:.4} vs {:.4} without; E_aniso {:.3e}",
                r[steps - 1],
                plain[steps - 1],
                last.anisotropic_energy
            );
            assert!(r[steps - 1] < plain[steps - 1] - 0.01, "{name} L={target} must make the volume fall faster");
            assert!(last.anisotropic_energy > 0.0);
        }
    }
}

#[test]
fn all_materials_contract_stably() {
    let mesh = unit_mesh("sphere.obj", 1.0);
    for (name, material) in [
        ("StVK", SOFTSHELL_MATERIAL_STVK),
        ("corotated", SOFTSHELL_MATERIAL_COROTATED),
        ("linear", SOFTSHELL_MATERIAL_LINEAR),
        ("neo-Hookean", SOFTSHELL_MATERIAL_NEO_HOOKEAN),
        ("Mooney-Rivlin", SOFTSHELL_MATERIAL_MOONEY_RIVLIN),
    ] {
        for solver in [SOFTSHELL_SOLVER_XPBD, SOFTSHELL_SOLVER_PBD] {
            let mut d = def();
            d.material = material;
            d.solver = solver;
            if solver == SOFTSHELL_SOLVER_PBD {
                d.pressure = 2.0;
            }
            let shell = new_shell(&mesh, &d);
            let r = run(&shell, 100);
            let s = step(&shell);
            println!(
                "{name} solver {solver}: r(100) {:.4}, residual {:.3e}, turns {}",
                r[99],
                s.residual,
                turns(&r, 1e-3)
            );
            assert!(r.iter().all(|v| v.is_finite()));
            // The linear material resists the rotations of buckling (it is not rotation
            // invariant), so it contracts least.
            assert!(r[99] < 0.98, "{name} must contract");
            assert!(r[99] > 0.0, "{name} must not collapse through itself in 100 steps");
        }
    }
}

#[test]
fn energy_constraints_over_stretch_less_than_edge_distance_constraints() {
    // Distance constraints only keep edge lengths: a triangle may shear and its area may grow or
    // shrink freely. The energy constraints keep the whole strain. Compare, after 100 steps of
    // the paper's setting (PBD, little damping), the largest area stretch of a triangle and the
    // number of triangles stretched by more than 1%.
    // Measured: on the sphere the energy constraints never grow a triangle's area while the
    // distance constraints do (slightly); on the eight, which folds through itself without the
    // collision stage, both stretch triangles by 13-26% and the trend is not clear.
    let mesh = unit_mesh("sphere.obj", 1.0);
    let area = |pos: &[f32], t: usize| {
        let v = |k: usize| {
            let i = mesh.triangles[3 * t + k] as usize;
            glam::Vec3::new(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2])
        };
        0.5 * (v(1) - v(0)).cross(v(2) - v(0)).length()
    };
    let stretch = |solver: u32| {
        let mut d = def();
        d.solver = solver;
        d.damping = 1.0;
        let shell = new_shell(&mesh, &d);
        run(&shell, 100);
        let n = mesh.positions.len();
        let mut pos = vec![0.0f32; n];
        let mut len = 0;
        // SAFETY: live shell and buffer.
        unsafe { softshell_shell_copy_positions(shell.0, pos.as_mut_ptr(), n, &mut len) };
        let ratios: Vec<f32> =
            (0..mesh.triangles.len() / 3).map(|t| area(&pos, t) / area(&mesh.positions, t)).collect();
        (ratios.iter().cloned().fold(0.0f32, f32::max), ratios.iter().filter(|&&r| r > 1.01).count())
    };
    let energy = stretch(SOFTSHELL_SOLVER_PBD);
    let distance = stretch(SOFTSHELL_SOLVER_PBD_DISTANCE);
    println!(
        "after 100 steps (largest area stretch, triangles stretched > 1%): energy {energy:?}, edge distance {distance:?}"
    );
    assert!(energy.0 < distance.0, "energy constraints must over-stretch less");
    assert!(energy.0 <= 1.0, "the energy constraints keep every triangle from growing");
    assert!(energy.1 <= distance.1);
}

#[test]
fn volume_ratio_after_100_steps_hardly_depends_on_initial_scale() {
    // V0, V0/4, V0/16: linear scales 1, 4^(-1/3), 16^(-1/3).
    //
    // With fixed absolute settings (Pa, m, kg/m^3) a smaller shell is relatively stiffer against
    // the same pressure but its motion is faster, so the ratio need not be the same: asserted
    // loosely below. A similar shell (positions x s, masses x s^2) moves the same way in the same
    // time steps when every acceleration scales like s: the membrane's (E t s / (rho t s^2)) needs
    // E x s^2 and the pressure's (P s^2 / (rho t s^2)) needs P x s. That checks that no absolute
    // length or tolerance hides in the solver.
    let scales = [1.0f32, 0.25f32.cbrt(), 0.0625f32.cbrt()];
    let absolute: Vec<f64> =
        scales.iter().map(|&s| run(&new_shell(&unit_mesh("sphere.obj", s), &def()), 100)[99]).collect();
    println!("r(100) at V0, V0/4, V0/16 with the default def unchanged: {absolute:?}");
    // With the defaults the two effects nearly cancel between V0 and V0/16 (smaller shells are
    // relatively stiffer, but buckle sooner): measured 0.73, 0.70, 0.76.
    let spread = absolute.iter().cloned().fold(f64::MIN, f64::max) - absolute.iter().cloned().fold(f64::MAX, f64::min);
    assert!(spread < 0.1, "default def: spread {spread}");
    let similar: Vec<f64> = scales
        .iter()
        .map(|&s| {
            let mut d = def();
            // Membrane force per mass ~ E t s / (rho t s^2), pressure per mass ~ P s^2 / (rho t s^2):
            // both must scale like the positions (s) for the same motion in the same time steps.
            d.pressure *= s;
            d.youngs_modulus *= s * s;
            run(&new_shell(&unit_mesh("sphere.obj", s), &d), 100)[99]
        })
        .collect();
    println!("r(100) at V0, V0/4, V0/16 for similar shells: {similar:?}");
    let spread_similar =
        similar.iter().cloned().fold(f64::MIN, f64::max) - similar.iter().cloned().fold(f64::MAX, f64::min);
    assert!(spread_similar < 0.02, "similar shells: spread {spread_similar}");
}
