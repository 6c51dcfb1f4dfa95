//! The two continuous collision queries, vertex-triangle and edge-edge, in double precision
//! (SPEC 1.6): filters first, then the inclusion search. Never a false negative; the reported
//! time of impact is never later than the true first time the distance reaches the thickness.

use super::filters::{V3, plane_distance_filter, sub, swept_aabbs_separated};
use super::hull_filter::separated_piecewise;
use super::inclusion::{self, SearchQueues};
use super::self_contact::{closest_on_triangle, closest_segments};
use glam::DVec3;

/// Coordinates (and thicknesses) above this magnitude are not searched: the query answers the
/// conservative "hit at t = 0". Keeps every intermediate of the search far from overflow.
const LARGEST_COORDINATE: f64 = 1.0715086071862673e301; // 2^1000

/// Tuning of the exact stage. The defaults suit any scale (the tolerance is relative).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CcdSettings {
    /// Most sub-domains the exact stage examines before answering the conservative "hit at the
    /// earliest time not yet ruled out". Bounds the worst-case time of one query.
    pub max_boxes: u32,
    /// A sub-domain whose gap values all lie within `tolerance` of the thickness (per axis) is
    /// reported as a hit, with `tolerance` this times the largest displacement of a point over
    /// the step (but at least its square times the extent of the points, and at least 1/64 of
    /// the thickness). Near misses closer
    /// than about that may therefore be reported as hits (false positives), never the other way
    /// round, and the time of impact is early by at most about this fraction of the step.
    pub relative_tolerance: f64,
    /// When set to `s >= 0`: the distance of a pair that survives the filters is computed at 9
    /// evenly spaced times (t = k/8). If one is within `thickness (1 + s)` the pair is reported
    /// as a hit without the inclusion search ([`Stage::SampledContact`]): a certain contact (up to
    /// the rounding of that distance, which can only add a near miss) when within the thickness,
    /// a false positive otherwise (a slack up to 3/4 stays inside what the search itself may
    /// report: it accepts a pair whose gap is within the thickness plus its tolerance in the
    /// max-norm, i.e. up to about `sqrt(3) (1 + 1/64) ~ 1.76` thicknesses apart).
    /// The time is then not searched but estimated from below: the distance shrinks at most at
    /// the speed `L` (the sum of the two primitives' largest vertex displacements over the step),
    /// so between two samples `t_j`, `t_j+1` it stays above `(d_j + d_j+1 - L (t_j+1 - t_j)) / 2`;
    /// with `r = thickness (1 + s)` the answer is `t_j + (d_j - r) / L` for the first interval
    /// where that bound does not exceed `r`. That bound is then refined by bisection towards the
    /// time within reach (to where the distance crosses the thickness, or `r` for a near miss),
    /// because contacts built at the early bound resolve worse (measured on the squeezed eight,
    /// 60 steps: 4,248 fail-safe reverts with the bound advanced only where provably free,
    /// 36 with plain bisection, 995 with the full search). With this setting the time is
    /// therefore an estimate, not the proven first time: a second dip of the distance between
    /// the bound and the time within reach may be skipped. Only the contact's normal and weights
    /// depend on it in the shell, whose non-penetration rests on the re-checks and fail-safe of
    /// `self_contact`, not on the time. The hit itself is never missed.
    /// When no sample is within reach, the same samples can prove a miss: if on every interval
    /// between samples the hulls the two primitives sweep are apart along the gap sampled at one
    /// of its ends (or, halving it up to four times, at a midpoint), the pair never comes within
    /// the thickness ([`Stage::SampledSeparation`]; Euclidean distance, rounding bounded as in
    /// the hull filter). On the kitten's contracting shell this decides 96% of the pairs the
    /// inclusion search used to refute (and the near misses it reported as hits because it
    /// measures the gap per axis); the search runs only for the rest.
    /// `None` (the default, the standalone queries): always searched, and the time is never
    /// later than the truth.
    pub certain_contact_slack: Option<f64>,
}

