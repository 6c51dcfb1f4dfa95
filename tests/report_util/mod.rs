//! Thin RAII wrappers over the C ABI shared by `tests/stability.rs`, `tests/leave_out.rs` and the
//! `error_vs_time` bench (which includes this file with `#[path]`). Only exported `softshell_*`
//! functions are called: nothing here reaches into the library's Rust internals.
#![allow(dead_code)]

use std::ffi::CStr;
use std::ptr::{null, null_mut};

use softshell::ffi::body::*;
use softshell::ffi::lattice::*;
use softshell::ffi::mesh::*;
use softshell::ffi::shell::*;
use softshell::ffi::version::softshell_last_error;
use softshell::ffi::{SoftshellMeshReport, SoftshellStatus};

pub mod cases;

/// A failing call: its status and the library's message.
pub type Failure = (SoftshellStatus, String);

/// The last error message of this thread.
pub fn last_error() -> String {
    // SAFETY: the library returns a valid NUL-terminated string.
    unsafe { CStr::from_ptr(softshell_last_error()) }.to_string_lossy().into_owned()
}

fn check(status: SoftshellStatus) -> Result<(), Failure> {
    if status == SoftshellStatus::Ok { Ok(()) } else { Err((status, last_error())) }
}

/// Reads `v` and `f` lines of an OBJ file of data/ (no `obj` feature needed).
pub fn read_obj(name: &str) -> (Vec<f32>, Vec<u32>) {
    let path = format!("{}/data/{name}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let (mut positions, mut triangles) = (Vec::new(), Vec::new());
    for line in text.lines() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => positions.extend(words.take(3).map(|w| w.parse::<f32>().unwrap())),
            Some("f") => triangles.extend(words.map(|w| w.split('/').next().unwrap().parse::<u32>().unwrap() - 1)),
            _ => {}
        }
    }
    (positions, triangles)
}

/// Moves the bounding-box centre to the origin and scales the diagonal to `diagonal`.
pub fn normalise(positions: &mut [f32], diagonal: f32) {
    let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
    for p in positions.chunks(3) {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let d = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f32>().sqrt();
    for p in positions.chunks_mut(3) {
        for k in 0..3 {
            p[k] = (p[k] - 0.5 * (lo[k] + hi[k])) / d * diagonal;
        }
    }
}

/// data/`name` scaled to a bounding-box diagonal of `diagonal`, centred at the origin.
pub fn unit_obj(name: &str, diagonal: f32) -> (Vec<f32>, Vec<u32>) {
    let (mut p, t) = read_obj(name);
    normalise(&mut p, diagonal);
    (p, t)
}

/// A regular tetrahedron of edge about `size`, outward normals.
pub fn tetrahedron(size: f32) -> (Vec<f32>, Vec<u32>) {
    let s = size / (2.0 * 2.0f32.sqrt()); // edge = 2 sqrt(2) s
    let p = vec![s, s, s, s, -s, -s, -s, s, -s, -s, -s, s];
    (p, vec![0, 1, 2, 0, 3, 1, 0, 2, 3, 1, 3, 2])
}

/// A closed triangular bipyramid whose apex angles are below 1 degree (sliver triangles).
pub fn sliver_bipyramid() -> (Vec<f32>, Vec<u32>) {
    let r = 0.006f32; // equator radius; apexes at y = +-0.5 -> apex angle ~ 1.2 * r / 0.5 rad
    let mut p = vec![0.0, 0.5, 0.0, 0.0, -0.5, 0.0];
    for k in 0..3 {
        let a = k as f32 * std::f32::consts::TAU / 3.0;
        p.extend([r * a.cos(), 0.0, -r * a.sin()]);
    }
    // Equator 2,3,4 counter-clockwise seen from +y.
    let t = vec![0, 2, 3, 0, 3, 4, 0, 4, 2, 1, 3, 2, 1, 4, 3, 1, 2, 4];
    (p, t)
}

/// An octahedron whose vertex 4 (+z) is moved onto the midpoint of vertices 0 (+x) and 2 (+y):
/// triangle `ZERO_AREA_TRIANGLE` (0, 2, 4) has zero area, the others do not.
pub fn octahedron_with_zero_area_triangle() -> (Vec<f32>, Vec<u32>) {
    let p = vec![
        1.0, 0.0, 0.0, // 0 +x
        -1.0, 0.0, 0.0, // 1 -x
        0.0, 1.0, 0.0, // 2 +y
        0.0, -1.0, 0.0, // 3 -y
        0.5, 0.5, 0.0, // 4 (+z moved onto the segment 0-2)
        0.0, 0.0, -1.0, // 5 -z
    ];
    let t = vec![
        3, 0, 4, // 0
        0, 2, 4, // 1: zero area
        2, 1, 4, // 2
        1, 3, 4, // 3
        0, 3, 5, // 4
        2, 0, 5, // 5
        1, 2, 5, // 6
        3, 1, 5, // 7
    ];
    (p, t)
}

/// Index of the zero-area triangle of [`octahedron_with_zero_area_triangle`].
pub const ZERO_AREA_TRIANGLE: usize = 1;

/// Largest absolute coordinate (infinite if any is not finite).
pub fn max_abs(values: &[f32]) -> f32 {
    values.iter().fold(0.0f32, |m, v| if v.is_finite() { m.max(v.abs()) } else { f32::INFINITY })
}

/// Root-mean-square distance between two equally long position arrays (3 floats per point).
pub fn rms_distance(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len());
    let n = a.len() / 3;
    let sum: f64 = a
        .chunks(3)
        .zip(b.chunks(3))
        .map(|(p, q)| (0..3).map(|k| (p[k] as f64 - q[k] as f64).powi(2)).sum::<f64>())
        .sum();
    (sum / n.max(1) as f64).sqrt()
}

