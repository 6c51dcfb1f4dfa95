//! Core blocks (SPEC 2.4): a node whose net force exceeds `break_force` is cut out of the
//! surface together with its fan of faces, which becomes a closed block of its own.
//!
//! **Decision** (the seed leaves the construction open): with the fan of node v over its ring
//! u_0..u_{k-1} (counter-clockwise), the fan faces keep their index and winding but move to copies
//! u_i' of the ring, and a cap of k faces from a new centre c' (at the ring's mean) closes the
//! block underneath; the surface left behind is closed by a cap of k faces from another new centre
//! c over the original ring. Both pieces stay closed, manifold and oriented, every new edge is a
//! spring with its rest length from the rest positions, and no existing vertex moves or is
//! renumbered. Mass: u_i' takes u_i's share of the fan's rest area (half where the fan holds all
//! of u_i's faces), c' half of v's mass (at v's velocity), c a sixth of each remaining ring mass (at their mean velocity): mass and momentum
//! are conserved exactly. The gas of the body is shared between the block and the rest in
//! proportion to their volumes, so neither pressure jumps. A block releases no block of its own,
//! nor does the patch's centre: v keeps a closed fan in the block, whose gas pushes on it (see
//! [`release`]).

use glam::{DVec3, Vec3};

use super::surface::{Fracture, Nodes, side_of};
use crate::mesh::Topology;

/// Ring of `v` as (ring vertices counter-clockwise, fan face of each ring edge u_i -> u_{i+1}),
/// or None when v's faces do not form one closed, unbroken, simple fan.
fn closed_ring(
    fracture: &Fracture,
    topology: &Topology,
    triangles: &[[u32; 3]],
    v: u32,
) -> Option<(Vec<u32>, Vec<u32>)> {
    let faces = topology.faces_of_vertex(v);
    if faces.len() < 3 {
        return None;
    }
    let mut next: Vec<(u32, u32, u32)> = Vec::with_capacity(faces.len()); // (a, b, face)
    for &f in faces {
        let t = triangles[f as usize];
        let corner = t.iter().position(|&c| c == v)?;
        let (a, b) = (t[(corner + 1) % 3], t[(corner + 2) % 3]);
        // Both sides at v must be unbroken manifold edges.
        for side in [corner, (corner + 2) % 3] {
            let e = topology.face_edges[f as usize][side];
            if e == u32::MAX || topology.edge_face_count[e as usize] != 2 || fracture.is_broken(f, side) {
                return None;
            }
            let [f0, f1] = topology.edge_faces[e as usize];
            let other = if f0 == f { f1 } else { f0 };
            if side_of(topology, other, e).is_some_and(|s| fracture.is_broken(other, s)) {
                return None;
            }
        }
        next.push((a, b, f));
    }
    let mut ring = Vec::with_capacity(faces.len());
    let mut ring_faces = Vec::with_capacity(faces.len());
    let mut current = next[0].0;
    for _ in 0..next.len() {
        let &(a, b, f) = next.iter().find(|(a, _, _)| *a == current)?;
        if ring.contains(&a) {
            return None;
        }
        ring.push(a);
        ring_faces.push(f);
        current = b;
    }
    (current == ring[0]).then_some((ring, ring_faces))
}

fn vertex_area(nodes: &Nodes, topology: &Topology, triangles: &[[u32; 3]], v: u32) -> f64 {
    topology.faces_of_vertex(v).iter().map(|&f| face_area(nodes, triangles[f as usize])).sum()
}

fn face_area(nodes: &Nodes, t: [u32; 3]) -> f64 {
    let p = t.map(|i| nodes.rest[i as usize].as_dvec3());
    0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length()
}

