//! The plain C structs of the ABI and their conversion from the runtime's records. Fixed
//! sizes, no pointers into fdd's memory: a host may copy, keep and free them as it likes.

use std::ffi::c_char;

use fdd_diagnostics::dtc::Dtc;
use fdd_diagnostics::event::{MemoryAction, Trigger};
use fdd_diagnostics::verdict::Verdict;

use crate::runtime::{EstimateRecord, EventRecord, ExtendedData};

/// Bytes of a DTC's text in the structs: `"P0123-1C"` and its NUL.
pub const FDD_DTC_TEXT_LEN: usize = 12;
/// Bytes of the name fields of the structs (estimate sources, freeze-frame signals), NUL
/// included; longer names are cut.
pub const FDD_NAME_LEN: usize = 48;

/// The event was caused by a monitor's test report.
pub const FDD_TRIGGER_TEST_RESULT: u8 = 0;
/// By the start of an operation cycle.
pub const FDD_TRIGGER_OPERATION_CYCLE_START: u8 = 1;
/// By the end of an operation cycle (pending cleared, MIL healed, aging).
pub const FDD_TRIGGER_OPERATION_CYCLE_END: u8 = 2;
/// By a ClearDTC (UDS 0x14).
pub const FDD_TRIGGER_CLEAR_DTC: u8 = 3;
/// By another event's entry displacing this one's.
pub const FDD_TRIGGER_DISPLACEMENT: u8 = 4;

/// Nothing happened to the memory entry.
pub const FDD_MEMORY_UNCHANGED: u8 = 0;
/// A new entry (freeze frame) was stored.
pub const FDD_MEMORY_STORED: u8 = 1;
/// The memory was full and nothing could be displaced: not stored.
pub const FDD_MEMORY_NOT_STORED: u8 = 2;
/// This event's entry was displaced by a more important one.
pub const FDD_MEMORY_DISPLACED: u8 = 3;
/// The entry aged out.
pub const FDD_MEMORY_AGED: u8 = 4;
/// The entry was erased by ClearDTC.
pub const FDD_MEMORY_CLEARED: u8 = 5;

/// The test did not run (enable conditions false).
pub const FDD_VERDICT_NOT_TESTED: u8 = 0;
/// The test passed.
pub const FDD_VERDICT_PASSED: u8 = 1;
/// The test failed.
pub const FDD_VERDICT_FAILED: u8 = 2;
/// The test leans to passed (not yet qualified).
pub const FDD_VERDICT_PRE_PASSED: u8 = 3;
/// The test leans to failed (not yet qualified).
pub const FDD_VERDICT_PRE_FAILED: u8 = 4;

/// One sample for `fdd_push_batch`.
#[allow(non_camel_case_types)]
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct fdd_sample {
    /// Signal id from `fdd_signal`.
    pub signal: u32,
    /// Time of the sample, ns of the host's clock.
    pub t_ns: u64,
    /// Value in the signal's unit (configured in `[[signals]]`).
    pub value: f64,
}

/// One DTC status change, drained with `fdd_events_drain`.
#[allow(non_camel_case_types)]
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct fdd_event {
    /// Time of the step (or cycle / clear call) that caused it, ns of the host's clock.
    pub t_ns: u64,
    /// The same time as the event memory saw it, s.
    pub time_s: f64,
    /// The DTC as the 3-byte UDS value (`code << 8 | failure type`).
    pub dtc: u32,
    /// The DTC as text, `"P0122-16"`, NUL-terminated.
    pub dtc_text: [c_char; FDD_DTC_TEXT_LEN],
    /// ISO 14229-1 status byte before and after the change.
    pub status_before: u8,
    pub status_after: u8,
    /// Fault detection counter after the change (-128..127).
    pub fdc: i8,
    /// Qualified failures since the last clear or aging.
    pub occurrence_counter: u8,
    /// Aging cycles counted.
    pub aging_counter: u8,
    /// What caused it: `FDD_TRIGGER_*`.
    pub trigger: u8,
    /// What happened to the memory entry: `FDD_MEMORY_*`.
    pub memory: u8,
    /// Whether `test_*` hold the test result that caused it (a report did).
    pub has_test_result: bool,
    /// The test's verdict: `FDD_VERDICT_*`.
    pub test_verdict: u8,
    /// The test statistic and its pass band `[test_min, test_max]` (units of the test; NaN
    /// where the test did not run).
    pub test_value: f64,
    pub test_min: f64,
    pub test_max: f64,
}