/// Intervals of the distance samples of [`CcdSettings::certain_contact_slack`].
pub(crate) const SAMPLES: usize = 8;
/// Half the most steps of the search for the time of a certain contact (as many bisections
/// would leave 2^-16 of the interval they start from).
const BISECTIONS: usize = 16;
/// The bisection of a certain contact's time stops once the pair moves at most this fraction of
/// the thickness over the interval left: the contact's weights and normal, taken there, then
/// differ from those at the exact time by that much at most.
const TIME_RESOLUTION: f64 = 1.0 / 256.0;
/// Steps of the golden-section search for a pass within reach between samples.
const GOLDEN_STEPS: usize = 24;

impl Default for CcdSettings {
    fn default() -> Self {
        Self { max_boxes: 1024, relative_tolerance: 1.0 / (1u64 << 20) as f64, certain_contact_slack: None }
    }
}

/// The stage that decided a query.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stage {
    /// Input outside the searched range (non-finite, or above 2^1000): conservative hit at 0.
    OutOfRange,
    /// The swept bounding boxes are apart: no contact.
    SweptAabb,
    /// The coplanarity cubic keeps its sign with a margin: no contact.
    PlaneFilter,
    /// The distance at a sample time is within the thickness (plus the slack of
    /// [`CcdSettings::certain_contact_slack`]): hit, its time estimated from below.
    SampledContact,
    /// No sample is within the thickness and, on every sample interval, the hulls the two
    /// primitives sweep are apart along the gap direction sampled there: no contact.
    SampledSeparation,
    /// The inclusion search answered within its budget.
    Inclusion,
    /// The inclusion search ran out of budget: conservative hit.
    BudgetExhausted,
}

/// A query's answer and how it was reached (for statistics and benchmarks).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CcdOutcome {
    /// First time in [0, 1] at which the distance may be <= thickness, or None.
    pub toi: Option<f64>,
    /// Which stage decided.
    pub stage: Stage,
    /// Sub-domains the inclusion search examined (0 if a filter decided).
    pub boxes: u32,
}

impl CcdOutcome {
    fn filtered(stage: Stage) -> Self {
        Self { toi: None, stage, boxes: 0 }
    }
}

fn out_of_range(start: &[V3; 4], end: &[V3; 4], thickness: f64) -> bool {
    let ok = |x: f64| x.abs() <= LARGEST_COORDINATE; // false for NaN
    !(ok(thickness) && start.iter().chain(end.iter()).all(|p| p.iter().all(|&x| ok(x))))
}

fn dv(p: V3) -> DVec3 {
    DVec3::new(p[0], p[1], p[2])
}

/// Largest displacement over the step of the points `range` of a pair.
fn largest_motion(start: &[V3; 4], end: &[V3; 4], range: std::ops::Range<usize>) -> f64 {
    range.map(|k| dv(end[k]).distance(dv(start[k]))).fold(0.0, f64::max)
}

/// The gap vectors (the first primitive's closest point minus the second's) at the times
/// `t = k / SAMPLES`, in order up to the first whose length is within `reach`, and their lengths.
/// Returns how many were sampled: all `SAMPLES + 1` when none is within reach. A contact needs
/// the samples before it only ([`sampled_time`]), so the later ones are not computed.
fn sample_gaps(
    start: &[V3; 4],
    end: &[V3; 4],
    reach: f64,
    gap: impl Fn(&[DVec3; 4]) -> DVec3,
) -> ([DVec3; SAMPLES + 1], [f64; SAMPLES + 1], usize) {
    let (s, e) = (start.map(dv), end.map(dv));
    let (mut gaps, mut lengths) = ([DVec3::ZERO; SAMPLES + 1], [f64::NAN; SAMPLES + 1]);
    for k in 0..=SAMPLES {
        let t = k as f64 / SAMPLES as f64;
        gaps[k] = gap(&std::array::from_fn(|i| s[i] + (e[i] - s[i]) * t));
        lengths[k] = gaps[k].length();
        if lengths[k] <= reach {
            return (gaps, lengths, k + 1);
        }
    }
    (gaps, lengths, SAMPLES + 1)
}

