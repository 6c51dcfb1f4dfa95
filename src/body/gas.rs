//! The ideal gas inside each closed fragment (SPEC 2.1, 2.4): exact volume, the conservative
//! pressure force `P ∂V/∂x`, the volume clamp, hole capping and the leak.
//!
//! A fragment's volume is measured over its faces plus a fan cap over each boundary loop (from
//! the loop's vertex mean), so a cracked fragment still has a volume and the force stays the exact
//! gradient of it: the cap centre's share of the gradient goes to the loop's vertices equally.
//! Allocated only when the body has gas.

use glam::{DVec3, Vec3, Vec3A};

use super::coupling_slices::SLICE;
use super::fan_rings::FanRings;
use super::headroom::with_room;
use crate::parallel::WorkerPool;

/// A boundary loop of a fragment, closed by a fan from the mean of its vertices.
#[derive(Clone, Debug)]
pub(crate) struct Cap {
    pub fragment: u32,
    pub ring: Vec<u32>,
}

/// Tests only: topology changes keep every fragment's gas fragment (no gathering, neither before
/// the measurement in [`Gas::after_change`] nor after it in [`Gas::keep_fragments_with_gas`]),
/// for a run to compare with. Global, as the gas may be rebuilt on a pool's thread; only one test
/// sets it, and other tests are only slower meanwhile.
#[cfg(test)]
pub(crate) static KEEP_EVERY_FRAGMENT: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Tests only: [`Gas::after_change`] also makes the gas as it was made before it gathered
/// pieces early ([`Gas::new`], then [`Gas::inherit`]) and panics unless the two are alike in
/// every field; [`GATHERED_EARLY`] counts the changes checked that gathered pieces early.
/// Global, like [`KEEP_EVERY_FRAGMENT`]: other tests only check more meanwhile.
/// Tests only: held by the tests that set [`KEEP_EVERY_FRAGMENT`] or [`CHECK_AFTER_CHANGE`],
/// so that neither sees the other's setting change under it.
#[cfg(test)]
pub(crate) static GATHERING_TESTS: std::sync::Mutex<()> = std::sync::Mutex::new(());
#[cfg(test)]
pub(crate) static CHECK_AFTER_CHANGE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
#[cfg(test)]
pub(crate) static GATHERED_EARLY: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Gas state of every fragment.
#[derive(Clone, Debug, Default)]
pub(crate) struct Gas {
    /// nRT of each fragment, J.
    pub n_rt: Vec<f64>,
    /// Volume below which the pressure stops growing (the clamp), per fragment, m^3.
    pub v_min: Vec<f64>,
    /// Caps over the boundary loops.
    pub caps: Vec<Cap>,
    /// The gas fragment of each face: one per fragment of the body (its connected pieces) when
    /// made; after a topology change one per piece that holds gas, then one more for all the
    /// faces of pieces without gas, when there are such ([`Gas::inherit`]). (A piece whose gas
    /// leaks to nothing keeps its own until the next change.)
    pub face_fragment: Vec<u32>,
    /// Fragment of each vertex (`u32::MAX` for a vertex used by no face, or, after a topology
    /// change, by faces of pieces without gas: see [`Gas::keep_fragments_with_gas`]).
    pub vertex_fragment: Vec<u32>,
    /// Per slice of eight vertices, their `vertex_fragment` when they share it (`u32::MAX`: none
    /// of them is used by a face), else [`MIXED_FRAGMENTS`] ([`slice_fragments`]): the solve's
    /// passes take a slice's gas term with one lookup, where comparing its eight fragments took
    /// about 20 instructions per slice in each product and direction pass.
    pub slice_vertex_fragment: Vec<u32>,
    /// A vertex of each fragment, the origin of its volume sums (accuracy only).
    pub reference_vertex: Vec<u32>,
    /// Last measured capped volume per fragment, m^3.
    pub volume: Vec<f64>,
    /// Last pressure per fragment, Pa (`nRT / max(V, v_min)`).
    pub pressure: Vec<f64>,
    /// Area of the caps (the holes) per fragment, m^2.
    pub open_area: Vec<f64>,
    /// True when the last measurement clamped a volume (near-zero or inverted fragment).
    pub clamped: bool,
    /// The triangle corners at each vertex in CSR form (each corner's next and previous vertex
    /// and its face's fragment, faces ascending), made with every body with gas and after each
    /// topology change ([`Gas::prepare_corners`]): lets the parallel measurement gather per
    /// vertex instead of scattering.
    corner_offsets: Vec<u32>,
    corners: Vec<Corner>,
    /// Per vertex: its corners close a ring around it (every neighbour is once the next and once
    /// the previous corner), so its gradient does not depend on the origin (see
    /// [`Gas::measure_with_gradient_parallel`]).
    closed_fan: Vec<bool>,
    /// The closed fans as rings, for the gradient eight vertices at a time.
    rings: FanRings,
    /// Per slice of eight vertices: the fragment of all their fans when it is one (`u32::MAX`
    /// otherwise), so the gradient pass tests a slice's gas with one lookup. Testing each
    /// vertex's first corner instead missed the cache about once a vertex (61,440 corners of
    /// 12 bytes on the issue-5 balloon, one read of each vertex's): the pass around the sums
    /// took 1.5-2.1% of a one-thread profile of the drop, about as much as the sums
    /// themselves, and 0.24% with this (the same gradient to the bit).
    slice_fragment: Vec<u32>,
    /// Per chunk of faces ([`FACE_CHUNK`]) and per fragment, that chunk's part of 6 V.
    chunk_six_v: Vec<f64>,
}

/// A triangle corner seen from its vertex: the next two corners of the triangle (in its winding)
/// and the triangle's fragment.
/// Stored per corner so the gathering pass reads 12 bytes instead of looking up the triangle,
/// its fragment and the corner's place in it (on the issue-5 balloon that lookup, a division and
/// two remainders per corner, made this pass 12% of an implicit step).
#[derive(Clone, Copy, Debug, Default)]
struct Corner {
    next: u32,
    prev: u32,
    fragment: u32,
}

