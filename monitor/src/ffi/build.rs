//! Construction: a builder over a configuration (the embedded default, TOML text or a file),
//! the choices a host makes once (which monitors, persistence, the event queue's size), and
//! the runtime it builds.

use std::ffi::c_char;
use std::path::PathBuf;

use super::error::{fail, Failure};
use super::{fdd_runtime, fdd_status, guarded, null, out, runtime_failure, text};
use super::{FDD_ERR_ARGUMENT, FDD_ERR_CONFIG};
use crate::runtime::{Runtime, RuntimeConfig};

/// Event records the runtime's queue holds until drained, unless the builder says otherwise.
pub const FDD_DEFAULT_EVENT_CAPACITY: usize = 256;

/// What a runtime is built from. Opaque to C.
#[allow(non_camel_case_types)]
pub struct fdd_builder {
    cfg: RuntimeConfig,
    only: Option<Vec<String>>,
    persistence: Option<PathBuf>,
    capacity: usize,
}

fn builder_of(cfg: RuntimeConfig, out_b: &mut *mut fdd_builder) {
    *out_b = Box::into_raw(Box::new(fdd_builder {
        cfg,
        only: None,
        persistence: None,
        capacity: FDD_DEFAULT_EVENT_CAPACITY,
    }));
}

/// The configuration of `toml` (`len` bytes of UTF-8, not necessarily NUL-terminated), or the
/// embedded default configuration (`config/fdd.toml`) when `toml` is NULL.
fn config_of(toml: *const c_char, len: usize) -> Result<RuntimeConfig, Failure> {
    let cfg = if toml.is_null() {
        RuntimeConfig::embedded()
    } else {
        // SAFETY: `toml` points to `len` readable bytes by the function's contract.
        let bytes = unsafe { std::slice::from_raw_parts(toml.cast::<u8>(), len) };
        let s = std::str::from_utf8(bytes).map_err(|e| {
            fail(
                FDD_ERR_CONFIG,
                format_args!("configuration text: not UTF-8 at byte {}", e.valid_up_to()),
            )
        })?;
        RuntimeConfig::parse(s, "configuration text")
    };
    cfg.map_err(|e| fail(FDD_ERR_CONFIG, format_args!("{e}")))
}

/// A builder over the configuration text `toml` (`len` bytes), or over the embedded default
/// configuration when `toml` is NULL. Free it with `fdd_builder_free`.
///
/// # Safety
/// `toml` is NULL or points to `len` readable bytes; `out_builder` points to a writable
/// pointer.
#[no_mangle]
pub unsafe extern "C" fn fdd_builder_new(
    toml: *const c_char,
    len: usize,
    out_builder: *mut *mut fdd_builder,
) -> fdd_status {
    guarded(|| {
        let o = out(out_builder, "out_builder")?;
        let cfg = config_of(toml, len)?;
        builder_of(cfg, o);
        Ok(())
    })
}

/// A builder over the configuration file at `path` (errors name the file, table and key).
///
/// # Safety
/// `path` is a NUL-terminated string; `out_builder` points to a writable pointer.
#[no_mangle]
pub unsafe extern "C" fn fdd_builder_from_file(
    path: *const c_char,
    out_builder: *mut *mut fdd_builder,
) -> fdd_status {
    guarded(|| {
        let o = out(out_builder, "out_builder")?;
        let p = text(path, "path")?;
        let cfg = RuntimeConfig::load(Some(std::path::Path::new(p)))
            .map_err(|e| fail(FDD_ERR_CONFIG, format_args!("{e}")))?;
        builder_of(cfg, o);
        Ok(())
    })
}

fn builder_mut<'a>(b: *mut fdd_builder) -> Result<&'a mut fdd_builder, Failure> {
    // SAFETY: NULL or a builder from `fdd_builder_new` not yet freed.
    unsafe { b.as_mut() }.ok_or_else(|| null("builder"))
}

/// Builds only the subsystem monitors named in `monitors`, a comma-separated list
/// (`"throttle"`, `"throttle,intake"`); the "no signal" monitor then watches only their
/// signals. By default every monitor enabled in the configuration's `[monitors]` is built.
///
/// # Safety
/// `builder` is a live builder; `monitors` is a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn fdd_builder_only_monitors(
    builder: *mut fdd_builder,
    monitors: *const c_char,
) -> fdd_status {
    guarded(|| {
        let b = builder_mut(builder)?;
        let list = text(monitors, "monitors")?;
        let names: Vec<String> = list
            .split(',')
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .collect();
        let known = b.cfg.monitors.enabled();
        if let Some(bad) = names.iter().find(|n| !known.contains(&n.as_str())) {
            return Err(fail(
                FDD_ERR_ARGUMENT,
                format_args!(
                    "monitor `{bad}` is not an enabled monitor of {} (enabled: {})",
                    b.cfg.origin,
                    known.join(", ")
                ),
            ));
        }
        b.only = Some(names);
        Ok(())
    })
}

/// Keeps the event memory across power cycles in the slot files `<base>.a` and `<base>.b`
/// (restored when the runtime is built, written at every operation-cycle end, confirmation
/// and clear).
///
/// # Safety
/// `builder` is a live builder; `base` is a NUL-terminated path.
#[no_mangle]
pub unsafe extern "C" fn fdd_builder_persistence(
    builder: *mut fdd_builder,
    base: *const c_char,
) -> fdd_status {
    guarded(|| {
        let b = builder_mut(builder)?;
        let p = text(base, "base")?;
        if p.is_empty() {
            return Err(fail(FDD_ERR_ARGUMENT, format_args!("`base` is empty")));
        }
        b.persistence = Some(PathBuf::from(p));
        Ok(())
    })
}

