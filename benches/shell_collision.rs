//! The shell's collision stage in the spirit of the paper's Table 2 (SPEC 1.6, 1.8): on the five
//! shared meshes scaled to a unit diagonal, with the default settings (one thread), per step:
//! the exact tests a brute-force method would need (every vertex-face and edge-edge pair), the
//! candidates (pairs whose swept boxes meet, from the BVH pairs cached across steps), after the
//! swept-hull filter, after the non-penetration filter (= exact CCD tests run: the inclusion
//! search, or the sampled distance for a certain contact), the contacts, and the collision
//! stage's share of the step time. The first table runs the default scene: every default
//! setting, until its stop (volume ratio below 0.3), at most 400 steps.
//! A second table squeezes each mesh with 30 times the default pressure (contacts appear), 60
//! steps without the stop.
//! Run with `cargo bench --bench shell_collision` (`SHELL_COLLISION_STEPS=n` caps both tables at n
//! steps; `SHELL_COLLISION_SQUEEZE=0` skips the squeezed table; `SHELL_COLLISION_MESHES=eight,bear`
//! runs only those meshes). Goal (issue 4): collision stage at most 50% of
//! the step on the kitten at default settings.
//!
//! Uses the Rust API (not the C ABI) for the per-filter counts and the stage's own time.

use std::path::Path;

use softshell::ffi::shell::softshell_shell_def_default;
use softshell::material::Material;
use softshell::mesh::{Topology, TriMesh, bounding_box, load_obj};
use softshell::shell::{BendingKind, Shell, ShellSettings, SolverKind};

fn unit_mesh(name: &str) -> (TriMesh, Topology) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("data").join(name);
    let mesh = load_obj(&path).expect("mesh loads");
    let b = bounding_box(mesh.positions());
    let (centre, diag) = ((b.min + b.max) * 0.5, b.diagonal());
    let positions = mesh.positions().iter().map(|&p| (p - centre) / diag).collect();
    let mesh = TriMesh::new(positions, mesh.triangles().to_vec()).expect("scaled mesh");
    let topo = Topology::build(mesh.triangles(), mesh.vertex_count());
    (mesh, topo)
}

fn default_settings() -> ShellSettings {
    let d = softshell_shell_def_default();
    ShellSettings {
        time_step: d.time_step,
        substeps: d.substeps,
        iterations: d.iterations,
        solver: SolverKind::Xpbd,
        pressure: d.pressure,
        material: Material::StVK,
        youngs_modulus: d.youngs_modulus,
        poisson_ratio: d.poisson_ratio,
        thickness: d.thickness,
        density: d.density,
        bending: BendingKind::IsometricRest,
        bending_coefficient: d.bending_coefficient,
        damping: d.damping,
        stop_volume_ratio: d.stop_volume_ratio,
        collisions: d.collisions,
        collision_thickness: d.collision_thickness,
        threads: 1,
    }
}

struct Row {
    brute: f64,
    candidates: f64,
    after_boxes: f64,
    tests: f64,
    contacts: f64,
    reverted: u64,
    collision_ms: f64,
    step_ms: f64,
    ratio: f64,
    steps: usize,
}

fn run(name: &str, pressure_factor: f32, steps: usize) -> Row {
    let (mesh, topo) = unit_mesh(name);
    let mut settings = default_settings();
    settings.pressure *= pressure_factor;
    if pressure_factor != 1.0 {
        settings.stop_volume_ratio = 0.0; // squeezed: run every step
    }
    let mut shell = Shell::new(&mesh, &topo, settings).expect("shell");
    let (v, e, f) = (mesh.vertex_count() as f64, topo.edges.len() as f64, mesh.triangle_count() as f64);
    let brute = v * f + e * (e - 1.0) / 2.0;
    let mut row = Row {
        brute,
        candidates: 0.0,
        after_boxes: 0.0,
        tests: 0.0,
        contacts: 0.0,
        reverted: 0,
        collision_ms: 0.0,
        step_ms: 0.0,
        ratio: 1.0,
        steps: 0,
    };
    let mut taken = 0;
    for _ in 0..steps {
        let stats = match shell.step(false) {
            Ok(s) => s,
            Err(e) => {
                println!("  {name}: step {} failed: {e}", taken + 1);
                break;
            }
        };
        let c = shell.collision_report();
        row.candidates += c.counts.candidates as f64;
        row.after_boxes += c.counts.after_boxes as f64;
        row.tests += c.counts.ccd_tests as f64;
        row.contacts += c.counts.contacts as f64;
        row.reverted += c.counts.reverted;
        row.collision_ms += c.seconds * 1e3;
        row.step_ms += stats.step_seconds * 1e3;
        row.ratio = stats.volume_ratio;
        taken += 1;
        if stats.finished {
            break;
        }
    }
    let n = taken.max(1) as f64;
    row.candidates /= n;
    row.after_boxes /= n;
    row.tests /= n;
    row.contacts /= n;
    row.collision_ms /= n;
    row.step_ms /= n;
    row.steps = taken;
    row
}

fn table(title: &str, pressure_factor: f32, steps: usize) {
    println!("\n{title} ({steps} steps, means per step)\n");
    println!(
        "| mesh | steps | brute-force tests | BVH candidates | after swept boxes | exact tests (after plane filter) | \
         contacts | fail-safe reverts (total) | collision ms | step ms | collision share | V/V0 |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    // SHELL_COLLISION_MESHES=eight,hand runs only the meshes whose names start with those.
    let only = std::env::var("SHELL_COLLISION_MESHES").unwrap_or_default();
    for name in ["kitten.obj", "hand.obj", "eight.obj", "wapiti_elk.obj", "bear.obj"] {
        if !only.is_empty() && !only.split(',').any(|m| name.starts_with(m)) {
            continue;
        }
        let r = run(name, pressure_factor, steps);
        println!(
            "| {name} | {} | {:.3e} | {:.0} | {:.0} | {:.0} | {:.1} | {} | {:.2} | {:.2} | {:.0}% | {:.3} |",
            r.steps,
            r.brute,
            r.candidates,
            r.after_boxes,
            r.tests,
            r.contacts,
            r.reverted,
            r.collision_ms,
            r.step_ms,
            100.0 * r.collision_ms / r.step_ms,
            r.ratio
        );
    }
}

fn main() {
    let steps = std::env::var("SHELL_COLLISION_STEPS").ok().and_then(|s| s.parse().ok());
    table(
        "Default settings (pressure 0.7 Pa, 1 thread), until the default stop (V/V0 below 0.3)",
        1.0,
        steps.unwrap_or(400),
    );
    if std::env::var("SHELL_COLLISION_SQUEEZE").map_or(true, |v| v != "0") {
        table("Squeezed: pressure x30", 30.0, steps.unwrap_or(60));
    }
}