#[cfg(test)]
thread_local! {
    /// How many times this thread built corner lists from a topology's fans (the tests tell the
    /// two ways of building them apart by it).
    static CORNERS_FROM_FANS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Vertices per chunk of the parallel measurement (fixed, so the sums do not depend on the
/// thread count).
const VERTEX_CHUNK: usize = 2048;

/// Faces per chunk of the parallel volume measurement (fixed, as above).
pub(crate) const FACE_CHUNK: usize = 4096;

/// A fragment with less than this fraction of its parent's volume is a shred and keeps no gas.
pub(crate) const SHRED_FRACTION: f64 = 1e-3;

/// Fraction of a fragment's volume at gas assignment below which the pressure is clamped.
pub(crate) const CLAMP_FRACTION: f64 = 1e-2;

/// 1/6 (each gradient term is a cross product over 6; a multiplication, where three f64
/// divisions per triangle corner were a third of the gathering pass).
const SIXTH: f64 = 1.0 / 6.0;

/// `(a - o)·((b - o)×(c - o))`: 6 V of a tetrahedron, in f64 (the caps, whose centres are
/// f64).
fn tet(o: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    (a - o).dot((b - o).cross(c - o))
}

/// A face's term of 6 V, its tetrahedron with the origin `o`: `(a - o)·((b - a)×(c - a))` (the
/// same as [`tet`]: the parts of `b - o` and `c - o` along `a - o` add nothing), in f32, then
/// widened. The cross product of the face's own edges is about its area, with no cancellation,
/// and its dot with `a - o` adds a relative error of a few f32 roundings; the f64 sums of these
/// terms then hold the volume to about 1e-7 of itself. In f64 about o (as [`tet`]), the
/// corners' widening and transposes took most of a face's instructions; eight faces a register
/// in f32 ([`add_face_tets_avx2`]) took the pass from 0.32 to 0.21-0.25 of the residual pass's
/// time (one-thread profiles of the issue-5 balloon). That balloon settles to the same volume
/// (V/V0 1.0235; 1.0503 without gravity), and ten drops 0 to 25 mm higher took 8.61 CG
/// iterations a step against 8.54 (the rounding moves each drop's count). The operations and
/// their order are those of the eight-face kernel, so a face gets the same bits either way.
#[inline(always)]
fn face_term(o: Vec3, a: Vec3, b: Vec3, c: Vec3) -> f64 {
    let (ax, ay, az) = (a.x - o.x, a.y - o.y, a.z - o.z);
    let (ux, uy, uz) = (b.x - a.x, b.y - a.y, b.z - a.z);
    let (vx, vy, vz) = (c.x - a.x, c.y - a.y, c.z - a.z);
    let (cx, cy, cz) = (uy * vz - vy * uz, uz * vx - vz * ux, ux * vy - vx * uy);
    ((ax * cx + ay * cy) + az * cz) as f64
}

/// The origin of each fragment's volume sums by fragment ([`origin_of`]).
trait Origin: Fn(usize) -> DVec3 + Copy {}
impl<F: Fn(usize) -> DVec3 + Copy> Origin for F {}

/// The origin of fragment `f`'s volume sums: one of its vertices, `reference[f]` (accuracy
/// only; the origin of a fragment without vertices is never used). Read where it is used
/// rather than gathered into a vector: that was an allocation per force evaluation.
#[inline]
pub fn origin_of(reference: &[u32], x: &[Vec3], f: usize) -> DVec3 {
    let v = reference[f];
    if v == u32::MAX { DVec3::ZERO } else { x[v as usize].as_dvec3() }
}

/// Adds each face's `6 V` term ([`face_term`], with its fragment's origin) into `six_v`, in
/// face order ([`TetSums`]): eight faces at a time with AVX2 where the processor has it (the
/// same operations in the same order and the same sums, so the same bits, tested).
fn add_face_tets(x: &[Vec3], origin: impl Origin, faces: &[[u32; 3]], face_fragment: &[u32], six_v: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2 (checked just above).
        unsafe { add_face_tets_avx2(x, origin, faces, face_fragment, six_v) };
        return;
    }
    add_face_tets_scalar(x, origin, faces, face_fragment, six_v);
}

fn add_face_tets_scalar(x: &[Vec3], origin: impl Origin, faces: &[[u32; 3]], face_fragment: &[u32], six_v: &mut [f64]) {
    let mut sums = TetSums::default();
    add_face_tets_from(&mut sums, 0, x, origin, faces, face_fragment, six_v);
    sums.flush(six_v);
}

/// The faces from `first` of the call's (`faces` starts there) into `sums` one at a time.
fn add_face_tets_from(
    sums: &mut TetSums,
    first: usize,
    x: &[Vec3],
    origin: impl Origin,
    faces: &[[u32; 3]],
    face_fragment: &[u32],
    six_v: &mut [f64],
) {
    for (k, (t, &frag)) in faces.iter().zip(face_fragment).enumerate() {
        let o = origin(frag as usize).as_vec3();
        let term = face_term(o, x[t[0] as usize], x[t[1] as usize], x[t[2] as usize]);
        sums.add(first + k, frag, term, six_v);
    }
}

/// Faces per run of [`TetSums`].
const TET_LANES: usize = 4;

/// The running sums of [`add_face_tets`]: over a run of faces of one fragment, face k of the
/// call in sum k mod 4, the four added pairwise into the fragment's total when the run ends.
/// One running sum in memory (`six_v[fragment] += term`) made every face wait for the last
/// one's load, addition and store.
#[derive(Default)]
struct TetSums {
    /// The run's fragment, None before the first face.
    fragment: Option<u32>,
    lanes: [f64; TET_LANES],
}

impl TetSums {
    /// Adds face k's term (k counted from the start of the call).
    #[inline(always)]
    fn add(&mut self, k: usize, fragment: u32, term: f64, six_v: &mut [f64]) {
        self.enter(fragment, six_v);
        self.lanes[k % TET_LANES] += term;
    }

    /// Adds four faces' terms, from a face k with k mod 4 = 0, all of `fragment`: lane l's
    /// term into sum l, as four calls of [`TetSums::add`] would.
    #[inline(always)]
    fn add_four(&mut self, fragment: u32, terms: [f64; TET_LANES], six_v: &mut [f64]) {
        self.enter(fragment, six_v);
        for (sum, term) in self.lanes.iter_mut().zip(terms) {
            *sum += term;
        }
    }

    /// Ends the run unless it is of `fragment`, and starts one of `fragment` from zero.
    #[inline(always)]
    fn enter(&mut self, fragment: u32, six_v: &mut [f64]) {
        if self.fragment != Some(fragment) {
            self.flush(six_v);
            self.fragment = Some(fragment);
            self.lanes = [0.0; TET_LANES];
        }
    }

    /// Adds the run's sums into its fragment's total and ends it.
    #[inline(always)]
    fn flush(&mut self, six_v: &mut [f64]) {
        if let Some(f) = self.fragment.take() {
            let l = self.lanes;
            six_v[f as usize] += (l[0] + l[1]) + (l[2] + l[3]);
        }
    }
}

/// Corner `corner` of eight faces as x, y and z lanes: each point loaded 16 bytes at a time and
/// transposed. (A function with the target feature, not a closure: a closure does not inherit
/// it, and its intrinsics became calls.)
///
/// # Safety
/// The processor must have AVX2; each of the points must be followed by another in `x`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn face_corners(
    x: &[Vec3],
    group: &[[u32; 3]; 8],
    corner: usize,
) -> (std::arch::x86_64::__m256, std::arch::x86_64::__m256, std::arch::x86_64::__m256) {
    use std::arch::x86_64::*;
    let base = x.as_ptr() as *const f32;
    // SAFETY: point i is followed by point i + 1 (the caller's contract), so the 16 bytes from
    // its start are inside the slice.
    let row = |face: usize| unsafe { _mm_loadu_ps(base.add(3 * group[face][corner] as usize)) };
    let (px, py, pz, _) = super::coupling_slices::transpose_rows(
        _mm256_set_m128(row(4), row(0)),
        _mm256_set_m128(row(5), row(1)),
        _mm256_set_m128(row(6), row(2)),
        _mm256_set_m128(row(7), row(3)),
    );
    (px, py, pz)
}

/// [`add_face_tets`] with AVX2: eight faces at a time ([`face_term`] in each lane); a group of
/// eight faces with a corner at the last point goes one at a time.
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn add_face_tets_avx2(
    x: &[Vec3],
    origin: impl Origin,
    faces: &[[u32; 3]],
    face_fragment: &[u32],
    six_v: &mut [f64],
) {
    use std::arch::x86_64::*;
    assert_eq!(faces.len(), face_fragment.len());
    // The last point's 16-byte load would read past the slice; groups touching it go one at a
    // time.
    let last = x.len().saturating_sub(1) as u32;
    let bound = _mm256_set1_epi32(last.wrapping_sub(1) as i32);
    let mut sums = TetSums::default();
    let mut k = 0;
    while k + 8 <= faces.len() {
        let group: &[[u32; 3]; 8] = faces[k..k + 8].try_into().expect("eight faces");
        let frags = &face_fragment[k..k + 8];
        // The 24 corners below the last point: max(index, last - 1) == last - 1 unsigned.
        // SAFETY: 96 bytes of eight [u32; 3] read unaligned as three 32-byte vectors.
        let inside = unsafe {
            let ptr = group.as_ptr() as *const __m256i;
            let max = _mm256_max_epu32(
                _mm256_max_epu32(_mm256_loadu_si256(ptr), _mm256_loadu_si256(ptr.add(1))),
                _mm256_loadu_si256(ptr.add(2)),
            );
            last > 0 && _mm256_movemask_epi8(_mm256_cmpeq_epi32(_mm256_max_epu32(max, bound), bound)) == -1
        };
        if !inside {
            add_face_tets_from(&mut sums, k, x, origin, group, frags, six_v);
            k += 8;
            continue;
        }
        let one_fragment = frags[1..].iter().all(|&f| f == frags[0]);
        let (ox, oy, oz) = if one_fragment {
            // One fragment (nearly always): its origin in every lane.
            let o = origin(frags[0] as usize).as_vec3();
            (_mm256_set1_ps(o.x), _mm256_set1_ps(o.y), _mm256_set1_ps(o.z))
        } else {
            let o: [Vec3; 8] = std::array::from_fn(|lane| origin(frags[lane] as usize).as_vec3());
            (
                _mm256_setr_ps(o[0].x, o[1].x, o[2].x, o[3].x, o[4].x, o[5].x, o[6].x, o[7].x),
                _mm256_setr_ps(o[0].y, o[1].y, o[2].y, o[3].y, o[4].y, o[5].y, o[6].y, o[7].y),
                _mm256_setr_ps(o[0].z, o[1].z, o[2].z, o[3].z, o[4].z, o[5].z, o[6].z, o[7].z),
            )
        };
        // SAFETY: AVX2 (this function's contract); every corner is followed by another point
        // (checked above).
        let (a, b, c) = unsafe { (face_corners(x, group, 0), face_corners(x, group, 1), face_corners(x, group, 2)) };
        // `face_term`, lane by lane.
        let (ax, ay, az) = (_mm256_sub_ps(a.0, ox), _mm256_sub_ps(a.1, oy), _mm256_sub_ps(a.2, oz));
        let (ux, uy, uz) = (_mm256_sub_ps(b.0, a.0), _mm256_sub_ps(b.1, a.1), _mm256_sub_ps(b.2, a.2));
        let (vx, vy, vz) = (_mm256_sub_ps(c.0, a.0), _mm256_sub_ps(c.1, a.1), _mm256_sub_ps(c.2, a.2));
        let cx = _mm256_sub_ps(_mm256_mul_ps(uy, vz), _mm256_mul_ps(vy, uz));
        let cy = _mm256_sub_ps(_mm256_mul_ps(uz, vx), _mm256_mul_ps(vz, ux));
        let cz = _mm256_sub_ps(_mm256_mul_ps(ux, vy), _mm256_mul_ps(vx, uy));
        let volume = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(ax, cx), _mm256_mul_ps(ay, cy)), _mm256_mul_ps(az, cz));
        let mut terms = [0.0f64; 8];
        // SAFETY: unaligned stores into eight local f64.
        unsafe {
            _mm256_storeu_pd(terms.as_mut_ptr(), _mm256_cvtps_pd(_mm256_castps256_ps128(volume)));
            _mm256_storeu_pd(terms.as_mut_ptr().add(4), _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(volume)));
        }
        if one_fragment {
            let (first, second) = terms.split_at(TET_LANES);
            sums.add_four(frags[0], first.try_into().expect("four"), six_v);
            sums.add_four(frags[0], second.try_into().expect("four"), six_v);
        } else {
            for (lane, (&frag, term)) in frags.iter().zip(terms).enumerate() {
                sums.add(k + lane, frag, term, six_v);
            }
        }
        k += 8;
    }
    add_face_tets_from(&mut sums, k, x, origin, &faces[k..], &face_fragment[k..], six_v);
    sums.flush(six_v);
}

/// Point `i` of `x` as a `Vec3A`: one unaligned 16-byte load where a point follows it (the
/// fourth lane, the next point's x, is ignored by every Vec3A operation used here), else
/// assembled from its three floats. (`Vec3A::from(Vec3)` assembles the lanes one by one: with
/// two points per triangle corner that was a fifth of the gradient pass's instructions.)
#[inline(always)]
pub(super) fn point(x: &[Vec3], i: usize) -> Vec3A {
    #[cfg(target_arch = "x86_64")]
    if i + 1 < x.len() {
        // SAFETY: points i and i + 1 are in the slice (checked above), so the 16 bytes from
        // the start of point i are too; SSE2 is always present on x86-64.
        return Vec3A::from(unsafe { std::arch::x86_64::_mm_loadu_ps(x.as_ptr().add(i) as *const f32) });
    }
    Vec3A::from(x[i])
}

