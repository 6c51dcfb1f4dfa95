//! The update pass of each conjugate-gradient iteration of the implicit integrator, over a chunk
//! of rows: `Δv += α p`, `r -= α A p`, `z = M⁻¹ r` (block Jacobi, filtered by the contacts) and
//! the sums `r·r` and `r·z`; and the first residual of a solve ([`initial_rows`]).
//!
//! With AVX2 two rows share each 256-bit register for the vector updates and the sums (the
//! vectors are `Vec3A`, four f32 a row), and each row's `z` is its block times `r` in SSE. One
//! row at a time this pass took about 54 instructions a row (callgrind, issue-5 balloon), once
//! per iteration.
//!
//! Measured and not kept: `Δv += α p` moved into the direction pass that follows (which reads p
//! anyway; the last step after the loop), so that this pass reads neither Δv nor p (16 bytes a
//! row fewer per iteration): the drop on two threads (per step the fastest of five
//! alternating runs, then the mean) 2.064 against 2.060 ms, no gain to be told from the noise.
//! Made with a plain multiply and add instead of this pass's fused one, the same change took the
//! drop's 600 steps from 4,994 to 5,244 CG iterations: a contact step's solve is that sensitive
//! to the last bit of its start.

use glam::Vec3A;

use super::implicit::ContactRows;
use super::symmetric_block::SymmetricBlock;

/// The pass on the rows `first..first + dv.len()` (`dv`, `r`, `z` and `ap` hold the chunk's
/// rows; `p` and `inv_diag` all rows; `contact` all rows or empty); returns the chunk's
/// `(r·r, r·z)` in f64. With `any_contact` false the contacts are not read.
#[allow(clippy::too_many_arguments)]
pub(crate) fn residual_rows(
    first: usize,
    (dv, r, z): (&mut [Vec3A], &mut [Vec3A], &mut [Vec3A]),
    p: &[Vec3A],
    ap: &[Vec3A],
    inv_diag: &[SymmetricBlock],
    contact: ContactRows,
    alpha: f32,
    any_contact: bool,
) -> (f64, f64) {
    // The chunk's rows, sliced once (no bounds check per vertex).
    let n = dv.len();
    let rows = first..first + n;
    let (p, inv_diag) = (&p[rows.clone()], &inv_diag[rows.clone()]);
    let contact = if any_contact { contact.rows(rows) } else { ContactRows::default() };
    assert!(r.len() == n && z.len() == n && ap.len() == n);
    assert!(contact.is_empty() || contact.slot.len() == n);
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the processor has the features the function is compiled for (checked above).
        return unsafe { residual_rows_avx2((dv, r, z), p, ap, inv_diag, contact, alpha) };
    }
    let (mut rr, mut rz) = (0.0f64, 0.0f64);
    for k in 0..n {
        let (ri, zi) = residual_row(k, (dv, r, z), p, ap, inv_diag, contact, alpha);
        rr += ri.length_squared() as f64;
        rz += ri.dot(zi) as f64;
    }
    (rr, rz)
}

/// The pass on row `k` (every slice holds the chunk's rows); returns the row's `r` and `z`.
#[inline(always)]
fn residual_row(
    k: usize,
    (dv, r, z): (&mut [Vec3A], &mut [Vec3A], &mut [Vec3A]),
    p: &[Vec3A],
    ap: &[Vec3A],
    inv_diag: &[SymmetricBlock],
    contact: ContactRows,
    alpha: f32,
) -> (Vec3A, Vec3A) {
    dv[k] += p[k] * alpha;
    let ri = r[k] - ap[k] * alpha;
    let mut zi = inv_diag[k].apply(ri);
    if !contact.is_empty() {
        zi = contact.apply(k, zi);
    }
    r[k] = ri;
    z[k] = zi;
    (ri, zi)
}

