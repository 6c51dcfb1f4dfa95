//! The C ABI. One file per handle plus the boundary (panics, NULLs, errors, buffers).
//!
//! This module is deliberately thin: it checks every argument, converts between C types and the
//! library's Rust types, and calls into the physics modules, which never see a raw pointer.
//! cbindgen reads these files to write `include/softshell.h`, so the doc comments here are
//! written for C readers.

pub mod body;
pub mod boundary;
pub mod ccd;
pub mod lattice;
pub mod mesh;
pub mod version;

pub use body::{SoftshellBody, SoftshellBodyDef, SoftshellBodyStats};
pub use boundary::SoftshellStatus;
pub use lattice::{SoftshellLattice, SoftshellLatticeDef, SoftshellLatticeStats};
pub use mesh::{SoftshellMesh, SoftshellMeshReport};
pub mod shell;
pub use shell::{SoftshellAnisotropyDef, SoftshellShell, SoftshellShellDef, SoftshellShellStats};
pub mod output;
