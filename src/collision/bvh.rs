//! Bounding-volume hierarchy over axis-aligned boxes (SPEC 1.6, "AABB culling"): built top down
//! by median splits, refit bottom up every step, rebuilt when refitting has made it loose.
//!
//! Pure data structure: it knows boxes and primitive indices, nothing of meshes or simulators
//! (see [`super::candidates`] for the mesh pairs).

use glam::{BVec4A, DVec3, Vec3A, Vec4};

use super::filters::V3;

/// An axis-aligned box; `min <= max` on every axis for a non-empty box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub min: V3,
    /// Largest corner.
    pub max: V3,
}

impl Aabb {
    /// The empty box (the identity of [`Aabb::union`]).
    pub const EMPTY: Aabb = Aabb { min: [f64::INFINITY; 3], max: [f64::NEG_INFINITY; 3] };

    /// The box of a set of points, grown by `margin` plus a few units in the last place of each
    /// coordinate, so that rounding can never make it smaller than the exact grown box.
    pub fn around(points: &[V3], margin: f64) -> Aabb {
        let mut b = Aabb::EMPTY;
        for p in points {
            for (axis, &x) in p.iter().enumerate() {
                b.min[axis] = b.min[axis].min(x);
                b.max[axis] = b.max[axis].max(x);
            }
        }
        b.grown(margin)
    }

    /// This box grown by `margin` plus a few units in the last place of each coordinate, so that
    /// rounding can never make it smaller than the exact grown box.
    pub fn grown(&self, margin: f64) -> Aabb {
        let mut b = *self;
        for axis in 0..3 {
            // The slack (4 eps of |coordinate| + margin) covers the two roundings below.
            let grow = |x: f64| margin + (x.abs() + margin) * (4.0 * f64::EPSILON);
            b.min[axis] -= grow(b.min[axis]);
            b.max[axis] += grow(b.max[axis]);
        }
        b
    }

    /// Whether the closed box holds the point (exact comparisons; false for NaN).
    #[inline]
    pub fn contains(&self, p: &V3) -> bool {
        (0..3).all(|k| self.min[k] <= p[k] && p[k] <= self.max[k])
    }

    /// The smallest box holding both.
    #[inline]
    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb {
            min: std::array::from_fn(|k| self.min[k].min(other.min[k])),
            max: std::array::from_fn(|k| self.max[k].max(other.max[k])),
        }
    }

    /// Whether the closed boxes share a point (touching counts).
    #[inline]
    pub fn overlaps(&self, other: &Aabb) -> bool {
        (0..3).all(|k| self.min[k] <= other.max[k] && other.min[k] <= self.max[k])
    }

    /// Half the surface area (0 for an empty or flat box).
    pub fn half_area(&self) -> f64 {
        let d: [f64; 3] = std::array::from_fn(|k| (self.max[k] - self.min[k]).max(0.0));
        d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
    }
}

/// The boxes the tree holds: f32 (half the memory of [`Aabb`], one SIMD compare per side). An
/// [`Aabb`] given to the tree is rounded outwards ([`Box32::around`]), so it always holds it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Box32 {
    /// Smallest corner.
    pub(crate) lo: Vec3A,
    /// Largest corner.
    pub(crate) hi: Vec3A,
}

impl Box32 {
    /// The empty box (the identity of [`Box32::union`]).
    pub(crate) const EMPTY: Box32 = Box32 { lo: Vec3A::INFINITY, hi: Vec3A::NEG_INFINITY };

    /// Rounded outwards without branches: moving each bound out by a relative 2^-23 plus 2^-149
    /// before the conversion (which rounds to nearest, within a relative 2^-24 or 2^-150) keeps
    /// it outside. Bounds beyond the f32 range clamp to it (an empty box stays empty); a NaN
    /// bound makes an empty box, which overlaps nothing, like the f64 comparisons.
    pub(crate) fn around(b: &Aabb) -> Box32 {
        const REL: f64 = 1.0 / (1u64 << 23) as f64;
        const ABS: f64 = f32::MIN_POSITIVE as f64 / (1u64 << 23) as f64; // 2^-149
        let (lo, hi) = (DVec3::from_array(b.min), DVec3::from_array(b.max));
        let lo = (lo - lo.abs() * REL - ABS).as_vec3a().min(Vec3A::splat(f32::MAX));
        let hi = (hi + hi.abs() * REL + ABS).as_vec3a().max(Vec3A::splat(f32::MIN));
        Box32 { lo, hi }
    }

    #[inline(always)]
    fn overlaps(&self, other: &Box32) -> bool {
        (self.lo.cmple(other.hi) & other.lo.cmple(self.hi)).all()
    }

