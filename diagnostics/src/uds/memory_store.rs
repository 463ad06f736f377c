//! [`EventMemoryStore`], the [`DtcStore`] of one [`EventMemory`], the DIDs of its freeze-frame
//! signals (rule in [the `uds` documentation](crate::uds#freeze-frame-dids)), and the per-memory
//! helpers a store over several memories is built from.

use crate::dtc::{DemError, Dtc, DtcGroup, DtcStatus, EventMemory};
use crate::event::DiagnosticEvent;

use super::{ClearRefused, DtcStore, ExtendedData, SnapshotValue};

/// DID of the first freeze-frame signal of an [`EventMemory`].
pub const FREEZE_FRAME_DID_BASE: u16 = 0xFD00;
/// Last DID available to freeze-frame signals (end of the system-supplier-specific range).
pub const FREEZE_FRAME_DID_LAST: u16 = 0xFEFF;

/// Every (event, position) freeze-frame slot's signal name, in configuration order.
fn signal_slots(memory: &EventMemory) -> impl Iterator<Item = &str> + '_ {
    memory
        .event_ids()
        .flat_map(move |id| memory.freeze_frame_signals(id).iter().map(String::as_str))
}

/// The DID table of `memory`: `(did, signal)` for each distinct freeze-frame signal, in DID
/// order ([the rule](crate::uds#freeze-frame-dids)). No allocation; quadratic in the number of
/// freeze-frame slots, which is fine for the tens a memory has.
pub fn freeze_frame_dids(memory: &EventMemory) -> impl Iterator<Item = (u16, &str)> + '_ {
    signal_slots(memory)
        .enumerate()
        .filter(move |&(k, s)| signal_slots(memory).take(k).all(|t| t != s))
        .map(|(_, s)| s)
        .zip(FREEZE_FRAME_DID_BASE..=FREEZE_FRAME_DID_LAST)
        .map(|(s, did)| (did, s))
}

/// The DID of freeze-frame signal `signal` in `memory`, if it is one (and within the first 512).
pub fn freeze_frame_did(memory: &EventMemory, signal: &str) -> Option<u16> {
    freeze_frame_dids(memory)
        .find(|&(_, s)| s == signal)
        .map(|(did, _)| did)
}

/// The snapshot record of `dtc` in `memory` as [`DtcStore::snapshot`] gives it: the freeze
/// frame of its memory entry, each signal under the DID `did_of(signal)` (signals without one
/// are skipped). `None` if `memory` does not hold `dtc`. For stores over several memories,
/// which pass their own DID assignment; [`EventMemoryStore`] passes [`freeze_frame_did`].
pub fn memory_snapshot(
    memory: &EventMemory,
    dtc: Dtc,
    did_of: &dyn Fn(&str) -> Option<u16>,
    visit: &mut dyn FnMut(SnapshotValue),
) -> Option<DtcStatus> {
    let id = memory.event_id_by_dtc(dtc)?;
    if let Some(entry) = memory.entry(id) {
        for (signal, value) in entry.freeze_frame() {
            if let Some(did) = did_of(signal) {
                visit(SnapshotValue { did, value });
            }
        }
    }
    Some(memory.status(id))
}

/// The extended data of `dtc` in `memory` as [`DtcStore::extended_data`] gives them; `None`
/// if `memory` does not hold `dtc`.
pub fn memory_extended_data(memory: &EventMemory, dtc: Dtc) -> Option<ExtendedData> {
    let id = memory.event_id_by_dtc(dtc)?;
    let info = memory.event_info(id);
    Some(ExtendedData {
        status: info.status,
        stored: info.stored,
        occurrence_counter: info.occurrence_counter,
        aging_counter: info.aging_counter,
        max_fdc: info.max_fdc,
    })
}

