//! The gas gradient around closed fans, eight vertices at a time (SPEC 2.1: the pressure force
//! `P ∂V/∂x`).
//!
//! Where the faces around a vertex v close one ring of neighbours `n_0 .. n_{L-1}` (in their
//! winding), `∂V/∂x_v = Σ_t (n_t - v) × (n_{t+1} - v) / 6`, the indices modulo L: each corner
//! `(v, n_t, n_{t+1})` of a face adds the cross product of its two other points, taken about v
//! itself (short edges, no cancellation; about any origin the sum is the same, the ring being
//! closed). In ring order each neighbour is loaded once, and the ring of a slice of eight
//! consecutive vertices is laid out for 256-bit registers: group t of the slice holds the t-th
//! ring entry of each of its eight vertices (lanes). After a lane's ring comes its first
//! neighbour again (the corner that closes the ring), then the vertex itself, so the lanes with
//! shorter rings add corners of zero while the longest one finishes.
//!
//! The corners alternate between two running sums (even and odd t): with one, each corner
//! waited for the last one's addition. A vertex of a slice that cannot go eight at a time (a
//! lane that is no ring, a fragment without gas, or a point at the end of the array, where a
//! 16-byte load would read past it) takes the same sums one at a time, to the same bits.

use glam::{Vec3, Vec3A};

use super::coupling_slices::SLICE;
use super::gas::point;
use super::headroom::{reserve_for, with_room};

/// The rings of a mesh's closed fans by slices of eight vertices (see the module doc).
#[derive(Clone, Debug, Default)]
pub(crate) struct FanRings {
    /// Per slice, where its groups start in `groups` (one more entry at the end).
    offsets: Vec<u32>,
    /// The ring entries, a group per position along the rings, a lane per vertex.
    groups: Vec<[u32; SLICE]>,
    /// Per vertex, the length of its ring (0: its fan is no single closed ring).
    length: Vec<u32>,
    /// Per slice, whether all eight lanes are rings and every entry is below the last point
    /// (so each can be loaded 16 bytes at a time).
    whole: Vec<bool>,
    /// The buffers [`FanRings::rebuild_keeping`] walks the rings into and makes them in (the
    /// rings before it), kept for the next rebuild by a body that may crack.
    spare_starts: Vec<u32>,
    spare_entries: Vec<u32>,
    spare_kept: Vec<bool>,
    spare_offsets: Vec<u32>,
    spare_groups: Vec<[u32; SLICE]>,
    spare_length: Vec<u32>,
    spare_whole: Vec<bool>,
}

impl FanRings {
    /// The rings of `n` vertices (tests; see [`FanRings::rebuild`]).
    #[cfg(test)]
    pub fn new(n: usize, fan: impl FnMut(usize, &mut Vec<(u32, u32)>) -> bool) -> Self {
        let mut rings = Self::default();
        rings.rebuild(n, fan);
        rings
    }

    /// Makes the rings of `n` vertices in this one's buffers; `fan(v, out)` puts into `out`
    /// (empty) the (next, previous) corners of the faces around v (in their winding) and
    /// returns whether to walk them: a fan that walks as one single ring gets it (every such
    /// fan is closed: the walk visits each corner once); an open fan or one that is closed but
    /// no single ring (two cones meeting at v) gets none.
    ///
    /// The corners and the rings go into buffers made once for all vertices: with a few vectors
    /// allocated per vertex, this and the fans' closure test (`Gas`) took about 4 ms on the
    /// issue-5 balloon (10,242 vertices), in its first step and in the first step after every
    /// topology change.
    pub fn rebuild(&mut self, n: usize, fan: impl FnMut(usize, &mut Vec<(u32, u32)>) -> bool) {
        self.rebuild_keeping(n, fan, |_| false);
    }

