//! Shared helpers of the `ffi_body_*` tests: meshes made in code, a RAII body wrapper, buffer
//! queries that also check the size protocol, and the invariants of SPEC 2.4 checked through the
//! C ABI only.
#![allow(dead_code)]

use std::collections::HashMap;
use std::ffi::CStr;

use softshell::ffi::body::*;
use softshell::ffi::mesh::*;
use softshell::ffi::version::softshell_last_error;
use softshell::ffi::{SoftshellBody, SoftshellMesh, SoftshellMeshReport, SoftshellStatus};

pub fn last_error() -> String {
    // SAFETY: the library returns a valid NUL-terminated string.
    unsafe { CStr::from_ptr(softshell_last_error()) }.to_string_lossy().into_owned()
}

/// An icosphere of radius `radius` with `levels` subdivisions (12, 42, 162, 642, 2562 vertices).
pub fn icosphere(levels: u32, radius: f32) -> (Vec<f32>, Vec<u32>) {
    let t = (1.0 + 5.0f64.sqrt()) / 2.0;
    let mut p: Vec<[f64; 3]> = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut next = Vec::with_capacity(f.len() * 4);
        for t in &f {
            let mut m = [0u32; 3];
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let key = (a.min(b), a.max(b));
                m[k] = *mid.entry(key).or_insert_with(|| {
                    let (pa, pb) = (p[a as usize], p[b as usize]);
                    p.push([(pa[0] + pb[0]) / 2.0, (pa[1] + pb[1]) / 2.0, (pa[2] + pb[2]) / 2.0]);
                    (p.len() - 1) as u32
                });
            }
            next.push([t[0], m[0], m[2]]);
            next.push([t[1], m[1], m[0]]);
            next.push([t[2], m[2], m[1]]);
            next.push([m[0], m[1], m[2]]);
        }
        f = next;
    }
    let positions = p
        .iter()
        .flat_map(|q| {
            let l = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
            q.map(|c| (c / l) as f32 * radius)
        })
        .collect();
    (positions, f.into_iter().flatten().collect())
}

/// The edges of a mesh, each once as `(a, b)` with a < b, in the order the triangles first use
/// them.
pub fn edges(t: &[u32]) -> Vec<(u32, u32)> {
    let mut seen = std::collections::HashSet::new();
    t.chunks_exact(3)
        .flat_map(|tri| (0..3).map(move |k| (tri[k].min(tri[(k + 1) % 3]), tri[k].max(tri[(k + 1) % 3]))))
        .filter(|&edge| seen.insert(edge))
        .collect()
}

/// `Σ L0²` over the edges of a mesh (each edge once).
pub fn sum_rest_squared(p: &[f32], t: &[u32]) -> f64 {
    edges(t)
        .into_iter()
        .map(|(a, b)| (0..3).map(|c| ((p[3 * a as usize + c] - p[3 * b as usize + c]) as f64).powi(2)).sum::<f64>())
        .sum()
}

/// A flat cloth of `n` x `n` vertices in the x-y plane (spacing `size / (n - 1)`), hanging down
/// from y = 0; vertex `row * n + column`.
pub fn cloth(n: u32, size: f32) -> (Vec<f32>, Vec<u32>) {
    let mut positions = Vec::new();
    for row in 0..n {
        for col in 0..n {
            positions.extend([col as f32 * size / (n - 1) as f32, -(row as f32) * size / (n - 1) as f32, 0.0]);
        }
    }
    let mut triangles = Vec::new();
    for row in 0..n - 1 {
        for col in 0..n - 1 {
            let a = row * n + col;
            triangles.extend([a, a + n, a + 1, a + 1, a + n, a + n + 1]);
        }
    }
    (positions, triangles)
}

pub struct Mesh(pub *mut SoftshellMesh);

impl Mesh {
    pub fn new(positions: &[f32], triangles: &[u32]) -> Self {
        let mut mesh = std::ptr::null_mut();
        // SAFETY: the slices are live for the call.
        let status = unsafe {
            softshell_mesh_from_arrays(
                positions.as_ptr(),
                positions.len() / 3,
                triangles.as_ptr(),
                triangles.len() / 3,
                &mut mesh,
            )
        };
        assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
        Mesh(mesh)
    }