    #[inline(always)]
    pub(crate) fn union(&self, other: &Box32) -> Box32 {
        Box32 { lo: self.lo.min(other.lo), hi: self.hi.max(other.hi) }
    }

    #[inline(always)]
    fn contains(&self, other: &Box32) -> bool {
        (self.lo.cmple(other.lo) & other.hi.cmple(self.hi)).all()
    }

    /// Whether the point lies in the box (bounds included; false for a NaN coordinate).
    #[inline(always)]
    pub(crate) fn contains_point(&self, p: Vec3A) -> bool {
        (self.lo.cmple(p) & p.cmple(self.hi)).all()
    }

    /// Half the surface area (0 for an empty or flat box), for the choice of the node to descend.
    fn half_area(&self) -> f32 {
        let d = (self.hi - self.lo).max(Vec3A::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }

    fn centroid(&self, axis: usize) -> f32 {
        0.5 * (self.lo[axis] + self.hi[axis])
    }
}

#[derive(Clone, Copy, Debug)]
struct Node {
    aabb: Box32,
    /// Leaf: first index into `order`; internal: left child.
    a: u32,
    /// Leaf: one past the last index into `order`; internal: right child.
    b: u32,
    /// Half the area of `aabb`, set with it (internal nodes descend the larger side).
    half_area: f32,
    /// Leaf: its index in [`Bvh::leaf_lanes`]; internal: [`NOT_LEAF`].
    lanes: u32,
}

/// [`Node::lanes`] of an internal node.
const NOT_LEAF: u32 = u32::MAX;

impl Node {
    #[inline(always)]
    fn is_leaf(&self) -> bool {
        self.lanes != NOT_LEAF
    }

    /// A leaf's lanes that hold a primitive (the padding after them is empty, but an infinite
    /// query box still overlaps an empty one: +inf <= +inf).
    #[inline(always)]
    fn used_lanes(&self) -> u32 {
        (1u32 << (self.b - self.a)) - 1
    }
}

/// The f32 boxes of one leaf's primitives side by side (structure of arrays: `lo[axis][half]`
/// holds lanes `4 * half ..` of that axis), padded with empty boxes: a box is tested against the
/// whole leaf with a few SIMD compares and one bit mask, so the leaf loops branch on the
/// overlaps only (mostly 1 in 6 on the kitten's edges), not on every test.
/// The keys likewise (`keys[slot][half]`), as the f32 with the key's bits, so that the pairs
/// sharing a key come out of one more mask instead of a branch per overlap (3 in 4 of the
/// kitten's edge overlaps are neighbours).
#[derive(Clone, Copy, Debug)]
struct LeafLanes {
    lo: [[Vec4; 2]; 3],
    hi: [[Vec4; 2]; 3],
    keys: [[Vec4; 2]; 3],
}

/// A key as the f32 compared in [`LeafLanes::sharing`]: the bits of a positive normal float
/// (never a subnormal, which the DAZ mode of a host's MXCSR would compare equal to 0), so two
/// keys compare equal exactly when they are equal. Keys from 2^30 up
/// become a NaN, which shares with nothing: a pair is then reported rather than skipped, which
/// the callers allow (they check what they need), while a skip is never wrong.
fn key_lane(key: u32) -> f32 {
    // Shifted past the subnormals: with the DAZ bit of MXCSR set (hosts built with -ffast-math,
    // engines that set FTZ/DAZ for speed) every subnormal compares equal to 0 and to each other,
    // so plain key bits would make every pair "share" a key. Keys 0..2^30 become the positive
    // normal floats from 2^-126 up (finite, exponent field 0x01..=0x81); larger keys a NaN.
    if key < 1 << 30 { f32::from_bits(key + 0x0080_0000) } else { f32::NAN }
}

impl LeafLanes {
    const EMPTY: LeafLanes =
        LeafLanes { lo: [[Vec4::INFINITY; 2]; 3], hi: [[Vec4::NEG_INFINITY; 2]; 3], keys: [[Vec4::NAN; 2]; 3] };

    fn set_keys(&mut self, lane: usize, keys: &[u32; 3]) {
        let (half, j) = (lane / 4, lane % 4);
        for (slot, &key) in keys.iter().enumerate() {
            self.keys[slot][half][j] = key_lane(key);
        }
    }

    /// Bit `j` set when lane `j` shares one of `keys` (each from [`key_lane`]).
    #[inline(always)]
    fn sharing(&self, keys: &[f32; 3]) -> u32 {
        let mut mask = 0;
        for half in 0..2 {
            let mut any = BVec4A::splat(false);
            for lane_keys in &self.keys {
                for &key in keys {
                    any |= lane_keys[half].cmpeq(Vec4::splat(key));
                }
            }
            mask |= any.bitmask() << (4 * half);
        }
        mask
    }