    /// [`FanRings::rebuild`] after a topology change, where these rings are those of the mesh
    /// before it and `same(v)` tells that vertex v's fan is what it was then (the same faces
    /// with the same corners): a slice of eight such vertices keeps its groups, copied, and only
    /// the others are walked and laid out again, to the same rings as a full rebuild. A change
    /// touches a few slices of the many (the issue-5 balloon's first crack: 301 springs of
    /// 30,720), and the full rebuild, about 0.55 ms, was the longest part of its rebuilds.
    ///
    /// The rings are made in spare buffers and the rings before become the next change's
    /// spares, where the spares had room ([`FanRings::reserve_headroom`], a body that may
    /// crack): in new buffers each page faults in on first use.
    pub fn rebuild_keeping(
        &mut self,
        n: usize,
        mut fan: impl FnMut(usize, &mut Vec<(u32, u32)>) -> bool,
        same: impl Fn(usize) -> bool,
    ) {
        let keep_spares = self.spare_entries.capacity() > 0;
        let old = (
            std::mem::take(&mut self.offsets),
            std::mem::take(&mut self.groups),
            std::mem::take(&mut self.length),
            std::mem::take(&mut self.whole),
        );
        let (old_offsets, old_groups, old_length) = (&old.0, &old.1, &old.2);
        let old_n = old_length.len();
        // A slice kept: whole before and now, and every lane's fan the same.
        let kept = |s: usize| (s + 1) * SLICE <= old_n.min(n) && (s * SLICE..(s + 1) * SLICE).all(&same);
        // The rings walked (a vertex of a kept slice or without one: none), vertex v's from
        // `ring_start[v]` to `ring_start[v + 1]`.
        let mut ring_start = std::mem::take(&mut self.spare_starts);
        ring_start.clear();
        ring_start.reserve(n + 1);
        // (Room for the rings of a closed surface, six corners a vertex on average: grown by
        // doubling, these buffers were copied again and again.)
        let mut entries = std::mem::take(&mut self.spare_entries);
        entries.clear();
        entries.reserve(6 * n + 64);
        let mut corners = Vec::new();
        ring_start.push(0u32);
        let slices = n.div_ceil(SLICE);
        let mut kept_slices = std::mem::take(&mut self.spare_kept);
        kept_slices.clear();
        kept_slices.extend((0..slices).map(kept));
        for v in 0..n {
            corners.clear();
            if !kept_slices[v / SLICE] && fan(v, &mut corners) {
                walk_into(&corners, &mut entries);
            }
            ring_start.push(entries.len() as u32);
        }
        let ring = |v: usize| &entries[ring_start[v] as usize..ring_start[v + 1] as usize];
        let mut offsets = std::mem::take(&mut self.spare_offsets);
        let mut groups = std::mem::take(&mut self.spare_groups);
        let mut length = std::mem::take(&mut self.spare_length);
        let mut whole = std::mem::take(&mut self.spare_whole);
        offsets.clear();
        offsets.reserve(slices + 1);
        groups.clear();
        groups.reserve(8 * slices);
        whole.clear();
        whole.reserve(slices);
        length.clear();
        length.reserve(n);
        for s in 0..slices {
            offsets.push(groups.len() as u32);
            let lanes = s * SLICE..((s + 1) * SLICE).min(n);
            let first = groups.len();
            if kept_slices[s] {
                groups.extend_from_slice(&old_groups[old_offsets[s] as usize..old_offsets[s + 1] as usize]);
                length.extend_from_slice(&old_length[lanes.clone()]);
            } else {
                let longest = lanes.clone().map(|v| ring(v).len()).max().unwrap_or(0);
                // The closing entry after the longest ring.
                groups.resize(first + longest + 1, [0; SLICE]);
                for (lane, v) in lanes.clone().enumerate() {
                    let ring = ring(v);
                    for (t, group) in groups[first..].iter_mut().enumerate() {
                        group[lane] = match t {
                            t if t < ring.len() => ring[t],
                            t if t == ring.len() && !ring.is_empty() => ring[0],
                            _ => v as u32,
                        };
                    }
                }
                length.extend(lanes.clone().map(|v| ring(v).len() as u32));
            }
            // A kept slice that was whole still is (its entries stay below the last point as
            // `n` grows); one that was not is measured again, as every other slice.
            if kept_slices[s] && old.3[s] {
                whole.push(true);
                continue;
            }
            let below_last = groups[first..].iter().flatten().all(|&i| (i as usize) + 1 < n);
            whole.push(lanes.len() == SLICE && length[lanes].iter().all(|&l| l > 0) && below_last);
        }
        offsets.push(groups.len() as u32);
        (self.offsets, self.groups, self.length, self.whole) = (offsets, groups, length, whole);
        if keep_spares {
            (self.spare_starts, self.spare_entries, self.spare_kept) = (ring_start, entries, kept_slices);
            (self.spare_offsets, self.spare_groups, self.spare_length, self.spare_whole) = old;
        }
    }

