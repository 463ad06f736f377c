//! The event memory: per-event ISO 14229-1 status bytes driven by debounced monitor results and
//! operation cycles, plus a fixed number of memory entries (extended data and freeze frame),
//! shaped after the AUTOSAR Diagnostic Event Manager (Dem).
//!
//! # Model
//!
//! - **Events** are configured once ([`EventMemoryConfig`]) and addressed by [`EventId`]. Every
//!   event has its status byte, debouncer and counters whether or not it holds a memory entry
//!   (as in Dem, where status is per event).
//! - **Operation cycles** are explicit: [`EventMemory::start_operation_cycle`] and
//!   [`EventMemory::end_operation_cycle`]. Reports are accepted only inside a cycle
//!   ([`DemError::NoOperationCycle`] otherwise). Starting a cycle while one runs ends it first.
//! - **Time** is passed in (seconds, any origin); it must be finite and never decrease across
//!   calls ([`DemError::TimeWentBackwards`]). A rejected call changes nothing.
//! - **Output**: every change of an event's status byte (and every store, refusal, displacement,
//!   aging or clear of its memory entry) is passed to the caller's sink as a
//!   [`DiagnosticEvent`]. A call that changes no status emits nothing and allocates nothing.
//!
//! # Status rules (see [`crate::dtc::status`] for the bits)
//!
//! At construction every status byte is `0x50`, as after ClearDTC (no persistence between
//! power cycles is modelled here).
//!
//! - **Qualified failure** (debounced `Failed`): sets testFailed, testFailedThisOperationCycle,
//!   pendingDTC and testFailedSinceLastClear; clears both "test not completed" bits. The first
//!   failure of an operation cycle counts a *failed cycle*; when the failed cycles counted
//!   since pendingDTC was last cleared reach `confirmation_threshold`, confirmedDTC is set (and
//!   warningIndicatorRequested, with the default [`MilOn::Confirmed`]). Cycles in which the test
//!   did not complete neither count nor break the sequence (OBD: "the next cycle in which the
//!   monitor runs"). A failure resets the healing and aging counters. testFailed 0 -> 1 counts
//!   an occurrence (occurrence counter, saturating at 255).
//! - **Qualified pass**: clears testFailed and both "test not completed" bits.
//! - **Operation cycle start**: clears testFailedThisOperationCycle, sets
//!   testNotCompletedThisOperationCycle, resets every debouncer (FDC 0).
//! - **Operation cycle end**, for an event whose test completed in the cycle without any failure
//!   (a *passed cycle*): clears pendingDTC and the failed-cycle count; if the MIL request is on,
//!   counts a healing cycle and switches it off after `mil.off_after_passing_cycles` consecutive
//!   ones (OBD: 3); if it is off (checked before healing, so the cycle that switches the MIL off
//!   does not count) and the event has a memory entry or is confirmed, counts an aging cycle, and
//!   at `aging_threshold` (OBD: 40) clears confirmedDTC and erases the entry ("aged").
//!   testFailedSinceLastClear stays until ClearDTC (ISO 14229-1 lets aging keep it). Cycles
//!   where the test did not complete count for nothing (AUTOSAR "aging requires tested cycle").
//! - **ClearDTC** ([`EventMemory::clear_dtc`]): status `0x50`, debouncer and all counters reset,
//!   entry erased; clearing all DTCs also resets the overflow indication.
//! - A `NotTested` result changes nothing.
//!
//! # Memory entries
//!
//! An event gets an entry at a qualified failure that is a new occurrence (testFailed 0 -> 1)
//! or the first failure of a cycle, if it has none. The entry holds the freeze frame (the values
//! the caller passes with that report, for the configured signals; updated later only with
//! [`FreezeFrameUpdate::Latest`]) and the time and order of storage; occurrence counter, aging
//! counter and maximum FDC since the last clear are read from the event. When every entry is in
//! use, the new entry may **displace** one whose priority is strictly lower (numerically
//! larger; 1 is the highest): the lowest priority first, among equal priorities a passive one
//! (testFailed = 0) before an active one, then the oldest (stored first). The displaced event
//! loses its entry and its extended data (occurrence and aging counters restart) and, as with
//! AUTOSAR `DemResetConfirmedBitOnOverflow`, its confirmedDTC bit; it emits an event with
//! trigger `displacement`. If nothing can be displaced the entry is **not stored**: the event
//! is emitted with `memory = "not_stored"` (carrying the report's freeze-frame values) and the
//! overflow counter grows. The overflow indication ([`EventMemory::overflow`], UDS/Dem
//! "event memory overflow") is set whenever a new entry met a full memory.
//!
//! # Allocation
//!
//! All state is allocated in [`EventMemory::new`]. Reports, cycle calls and queries allocate
//! only to build the [`DiagnosticEvent`]s they emit; a call that changes no status byte and no
//! entry allocates nothing (`tests/dtc_no_alloc.rs`).

