//! The C boundary itself: status codes, the thread-local error message, the wrappers that catch
//! every panic, and the typed helpers that turn raw pointers into references for one call.
//!
//! Every exported function goes through [`status_call`], [`handle_call`], [`handle_read`] or
//! [`value_call`], so a panic never unwinds into C (it would abort the host or be undefined
//! behaviour) and every failure leaves a message behind.

use std::cell::RefCell;
use std::ffi::{CStr, CString, c_char};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;

use crate::error::{Error, ErrorKind, Result};

/// Result of every fallible call. Values are explicit and append-only: they are never renumbered.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SoftshellStatus {
    /// Success. Outputs were written.
    Ok = 0,
    /// A pointer argument that must not be NULL was NULL. Nothing was changed.
    NullArgument = 1,
    /// An argument was out of range, not finite, of an unknown kind, or a def was not made by its
    /// `..._def_default()` function. Nothing was changed.
    InvalidArgument = 2,
    /// A mesh does not satisfy what the call needs (out-of-range index, NaN coordinate, open,
    /// non-manifold, degenerate triangle...). The message names the first offending item.
    InvalidMesh = 3,
    /// A file could not be read, parsed or written. The message names the file (and line).
    Io = 4,
    /// An output buffer was NULL or too small; `*out_len` holds the number of elements needed.
    BufferTooSmall = 5,
    /// A step diverged; the state was rolled back to before the step. The message says which
    /// quantity blew up and which setting would be stable.
    Unstable = 6,
    /// The feature was compiled out of this build (cargo features).
    Unsupported = 7,
    /// The handle was poisoned by an earlier internal failure; only `..._free` is allowed.
    Poisoned = 8,
    /// A bug inside softshell (a caught panic). The message says where; please report it.
    Internal = 9,
}

impl SoftshellStatus {
    /// The static, NUL-terminated name of the status ("OK", "INVALID_MESH", ...).
    pub(crate) fn name(self) -> &'static CStr {
        match self {
            SoftshellStatus::Ok => c"OK",
            SoftshellStatus::NullArgument => c"NULL_ARGUMENT",
            SoftshellStatus::InvalidArgument => c"INVALID_ARGUMENT",
            SoftshellStatus::InvalidMesh => c"INVALID_MESH",
            SoftshellStatus::Io => c"IO",
            SoftshellStatus::BufferTooSmall => c"BUFFER_TOO_SMALL",
            SoftshellStatus::Unstable => c"UNSTABLE",
            SoftshellStatus::Unsupported => c"UNSUPPORTED",
            SoftshellStatus::Poisoned => c"POISONED",
            SoftshellStatus::Internal => c"INTERNAL",
        }
    }

    /// Every status, in value order (for tests and for `softshell_status_name`).
    pub(crate) const ALL: [SoftshellStatus; 10] = [
        SoftshellStatus::Ok,
        SoftshellStatus::NullArgument,
        SoftshellStatus::InvalidArgument,
        SoftshellStatus::InvalidMesh,
        SoftshellStatus::Io,
        SoftshellStatus::BufferTooSmall,
        SoftshellStatus::Unstable,
        SoftshellStatus::Unsupported,
        SoftshellStatus::Poisoned,
        SoftshellStatus::Internal,
    ];
}

impl From<ErrorKind> for SoftshellStatus {
    fn from(kind: ErrorKind) -> Self {
        match kind {
            ErrorKind::NullArgument => SoftshellStatus::NullArgument,
            ErrorKind::InvalidArgument => SoftshellStatus::InvalidArgument,
            ErrorKind::InvalidMesh => SoftshellStatus::InvalidMesh,
            ErrorKind::Io => SoftshellStatus::Io,
            ErrorKind::BufferTooSmall => SoftshellStatus::BufferTooSmall,
            ErrorKind::Unstable => SoftshellStatus::Unstable,
            ErrorKind::Unsupported => SoftshellStatus::Unsupported,
            ErrorKind::Poisoned => SoftshellStatus::Poisoned,
            ErrorKind::Internal => SoftshellStatus::Internal,
        }
    }
}