type CopyFn<H, T> = unsafe extern "C" fn(*const H, *mut T, usize, *mut usize) -> SoftshellStatus;

/// Copies a buffer with the size protocol (NULL query, then the exact size).
pub fn copy_buffer<H, T: Copy + Default>(handle: *const H, copy: CopyFn<H, T>) -> Vec<T> {
    let mut needed = 0usize;
    // SAFETY: a NULL buffer with capacity 0 is the documented size query.
    unsafe { copy(handle, null_mut(), 0, &mut needed) };
    let mut out = vec![T::default(); needed];
    let mut len = 0usize;
    // SAFETY: `out` holds `needed` elements.
    let status = unsafe { copy(handle, out.as_mut_ptr(), out.len(), &mut len) };
    assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
    out
}

pub struct Mesh(pub *mut SoftshellMesh);

impl Mesh {
    pub fn new(positions: &[f32], triangles: &[u32]) -> Result<Mesh, Failure> {
        let mut mesh = null_mut();
        // SAFETY: the slices are live for the call; `mesh` is writable.
        let status = unsafe {
            softshell_mesh_from_arrays(
                positions.as_ptr(),
                positions.len() / 3,
                triangles.as_ptr(),
                triangles.len() / 3,
                &mut mesh,
            )
        };
        check(status).map(|_| Mesh(mesh))
    }

    pub fn report(&self) -> SoftshellMeshReport {
        let mut report = std::mem::MaybeUninit::<SoftshellMeshReport>::uninit();
        // SAFETY: live mesh, writable report.
        assert_eq!(unsafe { softshell_mesh_report(self.0, report.as_mut_ptr()) }, SoftshellStatus::Ok);
        // SAFETY: written on OK.
        unsafe { report.assume_init() }
    }
}

impl Drop for Mesh {
    fn drop(&mut self) {
        // SAFETY: made by the library, freed once.
        unsafe { softshell_mesh_free(self.0) }
    }
}

// ------------------------------------------------------------------------------------------ shell

pub struct Shell(pub *mut SoftshellShell);