/// The latest value of an estimate (`fdd_latest_estimate`).
#[allow(non_camel_case_types)]
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct fdd_estimate {
    /// Time of the step that produced it, ns.
    pub t_ns: u64,
    /// Value and 95 % interval, in the estimate's unit (deg for `throttle_angle`, Pa for
    /// `manifold_pressure`).
    pub value: f64,
    pub lower: f64,
    pub upper: f64,
    /// Where it comes from (`"tps"`, `"wattmeter_estimate"`, ...), NUL-terminated.
    pub source: [c_char; FDD_NAME_LEN],
}

/// A DTC and its status byte (`fdd_dtcs_by_status_mask`).
#[allow(non_camel_case_types)]
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct fdd_dtc_record {
    /// The 3-byte UDS value.
    pub dtc: u32,
    /// The DTC as text, NUL-terminated.
    pub dtc_text: [c_char; FDD_DTC_TEXT_LEN],
    /// ISO 14229-1 status byte.
    pub status: u8,
}

/// Extended data of a DTC (UDS 0x19 0x06).
#[allow(non_camel_case_types)]
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct fdd_extended_data {
    /// Qualified failures since the last clear or aging.
    pub occurrence_counter: u8,
    /// Aging cycles counted.
    pub aging_counter: u8,
    /// Largest fault detection counter since the last clear.
    pub max_fdc: i8,
    /// Current fault detection counter.
    pub fdc: i8,
    /// Whether the DTC holds a memory entry (freeze frame).
    pub stored: bool,
}

/// The memory entry of a DTC (UDS 0x19 0x04), without its values.
#[allow(non_camel_case_types)]
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct fdd_freeze_frame {
    /// The 3-byte UDS value.
    pub dtc: u32,
    /// ISO 14229-1 status byte.
    pub status: u8,
    /// The event's priority (1 is the most important).
    pub priority: u8,
    /// Occurrence and aging counters, largest FDC since the last clear.
    pub occurrence_counter: u8,
    pub aging_counter: u8,
    pub max_fdc: i8,
    /// Time the entry was stored, s.
    pub stored_time_s: f64,
    /// Values the freeze frame holds (the values written are the first `min(cap, count)`).
    pub value_count: usize,
}

/// One value of a freeze frame.
#[allow(non_camel_case_types)]
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct fdd_freeze_value {
    /// The signal or estimate name, NUL-terminated.
    pub name: [c_char; FDD_NAME_LEN],
    /// Its value at capture (NaN when it had none).
    pub value: f64,
}

/// `s` as a NUL-terminated array, cut to fit.
pub(crate) fn c_text<const N: usize>(s: &[u8]) -> [c_char; N] {
    let mut out = [0 as c_char; N];
    for (o, &b) in out.iter_mut().zip(s.iter().take(N.saturating_sub(1))) {
        *o = b as c_char;
    }
    out
}

pub(crate) fn dtc_text(dtc: Dtc) -> [c_char; FDD_DTC_TEXT_LEN] {
    c_text(&dtc.to_ascii())
}

fn trigger_code(t: Trigger) -> u8 {
    match t {
        Trigger::TestResult => FDD_TRIGGER_TEST_RESULT,
        Trigger::OperationCycleStart => FDD_TRIGGER_OPERATION_CYCLE_START,
        Trigger::OperationCycleEnd => FDD_TRIGGER_OPERATION_CYCLE_END,
        Trigger::ClearDtc => FDD_TRIGGER_CLEAR_DTC,
        Trigger::Displacement => FDD_TRIGGER_DISPLACEMENT,
    }
}

