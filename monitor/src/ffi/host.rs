//! The host loop: signals, samples, time, operation cycles, events and estimates.

use std::ffi::c_char;

use fdd_diagnostics::dtc::{Dtc, DtcStatus};
use fdd_diagnostics::TestResult;
use serde::Serialize;

use super::error::{fail, Failure};
use super::types::{memory_of, trigger_of, verdict_of};
use super::{
    copy_out, fdd_estimate, fdd_event, fdd_runtime, fdd_sample, fdd_status, null, out,
    runtime_failure, text, with_mut, with_ref, FDD_ERR_ARGUMENT, FDD_ERR_NOT_FOUND,
};
use crate::signal_table::SignalId;

/// The id of the signal `name` (a `[[signals]]` name of the configuration, e.g. `"tps"`):
/// resolve once, push many times.
///
/// # Safety
/// `rt` is a live runtime; `name` is a NUL-terminated string; `out_id` is writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_signal(
    rt: *const fdd_runtime,
    name: *const c_char,
    out_id: *mut u32,
) -> fdd_status {
    with_ref(rt, |h| {
        let o = out(out_id, "out_id")?;
        let n = text(name, "name")?;
        let id = h.rt.signal(n).ok_or_else(|| {
            fail(
                FDD_ERR_NOT_FOUND,
                format_args!("no signal `{n}` in {} ([[signals]])", h.rt.origin()),
            )
        })?;
        *o = u32::try_from(id.index())
            .map_err(|_| fail(FDD_ERR_ARGUMENT, format_args!("signal index overflows")))?;
        Ok(())
    })
}

fn push_one(h: &mut fdd_runtime, signal: u32, t_ns: u64, value: f64) -> Result<(), Failure> {
    h.rt.push(SignalId::from_index(signal as usize), t_ns, value)
        .map_err(|e| runtime_failure(Some(&h.rt), &e))
}

/// Stores a sample of `signal` at `t_ns` (ns of the host's clock): a bounds check and a
/// store, no allocation. Refused (`FDD_ERR_SAMPLE`, nothing stored) when the value is not
/// finite or the time does not increase; `FDD_ERR_UNKNOWN_SIGNAL` for an id not of this
/// runtime.
///
/// # Safety
/// `rt` is a live runtime.
#[no_mangle]
pub unsafe extern "C" fn fdd_push(
    rt: *mut fdd_runtime,
    signal: u32,
    t_ns: u64,
    value: f64,
) -> fdd_status {
    with_mut(rt, |h| push_one(h, signal, t_ns, value))
}

/// Stores `n` samples in order. Stops at the first refused one and returns its status;
/// `*accepted` receives the number stored before it (all `n` on `FDD_OK`), so that the host
/// can skip the refused sample and go on from `accepted + 1`. This out-parameter is written
/// on failure too.
///
/// # Safety
/// `rt` is a live runtime; `samples` points to `n` samples (or is NULL with `n` 0);
/// `accepted` is writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_push_batch(
    rt: *mut fdd_runtime,
    samples: *const fdd_sample,
    n: usize,
    accepted: *mut usize,
) -> fdd_status {
    with_mut(rt, |h| {
        let acc = out(accepted, "accepted")?;
        *acc = 0;
        if n == 0 {
            return Ok(());
        }
        if samples.is_null() {
            return Err(null("samples"));
        }
        // SAFETY: `samples` points to `n` samples by the contract.
        let s = unsafe { std::slice::from_raw_parts(samples, n) };
        for x in s {
            push_one(h, x.signal, x.t_ns, x.value)?;
            *acc += 1;
        }
        Ok(())
    })
}

/// Runs every monitor step due at or before `t_ns` on the samples pushed so far; their
/// events wait in the runtime's queue. `*steps` (if not NULL) receives the steps run.
/// Needs a running operation cycle; `t_ns` must not be before the previous call's.
///
/// # Safety
/// `rt` is a live runtime; `steps` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_advance_to(
    rt: *mut fdd_runtime,
    t_ns: u64,
    steps: *mut u64,
) -> fdd_status {
    with_mut(rt, |h| {
        let n =
            h.rt.advance_to(t_ns, &mut h.events)
                .map_err(|e| runtime_failure(Some(&h.rt), &e))?;
        // SAFETY: NULL or writable.
        if let Some(s) = unsafe { steps.as_mut() } {
            *s = n;
        }
        Ok(())
    })
}

/// Starts an operation cycle at `t_ns` (ignition on; ends the running one first, as AUTOSAR
/// Dem's `Dem_RestartOperationCycle`). Monitors run only inside one.
///
/// # Safety
/// `rt` is a live runtime.
#[no_mangle]
pub unsafe extern "C" fn fdd_start_operation_cycle(rt: *mut fdd_runtime, t_ns: u64) -> fdd_status {
    with_mut(rt, |h| {
        h.rt.start_operation_cycle(t_ns, &mut h.events)
            .map_err(|e| runtime_failure(Some(&h.rt), &e))
    })
}