    /// Room for a fraction `headroom` more vertices and ring entries (see `headroom`), and as
    /// much in the spare buffers a rebuild makes its rings in.
    /// Nothing for rings not made: a body stepped by an integrator that never makes them (XPBD,
    /// the explicit ones) would hold spare buffers it never uses (SPEC 5).
    pub fn reserve_headroom(&mut self, headroom: f64) {
        if self.length.is_empty() {
            return;
        }
        let (n, slices, groups) = (self.length.len(), self.whole.len(), self.groups.len());
        with_room(&mut self.offsets, headroom);
        with_room(&mut self.groups, headroom);
        with_room(&mut self.length, headroom);
        with_room(&mut self.whole, headroom);
        reserve_for(&mut self.spare_starts, n + 1, headroom);
        reserve_for(&mut self.spare_entries, 6 * n + 64, headroom);
        reserve_for(&mut self.spare_kept, slices, headroom);
        reserve_for(&mut self.spare_offsets, slices + 1, headroom);
        reserve_for(&mut self.spare_groups, groups, headroom);
        reserve_for(&mut self.spare_length, n, headroom);
        reserve_for(&mut self.spare_whole, slices, headroom);
    }

    /// Whether both hold the same rings (their spare buffers aside).
    #[cfg(test)]
    pub fn same_rings(&self, other: &FanRings) -> bool {
        (&self.offsets, &self.groups, &self.length, &self.whole)
            == (&other.offsets, &other.groups, &other.length, &other.whole)
    }

    /// Whether vertex v's fan is one closed ring.
    pub fn is_ring(&self, v: usize) -> bool {
        self.length.get(v).is_some_and(|&l| l > 0)
    }

    /// Whether the slice of vertex `first` (a multiple of eight) can go eight at a time.
    pub fn is_whole_slice(&self, first: usize) -> bool {
        first % SLICE == 0 && self.whole.get(first / SLICE).copied().unwrap_or(false)
    }

    /// `∂V/∂x_v` of a ring vertex, one corner at a time (the sums of [`FanRings::slice_gradient`]).
    pub fn gradient(&self, x: &[Vec3], v: usize) -> Vec3 {
        let (s, lane) = (v / SLICE, v % SLICE);
        let groups = &self.groups[self.offsets[s] as usize..self.offsets[s + 1] as usize];
        let length = self.length[v] as usize;
        let xv = point(x, v);
        let (mut even, mut odd) = (Vec3A::ZERO, Vec3A::ZERO);
        let mut b = point(x, groups[0][lane] as usize) - xv;
        for t in 0..length {
            let c = point(x, groups[t + 1][lane] as usize) - xv;
            if t % 2 == 0 {
                even += b.cross(c);
            } else {
                odd += b.cross(c);
            }
            b = c;
        }
        Vec3::from((even + odd) * (1.0 / 6.0))
    }

