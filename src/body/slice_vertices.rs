//! The per-vertex part of the implicit assembly (SPEC 2.2: the right side `h f + h² K v`, the
//! diagonal block `(m + Σ alpha) I + Σ w wᵀ + h² (P/V) g gᵀ` inverted, the force magnitude) for
//! the eight rows of a slice at once, from their springs' sums ([`SliceSums`]), where the rows
//! share their gas fragment (or all have none) and no external force was gathered (wind).
//!
//! Row by row this was most of the assembly once the springs' sums went eight rows at a time
//! (module doc of `spring_sums`): a 3x3 inverse with a division, the gas terms and the right side
//! in 128-bit registers per row. Here every lane of a 256-bit register is a row, with the same
//! operations in the same order as the row-by-row path [`vertex_blocks`] and
//! [`SymmetricParts::inverse`] (products and sums, no fused multiply-adds), so each row gets the
//! same bits either way (tested). On the issue-5 balloon (1 thread) the assembly went from 14.2%
//! to 12.1% of a profile of a step.
//!
//! The start of the solve then went row by row too (`start_vertex`: the obstacles' test, the
//! contact slot, the gas's `g·Δv`, the squares for the tolerance), about half of what was left.
//! For slices whose rows all move and touch no obstacle (all planes) it goes eight rows at once
//! ([`free_slice_start_avx2`]); each row's terms are then added to the sums in row order, in
//! f64, as one row at a time adds them (the same bits, tested). The assembly went from 1.16-1.27
//! to 0.99-1.02 times the residual pass's time (one-thread profiles of the drop).
//!
//! [`SymmetricParts::inverse`]: super::symmetric_block::SymmetricParts::inverse

use glam::{Vec3, Vec3A};

use super::coupling_slices::SLICE;
use super::spring_sums::{SliceSums, SpringSums};
use super::symmetric_block::SymmetricBlock;
#[cfg(target_arch = "x86_64")]
use super::symmetric_block::add_outer_lanes;

/// What every row of the system shares.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
#[derive(Clone, Copy)]
pub(crate) struct VertexConstants {
    pub h: f32,
    pub gravity: Vec3,
    /// `|g|` as `Vec3::length` gives it.
    pub gravity_length: f32,
    pub stiffness: f32,
}

/// The gas terms of a fragment in f32, as both paths use them: made once ([`GasTerms::new`]),
/// so that the rows of a slice and a row alone convert the f64 values alike.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct GasTerms {
    /// `P` (the force `g P`).
    pub pressure: f32,
    /// `max(P, 0)` (the force magnitude).
    pub pressure_bound: f32,
    /// `h² P/V` (the diagonal's `g gᵀ` term).
    pub coefficient: f32,
    /// `h² P/V Σ g·v` (the right side's `-g (h² P/V) (g·v)` term).
    pub rhs_scale: f32,
}

impl GasTerms {
    /// From the fragment's pressure `P`, its `h² P/V` and its `Σ g·v`.
    #[inline(always)]
    pub fn new(pressure: f64, coefficient: f64, gas_dot_v: f64) -> Self {
        GasTerms {
            pressure: pressure as f32,
            pressure_bound: pressure.max(0.0) as f32,
            coefficient: coefficient as f32,
            rhs_scale: (coefficient * gas_dot_v) as f32,
        }
    }
}

/// The gas fragment that the eight rows of a slice share.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
#[derive(Clone, Copy)]
pub(crate) struct SliceGas<'a> {
    /// `∂V/∂x` of the eight rows, first: the gradient from the slice's first row on (at least
    /// eight rows; with a row after them, the eight load sixteen bytes at a time).
    pub gradient: &'a [Vec3],
    pub terms: GasTerms,
}

/// The gas fragment of one row.
#[derive(Clone, Copy)]
pub(crate) struct RowGas {
    pub gradient: Vec3A,
    pub terms: GasTerms,
}