use thiserror::Error;

use crate::dtc::code::{Dtc, DtcSystem};
use crate::dtc::config::{EventMemoryConfig, FreezeFrameUpdate, MilConfig, MilOn};
use crate::dtc::debounce::{Debouncer, Qualified};
use crate::dtc::status::DtcStatus;
use crate::error::ConfigError;
use crate::event::{DiagnosticEvent, EventView, FreezeFrameView, MemoryAction, Trigger};
use crate::verdict::{TestResult, Verdict};

mod image;
pub use image::{
    DropReason, Dropped, EntryImage, EventImage, ImageError, ImageErrorKind, MemoryImage,
    RestoreReport, IMAGE_FORMAT_VERSION, IMAGE_MAGIC,
};

/// Handle of a configured event: its index in [`EventMemoryConfig::events`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct EventId(u16);

impl EventId {
    /// The index in the configuration's event list.
    pub const fn index(self) -> usize {
        self.0 as usize
    }
}

/// Which DTCs a ClearDTC applies to (UDS ClearDiagnosticInformation's groupOfDTC).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DtcGroup {
    /// Every DTC (`0xFFFFFF`).
    All,
    /// Every DTC of one system (P, C, B or U).
    System(DtcSystem),
    /// One DTC.
    Dtc(Dtc),
}

impl DtcGroup {
    /// The group of a UDS groupOfDTC value: `0xFFFFFF` is all DTCs, anything else one DTC.
    pub fn from_uds(value: u32) -> Result<DtcGroup, crate::dtc::DtcParseError> {
        if value == 0x00FF_FFFF {
            Ok(DtcGroup::All)
        } else {
            Dtc::from_u32(value).map(DtcGroup::Dtc)
        }
    }

    fn contains(&self, dtc: Dtc) -> bool {
        match *self {
            DtcGroup::All => true,
            DtcGroup::System(s) => dtc.code.system() == s,
            DtcGroup::Dtc(d) => d == dtc,
        }
    }
}

/// A rejected call. Nothing was changed.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum DemError {
    /// The [`EventId`] belongs to another memory.
    #[error("event id {0} is not configured in this event memory")]
    UnknownEvent(usize),
    /// No configured event has this DTC.
    #[error("DTC {0} is not configured in this event memory")]
    UnknownDtc(Dtc),
    /// The time is NaN or infinite.
    #[error("time {0} s is not finite")]
    NonFiniteTime(f64),
    /// The time is before the time of an earlier call.
    #[error("time {now} s is before the previous call's time {last} s")]
    TimeWentBackwards {
        /// The rejected time.
        now: f64,
        /// The latest accepted time.
        last: f64,
    },
    /// A test result arrived, or a cycle was ended, outside an operation cycle.
    #[error("no operation cycle is running (call start_operation_cycle first)")]
    NoOperationCycle,
    /// The freeze-frame values do not match the event's configured signals.
    #[error("{got} freeze-frame values given but the event has {expected} freeze-frame signals (pass all or none)")]
    FreezeFrameLength {
        /// Configured signals.
        expected: usize,
        /// Values given.
        got: usize,
    },
}

/// What comes with a report besides the test result: its time, the current values of the
/// event's freeze-frame signals (in configured order; empty if not available, then stored as
/// missing) and the isolation candidates (fault name, score), which are copied into any
/// emitted [`DiagnosticEvent`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReportContext<'a> {
    /// Time of the report, s.
    pub time_s: f64,
    /// Freeze-frame signal values, in the event's configured order, or empty.
    pub freeze_frame: &'a [f64],
    /// Isolation candidates `(fault, score)`.
    pub candidates: &'a [(&'a str, f64)],
}

impl<'a> ReportContext<'a> {
    /// A context at `time_s` with no freeze-frame values and no candidates.
    pub const fn at(time_s: f64) -> Self {
        ReportContext {
            time_s,
            freeze_frame: &[],
            candidates: &[],
        }
    }

    /// With freeze-frame values.
    pub const fn with_freeze_frame(mut self, values: &'a [f64]) -> Self {
        self.freeze_frame = values;
        self
    }

    /// With isolation candidates.
    pub const fn with_candidates(mut self, candidates: &'a [(&'a str, f64)]) -> Self {
        self.candidates = candidates;
        self
    }
}

/// The validated, immutable part of an event.
#[derive(Debug, Clone)]
struct EventDef {
    name: String,
    dtc: Dtc,
    priority: u8,
    confirmation_threshold: u8,
    aging_threshold: u8,
    mil: MilConfig,
    freeze_frame: Vec<String>,
    freeze_frame_update: FreezeFrameUpdate,
}

