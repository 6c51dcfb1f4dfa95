//! Connectivity of a triangle mesh: undirected edges with their faces, the faces around each
//! vertex, boundary loops, connected components and orientation consistency.
//!
//! Built once by sorting half-edges (O(F log F), deterministic), then read by validation, the
//! bending stencils, fracture and the report.

/// Marks a missing face in [`Topology::edge_faces`].
pub(crate) const NO_FACE: u32 = u32::MAX;

/// Connectivity of a triangle mesh. Edges are sorted by `(min, max)` vertex index.
#[derive(Clone, Debug, Default)]
pub struct Topology {
    /// Undirected edges `[a, b]` with `a < b`. Triangle sides whose two ends are the same vertex
    /// (a degenerate triangle) are not edges.
    pub edges: Vec<[u32; 2]>,
    /// The first two faces that use each edge, in face order; [`NO_FACE`] where fewer.
    pub edge_faces: Vec<[u32; 2]>,
    /// How many faces use each edge (1 = boundary, 2 = manifold interior, more = non-manifold).
    pub edge_face_count: Vec<u32>,
    /// For each face, the edge index of its sides (v0,v1), (v1,v2), (v2,v0); `u32::MAX` for a
    /// side whose ends coincide.
    pub face_edges: Vec<[u32; 3]>,
    /// Faces around each vertex in CSR form: faces of vertex v are
    /// `vertex_faces[vertex_face_offsets[v]..vertex_face_offsets[v + 1]]`, in face order.
    pub vertex_face_offsets: Vec<u32>,
    /// See [`Topology::vertex_face_offsets`].
    pub vertex_faces: Vec<u32>,
    /// Interior edges whose two faces run along them in the same direction (inconsistent winding).
    pub inconsistent_edges: Vec<u32>,
    /// Vertices whose faces form more than one fan (a pinch point): not vertex-manifold.
    pub non_manifold_vertices: Vec<u32>,
    /// Closed loops of boundary vertices, each following the winding of its faces.
    pub boundary_loops: Vec<Vec<u32>>,
    /// Connected component of each face (faces sharing a vertex are connected), numbered from 0
    /// in order of first face.
    pub face_components: Vec<u32>,
    /// Number of connected components (vertices used by no face do not count).
    pub component_count: usize,
    /// Number of vertices used by at least one face.
    pub referenced_vertices: usize,
}

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
    /// Builds the connectivity of `triangles` over `vertex_count` vertices (indices in range).
    pub fn build(triangles: &[[u32; 3]], vertex_count: usize) -> Self {
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

        topology.build_vertex_faces(triangles, vertex_count);
        topology.find_non_manifold_vertices(triangles, vertex_count);
        topology.build_boundary_loops(triangles);
        topology.build_components(triangles, vertex_count);
        topology
    }

    fn build_vertex_faces(&mut self, triangles: &[[u32; 3]], vertex_count: usize) {
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
    pub fn faces_of_vertex(&self, v: u32) -> &[u32] {
        let v = v as usize;
        &self.vertex_faces[self.vertex_face_offsets[v] as usize..self.vertex_face_offsets[v + 1] as usize]
    }

    /// Number of fans (groups of faces joined through manifold edges) around vertex `v`.
    pub fn fan_count(&self, triangles: &[[u32; 3]], v: u32) -> usize {
        let faces = self.faces_of_vertex(v);
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

    fn find_non_manifold_vertices(&mut self, triangles: &[[u32; 3]], vertex_count: usize) {
        self.non_manifold_vertices = (0..vertex_count as u32).filter(|&v| self.fan_count(triangles, v) > 1).collect();
    }

    fn build_boundary_loops(&mut self, triangles: &[[u32; 3]]) {
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

    fn build_components(&mut self, triangles: &[[u32; 3]], vertex_count: usize) {
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

    /// Number of edges used by exactly one face.
    pub fn boundary_edge_count(&self) -> usize {
        self.edge_face_count.iter().filter(|&&c| c == 1).count()
    }

    /// Number of edges used by more than two faces.
    pub fn non_manifold_edge_count(&self) -> usize {
        self.edge_face_count.iter().filter(|&&c| c > 2).count()
    }

    /// Heap bytes held by the topology.
    pub fn memory_bytes(&self) -> usize {
        self.edges.capacity() * 8
            + self.edge_faces.capacity() * 8
            + self.edge_face_count.capacity() * 4
            + self.face_edges.capacity() * 12
            + self.vertex_face_offsets.capacity() * 4
            + self.vertex_faces.capacity() * 4
            + self.inconsistent_edges.capacity() * 4
            + self.non_manifold_vertices.capacity() * 4
            + self.boundary_loops.iter().map(|l| l.capacity() * 4).sum::<usize>()
            + self.face_components.capacity() * 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TETRA: [[u32; 3]; 4] = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];

    #[test]
    fn closed_tetrahedron() {
        let t = Topology::build(&TETRA, 4);
        assert_eq!(t.edges.len(), 6);
        assert!(t.edge_face_count.iter().all(|&c| c == 2));
        assert!(t.inconsistent_edges.is_empty());
        assert!(t.non_manifold_vertices.is_empty());
        assert!(t.boundary_loops.is_empty());
        assert_eq!(t.component_count, 1);
        assert_eq!(t.faces_of_vertex(0), &[0, 1, 3]);
    }

    #[test]
    fn open_tetrahedron_has_one_boundary_loop_in_winding_order() {
        let t = Topology::build(&TETRA[..3], 4);
        assert_eq!(t.boundary_edge_count(), 3);
        assert_eq!(t.boundary_loops.len(), 1);
        let mut boundary = t.boundary_loops[0].clone();
        boundary.sort();
        assert_eq!(boundary, vec![0, 2, 3]);
    }

    #[test]
    fn flipped_face_and_pinch_vertex_are_found() {
        let mut flipped = TETRA;
        flipped[2] = [1, 3, 2];
        let t = Topology::build(&flipped, 4);
        assert_eq!(t.inconsistent_edges.len(), 3);

        // Two tetrahedra sharing vertex 0 only: one pinch vertex, two components? No: one component.
        let mut two = TETRA.to_vec();
        two.extend(TETRA.iter().map(|f| f.map(|v| if v == 0 { 0 } else { v + 3 })));
        let t = Topology::build(&two, 7);
        assert_eq!(t.non_manifold_vertices, vec![0]);
        assert_eq!(t.component_count, 1);
    }
}
