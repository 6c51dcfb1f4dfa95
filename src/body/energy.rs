//! Energies for the error report and the divergence check (SPEC 2.2, 4), and the bound behind
//! the stable time step estimate (`Body::stable_time_step`): `ω_max² ≈ max_i 2 w_i Σ_{springs at
//! i} K_s` (Gershgorin, SPEC 2.2), and the same with `K_d` for the damping rate `γ_max`.

use glam::Vec3;

use super::gas::{FACE_CHUNK, Gas};
use super::springs::{Springs, spring_extension};
use crate::parallel::{SharedSlice, WorkerPool};

/// Kinetic energy `Σ m v²/2`, J ([`lane_sum`]).
pub(crate) fn kinetic(mass: &[f32], v: &[Vec3]) -> f64 {
    let v = &v[..mass.len()];
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the processor has AVX2 and FMA (checked above); one velocity per mass.
        return unsafe { vertex_sum_avx2::<true>(mass, v, Vec3::ZERO) };
    }
    lane_sum(mass.len(), |k| 0.5 * mass[k] as f64 * v[k].as_dvec3().length_squared())
}

/// [`kinetic`] (`KINETIC`: `(0.5 m) |v|²` per vertex, `points` the velocities) or [`gravity`]
/// before its sign (`m (g·x)`, `points` the positions) with AVX2: the terms of eight vertices at
/// once in f64, in the lanes of [`lane_sum`] (vertex k in lane k mod 8), each computed with the
/// operations of the plain term in its order (no fused multiply-add), so the sum has the same
/// bits. Both are summed over every vertex once per implicit substep (its end energies): on the
/// issue-5 balloon they went from 1.3% to 1.0% of a one-thread profile of a step (they read the
/// arrays once; the conversions were not all of their time).
///
/// # Safety
/// The processor must have AVX2 and FMA; `points` must have a point per mass.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn vertex_sum_avx2<const KINETIC: bool>(mass: &[f32], points: &[Vec3], g: Vec3) -> f64 {
    use super::coupling_slices::load_points_transposed;
    use std::arch::x86_64::*;
    assert!(points.len() == mass.len());
    let count = mass.len();
    let whole = count - count % ENERGY_LANES;
    let (half, gx, gy, gz) =
        (_mm256_set1_pd(0.5), _mm256_set1_pd(g.x as f64), _mm256_set1_pd(g.y as f64), _mm256_set1_pd(g.z as f64));
    let (mut low, mut high) = (_mm256_setzero_pd(), _mm256_setzero_pd());
    for first in (0..whole).step_by(ENERGY_LANES) {
        // SAFETY: points first..first + 8 (first + 8 <= count); eight masses.
        let ((px, py, pz), m) =
            unsafe { (load_points_transposed(points, first), _mm256_loadu_ps(mass[first..first + 8].as_ptr())) };
        for (sum, lanes) in [(&mut low, 0), (&mut high, 1)] {
            // (Both halves written out: `_mm256_extractf128_ps` takes its lane as a constant.)
            let (x, y, z, m) = if lanes == 0 {
                (
                    _mm256_cvtps_pd(_mm256_castps256_ps128(px)),
                    _mm256_cvtps_pd(_mm256_castps256_ps128(py)),
                    _mm256_cvtps_pd(_mm256_castps256_ps128(pz)),
                    _mm256_cvtps_pd(_mm256_castps256_ps128(m)),
                )
            } else {
                (
                    _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(px)),
                    _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(py)),
                    _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(pz)),
                    _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(m)),
                )
            };
            let term = if KINETIC {
                // `0.5 * m * ((x x + y y) + z z)`.
                let squared =
                    _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(x, x), _mm256_mul_pd(y, y)), _mm256_mul_pd(z, z));
                _mm256_mul_pd(_mm256_mul_pd(half, m), squared)
            } else {
                // `m * ((gx x + gy y) + gz z)`.
                let along =
                    _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(gx, x), _mm256_mul_pd(gy, y)), _mm256_mul_pd(gz, z));
                _mm256_mul_pd(m, along)
            };
            *sum = _mm256_add_pd(*sum, term);
        }
    }
    let mut sums = [0.0f64; ENERGY_LANES];
    // SAFETY: four f64 into each half of the lanes.
    unsafe {
        _mm256_storeu_pd(sums.as_mut_ptr(), low);
        _mm256_storeu_pd(sums.as_mut_ptr().add(4), high);
    }
    let g = g.as_dvec3();
    for (lane, k) in (whole..count).enumerate() {
        sums[lane] += if KINETIC {
            0.5 * mass[k] as f64 * points[k].as_dvec3().length_squared()
        } else {
            mass[k] as f64 * g.dot(points[k].as_dvec3())
        };
    }
    pairwise(&sums)
}