/// The mutable part of an event.
#[derive(Debug, Clone, Copy)]
struct EventState {
    status: DtcStatus,
    debouncer: Debouncer,
    /// Operation cycles with a failure since pendingDTC was last cleared.
    failed_cycles: u8,
    /// Consecutive passed cycles while the MIL request is on.
    healing_cycles: u8,
    aging_counter: u8,
    occurrence_counter: u8,
    max_fdc: i8,
    slot: Option<u16>,
}

impl EventState {
    fn reset(&mut self) {
        self.status = DtcStatus::AFTER_CLEAR;
        self.debouncer.reset();
        self.failed_cycles = 0;
        self.healing_cycles = 0;
        self.aging_counter = 0;
        self.occurrence_counter = 0;
        self.max_fdc = 0;
    }
}

#[derive(Debug, Clone, Copy)]
struct Entry {
    event: u16,
    seq: u64,
    stored_time_s: f64,
}

/// Everything known about one event (a snapshot; see [`EventMemory::event_info`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EventInfo<'a> {
    /// The handle.
    pub id: EventId,
    /// Configured name.
    pub name: &'a str,
    /// The DTC.
    pub dtc: Dtc,
    /// Priority (1 highest).
    pub priority: u8,
    /// Status byte.
    pub status: DtcStatus,
    /// Fault detection counter.
    pub fdc: i8,
    /// Largest FDC since the last clear.
    pub max_fdc: i8,
    /// Qualified failures since the last clear or aging (or the loss of the entry).
    pub occurrence_counter: u8,
    /// Aging cycles counted.
    pub aging_counter: u8,
    /// Failed operation cycles counted towards confirmation.
    pub failed_cycles: u8,
    /// Passed cycles counted towards switching the MIL off.
    pub healing_cycles: u8,
    /// Whether the event holds a memory entry.
    pub stored: bool,
}

/// One memory entry (a view into the memory).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MemoryEntry<'a> {
    /// The event it belongs to.
    pub event: EventId,
    /// Event name.
    pub name: &'a str,
    /// The DTC.
    pub dtc: Dtc,
    /// The event's status byte.
    pub status: DtcStatus,
    /// The event's priority.
    pub priority: u8,
    /// Extended data: occurrence counter.
    pub occurrence_counter: u8,
    /// Extended data: aging counter.
    pub aging_counter: u8,
    /// Extended data: largest FDC since the last clear.
    pub max_fdc: i8,
    /// Storage order (larger = stored later), used for "oldest" in displacement.
    pub stored_seq: u64,
    /// Time the entry was stored, s.
    pub stored_time_s: f64,
    signals: &'a [String],
    values: &'a [f64],
}

