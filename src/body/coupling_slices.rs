//! The coupling blocks of the implicit system (one per (vertex, spring) pair) in sliced ELLPACK
//! layout, and the product kernel that streams them.
//!
//! Rows (vertices) go in slices of [`SLICE`] consecutive rows. A slice holds as many groups as
//! its longest row has couplings; group `k` of a slice holds the `k`-th coupling of each of its
//! rows, one row per lane, as structure of arrays (per lane the block's two packed words and the
//! other end's offset, [`CouplingGroup`]). A product then sums eight rows at once in 256-bit
//! registers with no horizontal additions.
//! On the issue-5 balloon's matrix (10,242 rows, 61,440 couplings, icosahedral valence 5 and 6,
//! so 0.07% of the lanes are padding), one thread, inside the solve, the same product repeated
//! 200 times: the couplings' sums take 51 µs, where rows one at a time (two couplings per
//! register, with horizontal additions) took about 60 µs of a 100 µs product; loading the
//! other ends and transposing them beat gathering them with `vgatherdps` (41 vs 45 µs in a
//! stand-alone test of the same matrix).
//!
//! Measured and not kept (shares of a 1-thread profile of the drop, the product at
//! 23.1-23.7% as it is): prefetching the other ends' rows of the group four ahead, 27.7-29.2%;
//! the sums as `a += (alpha d + w s)` (one addition in each row's chain per group instead of
//! two fused multiply-adds), 24.4-25.1%: the product waits on the loads of the other ends, not on
//! its sums.
//!
//! A lane past a row's last coupling (padding) holds a zero block whose other end is the row
//! itself, so it adds exactly zero and loads only rows that exist.
//!
//! The blocks are stored in bfloat16 (the upper half of an f32: its exponent range, 8 bits of
//! precision), 96 bytes a group instead of 160: the products of a step stream the couplings
//! again at every iteration and are bound by those bytes. The spring terms round each block
//! once ([`Coupling::packed`]) and the assembly builds the diagonal from the rounded blocks
//! ([`PackedCoupling::unpacked`]), so the matrix the
//! solve uses is exactly that of springs whose blocks moved by at most 0.4%: still symmetric,
//! positive definite and blind to rigid translations (every row's blocks sum to its diagonal's
//! spring part). That changes the linearisation of the step, not its forces (the right side),
//! so no equilibrium moves.

use std::ops::Range;

use glam::{Vec3, Vec3A, Vec4};

use super::gas::MIXED_FRAGMENTS;
use super::headroom::with_room;
use super::springs::Springs;

/// Rows per slice (the lanes of a 256-bit register of f32).
pub(crate) const SLICE: usize = 8;

/// The coupling block `alpha I + w wᵀ` of a (vertex, spring) pair: `w` in x, y, z, `alpha` in
/// the fourth lane (16 bytes; see the implicit integrator for `w = √beta u`).
#[derive(Clone, Copy, Default, Debug, PartialEq)]
#[repr(transparent)]
pub(crate) struct Coupling(pub Vec4);

impl Coupling {
    pub fn new(u: Vec3A, alpha: f32, beta: f32) -> Self {
        Coupling((u * beta.max(0.0).sqrt()).extend(alpha))
    }

    /// `w` (the fourth lane is ignored by every Vec3A dot product and length).
    #[inline(always)]
    pub fn w(self) -> Vec3A {
        Vec3A::from_vec4(self.0)
    }

    #[inline(always)]
    pub fn alpha(self) -> f32 {
        self.0.w
    }

    /// The block with `w` and `alpha` rounded to bfloat16, as the groups store it (the
    /// spring terms make their blocks so; the assembly builds the diagonal from them, see the
    /// module doc).
    #[inline(always)]
    pub fn packed(self) -> PackedCoupling {
        PackedCoupling(self.0.to_array().map(to_bf16))
    }

    /// The block with `w` and `alpha` rounded to bfloat16 (the f32 of [`Coupling::packed`]).
    #[cfg(test)]
    pub fn rounded(self) -> Self {
        self.packed().unpacked()
    }

    /// The block times `d` (the tests' reference).
    #[cfg(test)]
    pub fn apply(self, d: Vec3A) -> Vec3A {
        let w = self.w();
        d * self.0.w + w * w.dot(d)
    }
}

/// `v` rounded to the nearest bfloat16 (ties to even); a NaN stays a NaN.
#[inline(always)]
pub(crate) fn to_bf16(v: f32) -> u16 {
    if v.is_nan() {
        return 0x7FC0;
    }
    let bits = v.to_bits();
    (bits.wrapping_add(0x7FFF + ((bits >> 16) & 1)) >> 16) as u16
}

/// The f32 of a bfloat16 (exact).
#[inline(always)]
pub(crate) fn from_bf16(h: u16) -> f32 {
    f32::from_bits((h as u32) << 16)
}

/// A coupling block in bfloat16 (`w` in x, y, z, `alpha` last; 8 bytes): what the groups store,
/// made once per spring by the spring terms, which the assembly then copies into both ends'
/// rows (it converted two 16-byte blocks per spring before, a third of its instructions).
#[derive(Clone, Copy, Default, Debug, PartialEq, Eq)]
#[repr(transparent)]
pub(crate) struct PackedCoupling(pub [u16; 4]);

impl PackedCoupling {
    /// The f32 block (exact).
    #[inline(always)]
    pub fn unpacked(self) -> Coupling {
        #[cfg(target_arch = "x86_64")]
        {
            // The four halves widened into the upper halves of four f32 lanes at once with SSE2
            // (part of x86-64).
            use std::arch::x86_64::*;
            // SAFETY: SSE2 is always present on x86-64; an unaligned 8-byte load of the array.
            let v = unsafe {
                let h = _mm_loadl_epi64(self.0.as_ptr() as *const __m128i);
                _mm_castsi128_ps(_mm_unpacklo_epi16(_mm_setzero_si128(), h))
            };
            Coupling(Vec4::from(v))
        }
        #[cfg(not(target_arch = "x86_64"))]
        Coupling(Vec4::from_array(self.0.map(from_bf16)))
    }
}

/// The `k`-th coupling of each of the eight rows of a slice, `w` and `alpha` in bfloat16 (96
/// bytes, a cache line and a half: the product streams these).
///
/// Each lane's block is kept as the two 32-bit words of its [`PackedCoupling`] (`w.x` in the
/// lower half of `xy`, `w.y` in the upper; `w.z` and `alpha` likewise in `za`), so a lane's f32
/// is one shift or one mask of the word: the product widens the four components of a group in
/// four instructions (eight from planes of u16), and the assembly stores the words it gathered
/// as they are (it regrouped them into planes).
#[repr(C, align(32))]
#[derive(Clone, Copy, Default)]
pub(crate) struct CouplingGroup {
    pub(super) xy: [u32; SLICE],
    pub(super) za: [u32; SLICE],
    /// Per lane where the other end's row starts in the input seen as f32: 4 × the row (see
    /// [`CouplingGroup::set_other`]).
    pub(super) other_offset: [u32; SLICE],
}

impl CouplingGroup {
    /// Lane `lane`'s block.
    #[inline(always)]
    pub(super) fn block(&self, lane: usize) -> PackedCoupling {
        let (xy, za) = (self.xy[lane], self.za[lane]);
        PackedCoupling([xy as u16, (xy >> 16) as u16, za as u16, (za >> 16) as u16])
    }

    /// Writes lane `lane`'s block.
    #[inline(always)]
    pub(super) fn set_block(&mut self, lane: usize, c: PackedCoupling) {
        let [x, y, z, alpha] = c.0.map(u32::from);
        self.xy[lane] = x | y << 16;
        self.za[lane] = z | alpha << 16;
    }

    /// Lane `lane`'s other end.
    #[inline(always)]
    pub(super) fn other_row(&self, lane: usize) -> usize {
        (self.other_offset[lane] / 4) as usize
    }