fn ring_center(x: &[Vec3], ring: &[u32]) -> DVec3 {
    ring.iter().map(|&v| x[v as usize].as_dvec3()).sum::<DVec3>() / ring.len() as f64
}

/// A slice's fragment in [`Gas::slice_vertex_fragment`] when its vertices are of several
/// fragments (or some of them of none).
pub(crate) const MIXED_FRAGMENTS: u32 = u32::MAX - 1;

/// The fragment each slice of eight consecutive entries of `vertex_fragment` shares, or
/// [`MIXED_FRAGMENTS`] (a last slice of fewer entries by those it has).
pub(crate) fn slice_fragments(vertex_fragment: &[u32]) -> Vec<u32> {
    vertex_fragment
        .chunks(SLICE)
        .map(|rows| if rows.iter().all(|&f| f == rows[0]) { rows[0] } else { MIXED_FRAGMENTS })
        .collect()
}

impl Gas {
    /// Builds the fragment bookkeeping for `fragment_count` fragments (`face_fragment` per face)
    /// and the caps over `boundary_loops`; gas amounts are left at zero.
    pub fn new(
        vertex_count: usize,
        triangles: &[[u32; 3]],
        face_fragment: &[u32],
        fragment_count: usize,
        boundary_loops: &[Vec<u32>],
    ) -> Self {
        Self::with_caps_but_of(vertex_count, triangles, face_fragment, fragment_count, boundary_loops, None)
    }

