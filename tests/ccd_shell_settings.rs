//! The CCD with the shell's settings (the sampled stage of `CcdSettings::certain_contact_slack`:
//! certain contacts from distance samples, misses from hulls swept over sample intervals) on the
//! public ground truth: no false negatives, and the sampled stage decides most queries without
//! the inclusion search.

mod ccd_queries;

use ccd_queries::{Kind, load_all};
use softshell::collision::ccd::{CcdOutcome, CcdSettings, Stage, edge_edge_with, vertex_triangle_with};

fn shell_settings() -> CcdSettings {
    CcdSettings { certain_contact_slack: Some(0.0), ..CcdSettings::default() }
}

fn query(kind: Kind, start: &[[f64; 3]; 4], end: &[[f64; 3]; 4], thickness: f64) -> CcdOutcome {
    match kind {
        Kind::VertexFace => vertex_triangle_with(start, end, thickness, &shell_settings()),
        Kind::EdgeEdge => edge_edge_with(start, end, thickness, &shell_settings()),
    }
}

#[test]
fn public_queries_have_no_false_negatives_with_the_shell_settings() {
    let mut false_negatives = Vec::new();
    let (mut total, mut false_positives) = (0, 0);
    let mut stages = std::collections::BTreeMap::new();
    for category in &load_all() {
        for (index, q) in category.queries.iter().enumerate() {
            let out = query(category.kind, &q.start, &q.end, 0.0);
            total += 1;
            *stages.entry(format!("{:?}", out.stage)).or_insert(0) += 1;
            if q.collides && out.toi.is_none() {
                false_negatives.push(format!("{} #{index} ({:?})", category.name, out.stage));
            }
            false_positives += usize::from(!q.collides && out.toi.is_some());
            // A thickness never loses a hit.
            if q.collides {
                let thick = query(category.kind, &q.start, &q.end, 1e-6);
                assert!(thick.toi.is_some(), "{} #{index}: a thickness lost a hit ({:?})", category.name, thick.stage);
            }
        }
    }
    println!("{total} queries, {false_positives} false positives; deciding stages: {stages:?}");
    assert_eq!(total, 7279);
    assert!(false_negatives.is_empty(), "false negatives: {false_negatives:?}");
    assert!(false_positives * 20 < total, "{false_positives} false positives");
    // The sampled stage is exercised on both sides (the public set is mostly near misses).
    let count = |s: Stage| stages.get(&format!("{s:?}")).copied().unwrap_or(0);
    assert!(count(Stage::SampledContact) > 50, "{stages:?}");
    assert!(count(Stage::SampledSeparation) > 100, "{stages:?}");
}