/// Ends the running operation cycle at `t_ns` (ignition off): pending DTCs of tests that
/// passed are cleared, healing and aging counted, the memory persisted.
///
/// # Safety
/// `rt` is a live runtime.
#[no_mangle]
pub unsafe extern "C" fn fdd_end_operation_cycle(rt: *mut fdd_runtime, t_ns: u64) -> fdd_status {
    with_mut(rt, |h| {
        h.rt.end_operation_cycle(t_ns, &mut h.events)
            .map_err(|e| runtime_failure(Some(&h.rt), &e))
    })
}

/// Reports that the running cycle is a warm-up cycle (coolant up by 22 degC to at least
/// 70 degC); with `[operation_cycles] aging = "warm_up_cycle"` only those age DTCs.
///
/// # Safety
/// `rt` is a live runtime.
#[no_mangle]
pub unsafe extern "C" fn fdd_warm_up_completed(rt: *mut fdd_runtime) -> fdd_status {
    with_mut(rt, |h| {
        h.rt.warm_up_completed();
        Ok(())
    })
}

/// Enables (`on`) or disables a subsystem monitor (`"throttle"`, `"intake"`) at run time.
///
/// # Safety
/// `rt` is a live runtime; `monitor` is a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn fdd_set_monitor_enabled(
    rt: *mut fdd_runtime,
    monitor: *const c_char,
    on: bool,
) -> fdd_status {
    with_mut(rt, |h| {
        let m = text(monitor, "monitor")?;
        h.rt.set_monitor_enabled(m, on)
            .map_err(|e| runtime_failure(Some(&h.rt), &e))
    })
}

/// Moves up to `cap` waiting events, oldest first, into `buf`; `*written` receives how many.
///
/// # Safety
/// `rt` is a live runtime; `buf` points to `cap` writable events (or is NULL with `cap` 0);
/// `written` is writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_events_drain(
    rt: *mut fdd_runtime,
    buf: *mut fdd_event,
    cap: usize,
    written: *mut usize,
) -> fdd_status {
    with_mut(rt, |h| {
        let w = out(written, "written")?;
        if buf.is_null() && cap > 0 {
            return Err(null("buf"));
        }
        let mut n = 0;
        while n < cap {
            let Some(r) = h.events.pop() else { break };
            // SAFETY: `n < cap` and `buf` holds `cap` events.
            unsafe { buf.add(n).write(fdd_event::from(&r)) };
            n += 1;
        }
        *w = n;
        Ok(())
    })
}

/// Events waiting in the queue (`*pending`) and events dropped because it was full since
/// the runtime was built (`*dropped`); either pointer may be NULL.
///
/// # Safety
/// `rt` is a live runtime; `pending` and `dropped` are NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_events_count(
    rt: *const fdd_runtime,
    pending: *mut usize,
    dropped: *mut u64,
) -> fdd_status {
    with_ref(rt, |h| {
        // SAFETY: NULL or writable.
        if let Some(p) = unsafe { pending.as_mut() } {
            *p = h.events.len();
        }
        if let Some(d) = unsafe { dropped.as_mut() } {
            *d = h.events.dropped();
        }
        Ok(())
    })
}

/// The JSON of one event: the fields of `fdd replay --events`'s `DiagnosticEvent` that an
/// event record holds, plus `t_ns` and the event's and monitor's names.
#[derive(Serialize)]
struct EventJson<'a> {
    t_ns: u64,
    time_s: f64,
    event: &'a str,
    monitor: &'a str,
    dtc: Dtc,
    dtc_uds: u32,
    trigger: fdd_diagnostics::event::Trigger,
    status_before: DtcStatus,
    status_after: DtcStatus,
    fdc: i8,
    occurrence_counter: u8,
    aging_counter: u8,
    memory: fdd_diagnostics::event::MemoryAction,
    test_result: Option<TestResult>,
}

/// Counts the bytes written through it (the JSON's length without a buffer).
struct Counter(usize);