    /// Makes `row` lane `lane`'s other end. Kept as its offset in f32 (`row` below
    /// [`MAX_ROWS`]): the product's loads then take it as it is, where a row index needs a
    /// shift first (an address scales an index by at most 8, a row is 16 bytes): eight
    /// instructions of a group's 50-odd.
    #[inline(always)]
    pub(super) fn set_other(&mut self, lane: usize, row: u32) {
        // (4 × a larger row would wrap to another row's offset.)
        assert!((row as usize) < MAX_ROWS, "other end {row}: more than the {MAX_ROWS} rows a layout takes");
        self.other_offset[lane] = 4 * row;
    }
}

/// Rows a layout may have: 4 × a row, and of each lane of the last slice, fits an i32 (the
/// assembly compares rows with other ends that way, `spring_sums`).
pub(crate) const MAX_ROWS: usize = (1 << 29) - SLICE;

/// The couplings of all rows: per slice its first group (`offsets`, one more entry than slices)
/// and the groups.
#[derive(Default)]
pub(crate) struct CouplingSlices {
    pub offsets: Vec<u32>,
    pub groups: Vec<CouplingGroup>,
    /// Per group, the spring of each lane ([`NO_SPRING`] for padding): where the assembly finds
    /// the lane's block and right side (laid out by [`CouplingSlices::layout_springs`] with the
    /// other ends; empty when the rows were laid out otherwise, as the tests do).
    pub springs: Vec<[u32; SLICE]>,
    /// The [`Springs::adjacency_id`] of the springs laid out (0: none).
    adjacency_id: u64,
}

/// The spring of a padding lane.
pub(crate) const NO_SPRING: u32 = u32::MAX;

impl CouplingSlices {
    /// Lays the slices out for `springs` (their adjacency), with every lane's other end and
    /// spring, unless they are laid out already (the same [`Springs::adjacency_id`]): the layout
    /// changes only with the topology, and the assembly then writes only the blocks.
    pub fn layout_springs(&mut self, springs: &Springs) {
        if springs.adjacency_id != 0 && springs.adjacency_id == self.adjacency_id {
            return;
        }
        self.layout(&springs.offsets);
        let n = springs.offsets.len().saturating_sub(1);
        self.springs.clear();
        self.springs.resize(self.groups.len(), [NO_SPRING; SLICE]);
        for row in 0..n {
            let (slice, lane) = (row / SLICE, row % SLICE);
            let groups = self.offsets[slice] as usize..self.offsets[slice + 1] as usize;
            let around = springs.around(row);
            for (k, g) in groups.enumerate() {
                match around.get(k) {
                    Some(&(spring, other)) => {
                        self.groups[g].set_other(lane, other);
                        self.springs[g][lane] = spring;
                    }
                    None => pad(&mut self.groups[g], lane, row),
                }
            }
        }
        self.adjacency_id = springs.adjacency_id;
    }

    /// Lays the slices out for rows whose couplings are counted by `row_offsets` (CSR offsets,
    /// one more entry than rows). The lanes of rows past the last one (the tail of the last
    /// slice) are made padding here; every other lane is written through [`SliceRowsMut::row`].
    pub fn layout(&mut self, row_offsets: &[u32]) {
        self.adjacency_id = 0;
        let n = row_offsets.len().saturating_sub(1);
        assert!(n <= MAX_ROWS, "{n} rows, more than the {MAX_ROWS} a layout takes");
        let slices = n.div_ceil(SLICE);
        self.offsets.clear();
        self.offsets.reserve(slices + 1);
        self.offsets.push(0);
        let mut total = 0u32;
        for s in 0..slices {
            let rows = s * SLICE..((s + 1) * SLICE).min(n);
            let width = rows.map(|i| row_offsets[i + 1] - row_offsets[i]).max().unwrap_or(0);
            total += width;
            self.offsets.push(total);
        }
        self.groups.resize(total as usize, CouplingGroup::default());
        if n % SLICE != 0 {
            let s = slices - 1;
            for g in self.offsets[s] as usize..self.offsets[s + 1] as usize {
                for lane in n % SLICE..SLICE {
                    pad(&mut self.groups[g], lane, n - 1);
                }
            }
        }
    }

    /// Room for a fraction `headroom` more slices and groups than laid out (see `headroom`).
    pub fn reserve_headroom(&mut self, headroom: f64) {
        with_room(&mut self.offsets, headroom);
        with_room(&mut self.groups, headroom);
        with_room(&mut self.springs, headroom);
    }

    pub fn memory_bytes(&self) -> usize {
        self.offsets.capacity() * 4
            + self.groups.capacity() * std::mem::size_of::<CouplingGroup>()
            + self.springs.capacity() * std::mem::size_of::<[u32; SLICE]>()
    }
}

/// Makes a lane padding: a zero block whose other end is `row`.
fn pad(group: &mut CouplingGroup, lane: usize, row: usize) {
    group.set_block(lane, PackedCoupling::default());
    group.set_other(lane, row as u32);
}

/// The groups that hold rows `rows` (`rows.start` a multiple of [`SLICE`], `rows.end` too or the
/// last row).
pub(crate) fn group_range(offsets: &[u32], rows: Range<usize>) -> Range<usize> {
    // Whole slices only: a range ending inside a slice would share its groups with the next.
    let slices = offsets.len() - 1;
    assert!(
        rows.start % SLICE == 0 && (rows.end % SLICE == 0 || rows.end.div_ceil(SLICE) == slices),
        "rows {rows:?} are not whole slices of {slices}"
    );
    offsets[rows.start / SLICE] as usize..offsets[rows.end.div_ceil(SLICE)] as usize
}

/// The groups of a range of whole slices, to write.
pub(crate) struct SliceRowsMut<'a> {
    pub offsets: &'a [u32],
    /// The groups of [`group_range`]`(offsets, rows)`, for rows starting at `first_row`.
    pub groups: &'a mut [CouplingGroup],
    pub first_row: usize,
}

impl SliceRowsMut<'_> {
    /// The groups of row `row`'s slice (indices into `self.groups`).
    pub fn groups_of(&self, row: usize) -> Range<usize> {
        let base = self.offsets[self.first_row / SLICE] as usize;
        let slice = row / SLICE;
        self.offsets[slice] as usize - base..self.offsets[slice + 1] as usize - base
    }

    /// Row `row`'s lanes, to write its couplings (the slice's groups looked up once per row,
    /// not once per coupling: the lookups and checks took about 28 instructions per coupling).
    #[inline]
    pub fn row(&mut self, row: usize) -> RowMut<'_> {
        let groups = self.groups_of(row);
        RowMut { groups: &mut self.groups[groups], lane: row % SLICE, row }
    }

    /// Writes the `k`-th coupling of row `row` and its other end.
    #[cfg(test)]
    pub fn set(&mut self, row: usize, k: usize, c: Coupling, other: u32) {
        self.row(row).set(k, c.packed(), other);
    }

    /// Pads row `row`'s lanes from its `count`-th coupling to the end of its slice (every row
    /// is finished once per assembly, after its couplings are set).
    #[cfg(test)]
    pub fn finish_row(&mut self, row: usize, count: usize) {
        self.row(row).finish(count);
    }

    /// Writes row `row`'s couplings (with their other ends) and pads the rest of its slice's
    /// groups (the tests' way to fill a layout).
    #[cfg(test)]
    pub fn set_row(&mut self, row: usize, couplings: impl Iterator<Item = (Coupling, u32)>) {
        let mut count = 0;
        for (k, (c, other)) in couplings.enumerate() {
            self.set(row, k, c, other);
            count = k + 1;
        }
        self.finish_row(row, count);
    }
}

/// One row's lanes in the groups of its slice ([`SliceRowsMut::row`]).
pub(crate) struct RowMut<'a> {
    groups: &'a mut [CouplingGroup],
    lane: usize,
    row: usize,
}

