//! Status codes and the thread-local last error message.

use std::cell::RefCell;
use std::ffi::c_char;

use super::panic::boundary_value;

/// What a call did. Every fallible function returns one; the codes are stable and never reused.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GrStatus {
    /// Success.
    Ok = 0,
    /// A required pointer argument was NULL (a pointer may be NULL only where its array length is
    /// 0, or where the function says so).
    NullPointer = 1,
    /// An argument is invalid: an array length that disagrees with the counts, an index out of
    /// range, a non-finite number, an unknown enum value, an output buffer that is too small, or
    /// a session that is busy (another call on it is running).
    InvalidArgument = 2,
    /// The scene failed validation (non-finite vertex or matrix, face with other than 3 or 4
    /// vertices, vertex index or material out of range, reflectance outside [0,1), bad
    /// settings); the message names the object, face or field. Also returned by a solve that
    /// diverges (faces that cross or overlap while visibility is off or coarse), by a frame placed
    /// with no area or out of range, and by a scene whose estimated memory is over
    /// `memory_budget_mb` (the message begins "over the memory budget").
    InvalidScene = 3,
    /// The solve stopped because the progress callback returned 0 or `gr_session_cancel` was
    /// called; the last completed frame stays readable.
    Cancelled = 4,
    /// No frame has been solved yet, so there is nothing to read.
    NotSolved = 5,
    /// A bug: a panic (or other internal failure) caught at the boundary; the message says what.
    Internal = 6,
    /// A big allocation failed (the link rows or the link store) although the scene's estimate
    /// was within the memory budget: the machine had less than it reported, or something else
    /// took it meanwhile. The message ("out of memory while building ...") says how much was
    /// asked for; the session keeps its last completed frame, as after `GR_STATUS_CANCELLED`.
    OutOfMemory = 7,
}

/// A failed call: its status and the message stored for `gr_last_error`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Failure {
    pub status: GrStatus,
    pub message: String,
}

impl Failure {
    pub fn new(status: GrStatus, message: impl Into<String>) -> Self {
        Self { status, message: message.into() }
    }

    pub fn null(what: &str) -> Self {
        Self::new(GrStatus::NullPointer, format!("{what} is NULL"))
    }

    pub fn invalid(message: impl Into<String>) -> Self {
        Self::new(GrStatus::InvalidArgument, message)
    }

    /// The same failure with `prefix` before its message.
    pub fn prefixed(mut self, prefix: &str) -> Self {
        self.message.insert_str(0, prefix);
        self
    }
}

impl From<crate::Error> for Failure {
    fn from(e: crate::Error) -> Self {
        use crate::Error;
        let status = match &e {
            Error::Input(_) | Error::InvalidArgument(_) => GrStatus::InvalidArgument,
            Error::InvalidScene(_) | Error::OverBudget(_) => GrStatus::InvalidScene,
            Error::Cancelled => GrStatus::Cancelled,
            Error::OutOfMemory(_) => GrStatus::OutOfMemory,
            Error::Internal(_) => GrStatus::Internal,
        };
        Self::new(status, e.to_string())
    }
}

thread_local! {
    static LAST_ERROR: RefCell<Option<String>> = const { RefCell::new(None) };
}

/// Replaces this thread's last error message (`None` clears it).
pub(crate) fn set_last_error(message: Option<String>) {
    // `try_with`: a call made while the thread is being torn down keeps quiet instead of panicking.
    let _ = LAST_ERROR.try_with(|m| *m.borrow_mut() = message);
}

/// Copies this thread's last error message into `buf`.
///
/// Every function that returns a `GrStatus` clears the message when it starts and sets it when it
/// fails, so after a successful call the message is empty. The message is UTF-8 text without a
/// trailing newline. At most `len - 1` bytes are copied (cut at a character boundary) followed by
/// a NUL; nothing is written when `buf` is NULL or `len` is 0.
///
/// Returns the length in bytes of the whole message, without the NUL (0 when there is none):
/// call with `buf = NULL` to size a buffer of that length + 1.
///
/// # Safety
/// `buf` is NULL or points to `len` writable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn gr_last_error(buf: *mut c_char, len: usize) -> usize {
    boundary_value(0, || {
        LAST_ERROR
            .try_with(|m| {
                let m = m.borrow();
                let Some(msg) = m.as_deref() else {
                    if !buf.is_null() && len > 0 {
                        // SAFETY: buf points to at least 1 writable byte.
                        unsafe { *buf = 0 };
                    }
                    return 0;
                };
                if !buf.is_null() && len > 0 {
                    let mut n = msg.len().min(len - 1);
                    while !msg.is_char_boundary(n) {
                        n -= 1;
                    }
                    // SAFETY: buf points to len >= n + 1 writable bytes, distinct from msg.
                    unsafe {
                        std::ptr::copy_nonoverlapping(msg.as_ptr(), buf.cast::<u8>(), n);
                        *buf.add(n) = 0;
                    }
                }
                msg.len()
            })
            .unwrap_or(0)
    })
}