/// One row: its right side `h f + Σ rhs - g (h² P/V Σ g·v)` (before the pins), inverted
/// diagonal block `(m + Σ alpha) I + Σ w wᵀ + h² (P/V) g gᵀ` and force magnitude
/// `m |g| + K_s Σ|L - L0| + |∂V/∂x| max(P, 0)`, with the force `force` (gravity, gas pressure
/// and any external force). The diagonal block is made from the blocks as the coupling slices
/// store them (bfloat16): the matrix is then exactly that of the rounded springs (see
/// `coupling_slices`).
#[inline(always)]
pub(crate) fn vertex_blocks(
    springs: SpringSums,
    mass: f32,
    force: Vec3,
    gas: Option<RowGas>,
    constants: VertexConstants,
) -> (Vec3A, SymmetricBlock, f32) {
    let mut rhs = Vec3A::from(force) * constants.h + springs.rhs;
    let mut diag = springs.outer;
    diag.diagonal += Vec3A::splat(mass + springs.alpha);
    let mut magnitude = mass * constants.gravity_length + constants.stiffness * springs.extension;
    if let Some(gas) = gas {
        let g = gas.gradient;
        diag.add_outer(g, gas.terms.coefficient);
        magnitude += g.length() * gas.terms.pressure_bound;
        // -h² (P/V) g (g·v)
        rhs -= g * gas.terms.rhs_scale;
    }
    (rhs, diag.inverse(), magnitude)
}