impl RowMut<'_> {
    /// Writes the row's `k`-th coupling and its other end.
    #[inline(always)]
    pub fn set(&mut self, k: usize, c: PackedCoupling, other: u32) {
        let count = self.groups.len();
        let Some(group) = self.groups.get_mut(k) else {
            panic!("coupling {k} of row {} in a slice of {count}", self.row)
        };
        let lane = self.lane % SLICE;
        group.set_block(lane, c);
        group.set_other(lane, other);
    }

    /// Pads the row's lanes from its `count`-th coupling to the end of its slice (every row is
    /// finished once per assembly, after its couplings are set).
    pub fn finish(self, count: usize) {
        let (lane, row) = (self.lane, self.row);
        for group in self.groups.iter_mut().skip(count) {
            pad(group, lane, row);
        }
    }
}

/// Calls `f(row, Σ_c B_c (x_row - input[other_c]))` for each row of `rows` (`rows.start` a
/// multiple of [`SLICE`]), in order, summing over its couplings `B_c` in `groups` (the plain
/// Rust part of [`product_slices`]).
fn row_sums_scalar(
    offsets: &[u32],
    groups: &[CouplingGroup],
    input: &[Vec3A],
    rows: Range<usize>,
    mut f: impl FnMut(usize, Vec3A),
) {
    for row in rows {
        f(row, row_coupling_sum(offsets, groups, input, row));
    }
}

/// `Σ_c B_c (x_row - input[other_c])` over the couplings of row `row` alone, in the order of
/// its groups (the sums of the eight-row product, one lane). Panics if an other end is not a
/// row of `input`.
pub(crate) fn row_coupling_sum(offsets: &[u32], groups: &[CouplingGroup], input: &[Vec3A], row: usize) -> Vec3A {
    let (slice, lane) = (row / SLICE, row % SLICE);
    let mut acc = Vec3A::ZERO;
    for group in &groups[offsets[slice] as usize..offsets[slice + 1] as usize] {
        let other = group.other_row(lane);
        assert!(other < input.len(), "a coupling's other end is not a row");
        let d = input[row] - input[other];
        let [x, y, z, alpha] = group.block(lane).0.map(from_bf16);
        let w = Vec3A::new(x, y, z);
        let s = w.x * d.x + w.y * d.y + w.z * d.z;
        acc += alpha * d + w * s;
    }
    acc
}

/// [`row_coupling_sum`] of the rows of one slice at a time, for passes that need it at scattered
/// rows (the contact rows of the implicit integrator, twice a substep): a row's slice is summed
/// once, eight lanes at a time with AVX2, and its other rows then come from here. Each lane's
/// sum is [`row_coupling_sum`]'s, bit for bit (the same operations in the same order, no fused
/// multiply-add). One scalar row took about as many instructions as a whole slice, and the
/// contact rows lie in patches: on the issue-5 balloon these sums were 2.2% of a one-thread step.
pub(crate) struct SliceCouplingSums {
    /// The slice summed (`usize::MAX`: none yet).
    slice: usize,
    sums: [Vec3A; SLICE],
}

impl Default for SliceCouplingSums {
    fn default() -> Self {
        Self { slice: usize::MAX, sums: [Vec3A::ZERO; SLICE] }
    }
}

impl SliceCouplingSums {
    /// `row_coupling_sum(offsets, groups, input, row)`, summing `row`'s whole slice when it is
    /// not the last one asked for. Every call with one `SliceCouplingSums` must pass the same
    /// couplings and input. Panics if an other end is not a row of `input`.
    #[inline]
    pub fn row(&mut self, offsets: &[u32], groups: &[CouplingGroup], input: &[Vec3A], row: usize) -> Vec3A {
        let slice = row / SLICE;
        if slice != self.slice {
            self.sums = slice_coupling_sums(offsets, groups, input, slice);
            self.slice = slice;
        }
        self.sums[row % SLICE]
    }
}

/// [`row_coupling_sum`] of each row of slice `slice` (zero for lanes past the last row of
/// `input`). Panics if an other end is not a row of `input`.
fn slice_coupling_sums(offsets: &[u32], groups: &[CouplingGroup], input: &[Vec3A], slice: usize) -> [Vec3A; SLICE] {
    let first = slice * SLICE;
    #[cfg(target_arch = "x86_64")]
    if first + SLICE <= input.len()
        && std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
    {
        let groups = &groups[offsets[slice] as usize..offsets[slice + 1] as usize];
        // SAFETY: the processor has AVX2 and FMA (checked above); rows first..first + 8 are rows
        // of `input`.
        return unsafe { slice_coupling_sums_avx2(groups, input, first) };
    }
    std::array::from_fn(|lane| {
        let row = first + lane;
        if row < input.len() { row_coupling_sum(offsets, groups, input, row) } else { Vec3A::ZERO }
    })
}

/// [`slice_coupling_sums`] of a whole slice (its `groups`, its rows from `first`) with AVX2 (and
/// FMA enabled for the loads it shares with the product; it uses no fused multiply-add).
///
/// # Safety
/// The processor must have AVX2 and FMA; `first + 8 <= input.len()`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn slice_coupling_sums_avx2(groups: &[CouplingGroup], input: &[Vec3A], first: usize) -> [Vec3A; SLICE] {
    use std::arch::x86_64::*;
    // The largest offset a row's four f32 can start at.
    let limit = _mm256_set1_epi32((4 * (input.len() - 1)).min(u32::MAX as usize) as u32 as i32);
    let upper = _mm256_set1_epi32(0xFFFF_0000_u32 as i32);
    // SAFETY: rows first..first + 8 (the caller's contract).
    let (xx, xy, xz) = unsafe { load_rows_transposed(input, first) };
    let (mut ax, mut ay, mut az) = (_mm256_setzero_ps(), _mm256_setzero_ps(), _mm256_setzero_ps());
    for group in groups {
        // SAFETY: `other_offset`, `xy` and `za` are 32 aligned bytes (offsets 64, 0 and 32 of a
        // 32-byte aligned group).
        let (other, xy_words, za_words) = unsafe {
            (
                _mm256_load_si256(group.other_offset.as_ptr() as *const __m256i),
                _mm256_load_si256(group.xy.as_ptr() as *const __m256i),
                _mm256_load_si256(group.za.as_ptr() as *const __m256i),
            )
        };
        let inside = _mm256_cmpeq_epi32(_mm256_max_epu32(other, limit), limit);
        assert!(_mm256_movemask_epi8(inside) == -1, "a coupling's other end is not a row");
        let wx = _mm256_castsi256_ps(_mm256_slli_epi32::<16>(xy_words));
        let wy = _mm256_castsi256_ps(_mm256_and_si256(xy_words, upper));
        let wz = _mm256_castsi256_ps(_mm256_slli_epi32::<16>(za_words));
        let alpha = _mm256_castsi256_ps(_mm256_and_si256(za_words, upper));
        // SAFETY: every other end's four f32 are in `input` (checked above).
        let (px, py, pz) = unsafe { load_transposed(input, &group.other_offset) };
        let (dx, dy, dz) = (_mm256_sub_ps(xx, px), _mm256_sub_ps(xy, py), _mm256_sub_ps(xz, pz));
        // `row_coupling_sum`'s operations: s = wx dx + wy dy + wz dz, acc += alpha d + w s.
        let s = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(wx, dx), _mm256_mul_ps(wy, dy)), _mm256_mul_ps(wz, dz));
        ax = _mm256_add_ps(ax, _mm256_add_ps(_mm256_mul_ps(alpha, dx), _mm256_mul_ps(wx, s)));
        ay = _mm256_add_ps(ay, _mm256_add_ps(_mm256_mul_ps(alpha, dy), _mm256_mul_ps(wy, s)));
        az = _mm256_add_ps(az, _mm256_add_ps(_mm256_mul_ps(alpha, dz), _mm256_mul_ps(wz, s)));
    }
    let (mut sx, mut sy, mut sz) = ([0f32; SLICE], [0f32; SLICE], [0f32; SLICE]);
    // SAFETY: eight f32 into each local array.
    unsafe {
        _mm256_storeu_ps(sx.as_mut_ptr(), ax);
        _mm256_storeu_ps(sy.as_mut_ptr(), ay);
        _mm256_storeu_ps(sz.as_mut_ptr(), az);
    }
    std::array::from_fn(|lane| Vec3A::new(sx[lane], sy[lane], sz[lane]))
}

