//! Time of `Topology::build` (the mesh connectivity every simulator and the fracture rebuild
//! start from) on the 10,242-vertex balloon icosphere of issue 5 and on shared meshes of data/.
//! Run with `cargo bench --bench topology_build`; prints the best and the median of 40 builds.

use std::time::Instant;

use softshell::mesh::{Topology, load_obj};

#[path = "../tests/body_util/mod.rs"]
mod body_util;

/// The triangles and vertex count of an OBJ file of data/.
fn read_triangles(name: &str) -> (Vec<[u32; 3]>, usize) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data").join(name);
    let mesh = load_obj(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
    (mesh.triangles().to_vec(), mesh.vertex_count())
}

fn time(name: &str, triangles: &[[u32; 3]], vertices: usize) {
    let mut times = Vec::new();
    let mut edges = 0;
    for _ in 0..40 {
        let started = Instant::now();
        let topology = Topology::build(triangles, vertices);
        times.push(started.elapsed().as_secs_f64() * 1e3);
        edges = topology.edges.len();
    }
    times.sort_by(f64::total_cmp);
    println!(
        "{name:<24} {vertices:>6} vertices {:>6} faces {edges:>6} edges: best {:.3} ms, median {:.3} ms",
        triangles.len(),
        times[0],
        times[times.len() / 2]
    );
}

fn main() {
    let (positions, flat) = body_util::icosphere(5, 1.0);
    let balloon: Vec<[u32; 3]> = flat.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    time("balloon (icosphere 5)", &balloon, positions.len() / 3);
    for name in ["kitten.obj", "bear.obj", "hand_hires.obj"] {
        let (triangles, vertices) = read_triangles(name);
        time(name, &triangles, vertices);
    }
}
