//! Section 6 of the report: every finding is computed from what this run observed (the
//! work-precision runs, the figures and the stability rows), never written in advance.

use std::fmt::Write as _;

use softshell::ffi::body::*;
use softshell::ffi::lattice::*;
use softshell::ffi::shell::*;
use softshell::ffi::{SoftshellBodyDef, SoftshellLatticeDef, SoftshellShellDef};

use crate::Run;
use crate::figures::{FigObs, collisions_implemented, quantile};
use crate::report_util::cases::{self, Outcome, Row};
use crate::report_util::*;

/// Everything the findings are computed from.
pub struct Observed<'a> {
    pub stall: &'a [(u32, f64)],
    pub shell_contract: &'a [Run],
    pub body_spring: &'a [Run],
    pub body_gas: &'a [Run],
    pub body_reference: &'a [Run],
    pub lattice_reference: &'a [Run],
    pub rows: &'a [Row],
    pub figs: &'a FigObs,
}

fn error_of(runs: &[Run], family: &str, setting: &str) -> Option<f64> {
    runs.iter().find(|r| r.family == family && r.setting == setting).and_then(|r| r.error)
}

/// The number after `V/V0 ` in a stability row's detail.
fn detail_ratio(detail: &str) -> Option<f64> {
    let rest = &detail[detail.find("V/V0 ")? + 5..];
    rest.split(|c: char| c == ',' || c.is_whitespace()).next()?.parse().ok()
}

fn short(s: &str, n: usize) -> String {
    let t: String = s.chars().take(n).collect();
    if t.len() < s.len() { format!("{t}...") } else { t }
}

