//! PLY output (ASCII) with per-vertex scalars, one of them also written as vertex colours, so
//! MeshLab, Blender or ParaView show curvature, energy or force on the surface directly.

use std::io::Write as _;
use std::path::Path;

use glam::Vec3;

use crate::error::{Error, Result};

/// A named per-vertex scalar (one value per vertex).
pub struct VertexScalar<'a> {
    /// Property name in the PLY header (letters, digits and '_').
    pub name: &'a str,
    /// One value per vertex.
    pub values: &'a [f32],
}

/// Maps a value to a colour: a diverging blue-white-red map symmetric about 0 when the values
/// have both signs (curvature), otherwise a dark-blue-to-yellow ramp from min to max (energy).
/// The range is taken between the 2nd and 98th percentiles, so a few outliers (a sliver's
/// curvature) do not wash out the picture.
fn colour_map(values: &[f32]) -> impl Fn(f32) -> [u8; 3] {
    let mut finite: Vec<f32> = values.iter().copied().filter(|v| v.is_finite()).collect();
    finite.sort_by(f32::total_cmp);
    let pick =
        |q: f64| finite.get(((finite.len().saturating_sub(1)) as f64 * q).round() as usize).copied().unwrap_or(0.0);
    let (low, high) = (pick(0.02), pick(0.98));
    let diverging = low < 0.0 && high > 0.0;
    let scale = if diverging { low.abs().max(high) } else { (high - low).max(f32::MIN_POSITIVE) };
    move |v: f32| {
        let v = if v.is_finite() { v } else { 0.0 };
        let to_byte = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
        if diverging {
            let t = (v / scale).clamp(-1.0, 1.0);
            if t < 0.0 { [to_byte(1.0 + t), to_byte(1.0 + t), 255] } else { [255, to_byte(1.0 - t), to_byte(1.0 - t)] }
        } else {
            let t = ((v - low) / scale).clamp(0.0, 1.0);
            [to_byte(0.1 + 0.9 * t), to_byte(0.1 + 0.8 * t), to_byte(0.45 * (1.0 - t))]
        }
    }
}

/// Writes an ASCII PLY file with positions, triangles, every scalar in `scalars` as a float
/// property, and vertex colours from `scalars[colour_by]` (no colours when `scalars` is empty).
pub fn save_ply(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    scalars: &[VertexScalar<'_>],
    colour_by: usize,
    path: &Path,
) -> Result<()> {
    for s in scalars {
        if s.values.len() != positions.len() {
            return Err(Error::invalid_argument(format!(
                "scalar `{}` has {} values for {} vertices",
                s.name,
                s.values.len(),
                positions.len()
            )));
        }
        if s.name.is_empty() || !s.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(Error::invalid_argument(format!("scalar name `{}` must be letters, digits or '_'", s.name)));
        }
    }
    if !scalars.is_empty() && colour_by >= scalars.len() {
        return Err(Error::invalid_argument(format!("colour_by {colour_by} but only {} scalars", scalars.len())));
    }
    let shown = path.display();
    let io_error = |e: std::io::Error| Error::io(format!("cannot write PLY file {shown}: {e}"));
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).map_err(io_error)?);
    let mut header = format!(
        "ply\nformat ascii 1.0\ncomment softshell {}\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n",
        env!("CARGO_PKG_VERSION"),
        positions.len()
    );
    if !scalars.is_empty() {
        header.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\n");
    }
    for s in scalars {
        header.push_str(&format!("property float {}\n", s.name));
    }
    header
        .push_str(&format!("element face {}\nproperty list uchar uint vertex_indices\nend_header\n", triangles.len()));
    out.write_all(header.as_bytes()).map_err(io_error)?;
    let colour = scalars.get(colour_by).map(|s| (colour_map(s.values), s.values));
    for (i, p) in positions.iter().enumerate() {
        write!(out, "{} {} {}", p.x, p.y, p.z).map_err(io_error)?;
        if let Some((map, values)) = &colour {
            let [r, g, b] = map(values[i]);
            write!(out, " {r} {g} {b}").map_err(io_error)?;
        }
        for s in scalars {
            write!(out, " {}", s.values[i]).map_err(io_error)?;
        }
        writeln!(out).map_err(io_error)?;
    }
    for t in triangles {
        writeln!(out, "3 {} {} {}", t[0], t[1], t[2]).map_err(io_error)?;
    }
    out.flush().map_err(io_error)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_header_colours_and_scalars() {
        let path = std::env::temp_dir().join(format!("softshell-ply-{}.ply", std::process::id()));
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let h = [-1.0f32, 0.0, 1.0];
        save_ply(&p, &[[0, 1, 2]], &[VertexScalar { name: "mean_curvature", values: &h }], 0, &path).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("element vertex 3\n") && text.contains("property float mean_curvature\n"));
        let body: Vec<&str> = text.split("end_header\n").nth(1).unwrap().lines().collect();
        assert_eq!(body[0], "0 0 0 0 0 255 -1", "negative curvature is blue");
        assert_eq!(body[1], "1 0 0 255 255 255 0", "zero is white");
        assert_eq!(body[2], "0 1 0 255 0 0 1", "positive is red");
        assert_eq!(body[3], "3 0 1 2");
        let error = save_ply(&p, &[[0, 1, 2]], &[VertexScalar { name: "bad name", values: &h }], 0, &path).unwrap_err();
        assert!(error.message.contains("bad name"));
        std::fs::remove_file(path).ok();
    }
}
