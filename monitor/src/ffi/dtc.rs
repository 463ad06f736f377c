//! The DTC services with UDS semantics: DTCs by status mask (0x19 0x02), status byte,
//! freeze frame (0x19 0x04), extended data (0x19 0x06), ClearDiagnosticInformation (0x14),
//! and writing the persisted memory.

use fdd_diagnostics::dtc::{Dtc, DtcGroup};

use super::error::{fail, Failure};
use super::types::{c_text, dtc_text};
use super::{
    fdd_dtc_record, fdd_extended_data, fdd_freeze_frame, fdd_freeze_value, fdd_runtime, fdd_status,
    null, out, runtime_failure, with_mut, with_ref, FDD_ERR_ARGUMENT, FDD_ERR_NOT_FOUND,
};

/// The DTC of a 3-byte UDS value that this runtime has, with its event's and monitor's
/// names.
pub(crate) fn named(h: &fdd_runtime, dtc: u32) -> Result<(&str, &str), Failure> {
    let d = dtc_of(dtc)?;
    h.rt.event_name(d).ok_or_else(|| not_configured(d))
}

fn dtc_of(dtc: u32) -> Result<Dtc, Failure> {
    Dtc::from_u32(dtc).map_err(|_| {
        fail(
            FDD_ERR_ARGUMENT,
            format_args!("DTC 0x{dtc:X} is above 0xFFFFFF (3 bytes)"),
        )
    })
}

fn not_configured(d: Dtc) -> Failure {
    fail(
        FDD_ERR_NOT_FOUND,
        format_args!("DTC {d} is not configured in this runtime"),
    )
}

/// UDS 0x19 0x02 (reportDTCByStatusMask): the DTCs whose status byte has any bit of `mask`
/// set. `*count` receives how many match; the first `min(cap, count)` are written to `buf`
/// (a host passing `cap` 0 learns the count).
///
/// # Safety
/// `rt` is a live runtime; `buf` points to `cap` writable records (or is NULL with `cap` 0);
/// `count` is writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_dtcs_by_status_mask(
    rt: *const fdd_runtime,
    mask: u8,
    buf: *mut fdd_dtc_record,
    cap: usize,
    count: *mut usize,
) -> fdd_status {
    with_ref(rt, |h| {
        let c = out(count, "count")?;
        if buf.is_null() && cap > 0 {
            return Err(null("buf"));
        }
        let mut n = 0;
        for (dtc, status) in h.rt.dtcs_by_status_mask(mask) {
            if n < cap {
                let r = fdd_dtc_record {
                    dtc: dtc.to_u32(),
                    dtc_text: dtc_text(dtc),
                    status: status.byte(),
                };
                // SAFETY: `n < cap` and `buf` holds `cap` records.
                unsafe { buf.add(n).write(r) };
            }
            n += 1;
        }
        *c = n;
        Ok(())
    })
}

/// ISO 14229-1 DTCStatusAvailabilityMask (fdd supports all eight bits: 0xFF).
///
/// # Safety
/// `rt` is a live runtime; `mask` is writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_status_availability_mask(
    rt: *const fdd_runtime,
    mask: *mut u8,
) -> fdd_status {
    with_ref(rt, |h| {
        *out(mask, "mask")? = h.rt.status_availability_mask();
        Ok(())
    })
}

/// The status byte of DTC `dtc` (3-byte UDS value).
///
/// # Safety
/// `rt` is a live runtime; `status` is writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_dtc_status(
    rt: *const fdd_runtime,
    dtc: u32,
    status: *mut u8,
) -> fdd_status {
    with_ref(rt, |h| {
        let o = out(status, "status")?;
        let d = dtc_of(dtc)?;
        *o = h.rt.status(d).ok_or_else(|| not_configured(d))?.byte();
        Ok(())
    })
}

