//! Connectivity of a triangle mesh: undirected edges with their faces, the faces around each
//! vertex, boundary loops, connected components and orientation consistency.
//!
//! Built once in time linear in the mesh size (half-edges bucketed by vertex, then sorted
//! within each vertex's short list; deterministic), then read by validation, the bending
//! stencils, fracture and the report.

/// Marks a missing face in [`Topology::edge_faces`].
pub(crate) const NO_FACE: u32 = u32::MAX;

/// Connectivity of a triangle mesh. Edges are sorted by `(min, max)` vertex index.
#[derive(Clone, Debug, Default, PartialEq)]
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

/// The connected component of each face of `triangles` (faces sharing a vertex are connected),
/// numbered from 0 in order of first face, written into `out`; returns the count. `parent` and
/// `label` are per-vertex scratch (cleared and refilled: an update passes buffers it keeps).
pub(crate) fn components_into(
    triangles: &[[u32; 3]],
    vertex_count: usize,
    parent: &mut Vec<u32>,
    label: &mut Vec<u32>,
    out: &mut Vec<u32>,
) -> usize {
    parent.clear();
    parent.extend(0..vertex_count as u32);
    for t in triangles {
        union(parent, t[0], t[1]);
        union(parent, t[1], t[2]);
    }
    label.clear();
    label.resize(vertex_count, u32::MAX);
    let mut next = 0u32;
    out.clear();
    out.extend(triangles.iter().map(|t| {
        let root = find(parent, t[0]) as usize;
        if label[root] == u32::MAX {
            label[root] = next;
            next += 1;
        }
        label[root]
    }));
    next as usize
}

/// Buckets longer than this are sorted with the library sort instead of by insertion.
const INSERTION_SORT_MAX: usize = 32;

impl Topology {
    /// Builds the connectivity of `triangles` over `vertex_count` vertices (indices in range).
    ///
    /// Linear in the mesh size apart from sorting each vertex's few half-edges: the half-edges
    /// are bucketed by their smaller vertex (a counting sort), each bucket is sorted by the larger
    /// vertex, and the fans around every vertex are found with one union-find over the
    /// (vertex, face) incidences.
    pub fn build(triangles: &[[u32; 3]], vertex_count: usize) -> Self {
        let mut topology = Topology::default();
        topology.build_edges(triangles, vertex_count);
        let corner_slots = topology.build_vertex_faces(triangles, vertex_count);
        topology.find_non_manifold_vertices(triangles, vertex_count, &corner_slots);
        topology.build_boundary_loops(triangles);
        topology.build_components(triangles, vertex_count);
        topology
    }

