//! Wavefront OBJ input (through tobj) and output.
//!
//! Engines index their per-vertex data by the file's vertex order, so loading keeps it: vertex k
//! of the mesh is the k-th `v` line, used or not. tobj renumbers vertices in order of first use,
//! so the text handed to it starts with one polygon through every vertex in file order (dropped
//! again after parsing), and object, group and material lines are blanked so that everything lands
//! in one model. A line-by-line pre-check finds malformed lines first, because tobj's errors carry
//! no line number.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use glam::Vec3;

use super::tri_mesh::TriMesh;
use crate::error::{Error, Result};

/// Reads a triangle mesh from an OBJ file. Polygons are triangulated as fans; texture
/// coordinates, normals, points and lines are ignored; all objects and groups are merged.
pub fn load_obj(path: &Path) -> Result<TriMesh> {
    let shown = path.display();
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(format!("cannot read OBJ file {shown}: {e}")))?;
    let vertex_count = precheck(&text).map_err(|(line, what)| Error::io(format!("{shown}:{line}: {what}")))?;
    if vertex_count < 3 {
        return Err(Error::invalid_mesh(format!(
            "{shown}: the file has {vertex_count} vertices; a mesh needs at least 3"
        )));
    }

    // One polygon through every vertex in file order registers them with tobj in that order.
    let mut source = String::with_capacity(text.len() + vertex_count * 7);
    source.push('f');
    for v in 1..=vertex_count {
        let _ = write!(source, " {v}");
    }
    source.push('\n');
    for line in text.lines() {
        let keyword = line.split_whitespace().next().unwrap_or("");
        if matches!(keyword, "o" | "g" | "usemtl" | "mtllib") {
            source.push('#');
        }
        source.push_str(line);
        source.push('\n');
    }

    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
        ..Default::default()
    };
    let (models, _) = tobj::load_obj_buf(&mut source.as_bytes(), &options, |_| Ok(Default::default()))
        .map_err(|e| Error::io(format!("{shown}: {e}")))?;
    let [model] = models.as_slice() else {
        return Err(Error::io(format!("{shown}: expected one merged model, tobj returned {}", models.len())));
    };
    let mesh = &model.mesh;
    if mesh.positions.len() != vertex_count * 3 {
        return Err(Error::io(format!(
            "{shown}: tobj kept {} of the file's {vertex_count} vertices",
            mesh.positions.len() / 3
        )));
    }
    let positions = mesh.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])).collect();
    // Skip the vertex-order polygon: it became vertex_count - 2 fan triangles.
    let triangles: Vec<[u32; 3]> =
        mesh.indices.chunks_exact(3).skip(vertex_count - 2).map(|t| [t[0], t[1], t[2]]).collect();
    if triangles.is_empty() {
        return Err(Error::invalid_mesh(format!("{shown}: the file has no faces")));
    }
    TriMesh::new(positions, triangles).map_err(|e| Error::new(e.kind, format!("{shown}: {}", e.message)))
}

/// Checks every `v` and `f` line; returns the number of vertices or the first bad line (1-based)
/// with what is wrong with it.
fn precheck(text: &str) -> std::result::Result<usize, (usize, String)> {
    let mut vertices = 0usize;
    let mut faces: Vec<(usize, i64)> = Vec::new(); // (line, positive 1-based index) to check at the end
    for (number, line) in text.lines().enumerate() {
        let number = number + 1;
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let coordinates: Vec<&str> = words.collect();
                if coordinates.len() < 3 {
                    return Err((number, format!("vertex needs 3 coordinates, found {}: `{line}`", coordinates.len())));
                }
                if let Some(bad) = coordinates[..3].iter().find(|c| c.parse::<f32>().is_err()) {
                    return Err((number, format!("vertex coordinate `{bad}` is not a number")));
                }
                vertices += 1;
            }
            Some("f") => {
                let corners: Vec<&str> = words.collect();
                if corners.len() < 3 {
                    return Err((number, format!("face needs at least 3 vertices, found {}", corners.len())));
                }
                for corner in corners {
                    let index_text = corner.split('/').next().unwrap_or("");
                    let index: i64 = index_text.parse().map_err(|_| {
                        (number, format!("face vertex `{corner}` does not start with an integer index"))
                    })?;
                    if index == 0 {
                        return Err((number, "face vertex index 0: OBJ indices start at 1".to_owned()));
                    }
                    if index < 0 && -index > vertices as i64 {
                        return Err((
                            number,
                            format!("relative face index {index} reaches before the first vertex ({vertices} so far)"),
                        ));
                    }
                    if index > 0 {
                        faces.push((number, index));
                    }
                }
            }
            _ => {}
        }
    }
    if let Some(&(number, index)) = faces.iter().find(|&&(_, index)| index as usize > vertices) {
        return Err((number, format!("face index {index} is out of range: the file has {vertices} vertices")));
    }
    Ok(vertices)
}