/// The eight rows of `sums` with masses `mass` (eight): for each, what [`vertex_blocks`] gives
/// it with the force `g m (+ ∂V/∂x P)`: the right sides (before the pins) into `rhs` and the
/// inverted diagonal blocks into `inv_diag` (the assembly's rows: eight each; written there
/// directly, where a struct of the eight rows was copied there by the assembly, about 0.6% of
/// a one-thread step on the issue-5 balloon), and the force magnitudes returned.
///
/// # Safety
/// The processor must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn slice_vertices_avx2(
    sums: &SliceSums,
    mass: &[f32],
    constants: VertexConstants,
    gas: Option<SliceGas>,
    rhs: &mut [Vec3A],
    inv_diag: &mut [SymmetricBlock],
) -> [f32; SLICE] {
    use std::arch::x86_64::*;
    assert!(mass.len() == SLICE && rhs.len() == SLICE && inv_diag.len() == SLICE);
    let VertexConstants { h, gravity, gravity_length, stiffness } = constants;
    // (Intrinsics written out: one in a closure does not inherit the target feature and becomes
    // a call.)
    // SAFETY (every unaligned load below): eight f32 of an array of eight, or of `mass` (its
    // length asserted above).
    macro_rules! load {
        ($a:expr) => {
            unsafe { _mm256_loadu_ps($a.as_ptr()) }
        };
    }
    let m = load!(mass);
    // f = g m (+ ∂V/∂x P), as `Vec3` products per axis.
    let mut fx = _mm256_mul_ps(_mm256_set1_ps(gravity.x), m);
    let mut fy = _mm256_mul_ps(_mm256_set1_ps(gravity.y), m);
    let mut fz = _mm256_mul_ps(_mm256_set1_ps(gravity.z), m);
    // `(m |g|) + (K_s Σ|L - L0|)`.
    let mut magnitude = _mm256_add_ps(
        _mm256_mul_ps(m, _mm256_set1_ps(gravity_length)),
        _mm256_mul_ps(_mm256_set1_ps(stiffness), load!(sums.extension)),
    );
    // The diagonal block: `Σ w wᵀ`, then `(m + Σ alpha)` on its diagonal.
    let diagonal_add = _mm256_add_ps(m, load!(sums.alpha));
    // xx, yy, zz, xy, yz, zx.
    let mut block = [
        _mm256_add_ps(load!(sums.diagonal[0]), diagonal_add),
        _mm256_add_ps(load!(sums.diagonal[1]), diagonal_add),
        _mm256_add_ps(load!(sums.diagonal[2]), diagonal_add),
        load!(sums.off[0]),
        load!(sums.off[1]),
        load!(sums.off[2]),
    ];
    // `h f + Σ rhs`.
    let hh = _mm256_set1_ps(h);
    let (rx, ry, rz);
    if let Some(gas) = gas {
        assert!(gas.gradient.len() >= SLICE);
        // SAFETY: the first eight points of the gradient (asserted above).
        let (gx, gy, gz) = unsafe { super::coupling_slices::load_points_transposed(gas.gradient, 0) };
        let pressure = _mm256_set1_ps(gas.terms.pressure);
        fx = _mm256_add_ps(fx, _mm256_mul_ps(gx, pressure));
        fy = _mm256_add_ps(fy, _mm256_mul_ps(gy, pressure));
        fz = _mm256_add_ps(fz, _mm256_mul_ps(gz, pressure));
        // `add_outer(g, h² P/V)`: `sa = g s`, then `sa g` and `sa g.yzx`.
        let s = _mm256_set1_ps(gas.terms.coefficient);
        let scaled = [_mm256_mul_ps(gx, s), _mm256_mul_ps(gy, s), _mm256_mul_ps(gz, s)];
        add_outer_lanes(&mut block, scaled, [gx, gy, gz]);
        // `|g|` as `Vec3A::length` gives it: `√((x x + y y) + z z)` (a square root is rounded
        // exactly, eight lanes or one; one row at a time, with its own dot product and square
        // root, these lengths were the largest share of this kernel).
        let lengths = _mm256_sqrt_ps(_mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(gx, gx), _mm256_mul_ps(gy, gy)),
            _mm256_mul_ps(gz, gz),
        ));
        magnitude = _mm256_add_ps(magnitude, _mm256_mul_ps(lengths, _mm256_set1_ps(gas.terms.pressure_bound)));
        // Less `g (h² P/V Σ g·v)`.
        let k = _mm256_set1_ps(gas.terms.rhs_scale);
        rx = _mm256_sub_ps(_mm256_add_ps(_mm256_mul_ps(fx, hh), load!(sums.rhs[0])), _mm256_mul_ps(gx, k));
        ry = _mm256_sub_ps(_mm256_add_ps(_mm256_mul_ps(fy, hh), load!(sums.rhs[1])), _mm256_mul_ps(gy, k));
        rz = _mm256_sub_ps(_mm256_add_ps(_mm256_mul_ps(fz, hh), load!(sums.rhs[2])), _mm256_mul_ps(gz, k));
    } else {
        rx = _mm256_add_ps(_mm256_mul_ps(fx, hh), load!(sums.rhs[0]));
        ry = _mm256_add_ps(_mm256_mul_ps(fy, hh), load!(sums.rhs[1]));
        rz = _mm256_add_ps(_mm256_mul_ps(fz, hh), load!(sums.rhs[2]));
    }
    // The inverse by cofactors (as `SymmetricParts::inverse`).
    let [dxx, dyy, dzz, dxy, dyz, dzx] = block;
    let cxx = _mm256_sub_ps(_mm256_mul_ps(dyy, dzz), _mm256_mul_ps(dyz, dyz));
    let cyy = _mm256_sub_ps(_mm256_mul_ps(dxx, dzz), _mm256_mul_ps(dzx, dzx));
    let czz = _mm256_sub_ps(_mm256_mul_ps(dxx, dyy), _mm256_mul_ps(dxy, dxy));
    let cxy = _mm256_sub_ps(_mm256_mul_ps(dzx, dyz), _mm256_mul_ps(dxy, dzz));
    let cyz = _mm256_sub_ps(_mm256_mul_ps(dxy, dzx), _mm256_mul_ps(dyz, dxx));
    let czx = _mm256_sub_ps(_mm256_mul_ps(dxy, dyz), _mm256_mul_ps(dzx, dyy));
    let det = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dxx, cxx), _mm256_mul_ps(dxy, cxy)), _mm256_mul_ps(dzx, czx));
    let sign = _mm256_set1_ps(-0.0);
    let scale = _mm256_add_ps(
        _mm256_add_ps(_mm256_andnot_ps(sign, dxx), _mm256_andnot_ps(sign, dyy)),
        _mm256_andnot_ps(sign, dzz),
    );
    let threshold = _mm256_mul_ps(_mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(1e-12), scale), scale), scale);
    // `det.is_finite() && det > threshold` (false for a NaN either way).
    let finite = _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_andnot_ps(sign, det), _mm256_set1_ps(f32::INFINITY));
    let regular = _mm256_and_ps(finite, _mm256_cmp_ps::<_CMP_GT_OQ>(det, threshold));
    let one = _mm256_set1_ps(1.0);
    let inv = _mm256_div_ps(one, det);
    // The singular rows: the inverse of the diagonal (`max` with the floor second, as glam's).
    let floor = _mm256_set1_ps(f32::MIN_POSITIVE);
    let zero = _mm256_setzero_ps();
    let entries = [
        (_mm256_mul_ps(cxx, inv), _mm256_div_ps(one, _mm256_max_ps(dxx, floor))),
        (_mm256_mul_ps(cyy, inv), _mm256_div_ps(one, _mm256_max_ps(dyy, floor))),
        (_mm256_mul_ps(czz, inv), _mm256_div_ps(one, _mm256_max_ps(dzz, floor))),
        (_mm256_mul_ps(cxy, inv), zero),
        (_mm256_mul_ps(cyz, inv), zero),
        (_mm256_mul_ps(czx, inv), zero),
    ];
    let mut columns = [[0f32; SLICE]; 6];
    for (column, (regular_entry, singular_entry)) in columns.iter_mut().zip(entries) {
        // SAFETY: eight f32.
        unsafe { _mm256_storeu_ps(column.as_mut_ptr(), _mm256_blendv_ps(singular_entry, regular_entry, regular)) };
    }
    let mut magnitudes = [0f32; SLICE];
    // SAFETY: eight f32.
    unsafe { _mm256_storeu_ps(magnitudes.as_mut_ptr(), magnitude) };
    for (lane, block) in inv_diag.iter_mut().enumerate() {
        *block = SymmetricBlock::from_entries(columns.map(|c| c[lane]));
    }
    // SAFETY: AVX2 (this function's contract); eight rows (asserted above).
    unsafe { super::coupling_slices::store_rows_transposed(rhs, rx, ry, rz) };
    magnitudes
}