    pub fn report(&self) -> SoftshellMeshReport {
        let mut report = std::mem::MaybeUninit::<SoftshellMeshReport>::uninit();
        // SAFETY: live mesh, writable report.
        let status = unsafe { softshell_mesh_report(self.0, report.as_mut_ptr()) };
        assert_eq!(status, SoftshellStatus::Ok);
        // SAFETY: written on OK.
        unsafe { report.assume_init() }
    }
}

impl Drop for Mesh {
    fn drop(&mut self) {
        // SAFETY: made by softshell_mesh_from_arrays, freed once.
        unsafe { softshell_mesh_free(self.0) };
    }
}

pub struct Body(pub *mut SoftshellBody);

impl Drop for Body {
    fn drop(&mut self) {
        // SAFETY: made by softshell_body_new, freed once.
        unsafe { softshell_body_free(self.0) };
    }
}

/// Makes a body or returns the failing status and message.
pub fn try_body(
    positions: &[f32],
    triangles: &[u32],
    def: &SoftshellBodyDef,
) -> Result<Body, (SoftshellStatus, String)> {
    let mesh = Mesh::new(positions, triangles);
    let mut body = std::ptr::null_mut();
    // SAFETY: live mesh and def.
    let status = unsafe { softshell_body_new(mesh.0, def, &mut body) };
    if status == SoftshellStatus::Ok { Ok(Body(body)) } else { Err((status, last_error())) }
}

pub fn body(positions: &[f32], triangles: &[u32], def: &SoftshellBodyDef) -> Body {
    try_body(positions, triangles, def).unwrap_or_else(|(s, m)| panic!("softshell_body_new: {s:?}: {m}"))
}

type Copy<T> = unsafe extern "C" fn(*const SoftshellBody, *mut T, usize, *mut usize) -> SoftshellStatus;

/// Copies a buffer with the size protocol: asks with NULL, checks that a buffer one element too
/// small is refused and left untouched, then copies.
fn query<T: std::marker::Copy + Default + PartialEq + std::fmt::Debug>(body: &Body, copy: Copy<T>) -> Vec<T> {
    let mut needed = 0usize;
    // SAFETY: NULL buffer with capacity 0 is the documented size query.
    let status = unsafe { copy(body.0, std::ptr::null_mut(), 0, &mut needed) };
    assert_eq!(status, SoftshellStatus::BufferTooSmall);
    if needed > 0 {
        let mut short = vec![T::default(); needed - 1];
        let mut len = 0usize;
        // SAFETY: short holds needed - 1 elements.
        let status = unsafe { copy(body.0, short.as_mut_ptr(), short.len(), &mut len) };
        assert_eq!(status, SoftshellStatus::BufferTooSmall);
        assert_eq!(len, needed);
        assert!(short.iter().all(|v| *v == T::default()), "a refused copy wrote into the buffer");
    }
    let mut out = vec![T::default(); needed];
    let mut len = 0usize;
    // SAFETY: out holds needed elements.
    let status = unsafe { copy(body.0, out.as_mut_ptr(), out.len(), &mut len) };
    assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
    assert_eq!(len, needed);
    out
}

/// Everything a test reads from a body, each buffer fetched with the size protocol.
#[derive(Clone, Debug)]
pub struct Snapshot {
    pub generation: u64,
    pub positions: Vec<f32>,
    pub velocities: Vec<f32>,
    pub masses: Vec<f32>,
    pub triangles: Vec<u32>,
    pub origins: Vec<u32>,
    pub fragments: Vec<u32>,
    pub fragment_count: usize,
}

impl Snapshot {
    pub fn vertex_count(&self) -> usize {
        self.masses.len()
    }
    pub fn triangle_count(&self) -> usize {
        self.triangles.len() / 3
    }
    pub fn position(&self, i: usize) -> [f32; 3] {
        [self.positions[3 * i], self.positions[3 * i + 1], self.positions[3 * i + 2]]
    }
    pub fn total_mass(&self) -> f64 {
        self.masses.iter().map(|&m| m as f64).sum()
    }
    pub fn momentum(&self) -> [f64; 3] {
        let mut p = [0.0; 3];
        for (i, &m) in self.masses.iter().enumerate() {
            for k in 0..3 {
                p[k] += m as f64 * self.velocities[3 * i + k] as f64;
            }
        }
        p
    }
    pub fn center_y(&self) -> f64 {
        let m = self.total_mass();
        self.masses.iter().enumerate().map(|(i, &w)| w as f64 * self.positions[3 * i + 1] as f64).sum::<f64>() / m
    }
}

