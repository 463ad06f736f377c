//! Status codes and the thread's last error message.
//!
//! Every fallible call returns an [`fdd_status`]; on failure it also leaves a message naming
//! what went wrong (the key, the signal and time, the DTC) for [`crate::ffi::fdd_last_error`].
//! The message lives in a per-thread buffer that is reused: after the first failure on a
//! thread, recording one allocates only when a message is longer than any before it.

use std::cell::RefCell;
use std::ffi::CStr;
use std::fmt::{self, Write as _};

/// What a call did: `FDD_OK` or the reason it changed nothing.
#[allow(non_camel_case_types)]
pub type fdd_status = i32;

/// The call succeeded; its out-parameters are written.
pub const FDD_OK: fdd_status = 0;
/// A pointer argument that must not be NULL was NULL.
pub const FDD_ERR_NULL: fdd_status = 1;
/// The configuration (text or file) was invalid or unreadable, or a monitor could not be
/// built from it; the message names the file, the table and the key.
pub const FDD_ERR_CONFIG: fdd_status = 2;
/// An argument was invalid: a string that is not UTF-8, a DTC above `0xFFFFFF`, a capacity of
/// zero.
pub const FDD_ERR_ARGUMENT: fdd_status = 3;
/// A signal id that is not one of this runtime's signals.
pub const FDD_ERR_UNKNOWN_SIGNAL: fdd_status = 4;
/// A sample was refused: its value is not finite, or its time does not increase.
pub const FDD_ERR_SAMPLE: fdd_status = 5;
/// A time before the runtime's time (the host's clock went backwards).
pub const FDD_ERR_TIME: fdd_status = 6;
/// The call needs a running operation cycle (`fdd_start_operation_cycle`).
pub const FDD_ERR_NO_CYCLE: fdd_status = 7;
/// No such signal name, monitor, DTC, estimate or memory entry.
pub const FDD_ERR_NOT_FOUND: fdd_status = 8;
/// The caller's buffer is too small; nothing was written to it.
pub const FDD_ERR_BUFFER_TOO_SMALL: fdd_status = 9;
/// The persisted event memory could not be opened or written.
pub const FDD_ERR_PERSIST: fdd_status = 10;
/// The event memory refused the call.
pub const FDD_ERR_MEMORY: fdd_status = 11;
/// fdd panicked inside this call (a defect of fdd): the call was abandoned and the handle is
/// poisoned.
pub const FDD_ERR_PANIC: fdd_status = 12;
/// The handle was poisoned by an earlier panic (`FDD_ERR_PANIC`): its state may be
/// inconsistent, so every call but `fdd_runtime_free` refuses it.
pub const FDD_ERR_POISONED: fdd_status = 13;

/// The name of a status code, e.g. `c"FDD_ERR_CONFIG"`.
pub(crate) fn status_cstr(s: fdd_status) -> &'static CStr {
    match s {
        FDD_OK => c"FDD_OK",
        FDD_ERR_NULL => c"FDD_ERR_NULL",
        FDD_ERR_CONFIG => c"FDD_ERR_CONFIG",
        FDD_ERR_ARGUMENT => c"FDD_ERR_ARGUMENT",
        FDD_ERR_UNKNOWN_SIGNAL => c"FDD_ERR_UNKNOWN_SIGNAL",
        FDD_ERR_SAMPLE => c"FDD_ERR_SAMPLE",
        FDD_ERR_TIME => c"FDD_ERR_TIME",
        FDD_ERR_NO_CYCLE => c"FDD_ERR_NO_CYCLE",
        FDD_ERR_NOT_FOUND => c"FDD_ERR_NOT_FOUND",
        FDD_ERR_BUFFER_TOO_SMALL => c"FDD_ERR_BUFFER_TOO_SMALL",
        FDD_ERR_PERSIST => c"FDD_ERR_PERSIST",
        FDD_ERR_MEMORY => c"FDD_ERR_MEMORY",
        FDD_ERR_PANIC => c"FDD_ERR_PANIC",
        FDD_ERR_POISONED => c"FDD_ERR_POISONED",
        _ => c"FDD_ERR_UNKNOWN_STATUS",
    }
}

thread_local! {
    static LAST: RefCell<String> = const { RefCell::new(String::new()) };
}

/// A failed call: its status, with the message already recorded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Failure(pub fdd_status);

/// Records `msg` as this thread's last error and returns the failure `status`.
pub(crate) fn fail(status: fdd_status, msg: fmt::Arguments<'_>) -> Failure {
    record(msg);
    Failure(status)
}

/// Replaces this thread's last error message.
pub(crate) fn record(msg: fmt::Arguments<'_>) {
    // A failure while the message is borrowed (formatting re-entering fdd) keeps the old one.
    let _ = LAST.try_with(|cell| {
        if let Ok(mut s) = cell.try_borrow_mut() {
            s.clear();
            let _ = s.write_fmt(msg);
        }
    });
}

/// Calls `f` with this thread's last error message (empty before any failure).
pub(crate) fn with_last<R>(f: impl FnOnce(&str) -> R) -> R {
    LAST.with(|cell| match cell.try_borrow() {
        Ok(s) => f(&s),
        Err(_) => f(""),
    })
}