    /// `∂V/∂x` of the eight vertices `first..first + 8` into `out` (a whole slice,
    /// [`FanRings::is_whole_slice`]), with AVX2 where the processor has it.
    pub fn slice_gradient(&self, x: &[Vec3], first: usize, out: &mut [Vec3]) {
        assert!(self.is_whole_slice(first) && x.len() == self.length.len() && out.len() == SLICE);
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            let s = first / SLICE;
            let groups = &self.groups[self.offsets[s] as usize..self.offsets[s + 1] as usize];
            // SAFETY: AVX2 (checked above); the slice is whole, so its entries are below the
            // last point of x (whose length is the one the rings were made for), and its rows are
            // in x.
            unsafe { slice_gradient_avx2(x, groups, first, out) };
            return;
        }
        for (k, g) in out.iter_mut().enumerate() {
            *g = self.gradient(x, first + k);
        }
    }

    pub fn memory_bytes(&self) -> usize {
        self.offsets.capacity() * 4
            + self.groups.capacity() * std::mem::size_of::<[u32; SLICE]>()
            + self.length.capacity() * 4
            + self.whole.capacity()
            + (self.spare_starts.capacity()
                + self.spare_entries.capacity()
                + self.spare_offsets.capacity()
                + self.spare_length.capacity())
                * 4
            + self.spare_groups.capacity() * std::mem::size_of::<[u32; SLICE]>()
            + self.spare_kept.capacity()
            + self.spare_whole.capacity()
    }
}

/// The ring of a closed fan from its (next, previous) corners, appended to `out`: `n_0` the
/// first corner's next, each following entry the previous corner of the face whose next is the
/// entry before. Appends nothing and returns false if the walk does not go through every corner
/// once (no single ring).
fn walk_into(corners: &[(u32, u32)], out: &mut Vec<u32>) -> bool {
    let base = out.len();
    let mut walk = || {
        let &(start, mut current) = corners.first()?;
        out.push(start);
        while current != start {
            if out.len() - base >= corners.len() {
                return None;
            }
            out.push(current);
            current = corners.iter().find(|&&(next, _)| next == current)?.1;
        }
        (out.len() - base == corners.len()).then_some(())
    };
    let walked = walk().is_some();
    if !walked {
        out.truncate(base);
    }
    walked
}

/// [`walk_into`] into a vector of its own.
#[cfg(test)]
fn walk(corners: &[(u32, u32)]) -> Option<Vec<u32>> {
    let mut ring = Vec::new();
    walk_into(corners, &mut ring).then_some(ring)
}

/// Three axes of eight lanes.
#[cfg(target_arch = "x86_64")]
type Lanes = (std::arch::x86_64::__m256, std::arch::x86_64::__m256, std::arch::x86_64::__m256);

/// [`FanRings::slice_gradient`] with AVX2: each group's eight points loaded 16 bytes at a time
/// and transposed, the cross products as `Vec3A::cross` spells them (two products, then their
/// difference: the same bits). (Helpers are functions with the target feature, not closures: a
/// closure does not inherit it, and its intrinsics become calls.)
///
/// # Safety
/// The processor must have AVX2; rows `first..first + 8` must be in `x` and every entry of
/// `groups` followed by another point in it.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn slice_gradient_avx2(x: &[Vec3], groups: &[[u32; SLICE]], first: usize, out: &mut [Vec3]) {
    use std::arch::x86_64::*;
    // SAFETY: rows first..first + 8 are in x (the caller's contract).
    let v = unsafe { super::coupling_slices::load_points_transposed(x, first) };
    let zero = _mm256_setzero_ps();
    let (mut even, mut odd) = ((zero, zero, zero), (zero, zero, zero));
    // SAFETY (of every `around`): each entry is followed by another point (the contract).
    let mut b = unsafe { around(x, &groups[0], v) };
    for (t, group) in groups[1..].iter().enumerate() {
        let c = unsafe { around(x, group, v) };
        if t % 2 == 0 {
            even = add(even, cross(b, c));
        } else {
            odd = add(odd, cross(b, c));
        }
        b = c;
    }
    let sixth = _mm256_set1_ps(1.0 / 6.0);
    let sum = add(even, odd);
    let (mut gx, mut gy, mut gz) = ([0f32; SLICE], [0f32; SLICE], [0f32; SLICE]);
    // SAFETY: eight f32 into each local array.
    unsafe {
        _mm256_storeu_ps(gx.as_mut_ptr(), _mm256_mul_ps(sum.0, sixth));
        _mm256_storeu_ps(gy.as_mut_ptr(), _mm256_mul_ps(sum.1, sixth));
        _mm256_storeu_ps(gz.as_mut_ptr(), _mm256_mul_ps(sum.2, sixth));
    }
    for (lane, g) in out.iter_mut().enumerate() {
        *g = Vec3::new(gx[lane], gy[lane], gz[lane]);
    }
}

