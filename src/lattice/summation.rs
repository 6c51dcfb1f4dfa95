//! Box sums over the lattice, the heart of FastLSM (SPEC 3, "Fast summation").
//!
//! Every region sum, and the distribution back from regions to the particles they contain, is a
//! sum over the `(2w+1) x (2w+1)` box of sites around a site, clipped at the border, with holes
//! holding zero. The box is separable: first a running sum along x within each row
//! (`B(i+1) = B(i) + q(i+w+1) - q(i-w)`), then the same along z over whole rows. Each value is
//! added once and subtracted once per pass, so the cost is O(n) whatever w is.
//!
//! Values are interleaved: site `s` owns `data[s*ch .. (s+1)*ch]` (one region sum has `ch`
//! channels). Sums run in f64: the running sums add and subtract the same numbers again and
//! again, and f64 keeps that drift orders of magnitude below anything f32 positions can show.
//! [`box_sum_naive`] is the O(n w^2) definition, kept as the reference the tests compare with.

/// Rows are processed in blocks of at least this many: the z running sum restarts at each block,
/// so blocks are independent units of parallel work. Never derived from the thread count, so
/// results are bit-identical whatever the number of threads.
pub(crate) const ROW_BLOCK: usize = 32;

/// Rows per block for half-width `w`: [`ROW_BLOCK`], or `4w + 2` when that is more. A block's
/// start sums the `2w + 1` rows of its first window (and the fit recomputes the moments of the
/// `2w` rows around it), so with blocks of 32 rows a step cost `1 + 2w/32` times the O(n) work:
/// 2.5x w = 1 at w = 128 on a 256 x 256 lattice (a review). Blocks of at least `4w + 2` rows bound
/// that overhead by 1.5x whatever w is (at the price of fewer blocks to share among threads when
/// the regions are as wide as the lattice).
pub(crate) fn row_block(w: usize, rows: usize) -> usize {
    ROW_BLOCK.max(w.saturating_mul(4).saturating_add(2).min(rows.max(1)))
}

/// Running sum along one row: `out[i] = sum_{j=i-w}^{i+w} q[j]` clipped to the row, for each of
/// the `ch` channels. `q` and `out` hold `columns * ch` values.
pub(crate) fn running_sum_row(q: &[f64], out: &mut [f64], ch: usize, w: usize) {
    debug_assert_eq!(q.len(), out.len());
    // The channel counts the step uses get a copy compiled for their size (unrolled, no calls).
    match ch {
        9 => running_sum_row_n::<9>(q, out, w),
        15 => running_sum_row_n::<15>(q, out, w),
        21 => running_sum_row_n::<21>(q, out, w),
        _ => running_sum_row_any(q, out, ch, w),
    }
}

#[inline]
fn site<const CH: usize>(q: &[f64], j: usize) -> &[f64; CH] {
    q[j * CH..(j + 1) * CH].try_into().expect("CH values")
}

fn running_sum_row_n<const CH: usize>(q: &[f64], out: &mut [f64], w: usize) {
    let n = q.len() / CH;
    if n == 0 {
        return;
    }
    let mut acc = [0.0f64; CH];
    for j in 0..=w.min(n - 1) {
        let row = site::<CH>(q, j);
        for k in 0..CH {
            acc[k] += row[k];
        }
    }
    for (i, out) in out.chunks_exact_mut(CH).enumerate() {
        out.copy_from_slice(&acc);
        if i + w + 1 < n {
            let a = site::<CH>(q, i + w + 1);
            for k in 0..CH {
                acc[k] += a[k];
            }
        }
        if i >= w {
            let b = site::<CH>(q, i - w);
            for k in 0..CH {
                acc[k] -= b[k];
            }
        }
    }
}