/// [`residual_rows`] with AVX2 and FMA, on the chunk's rows (every slice holds exactly them,
/// `contact` too or is empty). The sums take each row's products in f64, the rows of even and
/// of odd index apart, added at the end: the result depends only on the chunk's rows.
///
/// Both rows' blocks apply in one register ([`SymmetricBlock::apply_pair`], the same bits as
/// one row at a time), and the contacts are looked at only where a row touches: on the issue-5
/// balloon (one thread, two profiles each way) this pass went from 0.41-0.50 to 0.353-0.355 of
/// the product's time, with the same CG iterations step for step.
///
/// Measured and not kept: the products summed in f32 over eight pairs of rows before each f64
/// addition (no conversions per row): 0.42 -> 0.35 of the product's time (three profiles each
/// way, one thread), but the other rounding took ten drops from 8.59 to 8.65 CG iterations a
/// step and the drop from 5,182 to 5,306 over its 600 steps, about what the pass saves.
///
/// # Safety
/// The processor must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn residual_rows_avx2(
    (dv, r, z): (&mut [Vec3A], &mut [Vec3A], &mut [Vec3A]),
    p: &[Vec3A],
    ap: &[Vec3A],
    inv_diag: &[SymmetricBlock],
    contact: ContactRows,
    alpha: f32,
) -> (f64, f64) {
    use std::arch::x86_64::*;
    let n = dv.len();
    assert!(r.len() == n && z.len() == n && ap.len() == n && p.len() == n && inv_diag.len() == n);
    let a = _mm256_set1_ps(alpha);
    // The fourth lane of each row is not part of the vector: cleared in r, so that r·r and
    // r·z see three lanes (z's is cleared by the block's product).
    let xyz = _mm256_castsi256_ps(_mm256_setr_epi32(-1, -1, -1, 0, -1, -1, -1, 0));
    let (mut rr_even, mut rr_odd, mut rz_even, mut rz_odd) =
        (_mm256_setzero_pd(), _mm256_setzero_pd(), _mm256_setzero_pd(), _mm256_setzero_pd());
    let (dvp, rp, zp) = (dv.as_mut_ptr() as *mut f32, r.as_mut_ptr() as *mut f32, z.as_mut_ptr() as *mut f32);
    let (pp, app) = (p.as_ptr() as *const f32, ap.as_ptr() as *const f32);
    for k in (0..n & !1).step_by(2) {
        // SAFETY: rows k and k + 1 < n of each slice (eight f32), unaligned 32-byte accesses.
        let (ri, zi) = unsafe {
            let at = 4 * k;
            _mm256_storeu_ps(
                dvp.add(at),
                _mm256_fmadd_ps(_mm256_loadu_ps(pp.add(at)), a, _mm256_loadu_ps(dvp.add(at))),
            );
            let ri = _mm256_and_ps(_mm256_fnmadd_ps(_mm256_loadu_ps(app.add(at)), a, _mm256_loadu_ps(rp.add(at))), xyz);
            _mm256_storeu_ps(rp.add(at), ri);
            let pair: &[SymmetricBlock; 2] = inv_diag[k..k + 2].try_into().expect("two rows");
            let mut zi = SymmetricBlock::apply_pair(pair, ri);
            if !contact.is_empty() && (contact.slot[k] != u32::MAX || contact.slot[k + 1] != u32::MAX) {
                let (z0, z1) = (Vec3A::from(_mm256_castps256_ps128(zi)), Vec3A::from(_mm256_extractf128_ps::<1>(zi)));
                zi = _mm256_set_m128(contact.apply(k + 1, z1).into(), contact.apply(k, z0).into());
            }
            _mm256_storeu_ps(zp.add(at), zi);
            (ri, zi)
        };
        let (r_even, r_odd) =
            (_mm256_cvtps_pd(_mm256_castps256_ps128(ri)), _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(ri)));
        let (z_even, z_odd) =
            (_mm256_cvtps_pd(_mm256_castps256_ps128(zi)), _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(zi)));
        rr_even = _mm256_fmadd_pd(r_even, r_even, rr_even);
        rr_odd = _mm256_fmadd_pd(r_odd, r_odd, rr_odd);
        rz_even = _mm256_fmadd_pd(r_even, z_even, rz_even);
        rz_odd = _mm256_fmadd_pd(r_odd, z_odd, rz_odd);
    }
    let mut sums = [[0.0f64; 4]; 4];
    // SAFETY: four f64 into each array.
    unsafe {
        _mm256_storeu_pd(sums[0].as_mut_ptr(), rr_even);
        _mm256_storeu_pd(sums[1].as_mut_ptr(), rr_odd);
        _mm256_storeu_pd(sums[2].as_mut_ptr(), rz_even);
        _mm256_storeu_pd(sums[3].as_mut_ptr(), rz_odd);
    }
    let lanes = |s: [f64; 4]| (s[0] + s[1]) + (s[2] + s[3]);
    let (mut rr, mut rz) = (lanes(sums[0]) + lanes(sums[1]), lanes(sums[2]) + lanes(sums[3]));
    if n % 2 == 1 {
        let (ri, zi) = residual_row(n - 1, (dv, r, z), p, ap, inv_diag, contact, alpha);
        rr += ri.length_squared() as f64;
        rz += ri.dot(zi) as f64;
    }
    (rr, rz)
}