/// The eight points of `group` minus the lanes' vertices `v`, by axis.
///
/// # Safety
/// The processor must have AVX2; every entry of `group` must be followed by another point.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn around(x: &[Vec3], group: &[u32; SLICE], v: Lanes) -> Lanes {
    use std::arch::x86_64::*;
    let base = x.as_ptr() as *const f32;
    // SAFETY: point i is followed by point i + 1 (the contract), so the 16 bytes from its start
    // are inside the slice.
    let (r04, r15, r26, r37) = unsafe {
        let row = |lane: usize| base.add(3 * group[lane] as usize);
        (
            _mm256_set_m128(_mm_loadu_ps(row(4)), _mm_loadu_ps(row(0))),
            _mm256_set_m128(_mm_loadu_ps(row(5)), _mm_loadu_ps(row(1))),
            _mm256_set_m128(_mm_loadu_ps(row(6)), _mm_loadu_ps(row(2))),
            _mm256_set_m128(_mm_loadu_ps(row(7)), _mm_loadu_ps(row(3))),
        )
    };
    let (px, py, pz, _) = super::coupling_slices::transpose_rows(r04, r15, r26, r37);
    (_mm256_sub_ps(px, v.0), _mm256_sub_ps(py, v.1), _mm256_sub_ps(pz, v.2))
}

