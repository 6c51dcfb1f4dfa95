//! Standalone continuous collision queries in double precision (API.md "Collision queries").
//!
//! Always compiled: no cargo feature gates these functions. The geometry lives in
//! `crate::collision`; this file only checks arguments and writes the outputs.

use super::boundary::{SoftshellStatus, arg_slice, out_arg, status_call, write_out};
use crate::collision::{self, filters::V3};
use crate::error::{Error, Result};

/// Reads a `double[3]` argument and checks that it is finite.
///
/// # Safety
/// `ptr` must be NULL or point to three doubles.
unsafe fn arg_dvec3(ptr: *const f64, name: &str) -> Result<V3> {
    // SAFETY: forwarded from the caller.
    let values = unsafe { arg_slice(ptr, 3, name)? };
    let vector = [values[0], values[1], values[2]];
    if let Some(axis) = vector.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid_argument(format!("argument `{name}`[{axis}] = {} is not finite", vector[axis])));
    }
    Ok(vector)
}

fn check_thickness(thickness: f64) -> Result<()> {
    if !thickness.is_finite() || thickness < 0.0 {
        return Err(Error::invalid_argument(format!(
            "`thickness` = {thickness} must be finite and >= 0 (a distance in the units of the positions)"
        )));
    }
    Ok(())
}

/// Reads the eight points of a query: four at t = 0 then four at t = 1.
///
/// # Safety
/// Each pointer must be NULL or point to three doubles.
unsafe fn arg_points(points: [*const f64; 8], names: [&str; 8]) -> Result<([V3; 4], [V3; 4])> {
    let mut read = [[0.0; 3]; 8];
    for k in 0..8 {
        // SAFETY: forwarded from the caller.
        read[k] = unsafe { arg_dvec3(points[k], names[k])? };
    }
    Ok(([read[0], read[1], read[2], read[3]], [read[4], read[5], read[6], read[7]]))
}

fn write_answer(out_hit: *mut i32, out_toi: *mut f64, toi: Option<f64>) {
    // SAFETY: both pointers were checked by out_arg before any work.
    unsafe {
        write_out(out_hit, i32::from(toi.is_some()));
        write_out(out_toi, toi.unwrap_or(1.0));
    }
}

/// Continuous collision of vertex `p` against triangle `abc`, each point moving linearly from
/// its first position (`p0`, `a0`, `b0`, `c0`, at t = 0) to its second (`p1`, `a1`, `b1`, `c1`,
/// at t = 1) over one step. Positions are x,y,z doubles in any length unit; `thickness` is a
/// distance in the same unit (0 for exact contact).
///
/// On success `*out_hit` is 1 and `*out_toi` the time in [0, 1] at which the distance may first
/// be <= `thickness`, or `*out_hit` is 0 and `*out_toi` is 1.0 (no contact during the step).
/// The answer is conservative: a contact is never missed, and `*out_toi` is never later than the
/// true first contact time. Usually it is within 1e-6 of the step of a time at which each
/// coordinate of the gap is already within `thickness` plus a tolerance (the largest of 1e-6 of
/// the largest displacement of a point, 1e-12 of the points' extent and `thickness` / 64); for
/// the rare queries that use up the fixed work budget it may be earlier. A near miss within
/// that tolerance of `thickness` (or within a few units in the last place of the coordinates),
/// or a query with a coordinate or a `thickness` above 2^1000 in magnitude, may be reported as a
/// hit (at t = 0). The time
/// per call is bounded (about 100 microseconds at worst; typically well under a microsecond).
///
/// Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` when a pointer is NULL and
/// `SOFTSHELL_STATUS_INVALID_ARGUMENT` when a coordinate is NaN or infinite or `thickness` is
/// negative, NaN or infinite; then neither output is written.
///
/// # Safety
/// Each position pointer must be NULL or point to three doubles; `out_hit` and `out_toi` must be
/// NULL or writable. Thread-safe: the call uses no shared state.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_ccd_vertex_triangle(
    p0: *const f64,
    a0: *const f64,
    b0: *const f64,
    c0: *const f64,
    p1: *const f64,
    a1: *const f64,
    b1: *const f64,
    c1: *const f64,
    thickness: f64,
    out_hit: *mut i32,
    out_toi: *mut f64,
) -> SoftshellStatus {
    status_call("softshell_ccd_vertex_triangle", || {
        let out_hit = out_arg(out_hit, "out_hit")?;
        let out_toi = out_arg(out_toi, "out_toi")?;
        // SAFETY: the caller promises three doubles behind each non-NULL pointer.
        let (start, end) =
            unsafe { arg_points([p0, a0, b0, c0, p1, a1, b1, c1], ["p0", "a0", "b0", "c0", "p1", "a1", "b1", "c1"])? };
        check_thickness(thickness)?;
        write_answer(out_hit, out_toi, collision::vertex_triangle(&start, &end, thickness));
        Ok(())
    })
}