/// The first residual of a solve on rows `first..first + r.len()` of a chunk: `r = rhs - A Δv`
/// (`ap` holds the chunk's rows of `A Δv`; `rhs` and `inv_diag` all rows), `z = M⁻¹ r`, both
/// filtered by the contacts (all rows or empty; not read without `any_contact`); returns the
/// chunk's `r·z`, each row's f32 dot product (as `Vec3A::dot` sums it) added in f64 in row
/// order.
#[allow(clippy::too_many_arguments)]
pub(crate) fn initial_rows(
    first: usize,
    (r, z): (&mut [Vec3A], &mut [Vec3A]),
    rhs: &[Vec3A],
    ap: &[Vec3A],
    inv_diag: &[SymmetricBlock],
    contact: ContactRows,
    any_contact: bool,
) -> f64 {
    // The chunk's rows of every array, sliced once (no bounds check per row).
    let n = r.len();
    let rows = first..first + n;
    let (rhs, inv_diag, ap, z) = (&rhs[rows.clone()], &inv_diag[rows.clone()], &ap[..n], &mut z[..n]);
    let contact = if any_contact { contact.rows(rows) } else { ContactRows::default() };
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2 (checked just above); the slices hold the chunk's rows.
        return unsafe { initial_rows_avx2((r, z), rhs, ap, inv_diag, contact) };
    }
    let mut rz = 0.0f64;
    for k in 0..n {
        rz += initial_row(k, (r, z), rhs, ap, inv_diag, contact) as f64;
    }
    rz
}

/// Row k of [`initial_rows`] (every slice indexed from the chunk's first row); returns its
/// `r·z` in f32.
#[inline(always)]
fn initial_row(
    k: usize,
    (r, z): (&mut [Vec3A], &mut [Vec3A]),
    rhs: &[Vec3A],
    ap: &[Vec3A],
    inv_diag: &[SymmetricBlock],
    contact: ContactRows,
) -> f32 {
    let mut ri = rhs[k] - ap[k];
    let mut zi = inv_diag[k].apply(ri);
    if !contact.is_empty() {
        ri = contact.apply(k, ri);
        zi = contact.apply(k, zi);
    }
    r[k] = ri;
    z[k] = zi;
    ri.dot(zi)
}