/// `b × c` lane by lane: x = b.y c.z - b.z c.y, and cyclic.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn cross(b: Lanes, c: Lanes) -> Lanes {
    use std::arch::x86_64::*;
    (
        _mm256_sub_ps(_mm256_mul_ps(b.1, c.2), _mm256_mul_ps(b.2, c.1)),
        _mm256_sub_ps(_mm256_mul_ps(b.2, c.0), _mm256_mul_ps(b.0, c.2)),
        _mm256_sub_ps(_mm256_mul_ps(b.0, c.1), _mm256_mul_ps(b.1, c.0)),
    )
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn add(sum: Lanes, term: Lanes) -> Lanes {
    use std::arch::x86_64::*;
    (_mm256_add_ps(sum.0, term.0), _mm256_add_ps(sum.1, term.1), _mm256_add_ps(sum.2, term.2))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A latitude-longitude sphere (two poles of valence `around`, the rest of valence 6), its
    /// points moved at random, with its faces' (next, previous) corners per vertex.
    fn sphere(rings: usize, around: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut unit = crate::body::test_randoms(0xfa2_7129);
        let mut x = vec![Vec3::new(0.0, 0.0, 1.0)];
        for r in 1..rings {
            let theta = std::f32::consts::PI * r as f32 / rings as f32;
            for a in 0..around {
                let phi = std::f32::consts::TAU * a as f32 / around as f32;
                x.push(Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()));
            }
        }
        x.push(Vec3::new(0.0, 0.0, -1.0));
        let last = x.len() as u32 - 1;
        let at = |r: usize, a: usize| (1 + (r - 1) * around + a % around) as u32;
        let mut t = Vec::new();
        for a in 0..around {
            t.push([0, at(1, a), at(1, a + 1)]);
            t.push([last, at(rings - 1, a + 1), at(rings - 1, a)]);
            for r in 1..rings - 1 {
                t.push([at(r, a), at(r + 1, a), at(r + 1, a + 1)]);
                t.push([at(r, a), at(r + 1, a + 1), at(r, a + 1)]);
            }
        }
        for p in &mut x {
            *p = *p * 2.0 + Vec3::new(unit(), unit(), unit()) * 0.05 + Vec3::splat(10.0);
        }
        (x, t)
    }

    /// (next, previous) of the faces around each vertex (in face order), and whether they close.
    fn fans(n: usize, t: &[[u32; 3]]) -> Vec<(Vec<(u32, u32)>, bool)> {
        (0..n as u32)
            .map(|v| {
                let corners: Vec<(u32, u32)> = t
                    .iter()
                    .filter_map(|f| {
                        let c = f.iter().position(|&i| i == v)?;
                        Some((f[(c + 1) % 3], f[(c + 2) % 3]))
                    })
                    .collect();
                let (mut next, mut prev): (Vec<u32>, Vec<u32>) = corners.iter().copied().unzip();
                next.sort_unstable();
                prev.sort_unstable();
                let closed = !corners.is_empty() && next == prev;
                (corners, closed)
            })
            .collect()
    }

    /// Eight at a time is one at a time to the bit, and both are the sum over the faces' corners
    /// (in f64) to rounding; a vertex at an open boundary or past the end gets no ring, and its
    /// slice goes one at a time.
    #[test]
    fn ring_gradients_are_the_corner_sums() {
        let (x, mut t) = sphere(7, 9);
        let n = x.len();
        // A hole: the corners of the removed face are no longer closed fans.
        let removed = t.remove(20);
        let fan = fans(n, &t);
        let rings = FanRings::new(n, |v, out| {
            out.extend_from_slice(&fan[v].0);
            fan[v].1
        });
        for &v in &removed {
            assert!(!rings.is_ring(v as usize), "vertex {v}");
        }
        assert!((0..n).filter(|&v| rings.is_ring(v)).count() == n - 3);
        let whole: Vec<usize> = (0..n).step_by(SLICE).filter(|&f| rings.is_whole_slice(f)).collect();
        assert!(whole.len() >= 3 && whole.len() < n / SLICE, "{whole:?}");
        for &first in &whole {
            let mut fast = [Vec3::NAN; SLICE];
            rings.slice_gradient(&x, first, &mut fast);
            for (lane, g) in fast.iter().enumerate() {
                assert_eq!(*g, rings.gradient(&x, first + lane), "vertex {}", first + lane);
            }
        }
        for v in (0..n).filter(|&v| rings.is_ring(v)) {
            let p = |i: u32| x[i as usize].as_dvec3();
            let exact: glam::DVec3 =
                fan[v].0.iter().map(|&(b, c)| (p(b) - p(v as u32)).cross(p(c) - p(v as u32)) / 6.0).sum();
            let got = rings.gradient(&x, v).as_dvec3();
            assert!(exact.length() > 0.1 && (got - exact).length() <= 1e-5 * exact.length(), "{v}: {got} vs {exact}");
        }
    }

    /// Two cones meeting at a vertex close its fan but make no single ring.
    #[test]
    fn two_rings_at_a_vertex_are_no_ring() {
        let one = [(1, 2), (2, 3), (3, 1)];
        assert_eq!(walk(&one), Some(vec![1, 2, 3]));
        let two = [(1, 2), (2, 3), (3, 1), (4, 5), (5, 6), (6, 4)];
        assert_eq!(walk(&two), None);
        assert_eq!(walk(&[(1, 2), (2, 4)]), None);
        let rings = FanRings::new(1, |_, out| {
            out.extend_from_slice(&two);
            true
        });
        assert!(!rings.is_ring(0) && !rings.is_whole_slice(0));
    }
}