/// Writes `positions` and `triangles` as an OBJ file (1-based indices). Coordinates are written
/// with the shortest text that reads back to the same f32, so a save and load round-trips exactly.
pub fn save_obj(positions: &[Vec3], triangles: &[[u32; 3]], path: &Path) -> Result<()> {
    let shown = path.display();
    let io_error = |e: std::io::Error| Error::io(format!("cannot write OBJ file {shown}: {e}"));
    let file = std::fs::File::create(path).map_err(io_error)?;
    let mut out = std::io::BufWriter::new(file);
    writeln!(
        out,
        "# softshell {}: {} vertices, {} triangles",
        env!("CARGO_PKG_VERSION"),
        positions.len(),
        triangles.len()
    )
    .map_err(io_error)?;
    for p in positions {
        writeln!(out, "v {} {} {}", p.x, p.y, p.z).map_err(io_error)?;
    }
    for t in triangles {
        writeln!(out, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1).map_err(io_error)?;
    }
    out.flush().map_err(io_error)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str, text: &str) -> std::path::PathBuf {
        let path = std::env::temp_dir().join(format!("softshell-obj-{}-{name}.obj", std::process::id()));
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn keeps_file_vertex_order_and_triangulates_quads() {
        let path = temp("order", "v 0 0 0\nv 9 9 9\nv 1 0 0\nv 1 1 0\nv 0 1 0\no thing\nf 5 4 3 1\n");
        let mesh = load_obj(&path).unwrap();
        assert_eq!(mesh.vertex_count(), 5);
        assert_eq!(mesh.positions()[1], Vec3::splat(9.0), "unused vertex 2 keeps its place");
        assert_eq!(mesh.positions()[4], Vec3::new(0.0, 1.0, 0.0));
        assert_eq!(mesh.triangles(), &[[4, 3, 2], [4, 2, 0]]);
        std::fs::remove_file(path).ok();
    }

    #[test]
    fn parse_errors_name_the_line() {
        let path = temp("bad", "v 0 0 0\nv 1 0 0\nv 0 x 0\nf 1 2 3\n");
        let error = load_obj(&path).unwrap_err();
        assert!(error.message.contains(":3:") && error.message.contains("`x`"), "{}", error.message);
        let path2 = temp("range", "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 7\n");
        let error = load_obj(&path2).unwrap_err();
        assert!(error.message.contains(":5:") && error.message.contains("7"), "{}", error.message);
        std::fs::remove_file(path).ok();
        std::fs::remove_file(path2).ok();
    }

    #[test]
    fn round_trip_is_exact() {
        let positions = vec![Vec3::new(0.1, -2.5e-7, 3.0), Vec3::new(1.0 / 3.0, 0.0, 0.0), Vec3::new(0.0, 7.0, 1e20)];
        let path = std::env::temp_dir().join(format!("softshell-obj-{}-rt.obj", std::process::id()));
        save_obj(&positions, &[[0, 1, 2]], &path).unwrap();
        let mesh = load_obj(&path).unwrap();
        assert_eq!(mesh.positions(), positions.as_slice());
        assert_eq!(mesh.triangles(), &[[0, 1, 2]]);
        std::fs::remove_file(path).ok();
    }
}