thread_local! {
    /// The message of the last failing call on this thread ("" before any failure).
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

/// Stores `message` as this thread's last error (NUL bytes inside it become spaces).
pub(crate) fn set_last_error(message: &str) {
    let clean = CString::new(message.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|slot| *slot.borrow_mut() = clean);
}

/// Pointer to this thread's last error message; valid until the next failing call on the thread.
pub(crate) fn last_error_ptr() -> *const c_char {
    LAST_ERROR.with(|slot| slot.borrow().as_ptr())
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(text) = payload.downcast_ref::<&str>() {
        (*text).to_owned()
    } else if let Some(text) = payload.downcast_ref::<String>() {
        text.clone()
    } else {
        "a panic without a message".to_owned()
    }
}

fn fail(error: Error) -> SoftshellStatus {
    set_last_error(&error.message);
    error.kind.into()
}

fn fail_with_panic(function: &str, payload: &(dyn std::any::Any + Send)) -> SoftshellStatus {
    set_last_error(&format!(
        "internal error in {function}: {} (this is a bug in softshell; please report it)",
        panic_message(payload)
    ));
    SoftshellStatus::Internal
}

/// Runs the body of an exported function that returns a status; catches panics.
pub(crate) fn status_call(function: &str, body: impl FnOnce() -> Result<()>) -> SoftshellStatus {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => SoftshellStatus::Ok,
        Ok(Err(error)) => fail(error),
        Err(payload) => fail_with_panic(function, payload.as_ref()),
    }
}

/// Runs the body of an exported function that returns a plain value (counts, sizes, names);
/// a panic returns `fallback` and leaves a message.
pub(crate) fn value_call<T>(function: &str, fallback: T, body: impl FnOnce() -> T) -> T {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(value) => value,
        Err(payload) => {
            fail_with_panic(function, payload.as_ref());
            fallback
        }
    }
}

/// A handle that can be poisoned: after a panic inside a call that mutates it, its state may be
/// half-updated, so every later call except free is refused with `POISONED`.
pub(crate) trait Poisonable {
    fn is_poisoned(&self) -> bool;
    fn poison(&mut self);
}

fn poisoned_error(name: &str) -> Error {
    Error::new(
        ErrorKind::Poisoned,
        format!("`{name}` was poisoned by an earlier internal error; free it and create a new one"),
    )
}

/// Runs a call that mutates a handle: NULL check, poison check, panic catch; a panic poisons it.
pub(crate) fn handle_call<H: Poisonable>(
    function: &str,
    handle: *mut H,
    name: &str,
    body: impl FnOnce(&mut H) -> Result<()>,
) -> SoftshellStatus {
    // SAFETY: the caller promises `handle` is NULL or a live handle it does not use elsewhere
    // during this call (the documented thread rule).
    let handle = match unsafe { arg_mut(handle, name) } {
        Ok(handle) => handle,
        Err(error) => return fail(error),
    };
    if handle.is_poisoned() {
        return fail(poisoned_error(name));
    }
    match catch_unwind(AssertUnwindSafe(|| body(&mut *handle))) {
        Ok(Ok(())) => SoftshellStatus::Ok,
        Ok(Err(error)) => fail(error),
        Err(payload) => {
            handle.poison();
            fail_with_panic(function, payload.as_ref())
        }
    }
}

/// Runs a call that only reads a handle: NULL check, poison check, panic catch.
pub(crate) fn handle_read<H: Poisonable>(
    function: &str,
    handle: *const H,
    name: &str,
    body: impl FnOnce(&H) -> Result<()>,
) -> SoftshellStatus {
    status_call(function, || {
        // SAFETY: the caller promises `handle` is NULL or a live handle.
        let handle = unsafe { arg_ref(handle, name)? };
        if handle.is_poisoned() {
            return Err(poisoned_error(name));
        }
        body(handle)
    })
}

