//! Library-wide calls: versions, status names and the last error message.

use std::ffi::{CStr, c_char};

use super::boundary::{SoftshellStatus, last_error_ptr, value_call};

const VERSION_STRING: &CStr = {
    // The same numbers as the SOFTSHELL_VERSION_* macros that build.rs writes into the header.
    match CStr::from_bytes_with_nul(concat!(env!("CARGO_PKG_VERSION"), "\0").as_bytes()) {
        Ok(text) => text,
        Err(_) => panic!("the crate version contains a NUL byte"),
    }
};

const fn parse_u32(text: &str) -> u32 {
    let bytes = text.as_bytes();
    let mut value = 0u32;
    let mut i = 0;
    while i < bytes.len() {
        value = value * 10 + (bytes[i] - b'0') as u32;
        i += 1;
    }
    value
}

const ABI_VERSION: u32 = (parse_u32(env!("CARGO_PKG_VERSION_MAJOR")) << 16)
    | (parse_u32(env!("CARGO_PKG_VERSION_MINOR")) << 8)
    | parse_u32(env!("CARGO_PKG_VERSION_PATCH"));

/// The version of the library that is linked, encoded as
/// `(major << 16) | (minor << 8) | patch`: equal to `SOFTSHELL_ABI_VERSION` when the header and
/// the library match. Never fails.
#[unsafe(no_mangle)]
pub extern "C" fn softshell_abi_version() -> u32 {
    value_call("softshell_abi_version", ABI_VERSION, || ABI_VERSION)
}

/// The version of the library that is linked, as "major.minor.patch" (equal to
/// `SOFTSHELL_VERSION_STRING` when the header and the library match). The string is static:
/// never free it. Never NULL.
#[unsafe(no_mangle)]
pub extern "C" fn softshell_version_string() -> *const c_char {
    value_call("softshell_version_string", VERSION_STRING.as_ptr(), || VERSION_STRING.as_ptr())
}

/// The static name of a status value, such as "INVALID_MESH" for `SOFTSHELL_STATUS_INVALID_MESH`,
/// or "UNKNOWN" for a value that is no status. The string is static: never free it. Never NULL.
#[unsafe(no_mangle)]
pub extern "C" fn softshell_status_name(status: u32) -> *const c_char {
    value_call("softshell_status_name", c"UNKNOWN".as_ptr(), || {
        SoftshellStatus::ALL.get(status as usize).map_or(c"UNKNOWN", |status| status.name()).as_ptr()
    })
}

/// A NUL-terminated, human-readable message about the last call that failed on the calling
/// thread: which argument, index or value was wrong and what to do instead. "" if no call has
/// failed on this thread. Successful calls leave it unchanged. Owned by the library: do not free
/// it; it stays valid until the next call on the same thread that fails (so
/// `softshell_status_name`, the version functions and successful calls may come in between, in
/// any order of evaluation). Never NULL.
#[unsafe(no_mangle)]
pub extern "C" fn softshell_last_error() -> *const c_char {
    value_call("softshell_last_error", c"".as_ptr(), last_error_ptr)
}