/// Eight `Vec3A` rows of `input` (from the f32 at `offsets[lane]`: 4 × the row), as their x, y
/// and z lanes.
///
/// # Safety
/// The processor must have AVX2; every offset plus 4 must be at most `4 * input.len()`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn load_transposed(
    input: &[Vec3A],
    offsets: &[u32; SLICE],
) -> (std::arch::x86_64::__m256, std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
    use std::arch::x86_64::*;
    let base = input.as_ptr() as *const f32;
    // Each index read from memory by itself (a volatile read): the product has the eight in a
    // register already (its bounds check), and the compiler then took them out of it (widened
    // to 64 bits, then `vpextrq` and `vmovq` per pair), which kept the loads of the rows
    // waiting. Read one by one, the product's share of a 1-thread profile of the issue-5
    // balloon went from 26.0% to 23.1%.
    // SAFETY: 16 bytes of `input` from each offset (the caller's contract), read unaligned (an
    // offset that is no multiple of 4 reads parts of two rows, never past the input); the
    // offset is an initialized u32 of the array.
    let row = |lane: usize| unsafe { _mm_loadu_ps(base.add(std::ptr::read_volatile(&offsets[lane]) as usize)) };
    let (x, y, z, _) = transpose_rows(
        _mm256_set_m128(row(4), row(0)),
        _mm256_set_m128(row(5), row(1)),
        _mm256_set_m128(row(6), row(2)),
        _mm256_set_m128(row(7), row(3)),
    );
    (x, y, z)
}

/// Eight rows of four f32, given as the pairs (0 | 4), (1 | 5), (2 | 6), (3 | 7) of 128-bit
/// halves, as their four lanes: x, y, z and w of rows 0 to 7 in order (callable where AVX2 is
/// enabled).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) fn transpose_rows(
    r04: std::arch::x86_64::__m256,
    r15: std::arch::x86_64::__m256,
    r26: std::arch::x86_64::__m256,
    r37: std::arch::x86_64::__m256,
) -> (std::arch::x86_64::__m256, std::arch::x86_64::__m256, std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
    use std::arch::x86_64::*;
    let xy01 = _mm256_unpacklo_ps(r04, r15); // x0 x1 y0 y1 | x4 x5 y4 y5
    let xy23 = _mm256_unpacklo_ps(r26, r37); // x2 x3 y2 y3 | x6 x7 y6 y7
    let zw01 = _mm256_unpackhi_ps(r04, r15);
    let zw23 = _mm256_unpackhi_ps(r26, r37);
    (
        _mm256_shuffle_ps::<0x44>(xy01, xy23),
        _mm256_shuffle_ps::<0xEE>(xy01, xy23),
        _mm256_shuffle_ps::<0x44>(zw01, zw23),
        _mm256_shuffle_ps::<0xEE>(zw01, zw23),
    )
}

/// The eight consecutive `Vec3A` rows `first..first + 8` of `input`, as their x, y and z lanes
/// ([`load_transposed`] without the indices: a product's own rows).
///
/// # Safety
/// The processor must have AVX2; `first + 8 <= input.len()`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) unsafe fn load_rows_transposed(
    input: &[Vec3A],
    first: usize,
) -> (std::arch::x86_64::__m256, std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
    use std::arch::x86_64::*;
    // SAFETY: rows first..first + 8 (the caller's contract), 16 aligned bytes each.
    let (r04, r15, r26, r37) = unsafe {
        let base = input.as_ptr().add(first) as *const f32;
        let row = |lane: usize| base.add(4 * lane);
        (
            _mm256_set_m128(_mm_load_ps(row(4)), _mm_load_ps(row(0))),
            _mm256_set_m128(_mm_load_ps(row(5)), _mm_load_ps(row(1))),
            _mm256_set_m128(_mm_load_ps(row(6)), _mm_load_ps(row(2))),
            _mm256_set_m128(_mm_load_ps(row(7)), _mm_load_ps(row(3))),
        )
    };
    let (x, y, z, _) = transpose_rows(r04, r15, r26, r37);
    (x, y, z)
}

/// Eight rows of x, y and z lanes into the eight `Vec3A` of `out` (a zero fourth lane): the
/// inverse of [`load_rows_transposed`].
///
/// # Safety
/// The processor must have AVX2. Panics unless `out` has eight rows.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn store_rows_transposed(
    out: &mut [Vec3A],
    x: std::arch::x86_64::__m256,
    y: std::arch::x86_64::__m256,
    z: std::arch::x86_64::__m256,
) {
    use std::arch::x86_64::*;
    assert!(out.len() == SLICE, "{} rows, not a slice", out.len());
    let zero = _mm256_setzero_ps();
    let xy01 = _mm256_unpacklo_ps(x, y); // x0 y0 x1 y1 | x4 y4 x5 y5
    let xy23 = _mm256_unpackhi_ps(x, y); // x2 y2 x3 y3 | x6 y6 x7 y7
    let z01 = _mm256_unpacklo_ps(z, zero); // z0 0 z1 0 | z4 0 z5 0
    let z23 = _mm256_unpackhi_ps(z, zero);
    let rows_of = [
        _mm256_shuffle_ps::<0x44>(xy01, z01), // row 0 | row 4
        _mm256_shuffle_ps::<0xEE>(xy01, z01), // 1 | 5
        _mm256_shuffle_ps::<0x44>(xy23, z23), // 2 | 6
        _mm256_shuffle_ps::<0xEE>(xy23, z23), // 3 | 7
    ];
    let to = out.as_mut_ptr() as *mut f32;
    // SAFETY: eight Vec3A (16 aligned bytes each) of `out` (asserted above).
    unsafe {
        for (lane, v) in rows_of.iter().enumerate() {
            _mm_store_ps(to.add(4 * lane), _mm256_castps256_ps128(*v));
            _mm_store_ps(to.add(4 * (lane + 4)), _mm256_extractf128_ps::<1>(*v));
        }
    }
}

/// What a product with the implicit system's matrix adds to each row after its couplings' sum
/// `Σ B (x_row - x_other)`, and how it filters the row. Every slice is indexed by row (all rows,
/// not a chunk's), except `gas_scale` (by fragment) and `contact_normal` (by slot).
#[derive(Clone, Copy)]
pub(crate) struct RowTerms<'a> {
    /// The diagonal's `m x`; a row whose inverse mass is 0 (pinned) is zero.
    pub mass: &'a [f32],
    pub inv_mass: &'a [f32],
    /// The gas's rank-one term `g (h² P/V Σ g·x)`: per row its fragment (`u32::MAX`: none) and
    /// gradient `g`, per fragment the scale (empty `fragment`: no gas); per slice the fragment
    /// its rows share or `gas::MIXED_FRAGMENTS` (`gas::slice_fragments` of `fragment`).
    pub fragment: &'a [u32],
    pub slice_fragment: &'a [u32],
    pub gradient: &'a [Vec3],
    pub gas_scale: &'a [f32],
    /// The contact filter: per row the slot of its contact normal (`u32::MAX`: free; empty: no
    /// contacts), whose component is taken out of the row.
    pub contact_slot: &'a [u32],
    pub contact_normal: &'a [Vec3A],
}