fn running_sum_row_any(q: &[f64], out: &mut [f64], ch: usize, w: usize) {
    let n = q.len() / ch;
    if n == 0 {
        return;
    }
    let mut acc = vec![0.0f64; ch];
    for j in 0..=w.min(n - 1) {
        add(&mut acc, &q[j * ch..(j + 1) * ch]);
    }
    for i in 0..n {
        out[i * ch..(i + 1) * ch].copy_from_slice(&acc);
        if i + w + 1 < n {
            add(&mut acc, &q[(i + w + 1) * ch..(i + w + 2) * ch]);
        }
        if i >= w {
            sub(&mut acc, &q[(i - w) * ch..(i - w + 1) * ch]);
        }
    }
}

/// `acc += row`.
#[inline]
pub(crate) fn add_row(acc: &mut [f64], row: &[f64]) {
    add(acc, row);
}

/// One step of a running sum: `acc += entering - leaving` (either may be absent at a border).
#[inline]
pub(crate) fn shift_rows(acc: &mut [f64], entering: Option<&[f64]>, leaving: Option<&[f64]>) {
    match (entering, leaving) {
        // One pass over three rows instead of two over two.
        (Some(a), Some(b)) => {
            for ((acc, a), b) in acc.iter_mut().zip(a).zip(b) {
                *acc += a - b;
            }
        }
        (Some(a), None) => add(acc, a),
        (None, Some(b)) => sub(acc, b),
        (None, None) => {}
    }
}

#[inline]
fn add(acc: &mut [f64], row: &[f64]) {
    for (a, b) in acc.iter_mut().zip(row) {
        *a += b;
    }
}

#[inline]
fn sub(acc: &mut [f64], row: &[f64]) {
    for (a, b) in acc.iter_mut().zip(row) {
        *a -= b;
    }
}

/// The running sum along z: the sum of rows `k-w ..= k+w` (clipped) of `src` for consecutive
/// rows `k`, starting at `k0`. Each row of `src` holds `stride` values (already summed along x).
/// The sums are kept in the caller's buffer (a window per block of rows every step allocated
/// one otherwise).
pub(crate) struct RowWindow<'a> {
    src: &'a [f64],
    stride: usize,
    rows: usize,
    w: usize,
    k: usize,
    acc: &'a mut Vec<f64>,
}

impl<'a> RowWindow<'a> {
    /// A window centred on row `k0`, its sums in `acc` (resized).
    pub(crate) fn new(src: &'a [f64], stride: usize, rows: usize, w: usize, k0: usize, acc: &'a mut Vec<f64>) -> Self {
        acc.clear();
        acc.resize(stride, 0.0);
        let last = (k0 + w).min(rows - 1);
        for j in k0.saturating_sub(w)..=last {
            add(acc, &src[j * stride..(j + 1) * stride]);
        }
        Self { src, stride, rows, w, k: k0, acc }
    }

    /// The box sums of every site of the current row (`stride` values).
    #[inline]
    pub(crate) fn current(&self) -> &[f64] {
        self.acc
    }

    /// Moves to the next row: `B(k+1) = B(k) + row(k+w+1) - row(k-w)`.
    pub(crate) fn advance(&mut self) {
        let (k, w, s) = (self.k, self.w, self.stride);
        let entering = (k + w + 1 < self.rows).then(|| &self.src[(k + w + 1) * s..(k + w + 2) * s]);
        let leaving = (k >= w).then(|| &self.src[(k - w) * s..(k - w + 1) * s]);
        shift_rows(self.acc, entering, leaving);
        self.k += 1;
    }
}

