//! Each simulator can be compiled out with its cargo feature (`shell`, `body`, `lattice`); a
//! C program linked against such a build gets `SOFTSHELL_STATUS_UNSUPPORTED` from the part's
//! `*_new`, with a message that names the feature, and its out-pointer left as it was. Runs in
//! every build CI makes (all parts, none, each alone): with a part built in, its `*_new` works.

use std::ffi::CStr;

use softshell::ffi::SoftshellStatus;
use softshell::ffi::body::*;
use softshell::ffi::lattice::*;
use softshell::ffi::mesh::*;
use softshell::ffi::shell::*;
use softshell::ffi::version::softshell_last_error;

fn last_error() -> String {
    // SAFETY: the library's thread-local message, valid until the next call on this thread.
    unsafe { CStr::from_ptr(softshell_last_error()) }.to_string_lossy().into_owned()
}

/// A closed tetrahedron, outward winding.
fn tetrahedron() -> *mut SoftshellMesh {
    let positions = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    let triangles = [0u32, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3];
    let mut mesh = std::ptr::null_mut();
    // SAFETY: live arrays of the given counts and a live out-pointer.
    let status = unsafe { softshell_mesh_from_arrays(positions.as_ptr(), 4, triangles.as_ptr(), 4, &mut mesh) };
    assert_eq!(status, SoftshellStatus::Ok, "{}", last_error());
    mesh
}

/// `status` of a part's `*_new`, built in or not; `out` must still hold the sentinel without it.
fn check(part: &str, built: bool, status: SoftshellStatus, out_untouched: bool) {
    if built {
        assert_eq!(status, SoftshellStatus::Ok, "{part}: {}", last_error());
    } else {
        assert_eq!(status, SoftshellStatus::Unsupported, "{part}");
        let message = last_error();
        assert!(message.contains(&format!("cargo feature `{part}`")), "{part}: {message}");
        assert!(out_untouched, "{part}: the out-pointer was written");
    }
}

#[test]
fn each_part_works_when_built_in_and_says_which_feature_is_missing_otherwise() {
    let mesh = tetrahedron();
    let sentinel = 0x10 as *mut u8;

    let mut shell = sentinel as *mut SoftshellShell;
    let def = softshell_shell_def_default();
    // SAFETY: a live mesh and def, a live out-pointer.
    let status = unsafe { softshell_shell_new(mesh, &def, &mut shell) };
    check("shell", cfg!(feature = "shell"), status, shell == sentinel as *mut SoftshellShell);
    if status == SoftshellStatus::Ok {
        // SAFETY: made above.
        unsafe { softshell_shell_free(shell) };
    }

    let mut body = sentinel as *mut SoftshellBody;
    let def = softshell_body_def_default();
    // SAFETY: as above.
    let status = unsafe { softshell_body_new(mesh, &def, &mut body) };
    check("body", cfg!(feature = "body"), status, body == sentinel as *mut SoftshellBody);
    if status == SoftshellStatus::Ok {
        // SAFETY: made above.
        unsafe { softshell_body_free(body) };
    }

    let mut lattice = sentinel as *mut SoftshellLattice;
    let def = softshell_lattice_def_default();
    // SAFETY: a live def, no image (a full rectangle), a live out-pointer.
    let status = unsafe { softshell_lattice_new(&def, std::ptr::null(), &mut lattice) };
    check("lattice", cfg!(feature = "lattice"), status, lattice == sentinel as *mut SoftshellLattice);
    if status == SoftshellStatus::Ok {
        // SAFETY: made above.
        unsafe { softshell_lattice_free(lattice) };
    }
    // SAFETY: made above.
    unsafe { softshell_mesh_free(mesh) };
}