impl Drop for Shell {
    fn drop(&mut self) {
        // SAFETY: made by the library, freed once.
        unsafe { softshell_shell_free(self.0) }
    }
}

impl Shell {
    pub fn new(positions: &[f32], triangles: &[u32], def: &SoftshellShellDef) -> Result<Shell, Failure> {
        let mesh = Mesh::new(positions, triangles)?;
        let mut shell = null_mut();
        // SAFETY: live mesh and def, writable out-pointer.
        check(unsafe { softshell_shell_new(mesh.0, def, &mut shell) }).map(|_| Shell(shell))
    }
    pub fn step(&self) -> Result<SoftshellShellStats, Failure> {
        let mut stats = SoftshellShellStats::default();
        // SAFETY: live shell, writable stats.
        check(unsafe { softshell_shell_step(self.0, &mut stats) }).map(|_| stats)
    }
    pub fn positions(&self) -> Vec<f32> {
        copy_buffer(self.0, softshell_shell_copy_positions)
    }
    pub fn face_energy(&self) -> Vec<f32> {
        copy_buffer(self.0, softshell_shell_copy_face_energy)
    }
    pub fn memory(&self) -> usize {
        // SAFETY: live shell.
        unsafe { softshell_shell_memory_bytes(self.0) }
    }
    pub fn add_region(&self, faces: &[u32], def: &SoftshellAnisotropyDef) -> Result<(), Failure> {
        // SAFETY: live shell, slice and def.
        check(unsafe { softshell_shell_add_anisotropic_region(self.0, faces.as_ptr(), faces.len(), def) })
    }
}

/// The faces whose centroid lies within `radius` of the mesh point farthest along +x: a cap.
pub fn cap_faces(positions: &[f32], triangles: &[u32], radius: f32) -> Vec<u32> {
    let tip = positions
        .chunks(3)
        .fold([f32::MIN, 0.0, 0.0], |best, p| if p[0] > best[0] { [p[0], p[1], p[2]] } else { best });
    triangles
        .chunks(3)
        .enumerate()
        .filter(|(_, t)| {
            let c: Vec<f32> =
                (0..3).map(|k| t.iter().map(|&v| positions[3 * v as usize + k]).sum::<f32>() / 3.0).collect();
            (0..3).map(|k| (c[k] - tip[k]).powi(2)).sum::<f32>().sqrt() < radius
        })
        .map(|(i, _)| i as u32)
        .collect()
}

// ------------------------------------------------------------------------------------------- body

pub struct Body(pub *mut softshell::ffi::SoftshellBody);

impl Drop for Body {
    fn drop(&mut self) {
        // SAFETY: made by the library, freed once.
        unsafe { softshell_body_free(self.0) }
    }
}

impl Body {
    pub fn new(positions: &[f32], triangles: &[u32], def: &SoftshellBodyDef) -> Result<Body, Failure> {
        let mesh = Mesh::new(positions, triangles)?;
        let mut body = null_mut();
        // SAFETY: live mesh and def, writable out-pointer.
        check(unsafe { softshell_body_new(mesh.0, def, &mut body) }).map(|_| Body(body))
    }
    pub fn step(&self) -> Result<SoftshellBodyStats, Failure> {
        let mut stats = SoftshellBodyStats::default();
        // SAFETY: live body, writable stats.
        check(unsafe { softshell_body_step(self.0, &mut stats) }).map(|_| stats)
    }
    pub fn positions(&self) -> Vec<f32> {
        copy_buffer(self.0, softshell_body_copy_positions)
    }
    pub fn velocities(&self) -> Vec<f32> {
        copy_buffer(self.0, softshell_body_copy_velocities)
    }
    pub fn masses(&self) -> Vec<f32> {
        copy_buffer(self.0, softshell_body_copy_masses)
    }
    pub fn triangles(&self) -> Vec<u32> {
        copy_buffer(self.0, softshell_body_copy_triangles)
    }
    pub fn memory(&self) -> usize {
        // SAFETY: live body.
        unsafe { softshell_body_memory_bytes(self.0) }
    }
    pub fn impulse(&self, vertex: u32, impulse: [f32; 3]) -> Result<(), Failure> {
        // SAFETY: live body, three readable floats.
        check(unsafe { softshell_body_apply_impulse(self.0, vertex, impulse.as_ptr()) })
    }
}

