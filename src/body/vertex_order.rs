//! The order in which a body stores its vertices: near in space, near in memory.
//!
//! A mesh's vertex numbering is the caller's: a subdivided icosphere, for one, numbers the
//! midpoints of each level after all the vertices of the level before, so neighbours of a vertex
//! lie all over the array. Every pass of a step gathers the neighbours of each vertex, and the
//! worker threads split the vertices into consecutive blocks, so with such a numbering most
//! gathers read lines another core has just written. A body of [`MIN_VERTICES`] or more
//! therefore stores its initial vertices along a Morton (Z-order) curve of their rest positions
//! and maps indices at its boundary: callers see their own numbering everywhere (positions,
//! triangles, pins, impulses, cuts, origins), and vertices made by fracture are appended at the
//! same index inside and out.
//!
//! On the issue-5 balloon (benches/body_balloon.rs, 10,242 vertices, 2 threads), with the mesh
//! renumbered along such a curve before the body got it (the experiment that led here), the
//! step took 3.95 ms in the icosphere's order and 2.65 ms along the curve, measured one after
//! the other (the residual pass alone 326 -> 146 ms over 600 steps); on one thread 5.01 and
//! 4.96 ms. With the order made here: 0.252 -> 0.242 of Bullet's step time in the peer script
//! (benches/peers, mean step times; 0.229 -> 0.204 of the median step times).

/// Meshes with fewer vertices keep their order (they fit in a core's cache, and one chunk of
/// the implicit integrator's passes is 1,024 vertices).
pub(crate) const MIN_VERTICES: usize = 2048;

/// Bits per axis of the Morton code.
const BITS: u32 = 10;

/// The map between the caller's vertex indices (external) and the body's (internal) for the
/// initial vertices; every index at or above their count is the same in both (identity when
/// the vectors are empty).
#[derive(Clone, Debug, Default)]
pub(crate) struct VertexOrder {
    /// `internal_of[external]`.
    internal_of: Vec<u32>,
    /// `external_of[internal]`.
    external_of: Vec<u32>,
}

impl VertexOrder {
    /// The order of `positions`: along the Morton curve of their bounding box when there are at
    /// least [`MIN_VERTICES`] of them (ties in input order), else the input order.
    pub fn new(positions: &[glam::Vec3]) -> Self {
        if positions.len() < MIN_VERTICES {
            return Self::default();
        }
        let (lo, hi) = positions
            .iter()
            .fold((glam::Vec3::splat(f32::MAX), glam::Vec3::splat(f32::MIN)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let scale = (hi - lo).max_element();
        let cells = ((1u32 << BITS) - 1) as f32;
        let code = |p: glam::Vec3| -> u64 {
            let q = if scale > 0.0 { (p - lo) / scale * cells } else { glam::Vec3::ZERO };
            let axis = |v: f32| (v.max(0.0) as u64).min(cells as u64);
            let (x, y, z) = (axis(q.x), axis(q.y), axis(q.z));
            (0..BITS).fold(0u64, |m, b| {
                m | ((x >> b) & 1) << (3 * b) | ((y >> b) & 1) << (3 * b + 1) | ((z >> b) & 1) << (3 * b + 2)
            })
        };
        let mut external_of: Vec<u32> = (0..positions.len() as u32).collect();
        // Stable: equal codes keep the input order. Each code made once (`sort_by_key` made two
        // per comparison: about 5 ms of the issue-5 balloon's 10,242 vertices, a fifth of making
        // the body).
        external_of.sort_by_cached_key(|&i| code(positions[i as usize]));
        let mut internal_of = vec![0u32; positions.len()];
        for (internal, &external) in external_of.iter().enumerate() {
            internal_of[external as usize] = internal as u32;
        }
        Self { internal_of, external_of }
    }

    /// Whether internal and external indices are the same.
    pub fn is_identity(&self) -> bool {
        self.external_of.is_empty()
    }

    /// The body's index of the caller's vertex `external`.
    pub fn internal(&self, external: usize) -> usize {
        self.internal_of.get(external).map_or(external, |&i| i as usize)
    }

    /// The caller's index of the body's vertex `internal`.
    pub fn external(&self, internal: usize) -> usize {
        self.external_of.get(internal).map_or(internal, |&i| i as usize)
    }

    /// `values` (in the caller's order, one per initial vertex) in the body's order.
    pub fn to_internal<T: Copy>(&self, values: &[T]) -> Vec<T> {
        if self.is_identity() {
            return values.to_vec();
        }
        self.external_of.iter().map(|&e| values[e as usize]).collect()
    }

    /// Triangles with every corner mapped by `map` (`internal` or `external`).
    pub fn map_triangles(triangles: &[[u32; 3]], map: impl Fn(usize) -> usize) -> Vec<[u32; 3]> {
        triangles.iter().map(|t| t.map(|i| map(i as usize) as u32)).collect()
    }

    pub fn memory_bytes(&self) -> usize {
        (self.internal_of.capacity() + self.external_of.capacity()) * 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn random_points(n: usize) -> Vec<Vec3> {
        let mut r = crate::body::test_randoms(7);
        (0..n).map(|_| Vec3::new(r(), r(), r())).collect()
    }

    #[test]
    fn small_meshes_keep_their_order() {
        let order = VertexOrder::new(&random_points(MIN_VERTICES - 1));
        assert!(order.is_identity());
        assert_eq!((order.internal(5), order.external(5), order.internal(1 << 20)), (5, 5, 1 << 20));
    }

    #[test]
    fn the_two_maps_are_inverse_permutations_and_later_indices_map_to_themselves() {
        let points = random_points(3000);
        let order = VertexOrder::new(&points);
        assert!(!order.is_identity());
        let mut seen = vec![false; points.len()];
        for e in 0..points.len() {
            let i = order.internal(e);
            assert!(!seen[i], "internal index {i} taken twice");
            seen[i] = true;
            assert_eq!(order.external(i), e);
        }
        assert_eq!((order.internal(3000), order.external(3007)), (3000, 3007));
        // Values move with their vertices.
        let internal = order.to_internal(&points);
        for e in 0..points.len() {
            assert_eq!(internal[order.internal(e)], points[e]);
        }
        for (i, p) in internal.iter().enumerate() {
            assert_eq!(*p, points[order.external(i)]);
        }
        let t = VertexOrder::map_triangles(&[[0, 1, 3000]], |e| order.internal(e));
        assert_eq!(VertexOrder::map_triangles(&t, |i| order.external(i)), vec![[0, 1, 3000]]);
    }

    /// Along the curve, consecutive vertices are close: the mean distance between internal
    /// neighbours is a small fraction of that between input neighbours of random points.
    #[test]
    fn consecutive_vertices_are_near_in_space() {
        let points = random_points(4096);
        let order = VertexOrder::new(&points);
        let internal = order.to_internal(&points);
        let mean_step = |p: &[Vec3]| p.windows(2).map(|w| w[0].distance(w[1])).sum::<f32>() / (p.len() - 1) as f32;
        let (input, curve) = (mean_step(&points), mean_step(&internal));
        assert!(curve < 0.2 * input, "mean step along the curve {curve} vs input {input}");
    }
}
