//! Broad phase of self-collision for a triangle mesh moving over one step (SPEC 1.6): swept
//! boxes of vertices, edges and faces in three BVHs, refit every step and rebuilt when loose,
//! and the vertex-face and edge-edge pairs whose swept boxes come within the thickness.
//! Pairs that share a vertex are skipped (a vertex against a face it belongs to, two edges of
//! one vertex). Knows nothing of the simulator that moves the mesh.

use super::bvh::{Aabb, Bvh};
use super::filters::V3;

/// Candidate pairs of one step.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Candidates {
    /// (vertex, triangle) pairs, sorted.
    pub vertex_face: Vec<(u32, u32)>,
    /// (edge, edge) pairs with the first index smaller, sorted.
    pub edge_edge: Vec<(u32, u32)>,
}

/// The swept boxes of a mesh's vertices, edges and faces in BVHs kept across steps.
#[derive(Clone, Debug)]
pub struct MeshBroadPhase {
    vertices: Bvh,
    edges: Bvh,
    faces: Bvh,
    /// The boxes in f64: the trees hold them rounded out to f32, so the pairs they report are
    /// confirmed here.
    vertex_boxes: Vec<Aabb>,
    edge_boxes: Vec<Aabb>,
    face_boxes: Vec<Aabb>,
    /// Rebuilds (of any of the three trees) since creation.
    pub rebuilds: u64,
}

/// Swept boxes: each primitive's box over its points at both ends of the step, grown by half the
/// thickness, so two boxes overlap whenever the primitives come within `thickness`.
fn swept_boxes<const N: usize>(x0: &[V3], x1: &[V3], prims: &[[u32; N]], half: f64) -> Vec<Aabb> {
    prims
        .iter()
        .map(|prim| {
            let mut points = [[0.0; 3]; 8];
            for (k, &v) in prim.iter().enumerate() {
                points[2 * k] = x0[v as usize];
                points[2 * k + 1] = x1[v as usize];
            }
            Aabb::around(&points[..2 * N], half)
        })
        .collect()
}

fn vertex_ids(count: usize) -> Vec<[u32; 1]> {
    (0..count as u32).map(|v| [v]).collect()
}

impl MeshBroadPhase {
    /// Builds the trees for vertices at `x0` (start of step) moving to `x1` (end), with the
    /// given `edges` (vertex pairs) and `triangles`. `thickness` >= 0 is the contact distance.
    pub fn new(x0: &[V3], x1: &[V3], edges: &[[u32; 2]], triangles: &[[u32; 3]], thickness: f64) -> Self {
        let half = 0.5 * thickness;
        let vertex_boxes = swept_boxes(x0, x1, &vertex_ids(x0.len()), half);
        let edge_boxes = swept_boxes(x0, x1, edges, half);
        let face_boxes = swept_boxes(x0, x1, triangles, half);
        Self {
            vertices: Bvh::build(vertex_boxes.clone()),
            edges: Bvh::build(edge_boxes.clone()),
            faces: Bvh::build(face_boxes.clone()),
            vertex_boxes,
            edge_boxes,
            face_boxes,
            rebuilds: 0,
        }
    }

    /// Refits the trees to a new step (same mesh, new positions); rebuilds the ones that became
    /// loose. Returns how many were rebuilt.
    pub fn update(&mut self, x0: &[V3], x1: &[V3], edges: &[[u32; 2]], triangles: &[[u32; 3]], thickness: f64) -> u32 {
        let half = 0.5 * thickness;
        self.vertex_boxes = swept_boxes(x0, x1, &vertex_ids(x0.len()), half);
        self.edge_boxes = swept_boxes(x0, x1, edges, half);
        self.face_boxes = swept_boxes(x0, x1, triangles, half);
        let rebuilt = u32::from(self.vertices.update(&self.vertex_boxes))
            + u32::from(self.edges.update(&self.edge_boxes))
            + u32::from(self.faces.update(&self.face_boxes));
        self.rebuilds += u64::from(rebuilt);
        rebuilt
    }

