//! Sparse Cholesky factorization of a scalar symmetric positive definite matrix on a graph,
//! applied to three right-hand sides at once (x, y, z as one `Vec3A`). The implicit integrator
//! (SPEC 2.2) factors the coarse level of its preconditioner with it (`coarse`).
//!
//! Measured and not used: the factor of the whole mesh's `M + c (h² K_s + h K_d) L` as the
//! preconditioner cut the CG iterations of the issue-5 balloon from 46 to 15 per step on the
//! ground (13 to 5.5 without gravity), but with 467k entries in L one solve cost about four CG
//! iterations, so the steps got slower (16 to 22 ms against 12).
//!
//! Ordering: nested dissection by coordinate bisection of the rest positions (a surface mesh has
//! small separators, so the fill stays near `n log n`). Factorization: up-looking (row by row, the
//! pattern of each row from the elimination tree), in f64, stored in f32. Solves gather only (the
//! forward solve by rows of L, the backward one by columns), so the two halves of every dissection
//! can be solved in parallel, each entry always summed in the same order.
//!
//! Measured and not kept: one copy of the factor (by rows; the backward solve scattering along
//! them instead of gathering along the columns) halves its bytes (606 to 314 KB on the issue-5
//! balloon's coarse level when its factor was exact, which the solves stream twice per CG
//! iteration) and took about a fifth off the backward solve (its share of a profile), about 1%
//! of a step. Its sums run in
//! one chain per row of the solution; over six drops of the balloon (benches/body_balloon.rs,
//! `BODY_DROP_OFFSET`) it took 6.48 CG iterations per step against 6.35 for these solves (the
//! drops spread by 0.3 either way), so no gain could be shown.

use glam::{Vec3, Vec3A};

#[cfg(test)]
use crate::parallel::WorkerPool;

