//! Springs along the mesh edges (SPEC 2.1): Hooke force, damping along the spring, energy and
//! the stiffness block used by the implicit integrator. Pure kernels; the loops live in `forces`.

use glam::Vec3;

use super::headroom::{reserve_for, with_room};

/// The springs of a body: end vertices and rest lengths, one entry per unbroken mesh edge.
#[derive(Clone, Debug, Default)]
pub(crate) struct Springs {
    /// End vertices `[i, j]`, i < j (the implicit integrator's assembly relies on it), sorted:
    /// the edges' order without the broken ones (`Body::break_edges` searches them).
    pub ends: Vec<[u32; 2]>,
    /// Rest length L0, m.
    pub rest: Vec<f32>,
    /// Springs around each vertex in CSR form: those of vertex i are
    /// `adjacency[offsets[i]..offsets[i + 1]]` as (spring, other end), in spring order. Lets the
    /// parallel loops gather per vertex in a fixed order instead of scattering. Both empty
    /// unless built ([`Adjacency`]).
    pub offsets: Vec<u32>,
    pub adjacency: Vec<(u32, u32)>,
    /// Names this adjacency (each [`Springs::build_adjacency`] takes a new one; 0: none built),
    /// so that what is laid out from it (the implicit integrator's coupling slices) is laid out
    /// again only when it changes.
    pub adjacency_id: u64,
    /// Per spring, true where its edge is the side of one face only (a cloth's border, a side
    /// of an opened crack): such a spring never breaks (a crack parts two faces), so the
    /// fracture check skips it. Made by a rebuild after a topology change, empty before the
    /// first (and in a body that cannot crack); every spring may break where it is empty.
    pub one_face: Vec<bool>,
}

/// Whether a body's springs keep their per-vertex adjacency ([`Springs::offsets`],
/// [`Springs::adjacency`]): only the implicit integrator gathers its system by vertex; the
/// others loop over the springs, and the adjacency was about 30% of such a body's memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Adjacency {
    Built,
    LeftOut,
}

impl Springs {
    /// Builds the per-vertex adjacency for `vertex_count` vertices.
    pub fn build_adjacency(&mut self, vertex_count: usize) {
        // Into the old buffers (see `surface::rebuild_springs`). A counting sort without a
        // second array of cursors: counted at `offsets[v + 2]`, summed so that `offsets[v + 1]`
        // is where vertex v's springs start, which the scatter then moves on to where they end,
        // the next vertex's start (a copy of the offsets as cursors was a fresh allocation at
        // every topology change).
        let mut offsets = std::mem::take(&mut self.offsets);
        offsets.clear();
        offsets.resize(vertex_count + 2, 0);
        for &[i, j] in &self.ends {
            debug_assert!(i < j, "spring ends must be ordered: [{i}, {j}]");
            offsets[i as usize + 2] += 1;
            offsets[j as usize + 2] += 1;
        }
        for v in 2..vertex_count + 2 {
            offsets[v] += offsets[v - 1];
        }
        let mut adjacency = std::mem::take(&mut self.adjacency);
        // Every slot is written below: only slots beyond the old length are filled first (as
        // in `Gas::build_corners`).
        adjacency.truncate(2 * self.ends.len());
        adjacency.resize(2 * self.ends.len(), (0, 0));
        for (k, &[i, j]) in self.ends.iter().enumerate() {
            let slot = &mut offsets[i as usize + 1];
            adjacency[*slot as usize] = (k as u32, j);
            *slot += 1;
            let slot = &mut offsets[j as usize + 1];
            adjacency[*slot as usize] = (k as u32, i);
            *slot += 1;
        }
        offsets.pop();
        self.offsets = offsets;
        self.adjacency = adjacency;
        // Unique over the process, not per body: a copy of a body's springs keeps its id, and
        // an id is never reused for another adjacency.
        static NEXT_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        self.adjacency_id = NEXT_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    }

    /// Room for a fraction `headroom` more springs and vertices in every array, its memory
    /// written now: a topology change rebuilds the springs into these arrays
    /// (`surface::rebuild_springs`), and within that room moves none of them (a reallocation
    /// copies the old contents, and new memory faults its pages in one by one on first use).
    pub fn reserve_headroom(&mut self, headroom: f64) {
        let count = self.ends.len();
        with_room(&mut self.ends, headroom);
        with_room(&mut self.rest, headroom);
        // (Empty until the first change: it is made with the fracture's rebuilds.)
        reserve_for(&mut self.one_face, count, headroom);
        if self.adjacency_id != 0 {
            with_room(&mut self.adjacency, headroom);
            // The offsets take one more entry while they are built.
            self.offsets.push(0);
            with_room(&mut self.offsets, headroom);
            self.offsets.pop();
        }
    }