fn null_error(name: &str) -> Error {
    Error::new(ErrorKind::NullArgument, format!("argument `{name}` is NULL"))
}

fn check_alignment<T>(ptr: *const T, name: &str) -> Result<()> {
    if !ptr.is_aligned() {
        return Err(Error::invalid_argument(format!(
            "argument `{name}` is not aligned to {} bytes",
            std::mem::align_of::<T>()
        )));
    }
    Ok(())
}

/// Borrows `*ptr` for the length of one call.
///
/// # Safety
/// `ptr` must be NULL or point to a live, initialised `T` not mutated during the call.
pub(crate) unsafe fn arg_ref<'a, T>(ptr: *const T, name: &str) -> Result<&'a T> {
    if ptr.is_null() {
        return Err(null_error(name));
    }
    check_alignment(ptr, name)?;
    // SAFETY: non-NULL and aligned; liveness is the caller's promise.
    Ok(unsafe { &*ptr })
}

/// Borrows `*ptr` mutably for the length of one call.
///
/// # Safety
/// `ptr` must be NULL or point to a live `T` used by nobody else during the call.
pub(crate) unsafe fn arg_mut<'a, T>(ptr: *mut T, name: &str) -> Result<&'a mut T> {
    if ptr.is_null() {
        return Err(null_error(name));
    }
    check_alignment(ptr, name)?;
    // SAFETY: non-NULL and aligned; exclusivity is the caller's promise.
    Ok(unsafe { &mut *ptr })
}

/// Borrows `len` elements at `ptr`. `(NULL, 0)` is the empty slice: `slice::from_raw_parts` is
/// undefined for NULL even at length 0, so it is never called with it.
///
/// # Safety
/// `ptr` must be NULL or point to `len` live, initialised elements.
pub(crate) unsafe fn arg_slice<'a, T>(ptr: *const T, len: usize, name: &str) -> Result<&'a [T]> {
    if len == 0 {
        return Ok(&[]);
    }
    if ptr.is_null() {
        return Err(Error::new(
            ErrorKind::NullArgument,
            format!("argument `{name}` is NULL but its length says {len} elements"),
        ));
    }
    check_alignment(ptr, name)?;
    if len.checked_mul(std::mem::size_of::<T>()).is_none_or(|bytes| bytes > isize::MAX as usize) {
        return Err(Error::invalid_argument(format!("argument `{name}`: length {len} is too large")));
    }
    // SAFETY: non-NULL, aligned, size checked; the elements' liveness is the caller's promise.
    Ok(unsafe { std::slice::from_raw_parts(ptr, len) })
}

/// Checks an out-pointer before any work, so a NULL is refused before anything changes.
pub(crate) fn out_arg<T>(ptr: *mut T, name: &str) -> Result<*mut T> {
    if ptr.is_null() {
        return Err(null_error(name));
    }
    check_alignment(ptr, name)?;
    Ok(ptr)
}

/// Writes `value` to an out-pointer checked by [`out_arg`].
///
/// # Safety
/// `ptr` must come from [`out_arg`] and point to writable memory for one `T`.
pub(crate) unsafe fn write_out<T>(ptr: *mut T, value: T) {
    // SAFETY: checked non-NULL and aligned by out_arg; writability is the caller's promise.
    unsafe { ptr.write(value) };
}

/// Reads a `float[3]` argument and checks that it is finite.
///
/// # Safety
/// `ptr` must be NULL or point to three floats.
pub(crate) unsafe fn arg_vec3(ptr: *const f32, name: &str) -> Result<[f32; 3]> {
    // SAFETY: forwarded from the caller.
    let values = unsafe { arg_slice(ptr, 3, name)? };
    let vector = [values[0], values[1], values[2]];
    if let Some(axis) = vector.iter().position(|v| !v.is_finite()) {
        return Err(Error::invalid_argument(format!("argument `{name}`[{axis}] = {} is not finite", vector[axis])));
    }
    Ok(vector)
}