// ---------------------------------------------------------------------------------------- lattice

pub struct Lattice(pub *mut softshell::ffi::SoftshellLattice);

impl Drop for Lattice {
    fn drop(&mut self) {
        // SAFETY: made by the library, freed once.
        unsafe { softshell_lattice_free(self.0) }
    }
}

impl Lattice {
    pub fn new(def: &SoftshellLatticeDef) -> Result<Lattice, Failure> {
        let mut lattice = null_mut();
        // SAFETY: live def, NULL mask (full sheet), writable out-pointer.
        check(unsafe { softshell_lattice_new(def, null(), &mut lattice) }).map(|_| Lattice(lattice))
    }
    pub fn step(&self) -> Result<SoftshellLatticeStats, Failure> {
        let mut stats = SoftshellLatticeStats::default();
        // SAFETY: live lattice, writable stats.
        check(unsafe { softshell_lattice_step(self.0, &mut stats) }).map(|_| stats)
    }
    pub fn positions(&self) -> Vec<f32> {
        copy_buffer(self.0, softshell_lattice_copy_positions)
    }
    pub fn velocities(&self) -> Vec<f32> {
        copy_buffer(self.0, softshell_lattice_copy_velocities)
    }
    pub fn set_positions(&self, p: &[f32]) -> Result<(), Failure> {
        // SAFETY: live lattice and slice.
        check(unsafe { softshell_lattice_set_positions(self.0, p.as_ptr(), p.len()) })
    }
    pub fn pin(&self, column: u32, row: u32) -> Result<(), Failure> {
        // SAFETY: live lattice.
        check(unsafe { softshell_lattice_pin(self.0, column, row) })
    }
    pub fn force(&self, column: u32, row: u32, f: [f32; 3]) -> Result<(), Failure> {
        // SAFETY: live lattice, three readable floats.
        check(unsafe { softshell_lattice_apply_force(self.0, column, row, f.as_ptr()) })
    }
    pub fn memory(&self) -> usize {
        // SAFETY: live lattice.
        unsafe { softshell_lattice_memory_bytes(self.0) }
    }
}

/// Rest positions of a full `columns` x `rows` sheet (particle order: row by row).
pub fn lattice_rest(columns: u32, rows: u32, spacing: f32) -> Vec<f32> {
    (0..rows).flat_map(|r| (0..columns).flat_map(move |c| [c as f32 * spacing, 0.0, r as f32 * spacing])).collect()
}

/// Runs `f` with the denormals-are-zero and flush-to-zero bits of this thread's MXCSR set, as a
/// host built with -ffast-math (gcc's crtfastmath.o) or an engine that sets them for speed
/// runs; the bits are restored afterwards, also when `f` panics.
#[cfg(target_arch = "x86_64")]
#[allow(dead_code)]
pub fn with_denormals_are_zero<R>(f: impl FnOnce() -> R + std::panic::UnwindSafe) -> R {
    fn read() -> u32 {
        let mut v: u32 = 0;
        // SAFETY: stmxcsr writes 4 bytes to a local.
        unsafe { std::arch::asm!("stmxcsr [{}]", in(reg) &mut v, options(nostack)) };
        v
    }
    fn write(v: u32) {
        // SAFETY: ldmxcsr reads 4 bytes from a local.
        unsafe { std::arch::asm!("ldmxcsr [{}]", in(reg) &v, options(nostack)) };
    }
    let saved = read();
    write(saved | (1 << 6) | (1 << 15)); // DAZ | FTZ
    let result = std::panic::catch_unwind(f);
    write(saved);
    result.unwrap_or_else(|e| std::panic::resume_unwind(e))
}
