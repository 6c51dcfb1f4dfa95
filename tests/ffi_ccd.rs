//! The standalone CCD queries through the C ABI: the public ground truth (no false negatives),
//! hand-written degenerate contacts, clear misses, and argument checking.

mod ccd_queries;

use std::ffi::CStr;
use std::ptr;

use ccd_queries::{Kind, load_all};
use softshell::ffi::SoftshellStatus;
use softshell::ffi::ccd::{softshell_ccd_edge_edge, softshell_ccd_vertex_triangle};

type P = [f64; 3];

/// Calls the C ABI; returns the status and the outputs (initialised to sentinels).
fn call(kind: Kind, start: &[P; 4], end: &[P; 4], thickness: f64) -> (SoftshellStatus, i32, f64) {
    let mut hit = -7;
    let mut toi = -7.0;
    let f = match kind {
        Kind::VertexFace => softshell_ccd_vertex_triangle,
        Kind::EdgeEdge => softshell_ccd_edge_edge,
    };
    // SAFETY: every pointer is to a live local of the right size.
    let status = unsafe {
        f(
            start[0].as_ptr(),
            start[1].as_ptr(),
            start[2].as_ptr(),
            start[3].as_ptr(),
            end[0].as_ptr(),
            end[1].as_ptr(),
            end[2].as_ptr(),
            end[3].as_ptr(),
            thickness,
            &mut hit,
            &mut toi,
        )
    };
    (status, hit, toi)
}

/// The answer of a query that must succeed: Some(toi) for a hit.
fn query(kind: Kind, start: &[P; 4], end: &[P; 4], thickness: f64) -> Option<f64> {
    let (status, hit, toi) = call(kind, start, end, thickness);
    assert_eq!(status, SoftshellStatus::Ok);
    assert!(hit == 0 || hit == 1, "hit = {hit}");
    assert!((0.0..=1.0).contains(&toi), "toi = {toi}");
    if hit == 0 {
        assert_eq!(toi, 1.0, "a miss reports toi = 1");
        None
    } else {
        Some(toi)
    }
}

fn vf(start: [P; 4], end: [P; 4], thickness: f64) -> Option<f64> {
    query(Kind::VertexFace, &start, &end, thickness)
}

fn ee(start: [P; 4], end: [P; 4], thickness: f64) -> Option<f64> {
    query(Kind::EdgeEdge, &start, &end, thickness)
}

/// Asserts a hit no later than `latest` and no earlier than `earliest`.
#[track_caller]
fn assert_hit(answer: Option<f64>, earliest: f64, latest: f64) {
    let toi = answer.expect("a contact was missed");
    assert!(toi <= latest, "toi {toi} is later than the contact at {latest}");
    assert!(toi >= earliest, "toi {toi} is earlier than plausible ({earliest})");
}

fn shift(points: [P; 4], by: P) -> [P; 4] {
    points.map(|p| [p[0] + by[0], p[1] + by[1], p[2] + by[2]])
}