/// Continuous collision of edge `ab` against edge `cd`, each point moving linearly from its
/// first position (`a0`, `b0`, `c0`, `d0`, at t = 0) to its second (`a1`, `b1`, `c1`, `d1`, at
/// t = 1) over one step. Positions are x,y,z doubles in any length unit; `thickness` is a
/// distance in the same unit (0 for exact contact). Parallel, collinear and zero-length edges
/// are handled.
///
/// On success `*out_hit` is 1 and `*out_toi` the time in [0, 1] at which the distance may first
/// be <= `thickness`, or `*out_hit` is 0 and `*out_toi` is 1.0 (no contact during the step).
/// The answer is conservative: a contact is never missed, and `*out_toi` is never later than the
/// true first contact time. Usually it is within 1e-6 of the step of a time at which each
/// coordinate of the gap is already within `thickness` plus a tolerance (the largest of 1e-6 of
/// the largest displacement of a point, 1e-12 of the points' extent and `thickness` / 64); for
/// the rare queries that use up the fixed work budget it may be earlier. A near miss within
/// that tolerance of `thickness` (or within a few units in the last place of the coordinates),
/// or a query with a coordinate or a `thickness` above 2^1000 in magnitude, may be reported as a
/// hit (at t = 0). The time
/// per call is bounded (about 100 microseconds at worst; typically well under a microsecond).
///
/// Returns `SOFTSHELL_STATUS_NULL_ARGUMENT` when a pointer is NULL and
/// `SOFTSHELL_STATUS_INVALID_ARGUMENT` when a coordinate is NaN or infinite or `thickness` is
/// negative, NaN or infinite; then neither output is written.
///
/// # Safety
/// Each position pointer must be NULL or point to three doubles; `out_hit` and `out_toi` must be
/// NULL or writable. Thread-safe: the call uses no shared state.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn softshell_ccd_edge_edge(
    a0: *const f64,
    b0: *const f64,
    c0: *const f64,
    d0: *const f64,
    a1: *const f64,
    b1: *const f64,
    c1: *const f64,
    d1: *const f64,
    thickness: f64,
    out_hit: *mut i32,
    out_toi: *mut f64,
) -> SoftshellStatus {
    status_call("softshell_ccd_edge_edge", || {
        let out_hit = out_arg(out_hit, "out_hit")?;
        let out_toi = out_arg(out_toi, "out_toi")?;
        // SAFETY: the caller promises three doubles behind each non-NULL pointer.
        let (start, end) =
            unsafe { arg_points([a0, b0, c0, d0, a1, b1, c1, d1], ["a0", "b0", "c0", "d0", "a1", "b1", "c1", "d1"])? };
        check_thickness(thickness)?;
        write_answer(out_hit, out_toi, collision::edge_edge(&start, &end, thickness));
        Ok(())
    })
}
