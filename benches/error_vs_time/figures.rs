//! The paper's figures (SPEC 1.8) as SVG: volume ratio over the first 100 steps for bending
//! coefficients (Fig. 17), with and without an anisotropic region (Fig. 20), and the four
//! materials at three initial volumes (Fig. 13). Shell only, through the C ABI.

use std::fmt::Write as _;

use softshell::ffi::SoftshellShellDef;
use softshell::ffi::shell::*;

use crate::plot::{Series, lines_svg};
use crate::report_util::*;
use crate::scenes::{material_name, solver_name};

/// What the figures observed, for the findings (section 6).
#[derive(Default)]
pub struct FigObs {
    /// kB, V/V0 at step 100, steps where V/V0 rose.
    pub fig17: Vec<(f32, f64, usize)>,
    /// Run name, V/V0 at step 100, failure note (empty = every step OK).
    pub fig20: Vec<(String, f64, String)>,
    /// Solver name, material, initial volume label, V/V0 at step 100, failure note.
    pub fig13: Vec<(&'static str, &'static str, &'static str, f64, String)>,
    /// Fig. 14 rows.
    pub fig14: Vec<Fig14Row>,
    /// Table 2 rows.
    pub table2: Vec<Table2Row>,
}

/// Fig. 14: one constraint form's area and edge-length ratios at frame 100.
pub struct Fig14Row {
    pub name: &'static str,
    pub area: Vec<f64>,
    pub edge: Vec<f64>,
    pub volume_ratio: f64,
    pub note: String,
}

/// Table 2: one mesh's collision work.
pub struct Table2Row {
    pub mesh: &'static str,
    pub vertices: usize,
    pub faces: usize,
    pub edges: usize,
    pub brute_force_pairs: u64,
    pub candidates: f64,
    pub ccd_tests: f64,
    pub contacts: f64,
    pub seconds_on: f64,
    pub seconds_off: f64,
    pub note: String,
}

const STEPS: usize = 100;
const MESH: &str = "eight.obj";

/// Volume ratio after each of the first 100 steps (stops early on a failed step).
fn ratios(
    p: &[f32],
    t: &[u32],
    def: &SoftshellShellDef,
    region: Option<(&[u32], SoftshellAnisotropyDef)>,
) -> (Vec<(f64, f64)>, String) {
    let shell = Shell::new(p, t, def).expect("figure shell");
    if let Some((faces, a)) = region {
        shell.add_region(faces, &a).expect("region");
    }
    let mut out = vec![(0.0, 1.0)];
    for k in 1..=STEPS {
        match shell.step() {
            Ok(s) => out.push((k as f64, s.volume_ratio)),
            Err(f) => return (out, format!("{:?} at step {k}", f.0)),
        }
    }
    (out, String::new())
}

/// Number of steps where the ratio rose (jitter, Fig. 17's "oscillates").
fn rises(points: &[(f64, f64)]) -> usize {
    points.windows(2).filter(|w| w[1].1 > w[0].1 + 1e-6).count()
}

fn svg(md: &mut String, file: &str, title: &str, series: &[Series]) {
    let path = format!("{}/report/{file}", env!("CARGO_MANIFEST_DIR"));
    lines_svg(&path, title, "step", "volume ratio V/V0", series).expect("plot");
    writeln!(md, "\n![{title}]({file})\n").unwrap();
}

fn base() -> SoftshellShellDef {
    SoftshellShellDef { collisions: false, stop_volume_ratio: 0.0, ..softshell_shell_def_default() }
}

pub fn all(md: &mut String) -> FigObs {
    let mut obs = FigObs::default();
    let d = base();
    let (p, t) = unit_obj(MESH, 1.0);
    writeln!(
        md,
        "Mesh: data/{MESH} ({} vertices) scaled to a unit diagonal; library defaults unless said \
         (from `softshell_shell_def_default()`: {}, {}, pressure {}, E = {} Pa, damping {}/s, \
         {} iterations), collisions off, no stop, 100 steps of 1/{:.0} s.",
        p.len() / 3,
        solver_name(d.solver),
        material_name(d.material),
        d.pressure,
        d.youngs_modulus,
        d.damping,
        d.iterations,
        1.0 / d.time_step,
    )
    .unwrap();

    // Fig. 17: bending coefficient, in the paper's form (PBD, flat-rest isometric bending).
    writeln!(md, "\n### Fig. 17: bending coefficient kB (paper's form: PBD, isometric bending)\n").unwrap();
    writeln!(md, "| kB | V/V0 at step 100 | steps where V/V0 rose | note |\n|---|---:|---:|---|").unwrap();
    let mut series = Vec::new();
    for kb in [1.0f32, 1e-1, 1e-2, 1e-3, 0.0] {
        let def = SoftshellShellDef {
            solver: SOFTSHELL_SOLVER_PBD,
            bending: SOFTSHELL_BENDING_ISOMETRIC,
            bending_coefficient: kb,
            ..base()
        };
        let (points, note) = ratios(&p, &t, &def, None);
        writeln!(md, "| {kb} | {:.4} | {} | {note} |", points.last().unwrap().1, rises(&points)).unwrap();
        obs.fig17.push((kb, points.last().unwrap().1, rises(&points)));
        series.push(Series { label: format!("kB = {kb}"), points });
    }
    svg(md, "fig17_bending.svg", "Fig. 17: volume ratio for kB (PBD, isometric bending)", &series);

    // Fig. 20: anisotropic region.
    writeln!(md, "### Fig. 20: with and without an anisotropic region (ARAP, defaults)\n").unwrap();
    let arap = softshell_anisotropy_def_default();
    let region = cap_faces(&p, &t, 0.2);
    writeln!(md, "Region: the {} faces within 0.2 of the +x tip of the mesh.\n", region.len()).unwrap();
    writeln!(md, "| run | V/V0 at step 100 | note |\n|---|---:|---|").unwrap();
    let mut series = Vec::new();
    let push = arap.inward_push;
    let defaults_name = format!("ARAP region, defaults (push {push})");
    let runs = [
        ("without region", None),
        (defaults_name.as_str(), Some((region.as_slice(), arap))),
        ("ARAP region, push 0.05", Some((region.as_slice(), SoftshellAnisotropyDef { inward_push: 0.05, ..arap }))),
        (
            "Sqrt region, push 0.05",
            Some((
                region.as_slice(),
                SoftshellAnisotropyDef { energy: SOFTSHELL_ANISOTROPY_SQRT, inward_push: 0.05, ..arap },
            )),
        ),
        (
            "StVK region, push 0.05",
            Some((
                region.as_slice(),
                SoftshellAnisotropyDef { energy: SOFTSHELL_ANISOTROPY_STVK, inward_push: 0.05, ..arap },
            )),
        ),
        (
            "active contraction L = 0.7, no push",
            Some((region.as_slice(), SoftshellAnisotropyDef { inward_push: 0.0, target_stretch: 0.7, ..arap })),
        ),
    ];
    for (name, r) in runs {
        let (points, note) = ratios(&p, &t, &base(), r);
        writeln!(md, "| {name} | {:.4} | {note} |", points.last().unwrap().1).unwrap();
        obs.fig20.push((name.to_string(), points.last().unwrap().1, note.clone()));
        series.push(Series { label: name.into(), points });
    }
    svg(md, "fig20_anisotropy.svg", "Fig. 20: with and without an anisotropic region", &series);

    // Fig. 13: four materials at V0, V0/4, V0/16, in both solver forms.
    let default_solver = softshell_shell_def_default().solver;
    for (solver, form, file) in [
        (SOFTSHELL_SOLVER_XPBD, "XPBD", "fig13_materials.svg"),
        (SOFTSHELL_SOLVER_PBD, "PBD (paper's form)", "fig13_materials_pbd.svg"),
    ] {
        let form = if solver == default_solver { format!("{form} (library default)") } else { form.to_string() };
        writeln!(md, "### Fig. 13: four materials at initial volumes V0, V0/4, V0/16, {form}\n").unwrap();
        writeln!(md, "V/V0 at step 100:\n\n| material | V0 | V0/4 | V0/16 |\n|---|---:|---:|---:|").unwrap();
        let mut series = Vec::new();
        for (material, name) in [
            (SOFTSHELL_MATERIAL_STVK, "StVK"),
            (SOFTSHELL_MATERIAL_COROTATED, "corotated"),
            (SOFTSHELL_MATERIAL_LINEAR, "linear"),
            (SOFTSHELL_MATERIAL_MOONEY_RIVLIN, "Mooney-Rivlin"),
        ] {
            let mut cells = Vec::new();
            for (volume, divisor) in [("V0", 1.0f32), ("V0/4", 4.0), ("V0/16", 16.0)] {
                let (q, tt) = unit_obj(MESH, divisor.powf(-1.0 / 3.0));
                let (points, note) = ratios(&q, &tt, &SoftshellShellDef { material, solver, ..base() }, None);
                let last = points.last().unwrap().1;
                obs.fig13.push((solver_name(solver), name, volume, last, note.clone()));
                cells.push(if note.is_empty() { format!("{last:.4}") } else { format!("{last:.4} ({note})") });
                series.push(Series { label: format!("{name}, {volume}"), points });
            }
            writeln!(md, "| {name} | {} |", cells.join(" | ")).unwrap();
        }
        svg(md, file, &format!("Fig. 13: materials at V0, V0/4, V0/16, {form}"), &series);
    }

    obs.fig14 = fig14(md, &p, &t);
    obs.table2 = table2(md);
    obs
}

/// The unique edges (a < b) of a triangle list.
fn edges(t: &[u32]) -> Vec<(u32, u32)> {
    let mut e: Vec<(u32, u32)> = t
        .chunks_exact(3)
        .flat_map(|f| [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    e.sort_unstable();
    e.dedup();
    e
}

fn vertex(p: &[f32], i: u32) -> [f64; 3] {
    let i = i as usize * 3;
    [p[i] as f64, p[i + 1] as f64, p[i + 2] as f64]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn face_areas(p: &[f32], t: &[u32]) -> Vec<f64> {
    t.chunks_exact(3)
        .map(|f| {
            let (a, b, c) = (vertex(p, f[0]), vertex(p, f[1]), vertex(p, f[2]));
            let (u, v) = (sub(b, a), sub(c, a));
            0.5 * norm([u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]])
        })
        .collect()
}

fn edge_lengths(p: &[f32], e: &[(u32, u32)]) -> Vec<f64> {
    e.iter().map(|&(a, b)| norm(sub(vertex(p, a), vertex(p, b)))).collect()
}

/// The value at fraction `q` (0..1) of a sorted list.
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// Sorted ratios as a curve: percentile (0..100) against ratio.
fn percentile_curve(sorted: &[f64]) -> Vec<(f64, f64)> {
    let n = sorted.len().max(2) - 1;
    sorted.iter().enumerate().map(|(i, &r)| (100.0 * i as f64 / n as f64, r)).collect()
}

/// Fig. 14: energy constraints against edge-distance constraints (the paper's baseline): the
/// triangles' area ratios A/A0 and the edges' length ratios L/L0 at frame 100.
fn fig14(md: &mut String, p: &[f32], t: &[u32]) -> Vec<Fig14Row> {
    writeln!(
        md,
        "### Fig. 14: energy constraints against edge-distance constraints\n\n\
         Same mesh and defaults; after {STEPS} frames, each triangle's area ratio A/A0 and each \
         edge's length ratio L/L0 (1 = unstretched; below 1 = compressed). The paper's edge-distance \
         baseline is `SOFTSHELL_SOLVER_PBD_DISTANCE`; the energy forms are the paper's PBD and the \
         library's XPBD.\n"
    )
    .unwrap();
    let e = edges(t);
    let (a0, l0) = (face_areas(p, t), edge_lengths(p, &e));
    let mut rows = Vec::new();
    for (solver, name) in [
        (SOFTSHELL_SOLVER_XPBD, "energy constraints, XPBD (library default)"),
        (SOFTSHELL_SOLVER_PBD, "energy constraints, PBD (paper)"),
        (SOFTSHELL_SOLVER_PBD_DISTANCE, "edge-distance constraints, PBD (paper's baseline)"),
    ] {
        let def = SoftshellShellDef { solver, ..base() };
        let shell = Shell::new(p, t, &def).expect("fig14 shell");
        let mut note = String::new();
        let mut ratio = 1.0;
        for k in 1..=STEPS {
            match shell.step() {
                Ok(s) => ratio = s.volume_ratio,
                Err(f) => {
                    note = format!("{:?} at step {k}", f.0);
                    break;
                }
            }
        }
        let q = shell.positions();
        let mut area: Vec<f64> = face_areas(&q, t).iter().zip(&a0).map(|(a, b)| a / b).collect();
        let mut edge: Vec<f64> = edge_lengths(&q, &e).iter().zip(&l0).map(|(a, b)| a / b).collect();
        area.sort_by(f64::total_cmp);
        edge.sort_by(f64::total_cmp);
        rows.push(Fig14Row { name, area, edge, volume_ratio: ratio, note });
    }
    writeln!(
        md,
        "| constraints | V/V0 | A/A0 min | 5 % | median | 95 % | max | L/L0 min | 5 % | median | 95 % | max | note |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"
    )
    .unwrap();
    for r in &rows {
        let q = |v: &[f64]| [0.0, 0.05, 0.5, 0.95, 1.0].map(|x| format!("{:.3}", quantile(v, x))).join(" | ");
        writeln!(md, "| {} | {:.4} | {} | {} | {} |", r.name, r.volume_ratio, q(&r.area), q(&r.edge), r.note).unwrap();
    }
    let series = |f: &dyn Fn(&Fig14Row) -> &Vec<f64>| -> Vec<Series> {
        rows.iter().map(|r| Series { label: r.name.to_string(), points: percentile_curve(f(r)) }).collect()
    };
    for (file, what, s) in [
        ("fig14_area.svg", "triangle area ratio A/A0", series(&|r| &r.area)),
        ("fig14_edges.svg", "edge length ratio L/L0", series(&|r| &r.edge)),
    ] {
        let title = format!("Fig. 14: sorted {what} at frame {STEPS}");
        let path = format!("{}/report/{file}", env!("CARGO_MANIFEST_DIR"));
        lines_svg(&path, &title, "percentile of elements", what, &s).expect("plot");
        writeln!(md, "\n![{title}]({file})\n").unwrap();
    }
    rows
}

const TABLE2_MESHES: [&str; 5] = ["kitten", "hand", "eight", "wapiti_elk", "bear"];
const TABLE2_STEPS: usize = 5;

/// Table 2: the collision stage's culling on five meshes, from the shell's own stats, against
/// the brute-force count of all vertex-face and edge-edge pairs.
fn table2(md: &mut String) -> Vec<Table2Row> {
    let mut rows = Vec::new();
    for mesh in TABLE2_MESHES {
        let (p, t) = unit_obj(&format!("{mesh}.obj"), 1.0);
        let (v, f, e) = (p.len() / 3, t.len() / 3, edges(&t).len());
        let brute = (v as u64) * (f as u64) + (e as u64) * (e as u64 - 1) / 2;
        let mut row = Table2Row {
            mesh,
            vertices: v,
            faces: f,
            edges: e,
            brute_force_pairs: brute,
            candidates: 0.0,
            ccd_tests: 0.0,
            contacts: 0.0,
            seconds_on: 0.0,
            seconds_off: 0.0,
            note: String::new(),
        };
        for collisions in [true, false] {
            let def = SoftshellShellDef { collisions, ..base() };
            let shell = match Shell::new(&p, &t, &def) {
                Ok(s) => s,
                Err(fail) => {
                    row.note = format!("{:?}: {}", fail.0, fail.1.chars().take(60).collect::<String>());
                    continue;
                }
            };
            let (mut cand, mut ccd, mut cont, mut secs, mut n) = (0u64, 0u64, 0u64, 0.0, 0usize);
            for k in 1..=TABLE2_STEPS {
                match shell.step() {
                    Ok(s) => {
                        cand += s.collision_candidates;
                        ccd += s.ccd_tests;
                        cont += s.contacts;
                        secs += s.step_seconds;
                        n += 1;
                    }
                    Err(fail) => {
                        row.note = format!("collisions {collisions}: {:?} at step {k}", fail.0);
                        break;
                    }
                }
            }
            let per = |x: u64| x as f64 / n.max(1) as f64;
            if collisions {
                (row.candidates, row.ccd_tests, row.contacts) = (per(cand), per(ccd), per(cont));
                row.seconds_on = secs / n.max(1) as f64;
            } else {
                row.seconds_off = secs / n.max(1) as f64;
            }
        }
        rows.push(row);
    }
    let implemented = rows.iter().any(|r| r.candidates > 0.0 || r.ccd_tests > 0.0 || r.contacts > 0.0);
    writeln!(md, "### Table 2: collision culling\n").unwrap();
    writeln!(
        md,
        "Meshes from data/ scaled to a unit diagonal, defaults with collisions on and off, {TABLE2_STEPS} \
         steps each; per-step means of the shell's stats (`collision_candidates`, `ccd_tests`, \
         `contacts`, `step_seconds`). Brute force = every vertex-face pair (V F) plus every \
         edge-edge pair (E (E - 1) / 2), computed here.\n"
    )
    .unwrap();
    if implemented {
        writeln!(
            md,
            "| mesh | V | F | brute-force pairs | candidates | culled | CCD tests | contacts | step s (on) | step s (off) | note |\n\
             |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"
        )
        .unwrap();
        for r in &rows {
            writeln!(
                md,
                "| {} | {} | {} | {:.3e} | {:.0} | {:.5} % | {:.0} | {:.0} | {:.2e} | {:.2e} | {} |",
                r.mesh,
                r.vertices,
                r.faces,
                r.brute_force_pairs as f64,
                r.candidates,
                100.0 * (1.0 - r.candidates / r.brute_force_pairs as f64),
                r.ccd_tests,
                r.contacts,
                r.seconds_on,
                r.seconds_off,
                r.note
            )
            .unwrap();
        }
    } else {
        writeln!(
            md,
            "**Not reproduced: the shell's collision stage is not implemented in this build.** With \
             `collisions` on, `collision_candidates`, `ccd_tests` and `contacts` read 0 on every \
             mesh and step, so there is no culling to tabulate; zeros are not printed as results. \
             Printed instead: the brute-force pair count the culling will be measured against, and \
             the mean step time with collisions on and off (wall time of a shared machine):\n\n\
             | mesh | V | F | E | brute-force pairs | step s (on) | step s (off) | note |\n\
             |---|---:|---:|---:|---:|---:|---:|---|"
        )
        .unwrap();
        for r in &rows {
            writeln!(
                md,
                "| {} | {} | {} | {} | {:.3e} | {:.2e} | {:.2e} | {} |",
                r.mesh, r.vertices, r.faces, r.edges, r.brute_force_pairs as f64, r.seconds_on, r.seconds_off, r.note
            )
            .unwrap();
        }
    }
    rows
}

/// True when any Table-2 row saw collision work.
pub fn collisions_implemented(rows: &[Table2Row]) -> bool {
    rows.iter().any(|r| r.candidates > 0.0 || r.ccd_tests > 0.0 || r.contacts > 0.0)
}