impl std::io::Write for Counter {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0 += b.len();
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The JSON form of `event` (one line, no newline), NUL-terminated in `buf`. `*len` receives
/// its length (without the NUL) also when the buffer is too small (`FDD_ERR_BUFFER_TOO_SMALL`,
/// nothing written), so the host can retry; 1024 bytes always suffice for the default
/// configuration's event names.
///
/// # Safety
/// `rt` is a live runtime; `event` points to an event; `buf` points to `cap` writable bytes
/// (or is NULL with `cap` 0); `len` is writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_event_json(
    rt: *const fdd_runtime,
    event: *const fdd_event,
    buf: *mut c_char,
    cap: usize,
    len: *mut usize,
) -> fdd_status {
    with_ref(rt, |h| {
        // SAFETY: NULL or a readable event.
        let e = unsafe { event.as_ref() }.ok_or_else(|| null("event"))?;
        let bad = |what: &str| fail(FDD_ERR_ARGUMENT, format_args!("event: invalid `{what}`"));
        let dtc = Dtc::from_u32(e.dtc).map_err(|_| bad("dtc"))?;
        let (name, monitor) = h.rt.event_name(dtc).ok_or_else(|| {
            fail(
                FDD_ERR_NOT_FOUND,
                format_args!("DTC {dtc} is not configured in this runtime"),
            )
        })?;
        let test_result = if e.has_test_result {
            Some(TestResult {
                value: e.test_value,
                min: e.test_min,
                max: e.test_max,
                verdict: verdict_of(e.test_verdict).ok_or_else(|| bad("test_verdict"))?,
            })
        } else {
            None
        };
        let j = EventJson {
            t_ns: e.t_ns,
            time_s: e.time_s,
            event: name,
            monitor,
            dtc,
            dtc_uds: e.dtc,
            trigger: trigger_of(e.trigger).ok_or_else(|| bad("trigger"))?,
            status_before: DtcStatus::from_byte(e.status_before),
            status_after: DtcStatus::from_byte(e.status_after),
            fdc: e.fdc,
            occurrence_counter: e.occurrence_counter,
            aging_counter: e.aging_counter,
            memory: memory_of(e.memory).ok_or_else(|| bad("memory"))?,
            test_result,
        };
        let mut c = Counter(0);
        serde_json::to_writer(&mut c, &j)
            .map_err(|err| fail(FDD_ERR_ARGUMENT, format_args!("event JSON: {err}")))?;
        let l = out(len, "len")?;
        *l = c.0;
        if buf.is_null() && cap > 0 {
            return Err(null("buf"));
        }
        if c.0 >= cap {
            return Err(fail(
                super::FDD_ERR_BUFFER_TOO_SMALL,
                format_args!("{} bytes needed (and a NUL), the buffer holds {cap}", c.0),
            ));
        }
        // SAFETY: `buf` holds `cap > c.0` bytes.
        let dst = unsafe { std::slice::from_raw_parts_mut(buf.cast::<u8>(), cap) };
        let mut w = &mut dst[..c.0];
        serde_json::to_writer(&mut w, &j)
            .map_err(|err| fail(FDD_ERR_ARGUMENT, format_args!("event JSON: {err}")))?;
        dst[c.0] = 0;
        Ok(())
    })
}

/// The configured name of the event with DTC `dtc` (3-byte UDS value), e.g.
/// `"tps_circuit_low"`, NUL-terminated in `buf`; `*len` as for `fdd_event_json`.
///
/// # Safety
/// `rt` is a live runtime; `buf` points to `cap` writable bytes; `len` is writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_event_name(
    rt: *const fdd_runtime,
    dtc: u32,
    buf: *mut c_char,
    cap: usize,
    len: *mut usize,
) -> fdd_status {
    with_ref(rt, |h| {
        copy_out(super::dtc::named(h, dtc)?.0.as_bytes(), buf, cap, len)
    })
}

/// The monitor that owns DTC `dtc` (`"throttle"`, `"intake"`, `"staleness"`), as
/// `fdd_event_name`.
///
/// # Safety
/// As `fdd_event_name`.
#[no_mangle]
pub unsafe extern "C" fn fdd_event_monitor(
    rt: *const fdd_runtime,
    dtc: u32,
    buf: *mut c_char,
    cap: usize,
    len: *mut usize,
) -> fdd_status {
    with_ref(rt, |h| {
        copy_out(super::dtc::named(h, dtc)?.1.as_bytes(), buf, cap, len)
    })
}

/// The latest value of the estimate `name` (`"throttle_angle"`: the throttle position in
/// deg, its 95 % interval and its source, `"tps"` or `"wattmeter_estimate"`);
/// `FDD_ERR_NOT_FOUND` until a step has reported it.
///
/// # Safety
/// `rt` is a live runtime; `name` is a NUL-terminated string; `out_estimate` is writable.
#[no_mangle]
pub unsafe extern "C" fn fdd_latest_estimate(
    rt: *const fdd_runtime,
    name: *const c_char,
    out_estimate: *mut fdd_estimate,
) -> fdd_status {
    with_ref(rt, |h| {
        let o = out(out_estimate, "out_estimate")?;
        let n = text(name, "name")?;
        let e = h.events.estimate(n).ok_or_else(|| {
            fail(
                FDD_ERR_NOT_FOUND,
                format_args!("no estimate `{n}` reported yet"),
            )
        })?;
        *o = fdd_estimate::from(e);
        Ok(())
    })
}