    fn set(&mut self, lane: usize, b: &Box32) {
        let (half, j) = (lane / 4, lane % 4);
        for axis in 0..3 {
            self.lo[axis][half][j] = b.lo[axis];
            self.hi[axis][half][j] = b.hi[axis];
        }
    }

    /// Bit `j` set when `q` overlaps the box in lane `j` (as [`Box32::overlaps`]: NaN bounds
    /// overlap nothing; the empty padding overlaps nothing but an infinite `q`, so the callers
    /// keep only [`Node::used_lanes`]).
    #[inline(always)]
    fn overlaps(&self, q: &Box32) -> u32 {
        let mut mask = 0;
        for half in 0..2 {
            let mut all = BVec4A::splat(true);
            for axis in 0..3 {
                all &= Vec4::splat(q.lo[axis]).cmple(self.hi[axis][half])
                    & self.lo[axis][half].cmple(Vec4::splat(q.hi[axis]));
            }
            mask |= all.bitmask() << (4 * half);
        }
        mask
    }
}

/// Most primitives in one leaf (kitten bench, f32 SIMD leaf tests: 8 traversed fastest of 2, 4, 8, 12, 16),
/// at most the 8 lanes of [`LeafLanes`].
const LEAF_SIZE: usize = 8;
const _: () = assert!(LEAF_SIZE <= 8);

/// A BVH over primitive boxes `0..n`, held in f32 ([`Box32`]): boxes given in f64 are rounded
/// outwards, so the traversals report every pair whose f64 boxes overlap, and may report pairs
/// within that rounding (a relative 2^-23) of overlapping; callers that need the exact f64 answer
/// confirm the pairs reported (see [`super::candidates`]), the others take the superset.
#[derive(Clone, Debug)]
pub struct Bvh {
    /// Nodes in pre-order: every child comes after its parent (refit walks them backwards).
    nodes: Vec<Node>,
    /// Primitive indices, grouped by leaf.
    order: Vec<u32>,
    /// The current primitive boxes.
    boxes: Vec<Box32>,
    /// The same boxes in `order`'s order (`leaf_boxes[k] = boxes[order[k]]`), so that the leaf
    /// loops of a traversal read contiguous memory instead of jumping across the primitives.
    leaf_boxes: Vec<Box32>,
    /// The same f32 boxes per leaf in lanes (leaf node `n` at `leaf_lanes[n.lanes]`, lane = slot
    /// minus the leaf's first slot), against which the traversals test a box at once.
    leaf_lanes: Vec<LeafLanes>,
    /// Inverse of `order`: primitive i is at `order[slot[i]]`.
    slot: Vec<u32>,
    /// Per primitive, optional (empty when none were given, see [`Bvh::build_with_keys`]): up to
    /// three keys; the traversals skip pairs sharing a key. In `order`'s order in `leaf_keys`.
    keys: Vec<[u32; 3]>,
    leaf_keys: Vec<[u32; 3]>,
    /// Per node: its parent (the root's is `u32::MAX`).
    parent: Vec<u32>,
    /// Per primitive: the leaf node holding it.
    leaf_of: Vec<u32>,
    /// Looseness (see [`Bvh::looseness`]) right after the last build.
    built_looseness: f64,
}

/// Refitting may make the tree this much looser than when it was built before it is rebuilt.
pub(crate) const REBUILD_LOOSENESS_RATIO: f64 = 1.5;

impl Bvh {
    /// Heap bytes of the tree's arrays (their capacities).
    pub fn memory_bytes(&self) -> usize {
        fn b<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        b(&self.nodes)
            + b(&self.order)
            + b(&self.boxes)
            + b(&self.leaf_boxes)
            + b(&self.leaf_lanes)
            + b(&self.slot)
            + b(&self.keys)
            + b(&self.leaf_keys)
            + b(&self.parent)
            + b(&self.leaf_of)
    }

    /// Builds the tree over `boxes` (primitive i has box `boxes[i]`).
    pub fn build(boxes: Vec<Aabb>) -> Bvh {
        Self::build_with_keys(boxes, Vec::new())
    }

    /// [`Bvh::build_with_keys`] over f32 boxes, taken as they are.
    pub(crate) fn build32(boxes: Vec<Box32>, keys: Vec<[u32; 3]>) -> Bvh {
        assert!(keys.is_empty() || keys.len() == boxes.len(), "one key triple per primitive");
        let mut bvh = Bvh {
            leaf_keys: keys.clone(),
            keys,
            nodes: Vec::new(),
            order: (0..boxes.len() as u32).collect(),
            leaf_boxes: boxes.clone(),
            leaf_lanes: Vec::new(),
            slot: (0..boxes.len() as u32).collect(),
            parent: Vec::new(),
            leaf_of: vec![0; boxes.len()],
            boxes,
            built_looseness: 0.0,
        };
        bvh.rebuild();
        bvh
    }