/// Cuts out the core block of node `v` (see the module doc). `touched` marks vertices whose
/// neighbourhood changed earlier in this pass (their `topology` entries are stale): a node whose
/// fan touches one is skipped. Returns true when a block was released.
pub(crate) fn release(
    fracture: &mut Fracture,
    topology: &Topology,
    triangles: &mut Vec<[u32; 3]>,
    nodes: &mut Nodes,
    touched: &mut [bool],
    v: u32,
) -> bool {
    if touched[v as usize] {
        return false;
    }
    let Some((ring, ring_faces)) = closed_ring(fracture, topology, triangles, v) else { return false };
    if ring.iter().any(|&u| touched[u as usize]) {
        return false;
    }
    let k = ring.len();
    // Ring copies u_i' with the fan's share of u_i's mass.
    let mut copies = Vec::with_capacity(k);
    for (i, &u) in ring.iter().enumerate() {
        let ui = u as usize;
        let fan_area = face_area(nodes, triangles[ring_faces[i] as usize])
            + face_area(nodes, triangles[ring_faces[(i + k - 1) % k] as usize]);
        let total = vertex_area(nodes, topology, triangles, u);
        // A ring vertex with no face outside the fan (a crack split the rest of its fan away)
        // stays in the patch's cap alone: it keeps half its mass. With its share of the area
        // (all of it) it went to the block whole and left the vertex at mass 0, an anchor
        // nothing moved (found by review: momentum then drifted by a quarter).
        let share = if topology.faces_of_vertex(u).len() <= 2 {
            0.5
        } else if total > 0.0 {
            (fan_area / total).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let m = nodes.mass[ui] as f64;
        let taken = (m * share) as f32;
        let (x, vel, rest) = (nodes.x[ui], nodes.v[ui], nodes.rest[ui]);
        copies.push(fracture.add_vertex(nodes, ui, x, vel, taken, rest));
        nodes.set_mass(ui, (m - taken as f64).max(0.0) as f32);
    }
    let center_x = (ring.iter().map(|&u| nodes.x[u as usize].as_dvec3()).sum::<DVec3>() / k as f64).as_vec3();
    let center_rest = (ring.iter().map(|&u| nodes.rest[u as usize].as_dvec3()).sum::<DVec3>() / k as f64).as_vec3();
    // Block cap centre c': half of v's mass at v's velocity.
    let vi = v as usize;
    let half = nodes.mass[vi] * 0.5;
    let v_vel = nodes.v[vi];
    let c_block = fracture.add_vertex(nodes, vi, center_x, v_vel, half, center_rest);
    let keep = nodes.mass[vi] - half;
    nodes.set_mass(vi, keep);
    // Surface cap centre c: a sixth of each ring vertex's remaining mass, at the mean velocity.
    let mut mass_c = 0.0f64;
    let mut momentum_c = DVec3::ZERO;
    for &u in &ring {
        let ui = u as usize;
        let m = nodes.mass[ui] as f64;
        let taken = (m / 6.0) as f32;
        mass_c += taken as f64;
        momentum_c += taken as f64 * nodes.v[ui].as_dvec3();
        nodes.set_mass(ui, (m - taken as f64).max(0.0) as f32);
    }
    let vel_c = if mass_c > 0.0 { (momentum_c / mass_c).as_vec3() } else { Vec3::ZERO };
    let c_surface = fracture.add_vertex(nodes, ring[0] as usize, center_x, vel_c, mass_c as f32, center_rest);
    // The c vertex is not pinned even if ring[0] is: it takes its mass from the whole ring.
    if mass_c > 0.0 {
        nodes.inv_mass[c_surface as usize] = 1.0 / mass_c as f32;
    }
    // Fan faces move to the ring copies (same index and winding).
    for &f in &ring_faces {
        for corner in triangles[f as usize].iter_mut() {
            if let Some(i) = ring.iter().position(|&u| u == *corner) {
                *corner = copies[i];
            }
        }
    }
    for i in 0..k {
        let j = (i + 1) % k;
        // Fan face i runs u_i -> u_j; the surface cap face takes its place over that edge.
        let fan = triangles[ring_faces[i] as usize];
        let side = (0..3)
            .find(|&s| fan[s] == copies[i] && fan[(s + 1) % 3] == copies[j])
            .expect("a fan face runs from one ring copy to the next (closed_ring)");
        let bit = fracture.broken[ring_faces[i] as usize] & (1 << side) != 0;
        // The fan face now shares that side with the block's cap, not with the face across the
        // crack: its bit moves to the surface cap (which meets that face), or the side would
        // count as a broken edge of two faces and lose its spring.
        fracture.broken[ring_faces[i] as usize] &= !(1 << side);
        // A crack's side keeps its rest length on both faces that now hold it: the surface cap
        // (the crack's side still) and the fan face (now a side of the block, as stretched).
        if let Some(length) = fracture.opened_side(ring_faces[i], side) {
            fracture.set_opened_side(triangles.len() as u32, 1, length);
        }
        fracture.broken.push(0);
        if bit {
            fracture.mark(triangles.len() as u32, 1);
        }
        triangles.push([c_surface, ring[i], ring[j]]);
        triangles.push([c_block, copies[j], copies[i]]);
        fracture.broken.push(0);
    }
    touched[vi] = true;
    for &u in &ring {
        touched[u as usize] = true;
    }
    // The block (v with its ring's copies and its cap's centre) and the patch's centre release
    // no block themselves. v keeps a closed fan in the block, and a block holding gas feels its
    // own pressure: without this a review saw blocks cut out of blocks at every step, a
    // tetrahedron growing to 462,903 vertices in 26 steps. The surface's own vertices still can,
    // each once (its fan then moves to a block), so the releases are bounded.
    for i in copies.iter().chain([&c_block, &c_surface]).map(|&c| c as usize).chain([vi]) {
        fracture.mark_in_core(i);
    }
    true
}