/// Reads a NUL-terminated path argument.
///
/// # Safety
/// `ptr` must be NULL or point to a NUL-terminated string.
pub(crate) unsafe fn arg_path(ptr: *const c_char, name: &str) -> Result<PathBuf> {
    if ptr.is_null() {
        return Err(null_error(name));
    }
    // SAFETY: non-NULL; NUL termination is the caller's promise.
    let bytes = unsafe { CStr::from_ptr(ptr) }.to_bytes();
    if bytes.is_empty() {
        return Err(Error::invalid_argument(format!("argument `{name}` is an empty path")));
    }
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        Ok(PathBuf::from(std::ffi::OsStr::from_bytes(bytes)))
    }
    #[cfg(not(unix))]
    {
        match std::str::from_utf8(bytes) {
            Ok(text) => Ok(PathBuf::from(text)),
            Err(_) => Err(Error::invalid_argument(format!("argument `{name}` is not UTF-8"))),
        }
    }
}

/// Converts a `uint32_t` kind selector into its Rust enum; an unknown value is an error.
pub(crate) fn arg_kind<T: TryFrom<u32>>(value: u32, name: &str, allowed: &str) -> Result<T> {
    T::try_from(value)
        .map_err(|_| Error::invalid_argument(format!("`{name}` = {value} is not a known value; use one of {allowed}")))
}

/// Copies `len` elements out through `(out, capacity, out_len)`: `fill` writes them into the
/// caller's buffer only once it is known to be large enough. `*out_len` is set to `len` both on
/// success and when the buffer is NULL or too small (then nothing else is written).
///
/// # Safety
/// `out` must be NULL or point to `capacity` writable elements; `out_len` NULL or writable.
pub(crate) unsafe fn copy_out<T>(
    len: usize,
    out: *mut T,
    capacity: usize,
    out_len: *mut usize,
    fill: impl FnOnce(&mut [T]),
) -> Result<()> {
    let out_len = out_arg(out_len, "out_len")?;
    if out.is_null() || capacity < len {
        // SAFETY: checked by out_arg.
        unsafe { write_out(out_len, len) };
        let given = if out.is_null() { "out is NULL".to_owned() } else { format!("capacity is {capacity}") };
        return Err(Error::new(
            ErrorKind::BufferTooSmall,
            format!("output buffer too small: {len} elements needed, {given}; *out_len holds the size needed"),
        ));
    }
    check_alignment(out as *const T, "out")?;
    if len > 0 {
        // SAFETY: `out` is non-NULL, aligned and holds at least `capacity >= len` elements.
        let buffer = unsafe { std::slice::from_raw_parts_mut(out, len) };
        fill(buffer);
    }
    // SAFETY: checked by out_arg.
    unsafe { write_out(out_len, len) };
    Ok(())
}

/// Writes `triples` one after another into `dst` (x,y,z or a,b,c per item): the layout of every
/// flat `float *` / `uint32_t *` buffer of the ABI.
pub(crate) fn write_triples<T: Copy>(dst: &mut [T], triples: impl IntoIterator<Item = [T; 3]>) {
    for (chunk, triple) in dst.chunks_exact_mut(3).zip(triples) {
        chunk.copy_from_slice(&triple);
    }
}

/// Checks a def's private cookie, so a def that was not made by its default function (stack
/// garbage, a zeroed struct, a def of another kind) is refused instead of being trusted.
pub(crate) fn check_cookie(cookie: u32, expected: u32, def_name: &str, default_fn: &str) -> Result<()> {
    if cookie != expected {
        return Err(Error::invalid_argument(format!(
            "`{def_name}` was not initialised by {default_fn}(): start from the default def and edit its fields"
        )));
    }
    Ok(())
}