/// The sampled estimate of [`CcdSettings::certain_contact_slack`] from the distances `d` at the
/// times `k / SAMPLES` (up to the first within `reach`, all of them when none is): None when no
/// sample (nor a golden-section probe) is within `reach`. `speed` bounds how fast the distance can shrink: it is the minimum over the
/// primitives' points of a gap whose time derivative is at most the sum of the two largest
/// displacements.
fn sampled_time(
    start: &[V3; 4],
    end: &[V3; 4],
    speed: f64,
    thickness: f64,
    reach: f64,
    d: &[f64],
    distance: impl Fn(&[DVec3; 4]) -> f64,
) -> Option<f64> {
    let (s, e) = (start.map(dv), end.map(dv));
    let at = |t: f64| distance(&std::array::from_fn(|i| s[i] + (e[i] - s[i]) * t));
    // `hit`: the sample ending the interval that holds `inside`, a time within reach (where the
    // distance is `inside_distance`).
    let (inside, inside_distance);
    let hit = match d.iter().position(|&x| x <= reach) {
        Some(k) => {
            (inside, inside_distance) = (k as f64 / SAMPLES as f64, d[k]);
            k
        }
        None => {
            // A fast pass (a crushed shell) is within reach for less than a sample interval:
            // look for it around the closest sample by a golden-section search (a heuristic:
            // finding a sample within reach is what counts; when none is found the search runs).
            let k = (0..=SAMPLES).min_by(|&x, &y| d[x].total_cmp(&d[y])).unwrap_or(0);
            let step = 1.0 / SAMPLES as f64;
            let (mut lo, mut hi) = ((k as f64 - 1.0).max(0.0) * step, (k as f64 + 1.0).min(SAMPLES as f64) * step);
            const INVERSE_PHI: f64 = 0.618_033_988_749_894_8;
            let (mut a, mut b) = (hi - INVERSE_PHI * (hi - lo), lo + INVERSE_PHI * (hi - lo));
            let (mut da, mut db) = (at(a), at(b));
            let mut found = None;
            for _ in 0..GOLDEN_STEPS {
                if da <= reach {
                    found = Some((a, da));
                    break;
                }
                if db <= reach {
                    found = Some((b, db));
                    break;
                }
                if da < db {
                    hi = b;
                    (b, db) = (a, da);
                    a = hi - INVERSE_PHI * (hi - lo);
                    da = at(a);
                } else {
                    lo = a;
                    (a, da) = (b, db);
                    b = lo + INVERSE_PHI * (hi - lo);
                    db = at(b);
                }
            }
            // The sample interval holding the time found within reach.
            (inside, inside_distance) = found?;
            ((inside * SAMPLES as f64).floor() as usize + 1).min(SAMPLES)
        }
    };
    // Rounded generously: the estimate must not come out later than the truth by rounding.
    let speed = speed * (1.0 + 1e-9);
    let step = 1.0 / SAMPLES as f64;
    // The first interval before the hit whose bound lets the distance come within `reach`
    // (the one ending at the hit does, up to rounding: then take that one, whose start is early
    // enough by the same bound).
    let j = (0..hit).find(|&j| 0.5 * (d[j] + d[j + 1] - speed * step) <= reach).unwrap_or(hit.saturating_sub(1));
    let t = j as f64 * step + (d[j] - reach) / speed * (1.0 - 1e-9);
    // NaN (no motion: then d[j] <= reach) maps to the sample.
    let lower = if t >= j as f64 * step { t.min(inside) } else { j as f64 * step };
    // The bound is early by the time the pair takes to close at its largest speed; a contact's
    // normal and weights are better taken where the distance actually comes within the thickness
    // (or within reach for a near miss): bisect between the bound and the time within reach.
    let target = if inside_distance <= thickness { thickness } else { reach };
    // A bracketed root search between the bound and the time within reach: a second dip of the
    // distance between them may be skipped, so the answer may come after the first contact (see
    // `CcdSettings::certain_contact_slack`); the bound alone resolved contacts worse. It keeps
    // `lo` outside the target distance and stops once the distance there is within
    // `TIME_RESOLUTION` of the thickness of it, or the pair moves less than that over the
    // interval left. Steps are regula falsi with the Illinois weighting (the distance is smooth
    // between samples: a few steps instead of a bisection's 6 to 10), with a bisection whenever
    // the secant falls outside the bracket (a NaN) or stalls.
    let (mut lo, mut hi) = (lower, inside);
    let mut lo_gap = at(lo) - target;
    if !(lo_gap > 0.0) {
        return Some(lo);
    }
    let resolution = thickness * TIME_RESOLUTION;
    // The bracket's values for the secant (one of them halved after two steps on the same side).
    let (mut lo_weight, mut hi_weight) = (lo_gap, inside_distance - target);
    let mut last_side = 0i8;
    for step in 0..2 * BISECTIONS {
        if lo_gap <= resolution || (hi - lo) * speed <= resolution {
            break;
        }
        let secant = hi - hi_weight * (hi - lo) / (hi_weight - lo_weight);
        // Every fourth step bisects, so a stalling secant still shrinks the bracket.
        let mid = if step % 4 == 3 || !(secant > lo && secant < hi) { 0.5 * (lo + hi) } else { secant };
        let gap = at(mid) - target;
        if gap <= 0.0 {
            (hi, hi_weight) = (mid, gap);
            if last_side == -1 {
                lo_weight *= 0.5;
            }
            last_side = -1;
        } else {
            (lo, lo_gap, lo_weight) = (mid, gap, gap);
            if last_side == 1 {
                hi_weight *= 0.5;
            }
            last_side = 1;
        }
    }
    Some(lo)
}

