//! A cloth (open mesh, no gas) pinned at its two top corners blows in the wind (SPEC 2.1 wind
//! drag on faces, pins).
#![cfg(feature = "body")]

mod body_util;

use body_util::*;
use softshell::ffi::body::*;

fn run(wind: [f32; 3], integrator: u32) -> (Snapshot, Snapshot) {
    let n = 12u32;
    let (positions, triangles) = cloth(n, 1.0);
    let mut def = softshell_body_def_default();
    def.integrator = integrator;
    def.total_mass = 0.2;
    def.spring_stiffness = 200.0;
    def.spring_damping = 0.05;
    def.wind = wind;
    def.drag = 2.0;
    if integrator == SOFTSHELL_INTEGRATOR_XPBD {
        def.substeps = 4;
    }
    let body = body(&positions, &triangles, &def);
    for corner in [0, n - 1] {
        // SAFETY: live body.
        assert_eq!(unsafe { softshell_body_pin_vertex(body.0, corner) }, softshell::ffi::SoftshellStatus::Ok);
    }
    let start = snapshot(&body);
    for _ in 0..240 {
        step(&body);
    }
    (start, snapshot(&body))
}

fn mean_z(s: &Snapshot) -> f64 {
    s.positions.chunks_exact(3).map(|p| p[2] as f64).sum::<f64>() / s.vertex_count() as f64
}

#[test]
fn cloth_pinned_at_two_corners_blows_in_the_wind() {
    for integrator in [SOFTSHELL_INTEGRATOR_IMPLICIT_EULER, SOFTSHELL_INTEGRATOR_XPBD] {
        let (start, calm) = run([0.0; 3], integrator);
        let (_, windy) = run([0.0, 0.0, 6.0], integrator);
        for s in [&calm, &windy] {
            assert!(s.positions.iter().all(|p| p.is_finite()));
            // The pinned corners did not move.
            assert_eq!(s.position(0), start.position(0));
            assert_eq!(s.position(11), start.position(11));
        }
        let (z_calm, z_windy) = (mean_z(&calm), mean_z(&windy));
        println!(
            "integrator {integrator}: mean z calm {z_calm:.4}, windy {z_windy:.4}; centre y calm {:.4}, windy {:.4}",
            calm.center_y(),
            windy.center_y()
        );
        assert!(z_calm.abs() < 1e-3, "without wind the cloth hangs in its plane ({z_calm})");
        assert!(z_windy > 0.1, "the wind must blow the cloth downwind ({z_windy})");
        // Hanging in calm air; lifted towards the horizontal by the wind.
        assert!(calm.center_y() < -0.45, "{}", calm.center_y());
        assert!(windy.center_y() > calm.center_y() + 0.02);
    }
}

/// A balloon that shatters at once (1,990 springs of 7,680 on the first step, ~280 fragments)
/// falls through wind with XPBD: the drag on the small fragments (split nodes share their
/// masses) must stay stable; implicit Euler, which keeps this ball whole, in the same wind. With the drag held for the whole step, XPBD's
/// kinetic energy went from 20 J to 1e35 J in ten steps while every step returned OK.
#[test]
fn a_shattered_balloon_in_wind_stays_bounded() {
    let (p, t) = icosphere(4, 0.5);
    for integrator in [SOFTSHELL_INTEGRATOR_XPBD, SOFTSHELL_INTEGRATOR_IMPLICIT_EULER] {
        let mut def = softshell_body_def_default();
        def.integrator = integrator;
        def.gas_amount = 30.0;
        def.break_strain = 0.08;
        def.substeps = 2;
        def.drag = 0.5;
        def.wind = [3.0, 0.0, 1.0];
        let body = body(&p, &t, &def);
        let mut most = 0.0f64;
        let mut fragments = 0;
        for _ in 0..30 {
            let stats = step(&body);
            most = most.max(stats.kinetic_energy);
            fragments = stats.fragment_count;
        }
        // (XPBD's first projection tears it apart; implicit Euler holds it together.)
        if integrator == SOFTSHELL_INTEGRATOR_XPBD {
            assert!(fragments > 100, "{fragments} fragments (the scene must shatter)");
        }
        // Falling for 0.5 s (about 25 J for the 1 kg body) plus what a 3.2 m/s wind can give.
        assert!(most < 100.0, "integrator {integrator}: kinetic energy reached {most:.3e} J");
    }
}