    /// (spring, other end) pairs around vertex `i`.
    pub fn around(&self, i: usize) -> &[(u32, u32)] {
        &self.adjacency[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    pub fn len(&self) -> usize {
        self.ends.len()
    }

    pub fn memory_bytes(&self) -> usize {
        self.ends.capacity() * 8
            + self.rest.capacity() * 4
            + self.offsets.capacity() * 4
            + self.adjacency.capacity() * 8
            + self.one_face.capacity()
    }

    /// Whether spring `k` joins two faces (see [`Springs::one_face`]), so may break.
    #[inline]
    pub fn may_break(&self, k: usize) -> bool {
        !self.one_face.get(k).copied().unwrap_or(false)
    }
}

/// Lengths below this fraction of the rest length have no direction: no force (degenerate guard).
pub(crate) const MIN_LENGTH_RATIO: f32 = 1e-6;

/// SPEC 2.1: force on end i of spring (i, j); the force on j is its opposite.
/// `f = K_s (|d| - L0) u + K_d ((v_j - v_i)·u) u`, `d = x_j - x_i`, `u = d/|d|`.
pub(crate) fn spring_force(xi: Vec3, xj: Vec3, vi: Vec3, vj: Vec3, rest: f32, ks: f32, kd: f32) -> Vec3 {
    let d = xj - xi;
    let len = d.length();
    if len <= MIN_LENGTH_RATIO * rest {
        return Vec3::ZERO;
    }
    let u = d / len;
    u * (ks * (len - rest) + kd * (vj - vi).dot(u))
}

/// Extension `|d| - L0` (m): the spring energy is `K_s e²/2` (`energy::springs_energy_strain`),
/// the strain `e / L0`.
pub(crate) fn spring_extension(xi: Vec3, xj: Vec3, rest: f32) -> f32 {
    (xj - xi).length() - rest
}

/// Strain `(|d| - L0)/L0`.
pub(crate) fn spring_strain(xi: Vec3, xj: Vec3, rest: f32) -> f32 {
    spring_extension(xi, xj, rest) / rest
}

/// The stiffness block `B = ∂f_i/∂x_j = a I + b u uᵀ` of a spring, returned as `(a, b, u)`:
/// `a = K_s max(0, 1 - L0/|d|)`, `a + b = K_s` (the exact Hessian with its transverse part clamped
/// at zero when compressed, so the implicit system stays positive definite).
#[cfg(test)]
pub(crate) fn spring_block(xi: Vec3, xj: Vec3, rest: f32, ks: f32) -> (f32, f32, Vec3) {
    let d = xj - xi;
    let len = d.length();
    if len <= MIN_LENGTH_RATIO * rest {
        return (0.0, 0.0, Vec3::ZERO);
    }
    let (a, b) = spring_block_coefficients(len, rest, ks);
    (a, b, d / len)
}

/// `(a, b)` of [`spring_block`] for a spring of length `len` (above the degenerate guard).
pub(crate) fn spring_block_coefficients(len: f32, rest: f32, ks: f32) -> (f32, f32) {
    let a = ks * (1.0 - rest / len).max(0.0);
    (a, ks - a)
}

/// True when a spring of length `len` is too short to have a direction (no force, no block).
pub(crate) fn is_degenerate(len: f32, rest: f32) -> bool {
    len <= MIN_LENGTH_RATIO * rest
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn force_is_minus_energy_gradient() {
        let (xi, xj) = (Vec3::new(0.1, 0.2, -0.3), Vec3::new(1.0, -0.4, 0.5));
        let (rest, ks) = (0.7, 123.0);
        let f = spring_force(xi, xj, Vec3::ZERO, Vec3::ZERO, rest, ks, 0.0);
        let h = 1e-3f32;
        for axis in 0..3 {
            let mut e = Vec3::ZERO;
            e[axis] = h;
            let energy = |xi: Vec3| {
                crate::body::energy::springs_energy_strain(|_| spring_extension(xi, xj, rest), &[rest], ks).0
            };
            let fd = (energy(xi + e) - energy(xi - e)) / (2.0 * h as f64);
            assert!((fd + f[axis] as f64).abs() < 1e-2 * (1.0 + fd.abs()), "axis {axis}: {fd} vs {}", f[axis]);
        }
    }

    #[test]
    fn block_matches_finite_differences_when_stretched() {
        let (xi, xj) = (Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.2, 0.3, -0.2));
        let (rest, ks) = (1.0, 50.0);
        let (a, b, u) = spring_block(xi, xj, rest, ks);
        let h = 1e-3f32;
        for axis in 0..3 {
            let mut e = Vec3::ZERO;
            e[axis] = h;
            let fd = (spring_force(xi, xj + e, Vec3::ZERO, Vec3::ZERO, rest, ks, 0.0)
                - spring_force(xi, xj - e, Vec3::ZERO, Vec3::ZERO, rest, ks, 0.0))
                / (2.0 * h);
            let exact = e / h * a + u * (b * u.dot(e / h));
            assert!((fd - exact).length() < 2e-2 * ks, "axis {axis}: {fd} vs {exact}");
        }
    }

    #[test]
    fn damping_acts_along_the_spring_only() {
        let f = spring_force(Vec3::ZERO, Vec3::X, Vec3::ZERO, Vec3::new(2.0, 5.0, 0.0), 1.0, 0.0, 3.0);
        assert_eq!(f, Vec3::new(6.0, 0.0, 0.0));
        assert_eq!(spring_force(Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::X, 1.0, 1.0, 1.0), Vec3::ZERO);
    }
}