    /// Builds the tree over `boxes` with a key triple per primitive (repeat a key to give fewer,
    /// e.g. a mesh edge's two vertices as `[a, b, a]`): the traversals then never report two
    /// primitives that share a key below 2^31 (mesh neighbours sharing a vertex), without testing
    /// their exact boxes or calling back (a shared key from 2^31 up may be reported, see
    /// [`key_lane`]). `keys` empty: no skipping.
    pub fn build_with_keys(boxes: Vec<Aabb>, keys: Vec<[u32; 3]>) -> Bvh {
        Self::build32(boxes.iter().map(Box32::around).collect(), keys)
    }

    /// Number of primitives.
    pub fn len(&self) -> usize {
        self.boxes.len()
    }

    /// True for a tree over no primitive.
    pub fn is_empty(&self) -> bool {
        self.boxes.is_empty()
    }

    /// Rebuilds the topology of the tree from the current primitive boxes.
    pub fn rebuild(&mut self) {
        self.nodes.clear();
        self.leaf_lanes.clear();
        self.order.clear();
        self.order.extend(0..self.boxes.len() as u32);
        if !self.boxes.is_empty() {
            self.nodes.reserve(2 * self.boxes.len() / LEAF_SIZE + 1);
            let count = self.boxes.len();
            self.build_node(0, count);
        }
        self.parent.clear();
        self.parent.resize(self.nodes.len(), u32::MAX);
        for (n, node) in self.nodes.iter().enumerate() {
            if node.is_leaf() {
                for &i in &self.order[node.a as usize..node.b as usize] {
                    self.leaf_of[i as usize] = n as u32;
                }
            } else {
                self.parent[node.a as usize] = n as u32;
                self.parent[node.b as usize] = n as u32;
            }
        }
        self.sort_leaf_keys();
        self.sort_leaf_boxes();
        self.built_looseness = self.looseness();
    }

    /// Builds the node over `order[begin..end]` and returns its index.
    fn build_node(&mut self, begin: usize, end: usize) -> u32 {
        let index = self.nodes.len() as u32;
        let aabb = self.order[begin..end].iter().fold(Box32::EMPTY, |acc, &i| acc.union(&self.boxes[i as usize]));
        let half_area = aabb.half_area();
        if end - begin <= LEAF_SIZE {
            let lanes = self.leaf_lanes.len() as u32;
            self.leaf_lanes.push(LeafLanes::EMPTY);
            self.nodes.push(Node { aabb, a: begin as u32, b: end as u32, half_area, lanes });
            return index;
        }
        self.nodes.push(Node { aabb, a: begin as u32, b: end as u32, half_area, lanes: NOT_LEAF });
        // Median split along the longest axis of the centroids' box.
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for &i in &self.order[begin..end] {
            for axis in 0..3 {
                let c = self.boxes[i as usize].centroid(axis);
                lo[axis] = lo[axis].min(c);
                hi[axis] = hi[axis].max(c);
            }
        }
        let axis = (0..3).max_by(|&x, &y| (hi[x] - lo[x]).total_cmp(&(hi[y] - lo[y]))).unwrap_or(0);
        let mid = begin + (end - begin) / 2;
        let boxes = &self.boxes;
        self.order[begin..end].select_nth_unstable_by(mid - begin, |&x, &y| {
            boxes[x as usize].centroid(axis).total_cmp(&boxes[y as usize].centroid(axis))
        });
        let left = self.build_node(begin, mid);
        let right = self.build_node(mid, end);
        self.nodes[index as usize] = Node { aabb, a: left, b: right, half_area, lanes: NOT_LEAF };
        index
    }

    /// What depends on the order only (after a build): the slots, the keys in leaf order and
    /// in the lanes, the empty lanes.
    fn sort_leaf_keys(&mut self) {
        for (k, &i) in self.order.iter().enumerate() {
            self.slot[i as usize] = k as u32;
            if !self.keys.is_empty() {
                self.leaf_keys[k] = self.keys[i as usize];
            }
        }
        for node in self.nodes.iter().filter(|n| n.is_leaf()) {
            let lanes = &mut self.leaf_lanes[node.lanes as usize];
            *lanes = LeafLanes::EMPTY;
            for (lane, keys) in self.leaf_keys.get(node.a as usize..node.b as usize).unwrap_or(&[]).iter().enumerate() {
                lanes.set_keys(lane, keys);
            }
        }
    }