    /// The gas after a topology change: [`Gas::new`] for the fragments after it, then
    /// [`Gas::inherit`] from `old`, the gas before it. A fragment whose parent (the old gas
    /// fragment of its first surviving face) holds no gas, or that has no parent (all its faces
    /// new), gets none: such fragments are gathered into one fragment without caps before
    /// anything is measured, as [`Gas::keep_fragments_with_gas`] would gather them afterwards,
    /// so the same gas, to the bit (tested). Why: after the issue-5 balloon has burst (15,000
    /// pieces, of which 100-160 hold gas), each change made, measured and then dropped a cap over
    /// the rim of every piece: about 2.8 ms of every cracking step, the longer half of the
    /// rebuild (the springs, built at the same time, about 1.4 ms).
    pub fn after_change(
        mut old: Gas,
        x: &[Vec3],
        triangles: &[[u32; 3]],
        face_fragment: &[u32],
        fragment_count: usize,
        boundary_loops: &[Vec<u32>],
    ) -> Self {
        let vertex_count = x.len();
        let parent = Self::parents(face_fragment, fragment_count, &old.face_fragment);
        let may_hold: Vec<bool> =
            parent.iter().map(|&p| p != u32::MAX && old.n_rt.get(p as usize).is_some_and(|&g| g > 0.0)).collect();
        #[cfg(test)]
        let keep_every = KEEP_EVERY_FRAGMENT.load(std::sync::atomic::Ordering::Relaxed);
        #[cfg(not(test))]
        let keep_every = false;
        let gather_early = !keep_every && !may_hold.iter().all(|&m| m);
        let mut gas = if !gather_early {
            Gas::new(vertex_count, triangles, face_fragment, fragment_count, boundary_loops)
        } else {
            // The fragments that may hold gas keep their order, numbered from 0; the others
            // share the last number.
            let without = may_hold.iter().filter(|&&m| m).count() as u32;
            let mut next = 0;
            let number: Vec<u32> = may_hold
                .iter()
                .map(|&m| {
                    if !m {
                        return without;
                    }
                    next += 1;
                    next - 1
                })
                .collect();
            let gathered: Vec<u32> = face_fragment.iter().map(|&f| number[f as usize]).collect();
            Gas::with_caps_but_of(
                vertex_count,
                triangles,
                &gathered,
                without as usize + 1,
                boundary_loops,
                Some(without),
            )
        };
        gas.inherit(&old, x, triangles);
        if !keep_every {
            gas.keep_fragments_with_gas(triangles);
        }
        #[cfg(test)]
        if CHECK_AFTER_CHANGE.load(std::sync::atomic::Ordering::Relaxed) {
            let mut made_late = Gas::new(vertex_count, triangles, face_fragment, fragment_count, boundary_loops);
            made_late.inherit(&old, x, triangles);
            if !keep_every {
                made_late.keep_fragments_with_gas(triangles);
            }
            assert_eq!(format!("{gas:?}"), format!("{made_late:?}"), "the gas gathered early differs");
            if gather_early {
                GATHERED_EARLY.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
        }
        gas.adopt_corner_buffers(&mut old);
        gas
    }

    /// Each fragment's parent in the gas before a change, whose faces were in `old_face_fragment`
    /// (the faces keep their index; new ones are appended): the old fragment of its first face
    /// that existed before, `u32::MAX` for none.
    fn parents(face_fragment: &[u32], fragment_count: usize, old_face_fragment: &[u32]) -> Vec<u32> {
        let mut parent = vec![u32::MAX; fragment_count];
        for (&frag, &old) in face_fragment.iter().zip(old_face_fragment) {
            if parent[frag as usize] == u32::MAX {
                parent[frag as usize] = old;
            }
        }
        parent
    }

    /// [`Gas::new`] without the caps of fragment `skip` (if any).
    fn with_caps_but_of(
        vertex_count: usize,
        triangles: &[[u32; 3]],
        face_fragment: &[u32],
        fragment_count: usize,
        boundary_loops: &[Vec<u32>],
        skip: Option<u32>,
    ) -> Self {
        assert!(fragment_count < MIXED_FRAGMENTS as usize, "{fragment_count} fragments");
        let mut vertex_fragment = vec![u32::MAX; vertex_count];
        let mut reference_vertex = vec![u32::MAX; fragment_count];
        for (t, &frag) in triangles.iter().zip(face_fragment) {
            for &v in t {
                vertex_fragment[v as usize] = frag;
            }
            if reference_vertex[frag as usize] == u32::MAX {
                reference_vertex[frag as usize] = t[0];
            }
        }
        let caps = boundary_loops
            .iter()
            .filter(|ring| ring.len() >= 3 && Some(vertex_fragment[ring[0] as usize]) != skip)
            // A boundary loop runs with its faces' winding; the cap closing it runs against it.
            .map(|ring| Cap { fragment: vertex_fragment[ring[0] as usize], ring: ring.iter().rev().copied().collect() })
            .collect();
        Self {
            n_rt: vec![0.0; fragment_count],
            v_min: vec![0.0; fragment_count],
            caps,
            face_fragment: face_fragment.to_vec(),
            slice_vertex_fragment: slice_fragments(&vertex_fragment),
            vertex_fragment,
            reference_vertex,
            volume: vec![0.0; fragment_count],
            pressure: vec![0.0; fragment_count],
            open_area: vec![0.0; fragment_count],
            clamped: false,
            corner_offsets: Vec::new(),
            corners: Vec::new(),
            closed_fan: Vec::new(),
            rings: FanRings::default(),
            slice_fragment: Vec::new(),
            chunk_six_v: Vec::new(),
        }
    }

    pub fn fragment_count(&self) -> usize {
        self.n_rt.len()
    }

    /// Sets a fragment's gas so that its pressure is `n_rt / volume` from now on; the clamp is a
    /// fixed fraction of `volume`.
    pub fn assign(&mut self, fragment: usize, n_rt: f64, volume: f64) {
        self.n_rt[fragment] = n_rt;
        self.v_min[fragment] = CLAMP_FRACTION * volume.max(0.0);
    }

    /// SPEC 2.1/2.4: capped volume and hole area of every fragment, then the pressure
    /// `P = nRT / max(V, v_min)` (SPEC 2.2 clamp; `clamped` reports it).
    pub fn measure(&mut self, x: &[Vec3], triangles: &[[u32; 3]]) {
        // 6 V summed in place in `volume` (no buffer per call: see `Gas::finish`).
        self.volume.fill(0.0);
        let reference = &self.reference_vertex;
        // (Eight faces at a time with AVX2: a topology change measures its new fragments here,
        // about 0.2 ms one face at a time on the issue-5 balloon's first cracking step.)
        add_face_tets(x, |f| origin_of(reference, x, f), triangles, &self.face_fragment, &mut self.volume);
        self.finish(x);
    }

    /// [`Gas::measure`] and [`Gas::volume_gradient`] in one pass over the faces (the cross
    /// products of the volume are the gradient), scattered into the vertices: the reference the
    /// gathering form that every integrator uses ([`Gas::measure_with_gradient_parallel`]) is
    /// tested against.
    #[cfg(test)]
    pub fn measure_with_gradient(&mut self, x: &[Vec3], triangles: &[[u32; 3]], out: &mut [Vec3]) {
        out.iter_mut().for_each(|g| *g = Vec3::ZERO);
        let six_v = &mut self.volume;
        six_v.fill(0.0);
        // Per run of faces of one fragment (runs are long: nearly always one fragment), its
        // origin, whether it holds gas, and its running 6 V in a local (the same additions in
        // the same order as into the slice, so the same bits).
        let (mut last, mut o, mut has_gas, mut sum) = (u32::MAX, DVec3::ZERO, false, 0.0f64);
        for (t, &frag) in triangles.iter().zip(&self.face_fragment) {
            if frag != last {
                if last != u32::MAX {
                    six_v[last as usize] = sum;
                }
                last = frag;
                o = origin_of(&self.reference_vertex, x, frag as usize);
                has_gas = self.n_rt[frag as usize] > 0.0;
                sum = six_v[frag as usize];
            }
            // Spelled out rather than `t.map(..)`: the array map was once left as a call that
            // went through the stack and doubled the cost of this loop (XPBD, explicit).
            let p = [x[t[0] as usize].as_dvec3() - o, x[t[1] as usize].as_dvec3() - o, x[t[2] as usize].as_dvec3() - o];
            let across = p[1].cross(p[2]);
            sum += p[0].dot(across);
            if has_gas {
                // ∂/∂a of a·(b×c)/6 = (b×c)/6, cyclic.
                out[t[0] as usize] += (across * SIXTH).as_vec3();
                out[t[1] as usize] += (p[2].cross(p[0]) * SIXTH).as_vec3();
                out[t[2] as usize] += (p[0].cross(p[1]) * SIXTH).as_vec3();
            }
        }
        if last != u32::MAX {
            six_v[last as usize] = sum;
        }
        self.cap_gradient(x, out);
        self.finish(x);
    }

    /// [`Gas::measure`] in parallel fixed chunks of faces (the volumes differ in rounding only).
    #[cfg(test)]
    pub fn measure_parallel(&mut self, pool: &WorkerPool, x: &[Vec3], triangles: &[[u32; 3]]) {
        let fragments = self.fragment_count().max(1);
        let parts = pool.map_collect(triangles.len().div_ceil(FACE_CHUNK), |c| {
            let mut six_v = vec![0.0f64; fragments];
            self.face_chunk_volumes(x, triangles, c, &mut six_v);
            six_v
        });
        self.finish_face_chunks(x, &parts.concat());
    }

    /// Face chunk `c`'s part of 6 V per fragment into `six_v` (the parallel form of
    /// [`Gas::measure`]: every chunk, in any order or at the same time, then
    /// [`Gas::finish_face_chunks`]).
    pub fn face_chunk_volumes(&self, x: &[Vec3], triangles: &[[u32; 3]], c: usize, six_v: &mut [f64]) {
        let range = c * FACE_CHUNK..((c + 1) * FACE_CHUNK).min(triangles.len());
        six_v.fill(0.0);
        let reference = &self.reference_vertex;
        add_face_tets(x, |f| origin_of(reference, x, f), &triangles[range.clone()], &self.face_fragment[range], six_v);
    }

    /// Volumes, hole areas and pressures from the face chunks' parts (`parts`: `max(fragments,
    /// 1)` per chunk of [`FACE_CHUNK`] faces, in chunk order).
    pub fn finish_face_chunks(&mut self, x: &[Vec3], parts: &[f64]) {
        self.sum_face_chunks(parts);
        self.finish(x);
    }

    /// 6 V per fragment into `volume`: the face chunks' parts added in chunk order.
    fn sum_face_chunks(&mut self, parts: &[f64]) {
        self.volume.fill(0.0);
        for part in parts.chunks_exact(self.fragment_count().max(1)) {
            for (total, value) in self.volume.iter_mut().zip(part) {
                *total += value;
            }
        }
    }

    /// [`Gas::measure_with_gradient`] in parallel chunks: each vertex gathers the gradient terms
    /// of its corners (in face order; about the vertex itself in f32 on closed fans, so the
    /// gradient differs from the scattering form's in rounding there, and is the same to the
    /// bit elsewhere), and the volume is summed over fixed chunks of faces (the sums differ
    /// from the serial form's in rounding only). Fixed chunks: the same bits on any number of
    /// threads.
    pub fn measure_with_gradient_parallel(
        &mut self,
        pool: &WorkerPool,
        x: &[Vec3],
        triangles: &[[u32; 3]],
        out: &mut [Vec3],
    ) {
        let n = out.len();
        self.prepare_corners(triangles, n);
        let fragments = self.fragment_count().max(1);
        let face_chunks = triangles.len().div_ceil(FACE_CHUNK);
        let mut chunk_six_v = std::mem::take(&mut self.chunk_six_v);
        chunk_six_v.clear();
        chunk_six_v.resize(face_chunks * fragments, 0.0);
        let this = &*self;
        pool.for_each_chunk_mut(out, VERTEX_CHUNK, |c, out| this.gradient_rows(x, c * VERTEX_CHUNK, out));
        pool.for_each_chunk_mut(&mut chunk_six_v, fragments, |c, six_v| {
            this.face_chunk_volumes(x, triangles, c, six_v)
        });
        self.finish_gradient(x, &chunk_six_v, out);
        self.chunk_six_v = chunk_six_v;
    }

    /// Whether the corner lists are made for `n` vertices.
    #[cfg(test)]
    pub fn has_corners_for(&self, n: usize) -> bool {
        self.corner_offsets.len() == n + 1
    }

    /// Makes the corner lists and rings of the gradient for the `n` vertices and `triangles`
    /// unless they are made (the gathering form of the gradient uses them). A new body makes
    /// them before its first step (on the issue-5 balloon, 10,242
    /// vertices, about 1 ms that the first step took on top of its own work); after a topology
    /// change the cracking step makes them in its fracture phase
    /// ([`Gas::prepare_corners_after_change`]), so here they are made already.
    pub fn prepare_corners(&mut self, triangles: &[[u32; 3]], n: usize) {
        if self.corner_offsets.len() != n + 1 {
            self.build_corners(triangles, n, None, None);
        }
    }

    /// [`Gas::prepare_corners`] right after [`Gas::after_change`], whose rings are still those
    /// of the mesh before the change: with `changed` (per vertex, whether the change touched
    /// its fan: `Fracture::changed`) only the touched fans' rings are made again
    /// ([`FanRings::rebuild_keeping`]); with `fans`, the faces around each vertex from the
    /// topology of `triangles` (`vertex_face_offsets`, `vertex_faces`), the corners are read
    /// from those ([`Gas::corners_from_fans`]).
    pub fn prepare_corners_after_change(
        &mut self,
        triangles: &[[u32; 3]],
        n: usize,
        changed: Option<&[bool]>,
        fans: Option<(&[u32], &[u32])>,
    ) {
        if self.corner_offsets.len() != n + 1 {
            self.build_corners(triangles, n, changed, fans);
        }
    }

    /// `∂V/∂x` (without the caps' share) at the vertices `first..first + out.len()` into `out`
    /// (the volume is summed over faces apart, [`Gas::face_chunk_volumes`]: here, at the first
    /// corner of each face, its f64 term and the irregular branch to it took about half of the
    /// pass's instructions). Slices of eight vertices whose fans are closed rings with gas go
    /// eight at a time (`fan_rings`: on the issue-5 balloon the pass went from 420M to 165M
    /// instructions over 200 steps, callgrind, one thread).
    pub fn gradient_rows(&self, x: &[Vec3], first: usize, out: &mut [Vec3]) {
        let mut k = 0;
        while k < out.len() {
            let v = first + k;
            // Eight ring vertices of fragments with gas at a time (`fan_rings`).
            if k + SLICE <= out.len() && self.rings.is_whole_slice(v) && self.slice_has_gas(v) {
                self.rings.slice_gradient(x, v, &mut out[k..k + SLICE]);
                k += SLICE;
                continue;
            }
            out[k] = self.vertex_gradient(x, v);
            k += 1;
        }
    }

    /// Whether the faces around each of the eight vertices from `first` (a multiple of eight)
    /// hold gas ([`Gas::fan_has_gas`] of each).
    #[inline]
    fn slice_has_gas(&self, first: usize) -> bool {
        match self.slice_fragment.get(first / SLICE) {
            Some(&f) if f != u32::MAX => self.n_rt[f as usize] > 0.0,
            _ => (first..first + SLICE).all(|i| self.fan_has_gas(i)),
        }
    }

    /// Whether the faces around vertex v (one fragment when its fan is closed: fragments are the
    /// components joined through vertices) hold gas.
    #[inline]
    fn fan_has_gas(&self, v: usize) -> bool {
        let first = self.corner_offsets[v] as usize;
        first < self.corner_offsets[v + 1] as usize && self.n_rt[self.corners[first].fragment as usize] > 0.0
    }

    /// `∂V/∂x_v` (without the caps' share) one vertex at a time.
    fn vertex_gradient(&self, x: &[Vec3], v: usize) -> Vec3 {
        let fan = &self.corners[self.corner_offsets[v] as usize..self.corner_offsets[v + 1] as usize];
        if self.closed_fan[v] {
            // Around a closed ring `Σ (b - o)×(c - o) = Σ b×c` for any origin o, so the gradient
            // is summed about the vertex itself in f32: short edges, no cancellation (about o,
            // the f64 terms are ~|x - o|² for a sum the size of the fan's area). On the issue-5
            // balloon (one thread, perf) this pass went from 9.2% of an implicit step in f64 to
            // 6.0%.
            if !self.fan_has_gas(v) {
                return Vec3::ZERO;
            }
            if self.rings.is_ring(v) {
                return self.rings.gradient(x, v);
            }
            // Two rings meeting at v: its corners in face order, in two running sums (even and
            // odd corners).
            let xv = point(x, v);
            let across = |corner: &Corner| {
                let (b, c) = (point(x, corner.next as usize), point(x, corner.prev as usize));
                (b - xv).cross(c - xv)
            };
            let (mut even, mut odd) = (Vec3A::ZERO, Vec3A::ZERO);
            let pairs = fan.chunks_exact(2);
            let last = pairs.remainder().first().map_or(Vec3A::ZERO, across);
            for pair in pairs {
                even += across(&pair[0]);
                odd += across(&pair[1]);
            }
            return Vec3::from(((even + last) + odd) * (1.0 / 6.0));
        }
        let mut sum = Vec3::ZERO;
        for corner in fan {
            let frag = corner.fragment as usize;
            if self.n_rt[frag] > 0.0 {
                let o = origin_of(&self.reference_vertex, x, frag);
                let (p1, p2) = (x[corner.next as usize].as_dvec3() - o, x[corner.prev as usize].as_dvec3() - o);
                // ∂/∂a of a·(b×c)/6 = (b×c)/6, cyclic.
                sum += (p1.cross(p2) * SIXTH).as_vec3();
            }
        }
        sum
    }

    /// The end of the parallel gathering: adds the face chunks' parts of 6 V (`chunk_six_v`,
    /// `max(fragments, 1)` per chunk of [`FACE_CHUNK`] faces, in chunk order: the sums of
    /// [`Gas::finish_face_chunks`], to the bit) and the caps' share of the gradient `out`, and
    /// sets volumes, hole areas and pressures.
    pub fn finish_gradient(&mut self, x: &[Vec3], chunk_six_v: &[f64], out: &mut [Vec3]) {
        self.sum_face_chunks(chunk_six_v);
        self.cap_gradient(x, out);
        self.finish(x);
    }

    /// Room for a fraction `headroom` more vertices and corners in the corner lists and rings
    /// that a topology change makes again (see `headroom`), for a body that may crack.
    pub fn reserve_headroom(&mut self, headroom: f64) {
        with_room(&mut self.corner_offsets, headroom);
        with_room(&mut self.corners, headroom);
        with_room(&mut self.closed_fan, headroom);
        with_room(&mut self.slice_fragment, headroom);
        self.rings.reserve_headroom(headroom);
    }

    /// Takes the corner lists and rings of `old` (the gas before a change) to make this gas's
    /// own in ([`Gas::prepare_corners`] then writes them anew): in new buffers each of their
    /// pages faulted in on first use (about 650 page faults, 0.6-1 ms, of the issue-5 balloon's
    /// first cracking step).
    fn adopt_corner_buffers(&mut self, old: &mut Gas) {
        self.corner_offsets = std::mem::take(&mut old.corner_offsets);
        self.corner_offsets.clear();
        self.corners = std::mem::take(&mut old.corners);
        self.closed_fan = std::mem::take(&mut old.closed_fan);
        self.slice_fragment = std::mem::take(&mut old.slice_fragment);
        self.rings = std::mem::take(&mut old.rings);
    }

    /// Whether the corner lists, closed fans and rings are those a new build from `triangles`
    /// makes (tests of the rebuild that keeps the rings no change touched).
    #[cfg(test)]
    pub fn corners_are_a_new_build(&self, triangles: &[[u32; 3]], n: usize) -> bool {
        let mut fresh = Gas { corner_offsets: Vec::new(), rings: FanRings::default(), ..self.clone() };
        fresh.build_corners(triangles, n, None, None);
        format!("{:?}", (&fresh.corner_offsets, &fresh.corners, &fresh.closed_fan, &fresh.slice_fragment))
            == format!("{:?}", (&self.corner_offsets, &self.corners, &self.closed_fan, &self.slice_fragment))
            && fresh.rings.same_rings(&self.rings)
    }

    /// The corners of `triangles` into `offsets` and `corners` (CSR, faces ascending at each
    /// vertex), read vertex by vertex from the fans `(offsets, faces)` of a topology of the
    /// same triangles whose faces all have three distinct corners.
    ///
    /// Why, after a topology change: its fracture phase finds the corner lists cold in the
    /// cache (the whole surface was read and written since), where [`Gas::scatter_corners`]
    /// writes them at random (each vertex's next slot); this writes them in order and reads the
    /// triangles at random instead, which the processor overlaps. On the issue-5 balloon's
    /// first crack (tests/ probe, 2 threads, 7 runs each way) the pass took 0.21-0.27 ms against
    /// 0.40-0.53 ms, in the longer of the fracture phase's two parallel rebuilds. A one-thread
    /// callgrind count, which sees no cache, had found it dearer (4.6M against 3.8M
    /// instructions): kept for the body's creation, where there is no topology to read.
    fn corners_from_fans(
        &self,
        triangles: &[[u32; 3]],
        (fan_offsets, fan_faces): (&[u32], &[u32]),
        offsets: &mut Vec<u32>,
        corners: &mut Vec<Corner>,
    ) {
        #[cfg(test)]
        CORNERS_FROM_FANS.with(|count| count.set(count.get() + 1));
        offsets.clear();
        offsets.extend_from_slice(fan_offsets);
        corners.clear();
        for (v, range) in fan_offsets.windows(2).enumerate() {
            let v = v as u32;
            corners.extend(fan_faces[range[0] as usize..range[1] as usize].iter().map(|&f| {
                let t = triangles[f as usize];
                let (next, prev) = match () {
                    _ if t[0] == v => (t[1], t[2]),
                    _ if t[1] == v => (t[2], t[0]),
                    _ => {
                        debug_assert_eq!(t[2], v, "face {f} in the fan of vertex {v}");
                        (t[0], t[1])
                    }
                };
                Corner { next, prev, fragment: self.face_fragment[f as usize] }
            }));
        }
    }

    /// The corners of `triangles` over `n` vertices into `offsets` and `corners` (CSR, faces
    /// ascending at each vertex): a count, then one pass over the faces writing each corner in
    /// its place (a list of corner numbers first, then a pass reading the faces again for each,
    /// took 1.0 ms against 0.65 ms on a 16k-vertex sphere).
    fn scatter_corners(&self, triangles: &[[u32; 3]], n: usize, offsets: &mut Vec<u32>, corners: &mut Vec<Corner>) {
        offsets.clear();
        offsets.resize(n + 1, 0);
        for t in triangles {
            for &v in t {
                offsets[v as usize + 1] += 1;
            }
        }
        for v in 0..n {
            offsets[v + 1] += offsets[v];
        }
        let mut cursor = offsets[..n].to_vec();
        // Every slot is written below: only slots beyond the old length are filled first (a
        // clear then a fill wrote the issue-5 balloon's 0.7 MB of corners twice in each
        // fracture phase). The count runs over the triangles and the writes over them zipped
        // with their fragments: of different lengths, slots kept from the old buffer would stay
        // unwritten (the caller asserts they match).
        corners.truncate(offsets[n] as usize);
        corners.resize(offsets[n] as usize, Corner { next: 0, prev: 0, fragment: 0 });
        for (t, &fragment) in triangles.iter().zip(&self.face_fragment) {
            for c in 0..3 {
                let slot = &mut cursor[t[c] as usize];
                corners[*slot as usize] = Corner { next: t[(c + 1) % 3], prev: t[(c + 2) % 3], fragment };
                *slot += 1;
            }
        }
    }

    /// The corners at each vertex (CSR, faces ascending); with `fans`, the faces around each
    /// vertex of the current triangles (a topology's `vertex_face_offsets` and `vertex_faces`),
    /// read from those in vertex order ([`Gas::corners_from_fans`]).
    fn build_corners(
        &mut self,
        triangles: &[[u32; 3]],
        n: usize,
        changed: Option<&[bool]>,
        fans: Option<(&[u32], &[u32])>,
    ) {
        debug_assert_eq!(triangles.len(), self.face_fragment.len());
        let mut offsets = std::mem::take(&mut self.corner_offsets);
        let mut corners = std::mem::take(&mut self.corners);
        // A face with a repeated corner is once in each of its vertices' fans but has three
        // corners: then the fans do not list every corner, and the corners are scattered.
        match fans
            .filter(|(fan_offsets, fan_faces)| fan_offsets.len() == n + 1 && fan_faces.len() == 3 * triangles.len())
        {
            Some(fans) => self.corners_from_fans(triangles, fans, &mut offsets, &mut corners),
            None => self.scatter_corners(triangles, n, &mut offsets, &mut corners),
        }
        self.corner_offsets = offsets;
        self.corners = corners;
        // The rings first: a fan that walks as one ring is closed, and only the others (open
        // fans and two cones meeting at a vertex, a few on most meshes) are compared sorted.
        // (Every list is reused from vertex to vertex: see `FanRings::new`.)
        let (offsets, corners) = (&self.corner_offsets, &self.corners);
        let fan = |v: usize| &corners[offsets[v] as usize..offsets[v + 1] as usize];
        let walk = |v: usize, out: &mut Vec<(u32, u32)>| {
            out.extend(fan(v).iter().map(|c| (c.next, c.prev)));
            !out.is_empty()
        };
        match changed {
            // (A vertex past the marks is new: changed.)
            Some(changed) => self.rings.rebuild_keeping(n, walk, |v| changed.get(v) == Some(&false)),
            None => self.rings.rebuild(n, walk),
        }
        let (mut next, mut prev) = (Vec::new(), Vec::new());
        let mut closed_fan = std::mem::take(&mut self.closed_fan);
        closed_fan.clear();
        closed_fan.extend((0..n).map(|v| {
            if self.rings.is_ring(v) {
                return true;
            }
            next.clear();
            prev.clear();
            next.extend(fan(v).iter().map(|c| c.next));
            prev.extend(fan(v).iter().map(|c| c.prev));
            next.sort_unstable();
            prev.sort_unstable();
            !fan(v).is_empty() && next == prev
        }));
        self.closed_fan = closed_fan;
        // The fragment of a vertex's fan is that of its first corner (`fan_has_gas`).
        let first_fragment = |v: usize| {
            let first = offsets[v] as usize;
            (first < offsets[v + 1] as usize).then(|| corners[first].fragment)
        };
        let mut slice_fragment = std::mem::take(&mut self.slice_fragment);
        slice_fragment.clear();
        slice_fragment.extend((0..n / SLICE).map(|s| {
            let f = first_fragment(s * SLICE);
            match f {
                Some(f) if (s * SLICE..(s + 1) * SLICE).all(|v| first_fragment(v) == Some(f)) => f,
                _ => u32::MAX,
            }
        }));
        self.slice_fragment = slice_fragment;
    }

    /// Adds the caps to the face sums of 6 V per fragment (left in `volume` by the caller: a
    /// buffer per call was an allocation per force evaluation) and sets volumes, hole areas and
    /// pressures.
    fn finish(&mut self, x: &[Vec3]) {
        let (six_v, open) = (&mut self.volume, &mut self.open_area);
        open.fill(0.0);
        for cap in &self.caps {
            let f = cap.fragment as usize;
            let (o, c) = (origin_of(&self.reference_vertex, x, f), ring_center(x, &cap.ring));
            for (k, &a) in cap.ring.iter().enumerate() {
                let b = cap.ring[(k + 1) % cap.ring.len()];
                let (pa, pb) = (x[a as usize].as_dvec3(), x[b as usize].as_dvec3());
                six_v[f] += tet(o, c, pa, pb);
                open[f] += 0.5 * (pa - c).cross(pb - c).length();
            }
        }
        for six_v in six_v.iter_mut() {
            *six_v /= 6.0;
        }
        self.refresh_pressures();
    }

    /// The pressures (and `clamped`) from the last measured volumes and the current nRT (which a
    /// leak changes after the measurement).
    pub fn refresh_pressures(&mut self) {
        self.clamped = false;
        for f in 0..self.fragment_count() {
            let volume = self.volume[f];
            if self.n_rt[f] <= 0.0 {
                self.pressure[f] = 0.0;
                continue;
            }
            if volume < self.v_min[f] {
                self.clamped = true;
            }
            self.pressure[f] = self.n_rt[f] / volume.max(self.v_min[f]).max(f64::MIN_POSITIVE);
        }
    }

    /// Writes `∂V_f/∂x_i` into `out[i]` for every vertex i (f its fragment; 0 for vertices of
    /// fragments without gas). Exact for the capped volume (SPEC 2.1: `= (1/3) Σ A_f n_f` on a
    /// closed mesh).
    #[cfg(test)]
    pub fn volume_gradient(&self, x: &[Vec3], triangles: &[[u32; 3]], out: &mut [Vec3]) {
        let face_fragment = &self.face_fragment;
        out.iter_mut().for_each(|g| *g = Vec3::ZERO);
        let origin = |f: usize| origin_of(&self.reference_vertex, x, f);
        for (t, &frag) in triangles.iter().zip(face_fragment) {
            if self.n_rt[frag as usize] <= 0.0 {
                continue;
            }
            let o = origin(frag as usize);
            let p = t.map(|v| x[v as usize].as_dvec3() - o);
            // ∂/∂a of a·(b×c)/6 = (b×c)/6, cyclic.
            out[t[0] as usize] += (p[1].cross(p[2]) * SIXTH).as_vec3();
            out[t[1] as usize] += (p[2].cross(p[0]) * SIXTH).as_vec3();
            out[t[2] as usize] += (p[0].cross(p[1]) * SIXTH).as_vec3();
        }
        self.cap_gradient(x, out);
    }

    /// The caps' share of `∂V/∂x`: each cap centre's gradient goes to its ring equally.
    fn cap_gradient(&self, x: &[Vec3], out: &mut [Vec3]) {
        let origin = |f: usize| origin_of(&self.reference_vertex, x, f);
        for cap in &self.caps {
            let f = cap.fragment as usize;
            if self.n_rt[f] <= 0.0 {
                continue;
            }
            let o = origin(f);
            let c = ring_center(x, &cap.ring) - o;
            let share = 1.0 / cap.ring.len() as f64;
            let mut grad_c = DVec3::ZERO;
            for (k, &a) in cap.ring.iter().enumerate() {
                let b = cap.ring[(k + 1) % cap.ring.len()];
                let (pa, pb) = (x[a as usize].as_dvec3() - o, x[b as usize].as_dvec3() - o);
                grad_c += pa.cross(pb) / 6.0;
                out[a as usize] += (pb.cross(c) / 6.0).as_vec3();
                out[b as usize] += (c.cross(pa) / 6.0).as_vec3();
            }
            for &a in &cap.ring {
                out[a as usize] += (grad_c * share).as_vec3();
            }
        }
    }

    /// A bound of the largest eigenvalue of `M⁻¹ K_gas` (1/s²), `K_gas` the stiffness of the
    /// pressure forces `P ∂V/∂x_i` (SPEC 2.1 eq. 8-9) at the last measured state:
    /// `-∂f/∂x = -P ∂²V/∂x² + (P/V) ∇V ∇Vᵀ`. The first term's block `∂²V/∂x_a∂x_b` is
    /// `[x_d - x_c]×/6` (c, d the corners across edge ab), so its row of vertex a is at most
    /// `P/6 Σ_{faces ∋ a} (|x_b - x_a| + |x_c - x_a|)` (Gershgorin); the second is of rank one
    /// per fragment, eigenvalue `(P/V) Σ w_i |∇_i V|²` with `|∇_i V| <= Σ_{faces ∋ i} A_f / 3`.
    /// (Below the clamp the pressure no longer follows V: the rank-one term is left out there.
    /// The caps are left out: an estimate.) Why: the stable step of the explicit integrators
    /// counted the springs alone, and a ball of nRT 1e9 J at K_s 1000 N/m was advised 30
    /// substeps where it needs thousands (found by review).
    pub fn stiffness_rate_bound(&self, x: &[Vec3], triangles: &[[u32; 3]], inv_mass: &[f32]) -> f64 {
        let n = x.len();
        let (mut row, mut grad) = (vec![0.0f64; n], vec![0.0f64; n]);
        for (t, &frag) in triangles.iter().zip(&self.face_fragment) {
            let p = self.pressure[frag as usize];
            if p <= 0.0 {
                continue;
            }
            let c = t.map(|i| x[i as usize].as_dvec3());
            let area = 0.5 * (c[1] - c[0]).cross(c[2] - c[0]).length();
            for k in 0..3 {
                let (a, b, d) = (c[k], c[(k + 1) % 3], c[(k + 2) % 3]);
                row[t[k] as usize] += p / 6.0 * ((b - a).length() + (d - a).length());
                grad[t[k] as usize] += area / 3.0;
            }
        }
        let mut rank_one = vec![0.0f64; self.fragment_count()];
        for (i, &frag) in self.vertex_fragment.iter().enumerate() {
            if frag != u32::MAX {
                rank_one[frag as usize] += inv_mass[i] as f64 * grad[i] * grad[i];
            }
        }
        let most_rank_one = (0..self.fragment_count())
            .filter(|&f| self.n_rt[f] > 0.0 && self.volume[f] > self.v_min[f])
            .map(|f| self.pressure[f] / self.volume[f] * rank_one[f])
            .fold(0.0, f64::max);
        let most_row = row.iter().zip(inv_mass).map(|(&r, &w)| r * w as f64).fold(0.0, f64::max);
        most_row + most_rank_one
    }

    /// Gas energy `Σ_f -nRT ln V` (continued linearly below the clamp, matching the clamped
    /// force), J.
    pub fn energy(&self) -> f64 {
        (0..self.fragment_count())
            .filter(|&f| self.n_rt[f] > 0.0)
            .map(|f| {
                let (v, vmin) = (self.volume[f], self.v_min[f].max(f64::MIN_POSITIVE));
                if v >= vmin {
                    -self.n_rt[f] * v.ln()
                } else {
                    -self.n_rt[f] * vmin.ln() - self.pressure[f] * (v - vmin)
                }
            })
            .sum()
    }

    /// SPEC 2.4 leak: `d(nRT)/dt = -leak_rate A_open (P - P_ext)` with `P_ext = 0` (the gas
    /// pressure is a gauge pressure), integrated exactly over `h`:
    /// `nRT *= exp(-h leak_rate A_open / V)`.
    pub fn leak(&mut self, h: f64, leak_rate: f64) {
        for f in 0..self.fragment_count() {
            if self.n_rt[f] > 0.0 && self.open_area[f] > 0.0 {
                let v = self.volume[f].max(self.v_min[f]).max(f64::MIN_POSITIVE);
                self.n_rt[f] *= (-h * leak_rate * self.open_area[f] / v).exp();
            }
        }
    }

    /// Hands the gas of `old` (the gas before a topology change) to this one, made for the
    /// fragments after it: each new fragment's parent is the old gas fragment of its first
    /// surviving face, and a parent's nRT is split between its children in proportion to their
    /// (capped) volumes, so the pressure does not jump. Shreds, children with less than
    /// [`SHRED_FRACTION`] of their parent's volume before the change, get no gas: it escapes
    /// through the burst (a gas in a near-zero volume would be arbitrarily stiff,
    /// `∂P/∂V = -P/V`). ([`Gas::after_change`] then gathers the fragments without gas,
    /// [`Gas::keep_fragments_with_gas`].)
    pub fn inherit(&mut self, old: &Gas, x: &[Vec3], triangles: &[[u32; 3]]) {
        let (old_n_rt, old_volume, old_face_fragment) = (&old.n_rt, &old.volume, &old.face_fragment);
        let n = self.fragment_count();
        let mut parent = Self::parents(&self.face_fragment, n, old_face_fragment);
        // Volumes of the new fragments with a unit gas so that measure() fills them.
        self.n_rt.iter_mut().for_each(|g| *g = 1.0);
        self.v_min.iter_mut().for_each(|v| *v = 0.0);
        self.measure(x, triangles);
        let mut total = vec![0.0f64; old_n_rt.len()];
        for f in 0..n {
            if parent[f] != u32::MAX {
                total[parent[f] as usize] += self.volume[f].max(0.0);
            }
        }
        for f in 0..n {
            if parent[f] != u32::MAX && self.volume[f] < SHRED_FRACTION * old_volume[parent[f] as usize].abs() {
                parent[f] = u32::MAX;
            }
        }
        // Shares over the children that keep gas.
        total.iter_mut().for_each(|t| *t = 0.0);
        for f in 0..n {
            if parent[f] != u32::MAX {
                total[parent[f] as usize] += self.volume[f].max(0.0);
            }
        }
        for f in 0..n {
            let (gas, volume) = match parent[f] {
                p if p != u32::MAX && total[p as usize] > 0.0 && old_n_rt[p as usize] > 0.0 => {
                    let v = self.volume[f].max(0.0);
                    (old_n_rt[p as usize] * v / total[p as usize], v)
                }
                _ => (0.0, 0.0),
            };
            self.assign(f, gas, volume);
        }
        // The volumes are those measured above (the positions have not moved): only the
        // pressures follow the new nRT (a second measurement was a pass over every face, about
        // 0.07 ms of the issue-5 balloon's first cracking step).
        self.refresh_pressures();
    }

    /// Keeps the fragments that hold gas, numbered in their order, and gathers all the others
    /// (pieces whose gas escaped: shreds, pieces of a burst) into one more fragment without gas
    /// and without caps. A burst leaves thousands of pieces and a few with gas (the issue-5
    /// balloon at 3% strain: 15,000 pieces 60 steps after its first crack, 100-160 with gas):
    /// kept as fragments, every pass of a step summed, reset and looked up per fragment, and
    /// slices of eight vertices mixed their fragments: its steps 60-99 took 58-65 ms on one
    /// thread and 46-47 ms on two, now 34-39 and 30-32 ms, the same steps to the bit (broken
    /// springs, vertices, pieces and CG iterations of every cracking step alike). Nothing
    /// changes when every fragment holds gas.
    fn keep_fragments_with_gas(&mut self, triangles: &[[u32; 3]]) {
        let n = self.fragment_count();
        let holders: Vec<usize> = (0..n).filter(|&f| self.n_rt[f] > 0.0).collect();
        if holders.len() == n {
            return;
        }
        let without = holders.len() as u32;
        let mut kept = vec![without; n];
        for (k, &f) in holders.iter().enumerate() {
            kept[f] = k as u32;
        }
        let face_fragment: Vec<u32> = self.face_fragment.iter().map(|&f| kept[f as usize]).collect();
        let mut gas = Gas::new(self.vertex_fragment.len(), triangles, &face_fragment, holders.len() + 1, &[]);
        // Their vertices count as vertices without gas: the solver's passes then take their
        // slices without a gas term (a zero one before).
        for f in gas.vertex_fragment.iter_mut().filter(|f| **f == without) {
            *f = u32::MAX;
        }
        gas.slice_vertex_fragment = slice_fragments(&gas.vertex_fragment);
        gas.caps = std::mem::take(&mut self.caps)
            .into_iter()
            .filter(|cap| kept[cap.fragment as usize] != without)
            .map(|cap| Cap { fragment: kept[cap.fragment as usize], ring: cap.ring })
            .collect();
        for (k, &f) in holders.iter().enumerate() {
            gas.n_rt[k] = self.n_rt[f];
            gas.v_min[k] = self.v_min[f];
            gas.volume[k] = self.volume[f];
            gas.open_area[k] = self.open_area[f];
        }
        gas.refresh_pressures();
        *self = gas;
    }

    pub fn memory_bytes(&self) -> usize {
        (self.n_rt.capacity()
            + self.v_min.capacity()
            + self.volume.capacity()
            + self.pressure.capacity()
            + self.open_area.capacity())
            * 8
            + (self.face_fragment.capacity()
                + self.vertex_fragment.capacity()
                + self.slice_vertex_fragment.capacity()
                + self.reference_vertex.capacity()
                + self.corner_offsets.capacity()
                + self.slice_fragment.capacity())
                * 4
            + self.closed_fan.capacity()
            + self.corners.capacity() * std::mem::size_of::<Corner>()
            + self.rings.memory_bytes()
            + self.chunk_six_v.capacity() * 8
            + self.caps.capacity() * std::mem::size_of::<Cap>()
            + self.caps.iter().map(|c| c.ring.capacity() * 4).sum::<usize>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A slice's shared fragment: one fragment, none (`u32::MAX`), mixed (two fragments, or
    /// gas and none), and a last slice of three entries by those it has.
    #[test]
    fn slices_share_a_fragment_or_are_mixed() {
        let none = u32::MAX;
        let mut fragment = vec![4; 8];
        fragment.extend([none; 8]);
        fragment.extend([1, 1, 1, 1, 1, 1, 1, 2]);
        fragment.extend([none, 3, 3, 3, 3, 3, 3, 3]);
        fragment.extend([5, 5, 5]);
        assert_eq!(slice_fragments(&fragment), [4, none, MIXED_FRAGMENTS, MIXED_FRAGMENTS, 5]);
        assert!(slice_fragments(&[]).is_empty());
    }

    fn tetra() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        (vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z], vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    }

    /// A fan is closed when its faces' next and previous corners are the same lists (sorted),
    /// and a ring when it closes one single ring: made by walking the rings first, both come
    /// out as that definition says on open fans (a tetrahedron without a face), on two cones
    /// meeting at a vertex (a second tetrahedron on vertex 0) and on fans that are rings.
    #[test]
    fn closed_fans_and_rings_follow_the_corners() {
        let (_, a) = tetra();
        // The second tetrahedron on vertices 0, 4, 5, 6; the first without its face [1, 2, 3].
        let b: Vec<[u32; 3]> = a.iter().map(|f| f.map(|v| if v == 0 { 0 } else { v + 3 })).collect();
        let t: Vec<[u32; 3]> = a.iter().chain(&b).copied().filter(|f| *f != [1, 2, 3]).collect();
        let n = 7;
        let mut gas = Gas::new(n, &t, &vec![0; t.len()], 1, &[]);
        assert!(!gas.has_corners_for(n));
        gas.prepare_corners(&t, n);
        assert!(gas.has_corners_for(n));
        for v in 0..n as u32 {
            let (mut next, mut prev): (Vec<u32>, Vec<u32>) = t
                .iter()
                .filter_map(|f| f.iter().position(|&i| i == v).map(|c| (f[(c + 1) % 3], f[(c + 2) % 3])))
                .unzip();
            next.sort_unstable();
            prev.sort_unstable();
            let closed = !next.is_empty() && next == prev;
            assert_eq!(gas.closed_fan[v as usize], closed, "vertex {v}");
            // Vertex 0 closes two rings (one per tetrahedron), 1-3 none, 4-6 one each.
            assert_eq!(gas.rings.is_ring(v as usize), v >= 4, "vertex {v}");
            assert_eq!(closed, v == 0 || v >= 4, "vertex {v}");
        }
    }

    /// The corners read from a topology's fans are those scattered from the faces, slot for
    /// slot, with each face's fragment: on two tetrahedra meeting at a vertex (one open, two
    /// fragments, faces out of vertex order); and with a face whose corner repeats (its fans
    /// then miss a corner), the corners are scattered instead, as a new build makes them.
    #[test]
    fn corners_from_fans_are_the_scattered_corners() {
        let (_, a) = tetra();
        let b: Vec<[u32; 3]> = a.iter().map(|f| f.map(|v| if v == 0 { 0 } else { v + 3 })).collect();
        let mut t: Vec<[u32; 3]> = b.iter().chain(&a).copied().filter(|f| *f != [1, 2, 3]).collect();
        let n = 7;
        let fragments: Vec<u32> = (0..t.len() as u32).map(|f| u32::from(f >= 4)).collect();
        let scattered = |t: &[[u32; 3]], fragments: &[u32]| {
            let mut gas = Gas::new(n, t, fragments, 2, &[]);
            gas.prepare_corners(t, n);
            gas
        };
        let debug =
            |gas: &Gas| format!("{:?}", (&gas.corner_offsets, &gas.corners, &gas.closed_fan, &gas.slice_fragment));
        for degenerate in [false, true] {
            if degenerate {
                t.push([4, 5, 4]);
            }
            let fragments: Vec<u32> = fragments.iter().copied().chain(degenerate.then_some(0)).collect();
            let topology = crate::mesh::Topology::build(&t, n);
            assert_eq!(topology.vertex_faces.len() == 3 * t.len(), !degenerate);
            let mut from_fans = Gas::new(n, &t, &fragments, 2, &[]);
            let read_from_fans = CORNERS_FROM_FANS.with(|count| count.get());
            from_fans.prepare_corners_after_change(
                &t,
                n,
                None,
                Some((&topology.vertex_face_offsets, &topology.vertex_faces)),
            );
            // The fans were read, but for the degenerate face (its corners were scattered).
            assert_eq!(CORNERS_FROM_FANS.with(|count| count.get()) - read_from_fans, usize::from(!degenerate));
            let reference = scattered(&t, &fragments);
            assert_eq!(debug(&from_fans), debug(&reference), "degenerate face: {degenerate}");
            assert!(from_fans.rings.same_rings(&reference.rings));
            assert!(
                from_fans.corners.iter().any(|c| c.fragment == 1) && from_fans.corners.iter().any(|c| c.fragment == 0)
            );
        }
    }

    /// The room reserved for a body that may crack is for corner lists and rings that were
    /// made: a gas without them gets none (it held spare ring buffers, found by review; every
    /// body with gas now makes them, but the reservation still follows what exists).
    #[test]
    fn a_gas_without_corners_reserves_no_room_for_them() {
        let (_, t) = tetra();
        let mut gas = Gas::new(4, &t, &vec![0; t.len()], 1, &[]);
        let before = gas.memory_bytes();
        gas.reserve_headroom(0.125);
        assert_eq!(gas.memory_bytes(), before, "room for corners never made");
        gas.prepare_corners(&t, 4);
        let made = gas.memory_bytes();
        gas.reserve_headroom(0.125);
        assert!(gas.memory_bytes() > made, "room for the corners made");
    }

    #[test]
    fn closed_volume_and_gradient_match_finite_differences() {
        let (mut x, t) = tetra();
        let ff = vec![0; 4];
        let mut gas = Gas::new(4, &t, &ff, 1, &[]);
        gas.assign(0, 1.0, 1.0 / 6.0);
        gas.measure(&x, &t);
        assert!((gas.volume[0] - 1.0 / 6.0).abs() < 1e-7);
        let mut g = vec![Vec3::ZERO; 4];
        gas.volume_gradient(&x, &t, &mut g);
        check_gradient(&mut gas, &mut x, &t, &g);
    }

    fn check_gradient(gas: &mut Gas, x: &mut [Vec3], t: &[[u32; 3]], g: &[Vec3]) {
        let h = 1e-3f32;
        for v in 0..x.len() {
            for axis in 0..3 {
                let keep = x[v];
                x[v][axis] += h;
                gas.measure(x, t);
                let plus = gas.volume[0];
                x[v] = keep;
                x[v][axis] -= h;
                gas.measure(x, t);
                let minus = gas.volume[0];
                x[v] = keep;
                let fd = (plus - minus) / (2.0 * h as f64);
                assert!((fd - g[v][axis] as f64).abs() < 1e-4, "vertex {v} axis {axis}: {fd} vs {}", g[v][axis]);
            }
        }
    }

    #[test]
    fn capped_open_mesh_has_the_closed_volume_and_an_exact_gradient() {
        // A square pyramid without its base: the cap closes it.
        let mut x = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.5, 1.0, 0.5),
        ];
        let t = vec![[0, 4, 1], [1, 4, 2], [2, 4, 3], [3, 4, 0]];
        let ff = vec![0; 4];
        let topo = crate::mesh::Topology::build(&t, 5);
        let mut gas = Gas::new(5, &t, &ff, 1, &topo.boundary_loops);
        gas.assign(0, 2.0, 1.0 / 3.0);
        gas.measure(&x, &t);
        assert!((gas.volume[0] - 1.0 / 3.0).abs() < 1e-6, "{}", gas.volume[0]);
        assert!((gas.open_area[0] - 1.0).abs() < 1e-6);
        assert!((gas.pressure[0] - 6.0).abs() < 1e-4);
        x[1].y += 0.1; // make the cap non-planar
        let mut g = vec![Vec3::ZERO; 5];
        gas.volume_gradient(&x, &t, &mut g);
        check_gradient(&mut gas, &mut x, &t, &g);
        // The one-pass form gives the same volume, pressure and gradient.
        gas.measure(&x, &t);
        let (volume, pressure, open) = (gas.volume[0], gas.pressure[0], gas.open_area[0]);
        let mut fused = vec![Vec3::ONE; 5];
        gas.measure_with_gradient(&x, &t, &mut fused);
        assert!((gas.volume[0] - volume).abs() < 1e-12 && (gas.pressure[0] - pressure).abs() < 1e-9);
        assert_eq!(gas.open_area[0], open);
        for (a, b) in fused.iter().zip(&g) {
            assert!((*a - *b).length() < 1e-6, "{a} vs {b}");
        }
        // The parallel gathering form: the same gradient to rounding (about the vertex itself
        // on closed fans, the apex here; to the bit elsewhere) and for any thread count, the
        // same volume.
        let mut serial = vec![Vec3::ONE; 5];
        gas.measure_with_gradient_parallel(&WorkerPool::new(1).unwrap(), &x, &t, &mut serial);
        assert!(gas.closed_fan[4] && !gas.closed_fan[0]);
        for (v, (a, b)) in serial.iter().zip(&fused).enumerate() {
            assert!((*a - *b).length() <= 1e-6 * b.length(), "vertex {v}: {a} vs {b}");
            if v != 4 {
                assert_eq!(a, b);
            }
        }
        for threads in [1, 2] {
            let mut gathered = vec![Vec3::ONE; 5];
            gas.measure_with_gradient_parallel(&WorkerPool::new(threads).unwrap(), &x, &t, &mut gathered);
            assert_eq!(gathered, serial);
            assert!((gas.volume[0] - volume).abs() < 1e-12 && gas.open_area[0] == open);
            gas.measure_parallel(&WorkerPool::new(threads).unwrap(), &x, &t);
            assert!((gas.volume[0] - volume).abs() < 1e-12 && gas.open_area[0] == open);
        }
    }

    /// Three closed bipyramids of twelve vertices each (three fragments): the slices of eight
    /// vertices are one of the first fragment, one across the first two, one of the second and
    /// one of the third (whose vertices keep the first three slices' rings below the last point,
    /// as eight at a time needs). The gathered gradient (eight vertices at a time where a slice's fans all
    /// hold gas) is the scattered one to rounding, with gas in every fragment and with none in
    /// the second.
    #[test]
    fn slices_of_one_fragment_or_two_gather_the_gradient() {
        let ring = 10u32;
        let (mut x, mut t, mut ff) = (Vec::new(), Vec::new(), Vec::new());
        let centres = [Vec3::ZERO, Vec3::new(5.0, 0.5, -1.0), Vec3::new(-3.0, 4.0, 2.0)];
        for (fragment, centre) in centres.into_iter().enumerate() {
            let base = x.len() as u32;
            x.push(centre + Vec3::Y * 1.3);
            x.push(centre - Vec3::Y * 0.9);
            for k in 0..ring {
                let angle = k as f32 * std::f32::consts::TAU / ring as f32;
                x.push(centre + Vec3::new(angle.cos(), 0.1 * (3.0 * angle).sin(), angle.sin()));
            }
            for k in 0..ring {
                let (a, b) = (base + 2 + k, base + 2 + (k + 1) % ring);
                t.push([base, b, a]);
                t.push([base + 1, a, b]);
                ff.extend([fragment as u32; 2]);
            }
        }
        let n = x.len();
        assert_eq!(n, 36);
        let mut gas = Gas::new(n, &t, &ff, 3, &[]);
        for with_gas in [[1.0, 1.0, 1.0], [1.0, 0.0, 1.0]] {
            for (f, &n_rt) in with_gas.iter().enumerate() {
                gas.assign(f, n_rt, 1.0);
            }
            let mut gathered = vec![Vec3::ONE; n];
            gas.measure_with_gradient_parallel(&WorkerPool::new(1).unwrap(), &x, &t, &mut gathered);
            assert_eq!(gas.slice_fragment, [0, u32::MAX, 1, 2]);
            // (The fourth slice's rings reach the last point: one vertex at a time.)
            assert!((0..3).all(|s| gas.rings.is_whole_slice(8 * s)), "the first three slices go eight at a time");
            let mut scattered = vec![Vec3::ZERO; n];
            gas.volume_gradient(&x, &t, &mut scattered);
            for (v, (a, b)) in gathered.iter().zip(&scattered).enumerate() {
                assert!((*a - *b).length() <= 1e-5 * (1.0 + b.length()), "{with_gas:?}, vertex {v}: {a} vs {b}");
            }
            let moved = |range: std::ops::Range<usize>| gathered[range].iter().all(|g| g.length() > 1e-3);
            assert!(moved(0..12) && moved(24..36));
            assert_eq!(moved(12..24), with_gas[1] > 0.0, "{with_gas:?}");
        }
    }

    /// The face volumes four at a time are the same bits as one at a time (two fragments with
    /// their own origins, a face at the last point, a tail of faces).
    /// The faces' 6 V terms eight at a time (AVX2) are those one at a time, to the bit (groups
    /// of one fragment and mixed ones, groups with the last point), and their sums are those of
    /// the f64 tetrahedra about the origins to the f32 terms' rounding.
    #[test]
    fn face_tets_eight_at_a_time_are_bitwise_one_at_a_time() {
        let mut unit = crate::body::test_randoms(0x7e7_7e7_7e7);
        let n = 40;
        let x: Vec<Vec3> = (0..n).map(|_| Vec3::new(unit(), unit(), unit()) * 5.0 + Vec3::splat(100.0)).collect();
        let faces: Vec<[u32; 3]> =
            (0..103u32).map(|k| [(k * 7) % n as u32, (k * 11 + 3) % n as u32, (k * 13 + 5) % n as u32]).collect();
        assert!(faces.iter().flatten().any(|&i| i as usize == n - 1));
        let origin = [DVec3::new(100.0, 101.0, 99.0), DVec3::new(0.25, -3.0, 7.0)];
        // Fragments alternating often (mixed groups of four), and in long runs (whole groups).
        for fragment_of in [|k: usize| (k % 5 == 0) as u32, |k: usize| ((k / 37) % 2) as u32] {
            let fragments: Vec<u32> = (0..faces.len()).map(fragment_of).collect();
            for first in [0, 1, 6] {
                let (mut fast, mut plain) = ([0.0f64; 2], [0.0f64; 2]);
                add_face_tets(&x, |f| origin[f], &faces[first..], &fragments[first..], &mut fast);
                add_face_tets_scalar(&x, |f| origin[f], &faces[first..], &fragments[first..], &mut plain);
                assert_eq!(fast.map(f64::to_bits), plain.map(f64::to_bits));
                // And the sums are the faces' terms added one by one, up to rounding.
                let (mut one_by_one, mut magnitude) = ([0.0f64; 2], [0.0f64; 2]);
                for (t, &f) in faces[first..].iter().zip(&fragments[first..]) {
                    let p = |i: u32| x[i as usize].as_dvec3();
                    let term = tet(origin[f as usize], p(t[0]), p(t[1]), p(t[2]));
                    one_by_one[f as usize] += term;
                    magnitude[f as usize] += term.abs();
                }
                for ((got, want), size) in plain.iter().zip(one_by_one).zip(magnitude) {
                    assert!(*got != 0.0 && (got - want).abs() <= 1e-6 * size, "{got} vs {want} (terms' size {size})");
                }
            }
        }
    }

    #[test]
    fn clamp_and_leak() {
        let (mut x, t) = tetra();
        let ff = vec![0; 4];
        let mut gas = Gas::new(4, &t, &ff, 1, &[]);
        gas.assign(0, 1.0, 1.0 / 6.0);
        x[3] = Vec3::new(0.0, 0.0, -0.5); // inverted
        gas.measure(&x, &t);
        assert!(gas.clamped && gas.pressure[0].is_finite() && gas.pressure[0] > 0.0);
        assert!(gas.energy().is_finite());
        gas.open_area[0] = 1.0;
        gas.leak(1.0, 1.0);
        assert!(gas.n_rt[0] < 1.0 && gas.n_rt[0] >= 0.0);
    }
}