impl<'a> MemoryEntry<'a> {
    /// The freeze frame: `(signal, value)` in configured order; NaN where no value was given.
    pub fn freeze_frame(&self) -> impl Iterator<Item = (&'a str, f64)> + 'a {
        let values = self.values;
        self.signals
            .iter()
            .zip(values.iter())
            .map(|(s, v)| (s.as_str(), *v))
    }
}

/// An AUTOSAR-Dem-shaped event memory with ISO 14229-1 status bytes. See the
/// [module documentation](self) for the rules.
#[derive(Debug, Clone)]
pub struct EventMemory {
    defs: Vec<EventDef>,
    states: Vec<EventState>,
    slots: Vec<Option<Entry>>,
    /// Freeze-frame values, `slots.len() * ff_stride`, slot-major.
    ff: Vec<f64>,
    ff_stride: usize,
    next_seq: u64,
    cycle_active: bool,
    cycles_started: u64,
    last_time_s: f64,
    overflow: bool,
    overflow_count: u32,
}

type Sink<'s> = &'s mut dyn FnMut(&EventView<'_>);

impl EventMemory {
    /// Validates `config` and allocates everything the memory will ever need. No operation
    /// cycle is running yet; every status byte is `0x50`.
    pub fn new(config: &EventMemoryConfig) -> Result<Self, ConfigError> {
        let dtcs = config.validate()?;
        let defs: Vec<EventDef> = config
            .events
            .iter()
            .zip(dtcs)
            .map(|(e, dtc)| EventDef {
                name: e.name.clone(),
                dtc,
                priority: e.priority,
                confirmation_threshold: e.confirmation_threshold,
                aging_threshold: e.aging_threshold,
                mil: e.mil,
                freeze_frame: e.freeze_frame.clone(),
                freeze_frame_update: e.freeze_frame_update,
            })
            .collect();
        let states = config
            .events
            .iter()
            .map(|e| EventState {
                status: DtcStatus::AFTER_CLEAR,
                debouncer: Debouncer::new(e.debounce),
                failed_cycles: 0,
                healing_cycles: 0,
                aging_counter: 0,
                occurrence_counter: 0,
                max_fdc: 0,
                slot: None,
            })
            .collect();
        let ff_stride = defs.iter().map(|d| d.freeze_frame.len()).max().unwrap_or(0);
        Ok(EventMemory {
            defs,
            states,
            slots: vec![None; config.capacity],
            ff: vec![f64::NAN; config.capacity * ff_stride],
            ff_stride,
            next_seq: 0,
            cycle_active: false,
            cycles_started: 0,
            last_time_s: f64::NEG_INFINITY,
            overflow: false,
            overflow_count: 0,
        })
    }

    // ---------------------------------------------------------------- lookups and queries

    /// Number of configured events.
    pub fn num_events(&self) -> usize {
        self.defs.len()
    }

    /// Number of memory entries.
    pub fn capacity(&self) -> usize {
        self.slots.len()
    }

    /// The event named `name`.
    pub fn event_id(&self, name: &str) -> Option<EventId> {
        self.defs
            .iter()
            .position(|d| d.name == name)
            .map(|i| EventId(i as u16))
    }

    /// The event with DTC `dtc`.
    pub fn event_id_by_dtc(&self, dtc: Dtc) -> Option<EventId> {
        self.defs
            .iter()
            .position(|d| d.dtc == dtc)
            .map(|i| EventId(i as u16))
    }

    /// The event at `index` in the configuration.
    pub fn event_id_at(&self, index: usize) -> Option<EventId> {
        (index < self.defs.len()).then_some(EventId(index as u16))
    }

    /// All event ids, in configuration order.
    pub fn event_ids(&self) -> impl Iterator<Item = EventId> {
        (0..self.defs.len() as u16).map(EventId)
    }

    /// The status byte of `id`. Panics if `id` is not from this memory (as do the other
    /// per-event queries).
    pub fn status(&self, id: EventId) -> DtcStatus {
        self.states[id.index()].status
    }

    /// The fault detection counter of `id`.
    pub fn fdc(&self, id: EventId) -> i8 {
        self.states[id.index()].debouncer.fdc()
    }

    /// The DTC of `id`.
    pub fn dtc(&self, id: EventId) -> Dtc {
        self.defs[id.index()].dtc
    }

    /// The configured name of `id`.
    pub fn name(&self, id: EventId) -> &str {
        &self.defs[id.index()].name
    }

    /// The freeze-frame signals of `id`, in configured order (the order of the values a report
    /// passes in [`ReportContext::freeze_frame`]).
    pub fn freeze_frame_signals(&self, id: EventId) -> &[String] {
        &self.defs[id.index()].freeze_frame
    }

    /// Everything about `id`.
    pub fn event_info(&self, id: EventId) -> EventInfo<'_> {
        let d = &self.defs[id.index()];
        let s = &self.states[id.index()];
        EventInfo {
            id,
            name: &d.name,
            dtc: d.dtc,
            priority: d.priority,
            status: s.status,
            fdc: s.debouncer.fdc(),
            max_fdc: s.max_fdc,
            occurrence_counter: s.occurrence_counter,
            aging_counter: s.aging_counter,
            failed_cycles: s.failed_cycles,
            healing_cycles: s.healing_cycles,
            stored: s.slot.is_some(),
        }
    }

    /// The memory entry of `id`, if it has one.
    pub fn entry(&self, id: EventId) -> Option<MemoryEntry<'_>> {
        let k = self.states[id.index()].slot? as usize;
        self.entry_at(k)
    }