    /// The boxes in leaf order and in the lanes (after every change of the boxes; the lanes
    /// past a leaf's primitives stay empty).
    fn sort_leaf_boxes(&mut self) {
        for (b, &i) in self.leaf_boxes.iter_mut().zip(&self.order) {
            *b = self.boxes[i as usize];
        }
        for node in self.nodes.iter().filter(|n| n.is_leaf()) {
            let lanes = &mut self.leaf_lanes[node.lanes as usize];
            for (lane, b) in self.leaf_boxes[node.a as usize..node.b as usize].iter().enumerate() {
                lanes.set(lane, b);
            }
        }
    }

    /// Sum of the internal nodes' half areas over that of the primitive boxes: how much empty
    /// space the tree makes a query visit. Grows when refitting after large motions.
    pub fn looseness(&self) -> f64 {
        let internal: f64 = self.nodes.iter().filter(|n| !n.is_leaf()).map(|n| n.half_area as f64).sum();
        let primitives: f64 = self.boxes.iter().map(|b| b.half_area() as f64).sum();
        if primitives > 0.0 { internal / primitives } else { 0.0 }
    }

    /// Replaces the primitive boxes (same count) and refits every node bottom up; rebuilds the
    /// tree instead when it became more than [`REBUILD_LOOSENESS_RATIO`] times looser than when
    /// built. Returns true when it rebuilt.
    pub fn update(&mut self, boxes: &[Aabb]) -> bool {
        assert_eq!(boxes.len(), self.boxes.len(), "a BVH update must keep the primitive count");
        for (b, new) in self.boxes.iter_mut().zip(boxes) {
            *b = Box32::around(new);
        }
        self.refit()
    }

    /// [`Bvh::update`] with f32 boxes, taken as they are.
    pub(crate) fn update32(&mut self, boxes: &[Box32]) -> bool {
        assert_eq!(boxes.len(), self.boxes.len(), "a BVH update must keep the primitive count");
        self.boxes.copy_from_slice(boxes);
        self.refit()
    }

    /// The refit (or rebuild) of [`Bvh::update`] after the boxes changed.
    fn refit(&mut self) -> bool {
        self.sort_leaf_boxes();
        self.refit_nodes();
        if self.looseness() > REBUILD_LOOSENESS_RATIO * self.built_looseness {
            self.rebuild();
            return true;
        }
        false
    }

    /// Replaces the boxes of the primitives `changed` by theirs in `boxes` (indexed by primitive)
    /// and grows the nodes above them to hold the new boxes, without the looseness check of
    /// [`Bvh::update`] (for a few changed boxes between full updates). Costs the changed
    /// primitives' depth, not the tree's size: nodes are only grown (a node keeps the space a
    /// primitive left until the next [`Bvh::update`]), so every node still holds its primitives'
    /// boxes, which is all a traversal needs.
    pub(crate) fn update_some(&mut self, changed: &[u32], boxes: &[Box32]) {
        for &i in changed {
            let b32 = boxes[i as usize];
            self.boxes[i as usize] = b32;
            self.leaf_boxes[self.slot[i as usize] as usize] = b32;
            let leaf = &self.nodes[self.leaf_of[i as usize] as usize];
            self.leaf_lanes[leaf.lanes as usize].set((self.slot[i as usize] - leaf.a) as usize, &b32);
            let mut n = self.leaf_of[i as usize];
            while n != u32::MAX {
                let node = &mut self.nodes[n as usize];
                if node.aabb.contains(&b32) {
                    break; // and so do its ancestors
                }
                node.aabb = node.aabb.union(&b32);
                node.half_area = node.aabb.half_area();
                n = self.parent[n as usize];
            }
        }
    }

    fn refit_nodes(&mut self) {
        for n in (0..self.nodes.len()).rev() {
            let node = self.nodes[n];
            let aabb = if node.is_leaf() {
                self.leaf_boxes[node.a as usize..node.b as usize].iter().fold(Box32::EMPTY, |acc, b| acc.union(b))
            } else {
                self.nodes[node.a as usize].aabb.union(&self.nodes[node.b as usize].aabb)
            };
            self.nodes[n].aabb = aabb;
            self.nodes[n].half_area = aabb.half_area();
        }
    }

    /// The lanes of `other`'s leaf `lanes` that share a key with slot `k` of `self` (none
    /// without keys).
    #[inline(always)]
    fn sharing(&self, k: usize, other: &Bvh, lanes: &LeafLanes) -> u32 {
        if self.leaf_keys.is_empty() || other.leaf_keys.is_empty() {
            return 0;
        }
        lanes.sharing(&self.leaf_keys[k].map(key_lane))
    }