/// Extended data of DTC `dtc` (UDS 0x19 0x06).
///
/// # Safety
/// `rt` is a live runtime; `data` is writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_dtc_extended_data(
    rt: *const fdd_runtime,
    dtc: u32,
    data: *mut fdd_extended_data,
) -> fdd_status {
    with_ref(rt, |h| {
        let o = out(data, "data")?;
        let d = dtc_of(dtc)?;
        *o =
            h.rt.extended_data(d)
                .ok_or_else(|| not_configured(d))?
                .into();
        Ok(())
    })
}

/// The memory entry of DTC `dtc` (UDS 0x19 0x04): `*frame` receives the entry and the number
/// of values its freeze frame holds (`value_count`); the first `min(cap, value_count)`
/// values are written to `values` (NULL with `cap` 0 to learn the count).
/// `FDD_ERR_NOT_FOUND` when the DTC has no entry.
///
/// # Safety
/// `rt` is a live runtime; `frame` is writable; `values` points to `cap` writable values.
#[no_mangle]
pub unsafe extern "C" fn fdd_dtc_freeze_frame(
    rt: *const fdd_runtime,
    dtc: u32,
    frame: *mut fdd_freeze_frame,
    values: *mut fdd_freeze_value,
    cap: usize,
) -> fdd_status {
    with_ref(rt, |h| {
        let f = out(frame, "frame")?;
        if values.is_null() && cap > 0 {
            return Err(null("values"));
        }
        let d = dtc_of(dtc)?;
        h.rt.status(d).ok_or_else(|| not_configured(d))?;
        let e = h.rt.freeze_frame(d).ok_or_else(|| {
            fail(
                FDD_ERR_NOT_FOUND,
                format_args!("DTC {d} has no memory entry (no freeze frame stored)"),
            )
        })?;
        let mut n = 0;
        for (name, value) in e.freeze_frame() {
            if n < cap {
                let v = fdd_freeze_value {
                    name: c_text(name.as_bytes()),
                    value,
                };
                // SAFETY: `n < cap` and `values` holds `cap` values.
                unsafe { values.add(n).write(v) };
            }
            n += 1;
        }
        *f = fdd_freeze_frame {
            dtc,
            status: e.status.byte(),
            priority: e.priority,
            occurrence_counter: e.occurrence_counter,
            aging_counter: e.aging_counter,
            max_fdc: e.max_fdc,
            stored_time_s: e.stored_time_s,
            value_count: n,
        };
        Ok(())
    })
}

/// UDS ClearDiagnosticInformation (0x14) at `t_ns`: `group` is `0xFFFFFF` for every DTC or
/// one DTC's 3-byte value. The DTCs go back to status 0x50, their entries and counters
/// erased, their monitors' latched tests restarted. `*cleared` (if not NULL) receives how
/// many DTCs were cleared.
///
/// # Safety
/// `rt` is a live runtime; `cleared` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_clear_dtc(
    rt: *mut fdd_runtime,
    group: u32,
    t_ns: u64,
    cleared: *mut usize,
) -> fdd_status {
    with_mut(rt, |h| {
        let g = DtcGroup::from_uds(group).map_err(|_| {
            fail(
                FDD_ERR_ARGUMENT,
                format_args!("group of DTC 0x{group:X} is above 0xFFFFFF (3 bytes)"),
            )
        })?;
        let n =
            h.rt.clear_dtc(g, t_ns, &mut h.events)
                .map_err(|e| runtime_failure(Some(&h.rt), &e))?;
        // SAFETY: NULL or writable.
        if let Some(c) = unsafe { cleared.as_mut() } {
            *c = n;
        }
        Ok(())
    })
}

/// Writes the event memory to the older persistence slot now (`*written` false without
/// persistence). The runtime also writes at every cycle end, confirmation and clear.
///
/// # Safety
/// `rt` is a live runtime; `written` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_persist_now(rt: *mut fdd_runtime, written: *mut bool) -> fdd_status {
    with_mut(rt, |h| {
        let w =
            h.rt.persist_now()
                .map_err(|e| runtime_failure(Some(&h.rt), &e))?;
        // SAFETY: NULL or writable.
        if let Some(o) = unsafe { written.as_mut() } {
            *o = w;
        }
        Ok(())
    })
}
