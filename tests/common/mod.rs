//! Helpers shared by the integration tests. They only wrap the C ABI: no test reaches into the
//! library's Rust internals.
#![allow(dead_code)]

use std::ffi::CStr;
#[cfg(feature = "obj")]
use std::ffi::CString;
use std::path::PathBuf;

use softshell::ffi::mesh::*;
use softshell::ffi::version::*;
use softshell::ffi::{SoftshellMesh, SoftshellStatus};

/// The last error message of this thread.
pub fn last_error() -> String {
    // SAFETY: the library returns a valid NUL-terminated string.
    unsafe { CStr::from_ptr(softshell_last_error()) }.to_string_lossy().into_owned()
}

/// Path of a file in the repository's data/ directory.
pub fn data_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data").join(name)
}

/// Loads `data/<name>` through the C ABI (`softshell_mesh_load_obj`); panics with the library's
/// message on failure. Without the `obj` feature the test reads the plain `v`/`f` lines itself and
/// goes through `softshell_mesh_from_arrays`, so the simulators' tests run in every build.
pub fn load_data_mesh(name: &str) -> *mut SoftshellMesh {
    #[cfg(feature = "obj")]
    {
        let path = CString::new(data_path(name).to_str().unwrap()).unwrap();
        let mut mesh = std::ptr::null_mut();
        // SAFETY: valid path and out-pointer.
        let status = unsafe { softshell_mesh_load_obj(path.as_ptr(), &mut mesh) };
        assert_eq!(status, SoftshellStatus::Ok, "loading {name}: {}", last_error());
        mesh
    }
    #[cfg(not(feature = "obj"))]
    {
        let text = std::fs::read_to_string(data_path(name)).unwrap();
        let (mut positions, mut triangles) = (Vec::new(), Vec::new());
        for line in text.lines() {
            let mut words = line.split_whitespace();
            match words.next() {
                Some("v") => positions.extend(words.take(3).map(|w| w.parse::<f32>().unwrap())),
                Some("f") => triangles.extend(words.map(|w| w.parse::<u32>().unwrap() - 1)),
                _ => {}
            }
        }
        mesh_from(&positions, &triangles).unwrap_or_else(|e| panic!("loading {name}: {e:?}"))
    }
}

/// Creates a mesh from flat arrays through the C ABI.
pub fn mesh_from(positions: &[f32], triangles: &[u32]) -> Result<*mut SoftshellMesh, (SoftshellStatus, String)> {
    let mut mesh = std::ptr::null_mut();
    // SAFETY: slices are live for the call.
    let status = unsafe {
        softshell_mesh_from_arrays(
            positions.as_ptr(),
            positions.len() / 3,
            triangles.as_ptr(),
            triangles.len() / 3,
            &mut mesh,
        )
    };
    if status == SoftshellStatus::Ok { Ok(mesh) } else { Err((status, last_error())) }
}

/// Positions of a mesh through the C ABI.
pub fn mesh_positions(mesh: *const SoftshellMesh) -> Vec<f32> {
    let mut len = 0usize;
    // SAFETY: size query with a NULL buffer.
    let status = unsafe { softshell_mesh_copy_positions(mesh, std::ptr::null_mut(), 0, &mut len) };
    assert_eq!(status, SoftshellStatus::BufferTooSmall);
    let mut out = vec![0.0f32; len];
    // SAFETY: buffer of `len` floats.
    let status = unsafe { softshell_mesh_copy_positions(mesh, out.as_mut_ptr(), out.len(), &mut len) };
    assert_eq!(status, SoftshellStatus::Ok);
    out
}

/// Triangles of a mesh through the C ABI.
pub fn mesh_triangles(mesh: *const SoftshellMesh) -> Vec<u32> {
    let mut len = 0usize;
    // SAFETY: size query with a NULL buffer.
    unsafe { softshell_mesh_copy_triangles(mesh, std::ptr::null_mut(), 0, &mut len) };
    let mut out = vec![0u32; len];
    // SAFETY: buffer of `len` elements.
    let status = unsafe { softshell_mesh_copy_triangles(mesh, out.as_mut_ptr(), out.len(), &mut len) };
    assert_eq!(status, SoftshellStatus::Ok);
    out
}

/// The version numbers written into include/softshell.h.
pub fn header_version() -> (u32, u32, u32) {
    let header =
        std::fs::read_to_string(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("include/softshell.h")).unwrap();
    let read = |name: &str| -> u32 {
        let line = header.lines().find(|l| l.starts_with(&format!("#define {name} "))).unwrap();
        line.split_whitespace().nth(2).unwrap().parse().unwrap()
    };
    (read("SOFTSHELL_VERSION_MAJOR"), read("SOFTSHELL_VERSION_MINOR"), read("SOFTSHELL_VERSION_PATCH"))
}

/// Runs `softshell_abi_version` (keeps the import used in every test binary).
pub fn abi_version() -> u32 {
    softshell_abi_version()
}

/// A `softshell_*_copy_*` function of float buffers, for any handle type.
pub type CopyFloats<H> = unsafe extern "C" fn(*const H, *mut f32, usize, *mut usize) -> SoftshellStatus;

/// A whole float buffer of `handle` by `copy`: its size asked with NULL, then copied.
pub fn copied<H>(handle: *mut H, copy: CopyFloats<H>) -> Vec<f32> {
    let mut len = 0usize;
    // SAFETY: the caller's live handle; a NULL buffer asks for the size.
    assert_eq!(unsafe { copy(handle, std::ptr::null_mut(), 0, &mut len) }, SoftshellStatus::BufferTooSmall);
    let mut out = vec![0.0f32; len];
    // SAFETY: `out` holds `len` floats.
    assert_eq!(unsafe { copy(handle, out.as_mut_ptr(), len, &mut len) }, SoftshellStatus::Ok, "{}", last_error());
    out
}
