//! softshell: an embeddable library for closed surfaces that shrink, inflate, tear or wobble.
//!
//! Three simulators sit behind opaque handles and a C ABI (`include/softshell.h`):
//! shell contraction (SPEC section 1), a mass-spring soft body with gas and fracture (section 2)
//! and a FastLSM elastic lattice surface (section 3).
//!
//! Dependencies point one way: `ffi -> shell/body/lattice -> solver/collision/material -> mesh`.
//! Nothing below `ffi` knows that a C caller exists; errors travel as [`error::Error`] values and
//! the `ffi` module turns them into status codes and messages.

#![deny(unsafe_op_in_unsafe_fn)]
#![warn(missing_docs)]

#[cfg(feature = "body")]
pub mod body;
pub mod collision;
pub mod error;
pub mod ffi;
#[cfg(feature = "lattice")]
pub mod lattice;
#[cfg(feature = "shell")]
pub mod material;
pub mod mesh;
pub mod parallel;
#[cfg(feature = "shell")]
pub mod shell;
#[cfg(feature = "shell")]
pub mod solver;