/// `Σ term(k)` over `0..count` in [`ENERGY_LANES`] running sums (term k in sum k mod 8, added
/// pairwise at the end), as [`springs_energy_strain`] sums: with one running sum each term
/// waited for the last one's addition, which set the pace of these short per-vertex terms.
#[inline]
fn lane_sum(count: usize, term: impl Fn(usize) -> f64) -> f64 {
    let mut sums = [0.0f64; ENERGY_LANES];
    for block in (0..count).step_by(ENERGY_LANES) {
        for (lane, sum) in sums.iter_mut().enumerate().take(count - block) {
            *sum += term(block + lane);
        }
    }
    pairwise(&sums)
}

/// `((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7))`.
fn pairwise(sums: &[f64; ENERGY_LANES]) -> f64 {
    let four = |e: &[f64]| (e[0] + e[1]) + (e[2] + e[3]);
    four(&sums[..4]) + four(&sums[4..])
}

/// Springs per parallel chunk (fixed, so the sums do not depend on the thread count); also the
/// implicit integrator's chunk of spring terms, which sums the end-of-substep energies in the
/// same chunks.
pub(crate) const SPRING_CHUNK: usize = 2048;

/// Spring energy (J) and the largest spring strain (0 when none is stretched) of spring chunk
/// `c`: the end-of-step stats need both (SPEC 2.5), and each needs every spring's length.
fn spring_chunk(springs: &Springs, x: &[Vec3], ks: f32, c: usize) -> (f64, f32) {
    let range = c * SPRING_CHUNK..((c + 1) * SPRING_CHUNK).min(springs.len());
    let (ends, rest) = (&springs.ends[range.clone()], &springs.rest[range]);
    springs_energy_strain(|k| spring_extension(x[ends[k][0] as usize], x[ends[k][1] as usize], rest[k]), rest, ks)
}

/// Running sums of [`springs_energy_strain`].
pub(crate) const ENERGY_LANES: usize = 8;

/// `Σ K_s e²/2` (J) and `max(0, max e / L0)` of springs with extensions `extension(k)` and rest
/// lengths `rest` (SPEC 2.5): the energy in eight running f64 sums (spring k in sum k mod 8,
/// added pairwise at the end) and the strain in eight running maxima ([`SpringEnergyLanes`]).
/// With one running sum every spring waited for the last one's addition and maximum: on the
/// issue-5 balloon (benches/body_balloon.rs, six alternating runs each) the mean step went from
/// 1.89 to 1.87 ms on one thread (medians 1.61 -> 1.56) and from 1.11 to 1.04 ms on two (0.92 ->
/// 0.87), the same trajectory to the bit. Both measurements of a state, the implicit
/// integrator's at the end of a substep (its spring terms, eight lanes at a time) and
/// [`state_energies`] (from the positions), sum in these lanes, so they agree to the bit.
#[inline]
pub(crate) fn springs_energy_strain(extension: impl Fn(usize) -> f32, rest: &[f32], ks: f32) -> (f64, f32) {
    let mut lanes = SpringEnergyLanes::new(ks);
    for (k, &rest) in rest.iter().enumerate() {
        lanes.add(k % ENERGY_LANES, extension(k), rest);
    }
    lanes.finish()
}

