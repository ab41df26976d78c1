//! The panic boundary every exported function runs inside (after rustls-ffi's
//! `ffi_panic_boundary`). Since Rust 1.81 a panic that reaches an `extern "C"` frame aborts the
//! host, so each body runs under `catch_unwind`; a caught panic becomes `GR_STATUS_INTERNAL` with
//! the panic message as the last error. Rayon re-raises a worker's panic on the thread that
//! called `install`, so panics in the solver's workers are caught here too.

use std::any::Any;
use std::panic::{AssertUnwindSafe, catch_unwind};

use super::error::{Failure, GrStatus, set_last_error};

/// The text of a panic payload (`panic!` gives a `&str` or a `String`).
fn panic_message(payload: &(dyn Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_owned()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic with a non-text payload".to_owned()
    }
}

/// Drops a panic payload without letting a panicking `Drop` escape.
fn drop_payload(payload: Box<dyn Any + Send>) {
    if let Err(again) = catch_unwind(AssertUnwindSafe(move || drop(payload))) {
        std::mem::forget(again);
    }
}

/// Runs the body of the exported function `name`: clears the last error, then returns
/// `GrStatus::Ok`, or the failure's status with its message stored as the last error.
pub(crate) fn boundary(name: &str, body: impl FnOnce() -> Result<(), Failure>) -> GrStatus {
    set_last_error(None);
    let failure = match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => return GrStatus::Ok,
        Ok(Err(failure)) => failure,
        Err(payload) => {
            let message = panic_message(&*payload);
            drop_payload(payload);
            Failure::new(
                GrStatus::Internal,
                crate::Error::Internal(format!("panic in {name}: {message}")).to_string(),
            )
        }
    };
    let status = failure.status;
    set_last_error(Some(failure.message));
    status
}

/// For functions that return a value rather than a status: `fallback` when the body panics.
pub(crate) fn boundary_value<T>(fallback: T, body: impl FnOnce() -> T) -> T {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(v) => v,
        Err(payload) => {
            drop_payload(payload);
            fallback
        }
    }
}

/// Runs `body` inside the same boundary as every exported function and returns its status
/// (`GrStatus::Internal` and a last error naming `name` when it panics). Public only so that the
/// integration tests can check the boundary itself; not part of the C ABI.
#[doc(hidden)]
pub fn run_in_boundary(name: &str, body: impl FnOnce()) -> GrStatus {
    boundary(name, || {
        body();
        Ok(())
    })
}