const TRI: [P; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

fn with_tri(p: P) -> [P; 4] {
    [p, TRI[0], TRI[1], TRI[2]]
}

#[test]
fn public_queries_have_no_false_negatives() {
    let categories = load_all();
    let total: usize = categories.iter().map(|c| c.queries.len()).sum();
    assert_eq!(total, 7279, "the public set holds 7,279 queries");
    let mut false_negatives = Vec::new();
    let mut totals = std::collections::BTreeMap::new();
    println!("{:<45} {:>7} {:>9} {:>7}", "category", "queries", "colliding", "false+");
    for category in &categories {
        let mut positives = 0;
        let mut false_positives = 0;
        for (index, q) in category.queries.iter().enumerate() {
            let hit = query(category.kind, &q.start, &q.end, 0.0).is_some();
            positives += usize::from(q.collides);
            if q.collides && !hit {
                false_negatives.push(format!("{} #{index}", category.name));
            }
            false_positives += usize::from(!q.collides && hit);
        }
        println!("{:<45} {:>7} {:>9} {:>7}", category.name, category.queries.len(), positives, false_positives);
        let entry = totals.entry(category.kind).or_insert((0, 0, 0));
        entry.0 += category.queries.len();
        entry.1 += positives;
        entry.2 += false_positives;
    }
    for (kind, (n, positives, false_positives)) in &totals {
        println!("{kind:?}: {n} queries, {positives} colliding, {false_positives} false positives");
    }
    assert_eq!(totals[&Kind::VertexFace].0, 3085);
    assert_eq!(totals[&Kind::VertexFace].1, 248);
    assert_eq!(totals[&Kind::EdgeEdge].0, 4194);
    assert_eq!(totals[&Kind::EdgeEdge].1, 187);
    assert!(false_negatives.is_empty(), "false negatives: {false_negatives:?}");
    let false_positives: usize = totals.values().map(|t| t.2).sum();
    // Rare, not zero: near misses within the search tolerance are reported as hits.
    assert!(false_positives * 20 < total, "{false_positives} false positives out of {total}");
}

#[test]
fn a_thickness_never_loses_a_hit() {
    // (Both times of impact are conservative lower bounds, so they need not be ordered.)
    for category in &load_all() {
        for (index, q) in category.queries.iter().enumerate() {
            if query(category.kind, &q.start, &q.end, 0.0).is_some() {
                let thick = query(category.kind, &q.start, &q.end, 1e-6);
                assert!(thick.is_some(), "{} #{index}: a thickness lost a hit", category.name);
            }
        }
    }
}

#[test]
fn rational_coordinates_are_parsed_exactly() {
    assert_eq!(ccd_queries::exact_rational("3", "4"), 0.75);
    assert_eq!(ccd_queries::exact_rational("-1", "2596148429267413814265248164610048"), -(2f64.powi(-111)));
    let big = "6004799503160661";
    assert_eq!(ccd_queries::exact_rational(big, "36028797018963968"), 6004799503160661.0 / 2f64.powi(55));
}

#[test]
fn vertex_triangle_degenerate_contacts_are_hits() {
    // Crossing the face at t = 0.5.
    assert_hit(vf(with_tri([0.2, 0.2, 1.0]), with_tri([0.2, 0.2, -1.0]), 0.0), 0.49, 0.5);
    // Coplanar motion sliding into the triangle through its edge x = 0 at t = 0.5.
    assert_hit(vf(with_tri([-0.5, 0.3, 0.0]), with_tri([0.5, 0.3, 0.0]), 0.0), 0.49, 0.5);
    // Touching the face exactly at t = 1 and at t = 0.
    assert_hit(vf(with_tri([0.25, 0.25, 1.0]), with_tri([0.25, 0.25, 0.0]), 0.0), 0.99, 1.0);
    assert_hit(vf(with_tri([0.25, 0.25, 0.0]), with_tri([0.25, 0.25, 1.0]), 0.0), 0.0, 0.0);
    // Static contact on an edge and on a vertex; nothing moves.
    assert_hit(vf(with_tri([0.5, 0.5, 0.0]), with_tri([0.5, 0.5, 0.0]), 0.0), 0.0, 0.0);
    assert_hit(vf(with_tri([1.0, 0.0, 0.0]), with_tri([1.0, 0.0, 0.0]), 0.0), 0.0, 0.0);
    // Passing exactly through a vertex of the triangle, and along an edge's line onto it.
    assert_hit(vf(with_tri([1.0, 0.0, 1.0]), with_tri([1.0, 0.0, -1.0]), 0.0), 0.49, 0.5);
    assert_hit(vf(with_tri([3.0, 0.0, 0.0]), with_tri([1.0, 0.0, 0.0]), 0.0), 0.99, 1.0);
    // The triangle moves onto a static vertex.
    assert_hit(
        vf([[0.2, 0.2, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]], with_tri([0.2, 0.2, 0.0]), 0.0),
        0.99,
        1.0,
    );
    // A degenerate (collinear) triangle swept through by the vertex at t = 0.25.
    let flat = [[0.5, 0.0, 1.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
    let mut flat_end = flat;
    flat_end[0] = [0.5, 0.0, -3.0];
    assert_hit(vf(flat, flat_end, 0.0), 0.24, 0.25);
    // Large coordinates, tiny motion: crossing at t = 0.5 around (1e6, 1e6, 1e6).
    let far = [1e6, 1e6, 1e6];
    let start = shift(with_tri([0.25, 0.25, 0.5e-6]), far);
    let end = shift(with_tri([0.25, 0.25, -0.5e-6]), far);
    assert_hit(vf(start, end, 0.0), 0.49, 0.5);
    // Within the thickness without touching: passes 0.01 above the face.
    let start = with_tri([-1.0, 0.3, 0.01]);
    let end = with_tri([1.0, 0.3, 0.01]);
    assert_hit(vf(start, end, 0.02), 0.0, 0.5);
    assert_eq!(vf(start, end, 0.005), None);
}

#[test]
fn vertex_triangle_clear_misses_are_misses() {
    // Above the face the whole step.
    assert_eq!(vf(with_tri([0.2, 0.2, 1.0]), with_tri([0.2, 0.2, 0.1]), 0.0), None);
    // In the plane, beside the triangle, stopping short of its hypotenuse.
    assert_eq!(vf(with_tri([2.0, 0.6, 0.0]), with_tri([0.5, 0.6, 0.0]), 0.0), None);
    // Crossing the plane outside the triangle.
    assert_eq!(vf(with_tri([0.8, 0.8, 1.0]), with_tri([0.8, 0.8, -1.0]), 0.0), None);
    // Both move in parallel at a fixed distance.
    let start = [[0.2, 0.2, 0.1], TRI[0], TRI[1], TRI[2]];
    assert_eq!(vf(start, shift(start, [5.0, -3.0, 2.0]), 0.0), None);
    // Large coordinates: misses by 1e-6 (the error bound there is about 1e-8).
    let far = [1e6, -1e6, 1e6];
    let start = shift(with_tri([1.0 + 1e-6, 0.5, 0.5e-6]), far);
    let end = shift(with_tri([1.0 + 1e-6, 0.5, -0.5e-6]), far);
    assert_eq!(vf(start, end, 0.0), None);
}

#[test]
fn edge_edge_degenerate_contacts_are_hits() {
    let a = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
    // Perpendicular edges crossing at t = 0.5.
    let start = [a[0], a[1], [0.5, -0.5, 1.0], [0.5, 0.5, 1.0]];
    let end = [a[0], a[1], [0.5, -0.5, -1.0], [0.5, 0.5, -1.0]];
    assert_hit(ee(start, end, 0.0), 0.49, 0.5);
    // Parallel edges coming together, overlapping in [0.5, 1] along x, at t = 0.5.
    let start = [a[0], a[1], [0.5, 1.0, 0.0], [1.5, 1.0, 0.0]];
    let end = [a[0], a[1], [0.5, -1.0, 0.0], [1.5, -1.0, 0.0]];
    assert_hit(ee(start, end, 0.0), 0.49, 0.5);
    // Collinear edges sliding onto each other along their common line, meeting at t = 0.5.
    let start = [a[0], a[1], [3.0, 0.0, 0.0], [4.0, 0.0, 0.0]];
    let end = [a[0], a[1], [-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]];
    assert_hit(ee(start, end, 0.0), 0.49, 0.5);
    // Endpoint meets endpoint exactly at t = 1; endpoint touching at t = 0 and moving away.
    let start = [a[0], a[1], [1.0, 1.0, 1.0], [1.0, 2.0, 1.0]];
    let end = [a[0], a[1], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
    assert_hit(ee(start, end, 0.0), 0.99, 1.0);
    assert_hit(ee(end, start, 0.0), 0.0, 0.0);
    // Static crossing edges.
    let cross = [a[0], a[1], [0.5, -1.0, 0.0], [0.5, 1.0, 0.0]];
    assert_hit(ee(cross, cross, 0.0), 0.0, 0.0);
    // A zero-length edge (a point) passing through the other edge at t = 0.25.
    let start = [a[0], a[1], [0.3, 0.0, 1.0], [0.3, 0.0, 1.0]];
    let end = [a[0], a[1], [0.3, 0.0, -3.0], [0.3, 0.0, -3.0]];
    assert_hit(ee(start, end, 0.0), 0.24, 0.25);
    // Large coordinates, tiny motion: crossing at t = 0.5 around (-1e6, 1e6, 1e6).
    let far = [-1e6, 1e6, 1e6];
    let start = shift([a[0], a[1], [0.5, -0.5, 0.5e-6], [0.5, 0.5, 0.5e-6]], far);
    let end = shift([a[0], a[1], [0.5, -0.5, -0.5e-6], [0.5, 0.5, -0.5e-6]], far);
    assert_hit(ee(start, end, 0.0), 0.49, 0.5);
    // Parallel edges 0.01 apart: a hit only with a larger thickness.
    let near = [a[0], a[1], [0.2, 0.01, 0.0], [0.8, 0.01, 0.0]];
    assert_hit(ee(near, near, 0.02), 0.0, 0.0);
    assert_eq!(ee(near, near, 0.005), None);
}

#[test]
fn edge_edge_clear_misses_are_misses() {
    let a = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
    // Parallel edges moving together, apart the whole time.
    let start = [a[0], a[1], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]];
    assert_eq!(ee(start, shift(start, [0.3, 0.2, 0.1]), 0.0), None);
    // Skew edges: the second passes below the first's end.
    let start = [a[0], a[1], [1.5, -0.5, 1.0], [1.5, 0.5, 1.0]];
    let end = [a[0], a[1], [1.5, -0.5, -1.0], [1.5, 0.5, -1.0]];
    assert_eq!(ee(start, end, 0.0), None);
    // Collinear edges separated by a gap along their line that shrinks but never closes.
    let start = [a[0], a[1], [3.0, 0.0, 0.0], [4.0, 0.0, 0.0]];
    let end = [a[0], a[1], [1.5, 0.0, 0.0], [2.5, 0.0, 0.0]];
    assert_eq!(ee(start, end, 0.0), None);
    // Large coordinates: misses by 1e-6.
    let far = [1e6, 1e6, -1e6];
    let start = shift([a[0], a[1], [1.0 + 1e-6, -0.5, 0.5e-6], [1.0 + 1e-6, 0.5, 0.5e-6]], far);
    let end = shift([a[0], a[1], [1.0 + 1e-6, -0.5, -0.5e-6], [1.0 + 1e-6, 0.5, -0.5e-6]], far);
    assert_eq!(ee(start, end, 0.0), None);
}

fn last_error() -> String {
    // SAFETY: the library returns a valid NUL-terminated string.
    unsafe { CStr::from_ptr(softshell::ffi::version::softshell_last_error()) }.to_string_lossy().into_owned()
}

#[test]
fn bad_arguments_are_refused_and_outputs_left_alone() {
    let start = with_tri([0.2, 0.2, 1.0]);
    let end = with_tri([0.2, 0.2, -1.0]);
    for kind in [Kind::VertexFace, Kind::EdgeEdge] {
        let (status, hit, toi) = call(kind, &start, &end, -1e-3);
        assert_eq!((status, hit, toi), (SoftshellStatus::InvalidArgument, -7, -7.0));
        assert!(last_error().contains("thickness"), "{}", last_error());
        for bad in [f64::NAN, f64::INFINITY] {
            let (status, hit, toi) = call(kind, &start, &end, bad);
            assert_eq!((status, hit, toi), (SoftshellStatus::InvalidArgument, -7, -7.0));
            let mut broken = end;
            broken[2][1] = bad;
            let (status, hit, toi) = call(kind, &start, &broken, 0.0);
            assert_eq!((status, hit, toi), (SoftshellStatus::InvalidArgument, -7, -7.0));
            assert!(last_error().contains("[1]"), "{}", last_error());
        }
    }
    let mut hit = -7;
    let mut toi = -7.0;
    let p = start[0].as_ptr();
    // SAFETY: NULL pointers must be refused before any dereference.
    unsafe {
        let status = softshell_ccd_vertex_triangle(p, p, p, ptr::null(), p, p, p, p, 0.0, &mut hit, &mut toi);
        assert_eq!(status, SoftshellStatus::NullArgument);
        assert!(last_error().contains("c0"), "{}", last_error());
        let status = softshell_ccd_edge_edge(p, p, p, p, p, p, p, p, 0.0, ptr::null_mut(), &mut toi);
        assert_eq!(status, SoftshellStatus::NullArgument);
        let status = softshell_ccd_edge_edge(p, p, p, p, p, p, p, p, 0.0, &mut hit, ptr::null_mut());
        assert_eq!(status, SoftshellStatus::NullArgument);
    }
    assert_eq!((hit, toi), (-7, -7.0));
}
