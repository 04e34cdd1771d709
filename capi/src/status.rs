//! What a call returns: `StrataStatus` and the last error's message.

use std::cell::RefCell;
use std::ffi::{CString, c_char};

/// What a call did.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StrataStatus {
    /// Success.
    Ok = 0,
    /// A null pointer, a bad size, an unknown name or an invalid setting.
    InvalidArgument = 1,
    /// The render failed (the message says why: e.g. a black scene, a film
    /// too large for the machine).
    RenderFailed = 2,
    /// The progress callback asked to stop; the film holds the work done.
    Cancelled = 3,
    /// A panic inside the engine, caught at the boundary.
    Panic = 4,
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

pub(crate) fn fail(status: StrataStatus, message: impl Into<String>) -> StrataStatus {
    let text = message.into().replace('\0', " ");
    LAST_ERROR.with(|e| *e.borrow_mut() = CString::new(text).unwrap_or_default());
    status
}

/// The message of the last failed call on this thread ("" if none); valid
/// until the next failing call on this thread.
#[unsafe(no_mangle)]
pub extern "C" fn strata_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}
