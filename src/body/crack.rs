//! Cracks (SPEC 2.4, edge-aligned form of the virtual node algorithm): a broken spring marks
//! its edge broken on both faces; then at each end vertex the fan of faces is split at the broken
//! edges, and every fan after the first gets a copy of the vertex (same x and v, mass split by
//! fan rest area, appended so that no survivor is renumbered). Faces keep their index and winding;
//! only the corner that named the vertex is re-instanced.
//!
//! Mass and momentum are conserved exactly (the copies share the velocity); positions do not move.

use super::surface::{Fracture, Nodes, side_of};
use crate::mesh::{NO_FACE, Topology};

/// Marks every side of `edges` (edge indices of `topology`) broken.
pub(crate) fn mark_broken(fracture: &mut Fracture, topology: &Topology, edges: &[u32]) {
    for &e in edges {
        for &f in &topology.edge_faces[e as usize] {
            if f == NO_FACE {
                continue;
            }
            if let Some(side) = side_of(topology, f, e) {
                fracture.broken[f as usize] |= 1 << side;
            }
        }
    }
}

fn find(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// The fans of faces around `v`: groups of its faces joined through unbroken manifold edges.
/// Each fan is sorted, and fans are ordered by their first face.
pub(crate) fn fans(fracture: &Fracture, topology: &Topology, triangles: &[[u32; 3]], v: u32) -> Vec<Vec<u32>> {
    let faces = topology.faces_of_vertex(v);
    let mut parent: Vec<usize> = (0..faces.len()).collect();
    for (i, &f) in faces.iter().enumerate() {
        let t = triangles[f as usize];
        for side in 0..3 {
            if t[side] != v && t[(side + 1) % 3] != v {
                continue;
            }
            let e = topology.face_edges[f as usize][side];
            if e == u32::MAX || topology.edge_face_count[e as usize] != 2 || fracture.is_broken(f, side) {
                continue;
            }
            let [f0, f1] = topology.edge_faces[e as usize];
            let other = if f0 == f { f1 } else { f0 };
            if let Some(other_side) = side_of(topology, other, e) {
                if fracture.is_broken(other, other_side) {
                    continue;
                }
            }
            if let Some(j) = faces.iter().position(|&g| g == other) {
                let (a, b) = (find(&mut parent, i), find(&mut parent, j));
                if a != b {
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
    }
    let mut groups: Vec<Vec<u32>> = Vec::new();
    let mut root_group: Vec<usize> = vec![usize::MAX; faces.len()];
    for (i, &face) in faces.iter().enumerate() {
        let root = find(&mut parent, i);
        if root_group[root] == usize::MAX {
            root_group[root] = groups.len();
            groups.push(Vec::new());
        }
        groups[root_group[root]].push(face);
    }
    groups
}

/// Rest area of a triangle: masses are split by rest area, which is never zero (a crumpled,
/// zero-area fan must not end up with no mass).
fn triangle_area(nodes: &Nodes, t: [u32; 3]) -> f64 {
    let p = t.map(|i| nodes.rest[i as usize].as_dvec3());
    0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length()
}

/// Splits the fans of every vertex in `vertices` (see the module doc); returns how many vertices
/// were added. `topology` describes the triangles before this call.
pub(crate) fn split_fans(
    fracture: &mut Fracture,
    topology: &Topology,
    triangles: &mut [[u32; 3]],
    nodes: &mut Nodes,
    vertices: &[u32],
) -> usize {
    let before = nodes.len();
    for &v in vertices {
        let groups = fans(fracture, topology, triangles, v);
        if groups.len() < 2 {
            continue;
        }
        let areas: Vec<f64> =
            groups.iter().map(|g| g.iter().map(|&f| triangle_area(nodes, triangles[f as usize])).sum()).collect();
        let total: f64 = areas.iter().sum();
        let vi = v as usize;
        let mass = nodes.mass[vi] as f64;
        let share = |k: usize| if total > 0.0 { areas[k] / total } else { 1.0 / groups.len() as f64 };
        let (x, vel, rest) = (nodes.x[vi], nodes.v[vi], nodes.rest[vi]);
        let mut given = 0.0f64;
        for (k, group) in groups.iter().enumerate().skip(1) {
            let m = (mass * share(k)) as f32;
            given += m as f64;
            let copy = fracture.add_vertex(nodes, vi, x, vel, m, rest);
            for &f in group {
                for corner in triangles[f as usize].iter_mut() {
                    if *corner == v {
                        *corner = copy;
                    }
                }
            }
        }
        // The first fan keeps the vertex and the rest of the mass (so the sum is exact in f32).
        nodes.set_mass(vi, (mass - given).max(0.0) as f32);
    }
    nodes.len() - before
}