/// [`initial_rows`] with AVX2, two rows to a register (the same bits: the blocks by
/// [`SymmetricBlock::apply_pair`], each row's dot product summed as `Vec3A::dot` sums it, the
/// contacts row by row where a row touches). One row at a time this pass took about 30 cycles
/// a row, once per substep.
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn initial_rows_avx2(
    (r, z): (&mut [Vec3A], &mut [Vec3A]),
    rhs: &[Vec3A],
    ap: &[Vec3A],
    inv_diag: &[SymmetricBlock],
    contact: ContactRows,
) -> f64 {
    use std::arch::x86_64::*;
    let n = r.len();
    assert!(z.len() == n && rhs.len() == n && ap.len() == n && inv_diag.len() == n);
    assert!(contact.is_empty() || contact.slot.len() == n);
    let mut rz = 0.0f64;
    let (rhsp, app) = (rhs.as_ptr() as *const f32, ap.as_ptr() as *const f32);
    for k in (0..n & !1).step_by(2) {
        let touches = !contact.is_empty() && (contact.slot[k] != u32::MAX || contact.slot[k + 1] != u32::MAX);
        if touches {
            rz += initial_row(k, (r, z), rhs, ap, inv_diag, contact) as f64;
            rz += initial_row(k + 1, (r, z), rhs, ap, inv_diag, contact) as f64;
            continue;
        }
        // (Taken here, after any row written through the slices: a pointer taken before them
        // would not be valid after those writes.)
        let (rp, zp) = (r.as_mut_ptr() as *mut f32, z.as_mut_ptr() as *mut f32);
        // SAFETY: rows k and k + 1 < n of each slice (eight f32), unaligned 32-byte accesses.
        let dots = unsafe {
            let at = 4 * k;
            let ri = _mm256_sub_ps(_mm256_loadu_ps(rhsp.add(at)), _mm256_loadu_ps(app.add(at)));
            let pair: &[SymmetricBlock; 2] = inv_diag[k..k + 2].try_into().expect("two rows");
            let zi = SymmetricBlock::apply_pair(pair, ri);
            _mm256_storeu_ps(rp.add(at), ri);
            _mm256_storeu_ps(zp.add(at), zi);
            // Each row's (x + y) + z of the products in its first lane, as `Vec3A::dot`.
            let m = _mm256_mul_ps(ri, zi);
            _mm256_add_ps(_mm256_add_ps(m, _mm256_permute_ps::<0b01>(m)), _mm256_permute_ps::<0b10>(m))
        };
        rz += _mm256_cvtss_f32(dots) as f64;
        rz += _mm_cvtss_f32(_mm256_extractf128_ps::<1>(dots)) as f64;
    }
    if n % 2 == 1 {
        rz += initial_row(n - 1, (r, z), rhs, ap, inv_diag, contact) as f64;
    }
    rz
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::symmetric_block::SymmetricParts;

    /// `count` random positive definite blocks (inverted), the tests' preconditioner.
    fn random_blocks(unit: &mut impl FnMut() -> f32, count: usize) -> Vec<SymmetricBlock> {
        (0..count)
            .map(|_| {
                let mut parts = SymmetricParts { diagonal: Vec3A::splat(2.0), off: Vec3A::ZERO };
                parts.add_outer(Vec3A::new(unit(), unit(), unit()), 1.5);
                parts.inverse()
            })
            .collect()
    }

    /// Random rows (an odd count, some in contact, garbage in the fourth lanes): the pass gives
    /// each row's update by its definition, and sums r·r and r·z in f64 up to rounding.
    #[test]
    fn the_pass_is_the_update_row_by_row() {
        let mut unit = crate::body::test_randoms(0x7a3c_91e5_0b2d_4f68);
        let n = 37;
        let first = 5;
        let total = first + n;
        let vector = |unit: &mut dyn FnMut() -> f32| {
            (0..total).map(|_| Vec3A::from_vec4(glam::Vec4::new(unit(), unit(), unit(), 1e30))).collect::<Vec<_>>()
        };
        let p = vector(&mut unit);
        let inv_diag = random_blocks(&mut unit, total);
        let normals = [Vec3A::Z, Vec3A::new(0.0, 0.6, 0.8)];
        let slot: Vec<u32> = (0..total).map(|i| if i % 5 == 1 { (i % 2) as u32 } else { u32::MAX }).collect();
        let alpha = 0.73;
        for any_contact in [false, true] {
            let rows = |v: &[Vec3A]| v[first..].to_vec();
            let (dv0, r0, ap) = (rows(&vector(&mut unit)), rows(&vector(&mut unit)), rows(&vector(&mut unit)));
            let (mut dv, mut r, mut z) = (dv0.clone(), r0.clone(), vec![Vec3A::splat(f32::NAN); n]);
            let contact = ContactRows { slot: &slot, normal: &normals };
            let (rr, rz) =
                residual_rows(first, (&mut dv, &mut r, &mut z), &p, &ap, &inv_diag, contact, alpha, any_contact);
            let (mut want_rr, mut want_rz) = (0.0f64, 0.0f64);
            for k in 0..n {
                let i = first + k;
                let want_dv = dv0[k] + p[i] * alpha;
                let want_r = r0[k] - ap[k] * alpha;
                let mut want_z = inv_diag[i].apply(want_r);
                if any_contact && slot[i] != u32::MAX {
                    let normal = normals[slot[i] as usize];
                    want_z -= normal * want_z.dot(normal);
                }
                assert!((dv[k] - want_dv).length() <= 1e-6 * (1.0 + want_dv.length()), "Δv {k}");
                assert!((r[k] - want_r).length() <= 1e-6 * (1.0 + want_r.length()), "r {k}");
                assert!((z[k] - want_z).length() <= 1e-6 * (1.0 + want_z.length()), "z {k}: {} vs {want_z}", z[k]);
                want_rr += want_r.length_squared() as f64;
                want_rz += want_r.dot(want_z) as f64;
            }
            assert!((rr - want_rr).abs() <= 1e-5 * want_rr, "{rr} vs {want_rr}");
            assert!((rz - want_rz).abs() <= 1e-5 * want_rr, "{rz} vs {want_rz}");
            assert!(want_rz.abs() > 1.0);
        }
    }

    /// The first residual two rows to a register is the row-by-row formula to the bit (rows,
    /// and the sum of each row's f32 dot product in row order), with and without contacts,
    /// for chunks that start at an odd row and have an odd length (the last row alone).
    #[test]
    fn the_first_residual_is_the_formula_row_by_row() {
        let mut unit = crate::body::test_randoms(0x0f1e_2d3c_4b5a_6978);
        let (first, n) = (3, 45);
        let total = first + n;
        let vector = |unit: &mut dyn FnMut() -> f32| {
            (0..total).map(|_| Vec3A::from_vec4(glam::Vec4::new(unit(), unit(), unit(), unit()))).collect::<Vec<_>>()
        };
        let rhs = vector(&mut unit);
        let inv_diag = random_blocks(&mut unit, total);
        let normals = [Vec3A::Z, Vec3A::new(0.0, 0.6, 0.8)];
        let slot: Vec<u32> = (0..total).map(|i| if i % 7 == 2 { (i % 2) as u32 } else { u32::MAX }).collect();
        let ap = vector(&mut unit)[first..].to_vec();
        for any_contact in [false, true] {
            let (mut r, mut z) = (vec![Vec3A::splat(f32::NAN); n], vec![Vec3A::splat(f32::NAN); n]);
            let contact = ContactRows { slot: &slot, normal: &normals };
            let rz = initial_rows(first, (&mut r, &mut z), &rhs, &ap, &inv_diag, contact, any_contact);
            let mut want_rz = 0.0f64;
            let bits = |v: Vec3A| v.to_array().map(f32::to_bits);
            for k in 0..n {
                let i = first + k;
                let mut want_r = rhs[i] - ap[k];
                let mut want_z = inv_diag[i].apply(want_r);
                if any_contact && slot[i] != u32::MAX {
                    let normal = normals[slot[i] as usize];
                    want_r -= normal * want_r.dot(normal);
                    want_z -= normal * want_z.dot(normal);
                }
                assert_eq!((bits(r[k]), bits(z[k])), (bits(want_r), bits(want_z)), "row {k} ({any_contact})");
                want_rz += want_r.dot(want_z) as f64;
            }
            assert_eq!(rz.to_bits(), want_rz.to_bits(), "{rz} vs {want_rz} ({any_contact})");
            assert!(want_rz.abs() > 1.0);
        }
    }
}