/// The running sums and maxima of [`springs_energy_strain`] (spring k of a chunk in lane
/// k mod 8), for code that has the extensions at hand one spring or eight at a time.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SpringEnergyLanes {
    half_ks: f64,
    energy: [f64; ENERGY_LANES],
    strain: [f32; ENERGY_LANES],
}

impl SpringEnergyLanes {
    pub fn new(ks: f32) -> Self {
        Self { half_ks: 0.5 * ks as f64, energy: [0.0; ENERGY_LANES], strain: [0.0; ENERGY_LANES] }
    }

    /// Adds a spring of extension `e` and rest length `rest` to `lane`.
    #[inline(always)]
    pub fn add(&mut self, lane: usize, e: f32, rest: f32) {
        let stretch = e as f64;
        self.energy[lane] += self.half_ks * stretch * stretch;
        self.strain[lane] = self.strain[lane].max(e / rest);
    }

    /// Adds eight springs, one to each lane: the operations of [`SpringEnergyLanes::add`] on
    /// every lane (no fused multiply-adds; `max` keeps the running maximum when the new
    /// strain is NaN or equal, as `f32::max` does for a maximum that is never NaN).
    ///
    /// # Safety
    /// The processor must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub unsafe fn add_lanes(&mut self, e: std::arch::x86_64::__m256, rest: std::arch::x86_64::__m256) {
        use std::arch::x86_64::*;
        let half_ks = _mm256_set1_pd(self.half_ks);
        // SAFETY: four f64 from and to each half of the energy lanes, eight f32 of the strain.
        unsafe {
            for (half, stretch) in
                [_mm256_cvtps_pd(_mm256_castps256_ps128(e)), _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(e))]
                    .into_iter()
                    .enumerate()
            {
                let sums = self.energy.as_mut_ptr().add(4 * half);
                let term = _mm256_mul_pd(_mm256_mul_pd(half_ks, stretch), stretch);
                _mm256_storeu_pd(sums, _mm256_add_pd(_mm256_loadu_pd(sums), term));
            }
            let strain = _mm256_loadu_ps(self.strain.as_ptr());
            _mm256_storeu_ps(self.strain.as_mut_ptr(), _mm256_max_ps(_mm256_div_ps(e, rest), strain));
        }
    }

    /// The energy (J, the lanes added pairwise) and the largest strain (at least 0).
    pub fn finish(&self) -> (f64, f32) {
        (pairwise(&self.energy), self.strain.iter().fold(0.0f32, |a, &b| a.max(b)))
    }
}

/// Vertices per chunk of [`state_energies`].
pub(crate) const VERTEX_CHUNK: usize = 4096;

/// The gas of a state for [`state_energies`]: the gas and the triangles.
pub(crate) type GasState<'a> = (&'a Gas, &'a [[u32; 3]]);

/// The buffers of [`state_energies`], kept by the body between calls (a vector of tasks and
/// one of sums per face chunk were allocated by every call, every step).
#[derive(Debug, Default)]
pub(crate) struct EnergySums {
    /// Per task (vertex chunks, then spring chunks, then face chunks): its two sums (kinetic and
    /// gravitational energy, or spring energy and the largest strain).
    parts: Vec<(f64, f64)>,
    /// Per face chunk, `max(fragments, 1)` parts of 6 V ([`Gas::finish_face_chunks`]).
    pub six_v: Vec<f64>,
}

impl EnergySums {
    pub fn memory_bytes(&self) -> usize {
        self.parts.capacity() * 16 + self.six_v.capacity() * 8
    }
}