/// Checks that a float setting is finite and within `[min, max]`.
pub(crate) fn check_range(name: &str, value: f32, min: f32, max: f32) -> Result<()> {
    if !value.is_finite() || value < min || value > max {
        return Err(Error::invalid_argument(format!("`{name}` = {value} must be finite and in [{min}, {max}]")));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Toy {
        poisoned: bool,
        value: u32,
    }

    impl Poisonable for Toy {
        fn is_poisoned(&self) -> bool {
            self.poisoned
        }
        fn poison(&mut self) {
            self.poisoned = true;
        }
    }

    fn last_error() -> String {
        // SAFETY: the pointer is valid until the next failing call on this thread.
        unsafe { CStr::from_ptr(last_error_ptr()) }.to_string_lossy().into_owned()
    }

    #[test]
    fn panic_becomes_internal_with_a_message() {
        let status = status_call("softshell_test", || panic!("boom {}", 42));
        assert_eq!(status, SoftshellStatus::Internal);
        assert!(last_error().contains("boom 42"), "{}", last_error());
        assert!(last_error().contains("softshell_test"));
        assert_eq!(value_call("softshell_count", 7usize, || panic!("x")), 7);
    }

    #[test]
    fn panic_in_a_mutating_call_poisons_the_handle() {
        let mut toy = Toy { poisoned: false, value: 1 };
        let status = handle_call("softshell_toy_step", &mut toy, "toy", |toy| {
            toy.value = 2;
            panic!("half-way")
        });
        assert_eq!(status, SoftshellStatus::Internal);
        assert!(toy.poisoned);
        let status = handle_call("softshell_toy_step", &mut toy, "toy", |_| Ok(()));
        assert_eq!(status, SoftshellStatus::Poisoned);
        assert!(last_error().contains("poisoned"));
        let status = handle_read("softshell_toy_read", &toy as *const Toy, "toy", |_| Ok(()));
        assert_eq!(status, SoftshellStatus::Poisoned);
    }

    #[test]
    fn errors_set_status_and_message_and_messages_persist() {
        let status = status_call("f", || Err(Error::invalid_mesh("triangle 3 has index 9")));
        assert_eq!(status, SoftshellStatus::InvalidMesh);
        assert_eq!(last_error(), "triangle 3 has index 9");
        assert_eq!(status_call("g", || Ok(())), SoftshellStatus::Ok);
        assert_eq!(last_error(), "triangle 3 has index 9", "a success must not erase the last failure");
    }

    #[test]
    fn slices_and_buffers() {
        // SAFETY: NULL with length 0 is the documented empty slice.
        let empty: &[f32] = unsafe { arg_slice(std::ptr::null(), 0, "p") }.unwrap();
        assert!(empty.is_empty());
        // SAFETY: NULL with a length must be refused before any dereference.
        let error = unsafe { arg_slice::<f32>(std::ptr::null(), 3, "p") }.unwrap_err();
        assert_eq!(error.kind, ErrorKind::NullArgument);

        let mut buffer = [0.0f32; 2];
        let mut len = 0usize;
        // SAFETY: buffer and len are live locals.
        let error = unsafe { copy_out(3, buffer.as_mut_ptr(), 2, &mut len, |_| unreachable!()) }.unwrap_err();
        assert_eq!(error.kind, ErrorKind::BufferTooSmall);
        assert_eq!(len, 3);
        assert_eq!(buffer, [0.0, 0.0]);
        let mut big = [0.0f32; 4];
        // SAFETY: as above.
        unsafe { copy_out(3, big.as_mut_ptr(), 4, &mut len, |dst| dst.copy_from_slice(&[1.0, 2.0, 3.0])) }.unwrap();
        assert_eq!(big, [1.0, 2.0, 3.0, 0.0]);
        assert_eq!(len, 3);
    }

    #[test]
    fn status_names_are_unique_and_values_fixed() {
        for (value, status) in SoftshellStatus::ALL.iter().enumerate() {
            assert_eq!(*status as u32, value as u32);
        }
        assert_eq!(SoftshellStatus::Internal as u32, 9);
    }
}