impl RowTerms<'_> {
    /// Row `i` of the product from its couplings' sum `sum` and its input `x` (the eight-row
    /// version's operations in its order, one lane).
    #[inline(always)]
    fn row(&self, i: usize, x: Vec3A, sum: Vec3A) -> Vec3A {
        let mut row = x * self.mass[i] + sum;
        if let Some(&fragment) = self.fragment.get(i).filter(|&&f| f != u32::MAX) {
            row += Vec3A::from(self.gradient[i]) * self.gas_scale[fragment as usize];
        }
        if let Some(&slot) = self.contact_slot.get(i).filter(|&&s| s != u32::MAX) {
            let n = self.contact_normal[slot as usize];
            row -= n * (row.x * n.x + row.y * n.y + row.z * n.z);
        }
        if self.inv_mass[i] == 0.0 { Vec3A::ZERO } else { row }
    }
}

/// Coupling groups (with their slices' `offsets`) whose other ends were all checked to be
/// below `rows`, once (the implicit integrator checks after each assembly, and the groups do not
/// change during its solve), so that the products can load the other ends' rows unchecked
/// instead of checking each group in every product (a vector load, comparison and branch in
/// each group's 50-odd instructions). One-thread profiles of the issue-5 balloon, three each
/// way: the product went from 2.60-3.00 to 2.48-2.85 times the residual pass's time, a gain
/// within the noise of such profiles.
#[derive(Clone, Copy)]
pub(crate) struct CheckedCouplings<'a> {
    offsets: &'a [u32],
    groups: &'a [CouplingGroup],
    rows: usize,
}

impl<'a> CheckedCouplings<'a> {
    /// Panics if an other end is not below `rows` (the tests' way; the implicit integrator
    /// finds the largest offset in its assembly, [`CheckedCouplings::with_largest`]).
    #[cfg(test)]
    pub fn new(offsets: &'a [u32], groups: &'a [CouplingGroup], rows: usize) -> Self {
        // SAFETY: the largest offset of these very groups.
        unsafe { Self::with_largest(offsets, groups, rows, largest_other_offset(groups)) }
    }

    /// [`CheckedCouplings::new`] with the groups' largest other-end offset found by the caller
    /// ([`largest_other_offset`] of parts that cover them: the implicit assembly takes it from
    /// each chunk's groups while they are in the cache, where each member of a team scanned all
    /// of them again). Panics if it is not below `rows`.
    ///
    /// # Safety
    /// `largest` must be at least every other-end offset of `groups`.
    pub unsafe fn with_largest(offsets: &'a [u32], groups: &'a [CouplingGroup], rows: usize, largest: u32) -> Self {
        // (The product loads 16 bytes from each offset, so a row's four f32 must all be there.)
        assert!(groups.is_empty() || largest as usize + 4 <= 4 * rows, "a coupling's other end is not a row");
        Self { offsets, groups, rows }
    }
}

/// The largest other-end offset in `groups` (0 without groups): eight lanes at a time with
/// AVX2 where the processor has it. The plain fold compiles to a compare and a conditional move
/// per lane (an unsigned maximum of packed u32 is not in x86-64's baseline SSE2), and each
/// member of a team checks all the groups once per substep: on the issue-5 balloon that took
/// about 0.9% of a one-thread step (`perf`), as long on each member of two.
pub(crate) fn largest_other_offset(groups: &[CouplingGroup]) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2 (checked just above).
        return unsafe { largest_other_offset_avx2(groups) };
    }
    groups.iter().fold(0u32, |m, group| group.other_offset.iter().fold(m, |m, &o| m.max(o)))
}

/// [`largest_other_offset`] with AVX2.
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn largest_other_offset_avx2(groups: &[CouplingGroup]) -> u32 {
    use std::arch::x86_64::*;
    let mut largest = _mm256_setzero_si256();
    for group in groups {
        // SAFETY: `other_offset` is 32 aligned bytes (offset 64 of a 32-byte aligned group).
        let lanes = unsafe { _mm256_load_si256(group.other_offset.as_ptr() as *const __m256i) };
        largest = _mm256_max_epu32(largest, lanes);
    }
    let mut lanes = [0u32; SLICE];
    // SAFETY: eight u32 into an array of eight.
    unsafe { _mm256_storeu_si256(lanes.as_mut_ptr() as *mut __m256i, largest) };
    lanes.into_iter().max().unwrap_or(0)
}

/// Rows `rows` (`rows.start` a multiple of [`SLICE`]) of the product `A input` of the implicit
/// system's matrix (the couplings in `groups`, the rest in `terms`) into `out` (its rows from
/// `rows.start`); returns `Σ input·out` over them. Eight rows at a time with AVX2 and FMA when
/// the processor has them: the couplings' sums stay in registers for the rest of the row (a
/// second pass over the rows, one at a time, took about 40% of the product's instructions).
/// The dot products are summed per lane (row mod 8) in f64 and the lanes added in a fixed order,
/// so the result depends on neither the thread count nor which path ran a slice.
///
/// Panics if `input` does not have the rows the couplings were checked for, or a slice of
/// `terms` is not one per row.
pub(crate) fn product_slices(
    couplings: CheckedCouplings,
    input: &[Vec3A],
    rows: Range<usize>,
    terms: &RowTerms,
    out: &mut [Vec3A],
) -> f64 {
    let n = input.len();
    assert_eq!(n, couplings.rows, "the input's rows against the couplings' checked rows");
    let (offsets, groups) = (couplings.offsets, couplings.groups);
    assert!(out.len() == rows.len() && rows.end <= n && rows.start % SLICE == 0, "rows {rows:?} of {n}");
    assert!(terms.mass.len() == n && terms.inv_mass.len() == n);
    assert!(
        terms.fragment.is_empty()
            || (terms.fragment.len() == n
                && terms.gradient.len() == n
                && terms.slice_fragment.len() == n.div_ceil(SLICE))
    );
    assert!(terms.contact_slot.is_empty() || terms.contact_slot.len() == n);
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the processor has the features the function is compiled for (checked above).
        return unsafe { product_slices_avx2(offsets, groups, input, rows, terms, out) };
    }
    product_slices_scalar(offsets, groups, input, rows, terms, out)
}

/// [`product_slices`] in plain Rust (the caller checked the slices' lengths).
fn product_slices_scalar(
    offsets: &[u32],
    groups: &[CouplingGroup],
    input: &[Vec3A],
    rows: Range<usize>,
    terms: &RowTerms,
    out: &mut [Vec3A],
) -> f64 {
    let mut lanes = [0.0f64; SLICE];
    let first = rows.start;
    row_sums_scalar(offsets, groups, input, rows, |i, sum| {
        let row = terms.row(i, input[i], sum);
        out[i - first] = row;
        lanes[i % SLICE] += input[i].dot(row) as f64;
    });
    sum_lanes(lanes)
}

/// The lanes' dot products added in a fixed order.
fn sum_lanes(l: [f64; SLICE]) -> f64 {
    ((l[0] + l[1]) + (l[2] + l[3])) + ((l[4] + l[5]) + (l[6] + l[7]))
}

/// Eight `Vec3` from `points[first..first + 8]`, as their x, y and z lanes (the 16-byte loads
/// read four bytes past each point: the last one's only if a point follows, else one at a time).
///
/// # Safety
/// The processor must have AVX2; `first + 8 <= points.len()`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) unsafe fn load_points_transposed(
    points: &[Vec3],
    first: usize,
) -> (std::arch::x86_64::__m256, std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
    use std::arch::x86_64::*;
    if first + SLICE < points.len() {
        let base = points[first..].as_ptr() as *const f32;
        // SAFETY: the points first..first + 8 and the one after them (checked above).
        let row = |lane: usize| unsafe { base.add(3 * lane) };
        // SAFETY: as above.
        let (r04, r15, r26, r37) = unsafe {
            (
                _mm256_set_m128(_mm_loadu_ps(row(4)), _mm_loadu_ps(row(0))),
                _mm256_set_m128(_mm_loadu_ps(row(5)), _mm_loadu_ps(row(1))),
                _mm256_set_m128(_mm_loadu_ps(row(6)), _mm_loadu_ps(row(2))),
                _mm256_set_m128(_mm_loadu_ps(row(7)), _mm_loadu_ps(row(3))),
            )
        };
        let (x, y, z, _) = transpose_rows(r04, r15, r26, r37);
        (x, y, z)
    } else {
        let p = &points[first..first + SLICE];
        let axis = |a: usize| std::array::from_fn::<f32, SLICE, _>(|lane| p[lane][a]);
        let (x, y, z) = (axis(0), axis(1), axis(2));
        // SAFETY: eight f32 from each array.
        unsafe { (_mm256_loadu_ps(x.as_ptr()), _mm256_loadu_ps(y.as_ptr()), _mm256_loadu_ps(z.as_ptr())) }
    }
}