pub fn snapshot(body: &Body) -> Snapshot {
    // SAFETY: live body.
    let (generation, vertices, triangles, fragment_count) = unsafe {
        (
            softshell_body_topology_generation(body.0),
            softshell_body_vertex_count(body.0),
            softshell_body_triangle_count(body.0),
            softshell_body_fragment_count(body.0),
        )
    };
    let s = Snapshot {
        generation,
        positions: query(body, softshell_body_copy_positions),
        velocities: query(body, softshell_body_copy_velocities),
        masses: query(body, softshell_body_copy_masses),
        triangles: query(body, softshell_body_copy_triangles),
        origins: query(body, softshell_body_copy_vertex_origins),
        fragments: query(body, softshell_body_copy_fragment_ids),
        fragment_count,
    };
    assert_eq!(s.positions.len(), 3 * vertices);
    assert_eq!(s.velocities.len(), 3 * vertices);
    assert_eq!(s.origins.len(), vertices);
    assert_eq!(s.triangles.len(), 3 * triangles);
    assert_eq!(s.fragments.len(), triangles);
    s
}

/// After a topology change, the buffers sized for the old counts must be refused (never
/// overrun) wherever the counts grew.
pub fn old_sizes_are_refused(body: &Body, old: &Snapshot) {
    let new = snapshot(body);
    let checks: [(usize, usize, Copy<f32>); 3] = [
        (old.positions.len(), new.positions.len(), softshell_body_copy_positions),
        (old.velocities.len(), new.velocities.len(), softshell_body_copy_velocities),
        (old.masses.len(), new.masses.len(), softshell_body_copy_masses),
    ];
    for (old_len, new_len, copy) in checks {
        if new_len > old_len {
            let mut buffer = vec![-7.0f32; old_len + 4]; // guard elements after the old size
            let mut len = 0usize;
            // SAFETY: buffer holds old_len + 4 floats; capacity says old_len.
            let status = unsafe { copy(body.0, buffer.as_mut_ptr(), old_len, &mut len) };
            assert_eq!(status, SoftshellStatus::BufferTooSmall);
            assert_eq!(len, new_len);
            assert!(buffer.iter().all(|&v| v == -7.0), "a too-small buffer was written");
        }
    }
    let checks: [(usize, usize, Copy<u32>); 3] = [
        (old.triangles.len(), new.triangles.len(), softshell_body_copy_triangles),
        (old.origins.len(), new.origins.len(), softshell_body_copy_vertex_origins),
        (old.fragments.len(), new.fragments.len(), softshell_body_copy_fragment_ids),
    ];
    for (old_len, new_len, copy) in checks {
        if new_len > old_len {
            let mut buffer = vec![7u32; old_len + 4];
            let mut len = 0usize;
            // SAFETY: buffer holds old_len + 4 values; capacity says old_len.
            let status = unsafe { copy(body.0, buffer.as_mut_ptr(), old_len, &mut len) };
            assert_eq!(status, SoftshellStatus::BufferTooSmall);
            assert_eq!(len, new_len);
            assert!(buffer.iter().all(|&v| v == 7), "a too-small buffer was written");
        }
    }
}

/// SPEC 2.4 invariants of a body's current surface: faces with three distinct in-range corners,
/// edges used by at most two faces, consistent winding, one fan per vertex, fragments equal to
/// the connected components, vertex origins in range.
pub fn check_surface(s: &Snapshot, input_vertices: usize) {
    let n = s.vertex_count();
    for t in s.triangles.chunks_exact(3) {
        assert!(t.iter().all(|&v| (v as usize) < n), "triangle {t:?} out of range ({n} vertices)");
        assert!(t[0] != t[1] && t[1] != t[2] && t[0] != t[2], "triangle {t:?} repeats a corner");
    }
    let mesh = Mesh::new(&s.positions, &s.triangles);
    let report = mesh.report();
    assert_eq!(report.non_manifold_edges, 0, "an edge is used by more than two faces");
    assert!(report.is_consistently_oriented, "a shared edge is run the same way by its two faces");
    assert_eq!(report.non_manifold_vertices, 0, "a vertex joins more than one fan");
    assert_eq!(report.components, s.fragment_count, "fragment count differs from the components");
    let mut seen: HashMap<u32, u32> = HashMap::new();
    let mut component_of_fragment: HashMap<u32, usize> = HashMap::new();
    let _ = &mut component_of_fragment;
    for &f in &s.fragments {
        assert!((f as usize) < s.fragment_count);
        *seen.entry(f).or_default() += 1;
    }
    assert_eq!(seen.len(), s.fragment_count, "every fragment id has triangles");
    for (i, &o) in s.origins.iter().enumerate() {
        assert!((o as usize) < input_vertices, "vertex {i} has origin {o}");
        if i < input_vertices {
            assert_eq!(o as usize, i, "a surviving vertex was renumbered");
        }
    }
}