    /// Calls `f(k, l)` for the slots `k` of leaf `nx` of `self` and `l` of leaf `ny` of `other`
    /// whose boxes overlap and share no key, in order; with `after_own` (a leaf with itself)
    /// only for `l` after `k`.
    #[inline(always)]
    fn leaf_pairs(&self, nx: &Node, other: &Bvh, ny: &Node, after_own: bool, mut f: impl FnMut(usize, usize)) {
        let lanes = &other.leaf_lanes[ny.lanes as usize];
        // Only the slots of `nx` that reach into `ny`'s box at all (one lane test): leaves that
        // meet mostly meet along a seam (kitten: this skips most slots of a visit).
        let mut slots = self.leaf_lanes[nx.lanes as usize].overlaps(&ny.aabb) & nx.used_lanes();
        while slots != 0 {
            let k = nx.a as usize + slots.trailing_zeros() as usize;
            slots &= slots - 1;
            let overlapping = lanes.overlaps(&self.leaf_boxes[k]) & ny.used_lanes();
            if overlapping == 0 {
                continue;
            }
            let mut mask = overlapping & !self.sharing(k, other, lanes);
            if after_own {
                mask &= !0u32 << (k - nx.a as usize + 1);
            }
            while mask != 0 {
                let l = ny.a as usize + mask.trailing_zeros() as usize;
                mask &= mask - 1;
                f(k, l);
            }
        }
    }

    /// Calls `f(j)` for every primitive `j` whose box overlaps `query`, in a fixed order.
    pub(crate) fn for_each_overlap_of(&self, q: &Box32, stack: &mut Vec<u32>, mut f: impl FnMut(u32)) {
        if self.nodes.is_empty() {
            return;
        }
        stack.clear();
        stack.push(0);
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if !node.aabb.overlaps(q) {
                continue;
            }
            if node.is_leaf() {
                let mut mask = self.leaf_lanes[node.lanes as usize].overlaps(q) & node.used_lanes();
                while mask != 0 {
                    let k = node.a as usize + mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    f(self.order[k]);
                }
            } else {
                stack.extend([node.b, node.a]);
            }
        }
    }

    /// Calls `f(i, j)` for every primitive `i` of `self` and `j` of `other` whose boxes overlap
    /// (and share no key, when both trees have keys).
    pub fn for_each_overlap(&self, other: &Bvh, f: impl FnMut(u32, u32)) {
        self.for_each_overlap_with(other, &mut Vec::new(), f);
    }

    /// [`Bvh::for_each_overlap`] with the caller's traversal stack (kept between calls: a new
    /// one was an allocation per refill of a shell's contact cache).
    pub(crate) fn for_each_overlap_with(
        &self,
        other: &Bvh,
        stack: &mut Vec<(u32, u32, bool)>,
        mut f: impl FnMut(u32, u32),
    ) {
        if self.nodes.is_empty() || other.nodes.is_empty() {
            return;
        }
        stack.clear();
        stack.push((0, 0, false));
        while let Some((x, y, _)) = stack.pop() {
            let (nx, ny) = (&self.nodes[x as usize], &other.nodes[y as usize]);
            if !nx.aabb.overlaps(&ny.aabb) {
                continue;
            }
            match (nx.is_leaf(), ny.is_leaf()) {
                (true, true) => self.leaf_pairs(nx, other, ny, false, |k, l| f(self.order[k], other.order[l])),
                // Descend into the larger internal node (or the only internal one).
                (false, true) => stack.extend([(nx.a, y, false), (nx.b, y, false)]),
                (true, false) => stack.extend([(x, ny.a, false), (x, ny.b, false)]),
                (false, false) => {
                    if nx.half_area >= ny.half_area {
                        stack.extend([(nx.a, y, false), (nx.b, y, false)]);
                    } else {
                        stack.extend([(x, ny.a, false), (x, ny.b, false)]);
                    }
                }
            }
        }
    }

    /// Calls `f(i, j)` with `i < j` once for every pair of primitives whose boxes overlap (and
    /// share no key, when the tree has keys).
    pub fn for_each_self_overlap(&self, f: impl FnMut(u32, u32)) {
        self.for_each_self_overlap_with(&mut Vec::new(), f);
    }