/// The sampled stage of [`CcdSettings::certain_contact_slack`] for a pair whose first
/// `first_points` points are the first primitive: a hit when a sample comes within `reach`
/// ([`sampled_time`]), a miss when the hulls swept over each sample interval stay apart along the
/// sampled gaps ([`separated_piecewise`]), None (search) otherwise.
fn sampled(
    start: &[V3; 4],
    end: &[V3; 4],
    first_points: usize,
    speed: f64,
    thickness: f64,
    reach: f64,
    gap: impl Fn(&[DVec3; 4]) -> DVec3,
) -> Option<CcdOutcome> {
    let (gaps, d, sampled) = sample_gaps(start, end, reach, &gap);
    if let Some(toi) = sampled_time(start, end, speed, thickness, reach, &d[..sampled], |x| gap(x).length()) {
        return Some(CcdOutcome { toi: Some(toi), stage: Stage::SampledContact, boxes: 0 });
    }
    // No sample within reach: all of them were taken.
    debug_assert_eq!(sampled, SAMPLES + 1);
    if separated_piecewise(start, end, first_points, &gaps, thickness, |x| gap(&x.map(dv))) {
        return Some(CcdOutcome::filtered(Stage::SampledSeparation));
    }
    None
}

fn from_search(search: inclusion::Search) -> CcdOutcome {
    let stage = if search.exhausted { Stage::BudgetExhausted } else { Stage::Inclusion };
    CcdOutcome { toi: search.toi, stage, boxes: search.boxes }
}

/// Vertex `p` against triangle `abc`, each moving linearly from `start = [p, a, b, c]` at t = 0
/// to `end` at t = 1. Returns the first time the distance may be <= `thickness` (negative
/// thickness counts as 0), or None when it certainly stays larger.
pub fn vertex_triangle(start: &[V3; 4], end: &[V3; 4], thickness: f64) -> Option<f64> {
    vertex_triangle_with(start, end, thickness, &CcdSettings::default()).toi
}