/// Mass and momentum equal (relative `tolerance`), positions of the old vertices unchanged, and
/// every new vertex placed where a vertex of the same origin was: the checks of a topology change
/// made with no time passing (`softshell_body_break_edge`).
pub fn check_split(before: &Snapshot, after: &Snapshot, tolerance: f64) {
    assert!((after.total_mass() - before.total_mass()).abs() <= tolerance * before.total_mass());
    let (p0, p1) = (before.momentum(), after.momentum());
    // Relative to the vertices' own momenta, whose f32 rounding the sum carries: a body at rest
    // whose net momentum is a small difference of large ones moves it by their rounding.
    let own: f64 = (0..before.vertex_count())
        .map(|i| before.masses[i] as f64 * (0..3).map(|k| (before.velocities[3 * i + k] as f64).abs()).sum::<f64>())
        .sum();
    let scale = own + 1e-9;
    for k in 0..3 {
        assert!((p1[k] - p0[k]).abs() <= tolerance * scale + 1e-9, "momentum {p0:?} -> {p1:?}");
    }
    for i in 0..before.vertex_count() {
        assert_eq!(before.position(i), after.position(i), "vertex {i} moved at the split");
    }
    for i in before.vertex_count()..after.vertex_count() {
        let p = after.position(i);
        let origin = after.origins[i];
        assert!(
            (0..before.vertex_count()).any(|j| before.origins[j] == origin && before.position(j) == p),
            "new vertex {i} is not where a vertex of origin {origin} was"
        );
    }
}

/// One step; panics with the library's message unless it is OK.
pub fn step(body: &Body) -> SoftshellBodyStats {
    let mut stats = SoftshellBodyStats::default();
    // SAFETY: live body, writable stats.
    let status = unsafe { softshell_body_step(body.0, &mut stats) };
    assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
    stats
}

pub fn try_step(body: &Body) -> Result<SoftshellBodyStats, (SoftshellStatus, String)> {
    let mut stats = SoftshellBodyStats::default();
    // SAFETY: live body, writable stats.
    let status = unsafe { softshell_body_step(body.0, &mut stats) };
    if status == SoftshellStatus::Ok { Ok(stats) } else { Err((status, last_error())) }
}

pub fn memory(body: &Body) -> usize {
    // SAFETY: live body.
    unsafe { softshell_body_memory_bytes(body.0) }
}

/// The `substeps >= N` and the `about X s` (largest stable time step) of an explicit
/// integrator's UNSTABLE message.
pub fn unstable_advice(message: &str) -> (u32, f64) {
    let field = |after: &str| message.split(after).nth(1).and_then(|t| t.split([' ', ')']).next()).map(str::to_owned);
    let substeps = field("substeps >= ").and_then(|t| t.parse().ok()).unwrap_or_else(|| panic!("no advice: {message}"));
    let estimate = field("about ").and_then(|t| t.parse().ok()).unwrap_or_else(|| panic!("no estimate: {message}"));
    (substeps, estimate)
}

/// The gas of a step's pieces, total nRT (J): `pressure × volume`, which holds only while no
/// piece is clamped (the pressure then counts the clamped volumes that push, the volume the
/// pieces' own): panics if one is.
pub fn gas_of(stats: &SoftshellBodyStats) -> f64 {
    assert!(!stats.volume_clamped, "a piece's volume is clamped: pressure x volume is not its gas");
    stats.pressure * stats.volume
}