    /// The candidate pairs of the current step into `out` (cleared first).
    pub fn candidates(&self, edges: &[[u32; 2]], triangles: &[[u32; 3]], out: &mut Candidates) {
        out.vertex_face.clear();
        out.edge_edge.clear();
        let (vb, eb, fb) = (&self.vertex_boxes, &self.edge_boxes, &self.face_boxes);
        self.vertices.for_each_overlap(&self.faces, |v, f| {
            if !triangles[f as usize].contains(&v) && vb[v as usize].overlaps(&fb[f as usize]) {
                out.vertex_face.push((v, f));
            }
        });
        self.edges.for_each_self_overlap(|i, j| {
            let [a, b] = edges[i as usize];
            let [c, d] = edges[j as usize];
            if a != c && a != d && b != c && b != d && eb[i as usize].overlaps(&eb[j as usize]) {
                out.edge_edge.push((i, j));
            }
        });
        out.vertex_face.sort_unstable();
        out.edge_edge.sort_unstable();
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // brute-force references read clearer with indices
mod tests {
    use super::*;
    use crate::mesh::Topology;

    struct Rng(u64);
    impl Rng {
        fn unit(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// A crumpled n x n grid sheet: vertices, triangles.
    fn sheet(n: usize, rng: &mut Rng) -> (Vec<V3>, Vec<[u32; 3]>) {
        let mut x = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let z = 0.3 * (rng.unit() - 0.5) + 0.5 * ((i as f64) * 0.7).sin() * ((j as f64) * 0.5).cos();
                x.push([i as f64 / n as f64, j as f64 / n as f64, z / n as f64 * 4.0]);
            }
        }
        let mut tris = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let v = (j * n + i) as u32;
                let n = n as u32;
                tris.push([v, v + 1, v + n + 1]);
                tris.push([v, v + n + 1, v + n]);
            }
        }
        (x, tris)
    }

    fn brute_force(x0: &[V3], x1: &[V3], edges: &[[u32; 2]], tris: &[[u32; 3]], thickness: f64) -> Candidates {
        let half = 0.5 * thickness;
        let vb = swept_boxes(x0, x1, &vertex_ids(x0.len()), half);
        let eb = swept_boxes(x0, x1, edges, half);
        let fb = swept_boxes(x0, x1, tris, half);
        let mut out = Candidates::default();
        for v in 0..x0.len() {
            for (f, tri) in tris.iter().enumerate() {
                if !tri.contains(&(v as u32)) && vb[v].overlaps(&fb[f]) {
                    out.vertex_face.push((v as u32, f as u32));
                }
            }
        }
        for i in 0..edges.len() {
            for j in i + 1..edges.len() {
                let ([a, b], [c, d]) = (edges[i], edges[j]);
                if a != c && a != d && b != c && b != d && eb[i].overlaps(&eb[j]) {
                    out.edge_edge.push((i as u32, j as u32));
                }
            }
        }
        out
    }

    fn moved(x: &[V3], rng: &mut Rng, amount: f64) -> Vec<V3> {
        x.iter().map(|p| std::array::from_fn(|k| p[k] + amount * (rng.unit() - 0.5))).collect()
    }

    #[test]
    fn candidates_match_brute_force_across_refits_and_rebuilds() {
        let mut rng = Rng(0xDEAD_BEEF_1234_5678);
        let (x, tris) = sheet(12, &mut rng);
        let edges = Topology::build(&tris, x.len()).edges;
        let thickness = 0.01;
        let mut x0 = x.clone();
        let mut x1 = moved(&x0, &mut rng, 0.05);
        let mut broad = MeshBroadPhase::new(&x0, &x1, &edges, &tris, thickness);
        let mut found = Candidates::default();
        let mut rebuilt = 0;
        for step in 0..12 {
            if step > 0 {
                x0 = x1;
                // Larger and larger motions eventually loosen the trees enough to rebuild.
                x1 = moved(&x0, &mut rng, 0.02 * step as f64);
                rebuilt += broad.update(&x0, &x1, &edges, &tris, thickness);
            }
            broad.candidates(&edges, &tris, &mut found);
            let expected = brute_force(&x0, &x1, &edges, &tris, thickness);
            assert_eq!(found, expected, "step {step}");
            assert!(!expected.vertex_face.is_empty() && !expected.edge_edge.is_empty());
        }
        assert!(rebuilt > 0, "large motions must trigger a rebuild");
        assert_eq!(broad.rebuilds, u64::from(rebuilt));
    }

