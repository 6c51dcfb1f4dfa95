//! Cracks (SPEC 2.4, edge-aligned form of the virtual node algorithm): a broken spring marks
//! its edge broken on both faces; then at each end vertex the fan of faces is split at the broken
//! edges, and every fan after the first gets a copy of the vertex (same x and v, mass split by
//! fan rest area, each fan at least a thousandth, appended so that no survivor is renumbered).
//! Faces keep their index and winding; only the corner that named the vertex is re-instanced. A
//! broken edge carries no spring while
//! its two faces still share it; once the split parts them, each is an edge of one face and a
//! spring again (`surface::edge_is_broken`), so every face keeps its three sides.
//!
//! Mass and momentum are conserved exactly (the copies share the velocity); positions do not move.

use super::surface::{Fracture, Nodes, edge_is_broken, side_of};
use crate::mesh::{NO_FACE, Topology};
use crate::parallel::WorkerPool;

/// Marks every side of `edges` (edge indices of `topology`) broken.
pub(crate) fn mark_broken(fracture: &mut Fracture, topology: &Topology, edges: &[u32]) {
    for &e in edges {
        for &f in &topology.edge_faces[e as usize] {
            if f == NO_FACE {
                continue;
            }
            if let Some(side) = side_of(topology, f, e) {
                fracture.mark(f, side);
            }
        }
    }
}

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

/// The fans of faces around `v`: groups of its faces joined through unbroken manifold edges,
/// numbered in order of their first face (the faces of a vertex are in face order). Appends to
/// `labels` the fan of each face of `v` (in `faces_of_vertex` order) and returns the number of
/// fans; `parent` is scratch.
pub(crate) fn fan_labels(
    fracture: &Fracture,
    topology: &Topology,
    triangles: &[[u32; 3]],
    v: u32,
    parent: &mut Vec<u32>,
    labels: &mut Vec<u32>,
) -> usize {
    let faces = topology.faces_of_vertex(v);
    parent.clear();
    parent.extend(0..faces.len() as u32);
    for (i, &f) in faces.iter().enumerate() {
        let t = triangles[f as usize];
        for side in 0..3 {
            if t[side] != v && t[(side + 1) % 3] != v {
                continue;
            }
            let e = topology.face_edges[f as usize][side];
            if e == u32::MAX || topology.edge_face_count[e as usize] < 2 || edge_is_broken(topology, Some(fracture), e)
            {
                continue;
            }
            let mut join = |j: usize| {
                let (a, b) = (find(parent, i as u32), find(parent, j as u32));
                if a != b {
                    parent[a.max(b) as usize] = a.min(b);
                }
            };
            if topology.edge_face_count[e as usize] == 2 {
                let [f0, f1] = topology.edge_faces[e as usize];
                let other = if f0 == f { f1 } else { f0 };
                if let Some(j) = faces.iter().position(|&g| g == other) {
                    join(j);
                }
            } else {
                // An unbroken edge of three or more faces (a non-manifold input) holds all of
                // them together at its ends: a crack elsewhere through the vertex must not
                // part them (each page was a fan of its own, and the first crack there opened
                // an edge nobody broke: found by review).
                for (j, &g) in faces.iter().enumerate() {
                    if g != f && topology.face_edges[g as usize].contains(&e) {
                        join(j);
                    }
                }
            }
        }
    }
    // A root is the smallest index of its fan (unions keep the smaller root), so it comes
    // before its other faces: fans numbered in order of their first face.
    let first = labels.len();
    let mut count = 0;
    for i in 0..faces.len() as u32 {
        let root = find(parent, i);
        let label = if root == i {
            count += 1;
            count - 1
        } else {
            labels[first + root as usize]
        };
        labels.push(label);
    }
    count as usize
}

/// The least share of a vertex's mass the copy of one of its fans takes.
const MIN_FAN_SHARE: f64 = 1e-3;

/// Rest area of a triangle: masses are split by rest area, which is never zero (a crumpled,
/// zero-area fan must not end up with no mass).
fn triangle_area(nodes: &Nodes, t: [u32; 3]) -> f64 {
    let p = t.map(|i| nodes.rest[i as usize].as_dvec3());
    0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length()
}