    /// Edges (sorted by `(a, b)`), their faces and face counts, the faces' edges and the
    /// inconsistently wound edges.
    fn build_edges(&mut self, triangles: &[[u32; 3]], vertex_count: usize) {
        // Bucket a holds the half-edges whose smaller vertex is a, as (larger vertex,
        // 3 face + side), in face and side order: bucket a is entries[start[a]..start[a + 1]].
        let mut start = vec![0u32; vertex_count + 2];
        for t in triangles {
            for side in 0..3 {
                let (a, b) = (t[side], t[(side + 1) % 3]);
                if a != b {
                    start[a.min(b) as usize + 2] += 1;
                }
            }
        }
        for i in 2..start.len() {
            start[i] += start[i - 1];
        }
        let mut entries = vec![(0u32, 0u32); start[vertex_count + 1] as usize];
        for (face, t) in triangles.iter().enumerate() {
            for side in 0..3 {
                let (a, b) = (t[side], t[(side + 1) % 3]);
                if a != b {
                    let slot = &mut start[a.min(b) as usize + 1];
                    entries[*slot as usize] = (a.max(b), 3 * face as u32 + side as u32);
                    *slot += 1;
                }
            }
        }
        start.truncate(vertex_count + 1);
        // Sort each bucket by (larger vertex, half-edge): the order of the old global sort by
        // (key, face, side). Insertion sort is stable and the half-edges are already in order.
        for a in 0..vertex_count {
            let bucket = &mut entries[start[a] as usize..start[a + 1] as usize];
            if bucket.len() > INSERTION_SORT_MAX {
                bucket.sort_unstable();
                continue;
            }
            for i in 1..bucket.len() {
                let item = bucket[i];
                let mut j = i;
                while j > 0 && bucket[j - 1].0 > item.0 {
                    bucket[j] = bucket[j - 1];
                    j -= 1;
                }
                bucket[j] = item;
            }
        }
        let edge_count = (0..vertex_count)
            .map(|a| {
                let bucket = &entries[start[a] as usize..start[a + 1] as usize];
                bucket.iter().enumerate().filter(|&(i, h)| i == 0 || bucket[i - 1].0 != h.0).count()
            })
            .sum();
        self.edges = Vec::with_capacity(edge_count);
        self.edge_faces = Vec::with_capacity(edge_count);
        self.edge_face_count = Vec::with_capacity(edge_count);
        self.face_edges = vec![[u32::MAX; 3]; triangles.len()];
        // Whether half-edge h runs from the smaller vertex to the larger.
        let forward = |h: u32| {
            let (face, side) = ((h / 3) as usize, (h % 3) as usize);
            triangles[face][side] < triangles[face][(side + 1) % 3]
        };
        for a in 0..vertex_count {
            let bucket = &entries[start[a] as usize..start[a + 1] as usize];
            let mut first = 0;
            while first < bucket.len() {
                let b = bucket[first].0;
                let mut end = first + 1;
                while end < bucket.len() && bucket[end].0 == b {
                    end += 1;
                }
                let group = &bucket[first..end];
                let edge = self.edges.len() as u32;
                self.edges.push([a as u32, b]);
                self.edge_face_count.push(group.len() as u32);
                let second = group.get(1).map_or(NO_FACE, |h| h.1 / 3);
                self.edge_faces.push([group[0].1 / 3, second]);
                if group.len() == 2 && forward(group[0].1) == forward(group[1].1) {
                    self.inconsistent_edges.push(edge);
                }
                for &(_, h) in group {
                    self.face_edges[(h / 3) as usize][(h % 3) as usize] = edge;
                }
                first = end;
            }
        }
    }

    /// The faces around each vertex (CSR). Returns for each corner (3 face + corner) its slot in
    /// `vertex_faces` (a corner repeating an earlier corner's vertex shares that corner's slot).
    fn build_vertex_faces(&mut self, triangles: &[[u32; 3]], vertex_count: usize) -> Vec<u32> {
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
        let mut corner_slots = vec![0u32; 3 * triangles.len()];
        for (face, t) in triangles.iter().enumerate() {
            for (corner, &v) in t.iter().enumerate() {
                corner_slots[3 * face + corner] = match t[..corner].iter().position(|&u| u == v) {
                    Some(earlier) => corner_slots[3 * face + earlier],
                    None => {
                        let slot = cursor[v as usize];
                        faces[slot as usize] = face as u32;
                        cursor[v as usize] += 1;
                        slot
                    }
                };
            }
        }
        self.referenced_vertices = (0..vertex_count).filter(|&v| counts[v + 1] > counts[v]).count();
        self.vertex_face_offsets = counts;
        self.vertex_faces = faces;
        corner_slots
    }

    /// Faces around vertex `v`.
    pub fn faces_of_vertex(&self, v: u32) -> &[u32] {
        let v = v as usize;
        &self.vertex_faces[self.vertex_face_offsets[v] as usize..self.vertex_face_offsets[v + 1] as usize]
    }