/// The energies of a state in one parallel pass (one fork for all of them): kinetic, spring and
/// gravitational energy (J) and the largest spring strain; with a gas, the face chunks' parts of
/// each fragment's 6 V are left in `sums.six_v` for [`Gas::finish_face_chunks`]. The sums do not
/// depend on the thread count (fixed chunks, added in order).
pub(crate) fn state_energies(
    pool: &WorkerPool,
    springs: &Springs,
    (x, v, mass): (&[Vec3], &[Vec3], &[f32]),
    ks: f32,
    g: Vec3,
    gas: Option<GasState>,
    sums: &mut EnergySums,
) -> (f64, f64, f64, f32) {
    let vertex_chunks = x.len().div_ceil(VERTEX_CHUNK);
    let spring_chunks = springs.len().div_ceil(SPRING_CHUNK);
    let face_chunks = gas.map_or(0, |(_, triangles)| triangles.len().div_ceil(FACE_CHUNK));
    let fragments = gas.map_or(1, |(gas, _)| gas.fragment_count().max(1));
    sums.parts.clear();
    sums.parts.resize(vertex_chunks + spring_chunks + face_chunks, (0.0, 0.0));
    sums.six_v.clear();
    sums.six_v.resize(face_chunks * fragments, 0.0);
    let six_v = SharedSlice::new(&mut sums.six_v);
    pool.for_each_chunk_mut(&mut sums.parts, 1, |task, part| {
        if task < vertex_chunks {
            let range = task * VERTEX_CHUNK..((task + 1) * VERTEX_CHUNK).min(x.len());
            part[0] = (kinetic(&mass[range.clone()], &v[range.clone()]), gravity(&mass[range.clone()], &x[range], g));
        } else if task < vertex_chunks + spring_chunks {
            let (energy, strain) = spring_chunk(springs, x, ks, task - vertex_chunks);
            part[0] = (energy, strain as f64);
        } else if let Some((gas, triangles)) = gas {
            let c = task - vertex_chunks - spring_chunks;
            // SAFETY: face chunk c's parts, written by this task alone.
            let parts = unsafe { six_v.part(c * fragments..(c + 1) * fragments) };
            gas.face_chunk_volumes(x, triangles, c, parts);
        }
    });
    let (mut kinetic_energy, mut spring, mut gravity_energy, mut max_strain) = (0.0, 0.0, 0.0, 0.0f32);
    for &(k, g) in &sums.parts[..vertex_chunks] {
        kinetic_energy += k;
        gravity_energy += g;
    }
    for &(energy, strain) in &sums.parts[vertex_chunks..vertex_chunks + spring_chunks] {
        spring += energy;
        max_strain = max_strain.max(strain as f32);
    }
    (kinetic_energy, spring, gravity_energy, max_strain)
}

/// Gravitational energy `-Σ m g·x`, J.
pub(crate) fn gravity(mass: &[f32], x: &[Vec3], g: Vec3) -> f64 {
    let x = &x[..mass.len()];
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the processor has AVX2 and FMA (checked above); one position per mass.
        return -unsafe { vertex_sum_avx2::<false>(mass, x, g) };
    }
    let g = g.as_dvec3();
    -lane_sum(mass.len(), |k| mass[k] as f64 * g.dot(x[k].as_dvec3()))
}

/// Total momentum `Σ m v`, kg m/s.
pub(crate) fn momentum(mass: &[f32], v: &[Vec3]) -> glam::DVec3 {
    mass.iter().zip(v).map(|(&m, v)| m as f64 * v.as_dvec3()).sum()
}