/// The fan labels ([`fan_labels`]) of every vertex of `vertices`, flattened in their order,
/// and the fan count of each.
fn all_fan_labels(
    fracture: &Fracture,
    topology: &Topology,
    triangles: &[[u32; 3]],
    vertices: &[u32],
) -> (Vec<u32>, Vec<u32>) {
    let (mut labels, mut counts, mut parent) = (Vec::new(), Vec::with_capacity(vertices.len()), Vec::new());
    for &v in vertices {
        counts.push(fan_labels(fracture, topology, triangles, v, &mut parent, &mut labels) as u32);
    }
    (labels, counts)
}

/// Splits the fans of every vertex in `vertices` (see the module doc); returns how many vertices
/// were added. `topology` describes the triangles before this call.
///
/// The fans of all the vertices are found first, on the triangles before any split (a split
/// renames only the corners of its own vertex, which another vertex's fans do not read), half
/// of them on another thread with a `pool`; then the splits, in the order of `vertices`. In the
/// issue-5 balloon's fracture storm (benches/body_balloon.rs, 1,300-1,800 vertices a step) the
/// fans took 0.7-1.1 ms of a 1.5-1.9 ms split, found one vertex at a time with a few small
/// vectors each.
pub(crate) fn split_fans(
    fracture: &mut Fracture,
    topology: &Topology,
    triangles: &mut [[u32; 3]],
    nodes: &mut Nodes,
    vertices: &[u32],
    pool: Option<&WorkerPool>,
) -> usize {
    let before = nodes.len();
    let ((mut labels, mut counts), (more_labels, more_counts)) = {
        let (fracture, triangles) = (&*fracture, &*triangles);
        let half = vertices.len() / 2;
        let labels_of = |part: &[u32]| all_fan_labels(fracture, topology, triangles, part);
        match pool.filter(|p| p.threads() > 1 && half > 0) {
            Some(pool) => pool.join(|| labels_of(&vertices[..half]), || labels_of(&vertices[half..])),
            None => (labels_of(vertices), (Vec::new(), Vec::new())),
        }
    };
    labels.extend(more_labels);
    counts.extend(more_counts);
    let mut areas = Vec::new();
    let mut offset = 0;
    for (&v, &count) in vertices.iter().zip(&counts) {
        let faces = topology.faces_of_vertex(v);
        let own = &labels[offset..offset + faces.len()];
        offset += faces.len();
        let count = count as usize;
        if count < 2 {
            continue;
        }
        areas.clear();
        areas.resize(count, 0.0f64);
        for (&f, &label) in faces.iter().zip(own) {
            areas[label as usize] += triangle_area(nodes, triangles[f as usize]);
        }
        // Each fan's share of the rest area, at least MIN_FAN_SHARE (then all scaled to sum to
        // 1): a sliver fan's copy got a mass whose f32 inverse overflows (8.5e-41 kg beside
        // faces a million times larger: every later step was NaN; found by review).
        let total: f64 = areas.iter().sum();
        for a in areas.iter_mut() {
            *a = if total > 0.0 { (*a / total).max(MIN_FAN_SHARE) } else { 1.0 };
        }
        let total: f64 = areas.iter().sum();
        let vi = v as usize;
        let mass = nodes.mass[vi] as f64;
        let share = |k: usize| areas[k] / total;
        let (x, vel, rest) = (nodes.x[vi], nodes.v[vi], nodes.rest[vi]);
        let mut given = 0.0f64;
        for k in 1..count {
            let m = (mass * share(k)) as f32;
            given += m as f64;
            let copy = fracture.add_vertex(nodes, vi, x, vel, m, rest);
            for (&f, _) in faces.iter().zip(own).filter(|&(_, &label)| label as usize == k) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::torus_grid;
    use glam::Vec3;

    /// The fans of `v` by flood fill: its faces, joined through a side at `v` whose edge has
    /// two or more faces and is not broken (`edge_is_broken`), to every other face of `v` on
    /// that edge; each fan sorted, in order of its first face.
    fn flood_fans(fracture: &Fracture, topology: &Topology, triangles: &[[u32; 3]], v: u32) -> Vec<Vec<u32>> {
        let faces = topology.faces_of_vertex(v);
        let mut fan = vec![usize::MAX; faces.len()];
        let mut fans: Vec<Vec<u32>> = Vec::new();
        for start in 0..faces.len() {
            if fan[start] != usize::MAX {
                continue;
            }
            let k = fans.len();
            let mut stack = vec![start];
            fan[start] = k;
            let mut members = Vec::new();
            while let Some(i) = stack.pop() {
                let f = faces[i];
                members.push(f);
                for side in 0..3 {
                    let t = triangles[f as usize];
                    let e = topology.face_edges[f as usize][side];
                    if (t[side] != v && t[(side + 1) % 3] != v)
                        || e == u32::MAX
                        || edge_is_broken(topology, Some(fracture), e)
                    {
                        continue;
                    }
                    let (a, b) = (t[side], t[(side + 1) % 3]);
                    for (j, &g) in faces.iter().enumerate() {
                        let u = triangles[g as usize];
                        let on_edge = g != f && u.contains(&a) && u.contains(&b);
                        if on_edge && fan[j] == usize::MAX {
                            fan[j] = k;
                            stack.push(j);
                        }
                    }
                }
            }
            members.sort_unstable();
            fans.push(members);
        }
        fans
    }

    /// A torus grid with random edges broken: the fans of every end vertex are those of a flood
    /// fill, and the splits (fans found on two threads or on one) give the same bits, keep the
    /// mass and place every copy on its origin.
    #[test]
    fn fans_match_a_flood_fill_and_splits_do_not_depend_on_the_threads() {
        let (nu, nv) = (14u32, 11u32);
        let triangles = torus_grid(nu, nv);
        let topology = Topology::build(&triangles, (nu * nv) as usize);
        let mut random = crate::body::test_randoms(0x00c0_ffee);
        let mut nodes = Nodes::default();
        for i in 0..nu {
            for j in 0..nv {
                let (a, b) =
                    (i as f32 / nu as f32 * std::f32::consts::TAU, j as f32 / nv as f32 * std::f32::consts::TAU);
                let p = Vec3::new((2.0 + b.cos()) * a.cos(), (2.0 + b.cos()) * a.sin(), b.sin());
                nodes.x.push(p);
                nodes.rest.push(p);
                nodes.v.push(Vec3::new(random(), random(), random()));
                nodes.mass.push(1.0 + random().abs());
                nodes.inv_mass.push(1.0);
            }
        }
        for round in 0..20 {
            let mut fracture = Fracture::new(nodes.len(), triangles.len());
            let share = 0.05 + 0.04 * round as f32;
            let edges: Vec<u32> = (0..topology.edges.len() as u32).filter(|_| random().abs() < share).collect();
            mark_broken(&mut fracture, &topology, &edges);
            let mut vertices: Vec<u32> = edges.iter().flat_map(|&e| topology.edges[e as usize]).collect();
            vertices.sort_unstable();
            vertices.dedup();
            let (mut labels, mut parent) = (Vec::new(), Vec::new());
            for &v in &vertices {
                labels.clear();
                let count = fan_labels(&fracture, &topology, &triangles, v, &mut parent, &mut labels);
                let mut fans = vec![Vec::new(); count];
                for (&face, &label) in topology.faces_of_vertex(v).iter().zip(&labels) {
                    fans[label as usize].push(face);
                }
                assert_eq!(fans, flood_fans(&fracture, &topology, &triangles, v), "round {round}, vertex {v}");
            }
            let pool = WorkerPool::new(2).unwrap();
            let split = |pool: Option<&WorkerPool>| {
                let mut fracture = Fracture::new(nodes.len(), triangles.len());
                mark_broken(&mut fracture, &topology, &edges);
                let (mut nodes, mut triangles) = (nodes.clone(), triangles.to_vec());
                let added = split_fans(&mut fracture, &topology, &mut triangles, &mut nodes, &vertices, pool);
                (added, triangles, nodes.x, nodes.mass, fracture.origin)
            };
            let (serial, parallel) = (split(None), split(Some(&pool)));
            assert_eq!(serial, parallel, "round {round}");
            let (added, _, x, mass, origin) = serial;
            assert!(round < 3 || added > 0, "round {round}: cracks that open");
            let total = |m: &[f32]| m.iter().map(|&m| m as f64).sum::<f64>();
            assert!((total(&mass) - total(&nodes.mass)).abs() < 1e-4, "round {round}: mass kept");
            assert!((nodes.len()..x.len()).all(|i| x[i] == nodes.x[origin[i] as usize]), "round {round}");
        }
    }
}