/// Fast box sum of a whole grid (serial), with exactly the blocking the step uses: x pass, then
/// the z window restarted every [`row_block`] rows.
pub(crate) fn box_sum(src: &[f64], columns: usize, rows: usize, ch: usize, w: usize) -> Vec<f64> {
    let stride = columns * ch;
    let mut bx = vec![0.0; src.len()];
    for (q, out) in src.chunks(stride).zip(bx.chunks_mut(stride)) {
        running_sum_row(q, out, ch, w);
    }
    let mut out = vec![0.0; src.len()];
    let block = row_block(w, rows);
    let mut acc = Vec::new();
    for k0 in (0..rows).step_by(block) {
        let mut window = RowWindow::new(&bx, stride, rows, w, k0, &mut acc);
        for k in k0..(k0 + block).min(rows) {
            out[k * stride..(k + 1) * stride].copy_from_slice(window.current());
            window.advance();
        }
    }
    out
}

/// The definition, O(n w^2): for every site the plain sum over its clipped box. The reference
/// the tests hold the fast sums to.
#[cfg(test)]
pub(crate) fn box_sum_naive(src: &[f64], columns: usize, rows: usize, ch: usize, w: usize) -> Vec<f64> {
    let mut out = vec![0.0; src.len()];
    for r in 0..rows {
        for c in 0..columns {
            let o = (r * columns + c) * ch;
            for rr in r.saturating_sub(w)..=(r + w).min(rows - 1) {
                for cc in c.saturating_sub(w)..=(c + w).min(columns - 1) {
                    let i = (rr * columns + cc) * ch;
                    for k in 0..ch {
                        out[o + k] += src[i + k];
                    }
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (no dependency needed).
    pub(crate) struct Lcg(pub u64);
    impl Lcg {
        pub(crate) fn next(&mut self) -> f64 {
            self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((self.0 >> 11) as f64) / ((1u64 << 53) as f64)
        }
    }

    #[test]
    fn fast_box_sums_agree_with_the_definition_with_holes() {
        let mut rng = Lcg(7);
        for &(columns, rows) in &[(1, 1), (7, 1), (1, 9), (13, 11), (40, 70)] {
            for ch in [3, 9, 15, 21] {
                let mut src = vec![0.0; columns * rows * ch];
                for site in 0..columns * rows {
                    let hole = rng.next() < 0.2 || (site % columns > 3 && site % columns < 6 && site / columns == 4);
                    if !hole {
                        for k in 0..ch {
                            src[site * ch + k] = 200.0 * rng.next() - 100.0;
                        }
                    }
                }
                for w in [1, 2, 3, 5, 8, 16, 100] {
                    let fast = box_sum(&src, columns, rows, ch, w);
                    let naive = box_sum_naive(&src, columns, rows, ch, w);
                    let scale = 100.0 * ((2 * w + 1) * (2 * w + 1)) as f64;
                    for (i, (a, b)) in fast.iter().zip(&naive).enumerate() {
                        assert!((a - b).abs() <= 1e-12 * scale, "{columns}x{rows} w={w} value {i}: fast {a} naive {b}");
                    }
                }
            }
        }
    }

    #[test]
    fn counting_particles_is_exact() {
        let (columns, rows) = (37, 45);
        let mut rng = Lcg(3);
        let ones: Vec<f64> = (0..columns * rows).map(|_| if rng.next() < 0.7 { 1.0 } else { 0.0 }).collect();
        for w in [1, 4, 9] {
            assert_eq!(box_sum(&ones, columns, rows, 1, w), box_sum_naive(&ones, columns, rows, 1, w));
        }
    }

    /// The blocks are long enough that restarting the running sums at each one costs at most
    /// half again the O(n) work, whatever w: a block of b rows adds the 2w rows around it.
    #[test]
    fn block_restarts_cost_at_most_half_again() {
        for rows in [1usize, 7, 32, 100, 256, 10_000] {
            for w in (0..3000).chain([usize::MAX / 2, usize::MAX]) {
                let b = row_block(w, rows);
                assert!(b >= ROW_BLOCK, "rows {rows} w {w}: {b}");
                if b < rows {
                    assert!((b as f64 + 2.0 * w as f64) / b as f64 <= 1.5, "rows {rows} w {w}: blocks of {b}");
                }
            }
        }
    }
}
