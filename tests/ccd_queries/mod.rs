//! Reader for the public CCD ground-truth queries in `tests/data/ccd/` (format: its README.md).
//! Shared by `tests/ffi_ccd.rs` and `benches/ccd_queries.rs`.
//!
//! Every coordinate is a rational `num/den` whose denominator is a power of two (up to 2^111),
//! so it is exactly a double: the numerator is read as an i128 and must convert to f64 without
//! rounding, then it is scaled by an exact power of two.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// Vertex-face or edge-edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Kind {
    VertexFace,
    EdgeEdge,
}

/// One query: four points at t = 0, four at t = 1, and the exact answer.
#[derive(Clone, Debug)]
pub struct Query {
    pub start: [[f64; 3]; 4],
    pub end: [[f64; 3]; 4],
    pub collides: bool,
}

/// All queries of one scene and kind.
pub struct Category {
    pub name: String,
    pub kind: Kind,
    pub queries: Vec<Query>,
}

pub fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/ccd")
}

/// 2^-k as an exact double (normal range only).
fn inverse_power_of_two(k: u32) -> f64 {
    assert!(k <= 1022, "denominator 2^{k} is out of the normal range");
    f64::from_bits(((1023 - k) as u64) << 52)
}

/// The exact double `num/den`; panics if `den` is not a power of two or the value is not exactly
/// representable.
pub fn exact_rational(num: &str, den: &str) -> f64 {
    let n: i128 = num.trim().parse().unwrap_or_else(|e| panic!("numerator {num:?}: {e}"));
    let d: u128 = den.trim().parse().unwrap_or_else(|e| panic!("denominator {den:?}: {e}"));
    assert!(d.is_power_of_two(), "denominator {d} is not a power of two");
    let mantissa = n as f64;
    assert_eq!(mantissa as i128, n, "numerator {n} is not exactly a double");
    let value = mantissa * inverse_power_of_two(d.trailing_zeros());
    assert!(value == 0.0 || value.is_normal(), "{num}/{den} underflows");
    value
}

fn parse_file(path: &Path, out: &mut Vec<Query>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let rows: Vec<(&str, [f64; 3], bool)> = text
        .lines()
        .filter(|line| !line.trim().is_empty())
        .map(|line| {
            let cols: Vec<&str> = line.split(',').collect();
            assert_eq!(cols.len(), 7, "{}: bad row {line:?}", path.display());
            let point =
                [exact_rational(cols[0], cols[1]), exact_rational(cols[2], cols[3]), exact_rational(cols[4], cols[5])];
            let truth = match cols[6].trim() {
                "0" => false,
                "1" => true,
                other => panic!("{}: ground truth {other:?}", path.display()),
            };
            (line, point, truth)
        })
        .collect();
    assert_eq!(rows.len() % 8, 0, "{}: {} rows is not a multiple of 8", path.display(), rows.len());
    for chunk in rows.chunks(8) {
        let truth = chunk[0].2;
        assert!(chunk.iter().all(|row| row.2 == truth), "{}: rows of one query disagree", path.display());
        out.push(Query {
            start: [chunk[0].1, chunk[1].1, chunk[2].1, chunk[3].1],
            end: [chunk[4].1, chunk[5].1, chunk[6].1, chunk[7].1],
            collides: truth,
        });
    }
}

/// Every category (scene x kind) in a fixed order.
pub fn load_all() -> Vec<Category> {
    let dir = data_dir();
    let mut scenes: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|entry| entry.unwrap().path())
        .filter(|path| path.is_dir())
        .collect();
    scenes.sort();
    let mut categories = Vec::new();
    for scene in scenes {
        for (sub, kind) in [("vertex-face", Kind::VertexFace), ("edge-edge", Kind::EdgeEdge)] {
            let folder = scene.join(sub);
            let mut files: Vec<PathBuf> = std::fs::read_dir(&folder)
                .unwrap_or_else(|e| panic!("{}: {e}", folder.display()))
                .map(|entry| entry.unwrap().path())
                .filter(|path| path.extension().is_some_and(|ext| ext == "csv"))
                .collect();
            files.sort();
            let mut queries = Vec::new();
            for file in &files {
                parse_file(file, &mut queries);
            }
            let name = format!("{}/{sub}", scene.file_name().unwrap().to_string_lossy());
            categories.push(Category { name, kind, queries });
        }
    }
    categories
}