/// Event records the runtime's queue holds until `fdd_events_drain` (default
/// `FDD_DEFAULT_EVENT_CAPACITY`; 1 to 1,000,000). Records that do not fit are counted
/// (`fdd_events_dropped`); the DTCs themselves stay in the event memory.
///
/// # Safety
/// `builder` is a live builder.
#[no_mangle]
pub unsafe extern "C" fn fdd_builder_event_capacity(
    builder: *mut fdd_builder,
    capacity: usize,
) -> fdd_status {
    guarded(|| {
        let b = builder_mut(builder)?;
        if !(1..=1_000_000).contains(&capacity) {
            return Err(fail(
                FDD_ERR_ARGUMENT,
                format_args!("event capacity {capacity} is outside 1..=1000000"),
            ));
        }
        b.capacity = capacity;
        Ok(())
    })
}

/// Frees a builder (NULL is accepted and ignored).
///
/// # Safety
/// `builder` is NULL or a builder not yet freed.
#[no_mangle]
pub unsafe extern "C" fn fdd_builder_free(builder: *mut fdd_builder) {
    if !builder.is_null() {
        // SAFETY: from `Box::into_raw` in `builder_of`, freed once.
        let _ = guarded(|| {
            drop(unsafe { Box::from_raw(builder) });
            Ok(())
        });
    }
}

/// Builds a runtime from `builder` (which stays usable, and is freed by the caller). Free
/// the runtime with `fdd_runtime_free`.
///
/// # Safety
/// `builder` is a live builder; `out_rt` points to a writable pointer.
#[no_mangle]
pub unsafe extern "C" fn fdd_runtime_build(
    builder: *const fdd_builder,
    out_rt: *mut *mut fdd_runtime,
) -> fdd_status {
    guarded(|| {
        let o = out(out_rt, "out_rt")?;
        // SAFETY: NULL or a live builder.
        let b = unsafe { builder.as_ref() }.ok_or_else(|| null("builder"))?;
        let mut rb = Runtime::builder(b.cfg.clone()).detail_outputs(false);
        if let Some(only) = &b.only {
            let names: Vec<&str> = only.iter().map(String::as_str).collect();
            rb = rb.only_monitors(&names);
        }
        if let Some(p) = &b.persistence {
            rb = rb.persistence(p.clone());
        }
        let (rt, _) = rb.build().map_err(|e| runtime_failure(None, &e))?;
        *o = Box::into_raw(Box::new(fdd_runtime::new(rt, b.capacity)));
        Ok(())
    })
}

/// A runtime of every enabled monitor from the configuration text `toml` (`len` bytes), or
/// from the embedded default configuration when `toml` is NULL.
///
/// # Safety
/// `toml` is NULL or points to `len` readable bytes; `out_rt` points to a writable pointer.
#[no_mangle]
pub unsafe extern "C" fn fdd_runtime_new(
    toml: *const c_char,
    len: usize,
    out_rt: *mut *mut fdd_runtime,
) -> fdd_status {
    let mut b: *mut fdd_builder = std::ptr::null_mut();
    if out_rt.is_null() {
        return null("out_rt").0;
    }
    // SAFETY: forwarded contracts.
    let s = unsafe { fdd_builder_new(toml, len, &mut b) };
    build_and_free(s, b, out_rt)
}

/// Builds the runtime of a builder just made (status `s`) and frees the builder.
fn build_and_free(s: fdd_status, b: *mut fdd_builder, out_rt: *mut *mut fdd_runtime) -> fdd_status {
    if s != super::FDD_OK {
        return s;
    }
    // SAFETY: `b` is a live builder, `out_rt` checked non-NULL by the caller.
    let s = unsafe { fdd_runtime_build(b, out_rt) };
    unsafe { fdd_builder_free(b) };
    s
}

/// A runtime of every enabled monitor from the configuration file at `path`.
///
/// # Safety
/// `path` is a NUL-terminated string; `out_rt` points to a writable pointer.
#[no_mangle]
pub unsafe extern "C" fn fdd_runtime_from_file(
    path: *const c_char,
    out_rt: *mut *mut fdd_runtime,
) -> fdd_status {
    let mut b: *mut fdd_builder = std::ptr::null_mut();
    if out_rt.is_null() {
        return null("out_rt").0;
    }
    // SAFETY: forwarded contracts.
    let s = unsafe { fdd_builder_from_file(path, &mut b) };
    build_and_free(s, b, out_rt)
}

/// Frees a runtime, poisoned or not (NULL is accepted and ignored). With persistence, the
/// event memory was written at the last cycle end, confirmation or clear; call
/// `fdd_end_operation_cycle` first to keep the running cycle's results.
///
/// # Safety
/// `rt` is NULL or a runtime not yet freed.
#[no_mangle]
pub unsafe extern "C" fn fdd_runtime_free(rt: *mut fdd_runtime) {
    if !rt.is_null() {
        // SAFETY: from `Box::into_raw` in `fdd_runtime_build`, freed once.
        let _ = guarded(|| {
            drop(unsafe { Box::from_raw(rt) });
            Ok(())
        });
    }
}