/// What the start of the solve adds up over the eight rows of a slice that all move and touch
/// nothing ([`free_slice_start_avx2`]), per row as the row-by-row assembly computes each term:
/// the caller adds them in row order, in f64, as that assembly does.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(crate) struct FreeSliceStart {
    /// `magnitude²` (of f64s).
    pub magnitude_squared: [f64; SLICE],
    /// `|rhs|²` (`Vec3A::length_squared`, then f64).
    pub rhs_squared: [f64; SLICE],
    /// `g·Δv` (`Vec3A::dot` of the gradient and the warm start, then f64; zero without `gradient`).
    pub gas_dot: [f64; SLICE],
}

/// The start of the solve for the eight rows `first..first + 8` of a slice, from their right
/// sides `rhs` and force magnitudes (`slice_vertices_avx2`'s), when none of them touches a plane of `planes` (the obstacles as
/// `slice_update::planes_of` gives them): then each one's Δv is its warm start `dv` and it is
/// free (what the assembly's `start_vertex` gives a moving row that touches nothing), and this
/// returns the sums' terms. None when a row is within `margin` of a plane or behind it
/// (`obstacles::touching`'s test `distance <= margin`, which a NaN distance fails: such a row is
/// free either way). The caller checks that the rows move (a pinned row starts at rest).
///
/// `gradient` (the gas gradient of all rows, or empty without gas), `x` (all positions): read
/// at rows `first..first + 8`; `dv`: the eight rows' warm start.
///
/// # Safety
/// The processor must have AVX2 and FMA; `first + 8` rows must be in `x`, and in `gradient` when
/// it is not empty.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn free_slice_start_avx2(
    (rhs, magnitude): (&[Vec3A], &[f32; SLICE]),
    x: &[Vec3],
    gradient: &[Vec3],
    dv: &[Vec3A],
    first: usize,
    planes: &[(Vec3, Vec3)],
    margin: f32,
) -> Option<FreeSliceStart> {
    use super::coupling_slices::{load_points_transposed, load_rows_transposed};
    use std::arch::x86_64::*;
    assert!(rhs.len() == SLICE && dv.len() == SLICE);
    assert!(first + SLICE <= x.len() && (gradient.is_empty() || first + SLICE <= gradient.len()));
    if !planes.is_empty() {
        // SAFETY: rows first..first + 8 of `x` (asserted above).
        let (px, py, pz) = unsafe { load_points_transposed(x, first) };
        let margin = _mm256_set1_ps(margin);
        for &(point, normal) in planes {
            let distance = super::slice_update::plane_distances((px, py, pz), point, normal);
            if _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(distance, margin)) != 0 {
                return None;
            }
        }
    }
    // Squares and dots in f32 as `Vec3A::dot` sums them (`(x x' + y y') + z z'`), then f64.
    // (Macros, not closures: an intrinsic in a closure does not inherit the target feature.)
    macro_rules! dot {
        (($ax:expr, $ay:expr, $az:expr), ($bx:expr, $by:expr, $bz:expr)) => {
            _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps($ax, $bx), _mm256_mul_ps($ay, $by)), _mm256_mul_ps($az, $bz))
        };
    }
    macro_rules! widen {
        ($v:expr) => {{
            let v = $v;
            let mut out = [0f64; SLICE];
            // SAFETY: four f64 into each half of the array.
            unsafe {
                _mm256_storeu_pd(out.as_mut_ptr(), _mm256_cvtps_pd(_mm256_castps256_ps128(v)));
                _mm256_storeu_pd(out.as_mut_ptr().add(4), _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(v)));
            }
            out
        }};
    }
    // SAFETY: eight rows of the local array and of `dv` (asserted above).
    let ((rx, ry, rz), (dx, dy, dz)) = unsafe { (load_rows_transposed(rhs, 0), load_rows_transposed(dv, 0)) };
    let rhs_squared = widen!(dot!((rx, ry, rz), (rx, ry, rz)));
    let gas_dot = if gradient.is_empty() {
        [0.0; SLICE]
    } else {
        // SAFETY: rows first..first + 8 of `gradient` (asserted above).
        let (gx, gy, gz) = unsafe { load_points_transposed(gradient, first) };
        widen!(dot!((gx, gy, gz), (dx, dy, dz)))
    };
    // `(m as f64) * (m as f64)`.
    // SAFETY: eight f32.
    let mut magnitude_squared = widen!(unsafe { _mm256_loadu_ps(magnitude.as_ptr()) });
    for m in &mut magnitude_squared {
        *m *= *m;
    }
    Some(FreeSliceStart { magnitude_squared, rhs_squared, gas_dot })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::obstacles::{Obstacle, touching};
    use crate::body::symmetric_block::SymmetricParts;

    /// The start of a free slice: None exactly where a row touches a plane as
    /// `obstacles::touching` sees it (within the margin, behind, or at a NaN distance), and
    /// otherwise each row's terms as the row-by-row assembly computes them, to the bit.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn a_free_slice_starts_as_its_rows_one_at_a_time() {
        if !(std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")) {
            return;
        }
        let mut unit = crate::body::test_randoms(0x5eed_0f5a_11ce_57a7);
        let margin = 1e-6;
        // 48 rows (six slices, the last one read without a row after it): slice 1 has a row
        // exactly at the margin above the ground, slice 2 one on it, slice 3 a NaN position
        // (free: its distance is not within the margin), slice 4 a row just above the margin
        // (free).
        let n = 48;
        let mut x: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), 0.2 + unit().abs(), unit())).collect();
        x[11].y = margin;
        x[18].y = 0.0;
        x[29].z = f32::NAN;
        x[36].y = 2.0 * margin;
        let gradient: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), unit(), unit())).collect();
        let dv: Vec<Vec3A> = (0..n).map(|_| Vec3A::new(unit(), unit(), unit())).collect();
        let ground = (Vec3::ZERO, Vec3::Y);
        let tilted = (Vec3::new(0.0, -0.5, 0.0), Vec3::new(0.6, 0.8, 0.0));
        for planes in [vec![], vec![ground], vec![tilted, ground]] {
            let obstacles: Vec<Obstacle> =
                planes.iter().map(|&(point, normal)| Obstacle::Plane { point, normal }).collect();
            for with_gas in [false, true] {
                let gradient = if with_gas { &gradient[..] } else { &[][..] };
                let mut free_slices = 0;
                for first in (0..n).step_by(SLICE) {
                    let rows = first..first + SLICE;
                    let rhs: [Vec3A; SLICE] = std::array::from_fn(|_| Vec3A::new(unit(), unit(), unit()) * 3.0);
                    let magnitudes: [f32; SLICE] = std::array::from_fn(|_| unit().abs() * 40.0);
                    // SAFETY: AVX2 and FMA (checked above); the rows are in x and the gradient.
                    let got = unsafe {
                        free_slice_start_avx2(
                            (&rhs, &magnitudes),
                            &x,
                            gradient,
                            &dv[rows.clone()],
                            first,
                            &planes,
                            margin,
                        )
                    };
                    let touches = rows.clone().any(|i| touching(x[i], &obstacles, margin).is_some());
                    assert_eq!(got.is_none(), touches, "slice at {first} with {} planes", planes.len());
                    let Some(got) = got else { continue };
                    free_slices += 1;
                    for (lane, i) in rows.enumerate() {
                        let magnitude = magnitudes[lane];
                        let gas_dot = if with_gas { Vec3A::from(gradient[i]).dot(dv[i]) as f64 } else { 0.0 };
                        let want =
                            [(magnitude as f64) * (magnitude as f64), rhs[lane].length_squared() as f64, gas_dot];
                        let got = [got.magnitude_squared[lane], got.rhs_squared[lane], got.gas_dot[lane]];
                        assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits), "row {i}");
                    }
                }
                // Without planes every slice is free; on the ground all but slices 1 and 2 (the
                // tilted plane cuts through some of the others).
                let expected = [6, 4, 2][planes.len()];
                assert!(
                    free_slices >= expected && free_slices <= 6 - planes.len().min(1) * 2,
                    "{} planes",
                    planes.len()
                );
            }
        }
    }

    /// Each lane of the eight-row version is the row-by-row version, bit for bit: with and
    /// without gas (of positive and negative pressure), for positive definite blocks and for
    /// blocks that take the inverse's fallback (the inverse of the diagonal): a massless row with
    /// no springs (singular), a negative determinant, one that overflows to infinity, and a NaN
    /// on the diagonal.
    #[test]
    fn eight_rows_at_once_are_the_rows_one_at_a_time() {
        #[cfg(target_arch = "x86_64")]
        if !(std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")) {
            return;
        }
        let mut unit = crate::body::test_randoms(0x51ce_0f7e_471c_e5a3);
        let constants = VertexConstants {
            h: 1.0 / 60.0,
            gravity: Vec3::new(0.1, -9.81, 0.2),
            gravity_length: Vec3::new(0.1, -9.81, 0.2).length(),
            stiffness: 3.0e3,
        };
        let fallback = [3, 5, 6, 7];
        for round in 0..40 {
            let mut lanes = [SpringSums::default(); SLICE];
            let mut mass = [0f32; SLICE];
            for (lane, sums) in lanes.iter_mut().enumerate() {
                mass[lane] = 0.01 + unit().abs();
                sums.rhs = Vec3A::new(unit(), unit(), unit());
                sums.extension = unit().abs() * 1e-2;
                sums.alpha = unit().abs() * 50.0;
                sums.outer = SymmetricParts::default();
                for _ in 0..6 {
                    sums.outer.add_outer(Vec3A::new(unit(), unit(), unit()) * 8.0, 1.0);
                }
            }
            lanes[3] = SpringSums::default();
            mass[3] = 0.0;
            lanes[5].outer.off = Vec3A::splat(-1e4);
            lanes[6].outer.diagonal = Vec3A::splat(1e14);
            lanes[7].outer.diagonal.y = f32::NAN;
            let mut sums = SliceSums::default();
            for (lane, s) in lanes.iter().enumerate() {
                for axis in 0..3 {
                    sums.rhs[axis][lane] = s.rhs[axis];
                    sums.diagonal[axis][lane] = s.outer.diagonal[axis];
                    sums.off[axis][lane] = s.outer.off[axis];
                }
                sums.extension[lane] = s.extension;
                sums.alpha[lane] = s.alpha;
            }
            // (With a row after the eight in rounds 1, 5, 9, ...: the gradient's 16-byte loads.)
            let gradient: Vec<Vec3> = (0..SLICE + 1).map(|_| Vec3::new(unit(), unit(), unit()) * 0.1).collect();
            let gradient = if round % 4 == 1 { &gradient[..] } else { &gradient[..SLICE] };
            let terms = GasTerms::new(2.5e3 * unit() as f64, 0.4 * unit().abs() as f64, unit() as f64);
            let gas = (round % 2 == 1).then_some(SliceGas { gradient, terms });
            #[cfg(target_arch = "x86_64")]
            let (mut got_rhs, mut got_inv_diag) = ([Vec3A::NAN; SLICE], [SymmetricBlock::default(); SLICE]);
            #[cfg(target_arch = "x86_64")]
            // SAFETY: the processor has AVX2 and FMA (checked above).
            let got_magnitude =
                unsafe { slice_vertices_avx2(&sums, &mass, constants, gas, &mut got_rhs, &mut got_inv_diag) };
            for lane in 0..SLICE {
                let mut force = constants.gravity * mass[lane];
                let row_gas = gas.map(|g| {
                    force += g.gradient[lane] * g.terms.pressure;
                    RowGas { gradient: Vec3A::from(g.gradient[lane]), terms: g.terms }
                });
                let (rhs, inv_diag, magnitude) = vertex_blocks(lanes[lane], mass[lane], force, row_gas, constants);
                #[cfg(target_arch = "x86_64")]
                {
                    let bits = |v: Vec3A| v.to_array().map(f32::to_bits);
                    assert_eq!(bits(got_rhs[lane]), bits(rhs), "round {round} lane {lane}");
                    let entries = |b: SymmetricBlock| {
                        let p = b.parts();
                        [bits(p.diagonal), bits(p.off)]
                    };
                    assert_eq!(entries(got_inv_diag[lane]), entries(inv_diag), "round {round} lane {lane}");
                    assert_eq!(got_magnitude[lane].to_bits(), magnitude.to_bits(), "round {round} lane {lane}");
                }
                if gas.is_none() {
                    // Without gas the special lanes take the fallback (the inverse of the
                    // diagonal: no off-diagonal part, finite), the others the cofactors.
                    let parts = inv_diag.parts();
                    let took_fallback = parts.off == Vec3A::ZERO;
                    assert_eq!(took_fallback, fallback.contains(&lane), "round {round} lane {lane}: {parts:?}");
                    assert!(!took_fallback || parts.diagonal.is_finite(), "round {round} lane {lane}: {parts:?}");
                }
            }
        }
    }
}