/// `max_i 2 c_i w_i` over the vertices (`c_i` springs at vertex i, `w_i` its inverse mass): the
/// Gershgorin bound of the spring network per unit spring constant, so that the largest
/// eigenvalue of `M⁻¹K` is at most `K_s` times it (SPEC 2.2 `ω_max² ≈ max_i Σ K_s w_i`, with the
/// factor 2 of a spring's two ends) and that of the damping `M⁻¹C` at most `K_d` times it (the
/// damping acts along the same springs).
pub(crate) fn spring_rate_bound(springs: &Springs, inv_mass: &[f32]) -> f64 {
    let mut count = vec![0u32; inv_mass.len()];
    for &[i, j] in &springs.ends {
        count[i as usize] += 1;
        count[j as usize] += 1;
    }
    count.iter().zip(inv_mass).map(|(&c, &w)| 2.0 * c as f64 * w as f64).fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Kinetic and gravitational energy against the plain sums, for 0 to 21 vertices (on both
    /// sides of a multiple of the running sums); one vertex's is its term exactly.
    #[test]
    fn vertex_energies_are_the_sums_of_their_terms() {
        let mut unit = crate::body::test_randoms(0xe4e7_9ee5_0002);
        let g = Vec3::new(0.0, -9.81, 0.5);
        for n in 0..22 {
            let mass: Vec<f32> = (0..n).map(|_| 0.1 + unit().abs()).collect();
            let v: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), unit(), unit()) * 3.0).collect();
            let x: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), 1.0 + unit(), unit())).collect();
            let want_kinetic: f64 = (0..n).map(|k| 0.5 * mass[k] as f64 * v[k].as_dvec3().length_squared()).sum();
            let want_gravity: f64 = -(0..n).map(|k| mass[k] as f64 * g.as_dvec3().dot(x[k].as_dvec3())).sum::<f64>();
            let (kinetic, gravity) = (kinetic(&mass, &v), gravity(&mass, &x, g));
            assert!((kinetic - want_kinetic).abs() <= 1e-12 * want_kinetic.abs().max(1e-300), "{n}");
            assert!((gravity - want_gravity).abs() <= 1e-12 * want_gravity.abs().max(1e-300), "{n}");
            if n == 1 {
                assert_eq!(kinetic.to_bits(), want_kinetic.to_bits());
                assert_eq!(gravity.to_bits(), want_gravity.to_bits());
            }
        }
    }

    /// Eight vertices at a time with AVX2 (where the processor has it), the rest one at a time:
    /// the plain running sums of [`lane_sum`] to the bit, for 0 to 40 vertices.
    #[test]
    fn vertex_energies_eight_at_a_time_have_the_bits_of_the_running_sums() {
        let mut unit = crate::body::test_randoms(0xe4e7_9ee5_0003);
        let g = Vec3::new(0.3, -9.81, 0.5);
        for n in 0..41 {
            let mass: Vec<f32> = (0..n).map(|_| 0.1 + unit().abs()).collect();
            let v: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), unit(), unit()) * 3.0).collect();
            let x: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), 1.0 + unit(), unit())).collect();
            let want_kinetic = lane_sum(n, |k| 0.5 * mass[k] as f64 * v[k].as_dvec3().length_squared());
            let want_gravity = -lane_sum(n, |k| mass[k] as f64 * g.as_dvec3().dot(x[k].as_dvec3()));
            assert_eq!(kinetic(&mass, &v).to_bits(), want_kinetic.to_bits(), "{n} vertices");
            assert_eq!(gravity(&mass, &x, g).to_bits(), want_gravity.to_bits(), "{n} vertices");
        }
    }

    /// Against the plain sum and maximum, for counts on both sides of a multiple of the running
    /// sums (0 to 21 springs), stretched and compressed: the largest strain is exact (0 when
    /// every spring is compressed), the energy equal up to the order of its additions.
    #[test]
    fn spring_energy_and_strain_are_the_sum_and_the_largest() {
        let mut unit = crate::body::test_randoms(0xe4e7_9ee5_0001);
        for n in 0..22 {
            let compressed_only = n % 5 == 1;
            let rest: Vec<f32> = (0..n).map(|_| 0.5 + unit().abs()).collect();
            let mut extension: Vec<f32> = rest
                .iter()
                .map(|&r| if compressed_only { -0.1 * r * unit().abs() } else { 0.3 * r * unit() })
                .collect();
            if !compressed_only && n > 2 {
                // At least one stretched, not always the first.
                extension[n / 2] = 0.05 * rest[n / 2];
            }
            let ks = 250.0f32;
            let (energy, strain) = springs_energy_strain(|k| extension[k], &rest, ks);
            let want: f64 = extension.iter().map(|&e| 0.5 * ks as f64 * e as f64 * e as f64).sum();
            let largest = extension.iter().zip(&rest).map(|(&e, &r)| e / r).fold(0.0f32, f32::max);
            assert!((energy - want).abs() <= 1e-12 * want.max(1e-300), "{n}: {energy} vs {want}");
            assert_eq!(strain.to_bits(), largest.to_bits(), "{n}");
            if compressed_only || n == 0 {
                assert_eq!(strain, 0.0);
            } else if n > 2 {
                assert!(strain > 0.0);
            }
        }
    }
}