    /// Number of fans (groups of faces joined through manifold edges) around vertex `v`.
    pub fn fan_count(&self, triangles: &[[u32; 3]], v: u32) -> usize {
        let faces = self.faces_of_vertex(v);
        // The union-find on the stack for the usual few faces (an update asks this of thousands
        // of vertices: a vector each was an allocation each).
        let mut on_stack = [0u32; 32];
        let mut on_heap = Vec::new();
        let parent: &mut [u32] = if faces.len() <= on_stack.len() {
            &mut on_stack[..faces.len()]
        } else {
            on_heap.resize(faces.len(), 0);
            &mut on_heap
        };
        parent.iter_mut().enumerate().for_each(|(i, p)| *p = i as u32);
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
                    union(parent, i as u32, j as u32);
                }
            }
        }
        (0..faces.len() as u32).filter(|&i| find(parent, i) == i).count()
    }

    /// Vertices with more than one fan ([`Topology::fan_count`] for all vertices at once): a
    /// union-find over the (vertex, face) slots of `vertex_faces`, where each manifold edge joins
    /// its two faces at both of its ends.
    fn find_non_manifold_vertices(&mut self, triangles: &[[u32; 3]], vertex_count: usize, corner_slots: &[u32]) {
        let mut parent: Vec<u32> = (0..self.vertex_faces.len() as u32).collect();
        let slot = |face: u32, v: u32| {
            let t = triangles[face as usize];
            let corner = if t[0] == v {
                0
            } else if t[1] == v {
                1
            } else {
                2
            };
            corner_slots[3 * face as usize + corner]
        };
        for (e, &[a, b]) in self.edges.iter().enumerate() {
            let [f0, f1] = self.edge_faces[e];
            if self.edge_face_count[e] != 2 || f0 == f1 {
                continue;
            }
            union(&mut parent, slot(f0, a), slot(f1, a));
            union(&mut parent, slot(f0, b), slot(f1, b));
        }
        self.non_manifold_vertices = (0..vertex_count)
            .filter(|&v| {
                let range = self.vertex_face_offsets[v]..self.vertex_face_offsets[v + 1];
                range.filter(|&i| find(&mut parent, i) == i).nth(1).is_some()
            })
            .map(|v| v as u32)
            .collect();
    }

    fn build_boundary_loops(&mut self, triangles: &[[u32; 3]]) {
        self.boundary_loops = self.boundary_loops_of(triangles);
    }

    /// The boundary loops of [`Topology::boundary_loops`], from the edges and face edges.
    fn boundary_loops_of(&self, triangles: &[[u32; 3]]) -> Vec<Vec<u32>> {
        let mut loops = Vec::new();
        // Directed boundary half-edges (a -> b as the face runs), grouped by their start vertex
        // a (counted, then placed: a sort of all of them took a third of this in a fracture
        // storm of the issue-5 balloon, some 5,000 of them), each group in order of b; so the
        // walks below visit them in the order of the pairs (a, b).
        let vertex_count = self.vertex_face_offsets.len().saturating_sub(1);
        let boundary = |edge: usize| {
            let face = self.edge_faces[edge][0] as usize;
            let side = self.face_edges[face].iter().position(|&e| e == edge as u32).unwrap();
            (triangles[face][side], triangles[face][(side + 1) % 3])
        };
        let mut start = vec![0u32; vertex_count + 2];
        for (edge, _) in self.edge_face_count.iter().enumerate().filter(|&(_, &count)| count == 1) {
            start[boundary(edge).0 as usize + 2] += 1;
        }
        for v in 2..vertex_count + 2 {
            start[v] += start[v - 1];
        }
        let mut end = vec![0u32; start[vertex_count + 1] as usize];
        for (edge, _) in self.edge_face_count.iter().enumerate().filter(|&(_, &count)| count == 1) {
            let (a, b) = boundary(edge);
            let slot = &mut start[a as usize + 1];
            end[*slot as usize] = b;
            *slot += 1;
        }
        start.pop();
        // `start[a]..start[a + 1]`: the ends of the half-edges from a.
        for a in 0..vertex_count {
            let group = &mut end[start[a] as usize..start[a + 1] as usize];
            if group.len() > 1 {
                group.sort_unstable();
            }
        }
        let mut used = vec![false; end.len()];
        for first in 0..end.len() {
            if used[first] {
                continue;
            }
            used[first] = true;
            let begin = start.partition_point(|&s| s as usize <= first) as u32 - 1;
            let mut boundary = vec![begin];
            let mut next = end[first];
            while next != begin {
                boundary.push(next);
                let group = start[next as usize] as usize..start[next as usize + 1] as usize;
                let Some(offset) = group.into_iter().find(|&i| !used[i]) else {
                    break; // an open chain (only at non-manifold boundary vertices)
                };
                used[offset] = true;
                next = end[offset];
            }
            loops.push(boundary);
        }
        loops
    }

    fn build_components(&mut self, triangles: &[[u32; 3]], vertex_count: usize) {
        let mut components = std::mem::take(&mut self.face_components);
        self.component_count =
            components_into(triangles, vertex_count, &mut Vec::new(), &mut Vec::new(), &mut components);
        self.face_components = components;
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
            + self.boundary_loops.capacity() * std::mem::size_of::<Vec<u32>>()
            + self.boundary_loops.iter().map(|l| l.capacity() * 4).sum::<usize>()
            + self.face_components.capacity() * 4
    }
}