fn memory_code(m: MemoryAction) -> u8 {
    match m {
        MemoryAction::Unchanged => FDD_MEMORY_UNCHANGED,
        MemoryAction::Stored => FDD_MEMORY_STORED,
        MemoryAction::NotStored => FDD_MEMORY_NOT_STORED,
        MemoryAction::Displaced => FDD_MEMORY_DISPLACED,
        MemoryAction::Aged => FDD_MEMORY_AGED,
        MemoryAction::Cleared => FDD_MEMORY_CLEARED,
    }
}

fn verdict_code(v: Verdict) -> u8 {
    match v {
        Verdict::NotTested => FDD_VERDICT_NOT_TESTED,
        Verdict::Passed => FDD_VERDICT_PASSED,
        Verdict::Failed => FDD_VERDICT_FAILED,
        Verdict::PrePassed => FDD_VERDICT_PRE_PASSED,
        Verdict::PreFailed => FDD_VERDICT_PRE_FAILED,
    }
}

impl From<&EventRecord> for fdd_event {
    fn from(r: &EventRecord) -> Self {
        let tr = r.test_result;
        fdd_event {
            t_ns: r.t_ns,
            time_s: r.time_s,
            dtc: r.dtc.to_u32(),
            dtc_text: dtc_text(r.dtc),
            status_before: r.status_before.byte(),
            status_after: r.status_after.byte(),
            fdc: r.fdc,
            occurrence_counter: r.occurrence_counter,
            aging_counter: r.aging_counter,
            trigger: trigger_code(r.trigger),
            memory: memory_code(r.memory),
            has_test_result: tr.is_some(),
            test_verdict: tr.map_or(FDD_VERDICT_NOT_TESTED, |t| verdict_code(t.verdict)),
            test_value: tr.map_or(f64::NAN, |t| t.value),
            test_min: tr.map_or(f64::NAN, |t| t.min),
            test_max: tr.map_or(f64::NAN, |t| t.max),
        }
    }
}

impl From<&EstimateRecord> for fdd_estimate {
    fn from(e: &EstimateRecord) -> Self {
        fdd_estimate {
            t_ns: e.t_ns,
            value: e.value,
            lower: e.lower,
            upper: e.upper,
            source: c_text(e.source.as_bytes()),
        }
    }
}

impl From<ExtendedData> for fdd_extended_data {
    fn from(x: ExtendedData) -> Self {
        fdd_extended_data {
            occurrence_counter: x.occurrence_counter,
            aging_counter: x.aging_counter,
            max_fdc: x.max_fdc,
            fdc: x.fdc,
            stored: x.stored,
        }
    }
}

/// The trigger, memory action and verdict of an event back in the runtime's terms (for its
/// JSON form).
pub(crate) fn trigger_of(code: u8) -> Option<Trigger> {
    Some(match code {
        FDD_TRIGGER_TEST_RESULT => Trigger::TestResult,
        FDD_TRIGGER_OPERATION_CYCLE_START => Trigger::OperationCycleStart,
        FDD_TRIGGER_OPERATION_CYCLE_END => Trigger::OperationCycleEnd,
        FDD_TRIGGER_CLEAR_DTC => Trigger::ClearDtc,
        FDD_TRIGGER_DISPLACEMENT => Trigger::Displacement,
        _ => return None,
    })
}

pub(crate) fn memory_of(code: u8) -> Option<MemoryAction> {
    Some(match code {
        FDD_MEMORY_UNCHANGED => MemoryAction::Unchanged,
        FDD_MEMORY_STORED => MemoryAction::Stored,
        FDD_MEMORY_NOT_STORED => MemoryAction::NotStored,
        FDD_MEMORY_DISPLACED => MemoryAction::Displaced,
        FDD_MEMORY_AGED => MemoryAction::Aged,
        FDD_MEMORY_CLEARED => MemoryAction::Cleared,
        _ => return None,
    })
}

pub(crate) fn verdict_of(code: u8) -> Option<Verdict> {
    Some(match code {
        FDD_VERDICT_NOT_TESTED => Verdict::NotTested,
        FDD_VERDICT_PASSED => Verdict::Passed,
        FDD_VERDICT_FAILED => Verdict::Failed,
        FDD_VERDICT_PRE_PASSED => Verdict::PrePassed,
        FDD_VERDICT_PRE_FAILED => Verdict::PreFailed,
        _ => return None,
    })
}