/// Memory of a 1-thread and a 2-thread handle of each simulator (threads = 1 holds no pool).
fn thread_memory() -> [(&'static str, usize, usize); 3] {
    let (p, t) = unit_obj("sphere.obj", 1.0);
    let shell =
        |threads| Shell::new(&p, &t, &SoftshellShellDef { threads, ..softshell_shell_def_default() }).unwrap().memory();
    let body =
        |threads| Body::new(&p, &t, &SoftshellBodyDef { threads, ..softshell_body_def_default() }).unwrap().memory();
    let lattice = |threads| {
        Lattice::new(&SoftshellLatticeDef { columns: 16, rows: 16, threads, ..softshell_lattice_def_default() })
            .unwrap()
            .memory()
    };
    [("shell", shell(1), shell(2)), ("body", body(1), body(2)), ("lattice", lattice(1), lattice(2))]
}

pub fn findings(o: &Observed) -> String {
    let mut md = String::from("## 6. Findings and gaps\n\nComputed from this run.\n");
    let mut item = |s: String| writeln!(md, "\n- {s}").unwrap();

    // Stability contract, per simulator: broken rows, and known bugs that no longer show.
    for sim in ["shell", "body", "lattice"] {
        let broken: Vec<&Row> =
            o.rows.iter().filter(|r| r.simulator == sim && matches!(r.outcome, Outcome::Broken(_))).collect();
        let known = match sim {
            "body" => cases::KNOWN_BODY_BUGS,
            "shell" => cases::KNOWN_SHELL_BUGS,
            _ => &[],
        };
        if broken.is_empty() {
            item(format!(
                "**{sim}: every stability case kept the contract** in this run (no BROKEN cell in section 5)."
            ));
        } else {
            let list: Vec<String> = broken
                .iter()
                .map(|r| {
                    format!(
                        "*{} / {}*{}: {}",
                        r.case,
                        r.setting,
                        if cases::is_known_bug(r) { " (known, allow-listed)" } else { " (NEW, not allow-listed)" },
                        short(r.outcome.detail(), 140)
                    )
                })
                .collect();
            item(format!(
                "**{sim} bug: {} stability case(s) broke the contract** (a step returned OK on a blown-up \
                 or non-finite state, or did not roll back; the same rows run in `cargo test --release \
                 --test stability -- --nocapture`, which fails on any not allow-listed): {}.",
                broken.len(),
                list.join("; ")
            ));
        }
        for (case, setting) in known {
            let seen = broken.iter().any(|r| r.case.starts_with(case) && r.setting == *setting);
            if !seen {
                item(format!(
                    "**{sim}: the allow-listed bug *{case} / {setting}* did not show in this run**: \
                     tests/report_util/cases.rs can drop it from the allow-list."
                ));
            }
        }
    }

    // Shell stability rows that return OK with an inverted volume.
    let inverted: Vec<String> = o
        .rows
        .iter()
        .filter(|r| r.simulator == "shell" && matches!(r.outcome, Outcome::Stable(_)))
        .filter_map(|r| {
            detail_ratio(r.outcome.detail())
                .filter(|v| *v < 0.0)
                .map(|v| format!("{} / {} (V/V0 {v})", r.case, r.setting))
        })
        .collect();
    if !inverted.is_empty() {
        item(format!(
            "**Shell: stability cases that turn inside out while every step returns OK:** {}. The \
             divergence check does not look at the sign of the volume.",
            inverted.join("; ")
        ));
    }

    // Fig. 20: inversion with an anisotropic region.
    let f20_inv: Vec<String> = o
        .figs
        .fig20
        .iter()
        .filter(|(_, v, note)| *v < 0.0 && note.is_empty())
        .map(|(n, v, _)| format!("{n} (V/V0 {v:.3})"))
        .collect();
    if let Some((name, v, _)) = o.figs.fig20.iter().find(|(n, _, _)| n.contains("defaults")) {
        if *v < 0.0 {
            item(format!(
                "**Shell: an anisotropic region with the default settings turns data/eight.obj inside out** ({name}: V/V0 = {v:.3} after 100 steps, every step OK)."
            ));
        } else {
            item(format!(
                "**Shell, Fig. 20: the anisotropic region with the default settings does not turn the \
                 mesh inside out in this run** ({name}: V/V0 = {v:.4} after 100 steps, every step OK)."
            ));
        }
    }
    if !f20_inv.is_empty() {
        item(format!(
            "**Shell, Fig. 20: runs that end inside out while every step returned OK:** {} \
             (no collision stage stops the region passing through the other side).",
            f20_inv.join("; ")
        ));
    }

    // Fig. 13: inverted cells and dependence on the initial volume.
    let f13_inv: Vec<String> = o
        .figs
        .fig13
        .iter()
        .filter(|c| c.3 < 0.0 && c.4.is_empty())
        .map(|c| format!("{} {} at {} ({:.3})", c.0, c.1, c.2, c.3))
        .collect();
    if f13_inv.is_empty() {
        item("**Fig. 13:** no run ended with a negative volume.".into());
    } else {
        item(format!(
            "**Shell bug, Fig. 13: turned inside out while every step returned OK:** {}. The \
             step's divergence check does not catch an inverted volume (SPEC: UNSTABLE with \
             rollback). Reproducer: `cargo test --release --test stability -- --ignored \
             shell_pbd_small_copy_inversion`.",
            f13_inv.join("; ")
        ));
    }
    for solver in ["XPBD", "PBD"] {
        let cells: Vec<&(&str, &str, &str, f64, String)> =
            o.figs.fig13.iter().filter(|c| c.0 == solver && c.1 == "StVK").collect();
        if cells.len() == 3 {
            let (lo, hi) = cells.iter().fold((f64::MAX, f64::MIN), |(l, h), c| (l.min(c.3), h.max(c.3)));
            let values: Vec<String> = cells.iter().map(|c| format!("{:.3}", c.3)).collect();
            item(format!(
                "**Fig. 13, {solver}:** the paper's volume ratio is independent of the initial volume; \
                 here StVK gives {} at V0 / V0/4 / V0/16 (spread {:.3}: {}). The meshes are scaled but \
                 pressure and density are not.",
                values.join(" / "),
                hi - lo,
                if hi - lo > 0.05 { "not reproduced" } else { "reproduced within 0.05" }
            ));
        }
    }

    // Fig. 17.
    if let (Some(stiff), Some(soft), Some(none)) = (
        o.figs.fig17.iter().find(|r| r.0 == 1.0),
        o.figs.fig17.iter().find(|r| r.0 == 1e-3),
        o.figs.fig17.iter().find(|r| r.0 == 0.0),
    ) {
        let ordered = o.figs.fig17.windows(2).all(|w| w[0].1 >= w[1].1 - 1e-3);
        let values: Vec<String> = o.figs.fig17.iter().map(|r| format!("{} -> {:.3}", r.0, r.1)).collect();
        let rises: Vec<String> = o.figs.fig17.iter().map(|r| format!("{}", r.2)).collect();
        item(format!(
            "**Fig. 17:** V/V0 at step 100 for kB {}; the contraction {} as kB falls (paper: stiffer \
             bending contracts less); kB = 1e-3 ends {:.3} from kB = 0; V/V0 rose in {} of 100 steps \
             (jitter; kB = 1 rose in {}).",
            values.join(", "),
            if ordered { "deepens monotonically" } else { "is NOT monotonic" },
            (soft.1 - none.1).abs(),
            rises.join(" / "),
            stiff.2
        ));
    }

    // Fig. 14.
    if o.figs.fig14.len() == 3 {
        let parts: Vec<String> = o
            .figs
            .fig14
            .iter()
            .map(|r| {
                format!(
                    "{}: A/A0 median {:.3} (max {:.3}), L/L0 median {:.3} (max {:.3}){}",
                    r.name,
                    quantile(&r.area, 0.5),
                    quantile(&r.area, 1.0),
                    quantile(&r.edge, 0.5),
                    quantile(&r.edge, 1.0),
                    if r.note.is_empty() { String::new() } else { format!(" ({})", r.note) }
                )
            })
            .collect();
        item(format!("**Fig. 14 (frame 100):** {}.", parts.join("; ")));
    }

    // Table 2.
    if collisions_implemented(&o.figs.table2) {
        let parts: Vec<String> = o
            .figs
            .table2
            .iter()
            .map(|r| format!("{} {:.0} candidates of {:.2e} pairs", r.mesh, r.candidates, r.brute_force_pairs as f64))
            .collect();
        item(format!("**Shell collisions (Table 2):** {}.", parts.join(", ")));
    } else {
        item(
            "**Shell collisions:** the collision stage is not implemented in this build \
             (`collision_candidates`, `ccd_tests`, `contacts` read 0 on all five Table-2 meshes with \
             collisions on), so Table 2 is not reproduced."
                .into(),
        );
    }

    // f32 stall.
    if let (Some(first), Some(last)) = (o.stall.first(), o.stall.last()) {
        let stuck: Vec<String> =
            o.stall.iter().filter(|(_, r)| (r - first.1).abs() > 0.01).map(|(s, r)| format!("{s}: {r:.4}")).collect();
        if stuck.is_empty() {
            item(format!(
                "**Shell, many substeps:** V/V0 after 10 steps stays within 0.01 of the 16-substep value \
                 ({:.4}) up to {} substeps: no f32 stall in this run.",
                first.1, last.0
            ));
        } else {
            item(format!(
                "**Shell bug (f32 stall with many substeps):** the default contraction gives V/V0 {:.4} \
                 after 10 steps at {} substeps, but more than 0.01 away at (substeps: V/V0) {}; at {} \
                 substeps it is {:.6}{}. The per-substep displacement falls below the positions' f32 \
                 resolution. Reproducer: `cargo test --release --test stability -- --ignored \
                 shell_many_substeps_still_contract`.",
                first.1,
                first.0,
                stuck.join(", "),
                last.0,
                last.1,
                if last.1 >= 0.9999 { " (it does not move at all)" } else { "" }
            ));
        }
    }

    // Body: explicit blow-ups that return OK in the work-precision scenes.
    let blown: Vec<String> = [o.body_spring, o.body_gas, o.body_reference]
        .iter()
        .flat_map(|runs| runs.iter())
        .filter(|r| r.note.contains("while every step returned OK"))
        .map(|r| format!("{} / {}", r.family, r.setting))
        .collect();
    if !blown.is_empty() {
        item(format!("**Body: blew up while returning OK in the work-precision scenes:** {}.", blown.join("; ")));
    }

    // Expected behaviour of the integrators on the triangle.
    let tri = |f: &str, s: &str| error_of(o.body_spring, f, s);
    if let (Some(imp), Some(xpbd), exp) = (
        tri("integrator (h = 1/60)", "implicit Euler"),
        tri("integrator (h = 1/60)", "XPBD"),
        tri("integrator (h = 1/60)", "explicit Euler"),
    ) {
        // Explicit Euler, undamped there, gains energy each step until the step check rolls a
        // step back as UNSTABLE (no error then).
        let exp = match exp {
            Some(e) => format!("explicit Euler gains energy (error {e:.2})"),
            None => "explicit Euler gains energy until a step is rolled back as UNSTABLE".to_owned(),
        };
        let sym: Vec<f64> = ["1/60", "1/120", "1/240"]
            .iter()
            .filter_map(|h| tri("time step, symplectic Euler", &format!("h = {h} s")))
            .collect();
        let order = if sym.len() == 3 { (sym[0] / sym[2]).log2() / 2.0 } else { f64::NAN };
        item(format!(
            "**Triangle breathing mode (expected behaviour):** at h = 1/60 s implicit Euler and XPBD \
             lose most of the oscillation (error {imp:.2} and {xpbd:.2} of the amplitude: backward \
             Euler's numerical damping); {exp}; symplectic Euler's \
             error goes {} as h halves: order {order:.2}.",
            sym.iter().map(|e| format!("{e:.2e}")).collect::<Vec<_>>().join(" -> ")
        ));
    }

    // Floors.
    let xs: Vec<(String, f64)> = o
        .body_reference
        .iter()
        .filter(|r| r.family == "substeps, XPBD")
        .filter_map(|r| r.error.map(|e| (r.setting.clone(), e)))
        .collect();
    if let Some(best) = xs.iter().min_by(|a, b| a.1.total_cmp(&b.1)) {
        let last = xs.last().unwrap();
        if last.1 > 1.5 * best.1 {
            item(format!(
                "**Body floor:** XPBD on the inflating sphere is best at {} ({:.2e}) and worse at {} \
                 ({:.2e}): more substeps stop helping (f32 positions at tiny substeps).",
                best.0, best.1, last.0, last.1
            ));
        }
    }
    // How far each reference is from converged, and the rows it cannot resolve.
    for (scene, runs) in [
        ("Shell contraction", o.shell_contract),
        ("Body inflation", o.body_reference),
        ("Lattice sag", o.lattice_reference),
    ] {
        let Some(uncertainty) = runs.iter().find(|r| r.family == "reference check").and_then(|r| r.error) else {
            continue;
        };
        let rows: Vec<&Run> = runs.iter().filter(|r| !r.family.starts_with("reference")).collect();
        let smallest = rows.iter().filter_map(|r| r.error).min_by(f64::total_cmp).unwrap_or(f64::NAN);
        let unresolved: Vec<String> = rows
            .iter()
            .filter(|r| r.error.is_some_and(|e| e < 2.0 * uncertainty))
            .map(|r| format!("{} / {}", r.family, r.setting))
            .collect();
        item(format!(
            "**{scene} reference:** its own error (the reference check) is {uncertainty:.2e}; the \
             smallest error of a row is {smallest:.2e}. {}",
            if unresolved.is_empty() {
                "Every row's error is over twice the reference's.".to_string()
            } else {
                format!("Within twice the reference's error, so not resolved: {}.", unresolved.join(", "))
            }
        ));
    }

    // Zero-area triangle without gas.
    for r in o.rows.iter().filter(|r| r.simulator == "body" && r.case.contains("no gas")) {
        if !matches!(r.outcome, Outcome::Rejected(_)) {
            item(format!(
                "**Body: a zero-area triangle without gas is accepted** ({} / {}: {}); SPEC 4 asks for \
                 rejection with the index.",
                r.case,
                r.setting,
                r.outcome.label()
            ));
            break;
        }
    }

    // Threads.
    let mem: Vec<String> = thread_memory().iter().map(|(s, one, two)| format!("{s} {one} -> {two} bytes")).collect();
    item(format!(
        "**threads = 1 holds no pool, but the evidence is thin:** `*_memory_bytes` with 1 and 2 \
         threads: {} (worker-thread stacks are not counted).",
        mem.join(", ")
    ));
    item("Not measured: meshes of 1M triangles (too slow for this bench on 2 cores); the lattice stats have no per-stage counter, so tests/leave_out.rs shows skipped work only through memory and results.".into());
    md
}