    #[test]
    fn far_apart_pieces_have_no_candidates_and_pairs_sharing_a_vertex_are_skipped() {
        // Two triangles far apart, and one triangle alone (all its pairs share vertices).
        let x =
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [5.0, 0.0, 0.0], [6.0, 0.0, 0.0], [5.0, 1.0, 0.0]];
        let tris = vec![[0, 1, 2], [3, 4, 5]];
        let edges = Topology::build(&tris, x.len()).edges;
        let broad = MeshBroadPhase::new(&x, &x, &edges, &tris, 0.1);
        let mut found = Candidates::default();
        broad.candidates(&edges, &tris, &mut found);
        assert_eq!(found, Candidates::default());
        // Move the second triangle onto the first: now there are candidates.
        let x1: Vec<V3> =
            x.iter().enumerate().map(|(i, p)| if i >= 3 { [p[0] - 5.0, p[1], p[2]] } else { *p }).collect();
        let broad = MeshBroadPhase::new(&x, &x1, &edges, &tris, 0.0);
        broad.candidates(&edges, &tris, &mut found);
        assert_eq!(found, brute_force(&x, &x1, &edges, &tris, 0.0));
        assert!(found.vertex_face.contains(&(3, 0)) && found.vertex_face.contains(&(0, 1)));
        // A gap of exactly the thickness still gives candidates (boxes grown with rounding slack).
        let gap = 0.1;
        let x2: Vec<V3> =
            x.iter().enumerate().map(|(i, p)| if i >= 3 { [p[0] - 4.0 + gap, p[1], p[2]] } else { *p }).collect();
        let broad = MeshBroadPhase::new(&x2, &x2, &edges, &tris, gap);
        broad.candidates(&edges, &tris, &mut found);
        assert!(found.vertex_face.contains(&(3, 0)), "{found:?}");
        let broad = MeshBroadPhase::new(&x2, &x2, &edges, &tris, 0.99 * gap);
        broad.candidates(&edges, &tris, &mut found);
        assert_eq!(found, Candidates::default());
    }

    #[test]
    fn bvh_overlap_queries_match_brute_force_on_random_boxes() {
        let mut rng = Rng(42);
        let boxes = |rng: &mut Rng, n: usize| -> Vec<Aabb> {
            (0..n)
                .map(|_| {
                    let c: V3 = std::array::from_fn(|_| rng.unit());
                    let r: V3 = std::array::from_fn(|_| 0.05 * rng.unit());
                    Aabb { min: std::array::from_fn(|k| c[k] - r[k]), max: std::array::from_fn(|k| c[k] + r[k]) }
                })
                .collect()
        };
        for n in [0, 1, 3, 17, 200] {
            let a = boxes(&mut rng, n);
            let b = boxes(&mut rng, n / 2 + 1);
            let (ta, tb) = (Bvh::build(a.clone()), Bvh::build(b.clone()));
            let mut got = Vec::new();
            ta.for_each_overlap(&tb, |i, j| got.push((i, j)));
            got.sort_unstable();
            let mut want = Vec::new();
            for i in 0..a.len() {
                for j in 0..b.len() {
                    if a[i].overlaps(&b[j]) {
                        want.push((i as u32, j as u32));
                    }
                }
            }
            assert_eq!(got, want, "n = {n}");
            let mut got = Vec::new();
            ta.for_each_self_overlap(|i, j| got.push((i, j)));
            got.sort_unstable();
            let mut want = Vec::new();
            for i in 0..a.len() {
                for j in i + 1..a.len() {
                    if a[i].overlaps(&a[j]) {
                        want.push((i as u32, j as u32));
                    }
                }
            }
            assert_eq!(got, want, "self, n = {n}");
        }
    }
}