    /// [`Bvh::for_each_self_overlap`] with the caller's traversal stack.
    pub(crate) fn for_each_self_overlap_with(&self, stack: &mut Vec<(u32, u32, bool)>, mut f: impl FnMut(u32, u32)) {
        if self.nodes.is_empty() {
            return;
        }
        // (x, y, same): pairs within node x when `same`, else between nodes x and y.
        stack.clear();
        stack.push((0, 0, true));
        while let Some((x, y, same)) = stack.pop() {
            let nx = &self.nodes[x as usize];
            if same {
                if nx.is_leaf() {
                    self.leaf_pairs(nx, self, nx, true, |k, l| {
                        let (i, j) = (self.order[k], self.order[l]);
                        f(i.min(j), i.max(j));
                    });
                } else {
                    stack.extend([(nx.a, nx.a, true), (nx.b, nx.b, true), (nx.a, nx.b, false)]);
                }
                continue;
            }
            let ny = &self.nodes[y as usize];
            if !nx.aabb.overlaps(&ny.aabb) {
                continue;
            }
            match (nx.is_leaf(), ny.is_leaf()) {
                (true, true) => self.leaf_pairs(nx, self, ny, false, |k, l| {
                    let (i, j) = (self.order[k], self.order[l]);
                    f(i.min(j), i.max(j));
                }),
                (false, true) => stack.extend([(nx.a, y, false), (nx.b, y, false)]),
                (true, false) => stack.extend([(x, ny.a, false), (x, ny.b, false)]),
                (false, false) => {
                    if nx.half_area >= ny.half_area {
                        stack.extend([(nx.a, y, false), (nx.b, y, false)]);
                    } else {
                        stack.extend([(x, ny.a, false), (x, ny.b, false)]);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn overlaps_brute(a: &[Aabb], b: &[Aabb]) -> Vec<(u32, u32)> {
        let mut out = Vec::new();
        for (i, x) in a.iter().enumerate() {
            for (j, y) in b.iter().enumerate() {
                if x.overlaps(y) {
                    out.push((i as u32, j as u32));
                }
            }
        }
        out
    }

    /// The pairs the tree must report: those of the boxes it holds (rounded out to f32), which
    /// include every pair of the f64 boxes.
    fn overlaps_brute32(a: &[Aabb], b: &[Aabb]) -> Vec<(u32, u32)> {
        let (a32, b32): (Vec<Box32>, Vec<Box32>) =
            (a.iter().map(Box32::around).collect(), b.iter().map(Box32::around).collect());
        let mut out = Vec::new();
        for (i, x) in a32.iter().enumerate() {
            for (j, y) in b32.iter().enumerate() {
                if x.overlaps(y) {
                    out.push((i as u32, j as u32));
                }
            }
        }
        let exact = overlaps_brute(a, b);
        assert!(exact.iter().all(|p| out.binary_search(p).is_ok()), "f32 boxes lost an f64 overlap");
        out
    }

    #[test]
    fn partial_updates_keep_every_overlap() {
        let mut seed = 0x2545_F491_4F6C_DD1Du64;
        let mut unit = move || {
            seed ^= seed >> 12;
            seed ^= seed << 25;
            seed ^= seed >> 27;
            (seed.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut random_box = |size: f64| {
            let c = [unit(), unit(), unit()];
            Aabb::around(&[c, [c[0] + size * unit(), c[1] + size * unit(), c[2] + size * unit()]], 0.0)
        };
        let mut boxes: Vec<Aabb> = (0..300).map(|_| random_box(0.1)).collect();
        let probes: Vec<Aabb> = (0..50).map(|_| random_box(0.2)).collect();
        let mut tree = Bvh::build(boxes.clone());
        let probe_tree = Bvh::build(probes.clone());
        for round in 0..20 {
            // Move a few boxes far (partial update), or all of them (full update).
            if round % 5 == 4 {
                boxes.iter_mut().for_each(|b| *b = random_box(0.1));
                tree.update(&boxes);
            } else {
                let changed: Vec<u32> = (0..300).filter(|i| (i * 7 + round) % 23 == 0).collect();
                for &i in &changed {
                    boxes[i as usize] = random_box(0.1);
                }
                let boxes32: Vec<Box32> = boxes.iter().map(Box32::around).collect();
                tree.update_some(&changed, &boxes32);
            }
            let mut found = Vec::new();
            tree.for_each_overlap(&probe_tree, |i, j| found.push((i, j)));
            found.sort_unstable();
            assert_eq!(found, overlaps_brute32(&boxes, &probes), "round {round}");
            let mut one_by_one = Vec::new();
            let mut stack = Vec::new();
            for (j, p) in probes.iter().enumerate() {
                tree.for_each_overlap_of(&Box32::around(p), &mut stack, |i| one_by_one.push((i, j as u32)));
            }
            one_by_one.sort_unstable();
            assert_eq!(one_by_one, found, "round {round}");
            let mut own = Vec::new();
            tree.for_each_self_overlap(|i, j| own.push((i, j)));
            own.sort_unstable();
            let brute: Vec<(u32, u32)> = overlaps_brute32(&boxes, &boxes).into_iter().filter(|(i, j)| i < j).collect();
            assert_eq!(own, brute, "round {round}");
        }
    }

    #[test]
    fn primitives_sharing_a_key_are_never_paired() {
        // Unit boxes on a line, each overlapping its neighbours; keys make neighbours k, k+1
        // share key k+1 (like consecutive edges of a polyline sharing a vertex).
        let boxes: Vec<Aabb> = (0..40).map(|k| Aabb::around(&[[k as f64 * 0.4, 0.0, 0.0]], 0.5)).collect();
        let keys: Vec<[u32; 3]> = (0..40u32).map(|k| [k, k + 1, k]).collect();
        let plain = Bvh::build(boxes.clone());
        let keyed = Bvh::build_with_keys(boxes.clone(), keys.clone());
        let (mut all, mut kept) = (Vec::new(), Vec::new());
        plain.for_each_self_overlap(|i, j| all.push((i, j)));
        keyed.for_each_self_overlap(|i, j| kept.push((i, j)));
        all.sort_unstable();
        kept.sort_unstable();
        let expected: Vec<(u32, u32)> = all.iter().copied().filter(|&(i, j)| j != i + 1).collect();
        assert!(all.len() > expected.len() && !expected.is_empty());
        assert_eq!(kept, expected);
        let mut across = Vec::new();
        keyed.for_each_overlap(&Bvh::build_with_keys(boxes, keys), |i, j| across.push((i, j)));
        assert!(across.iter().all(|&(i, j)| i != j && i != j + 1 && j != i + 1));
        assert_eq!(across.len(), 2 * expected.len());
        // Keys 0 and 2^31 (+0.0 and -0.0 as f32) are different keys: not skipped. Equal keys
        // from 2^31 up may be reported (never a wrong skip).
        let two = vec![Aabb::around(&[[0.0; 3]], 1.0), Aabb::around(&[[0.5, 0.0, 0.0]], 1.0)];
        for (keys, reported) in [([[0; 3], [1 << 31; 3]], true), ([[7; 3], [7; 3]], false), ([[u32::MAX; 3]; 2], true)]
        {
            let mut pairs = Vec::new();
            Bvh::build_with_keys(two.clone(), keys.to_vec()).for_each_self_overlap(|i, j| pairs.push((i, j)));
            assert_eq!(pairs == [(0, 1)], reported, "keys {keys:?}");
        }
    }

    #[test]
    fn f32_boxes_hold_their_f64_boxes() {
        let values: [f64; 13] =
            [0.0, 1.0, -1.0, 0.1, -0.1, 1e-40, -1e-40, 1e-300, -1e-300, 3.0e38, -3.0e38, 1e300, -1e300];
        for &a in &values {
            for &b in &values {
                let (lo, hi) = (a.min(b), a.max(b));
                let bx = Aabb { min: [lo, a, b], max: [hi, a, b] };
                let b32 = Box32::around(&bx);
                for k in 0..3 {
                    assert!((b32.lo[k] as f64) <= bx.min[k] || bx.min[k] > f32::MAX as f64, "{bx:?} -> {b32:?}");
                    assert!((b32.hi[k] as f64) >= bx.max[k] || bx.max[k] < f32::MIN as f64, "{bx:?} -> {b32:?}");
                }
            }
        }
        let empty = Box32::around(&Aabb::EMPTY);
        assert!(!empty.overlaps(&Box32::around(&Aabb { min: [0.0; 3], max: [1.0; 3] })));
    }

    /// A box that reaches infinity (a step diverging before its collision stage) overlaps every
    /// primitive once and never the padding of a leaf (which read past the primitives).
    #[test]
    fn infinite_boxes_overlap_only_the_primitives() {
        let boxes: Vec<Aabb> = (0..11).map(|i| Aabb { min: [i as f64; 3], max: [i as f64 + 0.5; 3] }).collect();
        let everything = Aabb { min: [f64::NEG_INFINITY; 3], max: [f64::INFINITY; 3] };
        let tree = Bvh::build(boxes.clone());
        let probe = Bvh::build(vec![everything]);
        let mut found = Vec::new();
        tree.for_each_overlap(&probe, |i, j| found.push((i, j)));
        probe.for_each_overlap(&tree, |j, i| found.push((i, j)));
        found.sort_unstable();
        let expected: Vec<(u32, u32)> = (0..11).flat_map(|i| [(i, 0), (i, 0)]).collect();
        assert_eq!(found, expected);
        let mut with_infinite = boxes;
        with_infinite[3] = everything;
        let tree = Bvh::build(with_infinite);
        let mut pairs = Vec::new();
        tree.for_each_self_overlap(|i, j| pairs.push((i, j)));
        pairs.sort_unstable();
        let expected: Vec<(u32, u32)> = (0..11).filter(|&i| i != 3).map(|i| (i.min(3), i.max(3))).collect();
        assert_eq!(pairs, expected);
    }
}
