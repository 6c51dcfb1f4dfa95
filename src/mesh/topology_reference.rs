//! The first implementation of [`Topology::build`] (a comparison sort of all half-edges and a
//! per-vertex fan search), kept for the tests only: the fast build must give identical output.

use super::{NO_FACE, Topology};

struct HalfEdge {
    key: (u32, u32),
    face: u32,
    side: u8,
    forward: bool,
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let grand = parent[parent[x as usize] as usize];
        parent[x as usize] = grand;
        x = grand;
    }
    x
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        // Smaller root wins so that the result does not depend on the order of unions.
        let (low, high) = if ra < rb { (ra, rb) } else { (rb, ra) };
        parent[high as usize] = low;
    }
}

impl Topology {
    /// The connectivity as the first implementation built it (a comparison sort of half-edges).
    pub(super) fn build_reference(triangles: &[[u32; 3]], vertex_count: usize) -> Self {
        let mut half_edges = Vec::with_capacity(triangles.len() * 3);
        for (face, t) in triangles.iter().enumerate() {
            for side in 0..3 {
                let (a, b) = (t[side], t[(side + 1) % 3]);
                if a != b {
                    let key = if a < b { (a, b) } else { (b, a) };
                    half_edges.push(HalfEdge { key, face: face as u32, side: side as u8, forward: a < b });
                }
            }
        }
        half_edges.sort_unstable_by_key(|h| (h.key, h.face, h.side));

        let mut topology = Topology { face_edges: vec![[u32::MAX; 3]; triangles.len()], ..Default::default() };
        let mut start = 0;
        while start < half_edges.len() {
            let key = half_edges[start].key;
            let mut end = start;
            while end < half_edges.len() && half_edges[end].key == key {
                end += 1;
            }
            let edge = topology.edges.len() as u32;
            let group = &half_edges[start..end];
            topology.edges.push([key.0, key.1]);
            topology.edge_face_count.push(group.len() as u32);
            let second = group.get(1).map_or(NO_FACE, |h| h.face);
            topology.edge_faces.push([group[0].face, second]);
            if group.len() == 2 && group[0].forward == group[1].forward {
                topology.inconsistent_edges.push(edge);
            }
            for h in group {
                topology.face_edges[h.face as usize][h.side as usize] = edge;
            }
            start = end;
        }

        topology.reference_build_vertex_faces(triangles, vertex_count);
        topology.reference_find_non_manifold_vertices(triangles, vertex_count);
        topology.reference_build_boundary_loops(triangles);
        topology.reference_build_components(triangles, vertex_count);
        topology
    }

    fn reference_build_vertex_faces(&mut self, triangles: &[[u32; 3]], vertex_count: usize) {
        let mut counts = vec![0u32; vertex_count + 1];
        for t in triangles {
            for (corner, &v) in t.iter().enumerate() {
                // A vertex repeated inside one degenerate triangle is listed once for it.
                if !t[..corner].contains(&v) {
                    counts[v as usize + 1] += 1;
                }
            }
        }
        for v in 0..vertex_count {
            counts[v + 1] += counts[v];
        }
        let mut cursor = counts.clone();
        let mut faces = vec![0u32; counts[vertex_count] as usize];
        for (face, t) in triangles.iter().enumerate() {
            for (corner, &v) in t.iter().enumerate() {
                if !t[..corner].contains(&v) {
                    faces[cursor[v as usize] as usize] = face as u32;
                    cursor[v as usize] += 1;
                }
            }
        }
        self.referenced_vertices = (0..vertex_count).filter(|&v| counts[v + 1] > counts[v]).count();
        self.vertex_face_offsets = counts;
        self.vertex_faces = faces;
    }

    /// Faces around vertex `v`.
    fn reference_faces_of_vertex(&self, v: u32) -> &[u32] {
        let v = v as usize;
        &self.vertex_faces[self.vertex_face_offsets[v] as usize..self.vertex_face_offsets[v + 1] as usize]
    }

    /// Number of fans (groups of faces joined through manifold edges) around vertex `v`.
    fn reference_fan_count(&self, triangles: &[[u32; 3]], v: u32) -> usize {
        let faces = self.reference_faces_of_vertex(v);
        let mut parent: Vec<u32> = (0..faces.len() as u32).collect();
        for (i, &face) in faces.iter().enumerate() {
            for side in 0..3 {
                let t = triangles[face as usize];
                if t[side] != v && t[(side + 1) % 3] != v {
                    continue;
                }
                let edge = self.face_edges[face as usize][side];
                if edge == u32::MAX || self.edge_face_count[edge as usize] != 2 {
                    continue;
                }
                let [f0, f1] = self.edge_faces[edge as usize];
                let other = if f0 == face { f1 } else { f0 };
                if let Some(j) = faces.iter().position(|&f| f == other) {
                    union(&mut parent, i as u32, j as u32);
                }
            }
        }
        (0..faces.len() as u32).filter(|&i| find(&mut parent, i) == i).count()
    }

    fn reference_find_non_manifold_vertices(&mut self, triangles: &[[u32; 3]], vertex_count: usize) {
        self.non_manifold_vertices =
            (0..vertex_count as u32).filter(|&v| self.reference_fan_count(triangles, v) > 1).collect();
    }

    fn reference_build_boundary_loops(&mut self, triangles: &[[u32; 3]]) {
        // Directed boundary half-edges (a -> b as the face runs), keyed by their start vertex.
        let mut outgoing: Vec<(u32, u32)> = Vec::new();
        for (edge, &count) in self.edge_face_count.iter().enumerate() {
            if count != 1 {
                continue;
            }
            let face = self.edge_faces[edge][0] as usize;
            let side = self.face_edges[face].iter().position(|&e| e == edge as u32).unwrap();
            outgoing.push((triangles[face][side], triangles[face][(side + 1) % 3]));
        }
        outgoing.sort_unstable();
        let mut used = vec![false; outgoing.len()];
        for first in 0..outgoing.len() {
            if used[first] {
                continue;
            }
            used[first] = true;
            let start = outgoing[first].0;
            let mut boundary = vec![start];
            let mut next = outgoing[first].1;
            while next != start {
                boundary.push(next);
                let from = outgoing.partition_point(|&(a, _)| a < next);
                let Some(offset) = (from..outgoing.len()).take_while(|&i| outgoing[i].0 == next).find(|&i| !used[i])
                else {
                    break; // an open chain (only at non-manifold boundary vertices)
                };
                used[offset] = true;
                next = outgoing[offset].1;
            }
            self.boundary_loops.push(boundary);
        }
    }

    fn reference_build_components(&mut self, triangles: &[[u32; 3]], vertex_count: usize) {
        let mut parent: Vec<u32> = (0..vertex_count as u32).collect();
        for t in triangles {
            union(&mut parent, t[0], t[1]);
            union(&mut parent, t[1], t[2]);
        }
        let mut label = vec![u32::MAX; vertex_count];
        let mut next = 0u32;
        self.face_components = triangles
            .iter()
            .map(|t| {
                let root = find(&mut parent, t[0]) as usize;
                if label[root] == u32::MAX {
                    label[root] = next;
                    next += 1;
                }
                label[root]
            })
            .collect();
        self.component_count = next as usize;
    }
}