#[path = "topology_update.rs"]
mod update;
pub use update::TopologySpare;

#[cfg(test)]
#[path = "topology_reference.rs"]
mod reference;

/// A closed triangulated torus grid of `nu` x `nv` quads (vertex `(i, j)` is `i nv + j`), for
/// tests.
#[cfg(test)]
pub(crate) fn torus_grid(nu: u32, nv: u32) -> Vec<[u32; 3]> {
    let id = |i: u32, j: u32| (i % nu) * nv + j % nv;
    let mut t = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            t.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            t.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    t
}

/// A small deterministic generator (xorshift64*) for the tests of the topology and its update.
#[cfg(test)]
pub(crate) mod tests_rng {
    pub(crate) struct Rng(pub u64);

    impl Rng {
        pub(crate) fn below(&mut self, n: u32) -> u32 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            ((self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 32) % n as u64) as u32
        }
    }
}

#[cfg(test)]
mod tests {
    use super::tests_rng::Rng;
    use super::*;

    /// Asserts that the fast build gives exactly what the reference build gives.
    fn assert_same_as_reference(triangles: &[[u32; 3]], vertex_count: usize, what: &str) -> Topology {
        let fast = Topology::build(triangles, vertex_count);
        let slow = Topology::build_reference(triangles, vertex_count);
        assert_same(&fast, &slow, what);
        for v in 0..vertex_count as u32 {
            let pinch = fast.fan_count(triangles, v) > 1;
            assert_eq!(pinch, fast.non_manifold_vertices.binary_search(&v).is_ok(), "{what}: fan count of {v}");
        }
        fast
    }

    fn assert_same(fast: &Topology, slow: &Topology, what: &str) {
        assert_eq!(fast.edges, slow.edges, "{what}: edges");
        assert_eq!(fast.edge_faces, slow.edge_faces, "{what}: edge_faces");
        assert_eq!(fast.edge_face_count, slow.edge_face_count, "{what}: edge_face_count");
        assert_eq!(fast.face_edges, slow.face_edges, "{what}: face_edges");
        assert_eq!(fast.vertex_face_offsets, slow.vertex_face_offsets, "{what}: vertex_face_offsets");
        assert_eq!(fast.vertex_faces, slow.vertex_faces, "{what}: vertex_faces");
        assert_eq!(fast.inconsistent_edges, slow.inconsistent_edges, "{what}: inconsistent_edges");
        assert_eq!(fast.non_manifold_vertices, slow.non_manifold_vertices, "{what}: non_manifold_vertices");
        assert_eq!(fast.boundary_loops, slow.boundary_loops, "{what}: boundary_loops");
        assert_eq!(fast.face_components, slow.face_components, "{what}: face_components");
        assert_eq!(fast.component_count, slow.component_count, "{what}: component_count");
        assert_eq!(fast.referenced_vertices, slow.referenced_vertices, "{what}: referenced_vertices");
    }