/// Defines the method `$name`, which runs the method `$with` (the same arguments after a
/// [`WeightedSum`]) with the fastest weighted sum of this processor. With AVX2 and FMA (checked
/// at run time: the library is built for baseline x86-64) it runs `$avx`, a function with those
/// features enabled into which `$with` (`#[inline(always)]`) and the kernel inline, so the
/// loop has no call per row (a row of the balloon's coarse factor has about 11 entries, 31 when
/// it was exact).
macro_rules! dispatched {
    ($(#[$doc:meta])* fn $name:ident / $avx:ident / $with:ident($($arg:ident: $ty:ty),* $(,)?)) => {
        $(#[$doc])*
        fn $name(&self, $($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
                // SAFETY: the processor has the features the function is compiled for (checked
                // just above).
                unsafe { self.$avx($($arg),*) };
                return;
            }
            self.$with(WeightedSum { avx2_fma: false }, $($arg),*)
        }

        /// The twin with AVX2 and FMA.
        ///
        /// # Safety
        /// The processor must have AVX2 and FMA.
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn $avx(&self, $($arg: $ty),*) {
            self.$with(WeightedSum { avx2_fma: true }, $($arg),*)
        }
    };
}

/// Parts of the dissection with fewer vertices than this are not split further.
const LEAF: usize = 48;

/// Subtrees with fewer rows than this are solved on one thread: half of one (a few thousand
/// entries of L, some microseconds) is about what handing a task to another thread costs. The
/// coarse level of the balloon (1,167 rows, 12.6k entries) splits into halves of 510 and 584
/// rows, and the second once more.
const PARALLEL_MIN: usize = 512;

/// A node of the dissection tree: the new indices `start..end` are its two halves (`left`, then
/// `right`) followed by its separator (`separator..end`). Leaves have no children.
#[derive(Clone, Copy, Debug)]
struct Part {
    start: u32,
    separator: u32,
    end: u32,
    children: Option<(u32, u32)>,
}

/// `L Lᵀ = P A Pᵀ` for a scalar SPD matrix A.
#[derive(Clone, Debug, Default)]
pub(crate) struct Cholesky {
    /// `perm[k]` = the original index of row k of the factor.
    perm: Vec<u32>,
    /// Inverse diagonal of L.
    inv_diag: Vec<f32>,
    /// Strictly lower part of L by columns (entries below the diagonal of each column).
    col_ptr: Vec<u32>,
    col_row: Vec<u32>,
    col_val: Vec<f32>,
    /// The same entries by rows (entries left of the diagonal of each row).
    row_ptr: Vec<u32>,
    row_col: Vec<u32>,
    row_val: Vec<f32>,
    parts: Vec<Part>,
    /// Per row of the top separator, where its entries in the second half's columns and in
    /// the separator's own columns start (a row's entries are in ascending columns: the first
    /// half's, the second half's, the separator's). Empty when the matrix is one leaf.
    top_split: Vec<[u32; 2]>,
}

/// The entries of a factor (by columns: `col_ptr`, `col_row`, `col_val`) that are at least
/// `threshold(row)` in size; returns them by columns as given, with the rows' offsets.
fn keep_large_entries(
    col_ptr: &[u32],
    col_row: &[u32],
    col_val: &[f64],
    threshold: impl Fn(usize) -> f64,
) -> (Vec<u32>, Vec<u32>, Vec<f64>, Vec<u32>) {
    let n = col_ptr.len() - 1;
    let (mut ptr, mut rows, mut values) = (Vec::with_capacity(n + 1), Vec::new(), Vec::new());
    let mut row_count = vec![0u32; n];
    ptr.push(0);
    for j in 0..n {
        for p in col_ptr[j] as usize..col_ptr[j + 1] as usize {
            let k = col_row[p] as usize;
            if col_val[p].abs() >= threshold(k) {
                rows.push(col_row[p]);
                values.push(col_val[p]);
                row_count[k] += 1;
            }
        }
        ptr.push(rows.len() as u32);
    }
    let mut row_ptr = vec![0u32; n + 1];
    for k in 0..n {
        row_ptr[k + 1] = row_ptr[k] + row_count[k];
    }
    // (Kept for the body's life, and counted in its memory.)
    rows.shrink_to_fit();
    values.shrink_to_fit();
    (ptr, rows, values, row_ptr)
}

/// Nested dissection of the graph (`offsets`, `neighbors` in CSR form) by the positions `pos`;
/// returns the new order and the dissection tree (root last).
fn nested_dissection(offsets: &[u32], neighbors: &[u32], pos: &[Vec3]) -> (Vec<u32>, Vec<Part>) {
    let n = pos.len();
    let mut order = Vec::with_capacity(n);
    let mut parts = Vec::new();
    let mut label = vec![0u32; n];
    let mut stamp = 0u32;
    let all: Vec<u32> = (0..n as u32).collect();
    dissect(all, offsets, neighbors, pos, &mut label, &mut stamp, &mut order, &mut parts);
    (order, parts)
}

#[allow(clippy::too_many_arguments)]
fn dissect(
    mut set: Vec<u32>,
    offsets: &[u32],
    neighbors: &[u32],
    pos: &[Vec3],
    label: &mut [u32],
    stamp: &mut u32,
    order: &mut Vec<u32>,
    parts: &mut Vec<Part>,
) -> u32 {
    let start = order.len() as u32;
    if set.len() <= LEAF {
        order.extend_from_slice(&set);
        let end = order.len() as u32;
        parts.push(Part { start, separator: start, end, children: None });
        return parts.len() as u32 - 1;
    }
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for &i in &set {
        lo = lo.min(pos[i as usize]);
        hi = hi.max(pos[i as usize]);
    }
    let extent = hi - lo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    set.sort_unstable_by(|&a, &b| pos[a as usize][axis].total_cmp(&pos[b as usize][axis]).then(a.cmp(&b)));
    let mid = set.len() / 2;
    *stamp += 2;
    let (left_tag, right_tag) = (*stamp, *stamp + 1);
    for &i in &set[..mid] {
        label[i as usize] = left_tag;
    }
    for &i in &set[mid..] {
        label[i as usize] = right_tag;
    }
    // The vertex separator: the vertices of the left half with a neighbour in the right half.
    // (The left half is the smaller without it: 510 rows against 584 at the top of the issue-5
    // balloon's coarse level. Moving the split so that both come out even took ten drops from
    // 8.59 to 8.70 CG iterations a step (benches/body_balloon.rs, `BODY_DROP_OFFSET`), about
    // what evener halves could save on two threads.)
    let (mut left, mut separator) = (Vec::with_capacity(mid), Vec::new());
    for &i in &set[..mid] {
        let around = &neighbors[offsets[i as usize] as usize..offsets[i as usize + 1] as usize];
        if around.iter().any(|&j| label[j as usize] == right_tag) {
            separator.push(i);
        } else {
            left.push(i);
        }
    }
    let right = set[mid..].to_vec();
    drop(set);
    let a = dissect(left, offsets, neighbors, pos, label, stamp, order, parts);
    let b = dissect(right, offsets, neighbors, pos, label, stamp, order, parts);
    let sep_start = order.len() as u32;
    order.extend_from_slice(&separator);
    let end = order.len() as u32;
    parts.push(Part { start, separator: sep_start, end, children: Some((a, b)) });
    parts.len() as u32 - 1
}

impl Cholesky {
    /// Factors `A = diag(diagonal) + off-diagonal`, with the off-diagonal entries of row i in
    /// `neighbors[offsets[i]..offsets[i+1]]` / `values[..]` (symmetric, each pair listed from
    /// both ends). `pos` guides the ordering. Returns `None` if A is not positive definite.
    ///
    /// With `drop_tolerance` (one threshold per row of A, each at least 0; empty: none) the
    /// factor is incomplete: once A is factored, the entries of the row of L that A's row i
    /// became smaller than `drop_tolerance[i]` times that row's diagonal entry are left out. `L̃ L̃ᵀ` is still symmetric positive definite (a triangular factor with a
    /// positive diagonal), so the solves are still a correct preconditioner for conjugate
    /// gradients, only a less exact one, at fewer entries per solve (see `coarse`).
    pub fn factor(
        diagonal: &[f64],
        offsets: &[u32],
        neighbors: &[u32],
        values: &[f64],
        pos: &[Vec3],
        drop_tolerance: &[f64],
    ) -> Option<Self> {
        let n = diagonal.len();
        assert!(
            drop_tolerance.is_empty() || (drop_tolerance.len() == n && drop_tolerance.iter().all(|&t| t >= 0.0)),
            "drop tolerances for {n} rows: {} given, or not all at least 0",
            drop_tolerance.len()
        );
        let (perm, parts) = nested_dissection(offsets, neighbors, pos);
        let mut inverse = vec![0u32; n];
        for (k, &i) in perm.iter().enumerate() {
            inverse[i as usize] = k as u32;
        }
        // Upper part of the permuted matrix by columns: for column k, the rows i < k.
        let mut upper_ptr = vec![0u32; n + 1];
        for (k, &i) in perm.iter().enumerate() {
            let around = &neighbors[offsets[i as usize] as usize..offsets[i as usize + 1] as usize];
            upper_ptr[k + 1] =
                upper_ptr[k] + around.iter().filter(|&&j| (inverse[j as usize] as usize) < k).count() as u32;
        }
        let mut upper_row = vec![0u32; upper_ptr[n] as usize];
        let mut upper_val = vec![0f64; upper_ptr[n] as usize];
        for (k, &i) in perm.iter().enumerate() {
            let mut cursor = upper_ptr[k] as usize;
            for p in offsets[i as usize] as usize..offsets[i as usize + 1] as usize {
                let row = inverse[neighbors[p] as usize];
                if (row as usize) < k {
                    upper_row[cursor] = row;
                    upper_val[cursor] = values[p];
                    cursor += 1;
                }
            }
        }
        // Elimination tree (Liu), with path compression through `ancestor`.
        let none = u32::MAX;
        let mut parent = vec![none; n];
        let mut ancestor = vec![none; n];
        for k in 0..n {
            for &row in &upper_row[upper_ptr[k] as usize..upper_ptr[k + 1] as usize] {
                let mut i = row;
                while i != none && (i as usize) < k {
                    let next = ancestor[i as usize];
                    ancestor[i as usize] = k as u32;
                    if next == none {
                        parent[i as usize] = k as u32;
                    }
                    i = next;
                }
            }
        }
        // Row patterns: row k of L holds the columns reached from the entries of column k of
        // the upper part by walking up the tree until k (or a column already seen for k).
        let mut flag = vec![none; n];
        let mut stack = Vec::new();
        let mut row_pattern = |k: usize, out: &mut Vec<u32>| {
            out.clear();
            flag[k] = k as u32;
            for &row in &upper_row[upper_ptr[k] as usize..upper_ptr[k + 1] as usize] {
                let mut i = row;
                let base = stack.len();
                while flag[i as usize] != k as u32 {
                    stack.push(i);
                    flag[i as usize] = k as u32;
                    i = parent[i as usize];
                }
                // Columns in topological order: deepest first along each path.
                out.extend(stack.drain(base..).rev());
            }
        };
        let mut col_count = vec![0u32; n];
        let mut pattern = Vec::new();
        for k in 0..n {
            row_pattern(k, &mut pattern);
            for &j in &pattern {
                col_count[j as usize] += 1;
            }
        }
        let mut col_ptr = vec![0u32; n + 1];
        for j in 0..n {
            col_ptr[j + 1] = col_ptr[j] + col_count[j];
        }
        let nnz = col_ptr[n] as usize;
        let mut col_row = vec![0u32; nnz];
        let mut col_val64 = vec![0f64; nnz];
        let mut diag = vec![0f64; n];
        let mut cursor: Vec<u32> = col_ptr[..n].to_vec();
        let mut x = vec![0f64; n];
        let mut row_ptr = vec![0u32; n + 1];
        for k in 0..n {
            row_pattern(k, &mut pattern);
            // x = column k of the upper part; then solve L[..k,..k] y = x on the pattern. The
            // pattern lists every column after the columns it depends on, except that paths
            // were appended in the order they were found: sort them into elimination order.
            pattern.sort_unstable();
            for p in upper_ptr[k] as usize..upper_ptr[k + 1] as usize {
                x[upper_row[p] as usize] = upper_val[p];
            }
            let mut d = diagonal[perm[k] as usize];
            for &j in &pattern {
                let j = j as usize;
                let lkj = x[j] / diag[j];
                x[j] = 0.0;
                for p in col_ptr[j] as usize..cursor[j] as usize {
                    x[col_row[p] as usize] -= col_val64[p] * lkj;
                }
                d -= lkj * lkj;
                let p = cursor[j] as usize;
                col_row[p] = k as u32;
                col_val64[p] = lkj;
                cursor[j] += 1;
            }
            // Not positive (or NaN): A is not positive definite.
            if d <= 0.0 || !d.is_finite() {
                return None;
            }
            diag[k] = d.sqrt();
            row_ptr[k + 1] = row_ptr[k] + pattern.len() as u32;
        }
        if !drop_tolerance.is_empty() {
            let threshold = |k: usize| drop_tolerance[perm[k] as usize] * diag[k];
            (col_ptr, col_row, col_val64, row_ptr) = keep_large_entries(&col_ptr, &col_row, &col_val64, threshold);
        }
        let nnz = col_row.len();
        // The same entries by rows (columns ascending within each row).
        let mut row_col = vec![0u32; nnz];
        let mut row_val = vec![0f32; nnz];
        let mut fill: Vec<u32> = row_ptr[..n].to_vec();
        for j in 0..n {
            for p in col_ptr[j] as usize..col_ptr[j + 1] as usize {
                let r = col_row[p] as usize;
                let q = fill[r] as usize;
                row_col[q] = j as u32;
                row_val[q] = col_val64[p] as f32;
                fill[r] += 1;
            }
        }
        let top_split = match parts.last().and_then(|root| Some((root, root.children?))) {
            Some((root, (_, b))) => {
                let b = parts[b as usize];
                (root.separator as usize..root.end as usize)
                    .map(|k| {
                        let row = &row_col[row_ptr[k] as usize..row_ptr[k + 1] as usize];
                        let at = |end: u32| row_ptr[k] + row.partition_point(|&c| c < end) as u32;
                        [at(b.start), at(b.end)]
                    })
                    .collect()
            }
            None => Vec::new(),
        };
        Some(Self {
            perm,
            inv_diag: diag.iter().map(|&d| (1.0 / d) as f32).collect(),
            col_ptr,
            col_row,
            col_val: col_val64.iter().map(|&v| v as f32).collect(),
            row_ptr,
            row_col,
            row_val,
            parts,
            top_split,
        })
    }

    /// Rows of the matrix it was made for.
    pub fn len(&self) -> usize {
        self.perm.len()
    }

    /// Entries of L below the diagonal.
    #[cfg(test)]
    pub fn fill(&self) -> usize {
        self.col_row.len()
    }

    pub fn memory_bytes(&self) -> usize {
        (self.perm.capacity()
            + self.inv_diag.capacity()
            + self.col_ptr.capacity()
            + self.col_row.capacity()
            + self.col_val.capacity()
            + self.row_ptr.capacity()
            + self.row_col.capacity()
            + self.row_val.capacity())
            * 4
            + self.parts.capacity() * std::mem::size_of::<Part>()
            + self.top_split.capacity() * 8
    }

    /// `out[i] = A⁻¹ rhs` for the first `len()` entries, using `work` (resized) as scratch.
    #[cfg(test)]
    pub fn solve(&self, pool: &WorkerPool, rhs: &[Vec3A], out: &mut [Vec3A], work: &mut Vec<Vec3A>) {
        // Without workers nothing may call rayon (it would use the global pool).
        let parallel = pool.threads() > 1;
        pool.install(|| self.solve_on(parallel, rhs, out, work));
    }

    /// [`Cholesky::solve`] on the calling thread alone when `parallel` is false (inside a team
    /// region, where the other threads wait at a barrier and take no tasks); the same bits
    /// either way.
    #[cfg(test)]
    pub fn solve_on(&self, parallel: bool, rhs: &[Vec3A], out: &mut [Vec3A], work: &mut Vec<Vec3A>) {
        let n = self.len();
        work.resize(n, Vec3A::ZERO);
        for (w, &i) in work.iter_mut().zip(&self.perm) {
            *w = rhs[i as usize];
        }
        let root = self.parts.len() - 1;
        let y = SharedSlice(work.as_mut_ptr(), n);
        self.forward(root, y, parallel);
        self.backward(root, y, parallel);
        for (w, &i) in work.iter().zip(&self.perm) {
            out[i as usize] = *w;
        }
    }

    /// The two halves of the top dissection (parts to solve at the same time), or None when
    /// the matrix is one leaf.
    pub fn top_halves(&self) -> Option<(usize, usize)> {
        self.parts.last()?.children.map(|(a, b)| (a as usize, b as usize))
    }

    /// The top part (the whole matrix).
    pub fn root(&self) -> usize {
        self.parts.len() - 1
    }

    /// Rows (in the factor's order) of part `node` and its subtree, and of its separator alone.
    pub fn part_rows(&self, node: usize) -> (std::ops::Range<usize>, std::ops::Range<usize>) {
        let part = self.parts[node];
        (part.start as usize..part.end as usize, part.separator as usize..part.end as usize)
    }

    /// `perm[k]`: the original index of row k of the factor.
    pub fn perm(&self) -> &[u32] {
        &self.perm
    }

    /// What half `half` (0 or 1, of [`Cholesky::top_halves`]) adds to the forward solve of
    /// each row of the top separator: `out[k - separator.start] = Σ L[k][j] y[j]` over the
    /// half's columns j, from `y` holding the half's forward solution. The two halves' parts are
    /// independent: each member of a team makes its own after solving its half.
    pub fn top_separator_part(&self, half: usize, y: &[Vec3A], out: &mut [Vec3A]) {
        assert!(y.len() >= self.len(), "a solution of {} rows for a factor of {}", y.len(), self.len());
        self.top_separator_part_sums(half, y, out);
    }

    dispatched! {
        /// The sums of [`Cholesky::top_separator_part`].
        fn top_separator_part_sums / top_separator_part_avx2 / top_separator_part_with(
            half: usize, y: &[Vec3A], out: &mut [Vec3A]
        )
    }

    #[inline(always)]
    fn top_separator_part_with(&self, s: WeightedSum, half: usize, y: &[Vec3A], out: &mut [Vec3A]) {
        let root = self.parts[self.root()];
        for ((k, o), split) in (root.separator as usize..root.end as usize).zip(out.iter_mut()).zip(&self.top_split) {
            let entries = if half == 0 {
                self.row_ptr[k] as usize..split[0] as usize
            } else {
                split[0] as usize..split[1] as usize
            };
            // SAFETY: the factor's columns are its rows, and y has them all (checked by the
            // caller).
            *o = unsafe { s.sum::<true>(y, &self.row_col[entries.clone()], &self.row_val[entries]) };
        }
    }

    /// The forward and backward solve of the top separator's rows in `y` (holding their right
    /// side), with the halves' parts `parts` ([`Cholesky::top_separator_part`]):
    /// `y[k] = ((b[k] - part0[k]) - part1[k] - Σ_sep L[k][j] y[j]) / L[k][k]`, then `Lᵀ` over
    /// the separator. Reads and writes only the separator's rows of `y` (so each member of a
    /// team can solve it in a copy of its own, and none waits for another).
    pub fn top_separator_solve(&self, y: &mut [Vec3A], parts: [&[Vec3A]; 2]) {
        assert!(y.len() >= self.len(), "a solution of {} rows for a factor of {}", y.len(), self.len());
        self.top_separator_forward(y, parts);
        self.backward_separator(self.root(), SharedSlice(y.as_mut_ptr(), y.len()));
    }

    dispatched! {
        /// The forward solve of [`Cholesky::top_separator_solve`].
        fn top_separator_forward / top_separator_forward_avx2 / top_separator_forward_with(
            y: &mut [Vec3A], parts: [&[Vec3A]; 2]
        )
    }

    #[inline(always)]
    fn top_separator_forward_with(&self, s: WeightedSum, y: &mut [Vec3A], parts: [&[Vec3A]; 2]) {
        let part = self.parts[self.root()];
        for (t, (k, split)) in (part.separator as usize..part.end as usize).zip(&self.top_split).enumerate() {
            let entries = split[1] as usize..self.row_ptr[k + 1] as usize;
            // SAFETY: the factor's columns are its rows, and y has them all (checked by the
            // caller).
            let sum = unsafe { s.sum::<true>(y, &self.row_col[entries.clone()], &self.row_val[entries]) };
            y[k] = (((y[k] - parts[0][t]) - parts[1][t]) - sum) * self.inv_diag[k];
        }
    }

    /// The forward solve `L y = b` of the subtree of part `node` alone, on this thread. `y` (in
    /// the factor's order) holds b on entry.
    ///
    /// # Safety
    /// `y` points to `len()` elements. Meanwhile no other thread reads or writes the rows this
    /// call writes (its subtree's), or writes the rows it reads (earlier rows of its subtree).
    pub unsafe fn forward_part(&self, node: usize, y: *mut Vec3A) {
        self.forward(node, SharedSlice(y, self.len()), false);
    }

    /// The backward solve `Lᵀ x = y` of the subtree of part `node` alone, on this thread, as
    /// [`Cholesky::forward_part`] (the rows after the subtree's, its ancestors' separators,
    /// solved).
    ///
    /// # Safety
    /// As [`Cholesky::forward_part`], with the rows it reads being later ones.
    pub unsafe fn backward_part(&self, node: usize, y: *mut Vec3A) {
        self.backward(node, SharedSlice(y, self.len()), false);
    }

    /// Forward solve `L y = b` on the rows of part `node` (its halves, then its separator). The
    /// two halves' subtrees of a part solved by one thread go row by row side by side
    /// ([`Cholesky::forward_pair`]).
    fn forward(&self, node: usize, y: SharedSlice, parallel: bool) {
        let part = self.parts[node];
        if let Some((a, b)) = part.children {
            if parallel && (part.end - part.start) as usize >= PARALLEL_MIN {
                join(|| self.forward(a as usize, y, true), || self.forward(b as usize, y, true));
            } else {
                self.forward_pair(self.subtree_rows(a), self.subtree_rows(b), y);
            }
        }
        self.forward_separator(node, y);
    }

    /// Rows of part `node` and its subtree (in the factor's order, a forward solve may take
    /// them in ascending order: each row reads only earlier rows of its subtree).
    fn subtree_rows(&self, node: u32) -> std::ops::Range<usize> {
        let part = self.parts[node as usize];
        part.start as usize..part.end as usize
    }

    dispatched! {
        /// The separator rows of [`Cholesky::forward`].
        fn forward_separator / forward_separator_avx2 / forward_separator_with(node: usize, y: SharedSlice)
    }

    #[inline(always)]
    fn forward_separator_with(&self, s: WeightedSum, node: usize, y: SharedSlice) {
        let part = self.parts[node];
        // SAFETY: rows separator..end are written by this call only; the rows it reads are
        // earlier ones of this part's subtree, finished before it.
        let y = unsafe { y.get() };
        assert!(y.len() >= self.len(), "a solution of {} rows for a factor of {}", y.len(), self.len());
        for k in part.separator as usize..part.end as usize {
            self.forward_row(s, y, k);
        }
    }

    dispatched! {
        /// The forward solve of two independent subtrees (rows `a` and `b`, the halves of a
        /// part), a row of each in turn.
        ///
        /// A row waits for the rows just before it (see [`weighted_sum_avx2_fma`]), so one
        /// subtree's rows form a chain of dependent sums; the other's row fills the wait. On the
        /// issue-5 balloon (benches/body_balloon.rs, two profiles each way) the two triangular
        /// solves went from 0.395 to 0.337-0.341 of the product's time on one thread (about 1.3%
        /// of a step), but only from 0.318-0.323 to 0.307-0.314 on two (each member solves one
        /// half, whose own halves are smaller), with the same bits (each row's sum is unchanged:
        /// the drop keeps its CG iterations step for step). Four subtrees side by side (the
        /// grandchildren, then the halves' separators as a pair) gave the same bits but no gain:
        /// 0.424 -> 0.477 of the product's time on one thread, 0.373 -> 0.372 on two (three
        /// profiles each way).
        fn forward_pair / forward_pair_avx2 / forward_pair_with(
            a: std::ops::Range<usize>, b: std::ops::Range<usize>, y: SharedSlice
        )
    }

    #[inline(always)]
    fn forward_pair_with(&self, s: WeightedSum, a: std::ops::Range<usize>, b: std::ops::Range<usize>, y: SharedSlice) {
        // SAFETY: rows a and b are written by this call only; the rows it reads are earlier
        // ones of their own subtree (each range is ascending).
        let y = unsafe { y.get() };
        assert!(y.len() >= self.len(), "a solution of {} rows for a factor of {}", y.len(), self.len());
        assert!(a.end <= self.len() && b.end <= self.len(), "subtrees {a:?} and {b:?} of {} rows", self.len());
        let common = a.len().min(b.len());
        for t in 0..common {
            self.forward_row(s, y, a.start + t);
            self.forward_row(s, y, b.start + t);
        }
        for k in (a.start + common..a.end).chain(b.start + common..b.end) {
            self.forward_row(s, y, k);
        }
    }

    /// Row k of the forward solve: `y[k] = (b[k] - Σ L[k][j] y[j]) / L[k][k]`.
    #[inline(always)]
    fn forward_row(&self, s: WeightedSum, y: &mut [Vec3A], k: usize) {
        let entries = self.row_ptr[k] as usize..self.row_ptr[k + 1] as usize;
        // SAFETY: the factor's columns are its rows, and y has them all (checked by the callers).
        let sum = unsafe { s.sum::<true>(y, &self.row_col[entries.clone()], &self.row_val[entries]) };
        y[k] = (y[k] - sum) * self.inv_diag[k];
    }

    /// Backward solve `Lᵀ x = y` on the rows of part `node` (its separator, then its halves;
    /// side by side within a thread, as [`Cholesky::forward`]).
    fn backward(&self, node: usize, y: SharedSlice, parallel: bool) {
        let part = self.parts[node];
        self.backward_separator(node, y);
        if let Some((a, b)) = part.children {
            if parallel && (part.end - part.start) as usize >= PARALLEL_MIN {
                join(|| self.backward(a as usize, y, true), || self.backward(b as usize, y, true));
            } else {
                self.backward_pair(self.subtree_rows(a), self.subtree_rows(b), y);
            }
        }
    }
}

impl Cholesky {
    dispatched! {
        /// The separator rows of [`Cholesky::backward`].
        fn backward_separator / backward_separator_avx2 / backward_separator_with(node: usize, y: SharedSlice)
    }

    #[inline(always)]
    fn backward_separator_with(&self, s: WeightedSum, node: usize, y: SharedSlice) {
        let part = self.parts[node];
        // SAFETY: rows separator..end are written by this call only; the rows it reads are
        // later ones (ancestors' separators), finished before this call started.
        let y = unsafe { y.get() };
        assert!(y.len() >= self.len(), "a solution of {} rows for a factor of {}", y.len(), self.len());
        for k in (part.separator as usize..part.end as usize).rev() {
            self.backward_row(s, y, k);
        }
    }

    dispatched! {
        /// The backward solve of two independent subtrees (rows `a` and `b`, the halves of a
        /// part, whose ancestors' separators are solved), a row of each in turn, descending (as
        /// [`Cholesky::forward_pair`]).
        fn backward_pair / backward_pair_avx2 / backward_pair_with(
            a: std::ops::Range<usize>, b: std::ops::Range<usize>, y: SharedSlice
        )
    }

    #[inline(always)]
    fn backward_pair_with(&self, s: WeightedSum, a: std::ops::Range<usize>, b: std::ops::Range<usize>, y: SharedSlice) {
        // SAFETY: rows a and b are written by this call only; the rows it reads are later ones
        // of their own subtree (each range is taken descending) or of the ancestors' separators.
        let y = unsafe { y.get() };
        assert!(y.len() >= self.len(), "a solution of {} rows for a factor of {}", y.len(), self.len());
        assert!(a.end <= self.len() && b.end <= self.len(), "subtrees {a:?} and {b:?} of {} rows", self.len());
        let common = a.len().min(b.len());
        for t in 1..=common {
            self.backward_row(s, y, a.end - t);
            self.backward_row(s, y, b.end - t);
        }
        for k in (a.start..a.end - common).rev().chain((b.start..b.end - common).rev()) {
            self.backward_row(s, y, k);
        }
    }

    /// Row k of the backward solve: `x[k] = (y[k] - Σ L[j][k] x[j]) / L[k][k]`.
    #[inline(always)]
    fn backward_row(&self, s: WeightedSum, y: &mut [Vec3A], k: usize) {
        let entries = self.col_ptr[k] as usize..self.col_ptr[k + 1] as usize;
        // SAFETY: the factor's rows, and y has them all (checked by the callers).
        let sum = unsafe { s.sum::<false>(y, &self.col_row[entries.clone()], &self.col_val[entries]) };
        y[k] = (y[k] - sum) * self.inv_diag[k];
    }
}

/// The weighted sums `Σ y[index[p]] value[p]` of the triangular solves, with AVX2 and FMA when
/// the processor has them (see `dispatched!`).
#[derive(Clone, Copy)]
struct WeightedSum {
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    /// Set only in the twins with AVX2 and FMA of `dispatched!`, after checking the processor.
    avx2_fma: bool,
}

impl WeightedSum {
    /// `Σ y[index[p]] value[p]`, the order of the additions fixed by the entries (so the bits do
    /// not depend on the thread count; they differ between the two kernels in the last bits).
    ///
    /// # Safety
    /// Every index must be below `y.len()` (the factor's entries are below its `len()`, see
    /// [`Cholesky::factor`], and the solves check that `y` has that many rows).
    ///
    /// `RECENT_LAST`: whether the entries a triangular solve has just solved (the rows nearest
    /// the one it is solving) are the last entries (forward, by rows) or the first (backward, by
    /// columns); the AVX2 kernel adds them last ([`weighted_sum_avx2_fma`]).
    #[inline(always)]
    unsafe fn sum<const RECENT_LAST: bool>(self, y: &[Vec3A], index: &[u32], value: &[f32]) -> Vec3A {
        #[cfg(target_arch = "x86_64")]
        if self.avx2_fma {
            // SAFETY: the processor has AVX2 and FMA (`avx2_fma` is set only after checking it);
            // the indices as the caller promises.
            return unsafe { weighted_sum_avx2_fma::<RECENT_LAST>(y, index, value) };
        }
        weighted_sum(y, index, value)
    }
}

/// `Σ y[index[p]] value[p]` in four running sums (entries p mod 4), added as `(s0 + s1) +
/// (s2 + s3)`: with one running sum each entry waited for the previous one's addition (4
/// cycles), which set the pace of the triangular solves (a row of the balloon's exact coarse
/// factor had about 31 entries). The order is fixed by the row, so the bits do not depend on the
/// thread count.
#[inline(always)]
fn weighted_sum(y: &[Vec3A], index: &[u32], value: &[f32]) -> Vec3A {
    let mut sums = [Vec3A::ZERO; 4];
    let (index4, index_rest) = index.split_at(index.len() - index.len() % 4);
    let (value4, value_rest) = value.split_at(index4.len().min(value.len()));
    for (i, v) in index4.chunks_exact(4).zip(value4.chunks_exact(4)) {
        sums[0] += y[i[0] as usize] * v[0];
        sums[1] += y[i[1] as usize] * v[1];
        sums[2] += y[i[2] as usize] * v[2];
        sums[3] += y[i[3] as usize] * v[3];
    }
    for (m, (&i, &v)) in index_rest.iter().zip(value_rest).enumerate() {
        sums[m] += y[i as usize] * v;
    }
    (sums[0] + sums[1]) + (sums[2] + sums[3])
}

/// [`weighted_sum`] two entries per 256-bit register (entry 2q in the low half, 2q + 1 in the
/// high one) and fused multiply-adds, in four running sums of pairs (pairs q mod 4, eight
/// entries an iteration); the rest pairwise into the first, an odd last entry at the end. About
/// half the instructions of the plain loop, which loads, checks, broadcasts, multiplies and
/// adds each entry alone.
///
/// The [`RECENT`] entries nearest the row being solved (the last ones with `RECENT_LAST`, else
/// the first) are left out of those sums and added one at a time after them, the nearest last.
/// A triangular solve's row needs the rows just before it, and its sum then waits for them only
/// through those few additions, not through the whole reduction of the running sums: the other
/// entries were solved earlier, and the processor sums them ahead while the rows before are
/// still being solved. On the issue-5 balloon (benches/body_balloon.rs, one thread, alternating
/// runs) the mean step went from 1.80 to 1.72 ms with the same CG iterations (6.3 a step).
/// Also tried: one such entry (1.77 against 1.74 ms with two in the same runs), four (1.78
/// against 1.75), and two with `(rhs - Σ) inv` taken before them so that each costs one fused
/// multiply-add by `value inv` on the way to the solved row (1.76 against 1.72): not kept.
///
/// # Safety
/// The processor must have AVX2 and FMA; every index must be below `y.len()`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn weighted_sum_avx2_fma<const RECENT_LAST: bool>(y: &[Vec3A], index: &[u32], value: &[f32]) -> Vec3A {
    use std::arch::x86_64::*;
    let n = index.len().min(value.len());
    let recent = n.min(RECENT);
    // The entries in the running sums: `first..first + summed`.
    let (first, summed) = if RECENT_LAST { (0, n - recent) } else { (recent, n - recent) };
    let (y, index, value) = (y.as_ptr() as *const f32, index.as_ptr(), value.as_ptr());
    // SAFETY (of every read below): p < n, so index[p] and value[p] are in their slices, and
    // each index is a row of y (the caller's promise); a Vec3A is four aligned f32.
    let row = |p: usize| unsafe { _mm_load_ps(y.add(4 * *index.add(p) as usize)) };
    // Entries p and p + 1 side by side, and their values each spread over its half.
    let spread = _mm256_setr_epi32(0, 0, 0, 0, 1, 1, 1, 1);
    let pair = |p: usize| unsafe {
        let rows = _mm256_insertf128_ps(_mm256_castps128_ps256(row(p)), row(p + 1), 1);
        let values = _mm_castpd_ps(_mm_load_sd(value.add(p) as *const f64));
        (rows, _mm256_permutevar8x32_ps(_mm256_castps128_ps256(values), spread))
    };
    let mut sums = [_mm256_setzero_ps(); 4];
    let (mut p, end) = (first, first + summed);
    while p + 8 <= end {
        for (q, sum) in sums.iter_mut().enumerate() {
            let (rows, values) = pair(p + 2 * q);
            *sum = _mm256_fmadd_ps(rows, values, *sum);
        }
        p += 8;
    }
    while p + 2 <= end {
        let (rows, values) = pair(p);
        sums[0] = _mm256_fmadd_ps(rows, values, sums[0]);
        p += 2;
    }
    let total = _mm256_add_ps(_mm256_add_ps(sums[0], sums[1]), _mm256_add_ps(sums[2], sums[3]));
    let mut sum = _mm_add_ps(_mm256_castps256_ps128(total), _mm256_extractf128_ps(total, 1));
    let single = |sum: __m128, p: usize| unsafe { _mm_fmadd_ps(row(p), _mm_set1_ps(*value.add(p)), sum) };
    if p < end {
        sum = single(sum, p);
    }
    // The nearest entries last: ascending after the others with `RECENT_LAST`, else descending.
    for k in 0..recent {
        sum = single(sum, if RECENT_LAST { end + k } else { recent - 1 - k });
    }
    Vec3A::from(sum)
}

/// Entries of each row (or column) that [`weighted_sum_avx2_fma`] adds after the others.
#[cfg(target_arch = "x86_64")]
const RECENT: usize = 2;

/// A slice shared by the two halves of a dissection, which write disjoint rows.
#[derive(Clone, Copy)]
struct SharedSlice(*mut Vec3A, usize);

// SAFETY: the solves hand the slice to tasks that write disjoint rows and read only rows finished
// before they started (see `forward` and `backward`).
unsafe impl Send for SharedSlice {}
unsafe impl Sync for SharedSlice {}

impl SharedSlice {
    /// # Safety
    /// The caller writes only rows no concurrent task reads or writes.
    #[allow(clippy::mut_from_ref)]
    unsafe fn get(&self) -> &mut [Vec3A] {
        // SAFETY: pointer and length of a live slice (see the type's comment).
        unsafe { std::slice::from_raw_parts_mut(self.0, self.1) }
    }
}

/// Runs both closures, in parallel inside a worker pool when the `parallel` feature is on.
fn join(a: impl FnOnce() + Send, b: impl FnOnce() + Send) {
    #[cfg(feature = "parallel")]
    {
        rayon::join(a, b);
    }
    #[cfg(not(feature = "parallel"))]
    {
        a();
        b();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX2 kernel sums the same entries as the plain one (to rounding: it pairs and fuses
    /// them differently), with the nearest entries at either end, for every count of entries a
    /// row can have up to 40 (the paths of eight, two and one entries, and of fewer entries than
    /// it adds last), and the same bits every time.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_avx2_weighted_sum_matches_the_plain_one() {
        if !(std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")) {
            eprintln!("skipped: this processor has no AVX2 and FMA");
            return;
        }
        let y: Vec<Vec3A> = (0..97)
            .map(|i| Vec3A::new((i as f32 * 0.37).sin(), (i as f32 * 0.11).cos() * 3.0, i as f32 - 40.0))
            .collect();
        for len in 0..=40 {
            let index: Vec<u32> = (0..len).map(|p| ((p * 31 + 7) % 97) as u32).collect();
            let value: Vec<f32> = (0..len).map(|p| 0.5 - (p as f32 * 0.73).sin()).collect();
            let plain = weighted_sum(&y, &index, &value);
            // SAFETY: the processor has AVX2 and FMA (checked above); every index is below 97.
            let kernels = unsafe {
                [weighted_sum_avx2_fma::<true>(&y, &index, &value), weighted_sum_avx2_fma::<false>(&y, &index, &value)]
            };
            let scale: f32 = index.iter().zip(&value).map(|(&i, &v)| (y[i as usize] * v).abs().max_element()).sum();
            for fast in kernels {
                let diff = (plain - fast).abs().max_element();
                assert!(diff <= 1e-6 * scale.max(1.0), "{len} entries: {plain} against {fast}");
                if len == 1 {
                    assert_eq!(fast, y[index[0] as usize] * value[0], "one entry is one product");
                }
            }
            // SAFETY: as above.
            assert_eq!(kernels[0], unsafe { weighted_sum_avx2_fma::<true>(&y, &index, &value) });
            assert_eq!(kernels[1], unsafe { weighted_sum_avx2_fma::<false>(&y, &index, &value) });
        }
    }

    /// A 30 x 30 grid graph with varied weights and a little mass on the diagonal: its positions
    /// and the matrix as [`Cholesky::factor`] takes it (diagonal, offsets, neighbours, values).
    #[allow(clippy::type_complexity)]
    fn grid_system() -> (Vec<Vec3>, Vec<f64>, Vec<u32>, Vec<u32>, Vec<f64>) {
        let side = 30;
        let n = side * side;
        let pos: Vec<Vec3> = (0..n).map(|i| Vec3::new((i % side) as f32, (i / side) as f32, 0.0)).collect();
        let mut adj = vec![Vec::new(); n];
        for i in 0..n {
            let (x, y) = (i % side, i / side);
            if x + 1 < side {
                adj[i].push((i + 1, 1.0 + (i % 7) as f64));
                adj[i + 1].push((i, 1.0 + (i % 7) as f64));
            }
            if y + 1 < side {
                adj[i].push((i + side, 2.0));
                adj[i + side].push((i, 2.0));
            }
        }
        let mut offsets = vec![0u32];
        let (mut neighbors, mut values, mut diagonal) = (Vec::new(), Vec::new(), Vec::new());
        for (i, a) in adj.iter().enumerate() {
            let mut d = 0.01 * (1 + i % 3) as f64;
            for &(j, w) in a {
                neighbors.push(j as u32);
                values.push(-w);
                d += w;
            }
            diagonal.push(d);
            offsets.push(neighbors.len() as u32);
        }
        (pos, diagonal, offsets, neighbors, values)
    }

    /// `A x` for the matrix of [`grid_system`].
    fn grid_product(diagonal: &[f64], offsets: &[u32], neighbors: &[u32], values: &[f64], x: &[Vec3A]) -> Vec<Vec3A> {
        (0..x.len())
            .map(|i| {
                let mut acc = x[i] * diagonal[i] as f32;
                for p in offsets[i] as usize..offsets[i + 1] as usize {
                    acc += x[neighbors[p] as usize] * values[p] as f32;
                }
                acc
            })
            .collect()
    }

    /// A grid graph, factored and solved against a product with its matrix.
    #[test]
    fn solves_a_graph_laplacian_system() {
        let (pos, diagonal, offsets, neighbors, values) = grid_system();
        let n = pos.len();
        let chol = Cholesky::factor(&diagonal, &offsets, &neighbors, &values, &pos, &[]).unwrap();
        let x: Vec<Vec3A> = (0..n).map(|i| Vec3A::new((i as f32 * 0.1).sin(), 1.0, (i % 5) as f32)).collect();
        let b = grid_product(&diagonal, &offsets, &neighbors, &values, &x);
        let mut first: Option<Vec<Vec3A>> = None;
        for threads in [1, 2, 3] {
            let pool = WorkerPool::new(threads).unwrap();
            let mut out = vec![Vec3A::ZERO; n];
            let mut work = Vec::new();
            chol.solve(&pool, &b, &mut out, &mut work);
            let err = out.iter().zip(&x).map(|(a, b)| (*a - *b).abs().max_element()).fold(0.0, f32::max);
            assert!(err < 2e-2, "threads {threads}: error {err}");
            // The same to the bit whatever the thread count (900 rows: the solve splits).
            match &first {
                None => first = Some(out),
                Some(one) => assert_eq!(one, &out),
            }
        }
        assert!(chol.fill() < n * 40, "fill {}", chol.fill());

        let whole = first.unwrap();
        let solved = split_solve(&chol, &b);
        for (got, want) in solved.iter().zip(&whole) {
            assert!((*got - *want).abs().max_element() <= 1e-4 * (1.0 + want.abs().max_element()), "{got} vs {want}");
        }
    }

    /// The split solve of a team (`implicit::Shared::coarse_part`): each half forward in a copy
    /// of its own with its part of the top separator, then in each copy the separator and that
    /// copy's half backward. The halves' rows together are the whole solve's; returned in the
    /// rows of A.
    fn split_solve(chol: &Cholesky, b: &[Vec3A]) -> Vec<Vec3A> {
        let n = b.len();
        let (half_a, half_b) = chol.top_halves().expect("900 rows split");
        let (_, separator) = chol.part_rows(chol.root());
        let rhs: Vec<Vec3A> = chol.perm().iter().map(|&i| b[i as usize]).collect();
        let mut copies = [rhs.clone(), rhs.clone()];
        let mut parts = [vec![Vec3A::ZERO; separator.len()], vec![Vec3A::ZERO; separator.len()]];
        for (h, node) in [half_a, half_b].into_iter().enumerate() {
            // SAFETY: a copy of this "member" alone.
            unsafe { chol.forward_part(node, copies[h].as_mut_ptr()) };
            chol.top_separator_part(h, &copies[h], &mut parts[h]);
        }
        let mut solved = vec![Vec3A::ZERO; n];
        for (h, node) in [half_a, half_b].into_iter().enumerate() {
            chol.top_separator_solve(&mut copies[h], [&parts[0], &parts[1]]);
            // SAFETY: as above.
            unsafe { chol.backward_part(node, copies[h].as_mut_ptr()) };
            let (rows, _) = chol.part_rows(node);
            solved[rows.clone()].copy_from_slice(&copies[h][rows]);
        }
        assert_eq!(copies[0][separator.clone()], copies[1][separator.clone()], "both copies solve the separator alike");
        solved[separator.clone()].copy_from_slice(&copies[0][separator]);
        let mut out = vec![Vec3A::ZERO; n];
        for (k, &i) in chol.perm().iter().enumerate() {
            out[i as usize] = solved[k];
        }
        out
    }

    /// An incomplete factor (`drop_tolerance`) keeps exactly the entries of the exact factor at
    /// or above each row's threshold, in both of its copies, and is still a symmetric positive
    /// definite approximation of the inverse: what conjugate gradients need of a preconditioner.
    #[test]
    fn an_incomplete_factor_keeps_the_large_entries_and_stays_symmetric_positive() {
        let (pos, diagonal, offsets, neighbors, values) = grid_system();
        let n = pos.len();
        let exact = Cholesky::factor(&diagonal, &offsets, &neighbors, &values, &pos, &[]).unwrap();
        let none_dropped = Cholesky::factor(&diagonal, &offsets, &neighbors, &values, &pos, &vec![0.0; n]).unwrap();
        assert_eq!(none_dropped.fill(), exact.fill());
        assert_eq!(none_dropped.row_val, exact.row_val);
        // A threshold per row of A, 0.01 to 0.04 (so a threshold read from the wrong row shows).
        let tolerance: Vec<f64> = (0..n).map(|i| 0.01 * (1 + i % 4) as f64).collect();
        let incomplete = Cholesky::factor(&diagonal, &offsets, &neighbors, &values, &pos, &tolerance).unwrap();
        let (kept, all) = (incomplete.fill(), exact.fill());
        assert!(kept < all / 2, "kept {kept} of {all} entries");
        // (row, column, value) of every entry of a factor, from its copy by rows and by columns.
        let by_rows = |chol: &Cholesky| -> Vec<(usize, u32, f32)> {
            (0..n)
                .flat_map(|k| (chol.row_ptr[k] as usize..chol.row_ptr[k + 1] as usize).map(move |p| (k, p)))
                .map(|(k, p)| (k, chol.row_col[p], chol.row_val[p]))
                .collect()
        };
        let by_columns = |chol: &Cholesky| -> Vec<(usize, u32, f32)> {
            let mut entries: Vec<(usize, u32, f32)> = (0..n)
                .flat_map(|j| (chol.col_ptr[j] as usize..chol.col_ptr[j + 1] as usize).map(move |p| (j, p)))
                .map(|(j, p)| (chol.col_row[p] as usize, j as u32, chol.col_val[p]))
                .collect();
            entries.sort_by_key(|&(k, j, _)| (k, j));
            entries
        };
        assert_eq!(by_rows(&incomplete), by_columns(&incomplete));
        // Exactly the exact factor's entries at or above their row's threshold (the same ordering,
        // so the same rows; L's diagonal entry of row k is 1 / inv_diag[k]).
        let expected: Vec<(usize, u32, f32)> = by_rows(&exact)
            .into_iter()
            .filter(|&(k, _, v)| {
                let threshold = tolerance[exact.perm[k] as usize] / exact.inv_diag[k] as f64;
                (v as f64).abs() >= threshold * (1.0 + 1e-6)
            })
            .collect();
        let got = by_rows(&incomplete);
        assert!(
            got.len() >= expected.len() && got.len() <= expected.len() + n / 100,
            "{} vs {}",
            got.len(),
            expected.len()
        );
        for entry in &expected {
            assert!(got.contains(entry), "{entry:?} dropped");
        }
        assert_eq!(incomplete.inv_diag, exact.inv_diag);
        let pool = WorkerPool::new(2).unwrap();
        let apply = |chol: &Cholesky, r: &[Vec3A]| {
            let (mut out, mut work) = (vec![Vec3A::ZERO; n], Vec::new());
            chol.solve(&pool, r, &mut out, &mut work);
            out
        };
        let dot = |u: &[Vec3A], v: &[Vec3A]| u.iter().zip(v).map(|(p, q)| p.dot(*q) as f64).sum::<f64>();
        let a: Vec<Vec3A> = (0..n).map(|i| Vec3A::new((i as f32).sin(), (i % 7) as f32 - 3.0, 1.0)).collect();
        let b: Vec<Vec3A> = (0..n).map(|i| Vec3A::new((i as f32 * 0.3).cos(), 0.5, (i % 5) as f32)).collect();
        let (ba, bb) = (apply(&incomplete, &a), apply(&incomplete, &b));
        let (ab, ba_) = (dot(&a, &bb), dot(&b, &ba));
        assert!((ab - ba_).abs() <= 1e-4 * ab.abs().max(ba_.abs()), "{ab} vs {ba_}");
        assert!(dot(&a, &ba) > 0.0 && dot(&b, &bb) > 0.0);
        // The split solve of a team gives the whole solve's answer.
        for (got, want) in split_solve(&incomplete, &a).iter().zip(&ba) {
            assert!((*got - *want).abs().max_element() <= 1e-5 * (1.0 + want.abs().max_element()), "{got} vs {want}");
        }
        // As a preconditioner: conjugate gradients on A x = A x0 to 1e-6 take a handful of
        // iterations with it (13), the exact factor one, and over a hundred with none (the
        // identity: the grid's smooth modes).
        let x0: Vec<Vec3A> = (0..n).map(|i| Vec3A::new((i as f32 * 0.1).sin(), 1.0, (i % 5) as f32)).collect();
        let rhs = grid_product(&diagonal, &offsets, &neighbors, &values, &x0);
        let iterations = |precondition: &dyn Fn(&[Vec3A]) -> Vec<Vec3A>| {
            let mut x = vec![Vec3A::ZERO; n];
            let mut r = rhs.clone();
            let mut z = precondition(&r);
            let mut p = z.clone();
            let mut rz = dot(&r, &z);
            let stop = 1e-6 * dot(&rhs, &rhs).sqrt();
            for it in 1..=2000 {
                let ap = grid_product(&diagonal, &offsets, &neighbors, &values, &p);
                let alpha = (rz / dot(&p, &ap)) as f32;
                for i in 0..n {
                    x[i] += p[i] * alpha;
                    r[i] -= ap[i] * alpha;
                }
                if dot(&r, &r).sqrt() <= stop {
                    return it;
                }
                z = precondition(&r);
                let rz_next = dot(&r, &z);
                let beta = (rz_next / rz) as f32;
                rz = rz_next;
                for i in 0..n {
                    p[i] = z[i] + p[i] * beta;
                }
            }
            2000
        };
        let with_exact = iterations(&|r| apply(&exact, r));
        let with_incomplete = iterations(&|r| apply(&incomplete, r));
        let with_none = iterations(&|r| r.to_vec());
        println!(
            "kept {kept} of {all} entries; CG iterations {with_exact} exact, {with_incomplete} incomplete, {with_none} none"
        );
        assert!(with_exact <= 3, "{with_exact}");
        assert!(with_incomplete > with_exact && with_incomplete <= 20, "{with_incomplete}");
        assert!(with_none > 5 * with_incomplete, "{with_none}");
    }
}