/// [`vertex_triangle`] with explicit settings, reporting the deciding stage.
pub fn vertex_triangle_with(start: &[V3; 4], end: &[V3; 4], thickness: f64, settings: &CcdSettings) -> CcdOutcome {
    vertex_triangle_in(start, end, thickness, settings, &mut SearchQueues::default())
}

/// [`vertex_triangle_with`] with the caller's search queues (kept between queries).
pub(crate) fn vertex_triangle_in(
    start: &[V3; 4],
    end: &[V3; 4],
    thickness: f64,
    settings: &CcdSettings,
    queues: &mut SearchQueues,
) -> CcdOutcome {
    let thickness = if thickness < 0.0 { 0.0 } else { thickness }; // NaN stays NaN: out of range
    if out_of_range(start, end, thickness) {
        return CcdOutcome { toi: Some(0.0), stage: Stage::OutOfRange, boxes: 0 };
    }
    let [p0, a0, b0, c0] = start;
    let [p1, a1, b1, c1] = end;
    if swept_aabbs_separated(&[*p0, *p1], &[*a0, *b0, *c0, *a1, *b1, *c1], thickness) {
        return CcdOutcome::filtered(Stage::SweptAabb);
    }
    let w = [sub(p0, a0), sub(p1, a1)];
    let e1 = [sub(b0, a0), sub(b1, a1)];
    let e2 = [sub(c0, a0), sub(c1, a1)];
    if plane_distance_filter(w, e1, e2, thickness) {
        return CcdOutcome::filtered(Stage::PlaneFilter);
    }
    if let Some(slack) = settings.certain_contact_slack {
        let gap = |x: &[DVec3; 4]| {
            let [p, a, b, c] = *x;
            let al = closest_on_triangle(p, a, b, c);
            p - (a * al[0] + b * al[1] + c * al[2])
        };
        let speed = largest_motion(start, end, 0..1) + largest_motion(start, end, 1..4);
        if let Some(stage) = sampled(start, end, 1, speed, thickness, thickness * (1.0 + slack), gap) {
            return stage;
        }
    }
    from_search(inclusion::vertex_triangle(
        start,
        end,
        thickness,
        settings.relative_tolerance,
        settings.max_boxes,
        queues,
    ))
}

/// Edge `ab` against edge `cd`, each moving linearly from `start = [a, b, c, d]` at t = 0 to
/// `end` at t = 1. Returns the first time the distance may be <= `thickness` (negative
/// thickness counts as 0), or None when it certainly stays larger.
pub fn edge_edge(start: &[V3; 4], end: &[V3; 4], thickness: f64) -> Option<f64> {
    edge_edge_with(start, end, thickness, &CcdSettings::default()).toi
}

/// [`edge_edge`] with explicit settings, reporting the deciding stage.
pub fn edge_edge_with(start: &[V3; 4], end: &[V3; 4], thickness: f64, settings: &CcdSettings) -> CcdOutcome {
    edge_edge_in(start, end, thickness, settings, &mut SearchQueues::default())
}