    /// The triangles and vertex count of an OBJ file of data/ (the crate's reader: file vertex
    /// order, polygons as fans).
    #[cfg(feature = "obj")]
    fn read_obj(name: &str) -> (Vec<[u32; 3]>, usize) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data").join(name);
        let mesh = crate::mesh::load_obj(&path).unwrap();
        (mesh.triangles().to_vec(), mesh.vertex_count())
    }

    /// A random mesh: a torus grid with holes, flips, pinches (vertices merged), degenerate
    /// triangles, duplicated faces (non-manifold edges), stray triangles, unused vertices, and
    /// sometimes a separate tetrahedron and a fan of many faces around one vertex.
    fn random_mesh(rng: &mut Rng, case: usize) -> (Vec<[u32; 3]>, u32) {
        let (nu, nv) = (3 + rng.below(6), 3 + rng.below(6));
        let mut triangles = torus_grid(nu, nv);
        let mut vertices = nu * nv + rng.below(4);
        triangles.retain(|_| rng.below(8) != 0);
        for t in triangles.iter_mut() {
            match rng.below(30) {
                0 => t.swap(0, 1),
                1 => t[2] = t[0],
                2 => t[1] = t[2],
                3 => *t = [t[0]; 3],
                4 => t[rng.below(3) as usize] = rng.below(vertices),
                _ => {}
            }
        }
        for _ in 0..rng.below(3) {
            let (from, to) = (rng.below(vertices), rng.below(vertices));
            for t in triangles.iter_mut() {
                t.iter_mut().filter(|c| **c == from).for_each(|c| *c = to);
            }
        }
        for _ in 0..rng.below(4) {
            if !triangles.is_empty() {
                let copy = triangles[rng.below(triangles.len() as u32) as usize];
                triangles.push(if rng.below(2) == 0 { copy } else { [copy[0], copy[2], copy[1]] });
            }
            triangles.push([rng.below(vertices), rng.below(vertices), rng.below(vertices)]);
        }
        if case % 3 == 1 {
            // A separate closed piece.
            triangles.extend(TETRA.iter().map(|t| t.map(|v| v + vertices)));
            vertices += 4;
        }
        if case % 10 == 0 {
            // A fan of many faces around one vertex: its bucket takes the library sort.
            let hub = vertices;
            let ring = 40 + rng.below(40);
            for k in 0..ring {
                triangles.push([hub, hub + 1 + k, hub + 1 + (k + 1) % ring]);
            }
            vertices += ring + 1;
        }
        (triangles, vertices)
    }

    #[test]
    #[cfg(feature = "obj")]
    fn fast_build_matches_the_reference_on_the_shared_meshes() {
        for name in ["sphere.obj", "torus.obj", "eight.obj", "hand.obj", "kitten.obj", "bear.obj", "wapiti_elk.obj"] {
            let (triangles, vertices) = read_obj(name);
            assert_same_as_reference(&triangles, vertices, name);
            // The same faces in another order, with some flipped and some removed (boundaries).
            let mut rng = Rng(0x9e37_79b9_7f4a_7c15 ^ triangles.len() as u64);
            let mut shuffled = triangles.clone();
            for i in (1..shuffled.len()).rev() {
                shuffled.swap(i, rng.below(i as u32 + 1) as usize);
            }
            shuffled.retain(|_| rng.below(10) != 0);
            for t in shuffled.iter_mut().filter(|_| rng.below(20) == 0) {
                t.swap(1, 2);
            }
            assert_same_as_reference(&shuffled, vertices, &format!("{name} shuffled, holed, flipped"));
        }
    }

    #[test]
    fn fast_build_matches_the_reference_on_random_meshes() {
        let mut rng = Rng(12345);
        // Cases with pinch vertices, non-manifold edges, inconsistent edges, boundary loops,
        // degenerate sides, several components.
        let mut seen = [0; 6];
        for case in 0..300 {
            let (triangles, vertices) = random_mesh(&mut rng, case);
            let t = assert_same_as_reference(&triangles, vertices as usize, &format!("random case {case}"));
            let features = [
                !t.non_manifold_vertices.is_empty(),
                t.non_manifold_edge_count() > 0,
                !t.inconsistent_edges.is_empty(),
                !t.boundary_loops.is_empty(),
                t.face_edges.iter().flatten().any(|&e| e == u32::MAX),
                t.component_count > 1,
            ];
            for (count, present) in seen.iter_mut().zip(features) {
                *count += present as usize;
            }
        }
        eprintln!("{seen:?}");
        assert!(seen.iter().all(|&c| c >= 30), "each feature must show up in many cases: {seen:?}");
        assert_same_as_reference(&[], 0, "empty");
        assert_same_as_reference(&[], 5, "no faces");
    }

    /// Cracks: corners of whole fans re-instanced with new vertices (as the fracture does).
    fn split_some_fans(rng: &mut Rng, topology: &Topology, triangles: &mut [[u32; 3]], vertices: &mut u32) {
        let known = topology.vertex_face_offsets.len() as u32 - 1;
        for _ in 0..1 + rng.below(6) {
            let v = rng.below(known);
            let faces = topology.faces_of_vertex(v).to_vec();
            if faces.is_empty() {
                continue;
            }
            let copy = *vertices;
            *vertices += 1 + rng.below(2);
            for &f in faces.iter().filter(|_| rng.below(2) == 0) {
                triangles[f as usize].iter_mut().filter(|c| **c == v).for_each(|c| *c = copy);
            }
        }
    }

    #[test]
    fn update_gives_the_same_as_a_new_build() {
        let mut rng = Rng(777);
        for case in 0..300 {
            let (mut triangles, mut vertices) = random_mesh(&mut rng, case);
            let mut topology = Topology::build(&triangles, vertices as usize);
            // Every other case updates through buffers it keeps, as the fracture does (each
            // update swaps them with the topology's own: stale contents must never leak).
            // ... all of those with a pool of 1, 2 or 3 threads (the components, the fans and the
            // boundary loops found on other threads).
            let pool = (case % 2 == 0).then(|| crate::parallel::WorkerPool::new(1 + (case as u32 / 2) % 3).unwrap());
            let mut spare = (case % 2 == 0).then(|| {
                topology.reserve_headroom(0.1);
                TopologySpare::for_topology(&topology, 0.1)
            });
            for round in 0..4 {
                let old = triangles.clone();
                match rng.below(4) {
                    0 => split_some_fans(&mut rng, &topology, &mut triangles, &mut vertices),
                    1 => {
                        // Random corners anywhere, some faces appended (core blocks), new vertices.
                        for _ in 0..rng.below(5) {
                            if !triangles.is_empty() {
                                let f = rng.below(triangles.len() as u32) as usize;
                                triangles[f][rng.below(3) as usize] = rng.below(vertices + 2);
                            }
                        }
                        for _ in 0..rng.below(4) {
                            triangles.push([rng.below(vertices + 2), rng.below(vertices + 2), vertices + rng.below(2)]);
                        }
                        vertices += 2;
                    }
                    2 => vertices += rng.below(3), // only new (unused) vertices
                    _ => split_some_fans(&mut rng, &topology, &mut triangles, &mut vertices),
                }
                match spare.as_mut() {
                    Some(spare) => topology.update_with(&old, &triangles, vertices as usize, spare, pool.as_ref()),
                    None => topology.update(&old, &triangles, vertices as usize),
                }
                let built = Topology::build(&triangles, vertices as usize);
                assert_same(&topology, &built, &format!("case {case}, round {round}"));
            }
        }
        #[cfg(feature = "obj")]
        {
            let (triangles, vertices) = read_obj("kitten.obj");
            let mut topology = Topology::build(&triangles, vertices);
            let (mut cracked, mut count) = (triangles.clone(), vertices as u32);
            split_some_fans(&mut rng, &topology, &mut cracked, &mut count);
            topology.update(&triangles, &cracked, count as usize);
            assert_same(&topology, &Topology::build(&cracked, count as usize), "kitten cracked");
        }
    }

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
