//! The error type every physics and mesh module returns.
//!
//! It carries a kind (what class of failure, which the C boundary turns into a status code) and a
//! message written for the person reading `softshell_last_error()`: which argument, index or
//! value was wrong and what to do instead.

use std::fmt;

/// What class of failure an [`Error`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorKind {
    /// An argument that must not be absent was absent.
    NullArgument,
    /// An argument is out of its range, not finite, or of an unknown kind.
    InvalidArgument,
    /// A mesh does not satisfy what the operation needs (indices, finiteness, topology).
    InvalidMesh,
    /// Reading or writing a file failed.
    Io,
    /// An output buffer is too small.
    BufferTooSmall,
    /// A step diverged and was rolled back.
    Unstable,
    /// The feature was compiled out of this build.
    Unsupported,
    /// A handle was poisoned by an earlier internal failure.
    Poisoned,
    /// A bug inside the library.
    Internal,
}

/// An error with its kind and a human-readable message.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Error {
    /// The class of failure.
    pub kind: ErrorKind,
    /// What went wrong and, where possible, what would work.
    pub message: String,
}

impl Error {
    /// An error of `kind` with `message`.
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> Self {
        Self { kind, message: message.into() }
    }

    /// Shorthand for [`ErrorKind::InvalidArgument`].
    pub fn invalid_argument(message: impl Into<String>) -> Self {
        Self::new(ErrorKind::InvalidArgument, message)
    }

    /// Shorthand for [`ErrorKind::InvalidMesh`].
    pub fn invalid_mesh(message: impl Into<String>) -> Self {
        Self::new(ErrorKind::InvalidMesh, message)
    }

    /// Shorthand for [`ErrorKind::Io`].
    pub fn io(message: impl Into<String>) -> Self {
        Self::new(ErrorKind::Io, message)
    }

    /// Shorthand for [`ErrorKind::Unsupported`]: `feature` names the cargo feature to enable.
    pub fn unsupported(what: &str, feature: &str) -> Self {
        Self::new(
            ErrorKind::Unsupported,
            format!("{what} was compiled out of this build of softshell; rebuild with the cargo feature `{feature}`"),
        )
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}: {}", self.kind, self.message)
    }
}

impl std::error::Error for Error {}

/// The result type of the library's Rust API.
pub type Result<T> = std::result::Result<T, Error>;