/// [`edge_edge_with`] with the caller's search queues (kept between queries).
pub(crate) fn edge_edge_in(
    start: &[V3; 4],
    end: &[V3; 4],
    thickness: f64,
    settings: &CcdSettings,
    queues: &mut SearchQueues,
) -> CcdOutcome {
    let thickness = if thickness < 0.0 { 0.0 } else { thickness }; // NaN stays NaN: out of range
    if out_of_range(start, end, thickness) {
        return CcdOutcome { toi: Some(0.0), stage: Stage::OutOfRange, boxes: 0 };
    }
    let [a0, b0, c0, d0] = start;
    let [a1, b1, c1, d1] = end;
    if swept_aabbs_separated(&[*a0, *b0, *a1, *b1], &[*c0, *d0, *c1, *d1], thickness) {
        return CcdOutcome::filtered(Stage::SweptAabb);
    }
    let w = [sub(c0, a0), sub(c1, a1)];
    let e1 = [sub(b0, a0), sub(b1, a1)];
    let e2 = [sub(d0, c0), sub(d1, c1)];
    if plane_distance_filter(w, e1, e2, thickness) {
        return CcdOutcome::filtered(Stage::PlaneFilter);
    }
    if let Some(slack) = settings.certain_contact_slack {
        let gap = |x: &[DVec3; 4]| {
            let [a, b, c, d] = *x;
            let (s, t) = closest_segments(a, b, c, d);
            (a + (b - a) * s) - (c + (d - c) * t)
        };
        let speed = largest_motion(start, end, 0..2) + largest_motion(start, end, 2..4);
        if let Some(stage) = sampled(start, end, 2, speed, thickness, thickness * (1.0 + slack), gap) {
            return stage;
        }
    }
    from_search(inclusion::edge_edge(start, end, thickness, settings.relative_tolerance, settings.max_boxes, queues))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// xorshift64*: a tiny deterministic generator for the randomized tests.
    struct Rng(u64);
    impl Rng {
        fn unit(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
        }
        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.unit()
        }
        fn vec(&mut self, scale: f64) -> V3 {
            [self.range(-scale, scale), self.range(-scale, scale), self.range(-scale, scale)]
        }
    }

    fn add(a: &V3, b: &V3, s: f64) -> V3 {
        [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]
    }

    /// Positions at t = 0 and t = 1 of points that are at `at` at time `t_star` and move with
    /// velocity `vel`.
    fn through(at: &V3, vel: &V3, t_star: f64) -> (V3, V3) {
        (add(at, vel, -t_star), add(at, vel, 1.0 - t_star))
    }

    /// The settings of the shell's self-contact: shortcuts for certain contacts.
    fn shell_settings() -> CcdSettings {
        CcdSettings { certain_contact_slack: Some(0.0), ..CcdSettings::default() }
    }

    #[test]
    fn random_constructed_vertex_triangle_contacts_are_never_missed() {
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        for case in 0..3000 {
            let scale = [1.0, 1e-3, 1e4][case % 3];
            let thickness = if case % 2 == 0 { 0.0 } else { 1e-3 * scale };
            let t_star = if case % 7 == 0 {
                0.0
            } else if case % 11 == 0 {
                1.0
            } else {
                rng.unit()
            };
            let tri = [rng.vec(scale), rng.vec(scale), rng.vec(scale)];
            let (u, v) = (rng.unit(), rng.unit());
            let (u, v) = if u + v > 1.0 { (1.0 - u, 1.0 - v) } else { (u, v) };
            let on = add(&add(&tri[0], &sub(&tri[1], &tri[0]), u), &sub(&tri[2], &tri[0]), v);
            // Within half the thickness at t_star (exactly on the triangle up to rounding if 0).
            let offset = rng.vec(thickness * 0.28);
            let p = add(&on, &offset, 1.0);
            let (start, end) = moving_through(&mut rng, [p, tri[0], tri[1], tri[2]], scale, case, t_star);
            // With zero thickness the construction is exact only up to rounding, so test with a
            // thickness that covers it (1e-12 of the scale).
            let thickness = thickness.max(1e-12 * scale);
            assert_found(case, t_star, |settings| vertex_triangle_with(&start, &end, thickness, settings).toi);
        }
    }

    /// Start and end positions of four points that each pass through the given point at
    /// `t_star` with a random velocity (tiny on every fifth case).
    fn moving_through(rng: &mut Rng, points: [V3; 4], scale: f64, case: usize, t_star: f64) -> ([V3; 4], [V3; 4]) {
        let mut start = [[0.0; 3]; 4];
        let mut end = [[0.0; 3]; 4];
        for (k, point) in points.iter().enumerate() {
            let vel = rng.vec(scale * if case % 5 == 0 { 1e-9 } else { 1.0 });
            (start[k], end[k]) = through(point, &vel, t_star);
        }
        (start, end)
    }

    /// The query finds the contact with the standalone settings (at or before `t_star`) and with
    /// the shell's (whose shortcut only estimates the time, see `certain_contact_slack`).
    fn assert_found(case: usize, t_star: f64, query: impl Fn(&CcdSettings) -> Option<f64>) {
        for (settings, exact_time) in [(CcdSettings::default(), true), (shell_settings(), false)] {
            let toi = query(&settings);
            assert!(toi.is_some(), "case {case}: contact at t = {t_star} missed");
            assert!(!exact_time || toi.unwrap() <= t_star, "case {case}: toi {} after {t_star}", toi.unwrap());
        }
    }

    /// The shell's sampled contact time: at or before the time the distance comes within the
    /// thickness, and late enough that the distance there exceeds the thickness by at most
    /// [`TIME_RESOLUTION`] of it (where the contact's weights and normal are taken), for slow and
    /// fast approaches, vertex-face and edge-edge.
    #[test]
    fn sampled_contact_times_resolve_the_thickness_crossing() {
        let thickness = 1e-3;
        for closing in [0.5, 3.0, 40.0, 1000.0] {
            // Distance along z: 3 thicknesses at t = 0, shrinking by `closing` thicknesses per step.
            let gap0 = 3.0 * thickness;
            let drop = closing * thickness;
            let crossing = (gap0 - thickness) / drop;
            if crossing > 1.0 {
                continue;
            }
            // Sliding sideways 4 times as fast: the speed bound alone would put the time early.
            let slide = 4.0 * drop;
            let tri = [[-20.0, -20.0, 0.0], [20.0, -20.0, 0.0], [0.0, 20.0, 0.0]];
            let vf_start = [[0.2, 0.3, gap0], tri[0], tri[1], tri[2]];
            let vf_end = [[0.2 + slide, 0.3, gap0 - drop], tri[0], tri[1], tri[2]];
            let ee_start = [[-20.0, 0.1, gap0], [20.0, 0.2, gap0], [0.1, -20.0, 0.0], [0.3, 20.0, 0.0]];
            let ee_end =
                [[-20.0 + slide, 0.1, gap0 - drop], [20.0 + slide, 0.2, gap0 - drop], ee_start[2], ee_start[3]];
            let vf_distance = |t: f64| (gap0 - drop * t).abs();
            let vf = vertex_triangle_with(&vf_start, &vf_end, thickness, &shell_settings());
            let ee = edge_edge_with(&ee_start, &ee_end, thickness, &shell_settings());
            for (kind, outcome) in [("vertex-face", vf), ("edge-edge", ee)] {
                assert_eq!(outcome.stage, Stage::SampledContact, "{kind}, closing {closing}");
                let toi = outcome.toi.unwrap();
                let distance = vf_distance(toi); // both pairs close along z from the same gap
                assert!(toi <= crossing, "{kind}, closing {closing}: toi {toi} after {crossing}");
                assert!(
                    distance <= thickness * (1.0 + TIME_RESOLUTION) * (1.0 + 1e-9),
                    "{kind}, closing {closing}: distance {distance} at toi {toi}, thickness {thickness}"
                );
            }
        }
    }

    #[test]
    fn random_constructed_edge_edge_contacts_are_never_missed() {
        let mut rng = Rng(0x0123_4567_89AB_CDEF);
        for case in 0..3000 {
            let scale = [1.0, 1e-3, 1e4][case % 3];
            let thickness = if case % 2 == 0 { 0.0 } else { 1e-3 * scale };
            let t_star = if case % 7 == 0 {
                0.0
            } else if case % 11 == 0 {
                1.0
            } else {
                rng.unit()
            };
            let (a, b) = (rng.vec(scale), rng.vec(scale));
            let dir = if case % 13 == 0 { sub(&b, &a) } else { rng.vec(scale) }; // parallel edges
            let u = if case % 17 == 0 { 1.0 } else { rng.unit() };
            let v = rng.unit();
            let on_ab = add(&a, &sub(&b, &a), u);
            let meet = add(&on_ab, &rng.vec(thickness * 0.28), 1.0);
            let c = add(&meet, &dir, -v);
            let d = add(&meet, &dir, 1.0 - v);
            let (start, end) = moving_through(&mut rng, [a, b, c, d], scale, case, t_star);
            let thickness = thickness.max(1e-12 * scale);
            assert_found(case, t_star, |settings| edge_edge_with(&start, &end, thickness, settings).toi);
        }
    }

    #[test]
    fn separated_motions_are_misses_decided_by_the_filters() {
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let start = [[0.2, 0.2, 2.0], tri[0], tri[1], tri[2]];
        let end = [[0.2, 0.2, 1.0], tri[0], tri[1], tri[2]];
        let outcome = vertex_triangle_with(&start, &end, 0.0, &CcdSettings::default());
        assert_eq!(outcome.toi, None);
        assert_eq!(outcome.stage, Stage::SweptAabb);
        // Overlapping boxes, but the vertex stays above the plane: the plane filter decides.
        let start = [[0.2, 0.2, 0.5], [0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 0.0]];
        let end = start;
        let outcome = vertex_triangle_with(&start, &end, 0.0, &CcdSettings::default());
        assert_eq!(outcome, CcdOutcome::filtered(Stage::PlaneFilter));
    }

    #[test]
    fn vertex_beside_the_triangle_in_its_plane_is_a_miss() {
        // Coplanar motion that passes beside the triangle: needs the inclusion search.
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let start = [[2.0, 0.6, 0.0], tri[0], tri[1], tri[2]];
        let end = [[0.5, 0.6, 0.0], tri[0], tri[1], tri[2]];
        let outcome = vertex_triangle_with(&start, &end, 0.0, &CcdSettings::default());
        assert_eq!(outcome.toi, None, "{outcome:?}");
        assert_eq!(outcome.stage, Stage::Inclusion);
        let end = [[0.0, 0.6, 0.0], tri[0], tri[1], tri[2]];
        let outcome = vertex_triangle_with(&start, &end, 0.0, &CcdSettings::default());
        let toi = outcome.toi.expect("crosses the hypotenuse");
        // Reaches the hypotenuse x + y = 1 when 2 - 2 s = 0.4, s = 0.8.
        assert!(toi <= 0.8 && toi > 0.8 - 1e-6, "{outcome:?}");
    }

    #[test]
    fn thick_contacts_are_found_early_enough_within_the_budget() {
        // The vertex passes 0.1/sqrt(2) from the hypotenuse; in the max-norm it comes within
        // `thickness` of the triangle when |z| <= thickness, at t = (1 - thickness) / 2.
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let start = [[0.55, 0.55, 1.0], tri[0], tri[1], tri[2]];
        let end = [[0.55, 0.55, -1.0], tri[0], tri[1], tri[2]];
        for thickness in [0.05, 0.1, 0.2] {
            let outcome = vertex_triangle_with(&start, &end, thickness, &CcdSettings::default());
            assert_eq!(outcome.stage, Stage::Inclusion, "{outcome:?}");
            assert!(outcome.boxes < 400, "{outcome:?}");
            let expected = (1.0 - thickness) / 2.0;
            let toi = outcome.toi.unwrap();
            // Early by at most the tolerance (thickness / 64) over the speed (2), plus a bucket.
            assert!(toi <= expected && toi >= expected - thickness / 128.0 - 1e-6, "{thickness}: {toi}");
        }
        assert_eq!(vertex_triangle(&start, &end, 0.03), None, "0.07 away in the max-norm");
    }

    #[test]
    fn out_of_range_inputs_are_conservative_hits() {
        let mut start = [[0.0; 3]; 4];
        let end = [[1.0; 3]; 4];
        start[2][1] = f64::NAN;
        assert_eq!(vertex_triangle(&start, &end, 0.0), Some(0.0));
        start[2][1] = 1e305;
        assert_eq!(edge_edge(&start, &end, 0.0), Some(0.0));
        assert_eq!(edge_edge(&end, &end, f64::NAN), Some(0.0));
    }
}