/// [`EventMemory::clear_dtc`] with its errors as [`ClearRefused`]: an unknown DTC is
/// [`ClearRefused::UnknownDtc`], a bad time [`ClearRefused::ConditionsNotCorrect`].
pub fn memory_clear(
    memory: &mut EventMemory,
    group: DtcGroup,
    time_s: f64,
    sink: impl FnMut(DiagnosticEvent),
) -> Result<usize, ClearRefused> {
    memory.clear_dtc(group, time_s, sink).map_err(|e| match e {
        DemError::UnknownDtc(d) => ClearRefused::UnknownDtc(d),
        DemError::NonFiniteTime(_) => {
            ClearRefused::ConditionsNotCorrect("the clear time is not finite")
        }
        DemError::TimeWentBackwards { .. } => ClearRefused::ConditionsNotCorrect(
            "the clear time is before the event memory's last call",
        ),
        _ => ClearRefused::ConditionsNotCorrect("the event memory refused the clear"),
    })
}

/// The [`DtcStore`] of one [`EventMemory`]: DTCs in configuration order, the snapshot record
/// is the memory entry's freeze frame (DIDs by [the rule](crate::uds#freeze-frame-dids)), the
/// extended data are the entry's counters.
///
/// ClearDTC needs a time and passes the [`DiagnosticEvent`]s it causes to a sink, so the
/// adapter holds both: `time_s` (s, the memory's clock) stamps every clear until
/// [`set_time`](Self::set_time) changes it, and `sink` receives the events. Set the time to
/// "now" before handling a request; a time before the memory's last call makes the clear fail
/// with [`ClearRefused::ConditionsNotCorrect`] (NRC `0x22`) and changes nothing.
///
/// ```
/// use fdd_diagnostics::dtc::{EventConfig, EventMemory, EventMemoryConfig};
/// use fdd_diagnostics::uds::{handle_request, EventMemoryStore, Reply};
///
/// let config = EventMemoryConfig { capacity: 4, events: vec![EventConfig::new("tps_low", "P0122-16", 2)] };
/// let mut memory = EventMemory::new(&config).unwrap();
/// let mut events = Vec::new();
/// let mut store = EventMemoryStore::new(&mut memory, 0.0, |e| events.push(e));
/// let mut response = Vec::with_capacity(4095);
/// assert_eq!(handle_request(&mut store, &[0x19, 0x02, 0xFF], &mut response), Reply::Positive);
/// assert_eq!(response, [0x59, 0x02, 0xFF, 0x01, 0x22, 0x16, 0x50]);
/// ```
pub struct EventMemoryStore<'m, F> {
    memory: &'m mut EventMemory,
    time_s: f64,
    sink: F,
}

impl<'m, F: FnMut(DiagnosticEvent)> EventMemoryStore<'m, F> {
    /// The store of `memory`; clears happen at `time_s` (s) and emit their events to `sink`.
    pub fn new(memory: &'m mut EventMemory, time_s: f64, sink: F) -> Self {
        EventMemoryStore {
            memory,
            time_s,
            sink,
        }
    }

    /// The time (s) the next clears are stamped with.
    pub fn set_time(&mut self, time_s: f64) {
        self.time_s = time_s;
    }

    /// The time (s) clears are stamped with.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// The memory.
    pub fn memory(&self) -> &EventMemory {
        self.memory
    }
}

impl<F: FnMut(DiagnosticEvent)> DtcStore for EventMemoryStore<'_, F> {
    fn status_availability_mask(&self) -> u8 {
        DtcStatus::AVAILABILITY_MASK
    }

    fn for_each_dtc(&self, f: &mut dyn FnMut(Dtc, DtcStatus)) {
        for id in self.memory.event_ids() {
            f(self.memory.dtc(id), self.memory.status(id));
        }
    }

    fn snapshot(&self, dtc: Dtc, visit: &mut dyn FnMut(SnapshotValue)) -> Option<DtcStatus> {
        let memory: &EventMemory = self.memory;
        memory_snapshot(memory, dtc, &|s| freeze_frame_did(memory, s), visit)
    }

    fn extended_data(&self, dtc: Dtc) -> Option<ExtendedData> {
        memory_extended_data(self.memory, dtc)
    }

    fn clear(&mut self, group: DtcGroup) -> Result<usize, ClearRefused> {
        memory_clear(self.memory, group, self.time_s, &mut self.sink)
    }
}
