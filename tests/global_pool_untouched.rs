//! The host's global rayon pool is never touched: a body with worker threads, stepped on the
//! caller's thread (its solver's team then has the caller as its first member and its own pool's
//! workers as the others) and inside its pool (a body that can crack), leaves the global pool
//! unbuilt, so the host can still configure it. In a process of its own (this file's only test):
//! any other test could build the global pool first.
#![cfg(feature = "body")]
#![cfg(feature = "parallel")]

mod body_util;

use body_util::*;
use softshell::ffi::SoftshellStatus;
use softshell::ffi::body::*;

#[test]
fn stepping_bodies_leaves_the_global_pool_unbuilt() {
    let (positions, triangles) = body_util::icosphere(2, 1.0);
    for break_strain in [0.0f32, 0.5] {
        let mut def = softshell_body_def_default();
        def.threads = 2;
        def.total_mass = 1.0;
        def.spring_stiffness = 400.0;
        def.gas_amount = 300.0;
        def.ground = true;
        def.ground_height = -1.5;
        def.break_strain = break_strain;
        let body = body(&positions, &triangles, &def);
        for _ in 0..20 {
            let mut stats = SoftshellBodyStats::default();
            // SAFETY: live body, writable stats.
            assert_eq!(unsafe { softshell_body_step(body.0, &mut stats) }, SoftshellStatus::Ok, "{}", last_error());
        }
    }
    assert!(
        rayon::ThreadPoolBuilder::new().num_threads(1).build_global().is_ok(),
        "a body's step built the global pool"
    );
}