/// [`product_slices`] with AVX2 and FMA (the caller checked the slices' lengths).
///
/// # Safety
/// The processor must have AVX2 and FMA; every other end in `groups` is below `input.len()`
/// ([`CheckedCouplings`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn product_slices_avx2(
    offsets: &[u32],
    groups: &[CouplingGroup],
    input: &[Vec3A],
    rows: Range<usize>,
    terms: &RowTerms,
    out: &mut [Vec3A],
) -> f64 {
    use std::arch::x86_64::*;
    let n = input.len();
    let free = _mm256_set1_epi32(-1);
    let upper = _mm256_set1_epi32(0xFFFF_0000_u32 as i32);
    let first = rows.start;
    let (mut dots_low, mut dots_high) = (_mm256_setzero_pd(), _mm256_setzero_pd());
    let mut row = rows.start;
    while row < rows.end {
        let slice = row / SLICE;
        let lanes = (rows.end - row).min(SLICE);
        let (xx, xy, xz) = if lanes == SLICE {
            // SAFETY: rows row..row + 8 are rows of `input` (row + 8 <= rows.end <= n).
            unsafe { load_rows_transposed(input, row) }
        } else {
            let own: [u32; SLICE] = std::array::from_fn(|lane| 4 * (row + lane).min(n - 1) as u32);
            // SAFETY: every offset of `own` is that of a row below n (clamped above).
            unsafe { load_transposed(input, &own) }
        };
        let (mut ax, mut ay, mut az) = (_mm256_setzero_ps(), _mm256_setzero_ps(), _mm256_setzero_ps());
        for group in &groups[offsets[slice] as usize..offsets[slice + 1] as usize] {
            // bfloat16 to f32: the lower half of a word shifted up, or the upper half masked.
            // SAFETY: `xy` and `za` are 32 aligned bytes (offsets 0 and 32 of a 32-byte aligned
            // group).
            let (wx, wy, wz, alpha) = unsafe {
                let (xy, za) = (
                    _mm256_load_si256(group.xy.as_ptr() as *const __m256i),
                    _mm256_load_si256(group.za.as_ptr() as *const __m256i),
                );
                (
                    _mm256_castsi256_ps(_mm256_slli_epi32::<16>(xy)),
                    _mm256_castsi256_ps(_mm256_and_si256(xy, upper)),
                    _mm256_castsi256_ps(_mm256_slli_epi32::<16>(za)),
                    _mm256_castsi256_ps(_mm256_and_si256(za, upper)),
                )
            };
            // SAFETY: every other end is below n (this function's contract).
            let (px, py, pz) = unsafe { load_transposed(input, &group.other_offset) };
            let dx = _mm256_sub_ps(xx, px);
            let dy = _mm256_sub_ps(xy, py);
            let dz = _mm256_sub_ps(xz, pz);
            let s = _mm256_fmadd_ps(wz, dz, _mm256_fmadd_ps(wy, dy, _mm256_mul_ps(wx, dx)));
            ax = _mm256_fmadd_ps(wx, s, _mm256_fmadd_ps(alpha, dx, ax));
            ay = _mm256_fmadd_ps(wy, s, _mm256_fmadd_ps(alpha, dy, ay));
            az = _mm256_fmadd_ps(wz, s, _mm256_fmadd_ps(alpha, dz, az));
        }
        if lanes < SLICE {
            // The last rows, fewer than a slice: one at a time.
            let (mut sx, mut sy, mut sz) = ([0f32; SLICE], [0f32; SLICE], [0f32; SLICE]);
            // SAFETY: eight f32 into each local array.
            unsafe {
                _mm256_storeu_ps(sx.as_mut_ptr(), ax);
                _mm256_storeu_ps(sy.as_mut_ptr(), ay);
                _mm256_storeu_ps(sz.as_mut_ptr(), az);
            }
            let mut dots = [0.0f64; SLICE];
            for lane in 0..lanes {
                let i = row + lane;
                let value = terms.row(i, input[i], Vec3A::new(sx[lane], sy[lane], sz[lane]));
                out[i - first] = value;
                dots[lane] = input[i].dot(value) as f64;
            }
            // SAFETY: four f64 from each half of the array.
            unsafe {
                dots_low = _mm256_add_pd(dots_low, _mm256_loadu_pd(dots.as_ptr()));
                dots_high = _mm256_add_pd(dots_high, _mm256_loadu_pd(dots.as_ptr().add(4)));
            }
            break;
        }
        // SAFETY: rows row..row + 8 of each per-row slice (all of length n, row + 8 <= n).
        let (mass, inv_mass) = unsafe {
            (
                _mm256_loadu_ps(terms.mass[row..row + SLICE].as_ptr()),
                _mm256_loadu_ps(terms.inv_mass[row..row + SLICE].as_ptr()),
            )
        };
        let mut rx = _mm256_add_ps(_mm256_mul_ps(xx, mass), ax);
        let mut ry = _mm256_add_ps(_mm256_mul_ps(xy, mass), ay);
        let mut rz = _mm256_add_ps(_mm256_mul_ps(xz, mass), az);
        if !terms.fragment.is_empty() {
            let fragment = &terms.fragment[row..row + SLICE];
            let shared = terms.slice_fragment[slice];
            let scale = if shared != MIXED_FRAGMENTS {
                (shared != u32::MAX).then(|| _mm256_set1_ps(terms.gas_scale[shared as usize]))
            } else {
                let scale: [f32; SLICE] = std::array::from_fn(|lane| match fragment[lane] {
                    u32::MAX => 0.0,
                    f => terms.gas_scale[f as usize],
                });
                // SAFETY: eight f32.
                Some(unsafe { _mm256_loadu_ps(scale.as_ptr()) })
            };
            if let Some(scale) = scale {
                // SAFETY: row + 8 <= n = gradient.len() (asserted by the caller).
                let (gx, gy, gz) = unsafe { load_points_transposed(terms.gradient, row) };
                rx = _mm256_fmadd_ps(gx, scale, rx);
                ry = _mm256_fmadd_ps(gy, scale, ry);
                rz = _mm256_fmadd_ps(gz, scale, rz);
            }
        }
        if !terms.contact_slot.is_empty() {
            let slots = &terms.contact_slot[row..row + SLICE];
            // SAFETY: eight u32.
            let all_free = unsafe {
                let v = _mm256_loadu_si256(slots.as_ptr() as *const __m256i);
                _mm256_movemask_epi8(_mm256_cmpeq_epi32(v, free)) == -1
            };
            if !all_free {
                // The normal's component out of each row in contact (a zero normal elsewhere).
                let normal = |lane: usize| match slots[lane] {
                    u32::MAX => Vec3A::ZERO,
                    s => terms.contact_normal[s as usize],
                };
                let normals: [Vec3A; SLICE] = std::array::from_fn(normal);
                let axis = |a: usize| std::array::from_fn::<f32, SLICE, _>(|lane| normals[lane][a]);
                let (x, y, z) = (axis(0), axis(1), axis(2));
                // SAFETY: eight f32 from each array.
                let (nx, ny, nz) =
                    unsafe { (_mm256_loadu_ps(x.as_ptr()), _mm256_loadu_ps(y.as_ptr()), _mm256_loadu_ps(z.as_ptr())) };
                let along = _mm256_fmadd_ps(rz, nz, _mm256_fmadd_ps(ry, ny, _mm256_mul_ps(rx, nx)));
                rx = _mm256_fnmadd_ps(nx, along, rx);
                ry = _mm256_fnmadd_ps(ny, along, ry);
                rz = _mm256_fnmadd_ps(nz, along, rz);
            }
        }
        // Pinned rows are zero.
        let moving = _mm256_cmp_ps::<_CMP_NEQ_UQ>(inv_mass, _mm256_setzero_ps());
        rx = _mm256_and_ps(rx, moving);
        ry = _mm256_and_ps(ry, moving);
        rz = _mm256_and_ps(rz, moving);
        let dot = _mm256_fmadd_ps(xz, rz, _mm256_fmadd_ps(xy, ry, _mm256_mul_ps(xx, rx)));
        dots_low = _mm256_add_pd(dots_low, _mm256_cvtps_pd(_mm256_castps256_ps128(dot)));
        dots_high = _mm256_add_pd(dots_high, _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(dot)));
        // The eight rows back as Vec3A (a zero fourth lane).
        // SAFETY: AVX2 (this function's contract).
        unsafe { store_rows_transposed(&mut out[row - first..row - first + SLICE], rx, ry, rz) };
        row += SLICE;
    }
    let mut lanes = [0.0f64; SLICE];
    // SAFETY: four f64 into each half of the array.
    unsafe {
        _mm256_storeu_pd(lanes.as_mut_ptr(), dots_low);
        _mm256_storeu_pd(lanes.as_mut_ptr().add(4), dots_high);
    }
    sum_lanes(lanes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::gas::slice_fragments;

    /// Both paths of [`product_slices`] (the AVX2 one where the processor has it) from row
    /// `from`: each row and the dot product.
    fn both_products(
        slices: &CouplingSlices,
        input: &[Vec3A],
        from: usize,
        terms: &RowTerms,
    ) -> Vec<(Vec<Vec3A>, f64)> {
        let n = input.len();
        let mut results = Vec::new();
        let mut out = vec![Vec3A::splat(f32::NAN); n - from];
        let dot = product_slices_scalar(&slices.offsets, &slices.groups, input, from..n, terms, &mut out);
        results.push((out, dot));
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
            let mut out = vec![Vec3A::splat(f32::NAN); n - from];
            // SAFETY: the processor has AVX2 and FMA (checked above); every other end is below n
            // (checked first).
            CheckedCouplings::new(&slices.offsets, &slices.groups, n);
            let dot = unsafe { product_slices_avx2(&slices.offsets, &slices.groups, input, from..n, terms, &mut out) };
            results.push((out, dot));
        }
        results
    }

    /// A random matrix with rows of 0 to 9 couplings and a row count that leaves the last slice
    /// partly empty, with random masses, some pinned rows, gas in two fragments (slices of one
    /// fragment, mixed slices and rows without gas) and contacts on some rows: both paths of
    /// the product agree with the product computed row by row from its definition, up to
    /// rounding, as does the dot product.
    #[test]
    fn products_agree_with_the_matrix_row_by_row() {
        // 104 rows: whole slices only, so the gradient of the last slice is loaded one point
        // at a time (nothing follows it).
        for n in [101, 104] {
            check_products(n);
        }
    }

    fn check_products(n: usize) {
        let mut unit = crate::body::test_randoms(0x2545_f491_4f6c_dd1d);
        let mut row_offsets = vec![0u32];
        let mut rows: Vec<Vec<(Coupling, u32)>> = Vec::new();
        for i in 0..n {
            let count = (i * 7 + 3) % 10;
            let row: Vec<(Coupling, u32)> = (0..count)
                .map(|k| {
                    let u = Vec3A::new(unit(), unit(), unit()).normalize_or_zero();
                    (Coupling::new(u, unit().abs(), unit().abs() * 3.0), ((i * 31 + k * 17) % n) as u32)
                })
                .collect();
            row_offsets.push(row_offsets.last().unwrap() + row.len() as u32);
            rows.push(row);
        }
        let mut slices = CouplingSlices::default();
        // Garbage left in the groups from an earlier layout must not matter.
        let mut stale = CouplingGroup { other_offset: [12; SLICE], ..CouplingGroup::default() };
        for lane in 0..SLICE {
            stale.set_block(lane, Coupling(Vec4::new(7.0, 7.0, 7.0, 5.0)).packed());
        }
        slices.groups = vec![stale; 400];
        slices.layout(&row_offsets);
        {
            let mut view = SliceRowsMut { offsets: &slices.offsets, groups: &mut slices.groups, first_row: 0 };
            for (i, row) in rows.iter().enumerate() {
                view.set_row(i, row.iter().copied());
            }
        }
        let input: Vec<Vec3A> = (0..n).map(|_| Vec3A::new(unit(), unit(), unit()) * 10.0).collect();
        // One row's couplings alone (the contacts' reactions) are the matrix's.
        for (i, row) in rows.iter().enumerate() {
            let want: Vec3A = row.iter().map(|&(c, j)| c.rounded().apply(input[i] - input[j as usize])).sum();
            let got = row_coupling_sum(&slices.offsets, &slices.groups, &input, i);
            assert!((got - want).length() <= 1e-5 * (1.0 + row.len() as f32 * 40.0), "row {i}: {got} vs {want}");
        }
        // By slices (eight lanes at once where the processor has AVX2 and the slice is whole),
        // asked in an order that goes back to slices summed before: the rows' sums, bit for bit.
        let mut sums = SliceCouplingSums::default();
        let order = (0..n).step_by(3).chain((0..n).rev().step_by(2)).chain(0..n);
        for i in order {
            let want = row_coupling_sum(&slices.offsets, &slices.groups, &input, i);
            let got = sums.row(&slices.offsets, &slices.groups, &input, i);
            assert_eq!(got.to_array().map(f32::to_bits), want.to_array().map(f32::to_bits), "row {i} by slices");
        }
        let mass: Vec<f32> = (0..n).map(|_| 0.5 + unit().abs()).collect();
        let inv_mass: Vec<f32> = (0..n).map(|i| if i % 13 == 5 { 0.0 } else { 1.0 / mass[i] }).collect();
        // Rows 0-39 in fragment 0, 40-51 without gas, then alternating (mixed slices).
        let fragment: Vec<u32> = (0..n as u32)
            .map(|i| match i {
                0..40 => 0,
                40..52 => u32::MAX,
                _ => [0, 1, u32::MAX][i as usize % 3],
            })
            .collect();
        let slice_fragment = slice_fragments(&fragment);
        assert!(slice_fragment.contains(&0) && slice_fragment.contains(&MIXED_FRAGMENTS));
        let gradient: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), unit(), unit())).collect();
        let gas_scale = [0.37f32, -1.25];
        let normals = [Vec3A::Y, Vec3A::new(0.6, 0.8, 0.0)];
        let contact_slot: Vec<u32> = (0..n).map(|i| if i % 11 == 3 { (i % 2) as u32 } else { u32::MAX }).collect();
        let mut pinned_seen = false;
        for (gas, contacts) in [(false, false), (true, false), (false, true), (true, true)] {
            let terms = RowTerms {
                mass: &mass,
                inv_mass: &inv_mass,
                fragment: if gas { &fragment } else { &[] },
                slice_fragment: if gas { &slice_fragment } else { &[] },
                gradient: if gas { &gradient } else { &[] },
                gas_scale: &gas_scale,
                contact_slot: if contacts { &contact_slot } else { &[] },
                contact_normal: &normals,
            };
            let expected: Vec<Vec3A> = (0..n)
                .map(|i| {
                    let sum: Vec3A =
                        rows[i].iter().map(|&(c, j)| c.rounded().apply(input[i] - input[j as usize])).sum();
                    let mut row = input[i] * mass[i] + sum;
                    if gas && fragment[i] != u32::MAX {
                        row += Vec3A::from(gradient[i]) * gas_scale[fragment[i] as usize];
                    }
                    if contacts && contact_slot[i] != u32::MAX {
                        let normal = normals[contact_slot[i] as usize];
                        row -= normal * row.dot(normal);
                    }
                    if inv_mass[i] == 0.0 { Vec3A::ZERO } else { row }
                })
                .collect();
            for from in [0, 48] {
                let want_dot: f64 = (from..n).map(|i| input[i].dot(expected[i]) as f64).sum();
                for (out, dot) in both_products(&slices, &input, from, &terms) {
                    for (k, got) in out.iter().enumerate() {
                        let (i, want) = (from + k, expected[from + k]);
                        let scale = 1.0 + rows[i].len() as f32 * 40.0 + want.length();
                        assert!((*got - want).length() <= 1e-5 * scale, "row {i}: {got} vs {want} ({gas}, {contacts})");
                        if inv_mass[i] == 0.0 {
                            assert_eq!(*got, Vec3A::ZERO);
                            pinned_seen = true;
                        }
                    }
                    assert!((dot - want_dot).abs() <= 1e-5 * (1.0 + want_dot.abs()), "{dot} vs {want_dot}");
                }
            }
        }
        assert!(pinned_seen);
        assert_eq!(group_range(&slices.offsets, 0..n), 0..slices.groups.len());
    }

    /// bfloat16 rounding: exact for values with 8 significant bits, to the nearest (ties to
    /// even) otherwise, within 2^-8 relative, and NaN kept.
    #[test]
    fn bfloat16_rounds_to_nearest_even() {
        for v in [0.0f32, -0.0, 1.0, -2.5, 1.5 * 2f32.powi(127), 2f32.powi(-126), 0.15625] {
            assert_eq!(from_bf16(to_bf16(v)).to_bits(), v.to_bits(), "{v}");
        }
        // 1 + 2^-8 lies halfway between 1 and 1 + 2^-7: ties go to the even mantissa (1).
        assert_eq!(from_bf16(to_bf16(1.0 + 2f32.powi(-8))), 1.0);
        assert_eq!(from_bf16(to_bf16(1.0 + 3.0 * 2f32.powi(-8))), 1.0 + 2.0 * 2f32.powi(-7));
        assert_eq!(from_bf16(to_bf16(1.0 + 2f32.powi(-8) + 2f32.powi(-20))), 1.0 + 2f32.powi(-7));
        let mut x = 1.234e-3f32;
        for _ in 0..2000 {
            let r = from_bf16(to_bf16(x));
            assert!((r - x).abs() <= x.abs() * 2f32.powi(-8), "{x} -> {r}");
            assert_eq!(from_bf16(to_bf16(r)), r);
            x *= -1.0137;
        }
        assert!(from_bf16(to_bf16(f32::NAN)).is_nan());
        let c = Coupling::new(Vec3A::new(0.6, 0.0, 0.8), 12.345, 67.89).rounded();
        assert_eq!(c, c.rounded());
        // The four-lane rounding of a block is the one-lane rounding of each lane.
        let mut y = 0.7319f32;
        for _ in 0..500 {
            let c = Coupling(Vec4::new(y, -y * 3.1, y * 1e-20, 1.0 / y));
            let lanes = c.0.to_array().map(|v| from_bf16(to_bf16(v)).to_bits());
            assert_eq!(c.rounded().0.to_array().map(f32::to_bits), lanes, "{c:?}");
            y *= -1.0731;
        }
        let c = Coupling(Vec4::new(f32::NAN, f32::INFINITY, -0.0, 1.0)).rounded().0;
        assert!(c.x.is_nan() && c.y == f32::INFINITY && c.z.to_bits() == (-0.0f32).to_bits() && c.w == 1.0);
    }

    /// A lane's block goes into the group's words and comes back the same, without touching
    /// the other lanes; the product's shift and mask read each component's f32.
    #[test]
    fn a_lane_block_round_trips_through_the_words() {
        let mut group = CouplingGroup::default();
        let blocks: [PackedCoupling; SLICE] = std::array::from_fn(|lane| {
            let l = lane as f32;
            Coupling(Vec4::new(-1.5 - l, 2.25 * l, 1e-30 + l, 3.0e5 / (1.0 + l))).packed()
        });
        for (lane, &b) in blocks.iter().enumerate() {
            group.set_block(lane, b);
        }
        for (lane, &b) in blocks.iter().enumerate() {
            assert_eq!(group.block(lane), b, "lane {lane}");
            let (xy, za) = (group.xy[lane], group.za[lane]);
            let read = [f32::from_bits(xy << 16), f32::from_bits(xy & 0xFFFF_0000), f32::from_bits(za << 16)];
            let alpha = f32::from_bits(za & 0xFFFF_0000);
            assert_eq!(Coupling(Vec4::new(read[0], read[1], read[2], alpha)), b.unpacked(), "lane {lane}");
        }
    }

    /// Two rows, the first with one coupling to `other` (the refusal tests' layout).
    fn one_coupling_to(other: u32) -> CouplingSlices {
        let mut slices = CouplingSlices::default();
        slices.layout(&[0, 1, 1]);
        let mut view = SliceRowsMut { offsets: &slices.offsets, groups: &mut slices.groups, first_row: 0 };
        view.set_row(0, [(Coupling::new(Vec3A::X, 1.0, 1.0), other)].into_iter());
        slices
    }

    /// Rows of unit mass (`ones`, one per row), without gas or contacts.
    fn unit_rows(ones: &[f32]) -> RowTerms<'_> {
        RowTerms {
            mass: ones,
            inv_mass: ones,
            fragment: &[],
            slice_fragment: &[],
            gradient: &[],
            gas_scale: &[],
            contact_slot: &[],
            contact_normal: &[],
        }
    }

    /// The check's maximum (eight lanes at a time with AVX2) is the plain one, whichever lane
    /// and group hold it, offsets above 2^31 included (an unsigned maximum).
    #[test]
    fn the_largest_other_end_is_found_in_any_lane() {
        let mut groups = vec![CouplingGroup::default(); 37];
        assert_eq!(largest_other_offset(&groups[..0]), 0);
        assert_eq!(largest_other_offset(&groups), 0);
        for (g, lane, value) in [(0, 0, 4u32), (36, 7, 40), (17, 3, 0x8000_0004), (5, 5, 0xFFFF_FFFC)] {
            let before = largest_other_offset(&groups);
            groups[g].other_offset[lane] = value;
            let plain = groups.iter().fold(0u32, |m, group| group.other_offset.iter().fold(m, |m, &o| m.max(o)));
            assert_eq!(largest_other_offset(&groups), plain, "group {g} lane {lane}");
            assert_eq!(plain, before.max(value));
        }
    }

    /// Couplings checked for some rows refuse an input of other rows (their other ends were
    /// checked against the rows, not against that input).
    #[test]
    #[should_panic(expected = "checked rows")]
    fn an_input_of_other_rows_than_checked_is_refused() {
        let slices = one_coupling_to(1);
        let couplings = CheckedCouplings::new(&slices.offsets, &slices.groups, 2);
        product_slices(couplings, &[Vec3A::ONE; 1], 0..1, &unit_rows(&[1.0; 1]), &mut [Vec3A::ZERO; 1]);
    }

    #[test]
    #[should_panic(expected = "not a row")]
    fn an_other_end_past_the_rows_is_refused() {
        let slices = one_coupling_to(5);
        let couplings = CheckedCouplings::new(&slices.offsets, &slices.groups, 2);
        product_slices(couplings, &[Vec3A::ONE; 2], 0..2, &unit_rows(&[1.0; 2]), &mut [Vec3A::ZERO; 2]);
    }
}