    /// The memory entries, in slot order (sort by `stored_seq` for chronological order).
    pub fn entries(&self) -> impl Iterator<Item = MemoryEntry<'_>> {
        (0..self.slots.len()).filter_map(|k| self.entry_at(k))
    }

    /// Number of memory entries in use.
    pub fn entries_used(&self) -> usize {
        self.slots.iter().filter(|s| s.is_some()).count()
    }

    /// UDS ReadDTCInformation by status mask: every event whose status byte has any bit of
    /// `mask` set, with that byte, in configuration order.
    pub fn dtcs_by_status_mask(&self, mask: u8) -> impl Iterator<Item = (Dtc, DtcStatus)> + '_ {
        self.defs
            .iter()
            .zip(&self.states)
            .filter(move |(_, s)| s.status.matches(mask))
            .map(|(d, s)| (d.dtc, s.status))
    }

    /// Whether any event requests the MIL.
    pub fn mil_on(&self) -> bool {
        self.states.iter().any(|s| s.status.warning_indicator())
    }

    /// Whether a new entry met a full memory since the last ClearDTC of all DTCs.
    pub fn overflow(&self) -> bool {
        self.overflow
    }

    /// Entries that could not be stored (nothing displaceable) since the last clear of all DTCs.
    pub fn overflow_count(&self) -> u32 {
        self.overflow_count
    }

    /// Whether an operation cycle is running.
    pub fn operation_cycle_active(&self) -> bool {
        self.cycle_active
    }

    /// Operation cycles started so far.
    pub fn operation_cycles_started(&self) -> u64 {
        self.cycles_started
    }

    fn entry_at(&self, k: usize) -> Option<MemoryEntry<'_>> {
        let e = self.slots[k]?;
        let d = &self.defs[e.event as usize];
        let s = &self.states[e.event as usize];
        let n = d.freeze_frame.len();
        let base = k * self.ff_stride;
        Some(MemoryEntry {
            event: EventId(e.event),
            name: &d.name,
            dtc: d.dtc,
            status: s.status,
            priority: d.priority,
            occurrence_counter: s.occurrence_counter,
            aging_counter: s.aging_counter,
            max_fdc: s.max_fdc,
            stored_seq: e.seq,
            stored_time_s: e.stored_time_s,
            signals: &d.freeze_frame,
            values: &self.ff[base..base + n],
        })
    }

    // ---------------------------------------------------------------- checks

    fn check_id(&self, id: EventId) -> Result<usize, DemError> {
        let i = id.index();
        if i < self.defs.len() {
            Ok(i)
        } else {
            Err(DemError::UnknownEvent(i))
        }
    }

    fn check_time(&self, t: f64) -> Result<(), DemError> {
        if !t.is_finite() {
            return Err(DemError::NonFiniteTime(t));
        }
        if t < self.last_time_s {
            return Err(DemError::TimeWentBackwards {
                now: t,
                last: self.last_time_s,
            });
        }
        Ok(())
    }

    // ---------------------------------------------------------------- reports

    /// Reports one test result of event `id`. The verdict goes through the event's debouncer;
    /// a qualified result updates the status byte and the memory as described in the
    /// [module documentation](self). Each status change is passed to `sink` (this event's,
    /// and first that of an event whose entry this one displaces). Returns the event's status
    /// byte after the report.
    ///
    /// `NotTested` changes nothing (it is accepted even outside an operation cycle).
    ///
    /// Builds an owned [`DiagnosticEvent`] per change; [`EventMemory::report_view`] hands out
    /// borrowed views instead and allocates nothing.
    pub fn report(
        &mut self,
        id: EventId,
        result: &TestResult,
        ctx: &ReportContext<'_>,
        mut sink: impl FnMut(DiagnosticEvent),
    ) -> Result<DtcStatus, DemError> {
        self.report_view(id, result, ctx, |v| sink(v.to_event()))
    }

    /// [`EventMemory::report`] with each change passed as a borrowed [`EventView`]: no
    /// allocation at all, status change or not.
    pub fn report_view(
        &mut self,
        id: EventId,
        result: &TestResult,
        ctx: &ReportContext<'_>,
        mut sink: impl FnMut(&EventView<'_>),
    ) -> Result<DtcStatus, DemError> {
        let i = self.check_id(id)?;
        self.check_time(ctx.time_s)?;
        let expected = self.defs[i].freeze_frame.len();
        if !ctx.freeze_frame.is_empty() && ctx.freeze_frame.len() != expected {
            return Err(DemError::FreezeFrameLength {
                expected,
                got: ctx.freeze_frame.len(),
            });
        }
        if result.verdict == Verdict::NotTested {
            self.last_time_s = ctx.time_s;
            return Ok(self.states[i].status);
        }
        if !self.cycle_active {
            return Err(DemError::NoOperationCycle);
        }
        self.last_time_s = ctx.time_s;

        let st = &mut self.states[i];
        let qualified = st.debouncer.report(result.verdict, ctx.time_s);
        st.max_fdc = st.max_fdc.max(st.debouncer.fdc());
        match qualified {
            None => {}
            Some(Qualified::Failed) => self.qualified_failed(i, result, ctx, &mut sink),
            Some(Qualified::Passed) => self.qualified_passed(i, result, ctx, &mut sink),
        }
        Ok(self.states[i].status)
    }

    fn qualified_passed(
        &mut self,
        i: usize,
        result: &TestResult,
        ctx: &ReportContext<'_>,
        sink: Sink<'_>,
    ) {
        let st = &mut self.states[i];
        let before = st.status;
        st.status
            .set_mask(DtcStatus::TF | DtcStatus::TNCSLC | DtcStatus::TNCTOC, false);
        if st.status != before {
            let ev = self.build_view(
                i,
                before,
                ctx.time_s,
                Trigger::TestResult,
                MemoryAction::Unchanged,
                None,
                Some((result, ctx)),
            );
            sink(&ev);
        }
    }

    fn qualified_failed(
        &mut self,
        i: usize,
        result: &TestResult,
        ctx: &ReportContext<'_>,
        sink: Sink<'_>,
    ) {
        let confirmation_threshold = self.defs[i].confirmation_threshold;
        let mil = self.defs[i].mil;
        let ff_update = self.defs[i].freeze_frame_update;
        let st = &mut self.states[i];
        let before = st.status;
        let new_occurrence = !before.test_failed();
        let first_in_cycle = !before.contains(DtcStatus::TFTOC);
        let mut s = before;
        s.set_mask(
            DtcStatus::TF | DtcStatus::TFTOC | DtcStatus::PDTC | DtcStatus::TFSLC,
            true,
        );
        s.set_mask(DtcStatus::TNCSLC | DtcStatus::TNCTOC, false);
        st.healing_cycles = 0;
        st.aging_counter = 0;
        if first_in_cycle {
            st.failed_cycles = st.failed_cycles.saturating_add(1);
            if st.failed_cycles >= confirmation_threshold {
                s.set_mask(DtcStatus::CDTC, true);
                if mil.enabled && mil.on == MilOn::Confirmed {
                    s.set_mask(DtcStatus::WIR, true);
                }
            }
        }
        if mil.enabled && mil.on == MilOn::FirstFailure {
            s.set_mask(DtcStatus::WIR, true);
        }
        if new_occurrence {
            st.occurrence_counter = st.occurrence_counter.saturating_add(1);
        }
        st.status = s;
        let slot = st.slot;

        let mut action = MemoryAction::Unchanged;
        let mut displaced = None;
        if new_occurrence || first_in_cycle {
            match slot {
                None => (action, displaced) = self.store(i, ctx, sink),
                Some(k) => {
                    if new_occurrence && ff_update == FreezeFrameUpdate::Latest {
                        self.capture_freeze_frame(k as usize, i, ctx.freeze_frame);
                    }
                }
            }
        }
        if self.states[i].status != before || action != MemoryAction::Unchanged {
            let ev = self.build_view(
                i,
                before,
                ctx.time_s,
                Trigger::TestResult,
                action,
                displaced,
                Some((result, ctx)),
            );
            sink(&ev);
        }
    }

    fn capture_freeze_frame(&mut self, k: usize, i: usize, values: &[f64]) {
        let n = self.defs[i].freeze_frame.len();
        let dst = &mut self.ff[k * self.ff_stride..k * self.ff_stride + n];
        if values.len() == n {
            dst.copy_from_slice(values);
        } else {
            dst.fill(f64::NAN);
        }
    }

    /// Finds or frees a slot for event `i` and stores its entry.
    fn store(
        &mut self,
        i: usize,
        ctx: &ReportContext<'_>,
        sink: Sink<'_>,
    ) -> (MemoryAction, Option<Dtc>) {
        let mut displaced = None;
        let k = match self.slots.iter().position(|s| s.is_none()) {
            Some(k) => k,
            None => {
                self.overflow = true;
                let Some(k) = self.displacement_victim(self.defs[i].priority) else {
                    self.overflow_count = self.overflow_count.saturating_add(1);
                    return (MemoryAction::NotStored, None);
                };
                let Some(victim) = self.slots[k] else {
                    return (MemoryAction::NotStored, None);
                };
                let v = victim.event as usize;
                let before = self.states[v].status;
                self.states[v].status.set_mask(DtcStatus::CDTC, false);
                self.states[v].occurrence_counter = 0;
                self.states[v].aging_counter = 0;
                // Built while the entry still exists, so the lost freeze frame is reported.
                let ev = self.build_view(
                    v,
                    before,
                    ctx.time_s,
                    Trigger::Displacement,
                    MemoryAction::Displaced,
                    None,
                    None,
                );
                sink(&ev);
                self.states[v].slot = None;
                self.slots[k] = None;
                displaced = Some(self.defs[v].dtc);
                k
            }
        };
        self.slots[k] = Some(Entry {
            event: i as u16,
            seq: self.next_seq,
            stored_time_s: ctx.time_s,
        });
        self.next_seq += 1;
        let st = &mut self.states[i];
        st.slot = Some(k as u16);
        if st.occurrence_counter == 0 {
            st.occurrence_counter = 1;
        }
        self.capture_freeze_frame(k, i, ctx.freeze_frame);
        (MemoryAction::Stored, displaced)
    }

    /// The slot to give up for a new entry of priority `priority`: strictly lower priority
    /// only; lowest priority first, then passive before active, then oldest.
    fn displacement_victim(&self, priority: u8) -> Option<usize> {
        let mut best: Option<(usize, (u8, bool, u64))> = None;
        for (k, slot) in self.slots.iter().enumerate() {
            let Some(e) = slot else { continue };
            let p = self.defs[e.event as usize].priority;
            if p <= priority {
                continue;
            }
            let passive = !self.states[e.event as usize].status.test_failed();
            // Larger priority number, then passive, then smaller seq is a better victim.
            let key = (p, passive, e.seq);
            let better = match best {
                None => true,
                Some((_, b)) => {
                    key.0 > b.0
                        || (key.0 == b.0 && (key.1 && !b.1 || (key.1 == b.1 && key.2 < b.2)))
                }
            };
            if better {
                best = Some((k, key));
            }
        }
        best.map(|(k, _)| k)
    }

    // ---------------------------------------------------------------- operation cycles

    /// Starts an operation cycle at `time_s` (ending the running one first, if any): for every
    /// event, clears testFailedThisOperationCycle, sets testNotCompletedThisOperationCycle and
    /// resets the debouncer. Emits one event per changed status byte.
    pub fn start_operation_cycle(
        &mut self,
        time_s: f64,
        mut sink: impl FnMut(DiagnosticEvent),
    ) -> Result<(), DemError> {
        self.start_operation_cycle_view(time_s, |v| sink(v.to_event()))
    }

    /// [`EventMemory::start_operation_cycle`] with borrowed [`EventView`]s (no allocation).
    pub fn start_operation_cycle_view(
        &mut self,
        time_s: f64,
        mut sink: impl FnMut(&EventView<'_>),
    ) -> Result<(), DemError> {
        self.check_time(time_s)?;
        if self.cycle_active {
            self.end_cycle(time_s, true, &mut sink);
        }
        self.last_time_s = time_s;
        self.cycle_active = true;
        self.cycles_started += 1;
        for i in 0..self.states.len() {
            let st = &mut self.states[i];
            let before = st.status;
            st.status.set_mask(DtcStatus::TFTOC, false);
            st.status.set_mask(DtcStatus::TNCTOC, true);
            st.debouncer.reset();
            if st.status != before {
                let ev = self.build_view(
                    i,
                    before,
                    time_s,
                    Trigger::OperationCycleStart,
                    MemoryAction::Unchanged,
                    None,
                    None,
                );
                sink(&ev);
            }
        }
        Ok(())
    }

    /// Ends the running operation cycle at `time_s`: for every event whose test completed in
    /// the cycle without failure, clears pendingDTC, counts healing (MIL off) and aging cycles,
    /// and erases aged entries. Emits one event per changed status byte or erased entry.
    pub fn end_operation_cycle(
        &mut self,
        time_s: f64,
        mut sink: impl FnMut(DiagnosticEvent),
    ) -> Result<(), DemError> {
        self.end_operation_cycle_view(time_s, |v| sink(v.to_event()))
    }

    /// [`EventMemory::end_operation_cycle`] with borrowed [`EventView`]s (no allocation).
    pub fn end_operation_cycle_view(
        &mut self,
        time_s: f64,
        sink: impl FnMut(&EventView<'_>),
    ) -> Result<(), DemError> {
        self.end_operation_cycle_aging(time_s, true, sink)
    }

    /// Ends the running operation cycle; `aging_cycle` says whether it also counts as an aging
    /// cycle. OBD ages a DTC over *warm-up* cycles (AUTOSAR `DemAgingCycleRef` pointing at a
    /// warm-up cycle): a drive too short to warm the engine up still clears pendingDTC and
    /// counts towards switching the MIL off, but not towards aging.
    pub fn end_operation_cycle_aging(
        &mut self,
        time_s: f64,
        aging_cycle: bool,
        mut sink: impl FnMut(&EventView<'_>),
    ) -> Result<(), DemError> {
        self.check_time(time_s)?;
        if !self.cycle_active {
            return Err(DemError::NoOperationCycle);
        }
        self.last_time_s = time_s;
        self.end_cycle(time_s, aging_cycle, &mut sink);
        Ok(())
    }

    fn end_cycle(&mut self, time_s: f64, aging_cycle: bool, sink: Sink<'_>) {
        self.cycle_active = false;
        for i in 0..self.states.len() {
            let def = &self.defs[i];
            let st = &mut self.states[i];
            let before = st.status;
            let tested = !before.contains(DtcStatus::TNCTOC);
            let failed = before.contains(DtcStatus::TFTOC);
            if !tested || failed {
                continue;
            }
            let mut action = MemoryAction::Unchanged;
            let mut s = before;
            s.set_mask(DtcStatus::PDTC, false);
            st.failed_cycles = 0;
            if !s.warning_indicator() && (st.slot.is_some() || s.confirmed()) {
                // Only an aging cycle counts (pendingDTC is cleared above either way).
                if aging_cycle {
                    st.aging_counter = st.aging_counter.saturating_add(1);
                    if st.aging_counter >= def.aging_threshold {
                        s.set_mask(DtcStatus::CDTC, false);
                        st.occurrence_counter = 0;
                        if st.slot.is_some() {
                            action = MemoryAction::Aged;
                        }
                    }
                }
            } else if s.warning_indicator() {
                st.healing_cycles = st.healing_cycles.saturating_add(1);
                if st.healing_cycles >= def.mil.off_after_passing_cycles {
                    s.set_mask(DtcStatus::WIR, false);
                    st.healing_cycles = 0;
                }
            }
            st.status = s;
            if s != before || action != MemoryAction::Unchanged {
                // Built while an aged entry still exists, so its freeze frame is reported.
                let ev = self.build_view(
                    i,
                    before,
                    time_s,
                    Trigger::OperationCycleEnd,
                    action,
                    None,
                    None,
                );
                sink(&ev);
            }
            if action == MemoryAction::Aged {
                if let Some(k) = self.states[i].slot.take() {
                    self.slots[k as usize] = None;
                }
            }
        }
    }

    // ---------------------------------------------------------------- ClearDTC

    /// ClearDTC (UDS ClearDiagnosticInformation) for `group` at `time_s`: every matching event
    /// goes back to status `0x50` with its debouncer, counters and memory entry reset. Clearing
    /// [`DtcGroup::All`] also resets the overflow indication and count. Returns the number of
    /// events cleared; a single DTC that is not configured is [`DemError::UnknownDtc`]. Allowed
    /// inside and outside operation cycles.
    pub fn clear_dtc(
        &mut self,
        group: DtcGroup,
        time_s: f64,
        mut sink: impl FnMut(DiagnosticEvent),
    ) -> Result<usize, DemError> {
        self.clear_dtc_view(group, time_s, |v| sink(v.to_event()))
    }

    /// [`EventMemory::clear_dtc`] with borrowed [`EventView`]s (no allocation).
    pub fn clear_dtc_view(
        &mut self,
        group: DtcGroup,
        time_s: f64,
        mut sink: impl FnMut(&EventView<'_>),
    ) -> Result<usize, DemError> {
        self.check_time(time_s)?;
        if let DtcGroup::Dtc(d) = group {
            if self.event_id_by_dtc(d).is_none() {
                return Err(DemError::UnknownDtc(d));
            }
        }
        self.last_time_s = time_s;
        let mut cleared = 0;
        for i in 0..self.states.len() {
            if !group.contains(self.defs[i].dtc) {
                continue;
            }
            cleared += 1;
            let before = self.states[i].status;
            let action = if self.states[i].slot.is_some() {
                MemoryAction::Cleared
            } else {
                MemoryAction::Unchanged
            };
            // Built before the entry goes, so the cleared freeze frame is reported.
            let changed = before != DtcStatus::AFTER_CLEAR || action != MemoryAction::Unchanged;
            self.states[i].reset();
            if changed {
                let ev = self.build_view(i, before, time_s, Trigger::ClearDtc, action, None, None);
                sink(&ev);
            }
            if let Some(k) = self.states[i].slot.take() {
                self.slots[k as usize] = None;
            }
        }
        if group == DtcGroup::All {
            self.overflow = false;
            self.overflow_count = 0;
        }
        Ok(cleared)
    }

    // ---------------------------------------------------------------- events

    #[allow(clippy::too_many_arguments)]
    fn build_view<'s>(
        &'s self,
        i: usize,
        before: DtcStatus,
        time_s: f64,
        trigger: Trigger,
        memory: MemoryAction,
        displaced: Option<Dtc>,
        cause: Option<(&TestResult, &ReportContext<'s>)>,
    ) -> EventView<'s> {
        let d = &self.defs[i];
        let s = &self.states[i];
        let freeze_frame = match (s.slot, cause) {
            (Some(k), _) => {
                let base = k as usize * self.ff_stride;
                FreezeFrameView {
                    signals: &d.freeze_frame,
                    values: &self.ff[base..base + d.freeze_frame.len()],
                }
            }
            (None, Some((_, ctx))) if memory == MemoryAction::NotStored => FreezeFrameView {
                signals: &d.freeze_frame,
                values: ctx.freeze_frame,
            },
            _ => FreezeFrameView::EMPTY,
        };
        EventView {
            time_s,
            event: &d.name,
            dtc: d.dtc,
            trigger,
            status_before: before,
            status_after: s.status,
            fdc: s.debouncer.fdc(),
            occurrence_counter: s.occurrence_counter,
            aging_counter: s.aging_counter,
            memory,
            displaced,
            freeze_frame,
            test_result: cause.map(|(r, _)| *r),
            candidates: cause.map_or(&[], |(_, ctx)| ctx.candidates),
        }
    }
}
